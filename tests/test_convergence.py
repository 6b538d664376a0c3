"""Time-step verification (nscd.convergence): outcome comparison and the reruns it makes.

A result provably unconverged beside a converged one, on an LNEC cell of 003 Table 4, is in
tests/test_lnec_table4.py."""
from __future__ import annotations

import math

import pytest

from nscd.analysis import verify_time_step
from nscd.convergence import TimeStepCheck, compare_outcomes

# --------------------------------------------------------------------------- comparing outcomes


def test_categorical_quantities_must_be_equal_and_real_ones_within_tolerance():
    a = {"mode": "B_L", "overturned": True, "impacts": 3, "peak": 1.00}
    assert compare_outcomes(a, dict(a)) == []
    assert compare_outcomes(a, {**a, "mode": "B_R"}, label="dt/2") == ["dt/2: mode B_L -> B_R"]
    assert compare_outcomes(a, {**a, "overturned": False}) == ["overturned True -> False"]
    assert compare_outcomes(a, {**a, "impacts": 4}) == ["impacts 3 -> 4"]
    # |1.00 - 1.09| = 0.09 <= 0.1 * 1.09, but 0.12 > 0.1 * 1.12
    assert compare_outcomes(a, {**a, "peak": 1.09}) == []
    assert compare_outcomes(a, {**a, "peak": 1.12}) == ["peak 1 -> 1.12"]
    # near zero only the absolute tolerance can tell two "nothing happened" runs alike
    small = {"peak": 1e-6}
    assert compare_outcomes(small, {"peak": 3e-6}, rtol=0.1) != []
    assert compare_outcomes(small, {"peak": 3e-6}, rtol=0.1, atol={"peak": 1e-3}) == []
    assert compare_outcomes({"x": math.nan}, {"x": math.nan}) == []


def test_bad_comparisons_are_refused():
    with pytest.raises(ValueError, match="must have the same"):
        compare_outcomes({"mode": "A"}, {"mode": "A", "peak": 0.0})
    with pytest.raises(ValueError, match="rtol == -0.1"):
        compare_outcomes({"peak": 1.0}, {"peak": 1.0}, rtol=-0.1)
    with pytest.raises(ValueError, match=r"atol\['peak'\] == -1.0"):
        compare_outcomes({"peak": 1.0}, {"peak": 2.0}, atol={"peak": -1.0})
    with pytest.raises(ValueError, match="dt == 0"):
        verify_time_step(lambda dt, scheme: {}, 0.0)
    with pytest.raises(ValueError, match="scheme == 'euler'"):
        verify_time_step(lambda dt, scheme: {}, 1e-3, scheme="euler")


def test_verify_time_step_reruns_at_half_the_step_and_with_the_other_scheme():
    calls = []

    def run(dt, scheme):
        calls.append((dt, scheme))
        # a threshold outcome that a step coarser than 0.7 ms decides wrongly, theta only
        return {"mode": "A" if dt < 7e-4 or scheme == "midpoint" else "B_L"}

    coarse = verify_time_step(run, 1e-3, scheme="theta")
    assert calls == [(1e-3, "theta"), (5e-4, "theta")]
    assert not coarse.converged and coarse.changes == ("dt/2: mode B_L -> A",)
    fine = verify_time_step(run, 6e-4, scheme="theta", other_scheme=True)
    assert fine.converged and fine.other_scheme == {"mode": "A"}
    assert fine.to_row() == {"mode": "A", "converged": True, "changes": ""}
    assert isinstance(fine, TimeStepCheck)
