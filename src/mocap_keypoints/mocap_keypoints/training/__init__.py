"""Training and evaluation of the keypoint node's own models (no ROS imports)."""
