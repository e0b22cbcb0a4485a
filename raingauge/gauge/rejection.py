"""Defocus rejection: keep the streaks whose size and speed obey the velocity law (Sec. 8).

Measured at the focus distance z0, a drop at depth z appears with radius
a' = w' z0 / (2 f) and speed v' = v z0 / z, where its apparent width w' also
holds the defocus blur.  Only near z0 do (a', v') satisfy the fall-velocity
law; away from it the blur fattens the streak and the perspective scales both,
so the pair leaves the law.  "Defocused streaks are removed by rejecting rain
streaks that do not satisfy the velocity-size relationship" [GargNayar2007,
Sec. 8 and its note 28].

The test is on the log ratio r = ln(v' / V(2 a')) with V the chosen law of
:func:`raingauge.physics.drops.fall_velocity` (the paper's v = 200 sqrt(a) by
default), and the tolerance comes from the measurement error: a floor for the
natural spread of drop speeds plus k standard errors of r, propagated from the
errors of the width and of the length.

Two focus tests complete it.  With the paper's uniform spreading of a
defocused drop (Eqs. 23-24) the streak's edges stay sharp but its change drops
by w / (w + b_c): the photometric focus q = (w / w')^2, from the streak's total
change and the drop brightness of the sharpest streaks, bounds the blur
(:func:`photometric_focus`).  With a real lens (a pillbox blur) the edges
soften and the fitted blur is bounded directly (:func:`passes_blur`).  Without
them, drops nearer than z0, whose perspective enlargement offsets their blur,
would pass the velocity law.

Notes
-----
The seed text refers to the velocity law of note 28 as "Eq. (??)"; it is
v = 200 sqrt(a) [GargNayar2007], the large-drop law (see DESIGN.md), which is
1.5-2.8 times too fast below 0.8 mm: with real rain choose a measured law
(``gunn_kinzer``, ``atlas1973``, ``beard1976``).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "velocity_log_ratio",
    "law_log_slope",
    "ratio_sigma",
    "law_tolerance",
    "passes_velocity_law",
    "DEFAULT_TOLERANCE_FLOOR",
    "DEFAULT_K_SIGMA",
    "DEFAULT_WIDTH_SIGMA_PX",
    "DEFAULT_MOTION_SIGMA_PX",
    "DEFAULT_BLUR_FLOOR_PX",
    "DEFAULT_BLUR_RELATIVE",
    "DEFAULT_BLUR_SIGMA_PX",
    "max_blur_px",
    "passes_blur",
    "photometric_focus",
    "exposure_area_px2",
    "q_sigma",
    "DEFAULT_Q_MIN",
]

#: Spread of real drop speeds about the law that is always tolerated (ln units, ~8 %).
DEFAULT_TOLERANCE_FLOOR = 0.08
#: Number of standard errors of the measurement allowed.
DEFAULT_K_SIGMA = 3.0
#: Typical standard error of a fitted streak width [px] (see tests/test_gauge_streaks.py).
DEFAULT_WIDTH_SIGMA_PX = 0.25
#: Typical standard error of a fitted streak motion [px].
DEFAULT_MOTION_SIGMA_PX = 1.0


#: Blur always accepted [px] (a sharp edge fits to ~0.5 px of blur in noise).
DEFAULT_BLUR_FLOOR_PX = 2.0
#: Blur accepted relative to the streak width [-]: w' / w <= sqrt(1 + 0.35^2) = 1.06.
DEFAULT_BLUR_RELATIVE = 0.35
#: Typical standard error of the fitted blur-circle diameter [px].
DEFAULT_BLUR_SIGMA_PX = 0.6


def _law_diameter(diameter_m, model: str):
    """Diameters for the law: raised to its smallest tabulated size; beyond its largest the
    law is NaN and the streak is rejected (a drop that looks larger than any raindrop is a
    defocused smaller one)."""
    from raingauge.physics.drops import FALL_VELOCITY_RANGES_M

    lo, _hi = FALL_VELOCITY_RANGES_M.get(model, (0.0, np.inf))
    return np.maximum(diameter_m, max(lo, 1e-5))


def velocity_log_ratio(radius_m, velocity_m_s, *, model: str = "paper", **velocity_kw) -> np.ndarray:
    """r = ln(v / V(2a)): how far a measured (a, v) lies from the law [-].

    Parameters
    ----------
    radius_m : array_like
        Measured drop radius a [m].
    velocity_m_s : array_like
        Measured fall speed v [m/s].
    model : str
        Fall-velocity law (``raingauge.physics.drops.FALL_VELOCITY_MODELS``).

    Returns
    -------
    ndarray
        r [-]; NaN where the law is undefined or v <= 0.
    """
    from raingauge.physics.drops import fall_velocity

    a = np.asarray(radius_m, dtype=float)
    v = np.asarray(velocity_m_s, dtype=float)
    law = fall_velocity(_law_diameter(2.0 * a, model), model=model, **velocity_kw)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((v > 0) & (law > 0), np.log(v / law), np.nan)


def law_log_slope(radius_m, *, model: str = "paper", **velocity_kw) -> np.ndarray:
    """d ln V / d ln a of the velocity law at radius a [-] (0.5 for the paper's law)."""
    from raingauge.physics.drops import fall_velocity

    a = np.asarray(radius_m, dtype=float)
    h = 0.02
    up = fall_velocity(_law_diameter(2.0 * a * math.exp(h), model), model=model, **velocity_kw)
    dn = fall_velocity(_law_diameter(2.0 * a * math.exp(-h), model), model=model, **velocity_kw)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (np.log(up) - np.log(dn)) / (2 * h)
    return np.where(np.isfinite(s), s, 0.5)


def ratio_sigma(radius_m, width_px, motion_px, *, width_sigma_px=DEFAULT_WIDTH_SIGMA_PX,
                motion_sigma_px=DEFAULT_MOTION_SIGMA_PX, model: str = "paper", **velocity_kw) -> np.ndarray:
    """Standard error of r from the width and motion errors [-].

    sigma_r^2 = (sigma_L / L_motion)^2 + (e sigma_w / w)^2, e = d ln V / d ln a.

    Parameters
    ----------
    radius_m : array_like
        Drop radius [m] (for the law's slope).
    width_px, motion_px : array_like
        Streak width and motion [px].
    width_sigma_px, motion_sigma_px : array_like
        Their standard errors [px].
    """
    e = law_log_slope(radius_m, model=model, **velocity_kw)
    w = np.maximum(np.asarray(width_px, dtype=float), 0.3)
    m = np.maximum(np.asarray(motion_px, dtype=float), 1.0)
    return np.sqrt((np.asarray(motion_sigma_px) / m) ** 2 + (e * np.asarray(width_sigma_px) / w) ** 2)


def law_tolerance(radius_m, width_px, motion_px, *, floor: float = DEFAULT_TOLERANCE_FLOOR,
                  k_sigma: float = DEFAULT_K_SIGMA, model: str = "paper", **kw) -> np.ndarray:
    """Tolerance on |r| [-]: sqrt(floor^2 + (k sigma_r)^2) with sigma_r of :func:`ratio_sigma`.

    The error model is the typical one (``DEFAULT_WIDTH_SIGMA_PX``,
    ``DEFAULT_MOTION_SIGMA_PX``), so the tolerance is a function of the
    streak's size alone and the sample volume can be computed for it.
    """
    sig = ratio_sigma(radius_m, width_px, motion_px, model=model, **kw)
    return np.sqrt(floor ** 2 + (k_sigma * sig) ** 2)


def passes_velocity_law(radius_m, velocity_m_s, width_px, motion_px, *, model: str = "paper",
                        floor: float = DEFAULT_TOLERANCE_FLOOR, k_sigma: float = DEFAULT_K_SIGMA,
                        **velocity_kw) -> np.ndarray:
    """True where the measured (a, v) agrees with the law within :func:`law_tolerance`.

    Parameters
    ----------
    radius_m : array_like
        Apparent radius a' = w' z0 / (2 f) [m] (blur included).
    velocity_m_s : array_like
        Apparent fall speed v' [m/s] at z0.
    width_px, motion_px : array_like
        The streak's apparent width and vertical motion [px].
    model : str
        Fall-velocity law.

    Returns
    -------
    bool ndarray
    """
    r = velocity_log_ratio(radius_m, velocity_m_s, model=model, **velocity_kw)
    tol = law_tolerance(radius_m, width_px, motion_px, floor=floor, k_sigma=k_sigma, model=model,
                        **velocity_kw)
    return np.isfinite(r) & (np.abs(r) <= tol)


def max_blur_px(width_px, *, floor_px: float = DEFAULT_BLUR_FLOOR_PX,
                relative: float = DEFAULT_BLUR_RELATIVE) -> np.ndarray:
    """Largest defocus blur a focused streak may show [px]: max(floor, relative * w).

    Parameters
    ----------
    width_px : array_like
        Focused streak width w [px].
    """
    return np.maximum(floor_px, relative * np.asarray(width_px, dtype=float))


def passes_blur(blur_px, width_px, *, floor_px: float = DEFAULT_BLUR_FLOOR_PX,
                relative: float = DEFAULT_BLUR_RELATIVE) -> np.ndarray:
    """True where the fitted blur circle is within :func:`max_blur_px` (the focus half of the test).

    The velocity law alone lets through drops nearer than z0 whose
    perspective enlargement offsets their blur; bounding the blur closes that
    gap so the accepted drops are sharp and their sizes need little correction.
    """
    b = np.asarray(blur_px, dtype=float)
    return np.isfinite(b) & (b <= max_blur_px(width_px, floor_px=floor_px, relative=relative))


#: Smallest photometric focus q = (w / w')^2 accepted (the blur is then under 0.29 w).
DEFAULT_Q_MIN = 0.6
#: Relative standard error of a streak's total signal [-].
DEFAULT_SIGNAL_REL_SIGMA = 0.06


def exposure_area_px2(plateau, motion_px, width_px) -> np.ndarray:
    """Total change of a uniform streak, Q = P (L_m + pi w' / 4) [gray levels px^2].

    A uniform streak (Eqs. 17, 23) is a capsule of width w' around a motion
    L_m with the constant change beta (E_r - E_b), beta = pi a_i^2 / A_capsule;
    its row sums have the plateau P = beta (E_r - E_b) w', so the total
    change is P A_capsule / w' = pi a_i^2 (E_r - E_b): the drop's own image area
    times its contrast, whatever the defocus.

    Parameters
    ----------
    plateau : array_like
        Row-sum plateau P [gray levels px].
    motion_px : array_like
        Motion L_m [px].
    width_px : array_like
        Apparent width w' [px].
    """
    return np.asarray(plateau) * (np.asarray(motion_px) + math.pi * np.asarray(width_px) / 4.0)


def photometric_focus(total_change, width_px, contrast_dn) -> np.ndarray:
    """q = (2 a_i / w')^2 = 4 Q / (pi C w'^2): how much of the streak's width is the drop's own.

    With the uniform spreading of Eq. (24) [GargNayar2007] a defocused drop's
    change is the focused one times w / (w + b_c); its total change Q is the
    drop's image area times the contrast C = E_r - E_b, so the focused width
    is 2 a_i = 2 sqrt(Q / (pi C)) and q = 1 in focus, (w / (w + b_c))^2 out of it.

    Parameters
    ----------
    total_change : array_like
        Q [gray levels px^2] (:func:`exposure_area_px2`).
    width_px : array_like
        Apparent width w' [px].
    contrast_dn : array_like
        Drop contrast C = E_r - E_b [gray levels] (estimated from the sharpest drops).
    """
    w = np.maximum(np.asarray(width_px, dtype=float), 1e-3)
    c = np.asarray(contrast_dn, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(c > 0, 4.0 * np.asarray(total_change) / (math.pi * c * w * w), np.nan)


def q_sigma(q, width_px, *, width_sigma_px: float = DEFAULT_WIDTH_SIGMA_PX,
            signal_rel_sigma: float = DEFAULT_SIGNAL_REL_SIGMA) -> np.ndarray:
    """Standard error of q from the errors of the total change and of the width [-]."""
    w = np.maximum(np.asarray(width_px, dtype=float), 0.3)
    return np.maximum(np.asarray(q) * np.sqrt(signal_rel_sigma ** 2 + (2 * width_sigma_px / w) ** 2), 1e-3)
