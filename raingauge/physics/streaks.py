"""Photometry of motion-blurred rain streaks: Eqs. (15)-(18) and (29) [GargNayar2007].

A drop passing over a pixel during an exposure of length T covers it for a
time tau << T.  The pixel integrates the drop's irradiance for tau and the
background's for T - tau, so the change it records is linear in the
background intensity with slope -beta = -tau / T (Eq. 18).  Appendix 10.2
bounds tau by 4 a / v, which with v = 200 sqrt(a) and a <= 3.5 mm gives
tau < 1.18 ms and, at T = 30 ms, beta < 0.039.

Times in seconds, irradiances in any consistent unit (the intensity is then
irradiance x seconds), image sizes in pixels.
"""

from __future__ import annotations

import math

import numpy as np

from raingauge.physics._checks import positive
from raingauge.physics.drops import fall_velocity

#: the paper's largest drop radius [m] (Appendix 10.2)
A_MAX_M = 3.5e-3


def exposure_intensity(times_s, irradiance) -> float | np.ndarray:
    """Eq. (15): the intensity a pixel records, I = integral of E(t) dt over the exposure.

    Parameters
    ----------
    times_s : array_like, shape (K,)
        Increasing sample times spanning the exposure [0, T] [s].
    irradiance : array_like, shape (..., K)
        Irradiance at the pixel at those times (drop or background) [irradiance unit, e.g. gray levels s^-1].

    Returns
    -------
    float or ndarray
        Intensity [irradiance x s] (trapezoidal rule).
    """
    t = np.asarray(times_s, dtype=float)
    e = np.asarray(irradiance, dtype=float)
    return np.trapezoid(e, t, axis=-1)


def motion_blurred_intensity(tau_s, exposure_s, e_drop_mean, e_background):
    """Eq. (16): I_r = tau E_r + (T - tau) E_b.

    Parameters
    ----------
    tau_s : array_like
        Time the drop covers the pixel tau [s] (0 <= tau <= T).
    exposure_s : float
        Exposure time T [s].
    e_drop_mean : array_like
        Time-averaged irradiance due to the drop E_r-bar [irradiance unit].
    e_background : array_like
        Background irradiance E_b (constant over the exposure) [irradiance unit].

    Returns
    -------
    ndarray
        I_r [irradiance unit x s].
    """
    tau = np.asarray(tau_s, dtype=float)
    _check_tau(tau, exposure_s)
    return tau * np.asarray(e_drop_mean, dtype=float) + (exposure_s - tau) * np.asarray(e_background, dtype=float)


def delta_intensity(tau_s, e_drop_mean, e_background):
    """Eq. (17): dI = I_r - I_b = tau (E_r - E_b).

    Parameters
    ----------
    tau_s : array_like
        Time the drop covers the pixel [s].
    e_drop_mean, e_background : array_like
        Drop and background irradiance [irradiance unit].
    """
    return np.asarray(tau_s, dtype=float) * (np.asarray(e_drop_mean, dtype=float)
                                             - np.asarray(e_background, dtype=float))


def beta(tau_s, exposure_s):
    """Eq. (18): slope beta = tau / T [-].

    Parameters
    ----------
    tau_s : array_like
        Time the drop covers the pixel [s].
    exposure_s : float
        Exposure time T [s].
    """
    return np.asarray(tau_s, dtype=float) / positive("exposure_s", exposure_s)


def alpha(tau_s, e_drop_mean):
    """Eq. (18): intercept alpha = tau E_r-bar [intensity].

    Parameters
    ----------
    tau_s : array_like
        Time the drop covers the pixel [s].
    e_drop_mean : array_like
        Time-averaged drop irradiance [irradiance unit].
    """
    return np.asarray(tau_s, dtype=float) * np.asarray(e_drop_mean, dtype=float)


def delta_from_background(i_background, *, beta: float, alpha: float):
    """Eq. (18): dI = -beta I_b + alpha, the linear photometric constraint of a streak.

    Parameters
    ----------
    i_background : array_like
        Background intensity I_b = E_b T at the streak's pixels [intensity, irradiance unit x s].
    beta : float
        Slope tau / T [-].
    alpha : float
        Intercept tau E_r-bar [intensity].
    """
    return -beta * np.asarray(i_background, dtype=float) + alpha


