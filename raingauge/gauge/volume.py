"""The gauge's sample volume, per drop size, from the camera profile (Sec. 8).

A drop of radius a at depth z, measured at the focus distance z0 (Sec. 8
[GargNayar2007]), shows an apparent width w' = sqrt(w^2 + b^2) with
w = 2 f a / z (Eq. 26 as corrected) and b the thin-lens blur circle
(``raingauge.physics.camera.blur_circle_px``; a pillbox of diameter b has
the variance b^2/16 across the streak, the same as a disc's chord of diameter
b), and an apparent speed v' = V(a) z0 / z.  Its streak changes each pixel by
A = beta (E_r - E_b) (Eqs. 17, 23-24), which sets whether Eq. (19) detects
it, whether it can be measured at all, and the errors of its width and
length (:func:`raingauge.gauge.rejection.streak_errors_px`, the same errors
the gauge gives each measured streak).  The defocus test of
:mod:`raingauge.gauge.rejection` then accepts it with probability

    P(a, z) = P_det P_size [Phi((tol - r) / s) - Phi((-tol - r) / s)] P_focus,
    r = ln(v' / V(a')),

tol the tolerance of the streak's own errors and s the standard error of r.
Each depth slab dz holds, per pixel of the image, (z / f)^2 dz of space, so
the gauge samples

    kappa(a; C, sigma) = int P(a, z) (z / f)^2 dz        [m^3 per px^2 of image]

for a drop contrast C = E_r - E_b and a noise sigma (the sensor's plus the
flicker of the undetected rain, Eq. 27).  A frame whose backgrounds vary
samples each size in the mean of kappa over its pixels' contrasts
(:meth:`SampleVolume.kappa` with :meth:`SampleVolume.histogram_weights`):
sizes visible over part of the frame are counted up by that part, and the
sizes visible nowhere are reported as missing
(:meth:`SampleVolume.hidden_share`).

and the volume imaged by the whole frame is kappa(a) times the frame's area
in pixels, less the border in which a streak is cut by the edge (edge
clipping: a streak w + |dx| wide and w + |dy| tall is whole only when it
starts inside a (N - w - |dx|) x (M - w - |dy|) rectangle).

Counting each drop once over consecutive frames (flux counting), a drop whose
streak moves (u_x, u_y) px/s is counted if it is whole in at least one frame;
the expected count per second per unit of image density is
:func:`effective_area_rate_px2_s`, from the identity
int min(d, chord) = |R| - |R intersect (R + d)| for a convex region R.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from raingauge.gauge._numeric import clip as _clip
from raingauge.gauge.rejection import (
    DEFAULT_BLUR_FLOOR_PX,
    DEFAULT_BLUR_RELATIVE,
    DEFAULT_BLUR_SIGMA_PX,
    DEFAULT_K_SIGMA,
    DEFAULT_Q_MIN,
    DEFAULT_TOLERANCE_FLOOR,
    detection_margin,
    detection_probability,
    law_tolerance,
    max_blur_px,
    q_sigma,
    ratio_sigma,
    row_snr,
    signal_rel_sigma,
    sizing_probability,
    streak_change_dn,
    streak_errors_px,
    velocity_log_ratio,
)

__all__ = [
    "DETECTION_GROW",
    "SampleVolume",
    "pass_probability",
    "effective_area_rate_px2_s",
    "whole_streak_area_px2",
    "EDGE_MARGIN_PX",
    "DEFOCUS_MODELS",
    "DEFAULT_CONTRAST_DN",
    "BACKGROUND_BIN_DN",
    "background_histogram",
]

#: How defocus widens a streak (see :func:`pass_probability`).
DEFOCUS_MODELS = ("uniform", "pillbox")

#: Hysteresis of the gauge's streak detection: a streak grows along the fall from its
#: pixels at the threshold c into the ones at this fraction of c [-].
DETECTION_GROW = 0.5

#: Streaks closer than this to the frame edge count as clipped [px].
EDGE_MARGIN_PX = 2.0

#: Drop contrast E_r - E_b assumed when none is given [gray levels]: an overcast sky seen
#: through the drop (E_r ~ 200, Sec. 4.2.3) over a dark background (~40).
DEFAULT_CONTRAST_DN = 160.0


#: Width of the bins of the background histogram [gray levels].
BACKGROUND_BIN_DN = 4.0


def background_histogram(frame, *, step: int = 8, n_bins: int = 64) -> np.ndarray:
    """Histogram of a frame's background levels E_b, every ``step``-th pixel [counts].

    Parameters
    ----------
    frame : (M, N) array
        Linearised frame [gray levels] (a neighbour of the analysed one: no streaks of its own there),
        or the 8-bit frame of a linear camera.
    step : int
        Sub-sampling [px].
    n_bins : int
        Bins of :data:`BACKGROUND_BIN_DN` from 0 (levels above the last bin go into it).

    Returns
    -------
    (n_bins,) int ndarray
    """
    sub = np.asarray(frame)[::step, ::step].ravel()
    if sub.dtype.kind in "ui":
        # the 8-bit codes of a linear camera, as linearised
        sub = sub.astype(np.float32)
    k = _clip((sub / BACKGROUND_BIN_DN).astype(np.int64), 0, n_bins - 1)
    return np.bincount(k, minlength=n_bins)


#: Every how many of the 400 depths of a radius the pass probability is kept for
#: :meth:`SampleVolume.pass_probability_at` [-].
P_TABLE_STRIDE = 4

#: Step of the winds the sample volume is built at [m/s] (:meth:`SampleVolume.in_wind`):
#: between two steps its quantities are taken linear in the wind.
WIND_STEP_M_S = 0.5


def _pitch(profile) -> float:
    return profile.pixel_pitch_m if profile.pixel_pitch_m else 5e-6


def _default_threshold(profile, noise_sigma_dn: float) -> float:
    """c of Eq. (19) as the gauge uses it: the profile's, raised to 1.2 sigma of the noise."""
    return float(max(profile.detection_threshold_dn, 1.2 * noise_sigma_dn))


