"""Sensor noise and the detection threshold c (step 3 of ``raingauge calibrate``).

Frames of a still, rain-free scene give the temporal noise of every pixel;
binning pixels by their mean intensity gives sigma against intensity, fitted
by the usual sensor model sigma^2 = sigma_read^2 + g I (read noise plus shot
noise).  The paper measures its camera's noise the same way and removes it
from the rain variance (Sec. 4.4, note 23 [GargNayar2007]).

The detection threshold c of Eq. (19) [GargNayar2007] is "the minimum change
in intensity due to a drop that is detectable in the presence of noise"; the
paper uses c = 3 gray levels.  Here c follows from the measured noise: a pixel
is a candidate when I_n - I_{n-1} >= c and I_n - I_{n+1} >= c.  Without rain
both differences are normal with variance 2 sigma^2 and correlation 1/2
(they share I_n), so the false-candidate rate per pixel and frame is the
bivariate normal tail P(c) = Phi_2(-c / (sqrt(2) sigma), -c / (sqrt(2) sigma); 1/2),
and c is chosen so that P(c) equals a target rate (default 1e-3, which gives
c = 3.4 gray levels for sigma = 1, close to the paper's c = 3; the
photometric and size filters remove most of the remaining isolated pixels).

Noise is measured on linearised frames (through the profile's response
table), in the units the detector works in.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Iterable

import numpy as np

from calibration.frames import linear_gray_frames
from raingauge.errors import InputError

__all__ = [
    "NoiseResult",
    "noise_curve",
    "temporal_moments",
    "false_candidate_rate",
    "detection_threshold",
    "calibrate_noise",
    "DEFAULT_FALSE_RATE",
]

#: Default false-candidate rate of Eq. (19) per pixel and frame [-].
DEFAULT_FALSE_RATE = 1e-3
#: Fewest frames accepted for the noise step.
MIN_FRAMES = 4


@dataclasses.dataclass
class NoiseResult:
    """Outcome of the noise step.

    Attributes
    ----------
    levels_dn : (B,) float
        Mean linear intensity of each populated bin [gray levels].
    sigma_dn : (B,) float
        Sensor noise standard deviation in each bin, quantisation removed [gray levels].
    measured_sigma_dn : (B,) float
        Temporal standard deviation of the frames as recorded (with the 8-bit
        quantisation the detector also sees) [gray levels].
    counts : (B,) int
        Pixels per bin.
    noise_sigma_dn : float
        RMS sensor noise over all unclipped pixels [gray levels] (the profile's noise_sigma_dn).
    read_sigma_dn : float
        Fitted intensity-independent noise [gray levels].
    shot_gain_dn : float
        Fitted shot-noise gain g in sigma^2 = read^2 + g I [gray levels].
    threshold_sigma_dn : float
        The noise the threshold is set for: the largest measured per-bin sigma [gray levels].
    c_dn : float
        Detection threshold of Eq. (19) [gray levels].
    false_rate : float
        Target false-candidate rate per pixel and frame used for c [-].
    n_frames : int
    still_fraction : float
        Fraction of unclipped pixels whose variance is consistent with the noise model [-].
    warnings : list of str
    """

    levels_dn: np.ndarray
    sigma_dn: np.ndarray
    measured_sigma_dn: np.ndarray
    counts: np.ndarray
    noise_sigma_dn: float
    read_sigma_dn: float
    shot_gain_dn: float
    threshold_sigma_dn: float
    c_dn: float
    false_rate: float
    n_frames: int
    still_fraction: float
    warnings: list[str]

    def sigma_at(self, intensity_dn) -> np.ndarray:
        """Modelled noise [gray levels] at a linear intensity [gray levels]."""
        i = np.asarray(intensity_dn, dtype=np.float64)
        return np.sqrt(np.maximum(self.read_sigma_dn ** 2 + self.shot_gain_dn * i, 0.0))

    def summary(self) -> str:
        pairs = ", ".join(f"{lv:.0f}:{s:.2f}" for lv, s in zip(self.levels_dn, self.sigma_dn))
        lines = [
            f"noise sigma       {self.noise_sigma_dn:.3f} gray levels RMS over {self.n_frames} frames "
            f"(sensor; {np.sqrt(np.mean(self.measured_sigma_dn ** 2)):.3f} as recorded in 8 bits)",
            f"noise model       sigma^2 = {self.read_sigma_dn:.3f}^2 + {self.shot_gain_dn:.4f} I",
            f"sigma by level    {pairs}",
            f"threshold c       {self.c_dn:.2f} gray levels (Eq. 19; {self.false_rate:.0e} false candidates "
            f"per pixel and frame at sigma {self.threshold_sigma_dn:.2f})",
        ]
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def to_provenance(self) -> dict:
        return {
            "calibrated": True,
            "noise_sigma_dn": round(self.noise_sigma_dn, 4),
            "read_sigma_dn": round(self.read_sigma_dn, 4),
            "shot_gain_dn": round(self.shot_gain_dn, 6),
            "threshold_c_dn": round(self.c_dn, 3),
            "false_rate": self.false_rate,
            "n_frames": self.n_frames,
            "levels_dn": [round(float(v), 2) for v in self.levels_dn],
            "sigma_by_level_dn": [round(float(v), 4) for v in self.sigma_dn],
            "measured_sigma_by_level_dn": [round(float(v), 4) for v in self.measured_sigma_dn],
            "warnings": list(self.warnings),
        }


def temporal_moments(frames: Iterable[np.ndarray], *, table: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray, int, bool]:
    """Per-pixel temporal mean and unbiased variance, one frame at a time.

    Parameters
    ----------
    frames : iterable of (M, N) arrays, or a (T, M, N) array
        uint8 frames (linearised through ``table`` when given) or linear floats [gray levels].
    table : (256,) float, optional
        Linearisation table [gray levels].

    Returns
    -------
    mean : (M*N,) [gray levels]
    var : (M*N,) [gray levels^2] (NaN when fewer than two frames)
    t : int
        Number of frames.
    quantised : bool
        True when the frames were 8-bit codes (their variance includes quantisation).
    """
    t = 0
    quantised = False
    ref = s1 = s2 = None
    for x, codes in linear_gray_frames(frames, table=table, dtype=np.float64, step="noise step",
                                       what="still frames"):
        quantised = quantised or codes
        x = x.ravel()
        if ref is None:
            ref = x.copy()
            s1 = np.zeros_like(x)
            s2 = np.zeros_like(x)
        d = x - ref  # shifted sums keep the variance accurate
        s1 += d
        s2 += d * d
        t += 1
    if t == 0:
        raise InputError("noise step: no frames. Fix: record a few seconds of the still scene")
    mean = ref + s1 / t
    var = (s2 - s1 * s1 / t) / (t - 1) if t > 1 else np.full_like(s1, np.nan)
    return mean, np.maximum(var, 0.0), t, quantised


def code_step_dn(level_dn, table: np.ndarray | None = None) -> np.ndarray:
    """Width of one 8-bit code in linear gray levels at a linear intensity.

    Parameters
    ----------
    level_dn : array
        Linear intensity [gray levels].
    table : (256,) float, optional
        Linearisation table [gray levels]; ``None`` for a linear camera (step 1).
    """
    level = np.asarray(level_dn, dtype=np.float64)
    if table is None:
        return np.ones_like(level)
    table = np.asarray(table, dtype=np.float64)
    codes = np.interp(level, table, np.arange(256.0))
    return np.interp(codes, np.arange(256.0), np.gradient(table))


def noise_curve(mean: np.ndarray, var: np.ndarray, *, n_bins: int = 16,
                clip: tuple[float, float] = (2.0, 253.0), min_count: int = 20
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Temporal noise against intensity.

    Parameters
    ----------
    mean, var : (P,) arrays
        Per-pixel temporal mean [gray levels] and variance [gray levels^2]
        (see :func:`temporal_moments`).
    n_bins : int
        Intensity bins between the clip limits.
    clip : (lo, hi)
        Pixels whose mean lies outside are clipped and left out [gray levels].
    min_count : int
        Fewest pixels a bin needs to be reported.

    Returns
    -------
    levels, sigma, counts : per populated bin [gray levels], [gray levels], [-]
    """
    edges = np.linspace(clip[0], clip[1], n_bins + 1)
    idx = np.digitize(mean, edges) - 1
    levels, sigma, counts = [], [], []
    for b in range(n_bins):
        sel = idx == b
        n = int(sel.sum())
        if n < min_count:
            continue
        # Pooled variance without the few pixels that moved: beyond 6x the median
        # of the (chi-square distributed) variances.
        v = var[sel]
        med = np.median(v)
        ok = v <= 6.0 * max(med, 1e-6)
        levels.append(float(mean[sel][ok].mean()))
        sigma.append(float(np.sqrt(v[ok].mean())))
        counts.append(int(ok.sum()))
    return np.array(levels), np.array(sigma), np.array(counts, dtype=int)


def false_candidate_rate(c_dn: float, sigma_dn: float) -> float:
    """False-candidate rate of Eq. (19) per pixel and frame without rain.

    P(I_n - I_{n-1} >= c and I_n - I_{n+1} >= c) for independent normal noise
    of standard deviation sigma: a bivariate normal tail with correlation
    rho = 1/2 at h = c / (sqrt(2) sigma),

        P = integral_h^inf phi(x) Q((h - rho x) / sqrt(1 - rho^2)) dx,

    evaluated by the trapezoidal rule (phi the normal density, Q its tail).

    Parameters
    ----------
    c_dn : float
        Threshold [gray levels].
    sigma_dn : float
        Noise standard deviation [gray levels].
    """
    from scipy.special import ndtr

    if sigma_dn <= 0:
        return 0.0
    rho = 0.5
    h = c_dn / (math.sqrt(2.0) * sigma_dn)
    x = np.linspace(h, max(h, 0.0) + 12.0, 8001)
    phi = np.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)
    q = ndtr(-(h - rho * x) / math.sqrt(1.0 - rho * rho))
    y = phi * q
    return float(np.sum((y[1:] + y[:-1]) * np.diff(x)) / 2.0)


