"""Argument checks shared by the physics modules (one message for one mistake)."""

from __future__ import annotations

import math


def positive(name: str, value) -> float:
    """``value`` as a float when it is finite and > 0; else ValueError naming the parameter.

    Parameters
    ----------
    name : str
        Parameter name as the caller spells it (``"exposure_s"``).
    value : float
        The value given [the parameter's unit].
    """
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}") from None
    if not (x > 0 and math.isfinite(x)):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return x