def tau_pixel_s(radius_px, rho_px, speed_px_s):
    """Eq. (29): time a drop's image covers a pixel, tau = (2 sqrt(a_i^2 - rho_i^2) + 1) / v_i [s].

    Parameters
    ----------
    radius_px : array_like
        Image radius of the drop a_i = f a / z [px].
    rho_px : array_like
        Distance of the pixel centre from the drop's path rho_i [px] (0 <= rho_i <= a_i).
    speed_px_s : array_like
        Image speed of the drop v_i = f v / z [px/s].

    Returns
    -------
    ndarray
        tau [s].  For rho_i > a_i the chord term is taken as 0 (the drop only
        grazes the pixel), leaving 1 / v_i.

    Notes
    -----
    The pixel is one unit wide: the drop covers it from the moment its
    leading edge enters until its trailing edge leaves, a path of the chord
    AB = 2 sqrt(a_i^2 - rho_i^2) plus one pixel.
    """
    a = np.asarray(radius_px, dtype=float)
    r = np.asarray(rho_px, dtype=float)
    v = np.asarray(speed_px_s, dtype=float)
    chord = 2.0 * np.sqrt(np.maximum(a * a - r * r, 0.0))
    return (chord + 1.0) / v


def tau_bound_s(radius_m, velocity_m_s):
    """Appendix 10.2 bound on Eq. (29): tau < 4 a / v [s] for drops imaged wider than a pixel.

    Since 2 a_i > 1, (2 a_i + 1) / v_i < 4 a_i / v_i = 4 a / v, independent of
    the distance and the focal length.

    Parameters
    ----------
    radius_m : array_like
        Drop radius a [m].
    velocity_m_s : array_like
        Fall speed v [m/s].
    """
    return 4.0 * np.asarray(radius_m, dtype=float) / np.asarray(velocity_m_s, dtype=float)


def tau_max_s(radius_m: float = A_MAX_M, velocity_model: str = "paper", **velocity_kw) -> float:
    """Largest time a drop covers a pixel, tau_max = 4 a / v(a) [s] (Appendix 10.2 [GargNayar2007]).

    Parameters
    ----------
    radius_m : float
        Largest drop radius a_max [m] (default the paper's 3.5 mm).
    velocity_model : str
        A fall-velocity model of :func:`raingauge.physics.drops.fall_velocity` [-].

    Returns
    -------
    float
        tau_max [s]: 1.18 ms for the paper's v = 200 sqrt(a) and a = 3.5 mm
        (= sqrt(a) / 50).

    Notes
    -----
    The bound is taken at the largest drop: under every velocity law
    4 a / v(a) grows with a above a ~ 0.4 mm (v grows more slowly than a),
    and no smaller drop reaches the value at a_max.  With a measured
    law the bound is larger (slower large drops): 1.18 ms is the paper's
    figure, not a law of nature.
    """
    v = float(fall_velocity(2.0 * radius_m, velocity_model, **velocity_kw))
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"velocity model {velocity_model!r} is undefined for a radius of "
                         f"{radius_m * 1e3:g} mm; choose a radius in the model's range")
    return 4.0 * radius_m / v


def beta_max(exposure_s: float, *, radius_m: float = A_MAX_M, velocity_model: str = "paper",
             **velocity_kw) -> float:
    """Upper bound of the photometric slope, beta_max = tau_max / T (Sec. 4.3 [GargNayar2007]).

    Parameters
    ----------
    exposure_s : float
        Exposure time T [s].
    radius_m : float
        Largest drop radius [m].
    velocity_model : str
        Fall-velocity model for tau_max [-].

    Returns
    -------
    float
        beta_max [-]; 0.039 at T = 30 ms with the paper's velocity law.

    Notes
    -----
    The paper quotes beta < 0.039 "for T = 30 ms" while calling 1/30 s the
    typical exposure; 1.18 ms / 33.3 ms would give 0.035.  In general the
    bound scales as 1/T.
    """
    t = positive("exposure_s", exposure_s)
    return tau_max_s(radius_m, velocity_model, **velocity_kw) / t


def _check_tau(tau: np.ndarray, exposure_s: float) -> None:
    positive("exposure_s", exposure_s)
    if np.any(tau < 0) or np.any(tau > exposure_s):
        raise ValueError("tau_s must lie in [0, exposure_s]: a drop cannot cover a pixel "
                         "for longer than the exposure")
