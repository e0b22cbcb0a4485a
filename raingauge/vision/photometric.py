"""Streaks and the photometric constraint of Eq. (18) [GargNayar2007].

Candidate pixels (Eq. 19) are grouped into streaks, the 8-connected components
of the candidate mask (note 13: sequential labelling [Horn1986]).  Along a real
rain streak the change is linear in the background it occludes,

    Delta I = -beta I_b + alpha,   beta = tau / T,   alpha = tau E_r,   (Eq. 18)

with 0 <= beta <= beta_max = tau_max / T (Sec. 4.3, App. 10.2).  A streak that
is not linear, or whose slope lies outside [0, beta_max], is not rain.

All per-streak sums are accumulated with ``numpy.bincount`` over the label of
each candidate pixel, so the cost grows with the number of candidate pixels,
never with a Python loop over streaks.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Iterator

import numpy as np

__all__ = [
    "label_streaks",
    "photometric_filter",
    "fit_streaks",
    "StreakFits",
    "Streak",
    "beta_max_for_exposure",
]


def beta_max_for_exposure(exposure_s: float, *, radius_m: float = 3.5e-3, velocity_model: str = "paper") -> float:
    """Upper bound of the Eq. (18) slope, beta_max = tau_max / T (App. 10.2) [GargNayar2007].

    Parameters
    ----------
    exposure_s : float
        Exposure time T [s].
    radius_m : float
        Largest drop radius a_max [m]; 3.5 mm in the paper.
    velocity_model : str
        Fall-velocity law for v(a_max) (see :mod:`raingauge.physics.drops`).

    Notes
    -----
    tau_max = 4 a_max / v(a_max) = 1.18 ms with the paper's v = 200 sqrt(a),
    so beta_max = 0.039 only for T = 30 ms; the bound scales as 1 / T.
    Delegates to :func:`raingauge.physics.streaks.beta_max`.
    """
    if not (math.isfinite(exposure_s) and exposure_s > 0):
        raise ValueError(f"exposure must be a positive time in seconds, got {exposure_s!r}")
    try:
        from raingauge.physics.streaks import beta_max
    except ImportError:  # physics.streaks not importable: the paper's law, App. 10.2
        if velocity_model != "paper":
            raise
        tau = 4.0 * radius_m / (200.0 * math.sqrt(radius_m))
        return tau / exposure_s
    return float(beta_max(exposure_s, radius_m=radius_m, velocity_model=velocity_model))


def label_streaks(mask: np.ndarray, *, connectivity: int = 8) -> tuple[np.ndarray, int]:
    """Label the streaks of a candidate mask (note 13 [GargNayar2007], [Horn1986]).

    Parameters
    ----------
    mask : (M, N) bool array
        Candidate rain pixels.
    connectivity : {4, 8}
        Pixel neighbourhood; 8 as Matlab's ``bwlabel``.

    Returns
    -------
    labels : (M, N) int32 array
        0 for background, 1..n for the streaks.
    n : int
        Number of streaks.
    """
    if connectivity == 8:
        return _label(mask)
    labels, n, _, _ = _label_stats(mask, connectivity=connectivity)
    return labels, n


def _label_stats(mask, *, connectivity=8):
    import cv2

    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"mask must be (M, N), got shape {mask.shape}")
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, got {connectivity!r}")
    m8 = mask.view(np.uint8) if mask.dtype == np.bool_ else (mask != 0).astype(np.uint8)
    if not m8.flags.c_contiguous:
        m8 = np.ascontiguousarray(m8)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(m8, connectivity=connectivity, ltype=cv2.CV_32S)
    return labels, n - 1, stats[1:], cents[1:]


@dataclasses.dataclass(frozen=True)
class Streak:
    """One streak, as ``skimage.measure.regionprops`` gives a region.

    Geometry is in pixels with x to the right and y down; ``orientation_deg``
    is the streak's axis measured counter-clockwise on screen from +x, in
    [0, 180) (90 = vertical).  Photometry is in gray levels of the linearised
    image.
    """

    label: int
    area: int
    bbox: tuple[int, int, int, int]
    centroid: tuple[float, float]
    orientation_deg: float
    major_axis_px: float
    minor_axis_px: float
    mean_change: float
    max_change: float
    mean_background: float
    beta: float
    alpha: float
    beta_se: float
    residual_rms: float
    linear: bool
    slope_ok: bool
    stationary: bool
    accepted: bool
    _labels: np.ndarray = dataclasses.field(repr=False, compare=False, default=None)

    @property
    def coords(self) -> np.ndarray:
        """(K, 2) array of (row, column) of the streak's pixels."""
        x, y, w, h = self.bbox
        rr, cc = np.nonzero(self._labels[y:y + h, x:x + w] == self.label)
        return np.column_stack([rr + y, cc + x])

    @property
    def length_px(self) -> float:
        """Streak length [px]: a uniform rod with the streak's second moment along its axis.

        A rod of length L has variance L^2 / 12 along it, so L = sqrt(12 lambda_1)
        = (sqrt(12) / 4) x the regionprops major axis (which assumes an ellipse).
        """
        return max(self.major_axis_px * math.sqrt(12.0) / 4.0, 1.0)

    @property
    def width_px(self) -> float:
        """Mean streak width [px]: area / length."""
        return self.area / max(self.major_axis_px, 1.0)


