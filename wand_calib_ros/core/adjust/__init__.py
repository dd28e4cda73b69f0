"""The bundle adjustment (Step 4, and Step 2 of Section III-B): its residuals and normal equations, the
wand's placements, the timing of free-running and rolling-shutter cameras, the outlier gates and the
distortion order and timing terms the data support."""
