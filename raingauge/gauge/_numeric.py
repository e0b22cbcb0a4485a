"""Small numeric helpers of the gauge's per-streak paths."""

from __future__ import annotations

import numpy as np


def clip(x, lo, hi):
    """``np.clip(x, lo, hi)`` (either bound may be None) without the cost of its Python
    wrapper, which is paid per call on the gauge's per-streak paths."""
    if lo is not None:
        x = np.maximum(x, lo)
    if hi is not None:
        x = np.minimum(x, hi)
    return x
