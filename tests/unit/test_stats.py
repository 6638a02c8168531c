"""Tests for the 95% intervals of reported numbers (checked against textbook values)."""

from __future__ import annotations

import pytest

from kinet_rl.stats import average_ranks, mean_interval, spearman, t_975, wilson_interval


def test_mean_interval_is_students_t() -> None:
    mean, half = mean_interval([1.0, 2.0, 3.0])
    assert mean == 2.0 and half == pytest.approx(4.303 * 1.0 / 3**0.5)
    assert mean_interval([5.0]) == (5.0, None)
    with pytest.raises(ValueError, match="at least one"):
        mean_interval([])


def test_t_quantile_falls_back_to_the_tabulated_dof_below_then_the_normal() -> None:
    assert t_975(2) == 4.303 and t_975(11) == t_975(10) == 2.228
    assert t_975(99) == 2.0 and t_975(999) == pytest.approx(1.96, abs=1e-3)
    with pytest.raises(ValueError, match="degree of freedom"):
        t_975(0)


def test_wilson_interval_matches_the_textbook_and_stays_in_0_1() -> None:
    low, high = wilson_interval(45, 100)  # 45%: [35.6%, 54.8%]
    assert low == pytest.approx(0.3561, abs=1e-3) and high == pytest.approx(0.5475, abs=1e-3)
    assert wilson_interval(0, 20)[0] == 0.0 and 0.0 < wilson_interval(0, 20)[1] < 0.2
    with pytest.raises(ValueError, match="successes"):
        wilson_interval(3, 2)


def test_spearman_ranks_ties_by_their_mean_rank() -> None:
    assert spearman([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert spearman([1, 2, 3, 4], [9, 4, 1, 0]) == pytest.approx(-1.0)  # monotone, not linear
    # ranks of y: 1, 2, 3.5, 5, 3.5 -> rho = 8 / sqrt(10 * 9.5)
    assert spearman([1, 2, 3, 4, 5], [5, 6, 7, 8, 7]) == pytest.approx(8 / 95**0.5)
    assert average_ranks([3.0, 1.0, 3.0]).tolist() == [2.5, 1.0, 2.5]


def test_spearman_is_none_when_undefined_and_refuses_unpaired_values() -> None:
    assert spearman([1, 2, 3], [4, 4, 4]) is None and spearman([1], [2]) is None
    with pytest.raises(ValueError, match="paired values; got 3 and 2"):
        spearman([1, 2, 3], [1, 2])
