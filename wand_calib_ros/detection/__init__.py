"""LED wand detection: blobs to labelled A/B/C points (no ROS)."""
