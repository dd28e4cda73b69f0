"""What is done with a finished calibration: a world frame from the floor, whether a camera moved and its
repair, and the scene a viewer (RViz) shows."""
