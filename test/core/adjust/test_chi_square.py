"""The chi-square quantiles of the significance tests against scipy's."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.special

from wand_calib_ros.core.adjust.chi_square import chi_square_quantile, chi_square_tails


@pytest.mark.parametrize("dof", [*range(1, 41), 50, 64, 99, 128, 200, 500, 1000, 4000])
def test_quantiles_match_scipy(dof: int) -> None:
    for probability in (1e-9, 1e-3, 0.01, 0.3, 0.5, 0.9, 0.95, 0.99, 0.999, 1 - 1e-9):
        x = chi_square_quantile(probability, dof)
        # scipy on the tail where its argument is exact: 1 - probability loses a small probability's digits
        if probability < 0.5:
            expected = 2.0 * float(scipy.special.gammaincinv(0.5 * dof, probability))
        else:
            expected = float(scipy.special.chdtri(dof, 1.0 - probability))
        assert x == pytest.approx(expected, rel=1e-10)
        lower, upper = chi_square_tails(x, dof)
        assert lower == pytest.approx(probability, rel=1e-10) and upper == pytest.approx(1 - probability, rel=1e-10)


def test_tails_match_scipy_on_both_sides_of_the_switch() -> None:
    for dof in (1, 2, 7, 30):
        for x in np.linspace(0.01, 4.0 * dof + 10.0, 57):
            lower, upper = chi_square_tails(float(x), dof)
            assert lower == pytest.approx(float(scipy.special.chdtr(dof, x)), rel=1e-12, abs=1e-300)
            assert upper == pytest.approx(float(scipy.special.chdtrc(dof, x)), rel=1e-11, abs=1e-300)


def test_bad_arguments_are_refused() -> None:
    for probability, dof in ((0.0, 3), (1.0, 3), (0.5, 0)):
        with pytest.raises(ValueError):
            chi_square_quantile(probability, dof)