def pass_probability(radius_m: float, z_m, profile, *, velocity_model: str = "paper",
                     rain_velocity_model: str | None = None, floor: float = DEFAULT_TOLERANCE_FLOOR,
                     k_sigma: float = DEFAULT_K_SIGMA, width_sigma_px=None, motion_sigma_px=None,
                     blur_variance_factor: float = 1.0,
                     blur_floor_px: float = DEFAULT_BLUR_FLOOR_PX, blur_relative: float = DEFAULT_BLUR_RELATIVE,
                     blur_sigma_px: float = DEFAULT_BLUR_SIGMA_PX, defocus_model: str = "uniform",
                     q_min: float = DEFAULT_Q_MIN, contrast_dn=DEFAULT_CONTRAST_DN,
                     noise_sigma_dn: float | None = None, detection_threshold_dn: float | None = None,
                     smooth_px: int = 5, grow: float = DETECTION_GROW, slant_cos=1.0) -> dict:
    """Probability that a drop of radius a at depth z is detected and passes the defocus test.

    P = P_det P_size P_law P_focus: the detection of Eq. (19) for the streak's change
    beta (E_r - E_b) (:func:`raingauge.gauge.rejection.detection_probability`), the
    chance that a streak of about one pixel is measured at all
    (:func:`raingauge.gauge.rejection.sizing_probability`),
    the velocity law with the tolerance of the streak's own errors
    (:func:`raingauge.gauge.rejection.streak_errors_px`, the same function the
    gauge applies to each measured streak), and the focus test.

    Parameters
    ----------
    radius_m : float
        True drop radius a [m].
    z_m : array_like
        Depths [m].
    profile : CameraProfile
    velocity_model : str
        The law the gauge tests against.
    rain_velocity_model : str, optional
        The law the drops follow (default: the same).
    floor, k_sigma :
        The velocity test's tolerance (see :mod:`raingauge.gauge.rejection`).
    width_sigma_px, motion_sigma_px : float, optional
        Fixed measurement errors [px]; default: each streak's own, from its
        expected signal against ``noise_sigma_dn``.
    blur_floor_px, blur_relative, blur_sigma_px :
        The blur test: b <= max(floor, relative w), fitted with this standard error
        (``"pillbox"`` only).
    defocus_model : str
        ``"uniform"``: the paper's Eqs. (23)-(24), the drop's change spread
        evenly over a streak w + b wide (w' = w + b; edges stay sharp): the
        velocity law and the photometric focus q = (w / w')^2 >= ``q_min``
        reject defocus (:func:`raingauge.gauge.rejection.photometric_focus`).  ``"pillbox"``: convolution with
        the blur circle (w'^2 = w^2 + factor b^2, soft edges, the blur test applies).
    blur_variance_factor : float
        w'^2 = w^2 + factor b^2 (1 for a pillbox blur) [-].
    contrast_dn : array_like
        E_r - E_b, the drop's brightness over the background [gray levels]
        (broadcast against ``z_m``); ``inf`` assumes every streak detected.
    noise_sigma_dn : array_like, optional
        Noise of one frame [gray levels] (default the profile's; broadcast against ``z_m``).
        In rain the faint defocused drops add their flicker (Eq. 27): pass the measured
        noise of the change image over sqrt(1.5).
    detection_threshold_dn : float, optional
        c of Eq. (19) [gray levels] (default the gauge's: the profile's, at least 1.2 sigma
        of the profile's noise).
    smooth_px : int
        Rows of the along-fall smoothing before detection.
    grow : float
        Hysteresis of the detection (:func:`raingauge.gauge.streaks.detect_streaks`): a
        streak is found where it reaches c and measured over where it reaches grow c.
    slant_cos : array_like
        cos(theta) of a streak slanted by a cross wind (:meth:`SampleVolume.wind_dimming`;
        1: falling straight down) [-].  The drop crosses each pixel in cos(theta) of the
        time, so the detection's per-pixel tests (Eq. 19 and the hysteresis that sets the
        streak's extent) see the change cos(theta) beta (E_r - E_b).  The measurement works
        on row sums across the streak: a slanted row holds the same signal over
        1 / cos(theta) as many pixels, so the widths, ends and total change are measured as
        those of an upright streak whose change is sqrt(cos(theta)) of it.

    Returns
    -------
    dict of arrays over ``z_m`` (broadcast with ``contrast_dn``): ``p`` (probability),
    ``p_law`` (the same without the focus test: detected, measured and on the velocity law),
    ``p_detect``, ``apparent_radius_m``, ``apparent_velocity_m_s``, ``width_px``, ``blur_px``,
    ``motion_px``, ``change_dn`` (the streak's change per pixel), ``q`` (the photometric
    focus (2 a_i / w')^2) and ``q_sigma`` (its standard error; NaN for ``"pillbox"``).
    """
    from raingauge.physics.camera import blur_circle_px
    from raingauge.physics.drops import fall_velocity
    from scipy.special import ndtr

    z = np.asarray(z_m, dtype=float)
    f = profile.focal_length_px
    z0 = profile.focus_distance_m
    if defocus_model not in DEFOCUS_MODELS:
        raise ValueError(f"unknown defocus model {defocus_model!r}; valid: {list(DEFOCUS_MODELS)}")
    noise = np.asarray(profile.noise_sigma_dn if noise_sigma_dn is None else noise_sigma_dn, dtype=float)
    c = (_default_threshold(profile, float(profile.noise_sigma_dn)) if detection_threshold_dn is None
         else float(detection_threshold_dn))
    noise_change = np.maximum(noise, 0.5) * math.sqrt(1.5)
    contrast = np.asarray(contrast_dn, dtype=float)
    a_img = f * radius_m / z
    w = np.maximum(2.0 * a_img, 1.0)
    b = blur_circle_px(z, focal_length_px=f, f_number=profile.f_number, focus_distance_m=z0,
                       pixel_pitch_m=_pitch(profile))
    if defocus_model == "uniform":
        w_app = w + b
    else:
        w_app = np.sqrt(w * w + blur_variance_factor * b * b)
    a_app = w_app * z0 / (2.0 * f)
    v_true = float(fall_velocity(2.0 * radius_m, model=rain_velocity_model or velocity_model))
    v_app = v_true * z0 / z
    motion = f * v_true * profile.exposure_s / z
    finite_c = np.isfinite(contrast)
    change = streak_change_dn(a_img, w_app, motion, np.where(finite_c, contrast, 1e6))
    slant = np.asarray(slant_cos, dtype=float)
    # (the detection's per-pixel change, and the change of the upright streak measured alike)
    change_det = change * slant
    change = change * np.sqrt(slant)
    plateau = change * w_app
    if width_sigma_px is None or motion_sigma_px is None:
        sw, sl = streak_errors_px(w_app, motion, plateau, noise_change)
        sw = sw if width_sigma_px is None else np.broadcast_to(width_sigma_px, sw.shape)
        sl = sl if motion_sigma_px is None else np.broadcast_to(motion_sigma_px, sl.shape)
    else:
        sw = np.broadcast_to(np.asarray(width_sigma_px, dtype=float), np.broadcast(z, contrast).shape)
        sl = np.broadcast_to(np.asarray(motion_sigma_px, dtype=float), sw.shape)
    r = velocity_log_ratio(a_app, v_app, model=velocity_model)
    tol = law_tolerance(a_app, w_app, motion, floor=floor, k_sigma=k_sigma, model=velocity_model,
                        width_sigma_px=sw, motion_sigma_px=sl)
    sig = ratio_sigma(a_app, w_app, motion, width_sigma_px=sw, motion_sigma_px=sl, model=velocity_model)
    sig = np.maximum(sig, 1e-6)
    with np.errstate(invalid="ignore"):
        p = np.where(np.isfinite(r) & np.isfinite(sig), ndtr((tol - r) / sig) - ndtr((-tol - r) / sig), 0.0)
    p_law = p
    if defocus_model == "pillbox":
        bmax = max_blur_px(w, floor_px=blur_floor_px, relative=blur_relative)
        p = p * ndtr((bmax - np.sqrt(blur_variance_factor) * b) / blur_sigma_px)
        q = s_q = np.full(np.shape(p), np.nan)
    else:
        q = (2.0 * a_img / w_app) ** 2
        rel = signal_rel_sigma(w_app, motion, plateau, noise_change)
        s_q = q_sigma(q, w_app, width_sigma_px=np.where(np.isfinite(sw), sw, 1.0),
                      signal_rel_sigma=np.where(np.isfinite(rel), rel, 1.0))
        with np.errstate(invalid="ignore"):
            p = p * np.where(np.isfinite(sw) & np.isfinite(rel), ndtr((q - q_min) / s_q), 0.0)
            s_q = np.where(np.isfinite(sw) & np.isfinite(rel), s_q, np.nan)
    p_det = np.where(finite_c, detection_probability(change_det, w_app, threshold_dn=c, noise_sigma_dn=noise,
                                                     smooth_px=smooth_px, length_px=motion + w_app), 1.0)
    # the streak's extent is taken at the hysteresis threshold grow c (detect_streaks)
    margin = np.where(finite_c, detection_margin(change_det, w_app, threshold_dn=grow * c, noise_sigma_dn=noise,
                                                 smooth_px=smooth_px), np.inf)
    p_size = sizing_probability(2.0 * a_img, margin, np.where(finite_c, row_snr(change, w_app, noise_change), np.inf))
    p = p * p_det * p_size
    p_law = p_law * p_det * p_size
    if not np.isfinite(v_true):
        p = np.zeros_like(p)
        p_law = np.zeros_like(p_law)
    return {"p": p, "p_law": p_law, "p_detect": p_det, "apparent_radius_m": a_app,
            "apparent_velocity_m_s": v_app, "width_px": w, "blur_px": b, "motion_px": motion,
            "change_dn": change_det, "q": q, "q_sigma": s_q}


