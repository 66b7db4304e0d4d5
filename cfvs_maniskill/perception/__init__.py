"""What both the data pipeline (`data/`) and the agents (`agents/`) use to read the wrist
camera: point-cloud utilities (table fit, object points, crops), wrist images, and the
keypoint labels that the networks learn and the agents decode. Neither of those packages
imports the other."""
