"""Calibration quality without ground truth.

:func:`rqe` is the Renyi quadratic entropy "crispness" (Sheehan, Harrison and Newman, IJRR 2012)
that seed 003 uses on real data: merge the two clouds with a candidate calibration and measure how
sharp the result is; a larger value is a better calibration.
"""

from __future__ import annotations

from numpy.typing import ArrayLike

from lidarcal._lidarcal import rqe as _rqe

__all__ = ["rqe"]


def rqe(points: ArrayLike, sigma: float) -> float:
    """Renyi quadratic entropy crispness ``C`` of an ``(N, 3)`` or ``(N, 4)`` cloud, in (0, 1].

    ``C = 1/N^2 sum_ij exp(-|x_i - x_j|^2 / (4 sigma^2))`` with pairs further apart than
    ``3 sqrt(2) sigma`` (3 kernel standard deviations) dropped and the rest found on a hash grid,
    so it costs O(N k), not O(N^2). The entropy is ``-log(C)``; larger ``C`` is crisper.

    >>> import numpy as np
    >>> rqe(np.zeros((10, 3)), 0.05)
    1.0
    """
    return _rqe(points, sigma)
