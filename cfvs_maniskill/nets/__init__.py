"""The CFVS networks: a pure-torch PointNet++ backbone, OAKN (coarse) and OPN (fine)."""
