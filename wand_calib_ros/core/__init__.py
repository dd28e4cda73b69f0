"""Numerical core: camera model, geometry, the paper's calibration steps, bundle adjustment (no ROS)."""