@dataclasses.dataclass
class StreakFits:
    """Per-streak measurements and Eq. (18) fits, one entry per label 1..n.

    Every attribute below is an array of length n; ``labels`` is the (M, N)
    label image of all candidate components and ``label[i]`` the value of
    streak i in it.  Components smaller than ``min_pixels`` are left out.
    """

    labels: np.ndarray
    label: np.ndarray           # (n,) label value of each streak in ``labels``
    area: np.ndarray
    bbox: np.ndarray            # (n, 4) x, y, w, h [px]
    centroid: np.ndarray        # (n, 2) x, y [px]
    orientation_deg: np.ndarray
    major_axis_px: np.ndarray
    minor_axis_px: np.ndarray
    mean_change: np.ndarray     # mean Delta I [gray levels]
    max_change: np.ndarray
    mean_background: np.ndarray
    beta: np.ndarray            # Eq. (18) slope (positive: change falls with background)
    alpha: np.ndarray           # Eq. (18) intercept [gray levels]
    beta_se: np.ndarray         # standard error of beta
    residual_rms: np.ndarray    # rms deviation from the line [gray levels]
    background_change_rms: np.ndarray  # rms of I_{n-1} - I_{n+1} over the streak [gray levels]
    linear: np.ndarray          # bool: passes the linearity test
    slope_ok: np.ndarray        # bool: beta compatible with [0, beta_max]
    stationary: np.ndarray      # bool: I_{n-1} = I_{n+1} along the streak (Eq. 19)
    accepted: np.ndarray        # bool: rain streak

    def __len__(self) -> int:
        return int(self.area.shape[0])

    def __getitem__(self, i: int) -> Streak:
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"streak index {i} out of range for {n} streaks")
        i %= n
        return Streak(
            label=int(self.label[i]), area=int(self.area[i]), bbox=tuple(int(v) for v in self.bbox[i]),
            centroid=(float(self.centroid[i, 0]), float(self.centroid[i, 1])),
            orientation_deg=float(self.orientation_deg[i]), major_axis_px=float(self.major_axis_px[i]),
            minor_axis_px=float(self.minor_axis_px[i]), mean_change=float(self.mean_change[i]),
            max_change=float(self.max_change[i]), mean_background=float(self.mean_background[i]),
            beta=float(self.beta[i]), alpha=float(self.alpha[i]), beta_se=float(self.beta_se[i]),
            residual_rms=float(self.residual_rms[i]), linear=bool(self.linear[i]),
            slope_ok=bool(self.slope_ok[i]), stationary=bool(self.stationary[i]),
            accepted=bool(self.accepted[i]), _labels=self.labels,
        )

    def __iter__(self) -> Iterator[Streak]:
        for i in range(len(self)):
            yield self[i]

    def accepted_only(self) -> list[Streak]:
        """The accepted (rain) streaks as :class:`Streak` objects."""
        return [self[int(i)] for i in np.flatnonzero(self.accepted)]


