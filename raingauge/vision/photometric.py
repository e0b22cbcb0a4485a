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
    "slope_uncertainty",
    "selection_pull",
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


def selection_pull(margin):
    """Mean noise of I_{n-1} of a pixel that passed the spike test, in units of sigma [dimensionless].

    Parameters
    ----------
    margin : array
        The pixel's one-frame change above the selection threshold, in units
        of the noise of a frame difference, sqrt(2) sigma [dimensionless].

    Returns
    -------
    array
        |E[e_{n-1} | selected]| / sigma = phi(d) / (sqrt(2) Phi(d)), d = max(margin, 0).

    Notes
    -----
    Eq. (19) keeps a pixel when I_n - I_{n-1} = s + e_n - e_{n-1} >= c.  With
    N = e_n - e_{n-1} (variance 2 sigma^2) and E[e_{n-1} | N] = -N / 2, the
    truncated-normal mean gives E[e_{n-1} | N >= -(s - c)] =
    -(sigma / sqrt 2) phi(d) / Phi(d) with d = (s - c) / (sqrt 2 sigma):
    0.56 sigma at the threshold, 0.20 one noise level above it and 0.04 two
    above.  Pixels at or below the threshold are given the value at d = 0.
    """
    d = np.maximum(np.asarray(margin, dtype=np.float64), 0.0)
    from scipy.special import log_ndtr

    log_phi = -0.5 * d * d - 0.5 * math.log(2.0 * math.pi)
    return np.exp(log_phi - log_ndtr(d)) / math.sqrt(2.0)


