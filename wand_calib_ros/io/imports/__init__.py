"""Wand observations written by other tools, read into this package's observations.

Formats: ``xypts`` (easyWand / Argus / DLTdv point files, :mod:`wand_calib_ros.io.imports.xypts`).
"""
