"""Step 4's orchestration: the placements the outliers and the model order are decided on."""

from __future__ import annotations

import numpy as np

from wand_calib_ros.core.refine import COARSE_PLACEMENTS, coarse_subset


def test_the_coarse_subset_does_not_shift_when_the_gate_keeps_a_placement_less() -> None:
    kept = np.arange(10_000)
    every = coarse_subset(kept, 10_000)
    assert every.size == COARSE_PLACEMENTS
    for gone in (0, 17, 6_666, 9_999):  # on the spread or between: the rest stays as it was
        fewer = coarse_subset(np.delete(kept, gone), 10_000)
        assert set(every) - set(fewer) <= {gone} and set(fewer) <= set(every)


def test_a_gate_that_kept_few_has_the_coarse_placements_spread_over_those() -> None:
    kept = np.arange(0, 10_000, 4)  # a quarter: most of the spread over the recording gated out
    chosen = coarse_subset(kept, 10_000)
    assert chosen.size == COARSE_PLACEMENTS and set(chosen) <= set(kept)
    assert np.all(np.diff(chosen) > 0)
