"""What the policies (`policies/`) and their datasets (`data/`) use to read the wrist
camera: point-cloud utilities (table fit, object points, crops), wrist images, and the
keypoint labels that the networks learn and the agents decode, so that a dataset is made
the way its agent sees."""
