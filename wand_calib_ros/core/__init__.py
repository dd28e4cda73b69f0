"""The method, without ROS: wand observations of a rig in, a calibration out.

Subpackages in the order they build on one another (each imports only those before it):

- :mod:`~wand_calib_ros.core.model`: the camera models, rigid geometry and the typed records of a rig,
  its observations and a finished calibration.
- :mod:`~wand_calib_ros.core.adjust`: the bundle adjustment and what it is made of: normal equations,
  placements, timing of free-running cameras, outlier gates, the model order the data support.
- :mod:`~wand_calib_ros.core.judge`: whether data and results can be right: degeneracy, plausibility,
  quality, diagnostics, accuracy against a truth.
- :mod:`~wand_calib_ros.core.initialise`: the paper's Steps 1-3 and Section III-B that give the
  adjustment its start, and the camera model each camera is calibrated in.
- :mod:`~wand_calib_ros.core.after`: what is done with a calibration: a world frame, bumps and repair,
  the scene a viewer shows.

On top: :mod:`~wand_calib_ros.core.refine` (Step 4 around the solver) and
:mod:`~wand_calib_ros.core.pipeline` (the entry point, :func:`~wand_calib_ros.core.pipeline.calibrate`).
"""
