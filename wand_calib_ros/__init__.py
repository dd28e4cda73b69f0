"""wand_calib_ros: multi-camera wand calibration (Fu, Quan & Cai) for ROS 2."""

__version__ = "0.1.0"
