"""The start of the adjustment: intrinsics from the data sheet (Step 1), pair poses from essential matrices
(Step 2), the wand-length LM (Step 3), the vision graph and chained pairs (Section III-B), two-marker
labels, cameras with known intrinsics placed one by one, and the camera model each camera is calibrated in."""