def detection_threshold(sigma_dn: float, *, false_rate: float = DEFAULT_FALSE_RATE, floor_dn: float = 1.0) -> float:
    """Threshold c of Eq. (19) [GargNayar2007] for a target false-candidate rate.

    Parameters
    ----------
    sigma_dn : float
        Temporal noise standard deviation [gray levels].
    false_rate : float
        Allowed false candidates per pixel and frame [-], in (0, 0.25).
    floor_dn : float
        Smallest threshold returned (one code step) [gray levels].

    Returns
    -------
    c : float [gray levels]
    """
    if not 0 < false_rate < 0.25:
        raise ValueError(f"false_rate must be in (0, 0.25), got {false_rate}")
    if sigma_dn <= 0:
        return float(floor_dn)
    # The rate falls monotonically with c: bisection on [0, 20 sigma].
    lo, hi = 0.0, 20.0 * sigma_dn
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if false_candidate_rate(mid, sigma_dn) > false_rate:
            lo = mid
        else:
            hi = mid
    return float(max(0.5 * (lo + hi), floor_dn))


def calibrate_noise(frames: Iterable[np.ndarray], *, table: np.ndarray | None = None,
                    false_rate: float = DEFAULT_FALSE_RATE, n_bins: int = 16) -> NoiseResult:
    """Noise sigma against intensity and the detection threshold from still frames.

    Parameters
    ----------
    frames : (T, M, N) array or iterable of (M, N) arrays
        Frames of a still, rain-free scene: uint8 codes, or floats already linear
        [gray levels].  Read one at a time, so a long recording needs no memory.
    table : (256,) float, optional
        Linearisation table applied to uint8 frames first [gray levels].
    false_rate : float
        Target false-candidate rate per pixel and frame for c [-].
    n_bins : int
        Intensity bins.

    Raises
    ------
    InputError
        Fewer than :data:`MIN_FRAMES` frames, or no unclipped pixels.
    """
    if isinstance(frames, np.ndarray) and frames.ndim != 3:
        raise InputError(f"noise step: expected gray frames (T, M, N), got shape {frames.shape}")
    mean, var, t, quantised = temporal_moments(frames, table=table)
    if t < MIN_FRAMES:
        raise InputError(
            f"noise step: {t} still frame(s); at least {MIN_FRAMES} are needed (20 or more give sigma within a few %). "
            "Fix: record a few seconds of the still scene without rain, camera fixed"
        )
    if table is not None:
        lo, hi = float(table[2]), float(table[253])
    else:
        lo, hi = 2.0, 253.0
    levels, sigma, counts = noise_curve(mean, var, n_bins=n_bins, clip=(lo, hi))
    if levels.size == 0:
        raise InputError(
            "noise step: every pixel of the still frames is black or saturated. "
            "Fix: record a scene of moderate brightness with the gauge's exposure"
        )
    warnings: list[str] = []
    measured = sigma
    # 8-bit codes add a quantisation variance of (code width)^2 / 12 (Sheppard's
    # correction); the sensor's own noise is what is left.
    q_var = code_step_dn(levels, table) ** 2 / 12.0 if quantised else np.zeros_like(levels)
    sensor_var = np.maximum(measured ** 2 - q_var, 0.0)
    # Fit sigma^2 = r^2 + g I by weighted least squares, g >= 0.
    a = np.column_stack([np.ones_like(levels), levels])
    w = np.sqrt(counts.astype(float))
    coef, *_ = np.linalg.lstsq(a * w[:, None], sensor_var * w, rcond=None)
    r2, g = float(coef[0]), float(coef[1])
    if g < 0 or r2 < 0:
        g = max(g, 0.0)
        r2 = float(np.average(sensor_var - g * levels, weights=counts))
        r2 = max(r2, 0.0)
    unclipped = (mean >= lo) & (mean <= hi)
    model_var = r2 + g * mean[unclipped]
    if quantised:
        model_var = model_var + code_step_dn(mean[unclipped], table) ** 2 / 12.0
    # A variance beyond the chi-square 99.9% point of the model means the pixel moved.
    from scipy.special import chdtri

    limit = model_var * chdtri(t - 1, 0.001) / (t - 1)
    still = float(np.mean(var[unclipped] <= np.maximum(limit, 1e-6)))
    if still < 0.97:
        warnings.append(f"{1 - still:.1%} of the pixels changed more than noise explains: the scene was not still "
                        "(wind, people, flicker); the noise figure may be too high")
    if t < 10:
        warnings.append(f"only {t} frames: sigma is uncertain by about {1 / math.sqrt(2 * (t - 1)):.0%}; "
                        "record 20 or more")
    if levels.size < 3:
        warnings.append("the still scene covers a narrow range of brightness; the noise model is extrapolated")
    noise_rms = float(np.sqrt(np.sum(sensor_var * counts) / np.sum(counts)))
    # The detector sees the quantised frames: the threshold is set for the measured noise.
    thr_sigma = float(measured.max())
    c = detection_threshold(thr_sigma, false_rate=false_rate)
    return NoiseResult(
        levels_dn=levels,
        sigma_dn=np.sqrt(sensor_var),
        measured_sigma_dn=measured,
        counts=counts,
        noise_sigma_dn=noise_rms,
        read_sigma_dn=math.sqrt(r2),
        shot_gain_dn=g,
        threshold_sigma_dn=thr_sigma,
        c_dn=c,
        false_rate=false_rate,
        n_frames=t,
        still_fraction=still,
        warnings=warnings,
    )