#: Percentile of the law-abiding streaks' brightness samples that estimates E_r [%].
BRIGHTNESS_PERCENTILE = 75.0

#: Narrowest streak whose brightness sample is used [px] (narrower ones are mostly noise).
BRIGHTNESS_MIN_WIDTH_PX = 2.5

#: Rain rate of the Marshall-Palmer size prior of :attr:`SampleVolume.brightness_q` [mm/h];
#: also the least rate of the prior of :meth:`SampleVolume.brightness_q_population_factor`.
BRIGHTNESS_PRIOR_RATE_MM_H = 10.0

#: The greatest rate of the prior of :meth:`SampleVolume.brightness_q_population_factor` [mm/h].
BRIGHTNESS_PRIOR_MAX_MM_H = 200.0


#: Range of the contrasts of :meth:`SampleVolume.brightness_q_at`, in half octaves about
#: the volume's ``contrast_dn`` (beyond it the nearest end holds) [-].
BRIGHTNESS_Q_NODES = (-8, 2)


def _brightness_parts(res, z, f: float, z0: float) -> tuple:
    """(law-abiding weight over z [m^3/px^2], q(z), sigma_q(z)), each (n_noises, n_z), of one
    radius from :func:`pass_probability` at one contrast: the input of
    :func:`_brightness_percentile_q` (streaks narrower than :data:`BRIGHTNESS_MIN_WIDTH_PX`
    give no brightness sample)."""
    shp = np.broadcast_shapes(*(np.shape(res[k]) for k in ("p_law", "q", "q_sigma", "apparent_radius_m")),
                              np.shape(z))
    dz = z[1] - z[0]
    w_app_z = np.broadcast_to(res["apparent_radius_m"], shp) * 2.0 * f / z0
    law = np.broadcast_to(res["p_law"], shp) * (z / f) ** 2 * dz
    return (np.where(w_app_z >= BRIGHTNESS_MIN_WIDTH_PX, law, 0.0), np.broadcast_to(res["q"], shp),
            np.broadcast_to(res["q_sigma"], shp))


#: The grid of q' of the contrast nodes of :meth:`SampleVolume.brightness_q_at` [-].
_Q_GRID_COARSE = np.linspace(0.0, 2.0, 201)


def _brightness_percentile_q(parts, q_min: float, *, percentile: float = BRIGHTNESS_PERCENTILE,
                             y: np.ndarray | None = None, flat_between=None,
                             prior_rate_mm_h: float | None = None) -> float:
    """The fixed point m = P{ q' : q' >= q_min m } of the model's measured focus q' [-].

    ``parts``: (radius a [m], law-abiding weight over z [m^3/px^2], q(z), sigma_q(z)) per
    radius of the grid; the sizes are weighted by a Marshall-Palmer prior of
    ``prior_rate_mm_h`` (default :data:`BRIGHTNESS_PRIOR_RATE_MM_H`), or, with
    ``flat_between`` = (lo, hi) [m], uniformly in log a between those radii; each depth's
    q' is normal about q(z) with its standard error.
    """
    from raingauge.physics.drops import MarshallPalmer

    radii = np.array([p[0] for p in parts])
    if flat_between is None:
        rate = BRIGHTNESS_PRIOR_RATE_MM_H if prior_rate_mm_h is None else float(prior_rate_mm_h)
        prior = MarshallPalmer(rate).number_density(2.0 * radii)
    else:
        prior = ((radii >= flat_between[0]) & (radii <= flat_between[1])) / radii
    # the radius grid is log-spaced: da is proportional to a
    size_w = prior * radii
    y = np.linspace(0.0, 2.0, 801) if y is None else y
    dens = np.zeros_like(y)
    for (a, wt, q, sq), sw in zip(parts, size_w):
        ok = (wt > 0) & np.isfinite(q) & np.isfinite(sq) & (sq > 0)
        if not ok.any() or not sw > 0:
            continue
        w_, q_, s_ = wt[ok] * sw, q[ok], sq[ok]
        dens += (w_ / s_) @ np.exp(-0.5 * ((y[None, :] - q_[:, None]) / s_[:, None]) ** 2)
    if not dens.sum() > 0:
        return 1.0
    m = 1.0
    for _ in range(50):
        keep = np.where(y >= q_min * m, dens, 0.0)
        cdf = np.cumsum(keep)
        if not cdf[-1] > 0:
            break
        m_new = float(np.interp(percentile / 100.0, cdf / cdf[-1], y))
        if abs(m_new - m) < 1e-4:
            m = m_new
            break
        m = m_new
    return m


def whole_streak_area_px2(motion_px, width_px, shape, *, margin_px: float = EDGE_MARGIN_PX) -> np.ndarray:
    """Area of the start positions from which a streak lies whole in the frame [px^2].

    (N - w - |dx| - 2 m)+ (M - w - |dy| - 2 m)+ for a frame of shape (M, N).

    Parameters
    ----------
    motion_px : (..., 2) array_like
        Streak motion (dx, dy) during the exposure [px].
    width_px : array_like
        Streak width w [px].
    shape : (M, N)
        Frame shape [px].
    margin_px : float
        Border within which a streak counts as clipped [px].
    """
    mot = np.asarray(motion_px, dtype=float)
    w = np.asarray(width_px, dtype=float)
    M, N = shape
    wr = _clip(N - w - np.abs(mot[..., 0]) - 2 * margin_px, 0, None)
    hr = _clip(M - w - np.abs(mot[..., 1]) - 2 * margin_px, 0, None)
    return wr * hr


def effective_area_rate_px2_s(motion_px, width_px, shape, *, exposure_s: float, frame_interval_s: float,
                              margin_px: float = EDGE_MARGIN_PX) -> np.ndarray:
    """Rate at which distinct drops are counted per unit image density [px^2/s].

    A drop moving (dx, dy) px per exposure T moves d = (dx, dy) Delta/T between
    frames; it is counted once if its streak is whole in at least one frame.
    With R the W_R x H_R rectangle of whole-streak start positions
    (:func:`whole_streak_area_px2`), the expected count per second is
    density x [W_R H_R - (W_R - |d_x|)+ (H_R - |d_y|)+] / Delta: every drop
    crossing R when the frames are close enough, W_R H_R / Delta (the
    snapshot rate) when a drop jumps past R between frames.

    Parameters
    ----------
    motion_px : (..., 2) array_like
        Streak motion (dx, dy) during the exposure [px].
    width_px : array_like
        Streak width [px].
    shape : (M, N)
        Frame shape [px].
    exposure_s : float
        Exposure T [s].
    frame_interval_s : float
        Frame interval Delta [s].

    Returns
    -------
    ndarray [px^2/s]
    """
    mot = np.asarray(motion_px, dtype=float)
    w = np.asarray(width_px, dtype=float)
    M, N = shape
    wr = _clip(N - w - np.abs(mot[..., 0]) - 2 * margin_px, 0, None)
    hr = _clip(M - w - np.abs(mot[..., 1]) - 2 * margin_px, 0, None)
    scale = frame_interval_s / exposure_s
    dx = np.abs(mot[..., 0]) * scale
    dy = np.abs(mot[..., 1]) * scale
    overlap = _clip(wr - dx, 0, None) * _clip(hr - dy, 0, None)
    return (wr * hr - overlap) / frame_interval_s


