"""Intervals of the reported numbers (Student's t for means, Wilson for success rates) and
Spearman's rank correlation."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: Two-sided 95% quantiles of Student's t by degrees of freedom (larger: the normal 1.96 is used).
T_975 = {
    1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306, 9: 2.262,
    10: 2.228, 12: 2.179, 15: 2.131, 20: 2.086, 30: 2.042, 60: 2.000,
}  # fmt: skip
Z_975 = 1.959964


def t_975(dof: int) -> float:
    """The two-sided 95% quantile of Student's t (the nearest tabulated dof at or below ``dof``)."""
    if dof < 1:
        raise ValueError(f"Student's t needs at least 1 degree of freedom, got {dof}.")
    if dof > max(T_975):
        return Z_975 if dof > 120 else T_975[max(T_975)]
    return T_975[max(d for d in T_975 if d <= dof)]


def mean_interval(values: Sequence[float]) -> tuple[float, float | None]:
    """Mean and half-width of its 95% interval (Student's t; None for one value)."""
    n = len(values)
    if n == 0:
        raise ValueError("mean_interval needs at least one value.")
    mean = sum(values) / n
    if n < 2:
        return mean, None
    std = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    return mean, t_975(n - 1) * std / math.sqrt(n)


def wilson_interval(successes: int, n: int) -> tuple[float, float]:
    """The 95% Wilson score interval ``(low, high)`` of a success rate of ``successes`` in ``n``."""
    if n < 1 or not 0 <= successes <= n:
        raise ValueError(f"wilson_interval needs 0 <= successes <= n, n >= 1; got {successes}/{n}.")
    p, z2 = successes / n, Z_975**2
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = Z_975 * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def average_ranks(values: Sequence[float] | np.ndarray) -> np.ndarray:
    """Ranks 1..n of ``values``; tied values share the mean of their ranks."""
    values = np.asarray(values, dtype=np.float64)
    order = np.argsort(values, kind="stable")
    ranks = np.empty(len(values))
    ranks[order] = np.arange(1, len(values) + 1)
    _, groups = np.unique(values, return_inverse=True)
    return (np.bincount(groups, weights=ranks) / np.bincount(groups))[groups]


def spearman(x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray) -> float | None:
    """Spearman's rank correlation of paired values (Pearson's of their :func:`average_ranks`),
    in [-1, 1]; None when it is undefined (fewer than 2 pairs, or one side constant)."""
    if len(x) != len(y):
        raise ValueError(f"spearman needs paired values; got {len(x)} and {len(y)}.")
    if len(x) < 2:
        return None
    rx, ry = average_ranks(x), average_ranks(y)
    dx, dy = rx - rx.mean(), ry - ry.mean()
    scale = math.sqrt(float((dx * dx).sum() * (dy * dy).sum()))
    return float((dx * dy).sum() / scale) if scale > 0 else None