def fit_streaks(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray, mask: np.ndarray, *,
                beta_max: float, labels: tuple[np.ndarray, int] | None = None,
                noise_sigma: float = 1.0, min_pixels: int = 5, max_relative_residual: float = 0.35,
                residual_sigmas: float = 3.0, slope_sigmas: float = 2.0) -> StreakFits:
    """Fit Eq. (18) to every streak of a candidate mask [GargNayar2007].

    Parameters
    ----------
    prev, cur, nxt : (M, N) float arrays
        Linearised frames n-1, n, n+1 [gray levels], aligned to frame n.
    mask : (M, N) bool array
        Candidate pixels of frame n (Eq. 19).
    beta_max : float
        Largest physical slope tau_max / T [dimensionless]; see
        :func:`beta_max_for_exposure`.
    labels : (labels, n), optional
        A labelling of ``mask`` already computed.
    noise_sigma : float
        Camera noise standard deviation [gray levels].
    min_pixels : int
        Streaks with fewer pixels are discarded before fitting [px] (clusters
        of noise spikes); they do not appear in the fits.
    max_relative_residual : float
        A streak is linear when its rms residual from the fitted line is at most
        ``residual_sigmas * sqrt(2) * noise_sigma + max_relative_residual * mean change``;
        the rms of I_{n-1} - I_{n+1} along it (the stationarity half of Eq. (19))
        must stay within the same allowance.
    residual_sigmas : float
        Noise allowance of the linearity test [standard deviations].
    slope_sigmas : float
        The slope is accepted when beta +- slope_sigmas * se(beta) meets [0, beta_max].

    Notes
    -----
    The background is I_{n-1} as in Sec. 5.1, and the change is taken against
    the other neighbour, Delta I = I_n - I_{n+1} (equal to I_n - I_{n-1} under
    Eq. (19)).  Regressing I_n - I_{n-1} on I_{n-1} itself would put the noise
    of I_{n-1} into both variables and bias the slope towards beta = 1 on
    smooth backgrounds, rejecting real streaks; with independent noise the
    only bias is the errors-in-variables attenuation towards beta = 0, which
    lies inside the accepted range.  On a uniform background the slope is
    undetermined (large ``beta_se``) and the streak is kept: Eq. (18) cannot
    refute it.
    """
    return _fit(prev, cur, nxt, mask, beta_max=beta_max, labels=labels, noise_sigma=noise_sigma,
                min_pixels=min_pixels, max_relative_residual=max_relative_residual,
                residual_sigmas=residual_sigmas, slope_sigmas=slope_sigmas)[0]


def _fit(prev, cur, nxt, mask, *, beta_max, labels, noise_sigma, min_pixels, max_relative_residual,
         residual_sigmas, slope_sigmas):
    if not (math.isfinite(beta_max) and beta_max > 0):
        raise ValueError(f"beta_max must be a positive number, got {beta_max!r}")
    if labels is None:
        lab, n = _label(mask)
    else:
        lab, n = labels
    cols = lab.shape[1]
    flat_lab = lab.ravel()
    idx = np.flatnonzero(np.asarray(mask).ravel()) if labels is None else np.flatnonzero(flat_lab)
    li = flat_lab[idx]
    # Discard the streaks too small to be rain before any fitting.
    area_all = np.bincount(li, minlength=n + 1)
    big = area_all >= max(int(min_pixels), 1)
    big[0] = False
    keep_ids = np.flatnonzero(big)
    sel = big[li]
    idx, li = idx[sel], li[sel]
    compact = np.zeros(n + 1, dtype=np.int64)
    compact[keep_ids] = np.arange(keep_ids.size)
    lj = compact[li]
    m = keep_ids.size

    x = prev.ravel()[idx].astype(np.float64)                           # background I_{n-1}
    z = nxt.ravel()[idx].astype(np.float64)                            # background I_{n+1}
    y = cur.ravel()[idx].astype(np.float64) - z                        # change against I_{n+1}
    cnt = np.bincount(lj, minlength=m).astype(np.float64)
    sx = np.bincount(lj, x, m)
    sy = np.bincount(lj, y, m)
    sxx = np.bincount(lj, x * x, m)
    sxy = np.bincount(lj, x * y, m)
    syy = np.bincount(lj, y * y, m)
    sbb = np.bincount(lj, (x - z) ** 2, m)
    rr = (idx // cols).astype(np.float64)
    cc = (idx % cols).astype(np.float64)
    sr = np.bincount(lj, rr, m)
    sc = np.bincount(lj, cc, m)
    srr = np.bincount(lj, rr * rr, m)
    scc = np.bincount(lj, cc * cc, m)
    src = np.bincount(lj, rr * cc, m)
    ymax = np.full(m, -np.inf)
    _segment_max(ymax, lj, y)
    rmin = np.full(m, np.inf); rmax = np.full(m, -np.inf)
    cmin = np.full(m, np.inf); cmax = np.full(m, -np.inf)
    _segment_min(rmin, lj, rr); _segment_max(rmax, lj, rr)
    _segment_min(cmin, lj, cc); _segment_max(cmax, lj, cc)
    bbox = np.column_stack([cmin, rmin, cmax - cmin + 1, rmax - rmin + 1]).astype(np.int32) if m else \
        np.zeros((0, 4), dtype=np.int32)

    safe = np.maximum(cnt, 1.0)
    mx, my = sx / safe, sy / safe
    vxx = np.maximum(sxx - safe * mx * mx, 0.0)
    vxy = sxy - safe * mx * my
    vyy = np.maximum(syy - safe * my * my, 0.0)
    # Background spread too small to determine a slope: treat it as flat.
    determined = vxx > 1e-9 * np.maximum(safe * mx * mx, 1.0)
    vxx_d = np.where(determined, vxx, 1.0)
    slope = np.where(determined, vxy / vxx_d, 0.0)
    rss = np.maximum(vyy - slope * vxy, 0.0)
    dof = np.maximum(cnt - 2.0, 1.0)
    resid_rms = np.sqrt(rss / safe)
    se = np.where(determined & (cnt > 2), np.sqrt(rss / dof) / np.sqrt(vxx_d), np.inf)
    beta = -slope
    alpha = my - slope * mx

    noise_dn = residual_sigmas * math.sqrt(2.0) * float(noise_sigma)
    allowance = noise_dn + max_relative_residual * np.maximum(my, 0.0)
    linear = resid_rms <= allowance
    # Eq. (19) also says I_{n-1} = I_{n+1} under a streak: the background is stationary.
    bg_change = np.sqrt(sbb / safe)
    stationary = bg_change <= allowance
    with np.errstate(invalid="ignore"):
        lo = beta - slope_sigmas * se
        hi = beta + slope_sigmas * se
    slope_ok = (hi >= 0.0) & (lo <= beta_max)
    accepted = linear & slope_ok & stationary & (my > 0)

    # Geometry (centroid and second moments of the pixel positions).
    mr, mc = sr / safe, sc / safe
    mu_rr = np.maximum(srr / safe - mr * mr, 0.0)
    mu_cc = np.maximum(scc / safe - mc * mc, 0.0)
    mu_rc = src / safe - mr * mc
    # screen coordinates: u = column, v = -row
    orient = np.degrees(0.5 * np.arctan2(-2.0 * mu_rc, mu_cc - mu_rr)) % 180.0
    tr = mu_rr + mu_cc
    disc = np.sqrt(np.maximum((mu_cc - mu_rr) ** 2 / 4.0 + mu_rc ** 2, 0.0))
    # 4 sqrt(lambda) as regionprops; at least one pixel
    major = np.maximum(4.0 * np.sqrt(tr / 2.0 + disc), 1.0)
    minor = np.maximum(4.0 * np.sqrt(np.maximum(tr / 2.0 - disc, 0.0)), 1.0)

    fits = StreakFits(
        labels=lab, label=keep_ids.astype(np.int32), area=cnt.astype(np.int64), bbox=bbox,
        centroid=np.column_stack([mc, mr]), orientation_deg=orient, major_axis_px=major,
        minor_axis_px=minor, mean_change=my, max_change=ymax, mean_background=mx, beta=beta,
        alpha=alpha, beta_se=se, residual_rms=resid_rms, background_change_rms=bg_change, linear=linear,
        slope_ok=slope_ok, stationary=stationary, accepted=accepted,
    )
    return fits, idx, lj


def _label(mask):
    import cv2

    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"mask must be (M, N), got shape {mask.shape}")
    m8 = mask.view(np.uint8) if mask.dtype == np.bool_ else (mask != 0).astype(np.uint8)
    if not m8.flags.c_contiguous:
        m8 = np.ascontiguousarray(m8)
    n, labels = cv2.connectedComponents(m8, connectivity=8, ltype=cv2.CV_32S)
    return labels, n - 1


