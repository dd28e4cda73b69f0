"""wand_calib_ros: multi-camera wand calibration (Fu, Quan & Cai) for ROS 2.

Importing the package before numpy limits OpenBLAS to one thread unless ``OPENBLAS_NUM_THREADS`` is
set: a calibration is many small matrix products, where numpy's and scipy's two OpenBLAS thread pools
contend for the cores and cost more than they give (``benchmarks/stages.py``: 4.8 s against 5.9 s
in-process on 16 cameras x 10,000 placements, on two cores).
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

__version__ = "0.1.0"
