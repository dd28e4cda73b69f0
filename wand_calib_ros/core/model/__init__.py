"""Camera models (the paper's generic radial model, OpenCV's pinhole ones), rigid geometry, and the typed
records of a calibration's input (rig, wand, observations) and output (result, world frame)."""