def _segment_max(out: np.ndarray, seg: np.ndarray, values: np.ndarray) -> None:
    """out[s] = max(out[s], values[seg == s]), unbuffered."""
    np.maximum.at(out, seg, values)


def _segment_min(out: np.ndarray, seg: np.ndarray, values: np.ndarray) -> None:
    np.minimum.at(out, seg, values)


def photometric_filter(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray, mask: np.ndarray, *,
                       beta_max: float, labels: tuple[np.ndarray, int] | None = None,
                       noise_sigma: float = 1.0, min_pixels: int = 5,
                       max_relative_residual: float = 0.35, residual_sigmas: float = 3.0,
                       slope_sigmas: float = 2.0) -> tuple[np.ndarray, StreakFits]:
    """Keep the streaks that obey the photometric constraint, Eq. (18) [GargNayar2007].

    Parameters are those of :func:`fit_streaks`.

    Returns
    -------
    accepted : (M, N) bool array
        Pixels of the accepted streaks: the estimate of the binary rain field b
        for frame n (Fig. 11(b)).
    fits : StreakFits
        Per-streak measurements, fits and verdicts.
    """
    fits, idx, li = _fit(prev, cur, nxt, mask, beta_max=beta_max, labels=labels, noise_sigma=noise_sigma,
                         min_pixels=min_pixels, max_relative_residual=max_relative_residual,
                         residual_sigmas=residual_sigmas, slope_sigmas=slope_sigmas)
    out = np.zeros(fits.labels.shape, dtype=bool)
    out.ravel()[idx] = fits.accepted[li]
    return out, fits
