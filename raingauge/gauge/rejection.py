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
errors of the streak's own width and length (:func:`streak_errors_px`: the
noise of the change against the streak's own signal, plus the pixel grid's
resolution of narrow streaks).  A faint or narrow streak gets a wider
tolerance, a bright wide one a narrow tolerance, and the sample volume
(:mod:`raingauge.gauge.volume`) integrates the same acceptance over depth for
the streak each drop size makes, so counts over volume stay unbiased.

Detection itself is Eq. (19) [GargNayar2007]: a pixel is a candidate when its
change over both neighbouring frames reaches c.  A focused streak changes its
pixels by beta (E_r - E_b) (Eqs. 17, 18), so a drop of a given size is seen
only where the background leaves it enough contrast
(:func:`detection_probability`).

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
    "streak_errors_px",
    "change_noise_dn",
    "signal_rel_sigma",
    "detection_probability",
    "sizing_probability",
    "detection_margin",
    "row_snr",
    "streak_change_dn",
    "WIDTH_NOISE_GAIN",
    "WIDTH_RESOLUTION_PX",
    "MOTION_NOISE_GAIN",
    "MOTION_FLOOR_PX",
    "MOTION_FAINT_GAIN",
    "WIDTH_FLOOR_PX",
]

#: Spread of real drop speeds about the law that is always tolerated (ln units, ~8 %).
DEFAULT_TOLERANCE_FLOOR = 0.08
#: Number of standard errors of the measurement allowed.
DEFAULT_K_SIGMA = 3.0

#: Widest tolerance of the velocity law on |ln(v / V(a))| (a factor of 2 in speed) [-].
DEFAULT_TOLERANCE_CAP = 0.7
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
                  k_sigma: float = DEFAULT_K_SIGMA, model: str = "paper", width_sigma_px=None,
                  motion_sigma_px=None, cap: float = DEFAULT_TOLERANCE_CAP, **kw) -> np.ndarray:
    """Tolerance on |r| [-]: sqrt(floor^2 + (k sigma_r)^2) with sigma_r of :func:`ratio_sigma`,
    at most ``cap``: a streak measured too poorly to place within a factor e^cap of the
    law says nothing about it (faint moving texture would pass any wider test).

    Parameters
    ----------
    radius_m, width_px, motion_px : array_like
        Apparent radius [m], width and motion of the streak [px].
    floor : float
        Natural spread of drop speeds always tolerated [ln units].
    k_sigma : float
        Standard errors of r allowed [-].
    width_sigma_px, motion_sigma_px : array_like, optional
        The streak's own standard errors of width and motion [px]
        (:func:`streak_errors_px`); default the typical ``DEFAULT_WIDTH_SIGMA_PX``,
        ``DEFAULT_MOTION_SIGMA_PX``.
    """
    ws = DEFAULT_WIDTH_SIGMA_PX if width_sigma_px is None else width_sigma_px
    ms = DEFAULT_MOTION_SIGMA_PX if motion_sigma_px is None else motion_sigma_px
    sig = ratio_sigma(radius_m, width_px, motion_px, width_sigma_px=ws, motion_sigma_px=ms, model=model, **kw)
    return np.minimum(np.sqrt(floor ** 2 + (k_sigma * sig) ** 2), cap)