@dataclass
class SampleVolume:
    """Sample volume of a camera profile per drop radius and drop contrast (tabulated).

    Parameters
    ----------
    profile : CameraProfile
    velocity_model : str
        The law of the defocus test (and of the drops).
    rain_velocity_model : str, optional
        The law the drops follow when it differs (for studies of a mismatch).
    floor, k_sigma : float
        Tolerance of the test (see :mod:`raingauge.gauge.rejection`).
    blur_variance_factor, defocus_model :
        See :func:`pass_probability`.
    radii_m : array, optional
        Radius grid [m] (default 0.1-4 mm, 60 log-spaced points).
    contrast_dn : float
        The drop contrast E_r - E_b of :meth:`kappa` when none is given [gray levels].
    contrasts_dn : array, optional
        Contrast grid of the table [gray levels] (default 1-255, 16 log-spaced points).
    noise_sigma_dn, detection_threshold_dn : float, optional
        Noise and Eq. (19) threshold c [gray levels] (default: the profile's, as the gauge uses them).
    grow : float
        Hysteresis of the detection (see :func:`pass_probability`) [-].
    noise_factors : array, optional
        Noise grid of the table, in units of ``noise_sigma_dn`` (rain's own flicker raises
        the noise a streak is measured in, Eq. 27 [GargNayar2007]).
    wind_m_s : float
        The drops' drift across the image [m/s]: each size's streak slants by its own
        angle, tan(theta) = u / v(a), and is tabled so (``slant_cos`` of
        :func:`pass_probability`).  The gauge keeps the volume without wind and asks it
        for the wind's (:meth:`in_wind`, the ``wind_m_s`` of :meth:`kappa` and the
        others).

    Attributes
    ----------
    brightness_q : float
        Where the drop brightness estimate of :func:`raingauge.gauge.gauge.drop_brightness_dn`
        falls, as a fraction of E_r - E_b: the percentile
        :data:`BRIGHTNESS_PERCENTILE` of the measured photometric focus q of the
        law-abiding streaks at least :data:`BRIGHTNESS_MIN_WIDTH_PX` wide that pass the focus
        test at that estimate, predicted by this model (the errors of q included) for
        Marshall-Palmer rain of :data:`BRIGHTNESS_PRIOR_RATE_MM_H`, at the profile's noise [-].
    brightness_q_by_noise : ndarray
        The same over ``noises_dn`` (:meth:`brightness_q_at`) [-].
    kappa_cube : ndarray (n_radii, n_noises, n_contrasts)
        kappa(a, sigma, C) [m^3/px^2] over ``noises_dn`` and ``contrasts_dn``.
    kappa_table : ndarray (n_radii, n_contrasts)
        kappa(a, C) [m^3/px^2] at the profile's noise.
    kappa_m3_px2 : ndarray
        kappa(a) [m^3/px^2] on ``radii_m`` at ``contrast_dn``.
    mean_depth_m : ndarray
        Mean depth of the accepted drops, weighted by the sampled space [m].
    depth_span_m : ndarray (n_radii, 2)
        The depths [m] between which a drop passes at all (probability above 1e-3 of its
        best), at any noise and contrast of the table: the depth range kappa integrates.
    apparent_radius_factor : ndarray
        (E[(a'/a)^3 | accepted])^(1/3): how much larger the accepted drops of
        radius a look at z0, the blur included [-].

    Notes
    -----
    Drops are detected only where the background leaves them contrast
    (Eqs. 17-19 [GargNayar2007]): over a frame whose backgrounds E_b vary, a
    drop of radius a is sampled in the mean over the frame's pixels of
    kappa(a, E_r - E_b) (:meth:`contrast_weights`, :meth:`kappa`), so the
    classes still visible over part of the frame are counted up by the part
    they are visible in, not lost.
    """

    profile: object
    velocity_model: str = "paper"
    rain_velocity_model: str | None = None
    floor: float = DEFAULT_TOLERANCE_FLOOR
    k_sigma: float = DEFAULT_K_SIGMA
    blur_variance_factor: float = 1.0
    defocus_model: str = "uniform"
    q_min: float = DEFAULT_Q_MIN
    grow: float = DETECTION_GROW
    radii_m: np.ndarray = field(default_factory=lambda: np.geomspace(0.1e-3, 4.0e-3, 60))
    min_width_px: float = 1.0
    contrast_dn: float = DEFAULT_CONTRAST_DN
    contrasts_dn: np.ndarray = field(default_factory=lambda: np.geomspace(1.0, 255.0, 16))
    noise_sigma_dn: float | None = None
    detection_threshold_dn: float | None = None
    noise_factors: np.ndarray = field(default_factory=lambda: np.array([1.0, 1.4, 2.0, 2.8, 4.0, 5.6]))
    wind_m_s: float = 0.0

    def __post_init__(self):
        from raingauge.physics.camera import blur_circle_px

        prof = self.profile
        z0 = prof.focus_distance_m
        f = prof.focal_length_px
        self.contrasts_dn = np.sort(np.asarray(self.contrasts_dn, dtype=float))
        self.radii_m = np.asarray(self.radii_m, dtype=float)
        cgrid = np.append(self.contrasts_dn, float(self.contrast_dn))
        noise0 = float(prof.noise_sigma_dn if self.noise_sigma_dn is None else self.noise_sigma_dn)
        self.noises_dn = max(noise0, 0.3) * np.sort(np.asarray(self.noise_factors, dtype=float))
        z_all = np.linspace(0.4 * z0, 2.5 * z0, 1600)
        b_all = blur_circle_px(z_all, focal_length_px=f, f_number=prof.f_number, focus_distance_m=z0,
                               pixel_pitch_m=_pitch(prof))
        table, zbar, fac, spans, p_z = [], [], [], [], []
        q_parts = []
        self._q_nodes = {}
        self._q_at_memo = None
        self._bracket_memo = None
        self._q_node_parts = []
        node_c = self.contrast_dn * 2.0 ** (0.5 * np.arange(BRIGHTNESS_Q_NODES[0], BRIGHTNESS_Q_NODES[1] + 1))
        self.wind_m_s = abs(float(self.wind_m_s))
        slants = (self.wind_dimming(self.radii_m, self.wind_m_s) if self.wind_m_s > 0.0
                  else np.ones(self.radii_m.size))
        self._calm = None
        self._windy = {}
        for a, slant in zip(self.radii_m, slants.tolist()):
            # the accepted drops lie where the blur is at most about the width (q >= q_min):
            # integrate over that span, generously widened
            w_all = np.maximum(2.0 * f * a / z_all, 1.0)
            near = np.nonzero(b_all <= 2.0 * w_all + 4.0)[0]
            lo = z_all[max(near[0] - 1, 0)] if near.size else 0.9 * z0
            hi = z_all[min(near[-1] + 1, z_all.size - 1)] if near.size else 1.1 * z0
            z = np.linspace(lo, hi, 400)
            dz = z[1] - z[0]
            res = pass_probability(a, z[None, None, :], prof, velocity_model=self.velocity_model,
                                   rain_velocity_model=self.rain_velocity_model, floor=self.floor,
                                   k_sigma=self.k_sigma, blur_variance_factor=self.blur_variance_factor,
                                   defocus_model=self.defocus_model, q_min=self.q_min,
                                   contrast_dn=cgrid[None, :, None], noise_sigma_dn=self.noises_dn[:, None, None],
                                   detection_threshold_dn=self.detection_threshold_dn, grow=self.grow,
                                   slant_cos=slant)
            wt = res["p"] * (z / f) ** 2 * dz
            k = wt.sum(axis=-1)                                  # (n_noises, n_contrasts + 1)
            # the depths where the drop passes at all, at any noise and contrast of the table
            p_full = np.broadcast_to(res["p"], wt.shape)
            p_z.append((z[::P_TABLE_STRIDE].copy(), p_full[:, :-1, ::P_TABLE_STRIDE].astype(np.float32)))
            p_any = p_full.max(axis=(0, 1))
            on = np.nonzero(p_any > 1e-3 * p_any.max())[0] if p_any.max() > 0 else np.zeros(0, int)
            spans.append((z[max(on[0] - 2, 0)], z[min(on[-1] + 2, z.size - 1)]) if on.size else (z0, z0))
            if self.defocus_model == "uniform":
                # at the nominal contrast (the table's last column)
                nominal = {key: np.broadcast_to(res[key], res["p"].shape)[:, -1]
                           for key in ("apparent_radius_m", "p_law", "q", "q_sigma")}
                q_parts.append((a,) + _brightness_parts(nominal, z, f, z0))
                # and at the contrasts of brightness_q_at's nodes, every few depths (kept for
                # the fixed points computed when first needed)
                zs = z[::P_TABLE_STRIDE]
                res_n = pass_probability(a, zs[None, None, :], prof, velocity_model=self.velocity_model,
                                         rain_velocity_model=self.rain_velocity_model, floor=self.floor,
                                         k_sigma=self.k_sigma, blur_variance_factor=self.blur_variance_factor,
                                         defocus_model=self.defocus_model, q_min=self.q_min,
                                         contrast_dn=node_c[None, :, None],
                                         noise_sigma_dn=self.noises_dn[:, None, None],
                                         detection_threshold_dn=self.detection_threshold_dn, grow=self.grow,
                                         slant_cos=slant)
                self._q_node_parts.append((a,) + tuple(x.astype(np.float32)
                                                       for x in _brightness_parts(res_n, zs, f, z0)))
            table.append(k)
            kd, wd = float(k[0, -1]), wt[0, -1]
            if kd > 0:
                zbar.append(float((wd * z).sum() / kd))
                a_app = np.broadcast_to(res["apparent_radius_m"], wt.shape)[0, -1]
                fac.append(float(((wd * (a_app / a) ** 3).sum() / kd) ** (1 / 3)))
            else:
                zbar.append(z0)
                fac.append(1.0)
        full = np.array(table)
        self.kappa_cube = full[:, :, :-1]
        self.kappa_table = full[:, 0, :-1]
        self.kappa_m3_px2 = full[:, 0, -1]
        self.mean_depth_m = np.array(zbar)
        self.depth_span_m = np.array(spans, dtype=float).reshape(-1, 2)
        self._p_z = p_z
        self._log_radii = np.log(self.radii_m)
        self._log_contrasts = np.log(self.contrasts_dn)
        self.apparent_radius_factor = np.array(fac)
        # below one pixel of focused width the size cannot be measured
        self.min_radius_m = self.min_width_px * z0 / (2.0 * f)
        self.brightness_q_by_noise = np.array([
            _brightness_percentile_q([(a, wt[i], q[i], sq[i]) for a, wt, q, sq in q_parts], self.q_min)
            if q_parts else 1.0 for i in range(self.noises_dn.size)])
        self.brightness_q = float(self.brightness_q_by_noise[0])

    # -- contrast
    def contrast_weights(self, contrast_dn) -> np.ndarray:
        """Weights over ``contrasts_dn`` that average the table over a set of contrasts [-].

        Linear interpolation in log contrast of each sample, averaged: the
        kappa of a frame whose pixels show the drops these contrasts is
        ``kappa_table @ weights``.  Contrasts below the grid detect nothing
        (weight on no node), above it count as the largest.

        Parameters
        ----------
        contrast_dn : array_like
            E_r - E_b over the frame's pixels (a sample of them) [gray levels].

        Returns
        -------
        (n_contrasts,) ndarray summing to the fraction of samples inside or above the grid.
        """
        c = np.asarray(contrast_dn, dtype=float).ravel()
        c = c[np.isfinite(c)]
        grid = np.log(self.contrasts_dn)
        out = np.zeros(grid.size)
        if c.size == 0:
            return out
        seen = c >= self.contrasts_dn[0]
        lc = np.log(_clip(c[seen], self.contrasts_dn[0], self.contrasts_dn[-1]))
        i = _clip(np.searchsorted(grid, lc, side="right") - 1, 0, grid.size - 2)
        t = _clip((lc - grid[i]) / (grid[i + 1] - grid[i]), 0.0, 1.0)
        out = np.bincount(i, 1.0 - t, minlength=grid.size) + np.bincount(i + 1, t, minlength=grid.size)
        return out / c.size

    def contrast_weights_each(self, contrasts) -> np.ndarray:
        """:meth:`contrast_weights` of each of several sets of contrasts, in one pass: (n,
        n_contrasts), row i that of ``contrasts[i]`` (the same sums, in the same order)."""
        sets = [np.asarray(c, dtype=float).ravel() for c in contrasts]
        n, G = len(sets), self.contrasts_dn.size
        if n == 0:
            return np.zeros((0, G))
        c = np.concatenate(sets) if n > 1 else sets[0]
        g = np.repeat(np.arange(n), [x.size for x in sets])
        fin = np.isfinite(c)
        size = np.bincount(g[fin], minlength=n)
        grid = np.log(self.contrasts_dn)
        seen = fin & (c >= self.contrasts_dn[0])
        g = g[seen]
        lc = np.log(_clip(c[seen], self.contrasts_dn[0], self.contrasts_dn[-1]))
        i = _clip(np.searchsorted(grid, lc, side="right") - 1, 0, grid.size - 2)
        t = _clip((lc - grid[i]) / (grid[i + 1] - grid[i]), 0.0, 1.0)
        out = (np.bincount(g * G + i, 1.0 - t, minlength=n * G)
               + np.bincount(g * G + i + 1, t, minlength=n * G)).reshape(n, G)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = out / size[:, None]
        out[size == 0] = 0.0
        return out

    def histogram_weights(self, histogram, drop_brightness_dn: float) -> np.ndarray:
        """:meth:`contrast_weights` of a frame from its histogram of background levels.

        Parameters
        ----------
        histogram : (n_bins,) array
            Counts of background levels in bins of :data:`BACKGROUND_BIN_DN`
            (:func:`background_histogram`).
        drop_brightness_dn : float
            E_r [gray levels].
        """
        h = np.asarray(histogram, dtype=float)
        total = h.sum()
        if not total > 0:
            return np.zeros(self.contrasts_dn.size)
        centres = (np.arange(h.size) + 0.5) * BACKGROUND_BIN_DN
        # each bin's contrast E_r - E_b on the grid (contrast_weights of it alone), weighted
        # by the bin's count, all bins at once
        c = float(drop_brightness_dn) - centres
        grid = np.log(self.contrasts_dn)
        seen = (h > 0) & np.isfinite(c) & (c >= self.contrasts_dn[0])
        lc = np.log(_clip(c[seen], self.contrasts_dn[0], self.contrasts_dn[-1]))
        i = _clip(np.searchsorted(grid, lc, side="right") - 1, 0, grid.size - 2)
        t = _clip((lc - grid[i]) / (grid[i + 1] - grid[i]), 0.0, 1.0)
        hs = h[seen]
        out = (np.bincount(i, hs * (1.0 - t), minlength=grid.size)
               + np.bincount(i + 1, hs * t, minlength=grid.size))
        return out / total

    def hidden_share(self, weights, rate_mm_h: float, *, visible_min: float = 0.5,
                     velocity_model: str | None = None) -> tuple[float, float]:
        """Smallest drop diameter the frame's backgrounds leave visible [m], and the share of
        the rain rate the invisible sizes may carry [-].

        A size is visible where the background-weighted sample volume
        (:meth:`visible_fraction`) keeps at least ``visible_min`` of its best;
        visible sizes are counted up by their volume.  Sizes seen in less than
        that share are counted up too, but their volume rests on the drop
        brightness E_r (estimated from the streaks) near the detection limit,
        so they count as possibly missing in the interval.  The share is that of the Marshall-Palmer spectrum at the
        measured rate [MarshallPalmer1948] (steeper, richer in small drops,
        than at the true, higher rate) over the measurable sizes; 1 when no
        size is visible (the gauge cannot measure against this background).

        Parameters
        ----------
        weights : (n_contrasts,) array
            :meth:`contrast_weights` of the frames.
        rate_mm_h : float
            The measured rate [mm/h].
        visible_min : float
            Smallest visible fraction counted as seen [-].
        velocity_model : str, optional
            Law of the drops' speeds (default the volume's).
        """
        from raingauge.physics.drops import fall_velocity

        d_min = 2.0 * float(self.min_radius_m)
        d = np.geomspace(max(d_min, 0.1e-3), 8e-3, 200)
        vis = self.visible_fraction(0.5 * d, weights=weights) >= visible_min
        if not vis.any():
            return float("inf"), 1.0
        d_det = float(d[np.argmax(vis)])
        v = np.nan_to_num(fall_velocity(d, model=velocity_model or self.rain_velocity_model or self.velocity_model),
                          nan=0.0)
        lam = 4.1e3 * max(float(rate_mm_h) if np.isfinite(rate_mm_h) else 0.5, 0.5) ** -0.21   # [1/m]
        w = d ** 3 * v * np.exp(-lam * d) * np.gradient(d)
        total = float(w.sum())
        share = float(w[~vis].sum()) / total if total > 0 else 1.0
        return d_det, float(min(max(share, 0.0), 1.0))

    # -- per radius
    def _noise_slice(self, noise_dn) -> np.ndarray:
        """kappa(a, C) (n_radii, n_contrasts) at a frame noise, linear between the grid's."""
        if noise_dn is None or not np.isfinite(noise_dn):
            return self.kappa_table
        i, t = self._noise_bracket(noise_dn)
        return (1.0 - t) * self.kappa_cube[:, i, :] + t * self.kappa_cube[:, i + 1, :]

    def brightness_q_at(self, noise_dn=None, contrast_dn=None, wind_m_s: float = 0.0) -> float:
        """:attr:`brightness_q` at a frame noise [gray levels] (linear between the grid's;
        default the profile's) and a drop contrast E_r - E_b [gray levels] (default
        ``contrast_dn``) [-].

        The errors of the measured focus q' grow as the noise over the contrast, and a
        faint streak is detected only where it is brighter than its mean: on a bright
        background the percentile of q' lies further above the in-focus q = 1.  Other
        contrasts than ``contrast_dn`` are computed on a grid of half octaves about it
        (:data:`BRIGHTNESS_Q_NODES`, each node when first needed), as the factor by which
        the percentile there differs from that at ``contrast_dn``, interpolated in log C.
        In a cross wind of ``wind_m_s`` [m/s] that of the wind's volume (:meth:`in_wind`,
        linear between the steps of :data:`WIND_STEP_M_S`).
        """
        wind = abs(float(wind_m_s)) if wind_m_s is not None and np.isfinite(wind_m_s) else 0.0
        if wind != self.wind_m_s:
            return float(sum(t * vol.brightness_q_at(noise_dn, contrast_dn, vol.wind_m_s) for vol, t in self._wind_nodes(wind)))
        noise = None if noise_dn is None or not np.isfinite(noise_dn) else float(noise_dn)
        # the base and the noise grid's two nodes about the frame's noise (linear weights):
        # kept for the last noise (the drop brightness asks at one noise for many contrasts)
        memo = self._q_at_memo
        if memo is None or memo[0] != noise:
            base = self.brightness_q if noise is None else float(np.interp(noise, self.noises_dn,
                                                                          self.brightness_q_by_noise))
            memo = self._q_at_memo = (noise, base, self._noise_bracket(noise), {})
        base, (i_n, tn), factors = memo[1], memo[2], memo[3]
        if contrast_dn is None or not np.isfinite(contrast_dn) or contrast_dn == self.contrast_dn:
            return base
        if self.defocus_model != "uniform":
            return base
        x = 2.0 * math.log2(max(float(contrast_dn), 1.0) / self.contrast_dn)    # in half octaves
        x = min(max(x, float(BRIGHTNESS_Q_NODES[0])), float(BRIGHTNESS_Q_NODES[1]))
        k = min(math.floor(x), BRIGHTNESS_Q_NODES[1] - 1)
        t = x - k

        def at(node):
            out = factors.get(node)
            if out is None:
                out = 0.0
                for i, w in ((i_n, 1.0 - tn), (i_n + 1, tn)):
                    if w > 0.0:
                        out += w * self._brightness_q_node(node, i) / self._brightness_q_node(0, i)
                factors[node] = out
            return out

        factor = (1.0 - t) * at(k) + (t * at(k + 1) if t > 0.0 else 0.0)
        return float(base * factor)

    def brightness_q_population_factor(self, noise_dn, contrast_dn, flat_between,
                                       prior_rate_mm_h: float | None = None, wind_m_s: float = 0.0) -> float:
        """q_ref of a Marshall-Palmer population of ``prior_rate_mm_h`` (default
        :data:`BRIGHTNESS_PRIOR_RATE_MM_H`, that of :attr:`brightness_q`) over that of drops
        spread uniformly in log a between the radii ``flat_between`` = (lo, hi) [m], at a
        frame noise and a drop contrast E_r - E_b [gray levels] (both from the same grid of
        depths and q', linear between its nodes) [-].  The completeness probe measures the
        second population's percentile in the frames; this factor carries it to the first.
        The heavier the rain, the larger the share of big drops, whose streaks are measured
        best, and the smaller the factor.  In a cross wind of ``wind_m_s`` [m/s] the factor
        of the wind's volume (:meth:`in_wind`, linear between the steps of
        :data:`WIND_STEP_M_S`): the wind takes the small drops, which slant most, out of
        both populations, and Marshall-Palmer's holds the more of them."""
        wind = abs(float(wind_m_s)) if wind_m_s is not None and np.isfinite(wind_m_s) else 0.0
        if wind != self.wind_m_s:
            return float(sum(t * vol.brightness_q_population_factor(noise_dn, contrast_dn, flat_between,
                                                                     prior_rate_mm_h, vol.wind_m_s)
                             for vol, t in self._wind_nodes(wind)))
        if self.defocus_model != "uniform" or not self._q_node_parts:
            return 1.0
        c = self.contrast_dn if contrast_dn is None or not np.isfinite(contrast_dn) else float(contrast_dn)
        x = 2.0 * math.log2(max(c, 1.0) / self.contrast_dn)
        x = min(max(x, float(BRIGHTNESS_Q_NODES[0])), float(BRIGHTNESS_Q_NODES[1]))
        k = min(math.floor(x), BRIGHTNESS_Q_NODES[1] - 1)
        t = x - k
        i_n, tn = self._noise_bracket(None if noise_dn is None else float(noise_dn))
        span = (float(flat_between[0]), float(flat_between[1]))
        out = 0.0
        for node, wc in ((k, 1.0 - t), (k + 1, t)):
            for i, wn in ((i_n, 1.0 - tn), (i_n + 1, tn)):
                if wc > 0.0 and wn > 0.0:
                    flat = self._brightness_q_node(node, i, span)
                    out += wc * wn * self._brightness_q_node(node, i, None, prior_rate_mm_h) / flat
        return float(out)

    def _brightness_q_node(self, node: int, i_noise: int, flat_between=None,
                           prior_rate_mm_h: float | None = None) -> float:
        """The percentile of q' (:func:`_brightness_percentile_q`, on every
        :data:`P_TABLE_STRIDE`-th depth and a coarser grid of q') at the contrast
        ``contrast_dn`` 2^(node / 2) and the noise ``noises_dn[i_noise]`` [-], for the
        population of ``flat_between`` or of ``prior_rate_mm_h``, computed when first
        asked for."""
        if flat_between is None and prior_rate_mm_h is not None and \
                float(prior_rate_mm_h) == BRIGHTNESS_PRIOR_RATE_MM_H:
            prior_rate_mm_h = None
        key = (node, i_noise, flat_between, prior_rate_mm_h)
        hit = self._q_nodes.get(key)
        if hit is not None:
            return hit
        j = node - BRIGHTNESS_Q_NODES[0]
        val = float(_brightness_percentile_q([(a, wt[i_noise, j], q[i_noise, j], sq[i_noise, j])
                                              for a, wt, q, sq in self._q_node_parts], self.q_min,
                                             y=_Q_GRID_COARSE, flat_between=flat_between,
                                             prior_rate_mm_h=prior_rate_mm_h))
        self._q_nodes[key] = val
        return val

    def in_wind(self, wind_m_s: float) -> "SampleVolume":
        """The sample volume of the same camera and tests for drops drifting at ``wind_m_s``
        [m/s] across the image (its ``wind_m_s``), built when first asked for and kept."""
        calm = self if self._calm is None else self._calm
        u = abs(float(wind_m_s))
        if u == calm.wind_m_s:
            return calm
        vol = calm._windy.get(u)
        if vol is None:
            vol = replace(calm, wind_m_s=u)
            vol._calm = calm
            calm._windy[u] = vol
        return vol

    def _wind_nodes(self, wind_m_s) -> list:
        """[(volume, weight)] of the winds of :data:`WIND_STEP_M_S` about ``wind_m_s`` [m/s]
        (linear weights; one volume on a step, the calm one without wind)."""
        calm = self if self._calm is None else self._calm
        u = abs(float(wind_m_s)) if wind_m_s is not None and np.isfinite(wind_m_s) else 0.0
        if u == 0.0:
            return [(calm, 1.0)]
        x = u / WIND_STEP_M_S
        k = math.floor(x)
        t = x - k
        nodes = [(calm.in_wind(k * WIND_STEP_M_S), 1.0 - t)]
        if t > 1e-9:
            nodes.append((calm.in_wind((k + 1) * WIND_STEP_M_S), t))
        return nodes

    def wind_dimming(self, radius_m, wind_m_s: float) -> np.ndarray:
        """Factor by which a cross wind dims a drop's streak, per pixel [-].

        A drop of radius a drifting at u across its fall v(a) moves along a path slanted
        by tan(theta) = u / v(a) and crosses each pixel in cos(theta) of the time it takes
        falling straight (Eq. 16 [GargNayar2007] with the image speed sqrt(u^2 + v^2)):
        its change beta (E_r - E_b) is that of a straight streak at the contrast
        cos(theta) (E_r - E_b) (the end caps, which do not lengthen, are left out: a few
        per cent of a streak several widths long).  The row sums across the streak are
        unchanged (its rows are wider by 1 / cos(theta)), their noise is not: the
        detection's per-pixel tests see the change dimmed by cos(theta), the measurement
        on the rows as if by sqrt(cos(theta)) (``slant_cos`` of :func:`pass_probability`).
        """
        from raingauge.physics.drops import fall_velocity

        a = np.asarray(radius_m, dtype=float)
        v = np.asarray(fall_velocity(2.0 * a, model=self.rain_velocity_model or self.velocity_model), dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = float(wind_m_s) / v
        return np.where(np.isfinite(r), 1.0 / np.sqrt(1.0 + r * r), 0.0)

    def kappa(self, radius_m, contrast_dn=None, *, weights=None, noise_dn=None,
              wind_m_s: float = 0.0) -> np.ndarray:
        """kappa(a) [m^3 per px^2 of image], 0 below the measurable size.

        Parameters
        ----------
        radius_m : array_like
            Drop radius [m].
        contrast_dn : float, optional
            One drop contrast E_r - E_b [gray levels] (default ``self.contrast_dn``).
        weights : (n_contrasts,) array, optional
            The frame's :meth:`contrast_weights`: kappa averaged over its backgrounds.
        noise_dn : float, optional
            The frame's noise [gray levels] (the change image's over sqrt(1.5); default the
            profile's).
        wind_m_s : float
            The drops' drift across the image [m/s]: the kappa of the wind's volume
            (:meth:`in_wind`; linear between the steps of :data:`WIND_STEP_M_S`), each size's
            streak slanted by its own angle (:meth:`wind_dimming`).
        """
        a = np.asarray(radius_m, dtype=float)
        wind = abs(float(wind_m_s)) if np.isfinite(wind_m_s) else 0.0
        if wind != self.wind_m_s:
            return sum(t * vol.kappa(a, contrast_dn, weights=weights, noise_dn=noise_dn, wind_m_s=vol.wind_m_s)
                       for vol, t in self._wind_nodes(wind))
        if weights is None and contrast_dn is None and noise_dn is None:
            col = self.kappa_m3_px2
        else:
            w = None if weights is None else np.asarray(weights, dtype=float)
            # the drops of one frame share its weights and noise: the column is kept for them
            key = (None if w is None else w.tobytes(), None if contrast_dn is None else float(contrast_dn),
                   None if noise_dn is None else float(noise_dn))
            cached = getattr(self, "_kappa_col", None)
            if cached is not None and cached[0] == key:
                col = cached[1]
            else:
                table = self._noise_slice(noise_dn)
                if w is not None:
                    col = table @ w
                elif contrast_dn is not None:
                    col = table @ self.contrast_weights([float(contrast_dn)])
                else:
                    col = table @ self.contrast_weights([float(self.contrast_dn)])
                self._kappa_col = (key, col)
        k = np.interp(np.log(_clip(a, 1e-9, None)), np.log(self.radii_m), col, left=0.0, right=col[-1])
        return np.where(a >= self.min_radius_m, k, 0.0)

    def visible_fraction(self, radius_m, *, weights) -> np.ndarray:
        """Share of the sample volume over the nominal background (contrast ``contrast_dn``, a
        dark scene) that a frame's backgrounds leave a drop of radius a [-] (0: invisible
        everywhere, 1: as over a dark background; above 1 with more contrast).

        Parameters
        ----------
        radius_m : array_like
            Drop radius [m].
        weights : (n_contrasts,) array
            The frame's :meth:`contrast_weights`.
        """
        best = self.kappa(radius_m)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(best > 0, self.kappa(radius_m, weights=weights) / best, 0.0)

    def depth_m(self, radius_m) -> np.ndarray:
        """Mean depth of accepted drops of radius a [m]."""
        a = np.asarray(radius_m, dtype=float)
        return np.interp(np.log(_clip(a, 1e-9, None)), np.log(self.radii_m), self.mean_depth_m)

    def depth_span(self, radius_m) -> tuple[np.ndarray, np.ndarray]:
        """(near, far) depths [m] between which a drop of radius a passes at all
        (:attr:`depth_span_m`, interpolated in log a)."""
        la = np.log(_clip(np.asarray(radius_m, dtype=float), 1e-9, None))
        lr = np.log(self.radii_m)
        return (np.interp(la, lr, self.depth_span_m[:, 0]), np.interp(la, lr, self.depth_span_m[:, 1]))

    def pass_probability_at(self, radius_m: float, z_m: float, contrast_dn: float,
                            noise_dn: float | None = None) -> float:
        """p(a, z) of :func:`pass_probability` for one drop contrast and frame noise, from the
        table the volume integrated (linear in log a, log C, the noise and z) [-].

        Parameters
        ----------
        radius_m, z_m : float
            Drop radius a and depth z [m].
        contrast_dn : float
            E_r - E_b behind the drop [gray levels].
        noise_dn : float, optional
            The frame's noise (default the profile's) [gray levels].
        """
        # the two contrasts of the grid around the drop's, linear weights in log C
        cgrid = self._log_contrasts
        c = float(contrast_dn)
        if not c >= self.contrasts_dn[0]:
            return 0.0
        lc = math.log(min(c, self.contrasts_dn[-1]))
        ic = int(_clip(np.searchsorted(cgrid, lc, side="right") - 1, 0, cgrid.size - 2))
        tc = min(max((lc - cgrid[ic]) / (cgrid[ic + 1] - cgrid[ic]), 0.0), 1.0)
        nodes = self._p_nodes(radius_m, z_m, noise_dn)
        return float((1 - tc) * nodes[ic] + tc * nodes[ic + 1])

    def _noise_bracket(self, noise_dn) -> tuple[int, float]:
        """The noise grid's node below a frame noise and the linear weight of the one above
        (node 0, weight 0 for None: the profile's noise)."""
        if noise_dn is None or not np.isfinite(noise_dn):
            return 0, 0.0
        # (kept for the last noise: a frame asks at one noise many times)
        last = self._bracket_memo
        if last is not None and last[0] == noise_dn:
            return last[1]
        x = float(_clip(noise_dn, self.noises_dn[0], self.noises_dn[-1]))
        i_n = int(_clip(np.searchsorted(self.noises_dn, x, side="right") - 1, 0, self.noises_dn.size - 2))
        out = i_n, (x - self.noises_dn[i_n]) / (self.noises_dn[i_n + 1] - self.noises_dn[i_n])
        self._bracket_memo = (noise_dn, out)
        return out

    def _p_nodes(self, radius_m: float, z_m: float, noise_dn) -> np.ndarray:
        """p(a, z) at every contrast of the grid, from the table the volume integrated
        (linear in log a, the noise and z) [-]."""
        la = math.log(max(float(radius_m), 1e-9))
        lr = self._log_radii
        j = int(_clip(np.searchsorted(lr, la, side="right") - 1, 0, lr.size - 2))
        tr = min(max((la - lr[j]) / (lr[j + 1] - lr[j]), 0.0, ), 1.0)
        i_n, tn = self._noise_bracket(noise_dn)
        nodes = np.zeros(self.contrasts_dn.size)
        for k, wk in ((j, 1.0 - tr), (j + 1, tr)):
            if wk <= 0.0:
                continue
            z, p = self._p_z[k]
            zf = float(z_m)
            if not z[0] <= zf <= z[-1]:
                continue
            iz = min(int((zf - z[0]) / (z[1] - z[0])), z.size - 2)
            tz = (zf - z[iz]) / (z[iz + 1] - z[iz])
            blk = p[i_n:i_n + 2, :, iz:iz + 2].astype(np.float64)
            val = (1 - tn) * blk[0] + tn * blk[-1]
            nodes += wk * ((1 - tz) * val[:, 0] + tz * val[:, -1])
        return nodes

    def pass_probability_over(self, radius_m: float, z_m: float, weights,
                              noise_dn: float | None = None, wind_m_s: float = 0.0) -> float:
        """p(a, z) averaged over the contrasts of a set of background pixels [-].

        ``weights`` are their :meth:`contrast_weights`, the same average over pixels
        that turns ``kappa_table`` into a frame's kappa: an expectation built from
        it belongs to the same model as that kappa.  Between the grid's contrasts
        p is linear in log C, as in :meth:`pass_probability_at`, so the sum over
        the grid's nodes is the mean of p over the pixels.

        Parameters
        ----------
        radius_m, z_m : float
            Drop radius a and depth z [m].
        weights : (n_contrasts,) array
            :meth:`contrast_weights` of the pixels behind the drop.
        noise_dn : float, optional
            The frame's noise (default the profile's) [gray levels].
        wind_m_s : float
            The drops' drift across the image [m/s] (:meth:`wind_dimming`, as :meth:`kappa`).
        """
        wind = abs(float(wind_m_s)) if np.isfinite(wind_m_s) else 0.0
        if wind != self.wind_m_s:
            return float(sum(t * vol.pass_probability_over(radius_m, z_m, weights, noise_dn, vol.wind_m_s)
                             for vol, t in self._wind_nodes(wind)))
        w = np.asarray(weights, dtype=float)
        return float(w @ self._p_nodes(radius_m, z_m, noise_dn))

    def true_radius_m(self, apparent_radius_m) -> np.ndarray:
        """Invert a' = a F(a): the drop radius behind an apparent radius at z0 [m]."""
        app = self.radii_m * self.apparent_radius_factor
        order = np.argsort(app)
        a = np.asarray(apparent_radius_m, dtype=float)
        return np.interp(a, app[order], self.radii_m[order])

    def depth_range_m(self, radius_m: float, *, p_min: float = 0.5) -> tuple[float, float]:
        """Depths [m] between which a drop of radius a passes with probability >= p_min."""
        z0 = self.profile.focus_distance_m
        z = np.linspace(0.4 * z0, 2.5 * z0, 4000)
        p = pass_probability(radius_m, z, self.profile, velocity_model=self.velocity_model,
                             rain_velocity_model=self.rain_velocity_model, floor=self.floor,
                             k_sigma=self.k_sigma, blur_variance_factor=self.blur_variance_factor,
                             defocus_model=self.defocus_model, q_min=self.q_min,
                             contrast_dn=self.contrast_dn, noise_sigma_dn=self.noise_sigma_dn,
                             detection_threshold_dn=self.detection_threshold_dn, grow=self.grow)["p"]
        ok = np.nonzero(p >= p_min)[0]
        if ok.size == 0:
            return (z0, z0)
        return float(z[ok[0]]), float(z[ok[-1]])

    def volume_m3(self, radius_m, *, motion_px=None) -> np.ndarray:
        """Snapshot sample volume of one frame [m^3], corrected for edge clipping.

        kappa(a) times the area of whole-streak start positions; the streak
        motion defaults to that of a drop of radius a falling at the law's
        speed at z0.
        """
        from raingauge.physics.drops import fall_velocity

        prof = self.profile
        a = np.asarray(radius_m, dtype=float)
        f = prof.focal_length_px
        z0 = prof.focus_distance_m
        w = 2 * f * a / z0
        if motion_px is None:
            v = fall_velocity(2 * a, model=self.rain_velocity_model or self.velocity_model)
            motion_px = np.stack([np.zeros_like(a), f * v * prof.exposure_s / z0], axis=-1)
        area = whole_streak_area_px2(motion_px, w, prof.shape)
        return self.kappa(a) * area
