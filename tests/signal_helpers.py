"""Signal helpers shared by the tests (not part of the package)."""

from __future__ import annotations

import numpy as np


def period_of(profile, guess):
    """Lag of the smallest mean squared difference between the profile and its shift [px].

    Searches lags from 0.5 to 1.6 times ``guess`` and refines the minimum with a parabola.
    """
    n = profile.size
    lags = np.arange(1, int(1.6 * guess) + 2)
    d = np.array([np.mean((profile[k:] - profile[:n - k]) ** 2) for k in lags])
    lo = int(0.5 * guess)
    j = lo - 1 + int(np.argmin(d[lo - 1:-1]))
    y0, y1, y2 = d[j - 1], d[j], d[j + 1]
    return lags[j] + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)
