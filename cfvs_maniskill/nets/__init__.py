"""What the policies' networks share: a pure-torch PointNet++ backbone and the weights files' format."""
