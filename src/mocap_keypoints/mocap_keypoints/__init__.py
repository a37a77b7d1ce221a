"""2D body keypoints with confidences (23-point layout) from a camera, a video file, an image
topic or OpenPose JSON."""
