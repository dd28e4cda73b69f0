"""Wand observations and intrinsics written by other tools, read into this package's observations and rig file.

Points: ``xypts`` (easyWand / Argus / DLTdv point files), ``easywand`` (easyWand's data file), ``caliscope`` and
``openlpt`` (point tables, :mod:`~wand_calib_ros.io.imports.point_table`). Intrinsics
(:mod:`~wand_calib_ros.io.imports.intrinsics`): aniposelib's and caliscope's TOML files, the Argus / easyWand camera
profile.
"""
