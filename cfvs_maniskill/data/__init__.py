"""Training data for any policy: the resumable collector of the sample kinds the policies
declare, procedural bodies, augmentation, HDF5 files."""