def passes_velocity_law(radius_m, velocity_m_s, width_px, motion_px, *, model: str = "paper",
                        floor: float = DEFAULT_TOLERANCE_FLOOR, k_sigma: float = DEFAULT_K_SIGMA,
                        width_sigma_px=None, motion_sigma_px=None, **velocity_kw) -> np.ndarray:
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
    width_sigma_px, motion_sigma_px : array_like, optional
        The streak's own standard errors [px] (:func:`streak_errors_px`); the
        tolerance then follows each streak's measurement.

    Returns
    -------
    bool ndarray
    """
    r = velocity_log_ratio(radius_m, velocity_m_s, model=model, **velocity_kw)
    tol = law_tolerance(radius_m, width_px, motion_px, floor=floor, k_sigma=k_sigma, model=model,
                        width_sigma_px=width_sigma_px, motion_sigma_px=motion_sigma_px, **velocity_kw)
    return np.isfinite(r) & (np.abs(r) <= tol)


#: Gain of the noise term of the width error [-] (calibrated on rendered streaks).
WIDTH_NOISE_GAIN = 0.8
#: Width error of a streak under ~1.5 px from the pixel grid alone [px] (it vanishes above 2 px).
WIDTH_RESOLUTION_PX = 0.45
#: Width error of any streak beyond its noise [px].
WIDTH_FLOOR_PX = 0.03
#: Motion error times the row sums' signal to noise [px] (calibrated on rendered streaks).
MOTION_NOISE_GAIN = 2.5
#: Motion error times the cube of the row sums' signal to noise [px]: faint ends are lost in noise.
MOTION_FAINT_GAIN = 8.0
#: Motion error of any streak beyond its noise [px].
MOTION_FLOOR_PX = 0.1
#: Band of pixels beyond the streak's width that enters a row sum [px].
_BAND_PX = 3.0


def streak_errors_px(width_px, motion_px, plateau, noise_sigma_dn) -> tuple[np.ndarray, np.ndarray]:
    """Standard errors of a uniform streak's width and motion from its own signal [px].

    A streak of apparent width w' and per-pixel change A = P / w' (P the
    row-sum plateau, Eqs. 17, 23 [GargNayar2007]) is measured on n = L - w'
    plateau rows of w' + 3 pixels each, every pixel carrying the noise
    sigma of the change image.  The box width's error is the noise of its
    edges over the rows, g_w sigma sqrt(w' + 3) / (A sqrt(n)), plus the pixel
    grid's own resolution of a narrow streak (a box under ~1.7 px is sampled
    by two pixels whose split depends on its sub-pixel position).  Each end is
    found where the 3-row smoothed row sum crosses P / 2; with s the row sums'
    signal to noise P / (sigma sqrt(w' + 3)) its error falls as g_L / s, and
    faster, as g_3 / s^3, once noise no longer hides the ends.

    Parameters
    ----------
    width_px : array_like
        Apparent width w' [px].
    motion_px : array_like
        Motion L [px].
    plateau : array_like
        Row-sum plateau P [gray levels px] (in the units of the noise).
    noise_sigma_dn : array_like
        Noise of the change image per pixel [gray levels].

    Returns
    -------
    (sigma_w, sigma_L) : ndarrays [px]; inf where the streak has no signal.

    Notes
    -----
    The closed-form measurement (:func:`raingauge.gauge.streaks.measure_streak_table`)
    is not a least-squares fit with its own covariance; the gains
    (:data:`WIDTH_NOISE_GAIN`, :data:`WIDTH_RESOLUTION_PX`, :data:`MOTION_NOISE_GAIN`,
    :data:`MOTION_FAINT_GAIN` and the floors) are calibrated on isolated streaks
    rendered with the simulator's Eqs. (15)-(24) at noise 1 and 3 gray levels
    and contrasts 100 and 160, whose measured scatter they follow within ~30 %.
    """
    w = np.maximum(np.asarray(width_px, dtype=float), 0.5)
    m = np.asarray(motion_px, dtype=float)
    p = np.asarray(plateau, dtype=float)
    s = np.maximum(np.asarray(noise_sigma_dn, dtype=float), 1e-3)
    band = w + _BAND_PX
    n_rows = np.maximum(m - w, 1.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        amp = p / w
        noise_w = WIDTH_NOISE_GAIN * s * np.sqrt(band) / (amp * np.sqrt(n_rows))
        grid_w = WIDTH_RESOLUTION_PX / (1.0 + np.exp((w - 1.7) / 0.1)) + WIDTH_FLOOR_PX
        sig_w = np.sqrt(noise_w ** 2 + grid_w ** 2)
        snr = p / (s * np.sqrt(band))
        sig_l = np.sqrt((MOTION_NOISE_GAIN / snr + MOTION_FAINT_GAIN / snr ** 3) ** 2 + MOTION_FLOOR_PX ** 2)
    bad = ~(p > 0) | ~np.isfinite(p)
    return np.where(bad, np.inf, sig_w), np.where(bad, np.inf, sig_l)


def change_noise_dn(prev, cur, nxt, *, step: int = 4, along_px: int = 1, iterations: int = 3) -> float:
    """Noise of the change image I_n - (I_{n-1} + I_{n+1}) / 2 of a frame, as it acts on a
    streak [gray levels].

    The sensor's noise (sqrt(1.5) sigma) and, in rain, the flicker of the many
    defocused drops too faint to be detected (the rain's own intensity
    fluctuation, Eq. (27) [GargNayar2007]).  A 3-sigma clipped standard
    deviation over every ``step``-th column leaves out the streaks themselves.
    That flicker comes in streaks along the fall and does not average out over
    a streak's rows as white noise does; ``along_px`` > 1 averages the change
    over that many rows and scales its standard deviation back by
    sqrt(along_px), the white noise that would scatter a streak as much.

    Notes
    -----
    The gauge uses the per-pixel noise (``along_px=1``).  The along-fall noise
    matches the measured acceptance at 10-30 mm/h better, but it makes the
    sample volume of heavy rain (where it is 5 times the sensor's) so
    sensitive to the drop brightness E_r, itself estimated from the streaks
    and biased low there, that the rate at 100 mm/h read twice the truth.

    Parameters
    ----------
    prev, cur, nxt : (M, N) arrays
        Linearised frames n-1, n, n+1 [gray levels].
    step : int
        Sub-sampling of the columns [px].
    along_px : int
        Rows averaged along the fall [px] (1: the per-pixel noise).
    iterations : int
        Clipping passes.
    """
    k = max(int(along_px), 1)
    # per-pixel noise: every 3rd row too (~77k samples at 1280x720: the standard deviation to 0.3 %)
    sl = (slice(None, None, 1 if k > 1 else 3), slice(None, None, step))
    if k == 1 and all(np.asarray(a).dtype == np.uint8 for a in (prev, cur, nxt)):
        from raingauge.gauge import _kernels

        if _kernels.AVAILABLE and np.ndim(cur) == 2:
            # the histogram in one compiled pass over the samples
            h = _kernels.change_histogram(prev, cur, nxt, sl[0].step, sl[1].step)
            return _change_noise_of_histogram(h.astype(np.float64), int(h.sum()), iterations)
        return _change_noise_u8(prev[sl], cur[sl], nxt[sl], iterations)
    ch = np.asarray(cur, dtype=np.float32)[sl] - 0.5 * (np.asarray(prev, dtype=np.float32)[sl]
                                                        + np.asarray(nxt, dtype=np.float32)[sl])
    if k > 1 and ch.shape[0] > k:
        cs = np.cumsum(ch, axis=0, dtype=np.float64)
        ch = (cs[k:] - cs[:-k]) / k
    ch = ch.ravel()
    centre, sd = float(np.median(ch)), float(np.std(ch))
    for _ in range(iterations):
        x = ch[np.abs(ch - centre) <= 3.0 * sd]
        if not x.size:
            break
        centre = float(x.mean())
        dev = x - np.float32(centre)
        sd = math.sqrt(float(np.dot(dev, dev)) / x.size) * 1.0135
    return sd * math.sqrt(k)


def _change_noise_u8(prev, cur, nxt, iterations: int) -> float:
    """:func:`change_noise_dn` (``along_px=1``) of 8-bit frames from the histogram of
    2 I_n - I_{n-1} - I_{n+1}: the change takes the 1021 half-integer values -255 ... 255,
    so its median and its clipped moments are sums over the histogram (no sort)."""
    c2 = cur.astype(np.int16) * 2
    c2 -= prev
    c2 -= nxt
    n = c2.size
    if n == 0:
        return float("nan")
    h = np.bincount((c2 + 510).ravel(), minlength=1021).astype(np.float64)
    return _change_noise_of_histogram(h, n, iterations)


def _change_noise_of_histogram(h: np.ndarray, n: int, iterations: int) -> float:
    """:func:`_change_noise_u8` from the (1021,) float histogram ``h`` of its ``n`` samples
    2 I_n - I_{n-1} - I_{n+1} + 510."""
    if n == 0:
        return float("nan")
    vals = 0.5 * (np.arange(1021, dtype=np.float64) - 510.0)
    cum = np.cumsum(h)
    lo, hi = np.searchsorted(cum, [(n - 1) // 2 + 1, n // 2 + 1])
    centre = 0.5 * (vals[lo] + vals[hi])
    mean = float(h @ vals) / n
    sd = math.sqrt(float(h @ (vals - mean) ** 2) / n)
    for _ in range(iterations):
        w = np.where(np.abs(vals - centre) <= 3.0 * sd, h, 0.0)
        m = float(w.sum())
        if not m:
            break
        centre = float(w @ vals) / m
        sd = math.sqrt(float(w @ (vals - centre) ** 2) / m) * 1.0135
    return sd


def streak_change_dn(radius_px, width_px, motion_px, contrast_dn) -> np.ndarray:
    """Change of a streak's pixels, beta (E_r - E_b), with uniform spreading [gray levels].

    beta = tau / T = pi a_i^2 / (w' L + pi w'^2 / 4): the drop's exposure area
    pi a_i^2 spread over the capsule w' wide around its motion L (Eqs. 17, 23-24
    [GargNayar2007], with the exact disc area; see the simulator's Notes).

    Parameters
    ----------
    radius_px : array_like
        Image radius of the drop a_i = f a / z [px].
    width_px : array_like
        Apparent width w' [px].
    motion_px : array_like
        Motion L [px].
    contrast_dn : array_like
        E_r - E_b [gray levels].
    """
    r = np.asarray(radius_px, dtype=float)
    w = np.asarray(width_px, dtype=float)
    m = np.asarray(motion_px, dtype=float)
    beta = math.pi * r * r / (w * m + math.pi * w * w / 4.0)
    return beta * np.asarray(contrast_dn, dtype=float)


#: Focused image diameter 2 a_i [px] at which half of the focused streaks are sized (calibrated).
SIZING_WIDTH_PX = 1.2
#: Spread of that transition [px].
SIZING_WIDTH_SPREAD_PX = 0.15
#: Detection margin (:func:`detection_margin`) at which half of the streaks are detected whole.
SIZING_MARGIN = -0.2
#: Spread of that transition [-].
SIZING_MARGIN_SPREAD = 0.3
#: Signal to noise of a streak's row sums at which half of the streaks are measured.
SIZING_ROW_SNR = 1.4
#: Spread of that transition [-].
SIZING_ROW_SNR_SPREAD = 0.3


def row_snr(change_dn, width_px, noise_sigma_dn) -> np.ndarray:
    """Signal to noise of a streak's row sums, A w' / (sigma sqrt(w' + 3)) [-].

    Parameters
    ----------
    change_dn : array_like
        Per-pixel change A [gray levels].
    width_px : array_like
        Apparent width w' [px].
    noise_sigma_dn : float
        Noise of the change image [gray levels].
    """
    w = np.asarray(width_px, dtype=float)
    s = np.maximum(np.asarray(noise_sigma_dn, dtype=float), 1e-3)
    return np.asarray(change_dn, dtype=float) * w / (s * np.sqrt(w + _BAND_PX))


def sizing_probability(image_diameter_px, margin, snr=np.inf) -> np.ndarray:
    """Chance that a detected, focused streak is measured and sized at all [-].

    A drop whose image 2 a_i is about one pixel leaves its size only in the
    partial coverage of the pixels it crosses (Eq. 22 [GargNayar2007]): its
    streak's width and photometric focus scatter across the one-pixel floor of
    the sizes the gauge can give, and a share of such streaks is not measured
    (too few plateau rows, a size under one pixel).  A streak whose change
    barely clears the detection threshold c of Eq. (19) is detected in pieces
    (the rows where noise lifts it), whose box no longer gives its length; and
    a streak whose row sums are near their noise cannot be measured across.

        P = Phi((2 a_i - w_50) / s_w) Phi((m - m_50) / s_m) Phi((s - s_50) / s_s)

    with m the detection margin of :func:`detection_margin` and s the row-sum
    signal to noise of :func:`row_snr`.

    Parameters
    ----------
    image_diameter_px : array_like
        Focused image diameter 2 f a / z [px].
    margin : array_like
        Detection margin m [-] (:func:`detection_margin`).
    snr : array_like
        Row-sum signal to noise s [-] (:func:`row_snr`).

    Notes
    -----
    The transitions (:data:`SIZING_WIDTH_PX`, :data:`SIZING_MARGIN`,
    :data:`SIZING_ROW_SNR` and their spreads) are calibrated on isolated drops
    rendered by the simulator and measured by the gauge (the measurement's
    failure modes have no closed form); tests/test_gauge_volume.py checks the
    round trip.
    """
    from scipy.special import ndtr

    d = np.asarray(image_diameter_px, dtype=float)
    m = np.asarray(margin, dtype=float)
    sn = np.asarray(snr, dtype=float)
    return (ndtr((d - SIZING_WIDTH_PX) / SIZING_WIDTH_SPREAD_PX) * ndtr((m - SIZING_MARGIN) / SIZING_MARGIN_SPREAD)
            * ndtr((sn - SIZING_ROW_SNR) / SIZING_ROW_SNR_SPREAD))


def detection_margin(change_dn, width_px, *, threshold_dn: float, noise_sigma_dn: float,
                     smooth_px: int = 5) -> np.ndarray:
    """How far a streak's smoothed candidate value clears the threshold of Eq. (19), in its noise [-].

    m = (A cover - sigma / sqrt(pi) - c) / (sigma sqrt(2 - 1 / pi) / sqrt(smooth_px)):
    see :func:`detection_probability` (its per-try probability is Phi(m)).

    Parameters
    ----------
    change_dn : array_like
        A = beta (E_r - E_b) [gray levels].
    width_px : array_like
        Apparent width w' [px].
    threshold_dn : float
        c [gray levels].
    noise_sigma_dn : float
        Noise of one frame [gray levels].
    smooth_px : int
        Rows averaged along the fall.
    """
    a = np.asarray(change_dn, dtype=float)
    w = np.asarray(width_px, dtype=float)
    cover = np.where(w >= 2.0, 1.0, np.where(w >= 1.0, 0.5 * (0.5 * w + 1.0), 0.75 * w))
    s = np.maximum(np.asarray(noise_sigma_dn, dtype=float), 0.3)
    mean = a * cover - s / math.sqrt(math.pi)
    sd = s * math.sqrt(2.0 - 1.0 / math.pi) / math.sqrt(max(int(smooth_px), 1))
    return (mean - float(threshold_dn)) / sd


def detection_probability(change_dn, width_px, *, threshold_dn: float, noise_sigma_dn: float,
                          smooth_px: int = 5, length_px=None) -> np.ndarray:
    """Chance that a streak of per-pixel change A is detected by Eq. (19) [-].

    The candidate test of Eq. (19) [GargNayar2007] is min(I_n - I_{n-1},
    I_n - I_{n+1}) >= c, here averaged over ``smooth_px`` rows along the fall
    (:func:`raingauge.gauge.streaks.detect_streaks`).  On the streak's best
    pixel column the change is A times the column's coverage (1 for w' >= 2;
    a narrower streak straddles two columns, the better covered holding on
    average (w' / 2 + 1) / 2 of it, 3 w' / 4 under one pixel); the noise term
    e_n - max(e_{n-1}, e_{n+1}) has mean -sigma / sqrt(pi) and standard
    deviation sigma sqrt(2 - 1 / pi), divided by sqrt(smooth_px) along the fall.
    A streak L px long offers L / smooth_px such independent tries; pieces of
    it are merged (:func:`raingauge.gauge.streaks.detect_streaks`) and it is
    measured on its row sums, not on its detected pixels, so it is found when
    one try succeeds: P = 1 - (1 - p)^(L / smooth_px).

    Parameters
    ----------
    change_dn : array_like
        A = beta (E_r - E_b) [gray levels] (:func:`streak_change_dn`).
    width_px : array_like
        Apparent width w' [px].
    threshold_dn : float
        c [gray levels].
    noise_sigma_dn : float
        Noise of one frame [gray levels].
    smooth_px : int
        Rows averaged along the fall.
    length_px : array_like, optional
        Streak length L [px] (default: one try).
    """
    from scipy.special import ndtr

    p = ndtr(detection_margin(change_dn, width_px, threshold_dn=threshold_dn, noise_sigma_dn=noise_sigma_dn,
                              smooth_px=smooth_px))
    if length_px is None:
        return p
    tries = np.maximum(np.asarray(length_px, dtype=float) / max(int(smooth_px), 1), 1.0)
    return 1.0 - (1.0 - p) ** tries


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
#: Relative standard error of a streak's total signal beyond its noise [-] (calibrated on
#: isolated drops rendered by the simulator: the photometric focus q of focused and
#: slightly defocused drops scatters by this much more than their noise explains).
DEFAULT_SIGNAL_REL_SIGMA = 0.1


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


def q_sigma(q, width_px, *, width_sigma_px=DEFAULT_WIDTH_SIGMA_PX,
            signal_rel_sigma=DEFAULT_SIGNAL_REL_SIGMA) -> np.ndarray:
    """Standard error of q from the errors of the total change and of the width [-].

    Parameters
    ----------
    q : array_like
        Photometric focus [-].
    width_px : array_like
        Apparent width w' [px].
    width_sigma_px : array_like
        Standard error of w' [px] (the streak's own, :func:`streak_errors_px`).
    signal_rel_sigma : array_like
        Relative standard error of the total change Q [-].
    """
    w = np.maximum(np.asarray(width_px, dtype=float), 0.3)
    ws = np.asarray(width_sigma_px, dtype=float)
    return np.maximum(np.asarray(q) * np.sqrt(np.asarray(signal_rel_sigma) ** 2 + (2 * ws / w) ** 2), 1e-3)


def signal_rel_sigma(width_px, motion_px, plateau, noise_sigma_dn) -> np.ndarray:
    """Relative standard error of a streak's total change Q = P (L + pi w' / 4) [-].

    The plateau P is the median of the middle half of the row sums (n / 2 rows
    of w' + 3 noisy pixels; the median costs a factor sqrt(pi / 2)), the
    length adds its own error (:func:`streak_errors_px`), and
    :data:`DEFAULT_SIGNAL_REL_SIGMA` covers the rest in quadrature.

    Parameters
    ----------
    width_px, motion_px : array_like
        Apparent width and motion [px].
    plateau : array_like
        Row-sum plateau P [gray levels px].
    noise_sigma_dn : array_like
        Noise of the change image per pixel [gray levels].
    """
    w = np.maximum(np.asarray(width_px, dtype=float), 0.5)
    m = np.maximum(np.asarray(motion_px, dtype=float), 1.0)
    p = np.asarray(plateau, dtype=float)
    s = np.asarray(noise_sigma_dn, dtype=float)
    n_half = np.maximum(0.5 * (m - w), 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel_p = math.sqrt(math.pi / 2) * s * np.sqrt(w + _BAND_PX) / (p * np.sqrt(n_half))
        sig_l = streak_errors_px(w, m, p, s)[1]
        rel_l = sig_l / (m + math.pi * w / 4)
        out = np.sqrt(rel_p ** 2 + rel_l ** 2 + DEFAULT_SIGNAL_REL_SIGMA ** 2)
    return np.where(np.isfinite(out), out, np.inf)
