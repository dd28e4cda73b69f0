"""Step 1: fitting the five classic projections and choosing the plausible ones."""

from __future__ import annotations

import numpy as np
import pytest

from wand_calib_ros.core.errors import ModelError
from wand_calib_ros.core.initialise.intrinsics_init import fit_projection, initial_model, lens_candidates
from wand_calib_ros.core.model.rig import CameraSpec


def _spec(angle: float, lens: str | None = None, focal: float = 1.8) -> CameraSpec:
    return CameraSpec("cam", (640, 480), (5.6, 5.6), focal, angle, lens)


def test_equidistant_fit_is_exact() -> None:
    candidate = fit_projection("equidistant", 1.8, np.radians(92.5))
    assert candidate.k1 == pytest.approx(1.8, abs=1e-12) and candidate.k2 == pytest.approx(0.0, abs=1e-12)
    assert candidate.fit_rms_mm < 1e-12


def test_fits_follow_the_taylor_series_at_small_angles() -> None:
    # f tan(t) = f (t + t^3/3 + ...), 2 f sin(t/2) = f (t - t^3/24 + ...)
    perspective = fit_projection("perspective", 4.0, np.radians(5.0))
    equisolid = fit_projection("equisolid", 4.0, np.radians(5.0))
    assert perspective.k2 == pytest.approx(4.0 / 3, rel=1e-2)
    assert equisolid.k2 == pytest.approx(-4.0 / 24, rel=1e-2)


def test_fisheye_beyond_ninety_degrees_excludes_perspective_and_turning_curves() -> None:
    names = {c.projection for c in lens_candidates(_spec(92.5))}
    assert "perspective" not in names and "orthogonal" not in names
    assert {"equidistant", "equisolid", "stereographic"} <= names


def test_lens_hint_short_circuits_the_choice() -> None:
    assert [c.projection for c in lens_candidates(_spec(40.0, "conventional", 4.2))] == ["perspective"]
    assert [c.projection for c in lens_candidates(_spec(92.5, "equisolid"))] == ["equisolid"]
    assert "perspective" not in {c.projection for c in lens_candidates(_spec(60.0, "fisheye"))}


def test_near_identical_curves_are_merged() -> None:
    # At 3 degrees every projection is f*theta within a fraction of a pixel.
    assert len(lens_candidates(_spec(3.0, focal=4.0))) == 1


def test_unknown_lens_and_bad_data_sheet_are_errors() -> None:
    with pytest.raises(ModelError, match="unknown lens"):
        lens_candidates(_spec(40.0, "pinhole"))
    with pytest.raises(ModelError, match="max_view_angle_deg"):
        lens_candidates(_spec(190.0))
    with pytest.raises(ModelError, match="no classic projection"):
        lens_candidates(_spec(120.0, "conventional"))


def test_initial_model_uses_pixel_size_and_image_centre() -> None:
    spec = _spec(92.5)
    model = initial_model(spec, lens_candidates(spec)[0])
    assert np.allclose(model.m, 1000 / 5.6) and np.allclose(model.principal_point, [319.5, 239.5])
    assert np.all(model.k[2:] == 0)