def slope_uncertainty(vxx, rss, n, near_dev, *, noise_sigma: float, score_sq=None, n_clusters=None):
    """Standard error and selection shift of the Eq. (18) slope fitted over a streak [GargNayar2007].

    The fit regresses the change y = I_n - I_{n+1} on the background
    x = I_{n-1} over the K pixels of a streak.  Both carry camera noise of
    standard deviation sigma, and the pixels were *selected* by a threshold
    on the same noisy frames (Eq. 19), so a faint streak on a background of
    little contrast gives a slope that is both noisy and biased.  The slope is
    judged against what the noise can do rather than by a hard cut.

    Parameters
    ----------
    vxx : array
        Sum of squared deviations of x about its mean over each streak
        [gray levels^2].
    rss : array
        Residual sum of squares of the least-squares line [gray levels^2].
    n : array
        Pixels per streak, K [px].
    near_dev : array
        Sum over the streak's pixels of |y_i - mean(y)| weighted by the
        pixel's :func:`selection_pull` [gray levels].
    noise_sigma : float
        Camera noise standard deviation per frame [gray levels].
    score_sq : array, optional
        Sum over the blocks of pixels of each streak of
        (sum_block r_i (x_i - mean x))^2, r the residuals [gray levels^4].
    n_clusters : array, optional
        Blocks per streak.

    Returns
    -------
    se : array
        Standard error of beta [dimensionless]; ``inf`` when the background
        does not vary over the streak (Eq. (18) cannot refute it).
    shift : array
        Largest amount by which the selection can have lowered beta
        [dimensionless]; it never raises it.

    Notes
    -----
    se^2 = s^2 / S_xx with s^2 the larger of the residual variance
    RSS / (K - 2) and the noise variance of y, 2 sigma^2.  The residual alone
    is too optimistic for faint streaks: the threshold truncates the scatter
    of y from below, so a few pixels of a 4-gray-level streak give a tiny
    residual and an apparently precise, wrong slope.  The residual is kept
    when larger (the change varies along a real streak's edges, where the
    drop covers a pixel for part of tau).

    Selection: a pixel whose change is near the threshold c passes Eq. (19)
    more easily when the noise e_x of I_{n-1} is negative
    (:func:`selection_pull`), and these are the pixels of smaller y.  The
    least-squares slope moves by sum_i E[e_x,i] (y_i - mean y) / S_xx,
    positive in dy/dx (beta lowered) and at most
    sigma sum_i pull_i |y_i - mean y| / S_xx.  Pixels far above the threshold
    are selected whatever their noise and contribute nothing: a bright
    streak gets no allowance.

    Neighbouring pixels do not deviate from the line independently: a drop
    covers the pixels at a streak's edges for part of tau only (a smaller beta
    and alpha there, the same along the whole edge), and streaks of two drops
    that touch form one component with two lines.  With ``score_sq`` the
    cluster-robust (sandwich) variance over blocks of pixels [LiangZeger1986],
    G / (G - 1) sum_g (sum_{i in g} r_i (x_i - mean x))^2 / S_xx^2, is used
    when it exceeds the independent-pixel one.
    """
    vxx = np.asarray(vxx, dtype=np.float64)
    rss = np.asarray(rss, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    near_dev = np.asarray(near_dev, dtype=np.float64)
    if not (math.isfinite(noise_sigma) and noise_sigma >= 0):
        raise ValueError(f"noise_sigma must be a non-negative number of gray levels, got {noise_sigma!r}")
    sigma = float(noise_sigma)
    s2 = np.maximum(rss / np.maximum(n - 2.0, 1.0), 2.0 * sigma * sigma)
    ok = (vxx > 0) & (n > 2)
    vxx_d = np.where(ok, vxx, 1.0)
    var = s2 / vxx_d
    if score_sq is not None:
        g = np.asarray(n_clusters, dtype=np.float64)
        multi = g > 1
        var_cr = np.where(multi, g / np.where(multi, g - 1.0, 1.0), 0.0) * np.asarray(score_sq, np.float64) / vxx_d ** 2
        var = np.maximum(var, var_cr)
    se = np.where(ok, np.sqrt(var), np.inf)
    shift = np.where(ok, sigma * near_dev / vxx_d, np.inf)
    return se, shift


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
    beta_se: np.ndarray         # standard error of beta (cluster-robust for streaks the plain one refutes)
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
                residual_sigmas: float = 3.0, slope_sigmas: float = 2.0, cluster_px: int = 8) -> StreakFits:
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
        The slope is accepted when [beta - k se, beta + k se + shift] meets
        [0, beta_max], with k = slope_sigmas, se the standard error of beta
        given the noise and shift the largest lowering of beta by the
        threshold selection (:func:`slope_uncertainty`).  The shift and the
        cluster-robust error only widen the interval, so they are evaluated
        for the streaks the plain interval refutes.
    cluster_px : int
        Side of the square blocks of pixels whose residuals are taken as
        correlated in the slope's error [px] (cluster-robust variance, see
        :func:`slope_uncertainty`); 0 or 1 treats pixels as independent.

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
    refute it.  The slope's error comes from the noise, not from the scatter
    of the selected pixels alone: a faint streak (a few gray levels, a few
    noise levels) has a slope barely measurable over its background, and the
    threshold that selected its pixels biases that slope negative; both are
    allowed for (:func:`slope_uncertainty`, :func:`selection_pull`), so faint
    rain is no longer rejected for a slope the noise made, while a bright
    blob whose change grows with the background (beta < 0) or follows it
    (beta ~ 1) is still refuted.
    """
    return _fit(prev, cur, nxt, mask, beta_max=beta_max, labels=labels, noise_sigma=noise_sigma,
                min_pixels=min_pixels, max_relative_residual=max_relative_residual,
                residual_sigmas=residual_sigmas, slope_sigmas=slope_sigmas, cluster_px=cluster_px)[0]


def _fit(prev, cur, nxt, mask, *, beta_max, labels, noise_sigma, min_pixels, max_relative_residual,
         residual_sigmas, slope_sigmas, cluster_px=8):
    if not (math.isfinite(beta_max) and beta_max > 0):
        raise ValueError(f"beta_max must be a positive number, got {beta_max!r}")
    if labels is None:
        lab, n = _label(mask)
    else:
        lab, n = labels
    flat_lab = lab.ravel()
    idx = np.flatnonzero(np.asarray(mask).ravel()) if labels is None else np.flatnonzero(flat_lab)
    li = flat_lab[idx]
    idx, lj, keep_ids = _big_streaks(idx, li, n, min_pixels)
    x = prev.ravel()[idx].astype(np.float64)                           # background I_{n-1}
    z = nxt.ravel()[idx].astype(np.float64)                            # background I_{n+1}
    c = cur.ravel()[idx]
    t = _streak_tests(idx, lj, keep_ids.size, x, c, z, lab.shape, beta_max=beta_max, noise_sigma=noise_sigma,
                      max_relative_residual=max_relative_residual, residual_sigmas=residual_sigmas,
                      slope_sigmas=slope_sigmas, cluster_px=cluster_px)
    m = keep_ids.size
    cols = lab.shape[1]
    lj, cnt, safe = t["lj"], t["cnt"], t["safe"]
    rr = (idx // cols).astype(np.float64)
    cc = (idx % cols).astype(np.float64)
    sr = np.bincount(lj, rr, m)
    sc = np.bincount(lj, cc, m)
    srr = np.bincount(lj, rr * rr, m)
    scc = np.bincount(lj, cc * cc, m)
    src = np.bincount(lj, rr * cc, m)
    rmin = np.full(m, np.inf); rmax = np.full(m, -np.inf)
    cmin = np.full(m, np.inf); cmax = np.full(m, -np.inf)
    _segment_min(rmin, lj, rr); _segment_max(rmax, lj, rr)
    _segment_min(cmin, lj, cc); _segment_max(cmax, lj, cc)
    bbox = np.column_stack([cmin, rmin, cmax - cmin + 1, rmax - rmin + 1]).astype(np.int32) if m else \
        np.zeros((0, 4), dtype=np.int32)

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
        minor_axis_px=minor, mean_change=t["my"], max_change=t["ymax"], mean_background=t["mx"], beta=t["beta"],
        alpha=t["alpha"], beta_se=t["se"], residual_rms=t["resid_rms"], background_change_rms=t["bg_change"],
        linear=t["linear"], slope_ok=t["slope_ok"], stationary=t["stationary"], accepted=t["accepted"],
    )
    return fits, idx, lj


def _big_streaks(idx, li, n, min_pixels):
    """The pixels of the streaks of at least ``min_pixels``: (idx, compact streak index, label of each streak)."""
    # Discard the streaks too small to be rain before any fitting.
    area_all = np.bincount(li, minlength=n + 1)
    big = area_all >= max(int(min_pixels), 1)
    big[0] = False
    keep_ids = np.flatnonzero(big)
    # (np.take and the positions of the kept pixels: several times quicker than
    # boolean-mask indexing on the many small components of a noisy frame)
    sel = np.flatnonzero(np.take(big, li))
    idx, li = np.take(idx, sel), np.take(li, sel)
    compact = np.zeros(n + 1, dtype=np.int64)
    compact[keep_ids] = np.arange(keep_ids.size)
    return idx, np.take(compact, li), keep_ids


def _streak_tests(idx, lj, m, x, c, z, shape, *, beta_max, noise_sigma, max_relative_residual, residual_sigmas,
                  slope_sigmas, cluster_px=8, ymax=True):
    """The Eq. (18) fit and tests of :func:`fit_streaks` on the pixels of m streaks.

    ``idx`` are the flat pixel indices in a frame of ``shape``, in increasing
    order, ``lj`` their streak (0..m-1), ``x`` and ``z`` the float64 values of
    I_{n-1} and I_{n+1}, ``c`` those of I_n.  Every per-streak sum runs over
    the pixels in the order given, so the result does not depend on how the
    streaks are numbered.
    """
    cols = shape[1]
    y = c.astype(np.float64) - z                                       # change against I_{n+1}
    cnt = np.bincount(lj, minlength=m).astype(np.float64)
    sx = np.bincount(lj, x, m)
    sy = np.bincount(lj, y, m)
    sxx = np.bincount(lj, x * x, m)
    sxy = np.bincount(lj, x * y, m)
    syy = np.bincount(lj, y * y, m)
    sbb = np.bincount(lj, (x - z) ** 2, m)
    ym = None
    if ymax:
        ym = np.full(m, -np.inf)
        _segment_max(ym, lj, y)

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
    resid_rms = np.sqrt(rss / safe)
    beta = -slope
    alpha = my - slope * mx
    vxx_fit = np.where(determined, vxx, 0.0)
    zero = np.zeros(m)
    se, shift = slope_uncertainty(vxx_fit, rss, cnt, zero, noise_sigma=float(noise_sigma))
    with np.errstate(invalid="ignore"):
        refuted = ~((beta + slope_sigmas * se >= 0.0) & (beta - slope_sigmas * se <= beta_max))
    if refuted.any():
        # Only a streak the independent-pixel error refutes needs the wider
        # allowances (they can only widen the interval): the selection shift
        # and the cluster-robust error, on its pixels alone.
        on = refuted[lj]
        sj, sx_, sy_, sz_, sidx = lj[on], x[on], y[on], z[on], idx[on]
        # Mean noise of I_{n-1} among the pixels that passed the threshold, in
        # units of sigma, from each pixel's one-frame change above the
        # streak's weakest (an estimate of the threshold it was selected by).
        spike = sy_ + sz_ - np.maximum(sx_, sz_)
        smin = np.full(m, np.inf)
        _segment_min(smin, sj, spike)
        pull = selection_pull((spike - smin[sj]) / (math.sqrt(2.0) * max(float(noise_sigma), 1e-12)))
        near_dev = np.bincount(sj, pull * np.abs(sy_ - my[sj]), m)
        score_sq = n_clusters = None
        if cluster_px and cluster_px > 1:
            # residual scores summed over blocks of cluster_px x cluster_px pixels of each streak
            bpx = int(cluster_px)
            nbc = cols // bpx + 1
            block = (sidx // cols) // bpx * nbc + (sidx % cols) // bpx
            stride = (shape[0] // bpx + 1) * nbc
            uniq, inv = np.unique(sj * stride + block, return_inverse=True)
            owner = uniq // stride
            res = sy_ - my[sj] - slope[sj] * (sx_ - mx[sj])
            g = np.bincount(inv, res * (sx_ - mx[sj]), uniq.size)
            score_sq = np.bincount(owner, g * g, m)
            n_clusters = np.bincount(owner, minlength=m)
        se_w, shift_w = slope_uncertainty(vxx_fit, rss, cnt, near_dev, noise_sigma=float(noise_sigma),
                                          score_sq=score_sq, n_clusters=n_clusters)
        se = np.where(refuted, se_w, se)
        shift = np.where(refuted, shift_w, 0.0)

    noise_dn = residual_sigmas * math.sqrt(2.0) * float(noise_sigma)
    allowance = noise_dn + max_relative_residual * np.maximum(my, 0.0)
    linear = resid_rms <= allowance
    # Eq. (19) also says I_{n-1} = I_{n+1} under a streak: the background is stationary.
    bg_change = np.sqrt(sbb / safe)
    stationary = bg_change <= allowance
    with np.errstate(invalid="ignore"):
        lo = beta - slope_sigmas * se
        hi = beta + slope_sigmas * se + shift
    slope_ok = (hi >= 0.0) & (lo <= beta_max)
    accepted = linear & slope_ok & stationary & (my > 0)
    return dict(lj=lj, cnt=cnt, safe=safe, mx=mx, my=my, ymax=ym, beta=beta, alpha=alpha, se=se,
                resid_rms=resid_rms, bg_change=bg_change, linear=linear, slope_ok=slope_ok,
                stationary=stationary, accepted=accepted)


def _label_pixels(flat, shape):
    """8-connected components of the sparse pixel set ``flat`` (increasing flat indices), ((P,) labels 1..n, n).

    The same components as :func:`_label` on the mask of these pixels,
    possibly numbered differently, at a cost that grows with the pixels
    rather than the frame.
    """
    flat = np.asarray(flat, np.int64)
    P = flat.size
    if P == 0:
        return np.zeros(0, np.int64), 0
    W = int(shape[1])
    col = flat % W
    ii = np.arange(P)
    # forward neighbours: the right one (next in the sorted list if present) and
    # the three below (consecutive in the list from the first one >= flat + W - 1);
    # the other four are their mirror images
    right = np.flatnonzero((flat[1:] == flat[:-1] + 1) & (col[:-1] < W - 1))
    src, dst = [right], [right + 1]
    pos0 = np.searchsorted(flat, flat + (W - 1))
    for k in range(3):
        pos = np.minimum(pos0 + k, P - 1)
        d = flat[pos] - flat - W          # -1, 0, 1: below left, below, below right
        hit = ((d == 0) | ((d == -1) & (col > 0)) | ((d == 1) & (col < W - 1))) & (pos0 + k < P)
        src.append(ii[hit])
        dst.append(pos[hit])
    src = np.concatenate(src)
    dst = np.concatenate(dst)
    lab = _merge_edges(src, dst, P)
    if lab is None:     # slow to converge (long winding shapes): a graph library
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        graph = coo_matrix((np.ones(src.size, np.int8), (src, dst)), shape=(P, P)).tocsr()
        n, lab = connected_components(graph, directed=False)
        return lab.astype(np.int64) + 1, int(n)
    roots = np.cumsum(lab == ii)      # the roots numbered 1..n
    return roots[lab], int(roots[-1])


def _merge_edges(src, dst, P, max_rounds=64):
    """Connected components of P nodes joined by the edges (src, dst): each node's root (a node of its
    component, the same for the whole component), or None when ``max_rounds`` were not enough.

    Every round hooks, for each edge whose two ends disagree, the larger of
    their labels onto the smaller, then follows the labels to their roots;
    labels only ever become labels of connected nodes, and the rounds end
    when every edge has one label at both ends.
    """
    lab = np.arange(P)
    for _ in range(max_rounds):
        a = lab[src]
        b = lab[dst]
        differ = a != b
        if not differ.any():
            return lab
        a, b = a[differ], b[differ]
        np.minimum.at(lab, np.maximum(a, b), np.minimum(a, b))
        while True:
            up = lab[lab]
            if np.array_equal(up, lab):
                break
            lab = up
    return None


def _accept_pixels(flat, x, c, z, shape, *, beta_max, noise_sigma, min_pixels, max_relative_residual=0.35,
                   residual_sigmas=3.0, slope_sigmas=2.0, cluster_px=8):
    """:func:`photometric_filter` on a sparse pixel set: the accepted pixels of ``flat``, (P,) bool.

    ``flat`` are increasing flat indices of the candidate pixels in a frame of
    ``shape``, ``x``, ``c``, ``z`` the (P,) values of I_{n-1}, I_n, I_{n+1}
    there; the verdicts equal those of :func:`photometric_filter` on frames
    holding these values.
    """
    import cv2

    if not (math.isfinite(beta_max) and beta_max > 0):
        raise ValueError(f"beta_max must be a positive number, got {beta_max!r}")
    if flat.size * 128 < shape[0] * shape[1]:
        li, n = _label_pixels(flat, shape)
    else:   # dense: the frame-sized labelling is cheaper
        m8 = np.zeros(shape, np.uint8)
        m8.ravel()[flat] = 1
        n, lab = cv2.connectedComponents(m8, connectivity=8, ltype=cv2.CV_32S)
        li, n = lab.ravel()[flat], n - 1
    pos = np.arange(flat.size)
    pos, lj, keep_ids = _big_streaks(pos, li, n, min_pixels)
    out = np.zeros(flat.size, bool)
    if keep_ids.size == 0:
        return out
    t = _streak_tests(flat[pos], lj, keep_ids.size, np.asarray(x)[pos].astype(np.float64), np.asarray(c)[pos],
                      np.asarray(z)[pos].astype(np.float64), shape, beta_max=beta_max, noise_sigma=noise_sigma,
                      max_relative_residual=max_relative_residual, residual_sigmas=residual_sigmas,
                      slope_sigmas=slope_sigmas, cluster_px=cluster_px, ymax=False)
    out[pos] = t["accepted"][lj]
    return out


def _accepted_mask(prev, cur, nxt, mask, *, beta_max, noise_sigma=1.0, min_pixels=5, max_relative_residual=0.35,
                   residual_sigmas=3.0, slope_sigmas=2.0, cluster_px=8, labels_out=None, with_index=False):
    """The accepted mask of :func:`photometric_filter` and the number of accepted streaks, without the fits.

    ``mask`` is a C-contiguous (M, N) bool array; ``labels_out`` an optional
    (M, N) int32 array that receives the label image (scratch space).  With
    ``with_index`` the flat indices of the accepted pixels (increasing) come third.
    """
    import cv2

    if not (math.isfinite(beta_max) and beta_max > 0):
        raise ValueError(f"beta_max must be a positive number, got {beta_max!r}")
    m8 = mask.view(np.uint8)
    # Wu's scan (SAUF) is the quickest on sparse candidate masks; the verdicts
    # do not depend on how the streaks are numbered
    n, lab = cv2.connectedComponentsWithAlgorithm(m8, 8, cv2.CV_32S, cv2.CCL_WU, labels_out)
    idx = np.flatnonzero(mask.ravel())
    idx, lj, keep_ids = _big_streaks(idx, np.take(lab.ravel(), idx), n - 1, min_pixels)
    out = np.zeros(mask.shape, bool)
    if keep_ids.size == 0:
        return (out, 0, idx[:0]) if with_index else (out, 0)
    x = np.take(prev.ravel(), idx).astype(np.float64)
    z = np.take(nxt.ravel(), idx).astype(np.float64)
    t = _streak_tests(idx, lj, keep_ids.size, x, np.take(cur.ravel(), idx), z, mask.shape, beta_max=beta_max,
                      noise_sigma=noise_sigma, max_relative_residual=max_relative_residual,
                      residual_sigmas=residual_sigmas, slope_sigmas=slope_sigmas, cluster_px=cluster_px, ymax=False)
    acc = t["accepted"]
    on = acc[lj]
    out.ravel()[idx] = on
    if with_index:
        return out, int(np.count_nonzero(acc)), idx[on]
    return out, int(np.count_nonzero(acc))


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
                       slope_sigmas: float = 2.0, cluster_px: int = 8) -> tuple[np.ndarray, StreakFits]:
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
                         residual_sigmas=residual_sigmas, slope_sigmas=slope_sigmas, cluster_px=cluster_px)
    out = np.zeros(fits.labels.shape, dtype=bool)
    out.ravel()[idx] = fits.accepted[li]
    return out, fits
