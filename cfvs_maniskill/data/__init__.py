"""CFVS training data: coarse (OAKN) and fine (OPN) datasets, labels, augmentation, HDF5 files."""
