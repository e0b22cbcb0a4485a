"""Per-streak measurement of focused drops (Sec. 8 [GargNayar2007]).

A drop of radius a at depth z, falling at v during the exposure T, draws a
streak of width w = 2 f a / z and length L = f v T / z + w pixels (Eq. 26 as
corrected, and Fig. 20(b)).  Inverting, with the depth z,

    a = w z / (2 f),        v = (L - w) z / (f T).                    (Sec. 8)

The gauge measures w and L with sub-pixel accuracy:

* **Length.**  The row sums of the streak's change image along the fall
  direction form a box of length v_i T (the drop's image motion) convolved
  with the drop's projected disc and the blur.  That kernel is symmetric, so
  the two crossings of half the plateau height lie exactly at the ends of the
  box: their distance is v_i T whatever the blur, sub-pixel by interpolation.
* **Width.**  The profile across the streak, collected from every row of the
  plateau and aligned on the streak's axis (a super-resolved profile, as each
  row samples the axis at another sub-pixel phase), is fitted by the chord of
  a disc of diameter w (the time a pixel spends under a passing disc,
  2 sqrt(a^2 - x^2) / v_i, Eq. (29)) convolved with a Gaussian of standard
  deviation s that holds the pixel's own box (1/12 px^2), the optics and the
  defocus.  s beyond the sharp-focus value gives the blur circle, hence the
  depth (depth from defocus, up to the near/far ambiguity that the velocity
  law resolves).

:class:`StreakProps` computes these lazily by fits, like scikit-image's
``regionprops``; :func:`measure_streak_table` is the gauge's closed-form fast
path for all streaks of a frame at once (moments across the streak refined by
a least-squares box width, half-plateau end crossings corrected by the exact
cap offset :func:`cap_offset_px`), as accurate for uniform streaks
(tests/test_gauge_streaks.py) and some 50 times cheaper; :func:`detect_streaks` is the gauge's fast path from three
frames to labelled streaks (Eq. (19) on a change image smoothed along the fall
direction), with pieces of one streak merged.
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from raingauge.gauge import _kernels

__all__ = [
    "StreakProps",
    "StreakSet",
    "change_images",
    "spike_image",
    "measure_streak_table",
    "cap_offset_px",
    "slant_end_shift_px",
    "detect_streaks",
    "smoothed_spike",
    "measure_streaks",
    "chord_gauss_profile",
    "fit_cross_profile",
    "half_level_span",
    "box_gauss_profile",
    "PROFILE_SHAPES",
    "fit_along_profile",
    "fit_along_profiles",
    "fit_cross_profiles",
    "fit_batch",
    "fall_kernel",
    "radius_from_width_m",
    "velocity_from_length_m_s",
    "depth_from_blur_m",
    "SHARP_SIGMA_PX",
]

#: Standard deviation of a sharp streak edge beyond the pixel's own box [px]:
#: a small optical spread, the floor of the fitted blur s (the pixel box is
#: modelled exactly).
SHARP_SIGMA_PX = 0.1

_GL_X, _GL_W = np.polynomial.legendre.leggauss(12)


# ---------------------------------------------------------------- equations
def radius_from_width_m(width_px, z_m, *, focal_length_px: float):
    """Drop radius from the streak width, a = w z / (2 f) (Sec. 8 [GargNayar2007]).

    Parameters
    ----------
    width_px : array_like
        Focused streak width w [px].
    z_m : array_like
        Drop depth z [m].
    focal_length_px : float
        Focal length f [px].

    Returns
    -------
    ndarray
        Radius a [m].

    Notes
    -----
    Inverse of Eq. (26) as corrected, w = 2 f a / z (the text's f z / a is a
    slip); valid while w > 1 px.
    """
    return np.asarray(width_px, dtype=float) * np.asarray(z_m, dtype=float) / (2.0 * focal_length_px)


def velocity_from_length_m_s(length_px, width_px, z_m, *, focal_length_px: float, exposure_s: float):
    """Drop speed from the streak length, v = (L - w) z / (f T) (Sec. 8 [GargNayar2007]).

    Parameters
    ----------
    length_px : array_like
        Streak length L [px] (end to end, the drop's image included).
    width_px : array_like
        Streak width w [px].
    z_m : array_like
        Depth z [m].
    focal_length_px : float
        Focal length f [px].
    exposure_s : float
        Exposure time T [s].

    Returns
    -------
    ndarray
        Speed [m/s].
    """
    motion = np.asarray(length_px, dtype=float) - np.asarray(width_px, dtype=float)
    return motion * np.asarray(z_m, dtype=float) / (focal_length_px * exposure_s)


def depth_from_blur_m(blur_px, *, focal_length_px: float, f_number: float, focus_distance_m: float,
                      pixel_pitch_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The two depths whose thin-lens blur circle has diameter b [Horn1986].

    Inverts ``raingauge.physics.camera.blur_circle_px``:
    b = K |z - z0| / z with K = (f_m/N) f_m / ((z0 - f_m) p), so
    z_near = K z0 / (K + b) and z_far = K z0 / (K - b) (infinite when b >= K).

    Parameters
    ----------
    blur_px : array_like
        Blur-circle diameter b [px] (>= 0).
    focal_length_px, f_number, focus_distance_m, pixel_pitch_m : float
        Camera: f [px], N [-], z0 [m], pixel pitch [m].

    Returns
    -------
    (z_near, z_far) : ndarrays [m]
    """
    fm = focal_length_px * pixel_pitch_m
    k = (fm / f_number) * fm / ((focus_distance_m - fm) * pixel_pitch_m)
    b = np.abs(np.asarray(blur_px, dtype=float))
    z0 = focus_distance_m
    near = k * z0 / (k + b)
    with np.errstate(divide="ignore"):
        far = np.where(b < k, k * z0 / np.maximum(k - b, 1e-300), np.inf)
    return near, far


# ---------------------------------------------------------------- 1-D fits
def chord_gauss_profile(xi, *, amplitude: float, centre: float, width: float, sigma: float):
    """Cross-profile of a streak: a disc's chord convolved with a Gaussian.

    m(x) = A int sqrt(1 - (2u/w)^2) g_s(x - x0 - u) du / int g_s,
    the time a pixel at offset x spends under a disc of diameter w sweeping
    past (Eq. (29) [GargNayar2007], tau ~ 2 sqrt(a^2 - rho^2) / v), spread by
    the pixel box, the optics and the defocus (a Gaussian of std s).

    Parameters
    ----------
    xi : array_like
        Offsets across the streak [px].
    amplitude : float
        Peak of the sharp chord A [gray levels].
    centre : float
        Axis position x0 [px].
    width : float
        Chord (drop image) diameter w [px] (> 0).
    sigma : float
        Gaussian standard deviation s [px] (> 0).

    Returns
    -------
    ndarray
        Profile [gray levels], the shape of ``xi``.
    """
    x = np.asarray(xi, dtype=float)[..., None] - centre
    half = 0.5 * width
    u = half * _GL_X
    chord = np.sqrt(np.clip(1.0 - _GL_X ** 2, 0.0, None))
    g = np.exp(-0.5 * ((x - u) / sigma) ** 2) / (sigma * math.sqrt(2 * math.pi))
    return amplitude * half * np.sum(_GL_W * chord * g, axis=-1)


def _lm_batch(model, p0, lo, hi, y, wts, *, iters: int = 10):
    """Levenberg-Marquardt on B independent problems at once (padding has weight 0).

    ``model(P, idx)`` maps (b, n) parameters of the data rows ``idx`` to (b, K)
    predictions.  Problems that have converged drop out of the iteration.
    Returns (P, J, residuals) with J the (B, K, n) Jacobian of the weighted residuals.
    """
    p = np.clip(np.asarray(p0, dtype=float), lo, hi)
    b, n = p.shape

    def resid(pp, idx):
        return (model(pp, idx) - y[idx]) * wts[idx]

    def jacobian(pp, r0, idx):
        h = 1e-4 * np.maximum(np.abs(pp), 1e-2)
        m = pp.shape[0]
        # all n shifted copies in one model call
        q = np.repeat(pp[None, :, :], n, axis=0)
        q[np.arange(n), :, np.arange(n)] += h.T
        rr = resid(q.reshape(n * m, -1), np.tile(idx, n)).reshape(n, m, -1)
        return np.moveaxis((rr - r0[None]) / h.T[:, :, None], 0, -1)

    everything = np.arange(b)
    r = resid(p, everything)
    cost = np.einsum("bk,bk->b", r, r)
    jac = jacobian(p, r, everything)
    lam = np.full(b, 1e-2)
    active = np.ones(b, bool)
    eye = np.eye(n)
    for _ in range(iters):
        idx = np.nonzero(active)[0]
        if idx.size == 0:
            break
        ja, ra = jac[idx], r[idx]
        jtj = np.einsum("bkn,bkm->bnm", ja, ja)
        g = np.einsum("bkn,bk->bn", ja, ra)
        diag = np.einsum("bnn->bn", jtj)
        a = jtj + (lam[idx, None] * (diag + 1e-9))[:, :, None] * eye
        try:
            step = -np.linalg.solve(a, g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            step = -g / (lam[idx, None] * (diag + 1e-9) + 1e-12)
        pn = np.clip(p[idx] + step, lo[idx], hi[idx])
        rn = resid(pn, idx)
        cn = np.einsum("bk,bk->b", rn, rn)
        better = cn < cost[idx]
        gain = np.where(better, (cost[idx] - cn) / np.maximum(cost[idx], 1e-300), 0.0)
        up = idx[better]
        if up.size:
            p[up] = pn[better]
            r[up] = rn[better]
            cost[up] = cn[better]
            jac[up] = jacobian(p[up], r[up], up)
        lam[idx] = np.where(better, np.maximum(lam[idx] / 5, 1e-7), np.minimum(lam[idx] * 8, 1e8))
        # converged: tiny gain after a step, or stuck at large damping
        done = (better & (gain < 1e-5)) | (lam[idx] > 1e4)
        active[idx[done]] = False
    return p, jac, r


def _param_errors(jac, r, dof):
    """Standard errors of the parameters from the (B, K, n) Jacobian (B, n)."""
    s2 = np.einsum("bk,bk->b", r, r) / np.maximum(dof, 1)
    jtj = np.einsum("bkn,bkm->bnm", jac, jac)
    cov = np.linalg.pinv(jtj) * s2[:, None, None]
    return cov


def _chord_gauss_batch(xi, params):
    amp, cen, w, s = (params[:, k][:, None, None] for k in range(4))
    s = np.sqrt(s * s + 1.0 / 12.0)          # the pixel's box, as a Gaussian
    x = xi[None, :, None] - cen
    half = 0.5 * w
    u = half * _GL_X[None, None, :]
    chord = np.sqrt(np.clip(1.0 - _GL_X ** 2, 0.0, None))
    g = np.exp(-0.5 * ((x - u) / s) ** 2) / (s * math.sqrt(2 * math.pi))
    return (amp[..., 0] * half[..., 0]) * np.sum(_GL_W * chord * g, axis=-1)


def _erf_antiderivative(t):
    from scipy.special import erf

    return t * erf(t) + np.exp(-t * t) / math.sqrt(math.pi)


def _box_gauss_batch(xi, params):
    """Box of width w, convolved with a Gaussian s and integrated over the pixel (B, K)."""
    amp, cen, w, s = (params[:, k][:, None] for k in range(4))
    x = (xi if np.ndim(xi) == 2 else xi[None, :]) - cen
    k = 1.0 / (math.sqrt(2.0) * s)
    g = _erf_antiderivative
    hw = 0.5 * w
    acc = (g((x + 0.5 + hw) * k) - g((x - 0.5 + hw) * k) - g((x + 0.5 - hw) * k) + g((x - 0.5 - hw) * k))
    return 0.5 * amp * acc / k


def box_gauss_profile(xi, *, amplitude: float, centre: float, width: float, sigma: float):
    """Cross-profile of a uniform streak: a box of width w convolved with a Gaussian.

    The paper takes the time tau a drop spends over a pixel as the same for
    every pixel of a streak (Appendix 10.2 [GargNayar2007]: "tau and beta are
    constant for all pixels on a streak"), and Eqs. (23)-(24) spread a
    defocused drop uniformly over a streak w + b_c wide: across the streak
    the change is a box.

    Parameters
    ----------
    xi : array_like
        Offsets across the streak [px].
    amplitude : float
        Height of the box [gray levels].
    centre : float
        Axis position [px].
    width : float
        Box width [px] (> 0).
    sigma : float
        Gaussian standard deviation (pixel box, optics) [px] (> 0).
    """
    p = np.array([[amplitude, centre, width, sigma]], dtype=float)
    return _box_gauss_batch(np.asarray(xi, dtype=float).ravel(), p)[0].reshape(np.shape(xi))


#: Cross-profile shapes: ``"uniform"`` (the paper's constant tau, Eqs. 23-24) or
#: ``"chord"`` (tau ~ 2 sqrt(a^2 - rho^2) / v of Eq. (29) resolved across the streak).
PROFILE_SHAPES = ("uniform", "chord")


def fit_cross_profile(xi, values, *, sigma_min: float = SHARP_SIGMA_PX, weights=None,
                      shape: str = "uniform") -> dict:
    """Least-squares fit of a streak's cross-profile (one streak; see :func:`fit_cross_profiles`).

    Parameters
    ----------
    xi : (K,) array
        Offsets across the streak [px].
    values : (K,) array
        Mean change at those offsets [gray levels].
    sigma_min : float
        Smallest allowed s, the sharp-focus spread [px].
    weights : (K,) array, optional
        Inverse standard errors of ``values``.
    shape : str
        ``"uniform"`` (:func:`box_gauss_profile`, the paper's model) or
        ``"chord"`` (:func:`chord_gauss_profile`).

    Returns
    -------
    dict
        ``amplitude, centre, width, sigma`` and the standard errors
        ``width_err, sigma_err``; ``width_apparent``, the width of a sharp
        profile of the same shape and variance (blur included); ``chi2``, the
        reduced chi-square of the fit (about 1 for one streak in noise of the
        given weights; two streaks side by side fit badly); ``ok``.
    """
    w = None if weights is None else np.asarray(weights, dtype=float)
    return fit_cross_profiles([(np.asarray(xi, dtype=float), np.asarray(values, dtype=float), w)],
                              sigma_min=sigma_min, shape=shape)[0]


_BAD_CROSS = {"amplitude": 0.0, "centre": 0.0, "width": float("nan"), "sigma": float("nan"),
              "width_err": float("inf"), "sigma_err": float("inf"), "width_apparent": float("nan"),
              "chi2": float("inf"), "ok": False}


def _pad(arrays, fill=0.0):
    k = max(a.size for a in arrays)
    out = np.full((len(arrays), k), fill, dtype=float)
    for i, a in enumerate(arrays):
        out[i, :a.size] = a
    return out


def fit_cross_profiles(data, *, sigma_min: float = SHARP_SIGMA_PX, shape: str = "uniform") -> list[dict]:
    """Fit many cross-profiles at once (one Levenberg-Marquardt over the batch).

    Parameters
    ----------
    data : list of (xi, values, weights)
        Per streak: offsets [px], mean change [gray levels], inverse standard
        errors (or None).
    sigma_min : float
        Smallest allowed s [px].
    shape : str
        ``"uniform"`` or ``"chord"`` (see :func:`fit_cross_profile`).

    Returns
    -------
    list of dicts as :func:`fit_cross_profile`.
    """
    if shape not in PROFILE_SHAPES:
        raise ValueError(f"unknown profile shape {shape!r}; valid: {list(PROFILE_SHAPES)}")
    var_k = 12.0 if shape == "uniform" else 16.0
    out: list[dict | None] = [None] * len(data)
    rows = []
    for i, (xi, y, wts) in enumerate(data):
        xi = np.asarray(xi, dtype=float)
        y = np.asarray(y, dtype=float)
        if xi.size < 6:
            out[i] = dict(_BAD_CROSS)
            continue
        wts = np.ones_like(y) if wts is None else np.asarray(wts, dtype=float)
        pos = np.clip(y, 0.0, None)
        total = pos.sum()
        if total <= 0:
            out[i] = dict(_BAD_CROSS)
            continue
        c0 = float(np.sum(pos * xi) / total)
        var0 = float(np.sum(pos * (xi - c0) ** 2) / total)
        w0 = max(math.sqrt(var_k * max(var0 - 1.0 / 12.0 - sigma_min ** 2, 0.04)), 0.6)
        step = float(np.median(np.diff(np.sort(xi))))
        a0 = max(total * step / ((1.0 if shape == "uniform" else math.pi / 4) * w0), 1e-3)
        rows.append((i, xi, y, wts, [a0, c0, w0, sigma_min * 1.2],
                     [0.0, c0 - 3.0, 0.2, sigma_min],
                     [np.inf, c0 + 3.0, max(4 * w0 + 10, 50.0), max(20.0, 3 * w0)]))
    if rows:
        idx = [r[0] for r in rows]
        xi = _pad([r[1] for r in rows])
        y = _pad([r[2] for r in rows])
        wts = _pad([r[3] for r in rows])
        p0 = np.array([r[4] for r in rows])
        lo = np.array([r[5] for r in rows])
        hi = np.array([r[6] for r in rows])
        if shape == "uniform":
            def model(P, idx):
                return _box_gauss_batch(xi[idx], P)
        else:
            def model(P, idx):
                return np.stack([_chord_gauss_batch(xi[i], P[j:j + 1])[0] for j, i in enumerate(idx)])
        p, jac, r = _lm_batch(model, p0, lo, hi, y, wts)
        dof = np.array([row[1].size for row in rows]) - 4
        chi2 = np.einsum("bk,bk->b", r, r) / np.maximum(dof, 1)
        try:
            cov = _param_errors(jac, r, dof)
            errs = np.sqrt(np.clip(np.einsum("bnn->bn", cov), 0.0, None))
        except np.linalg.LinAlgError:
            errs = np.full(p.shape, np.inf)
        for j, i in enumerate(idx):
            amp, cen, w, sg = (float(v) for v in p[j])
            w_app = math.sqrt(var_k * max(w * w / var_k + sg * sg - sigma_min ** 2, 0.0))
            out[i] = {"amplitude": amp, "centre": cen, "width": w, "sigma": sg,
                      "width_err": float(errs[j, 2]), "sigma_err": float(errs[j, 3]),
                      "width_apparent": w_app, "chi2": float(chi2[j]), "ok": True}
    return out


def _semicircle_cdf_gauss_batch(t, radius, sigma):
    """CDF of the projection of a disc of ``radius`` convolved with a Gaussian (B, K)."""
    from scipy.special import ndtr

    u = radius[:, None, None] * _GL_X[None, None, :]
    dens = (2.0 / math.pi) * np.sqrt(np.clip(1.0 - _GL_X ** 2, 0.0, None))  # per unit of x in [-1,1]
    return np.sum(_GL_W * dens * ndtr((t[..., None] - u) / sigma[:, None, None]), axis=-1)


def _cap_integral(u):
    """int_{-1}^{u} sqrt(1 - x^2) dx for u clipped to [-1, 1]."""
    u = np.clip(u, -1.0, 1.0)
    return 0.5 * (u * np.sqrt(1.0 - u * u) + np.arcsin(u)) + math.pi / 4


def _capsule_cumulative(t, top, bot, r):
    """int_{-inf}^{t} of the capsule's row profile (unit plateau, caps of radius r)."""
    upper = r * _cap_integral((np.minimum(t, top) - top) / r)
    middle = np.clip(np.minimum(t, bot) - top, 0.0, None)
    lower = np.where(t > bot, r * (_cap_integral(np.clip((t - bot) / r, 0.0, 1.0)) - math.pi / 4), 0.0)
    return upper + middle + lower


def _ends_batch(t_top, t_bot, radius, sigma, shape):
    """Row-sum profile (B, K) of a streak with ends at rows top/bottom (unit plateau)."""
    if shape == "uniform":
        # pixel-integrated capsule: rows integrate [y - 1/2, y + 1/2]
        r = radius[:, None]
        length = t_top - t_bot              # bottom - top, per row (constant)
        hi = _capsule_cumulative(t_top + 0.5, 0.0, length, r)
        lo = _capsule_cumulative(t_top - 0.5, 0.0, length, r)
        return hi - lo
    ga = _semicircle_cdf_gauss_batch(t_top, radius, sigma)
    gb = _semicircle_cdf_gauss_batch(t_bot, radius, sigma)
    return ga - gb


def fit_along_profile(rows, sums, *, width: float, sigma: float, top0: float, bottom0: float,
                      weights=None, shape: str = "uniform") -> dict:
    """Fit the row sums along a streak; the motion is the distance between its ends.

    ``shape="uniform"`` (the paper's constant tau, Eqs. 23-24): the streak is
    the capsule swept by the drop's image (diameter w, blur included) with a
    constant change inside, so the row sums are a plateau with semicircular
    caps, sqrt(1 - ((y - y_end) / (w/2))^2), beyond the rows y_top and
    y_bottom of the drop centre at the start and end of the exposure.
    ``shape="chord"``: a disc sweeping, the plateau convolved with the
    projection of the disc (Fig. 20(b) [GargNayar2007]).  Either way the
    motion y_bottom - y_top does not depend on the blur.

    Parameters
    ----------
    rows : (K,) array
        Row coordinates [px].
    sums : (K,) array
        Change summed across the streak on each row [gray levels px].
    width, sigma : float
        Streak width w and edge spread s [px].
    top0, bottom0 : float
        Starting guesses of y_top, y_bottom [px] (half-level crossings).
    weights : (K,) array, optional
        Inverse standard errors of ``sums``.
    shape : str
        ``"uniform"`` or ``"chord"``.

    Returns
    -------
    dict with ``plateau, top, bottom, motion, motion_err``.
    """
    w = None if weights is None else np.asarray(weights, dtype=float)
    return fit_along_profiles([(np.asarray(rows, dtype=float), np.asarray(sums, dtype=float), w,
                                float(width), float(sigma), float(top0), float(bottom0))], shape=shape)[0]


def fit_along_profiles(data, *, shape: str = "uniform") -> list[dict]:
    """Fit many along-streak row-sum profiles at once (see :func:`fit_along_profile`).

    Parameters
    ----------
    data : list of (rows, sums, weights, width, sigma, top0, bottom0)
    shape : str
        ``"uniform"`` or ``"chord"``.
    """
    if not data:
        return []
    rows_l, y_l, w_l, p0, lo, hi, rad, sig, rel0 = [], [], [], [], [], [], [], [], []
    for rows, y, wts, width, sigma, top0, bottom0 in data:
        wts = np.ones_like(y) if wts is None else wts
        r = max(width, 0.2) / 2.0
        c = 0.87 * r if shape == "uniform" else 0.0
        t0, b0 = top0 + c, bottom0 - c
        inner = (rows > t0 + width) & (rows < b0 - width)
        plat0 = float(np.median(y[inner])) if inner.sum() >= 2 else float(np.max(y))
        rows_l.append(rows - rows[0])
        rel0.append(rows[0])
        y_l.append(y)
        w_l.append(wts)
        p0.append([plat0, t0 - rows[0], b0 - rows[0]])
        lo.append([0.0, -5.0, -5.0])
        hi.append([np.inf, rows[-1] - rows[0] + 5.0, rows[-1] - rows[0] + 5.0])
        rad.append(r)
        sig.append(max(sigma, 1e-3))
    n_k = np.array([a.size for a in rows_l])
    # pad rows with far-away coordinates (weight 0)
    rows = _pad(rows_l, fill=-1e6)
    y = _pad(y_l)
    wts = _pad(w_l)
    rad = np.array(rad)
    sig = np.array(sig)

    def model(P, idx):
        plat, top, bot = P[:, 0:1], P[:, 1:2], P[:, 2:3]
        return plat * _ends_batch(rows[idx] - top, rows[idx] - bot, rad[idx], sig[idx], shape)

    p, jac, res = _lm_batch(model, np.array(p0), np.array(lo), np.array(hi), y, wts)
    try:
        cov = _param_errors(jac, res, n_k - 3)
        m_err = np.sqrt(np.clip(cov[:, 1, 1] + cov[:, 2, 2] - 2 * cov[:, 1, 2], 0.0, None))
    except np.linalg.LinAlgError:
        m_err = np.full(len(data), np.inf)
    out = []
    for j in range(len(data)):
        top = float(p[j, 1] + rel0[j])
        bot = float(p[j, 2] + rel0[j])
        out.append({"plateau": float(p[j, 0]), "top": top, "bottom": bot, "motion": bot - top,
                    "motion_err": float(m_err[j])})
    return out


def half_level_span(profile, level: float) -> tuple[float, float] | None:
    """Sub-pixel positions where a 1-D profile first and last crosses ``level``.

    Parameters
    ----------
    profile : (K,) array
        Samples at positions 0..K-1 [any unit].
    level : float
        Crossing level [same unit].

    Returns
    -------
    (first, last) [samples], or None when the profile never reaches the level.
    """
    p = np.asarray(profile, dtype=float)
    above = np.nonzero(p >= level)[0]
    if above.size == 0:
        return None
    i0, i1 = int(above[0]), int(above[-1])
    if i0 > 0:
        a, b = p[i0 - 1], p[i0]
        first = i0 - 1 + (level - a) / (b - a) if b != a else float(i0)
    else:
        first = 0.0
    if i1 < p.size - 1:
        a, b = p[i1], p[i1 + 1]
        last = i1 + (a - level) / (a - b) if a != b else float(i1)
    else:
        last = float(p.size - 1)
    return float(first), float(last)


# ---------------------------------------------------------------- detection
def change_images(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The spike and change images of frame n.

    Parameters
    ----------
    prev, cur, nxt : (M, N) float32 arrays
        Linearised frames n-1, n, n+1 [gray levels].

    Returns
    -------
    spike : (M, N) float32
        min(I_n - I_{n-1}, I_n - I_{n+1}), the left side of Eq. (19) [GargNayar2007].
    change : (M, N) float32
        I_n - (I_{n-1} + I_{n+1}) / 2, the drop's change over its background, used
        for measuring (unbiased, with 1.5x the noise variance of one frame).
    """
    import cv2

    d1 = cv2.subtract(cur, prev)
    d2 = cv2.subtract(cur, nxt)
    spike = cv2.min(d1, d2)
    change = cv2.addWeighted(d1, 0.5, d2, 0.5, 0.0)
    return spike, change


def spike_image(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray) -> np.ndarray:
    """min(I_n - I_{n-1}, I_n - I_{n+1}), the left side of Eq. (19) [GargNayar2007], alone.

    Parameters
    ----------
    prev, cur, nxt : (M, N) arrays
        Frames n-1, n, n+1: uint8 (a linear camera; the spike is then exact in int16,
        at half the memory traffic of float32) or float32 linearised [gray levels].

    Returns
    -------
    (M, N) int16 or float32 array [gray levels]
    """
    import cv2

    # min(I_n - I_{n-1}, I_n - I_{n+1}) = I_n - max(I_{n-1}, I_{n+1}): two passes, not three
    brightest = cv2.max(prev, nxt)
    if prev.dtype == np.uint8 and cur.dtype == np.uint8 and nxt.dtype == np.uint8:
        spike = cur.astype(np.int16)
        spike -= brightest
        return spike
    return cv2.subtract(cur, brightest)


def fall_kernel(length_px: int, slope: float = 0.0) -> np.ndarray:
    """Normalised line kernel of ``length_px`` rows along the fall direction dx/dy = slope.

    Parameters
    ----------
    length_px : int
        Number of rows spanned [px] (odd).
    slope : float
        Horizontal image motion per row of the streaks (wind) [px/px].
    """
    n = int(length_px)
    half = n // 2
    reach = int(math.ceil(abs(slope) * half)) + 1
    k = np.zeros((n, 2 * reach + 1), np.float32)
    for i in range(n):
        x = reach + slope * (i - half)
        x0 = int(math.floor(x))
        frac = x - x0
        k[i, x0] += 1.0 - frac
        if frac > 0:
            k[i, x0 + 1] += frac
    return k / k.sum()


#: Largest step between the directions :func:`wind_slopes` smooths along [px/px]: over the
#: +-2 rows of a 5-row smoothing the streak then strays at most 0.25 px off one of them.
WIND_SLOPE_STEP = 0.25


def wind_slopes(drift_m_s: float, velocity_model: str = "gunn_kinzer", *,
                diameters_mm=(0.5, 5.0), step: float = WIND_SLOPE_STEP) -> list[float]:
    """Directions dx/dy [px/px] that cover the slants u / v(D) of drops of the
    ``diameters_mm`` range falling at v(D) through a cross wind u = ``drift_m_s``,
    at most ``step`` apart (:func:`detect_streaks`'s ``slopes``)."""
    from raingauge.physics.drops import fall_velocity

    u = float(drift_m_s)
    if not (math.isfinite(u) and u != 0.0):
        return [0.0]
    v = np.asarray(fall_velocity(np.asarray(diameters_mm, dtype=float) * 1e-3, model=velocity_model), dtype=float)
    lo, hi = sorted((u / float(v.max()), u / float(v.min())))
    n = max(int(math.ceil((hi - lo) / step)), 0)
    return [float(x) for x in np.linspace(lo, hi, n + 1)]


def detect_streaks(spike: np.ndarray, *, c: float = 3.0, smooth_px: int = 5, min_pixels: int = 6,
                   merge_gap_px: float = 6.0, slope: float = 0.0, slopes=None,
                   grow: float = 1.0, grow_rows: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Label candidate streaks: Eq. (19) on a change image smoothed along the fall.

    Parameters
    ----------
    spike : (M, N) float32 array, or (prev, cur, nxt)
        min(I_n - I_{n-1}, I_n - I_{n+1}) [gray levels] (see :func:`change_images`),
        or the three frames it is taken of (:func:`spike_image`; the 8-bit frames of a
        linear camera are then summed along the fall in one compiled pass, the same
        integers).
    c : float
        Detection threshold [gray levels] (the profile's ``detection_threshold_dn``).
    smooth_px : int
        Length of the vertical box filter [px] (odd); rain streaks are long
        along the fall, so averaging along it raises their signal to noise by
        sqrt(smooth_px) while isolated noise spikes fade.  1 disables it.
    min_pixels : int
        Smallest component kept [px].
    merge_gap_px : float
        Pieces of one streak (split by a dark background stretch or by noise)
        are merged when they are collinear within their widths and the gap
        between them is at most this [px].
    slope : float
        Direction of the fall in the image, dx/dy [px/px] (wind slants the
        streaks); the smoothing follows it.
    slopes : sequence of float, optional
        More directions of the fall [px/px]: the change is smoothed along each of them
        and along ``slope``, and the largest of the smoothed changes is thresholded.
        In a cross wind u each drop size slants by its own u / v(a) (the small, slow
        drops most): smoothed along another direction, a thin streak's change is
        spread off it and a faint one is lost (:func:`wind_slopes`).
    grow : float
        Hysteresis: a streak also takes the pixels of the smoothed spike at or above
        ``grow`` c within ``grow_rows`` of one of its pixels at c in the same column
        (1: none).  A faint streak over a varying background (Eq. 17: its change
        beta (E_r - E_b) follows E_b) passes c only in patches; grown along the fall
        it keeps its whole length, which its speed is read from.
    grow_rows : int
        How far the growth reaches, along the column only [px].

    Returns
    -------
    labels : (M, N) uint16 or int32 array
        0 for background, else the component's label (merged pieces share one); 16 bits
        while they hold every label.
    stats : (n + 1, 5) int array
        x, y, width, height, area of each label, as
        ``cv2.connectedComponentsWithStats``; the area is 0 for the background,
        for components under ``min_pixels`` and for pieces merged into another
        label (streaks are the labels with area > 0).
    """
    import cv2

    if not (c > 0 and math.isfinite(c)):
        raise ValueError(f"detection threshold c must be a positive number of gray levels, got {c!r}")
    extra = [float(v) for v in (slopes or ()) if abs(float(v) - slope) >= 0.05]
    if isinstance(spike, tuple):
        n_s = int(smooth_px)
        if (_kernels.AVAILABLE and abs(slope) < 0.05 and not extra and 1 < n_s <= 64 and spike[1].shape[0] > n_s
                and all(f.dtype == np.uint8 for f in spike)):
            # the same integer sums in one compiled pass over the three frames
            mask, low = _kernels.spike_masks(*spike, n_s, float(c) * n_s,
                                             float(c * grow) * n_s if grow < 1.0 else None)
            return _label_and_merge(mask, low, min_pixels=min_pixels, merge_gap_px=merge_gap_px, slope=slope,
                                    grow_slopes=extra,
                                    grow_rows=grow_rows)
        spike = spike_image(*spike)
    n_s = int(smooth_px)
    if (_kernels.AVAILABLE and (extra or abs(slope) >= 0.05) and 1 < n_s <= 64 and spike.shape[0] > n_s
            and spike.shape[1] >= 64 and spike.dtype in (np.int16, np.float32)):
        # a cross wind: the largest over the directions of the smoothed spike, thresholded, in
        # one compiled pass (smoothed_spike's filters, summed exactly: OpenCV's float32 sums
        # fall either side of a threshold they equal)
        mask, low = _kernels.slant_masks(spike, n_s, (slope, *extra), float(c),
                                         float(c * grow) if grow < 1.0 else None)
        return _label_and_merge(mask, low, min_pixels=min_pixels, merge_gap_px=merge_gap_px, slope=slope,
                                grow_slopes=extra, grow_rows=grow_rows)
    if spike.dtype == np.int16 and abs(slope) < 0.05 and not extra and 0 < smooth_px <= 64:
        # exact integer box sum (|spike| <= 255): compare the sum with n c
        n_s = max(int(smooth_px), 1)
        if n_s > 1 and spike.shape[0] > n_s:
            # vertical box sum by shifted adds (faster than a 16-bit box filter); the n // 2
            # rows at the top and bottom, where no streak is whole, stay 0
            s = np.zeros_like(spike)
            half = n_s // 2
            acc = s[half:spike.shape[0] - (n_s - 1 - half)]
            np.copyto(acc, spike[:acc.shape[0]])
            for i in range(1, n_s):
                acc += spike[i:i + acc.shape[0]]
        else:
            s = spike
        mask = cv2.compare(s, float(c) * n_s, cv2.CMP_GE)
        low = cv2.compare(s, float(c * grow) * n_s, cv2.CMP_GE) if grow < 1.0 else None
    else:
        s = smoothed_spike(spike, smooth_px=smooth_px, slope=slope, slopes=extra)
        mask = cv2.compare(s, float(c), cv2.CMP_GE)
        low = cv2.compare(s, float(c * grow), cv2.CMP_GE) if grow < 1.0 else None
    return _label_and_merge(mask, low, min_pixels=min_pixels, merge_gap_px=merge_gap_px, slope=slope,
                            grow_slopes=extra, grow_rows=grow_rows)


def smoothed_spike(spike: np.ndarray, *, smooth_px: int = 5, slope: float = 0.0, slopes=()) -> np.ndarray:
    """The spike image smoothed along the fall that :func:`detect_streaks` thresholds: over
    ``smooth_px`` rows along ``slope`` and, with more ``slopes``, the largest of it smoothed
    along each of them (float32, a new array; the spike itself for ``smooth_px`` 1)."""
    import cv2

    if spike.dtype != np.float32:
        spike = spike.astype(np.float32)
    if smooth_px <= 1:
        return spike
    if abs(slope) < 0.05 and not slopes:
        s = cv2.blur(spike, (1, int(smooth_px)))
    else:
        # (among other directions the rows are reflected at the frame's top and bottom as theirs)
        s = cv2.filter2D(spike, -1, fall_kernel(int(smooth_px), slope), borderType=cv2.BORDER_REFLECT)
    if slopes:
        # (s is this call's own array: the largest is kept in place, one buffer for the rest)
        buf = np.empty_like(s)
        for other in slopes:
            cv2.filter2D(spike, -1, fall_kernel(int(smooth_px), other), dst=buf, borderType=cv2.BORDER_REFLECT)
            cv2.max(s, buf, dst=s)
    return s


def _reach_kernel(grow_rows: int, slope: float) -> np.ndarray:
    """The structuring element of the hysteresis growth: a line of 2 ``grow_rows`` + 1 rows
    along the fall dx/dy = ``slope`` (one pixel per row, the nearest to the line; a column
    below 0.05).  Grown down the column only, a streak slanted by the wind kept only
    upright pieces of its pixels between the threshold and its growth."""
    g = int(grow_rows)
    if abs(slope) < 0.05:
        return np.ones((2 * g + 1, 1), np.uint8)
    half = int(math.ceil(abs(slope) * g))
    k = np.zeros((2 * g + 1, 2 * half + 1), np.uint8)
    rows = np.arange(-g, g + 1)
    k[rows + g, np.rint(slope * rows).astype(int) + half] = 1
    return k


def _reach_union(grow_rows: int, slopes) -> np.ndarray:
    """The union of the :func:`_reach_kernel` lines along each of ``slopes``, centred on one
    another (the hysteresis's reach along all the directions the change was smoothed along)."""
    kernels = [_reach_kernel(grow_rows, float(v)) for v in slopes]
    width = max(k.shape[1] for k in kernels)
    union = np.zeros((kernels[0].shape[0], width), np.uint8)
    for k in kernels:
        off = (width - k.shape[1]) // 2
        union[:, off:off + k.shape[1]] |= k
    return union


def _label_and_merge(mask, low, *, min_pixels, merge_gap_px, slope, grow_rows, grow_slopes=()):
    """:func:`detect_streaks` from its masks on: the hysteresis growth (with ``low``; along
    ``slope`` and each of ``grow_slopes``, the other directions the change was smoothed
    along), the labelling, the small components' area set to 0, and the merge of collinear
    pieces."""
    import cv2

    if low is not None:
        # (the union of the dilations along each direction is one dilation by the union of
        # their lines, the same pixels in one pass)
        reach = cv2.dilate(mask, _reach_union(int(grow_rows), (slope, *(grow_slopes or ()))))
        mask = cv2.bitwise_or(mask, cv2.bitwise_and(low, reach))
    if _kernels.AVAILABLE:
        # the same labels from the mask's runs (the mask is sparse: a few percent of the frame)
        labels, stats = _kernels.label_components(mask)[1:]
    else:
        # 16-bit labels halve the labelling's cost; safe while there are fewer pixels than labels
        ltype = cv2.CV_16U if cv2.countNonZero(mask) < 65000 else cv2.CV_32S
        labels, stats = cv2.connectedComponentsWithStats(mask, connectivity=8, ltype=ltype)[1:3]
        stats = stats[:, :5].copy()
        stats[0] = 0
    # components below min_pixels keep their label but get area 0 (never measured);
    # relabelling the whole frame would cost more than the rest of the detection
    stats[stats[:, 4] < min_pixels, 4] = 0
    big = np.nonzero(stats[:, 4] > 0)[0]
    # merge collinear pieces separated by a short vertical gap
    if big.size > 1 and merge_gap_px > 0:
        _merge_pieces(labels, stats, big, merge_gap_px, slope=slope)
    return labels, stats


def union_roots_dict(first, second) -> tuple[np.ndarray, np.ndarray]:
    """Union of the pairs (first[k], second[k]), in order, each second's set put under its
    first's root (path halving): the members (in order of first appearance) and the root
    of each.  The reference form of :func:`raingauge.gauge._kernels.union_roots`."""
    parent: dict[int, int] = {}

    def find(i):
        parent.setdefault(i, i)
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for ia, ib in zip(np.asarray(first).tolist(), np.asarray(second).tolist()):
        parent[find(ib)] = find(ia)
    members = np.fromiter(parent.keys(), dtype=np.int64, count=len(parent))
    roots = np.fromiter((find(i) for i in members.tolist()), dtype=np.int64, count=members.size)
    return members, roots


def _merge_pieces(labels: np.ndarray, stats: np.ndarray, big: np.ndarray, merge_gap_px: float, *,
                  slope: float = 0.0) -> None:
    """Merge collinear pieces of one streak in place (labels and stats).

    Two pieces are joined when their centres lie within their widths of each other
    across the fall, the vertical gap between their boxes is at most ``merge_gap_px``
    and their widths agree within a factor 2.  With the fall slanted by ``slope`` (dx/dy,
    the wind; from 0.05 on, as the smoothing of :func:`detect_streaks`) the centres are
    compared along it and the widths taken across it (a box's width less |slope| times
    its height), and pieces whose boxes share up to 2 |slope| rows join too (the next
    piece of a slanted streak can begin in the row where the last one ends, further
    along).  A merged group keeps the label of one of its pieces
    (the root of a union over the pairs taken in a fixed order: by rank distance in x,
    then by piece), whose stats become the group's box and total area; the other pieces
    get area 0 and their pixels that label.  No loop over groups: the boxes come from
    grouped minima and maxima, the pixels are relabelled in one gather.
    """
    x, y, w, h = (stats[big, k].astype(float) for k in range(4))
    s = float(slope) if abs(slope) >= 0.05 else 0.0
    # across the fall: the centre where its line crosses row 0, the width less the slant
    cx = x + w / 2 - s * (y + h / 2)
    w = np.maximum(w - abs(s) * h, 1.0) if s else w
    order = np.argsort(cx, kind="stable")
    idx = big[order]
    cxs = cx[order]
    ys_, ws_, hs_ = y[order], w[order], h[order]
    narrow = ws_ <= np.maximum(0.5 * hs_, 8.0)            # pieces along the fall only
    n_big = idx.size
    # candidate pairs (a, b > a) in cx order with cxs[b] - cxs[a] <= max(w_a, 3) + 2
    # (exact: half-integer centres, integer widths), listed by rank distance k = b - a, then a
    hi = np.searchsorted(cxs, cxs + np.maximum(ws_, 3) + 2, side="right")
    cnt = np.maximum(hi - np.arange(n_big) - 1, 0)
    if not cnt.any():
        return
    a_i = np.repeat(np.arange(n_big), cnt)
    k_i = np.arange(a_i.size) - np.repeat(np.cumsum(cnt) - cnt, cnt) + 1
    b_i = a_i + k_i
    gap = np.maximum(ys_[b_i] - (ys_[a_i] + hs_[a_i]), ys_[a_i] - (ys_[b_i] + hs_[b_i]))
    ratio = (ws_[a_i] + 1) / (ws_[b_i] + 1)
    ok = narrow[a_i] & narrow[b_i] & (gap >= -round(2.0 * abs(s))) & (gap <= merge_gap_px) & \
        (np.abs(cxs[b_i] - cxs[a_i]) <= 0.5 * np.minimum(ws_[a_i], ws_[b_i]) + 1.5) & \
        (ratio >= 0.5) & (ratio <= 2.0)
    if not ok.any():
        return
    sel = np.nonzero(ok)[0]
    sel = sel[np.lexsort((a_i[sel], k_i[sel]))]
    if _kernels.AVAILABLE:
        members, roots = _kernels.union_roots(stats.shape[0], idx[a_i[sel]], idx[b_i[sel]])
    else:
        members, roots = union_roots_dict(idx[a_i[sel]], idx[b_i[sel]])
    # every member of ``parent`` belongs to a group of at least two pieces
    remap = np.arange(stats.shape[0], dtype=labels.dtype)
    remap[members] = roots
    x0 = stats[members, 0]
    y0 = stats[members, 1]
    x1 = x0 + stats[members, 2]
    y1 = y0 + stats[members, 3]
    rs = np.unique(roots)
    gx0 = np.full(stats.shape[0], np.iinfo(np.int64).max)
    gy0 = gx0.copy()
    gx1 = np.full(stats.shape[0], np.iinfo(np.int64).min)
    gy1 = gx1.copy()
    np.minimum.at(gx0, roots, x0)
    np.minimum.at(gy0, roots, y0)
    np.maximum.at(gx1, roots, x1)
    np.maximum.at(gy1, roots, y1)
    area = np.bincount(roots, stats[members, 4], stats.shape[0]).astype(stats.dtype)
    stats[members, 4] = 0
    stats[rs, 0] = gx0[rs]
    stats[rs, 1] = gy0[rs]
    stats[rs, 2] = gx1[rs] - gx0[rs]
    stats[rs, 3] = gy1[rs] - gy0[rs]
    stats[rs, 4] = area[rs]
    # relabel the pixels of the merged boxes (all at once: the remap is idempotent)
    bx, by, bw, bh = gx0[rs], gy0[rs], gx1[rs] - gx0[rs], gy1[rs] - gy0[rs]
    n_cols = labels.shape[1]
    rows_per = bh
    row_start = np.repeat(by, rows_per) + (np.arange(int(rows_per.sum())) - np.repeat(np.cumsum(rows_per) - rows_per, rows_per))
    row_x0 = np.repeat(bx, rows_per)
    row_w = np.repeat(bw, rows_per)
    flat = np.repeat(row_start * n_cols + row_x0, row_w) + \
        (np.arange(int(row_w.sum())) - np.repeat(np.cumsum(row_w) - row_w, row_w))
    lab = labels.reshape(-1)
    lab[flat] = remap[lab[flat]]


# ---------------------------------------------------------------- per streak
class StreakProps:
    """Measurements of one streak, computed lazily (like ``skimage.measure.regionprops``).

    Parameters
    ----------
    label : int
        The streak's label in ``labels``.
    bbox : (x, y, width, height) ints
        Bounding box of its detected pixels [px].
    change : (M, N) float32 array
        I_n - (I_{n-1} + I_{n+1}) / 2 [gray levels].
    labels : (M, N) int array
        Streak labels (other streaks are masked out of the measurement).
    camera : CameraProfile
        Focal length, exposure, F-number, focus distance and pitch.
    margin_px : int
        Extra pixels around the box to catch the blurred ends and sides.
    noise_sigma : float
        Noise of ``change`` [gray levels].
    prev, cur : (M, N) arrays, optional
        Frames n-1 and n, for the photometric test of Eq. (18).
    shape : str
        Cross-profile model, ``"uniform"`` or ``"chord"`` (:func:`fit_cross_profile`).
    valid : (n + 1,) bool array, optional
        Which labels are streaks (``stats[:, 4] > 0``); other labelled pixels
        (specks, merged pieces) are not masked out of the measurement.
    """

    def __init__(self, label: int, bbox, change: np.ndarray, labels: np.ndarray, camera, *,
                 margin_px: int = 4, noise_sigma: float = 2.0, prev: np.ndarray | None = None,
                 cur: np.ndarray | None = None, shape: str = "uniform", valid: np.ndarray | None = None):
        self.label = int(label)
        self.bbox = tuple(int(v) for v in bbox)
        self._change = change
        self._labels = labels
        self.camera = camera
        self.margin_px = int(margin_px)
        self.noise_sigma = float(noise_sigma)
        self._prev = prev
        self._cur = cur
        self.shape = shape
        self._valid = valid

    # -- geometry of the crop
    @cached_property
    def _crop(self):
        x, y, w, h = self.bbox
        m = self.margin_px
        mh = m + max(2, w // 2)
        rows, cols = self._change.shape
        x0, x1 = max(x - mh, 0), min(x + w + mh, cols)
        y0, y1 = max(y - m, 0), min(y + h + m, rows)
        lab = self._labels[y0:y1, x0:x1]
        own = lab == self.label
        other = (lab != 0) & ~own
        if self._valid is not None:
            other &= self._valid[lab]
        img = self._change[y0:y1, x0:x1].astype(np.float64)
        return x0, y0, img, own, other

    @cached_property
    def clipped(self) -> bool:
        """True when the streak touches the frame edge (its length or width is cut)."""
        x, y, w, h = self.bbox
        rows, cols = self._change.shape
        return x <= 0 or y <= 0 or x + w >= cols or y + h >= rows

    @cached_property
    def axis(self) -> tuple[float, float, float]:
        """The streak's axis x = x_mid + slope (y - y_mid): (x_mid, y_mid, slope) [px, px, px/px]."""
        x0, y0, img, own, other = self._crop
        wts = np.where(own, np.clip(img, 0, None), 0.0)
        tot = wts.sum()
        if tot <= 0:
            x, y, w, h = self.bbox
            return x + w / 2.0, y + h / 2.0, 0.0
        yy, xx = np.mgrid[0:img.shape[0], 0:img.shape[1]]
        xm = float((wts * xx).sum() / tot)
        ym = float((wts * yy).sum() / tot)
        myy = float((wts * (yy - ym) ** 2).sum() / tot)
        mxy = float((wts * (xx - xm) * (yy - ym)).sum() / tot)
        slope = mxy / myy if myy > 1e-9 else 0.0
        return xm + x0, ym + y0, slope

    @cached_property
    def _row_width(self) -> float:
        """Width of the detected pixels along a row (area / rows) [px]."""
        x0, y0, img, own, other = self._crop
        rows = int(np.count_nonzero(own.any(axis=1)))
        return float(own.sum()) / max(rows, 1)

    @cached_property
    def _rows(self):
        """Per-row sums and aligned samples across the streak."""
        x0, y0, img, own, other = self._crop
        xm, ym, slope = self.axis
        half = 0.5 * self._row_width + 1.5 + self.margin_px / 2
        rows = np.arange(img.shape[0]) + y0
        cols = np.arange(img.shape[1]) + x0
        centre = xm + slope * (rows - ym)
        off = cols[None, :] - centre[:, None]
        band = (np.abs(off) <= half) & ~other
        row_sum = np.where(band, img, 0.0).sum(axis=1)
        row_n = band.sum(axis=1)
        return rows, off, band, row_sum, row_n, img

    @cached_property
    def _ends(self):
        """Rough ends: half-plateau crossings of the (3-row smoothed) row sums."""
        rows, off, band, row_sum, row_n, img = self._rows
        x, y, w, h = self.bbox
        sm = np.convolve(row_sum, np.ones(3) / 3.0, mode="same")
        inner = (rows >= y + 0.25 * h) & (rows <= y + 0.75 * h)
        if inner.sum() < 2:
            inner = np.ones_like(rows, dtype=bool)
        plateau = float(np.median(sm[inner]))
        if plateau <= 0:
            return None
        span = half_level_span(sm, 0.5 * plateau)
        if span is None:
            return None
        return span[0] + rows[0], span[1] + rows[0], plateau

    def _along_data(self):
        """(rows, sums, weights, width, sigma, top0, bottom0) for the along fit, or None."""
        ends = self._ends
        if ends is None:
            return None
        fit = self.cross_fit
        if not fit["ok"]:
            return None
        rows, off, band, row_sum, row_n, img = self._rows
        wts = 1.0 / (max(self.noise_sigma, 1e-3) * np.sqrt(np.maximum(row_n, 1)))
        return (rows.astype(float), row_sum, wts, fit["width_apparent"], SHARP_SIGMA_PX, ends[0], ends[1])

    @cached_property
    def along_fit(self) -> dict | None:
        """Fit of the row sums along the streak (see :func:`fit_along_profile`)."""
        data = self._along_data()
        if data is None:
            return None
        return fit_along_profiles([data], shape=self.shape)[0]

    @cached_property
    def motion_y_px(self) -> float:
        """Vertical image motion of the drop during the exposure, v_y T [px].

        From the fit of the row sums (:attr:`along_fit`): the distance between
        the drop centre's rows at the start and the end of the exposure,
        independent of the blur.
        """
        fit = self.along_fit
        if fit is None:
            return float("nan")
        return max(fit["motion"], 0.0)

    @cached_property
    def rough_motion_y_px(self) -> float:
        """Vertical motion from the half-level crossings of the row sums, less the caps
        of a uniform streak (0.87 w'/2 each end) [px]; cheap, ~1 px."""
        ends = self._ends
        w = self.cross_fit["width_apparent"]
        if ends is None or not np.isfinite(w):
            return float("nan")
        cap = 0.87 * w if self.shape == "uniform" else 0.0
        return max(ends[1] - ends[0] - cap, 0.0)

    @cached_property
    def motion_err_px(self) -> float:
        """Standard error of :attr:`motion_y_px` [px]."""
        fit = self.along_fit
        return float("inf") if fit is None else fit["motion_err"]

    @cached_property
    def motion_px(self) -> tuple[float, float]:
        """Image motion during the exposure (dx, dy) [px]."""
        my = self.motion_y_px
        return (self.axis[2] * my, my)

    @cached_property
    def row_plateau(self) -> float:
        """Change summed across the streak in its middle [gray levels px]."""
        fit = self.along_fit
        return float("nan") if fit is None else fit["plateau"]

    def _cross_data(self):
        """(offsets, mean change, weights) of the aligned cross-profile, or None."""
        rows, off, band, row_sum, row_n, img = self._rows
        ends = self._ends
        if ends is None:
            return None
        top, bot, _ = ends
        w_guess = max(self._row_width / math.sqrt(1 + self.axis[2] ** 2) - 2, 1.0)
        sel = (rows >= top + 0.5 * w_guess + 1) & (rows <= bot - 0.5 * w_guess - 1)
        if sel.sum() < 2:
            mid = 0.5 * (top + bot)
            sel = np.abs(rows - mid) <= 1.0
        cos_t = 1.0 / math.sqrt(1 + self.axis[2] ** 2)
        o = off[sel][band[sel]] * cos_t
        v = img[sel][band[sel]]
        if o.size < 6:
            return None
        bin_w = 0.5
        k = np.floor(o / bin_w).astype(int)
        kmin = k.min()
        counts = np.bincount(k - kmin)
        sums = np.bincount(k - kmin, weights=v)
        good = counts > 0
        xi = (np.nonzero(good)[0] + kmin + 0.5) * bin_w
        vals = sums[good] / counts[good]
        wts = np.sqrt(counts[good]) / max(self.noise_sigma, 1e-3)
        return xi, vals, wts

    @cached_property
    def cross_fit(self) -> dict:
        """Fit of the super-resolved cross-profile (see :func:`fit_cross_profile`)."""
        data = self._cross_data()
        if data is None:
            return dict(_BAD_CROSS)
        return fit_cross_profiles([data], shape=self.shape)[0]

    @cached_property
    def width_px(self) -> float:
        """Focused width w of the drop's image [px] (blur removed)."""
        return float(self.cross_fit["width"])

    @cached_property
    def width_err_px(self) -> float:
        """Standard error of :attr:`width_px` [px]."""
        return float(self.cross_fit["width_err"])

    @cached_property
    def apparent_width_px(self) -> float:
        """Width of a sharp streak with the same spread, blur included [px]."""
        return float(self.cross_fit["width_apparent"])

    @cached_property
    def blur_px(self) -> float:
        """Defocus blur-circle diameter b [px] (pillbox: variance b^2/16 beyond sharp focus)."""
        s = self.cross_fit["sigma"]
        if not np.isfinite(s):
            return float("nan")
        return 4.0 * math.sqrt(max(s * s - SHARP_SIGMA_PX ** 2, 0.0))

    @cached_property
    def amplitude(self) -> float:
        """Peak change of the sharp drop image [gray levels]."""
        return float(self.cross_fit["amplitude"])

    @cached_property
    def length_px(self) -> float:
        """Streak length L = |motion| + w [px] (Fig. 20(b))."""
        dx, dy = self.motion_px
        return math.hypot(dx, dy) + self.width_px

    @cached_property
    def centroid_px(self) -> tuple[float, float]:
        """Centre of the streak (x, y) [px]."""
        fit = self.along_fit
        xm, ym, slope = self.axis
        if fit is None:
            return xm, ym
        yc = 0.5 * (fit["top"] + fit["bottom"])
        return xm + slope * (yc - ym), yc

    @cached_property
    def top_px(self) -> float:
        """Row of the drop centre at the start of the exposure [px]."""
        fit = self.along_fit
        return float("nan") if fit is None else fit["top"]

    @cached_property
    def background_dn(self) -> float:
        """Mean background I_b under the streak, (I_{n-1} + I_{n+1}) / 2 [gray levels]."""
        if self._cur is None:
            return float("nan")
        x0, y0, img, own, other = self._crop
        h, w = img.shape
        cur = self._cur[y0:y0 + h, x0:x0 + w].astype(np.float64)
        if not own.any():
            return float("nan")
        return float(np.mean((cur - img)[own]))

    @cached_property
    def beta_fit(self) -> tuple[float, float] | None:
        """Photometric slope of Eq. (18) [GargNayar2007]: dI = -beta I_b + alpha.

        Fitted over the streak's own pixels when the background under it
        varies enough to fix a slope (> 4 gray levels standard deviation);
        None otherwise.
        """
        if self._prev is None or self._cur is None:
            return None
        x0, y0, img, own, other = self._crop
        h, w = img.shape
        bg = self._prev[y0:y0 + h, x0:x0 + w][own].astype(np.float64)
        di = (self._cur[y0:y0 + h, x0:x0 + w][own] - self._prev[y0:y0 + h, x0:x0 + w][own]).astype(np.float64)
        if bg.size < 6 or bg.std() < 4.0:
            return None
        slope, intercept = np.polyfit(bg, di, 1)
        return float(-slope), float(intercept)

    # -- physical units via the camera
    def radius_m(self, z_m: float | None = None) -> float:
        """Drop radius a = w z / (2 f) [m], at depth ``z_m`` (default z0)."""
        z = self.camera.focus_distance_m if z_m is None else z_m
        return float(radius_from_width_m(self.width_px, z, focal_length_px=self.camera.focal_length_px))

    def velocity_m_s(self, z_m: float | None = None) -> float:
        """Fall speed (vertical) v = v_y T z / (f T) [m/s], at depth ``z_m`` (default z0)."""
        z = self.camera.focus_distance_m if z_m is None else z_m
        return float(self.motion_y_px * z / (self.camera.focal_length_px * self.camera.exposure_s))

    def depth_candidates_m(self) -> tuple[float, float]:
        """Near and far depths whose blur circle matches :attr:`blur_px` [m]."""
        cam = self.camera
        near, far = depth_from_blur_m(self.blur_px, focal_length_px=cam.focal_length_px,
                                      f_number=cam.f_number, focus_distance_m=cam.focus_distance_m,
                                      pixel_pitch_m=cam.pixel_pitch_m or 5e-6)
        return float(near), float(far)

    def depth_m(self, velocity_model: str = "paper", *, min_blur_px: float = 0.5) -> float:
        """Depth from defocus [m]: z0 while the blur is under ``min_blur_px``;
        otherwise whichever of the near/far depths makes (a, v) agree best
        with the velocity law.
        """
        from raingauge.physics.drops import fall_velocity

        b = self.blur_px
        if not np.isfinite(b) or b < min_blur_px:
            return self.camera.focus_distance_m
        best, best_err = self.camera.focus_distance_m, float("inf")
        for z in self.depth_candidates_m():
            if not np.isfinite(z):
                continue
            a = self.radius_m(z)
            v = self.velocity_m_s(z)
            law = float(fall_velocity(2 * a, model=velocity_model))
            if np.isfinite(law) and law > 0 and v > 0:
                err = abs(math.log(v / law))
                if err < best_err:
                    best, best_err = z, err
        return best


class StreakSet(list):
    """The measured streaks of one frame (a list of :class:`StreakProps`)."""


def fit_batch(props, *, shape: str = "uniform", along: bool = True) -> None:
    """Fit the cross and along profiles of many streaks in two batched fits.

    Fills the lazily computed ``cross_fit`` and (with ``along``) ``along_fit``
    of each :class:`StreakProps` (same results as one by one, much faster).
    """
    props = list(props)
    cross = [(p, p._cross_data()) for p in props if "cross_fit" not in p.__dict__]
    todo = [(p, d) for p, d in cross if d is not None]
    for p, d in cross:
        if d is None:
            p.__dict__["cross_fit"] = dict(_BAD_CROSS)
    for (p, _), fit in zip(todo, fit_cross_profiles([d for _, d in todo], shape=shape)):
        p.__dict__["cross_fit"] = fit
    if not along:
        return
    along = [(p, p._along_data()) for p in props]
    todo = [(p, d) for p, d in along if d is not None]
    for p, d in along:
        if d is None:
            p.__dict__["along_fit"] = None
    for (p, _), fit in zip(todo, fit_along_profiles([d for _, d in todo], shape=shape)):
        p.__dict__["along_fit"] = fit


def measure_streaks(change: np.ndarray, labels: np.ndarray, stats: np.ndarray, camera, *,
                    select=None, noise_sigma: float = 2.0, prev=None, cur=None,
                    shape: str = "uniform") -> StreakSet:
    """:class:`StreakProps` for the labelled streaks (all, or the indices in ``select``).

    Parameters
    ----------
    change : (M, N) float32 array
        I_n - (I_{n-1} + I_{n+1}) / 2 [gray levels].
    labels, stats : from :func:`detect_streaks`.
    camera : CameraProfile
    select : iterable of int, optional
        Labels to measure (default: all).
    noise_sigma : float
        Noise of ``change`` [gray levels].
    """
    ids = np.nonzero(stats[:, 4] > 0)[0] if select is None else select
    out = StreakSet()
    for i in ids:
        out.append(StreakProps(int(i), stats[i, :4], change, labels, camera, noise_sigma=noise_sigma,
                               prev=prev, cur=cur, shape=shape, valid=stats[:, 4] > 0))
    fit_batch(out, shape=shape)
    return out


# ---------------------------------------------------------------- fast path (all streaks at once)
def _cap_offset_table():
    """Half-plateau crossing of a streak end beyond the drop centre's row, tabulated in w [px].

    The row sums of a uniform streak (pixel-integrated capsule, caps of radius w/2) smoothed
    over three rows cross half their plateau at a fixed distance beyond the row of the drop
    centre at the start (or end) of the exposure; averaged over the sub-pixel phase.
    """
    widths = np.geomspace(0.2, 60.0, 90)
    phases = (np.arange(16) + 0.5) / 16
    out = np.empty(widths.size)
    for i, w in enumerate(widths):
        r = 0.5 * w
        n = int(2 * w + 16)
        # rows around the top end only (the plateau below it is 1): row centre minus the end
        rows = np.arange(n)[None, :] - (w + 6) - phases[:, None]
        hi = _capsule_cumulative(rows + 0.5, 0.0, 1e6, r)
        lo = _capsule_cumulative(rows - 0.5, 0.0, 1e6, r)
        prof = hi - lo
        sm = prof.copy()
        sm[:, 1:-1] = (prof[:, :-2] + prof[:, 1:-1] + prof[:, 2:]) / 3.0
        k = np.argmax(sm >= 0.5, axis=1)
        a_ = sm[np.arange(phases.size), k - 1]
        b_ = sm[np.arange(phases.size), k]
        cross = k - 1 + (0.5 - a_) / (b_ - a_)
        out[i] = float(np.mean(-(rows[:, 0] + cross)))
    return widths, out


_CAP_TABLE = None

#: Slants |dx/dy| of a streak [px/px] and how much shorter than its drop's vertical motion
#: its measured motion then is, per pixel of its half-width w'/2 [-] (:func:`slant_end_shift_px`):
#: measured on noise-free rendered streaks (the simulator's capsules, 1.4-3.5 px in radius,
#: 30-60 px long, over a uniform backdrop at a contrast of 160), within about 20 % of it
#: over those widths.
SLANT_SHORTENING = ((0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0),
                    (0.0, 0.057, 0.139, 0.274, 0.427, 0.558, 0.63, 0.70))


def slant_end_shift_px(width_px, slope) -> np.ndarray:
    """How much nearer the rows of the drop centre each end's half-plateau crossing lies on
    a streak slanted by ``slope`` (dx/dy) than on an upright one of the same apparent width
    w' [px], :func:`cap_offset_px` less this being the slanted streak's offset.

    The rows cut a slanted end cap obliquely: the row sums fall off over the cap's
    projection along the rows, and on pixels that the slanted edge crosses part-way, so
    their half level is reached nearer the end than on an upright streak's round cap.
    Without this the motion of a streak of w' = 3.7 px slanted by 0.75 (a drop of 0.5 mm in
    focus at 2.5 m, drifting 3 m/s) was measured 0.5 px short, and of one slanted by 1.0
    0.8 px: its speed slow by 1-2 %, and a defocused drop just inside the sample volume
    falls foul of the velocity law more often than upright.  Half of
    :data:`SLANT_SHORTENING` times w' / 2 at |slope| (held beyond its last slant).
    """
    w = np.asarray(width_px, dtype=float)
    s = np.abs(np.nan_to_num(np.asarray(slope, dtype=float)))
    return 0.25 * w * np.interp(s, SLANT_SHORTENING[0], SLANT_SHORTENING[1])


def cap_offset_px(width_px) -> np.ndarray:
    """Distance from a streak end's half-plateau crossing (3-row smoothed row sums) to the
    row of the drop centre there [px], for a uniform streak of apparent width w [px].

    ~ (sqrt(3)/4) w for wide streaks (the cap sqrt(1 - (d/r)^2) is at half height at
    d = 0.87 r), less for narrow ones whose cap is spread by the pixel and the smoothing.
    """
    global _CAP_TABLE
    if _CAP_TABLE is None:
        _CAP_TABLE = _cap_offset_table()
    w, off = _CAP_TABLE
    return np.interp(np.asarray(width_px, dtype=float), w, off)


_BOX_FACTORS = np.geomspace(0.4, 2.0, 17)


def _refine_box_width(ks, o, v, cen, w0, K):
    """Least-squares width of a pixel-integrated box (height free) per streak [px].

    ``ks`` streak index, ``o`` offset across [px] and ``v`` change of each pixel; ``cen``
    the centres and ``w0`` the starting widths (K,).  The squared residual is evaluated at
    w0 times :data:`_BOX_FACTORS` on the same pixels and the minimum is refined by a
    parabola in ln w; streaks without a finite start keep it.
    """
    good = np.isfinite(w0) & np.isfinite(cen) & (w0 > 0)
    base = np.where(good, np.maximum(w0, 0.6), 1.0)
    reach = 0.5 * base * _BOX_FACTORS[-1] + 1.0
    u = o - np.where(good, cen, 0.0)[ks]
    keep = np.abs(u) <= reach[ks]
    ku, uu, vv = ks[keep], np.abs(u[keep]), v[keep]
    nf = _BOX_FACTORS.size
    # the pixel-integrated box of half width h covers a pixel at offset |u| by min(1, 2h)
    # inside |u| <= |h - 1/2|, by h + 1/2 - |u| out to h + 1/2, else 0: with the pixels
    # sorted by streak and |u|, its sums come from cumulative sums at two boundaries
    span = float(uu.max()) + 2.0 if uu.size else 1.0
    key = ku * span + uu
    order = np.argsort(key)
    key, uo, vo = key[order], uu[order], vv[order]

    def cums(x):
        out = np.empty(x.size + 1)
        out[0] = 0.0
        np.cumsum(x, out=out[1:])
        return out

    c_n, c_u, c_uu = np.arange(uo.size + 1, dtype=np.float64), cums(uo), cums(uo * uo)
    c_v, c_vu = cums(vo), cums(vo * uo)
    hw = 0.5 * base[:, None] * _BOX_FACTORS[None, :]                     # (K, nf)
    a_ = np.abs(hw - 0.5)
    b_ = hw + 0.5
    c_in = np.minimum(1.0, 2.0 * hw)
    kofs = (np.arange(K) * span)[:, None]
    i0 = np.searchsorted(key, kofs).astype(np.int64)
    # (both boundaries held inside the streak's own run of keys: a box wider than its
    # farthest pixel covers them all)
    ia = np.searchsorted(key, kofs + np.minimum(a_, span - 1.0), side="right")
    ib = np.searchsorted(key, kofs + np.minimum(b_, span - 1.0), side="left")

    def seg(c, lo_i, hi_i):
        return c[hi_i] - c[lo_i]

    n_p, u_p, uu_p = seg(c_n, ia, ib), seg(c_u, ia, ib), seg(c_uu, ia, ib)
    svc = c_in * seg(c_v, i0, ia) + b_ * seg(c_v, ia, ib) - seg(c_vu, ia, ib)
    scc = c_in * c_in * seg(c_n, i0, ia) + b_ * b_ * n_p - 2.0 * b_ * u_p + uu_p
    with np.errstate(all="ignore"):
        gain = np.where((scc > 0) & (svc > 0), svc * svc / scc, -np.inf)   # SSE = sum v^2 - gain
    j = np.argmax(gain, axis=1)
    jj = np.clip(j, 1, nf - 2)
    ar = np.arange(K)
    g0, g1, g2 = gain[ar, jj - 1], gain[ar, jj], gain[ar, jj + 1]
    with np.errstate(all="ignore"):
        den = g0 - 2 * g1 + g2
        shift = np.where((den < 0) & np.isfinite(den), 0.5 * (g0 - g2) / den, 0.0)
    shift = np.clip(shift, -1.0, 1.0)
    step = np.log(_BOX_FACTORS[1] / _BOX_FACTORS[0])
    w_fit = base * _BOX_FACTORS[jj] * np.exp(shift * step)
    inside = (j >= 1) & (j <= nf - 2) & np.isfinite(gain[ar, j])
    return np.where(good & inside, w_fit, w0)


def _crop_pixels(x0, x1, y0, y1):
    """Every pixel of K rectangular crops [y0, y1) x [x0, x1), row by row (no loop).

    Returns ``rstart`` (first row of each crop in the list of rows), ``R`` (number of
    rows), ``row_k`` (crop of each row), and per pixel ``rkey`` (its row), ``kk`` (its
    crop), ``ly, lx`` (position in the crop) and ``gy, gx`` (position in the image).
    """
    cw, ch = x1 - x0, y1 - y0
    K = ch.size
    rstart = np.concatenate(([0], np.cumsum(ch)[:-1]))
    R = int(ch.sum())
    row_k = np.repeat(np.arange(K), ch)
    row_l = np.arange(R) - rstart[row_k]
    per_row = cw[row_k]
    rkey = np.repeat(np.arange(R), per_row)
    kk = row_k[rkey]
    ly = row_l[rkey]
    lx = np.arange(rkey.size) - np.concatenate(([0], np.cumsum(per_row)[:-1]))[rkey]
    gy = y0[kk] + ly
    gx = x0[kk] + lx
    return rstart, R, row_k, rkey, kk, ly, lx, gy, gx


def _pixel_values(change, flat, cur, contrast):
    """Change I_n - (I_{n-1} + I_{n+1}) / 2 at the flat pixel indices (divided by the local
    contrast E_r - I_b and scaled to C_ref when ``contrast`` = (E_r, C_ref) is given, Eq. 18),
    the raw change and I_n there (float64)."""
    cg = None if cur is None else np.take(cur, flat).astype(np.float64)
    if isinstance(change, tuple):
        p_, c_, n_ = change
        cc = cg if (c_ is cur and cg is not None) else np.take(c_, flat).astype(np.float64)
        raw = cc - 0.5 * (np.take(p_, flat).astype(np.float64) + np.take(n_, flat))
    else:
        raw = np.take(change, flat).astype(np.float64)
    val = raw
    if contrast is not None and cg is not None:
        e_r, c_ref = contrast
        val = raw * (c_ref / np.maximum(e_r - (cg - raw), 0.25 * c_ref))
    return val, raw, cg


#: The flanks of a streak begin this far beyond half its detected row width [px].
FLANK_GAP_PX = 1.5

#: Fewest flank pixels for a row's baseline (fewer: no baseline) [-].
FLANK_MIN_PIXELS = 8


#: A streak measured wider than its detected rows by more than this is measured again with
#: its flanks beyond the measured width [px].
WIDE_MARGIN_PX = 1.0

#: The per-streak entries of :func:`measure_streak_table` (the others list pixels).
PER_STREAK_KEYS = ("label", "xm", "ym", "slope", "width_apparent", "top", "bottom", "motion", "plateau",
                   "background_dn", "beta", "chi2", "ok", "row_width")

#: Rows on either side over which the flanks' change is averaged for the baseline [px].
FLANK_HALF_ROWS = 4


def _flank_baseline(rb, flank, values, row_k, rstart, ch, K: int, *,
                    half_rows: int = FLANK_HALF_ROWS) -> np.ndarray:
    """Local baseline of the change under streaks, per row of their bands [gray levels].

    The band pixels beside a streak (its flanks) carry none of the streak's own change;
    their mean over the rows within ``half_rows`` of each row (inside the same streak's
    band) is the offset that other rain (a wide defocused drop near the camera over
    frame n-1, n or n+1) or a slow change of the scene adds under the streak there.
    Rows with fewer than :data:`FLANK_MIN_PIXELS` flank pixels in reach get none.

    Parameters
    ----------
    rb : (P,) int array
        Band row of each band pixel (index into the R rows of all the bands).
    flank : (P,) bool array
        Whether each band pixel is a flank pixel.
    values : (P,) array
        Change of each band pixel [gray levels].
    row_k, rstart, ch : arrays
        Streak of each of the R rows; first row and number of rows of each of the K streaks.

    Returns
    -------
    (R,) array: the baseline of each band row [gray levels].
    """
    R = row_k.size
    sv = np.bincount(rb[flank], weights=np.asarray(values, dtype=np.float64)[flank], minlength=R)
    sn = np.bincount(rb[flank], minlength=R).astype(np.float64)
    cv = np.concatenate(([0.0], np.cumsum(sv)))
    cn = np.concatenate(([0.0], np.cumsum(sn)))
    r = np.arange(R)
    first = rstart[row_k]
    last = first + ch[row_k] - 1
    lo = np.maximum(r - int(half_rows), first)
    hi = np.minimum(r + int(half_rows), last) + 1
    n = cn[hi] - cn[lo]
    with np.errstate(all="ignore"):
        base = np.where(n >= FLANK_MIN_PIXELS, (cv[hi] - cv[lo]) / np.maximum(n, 1.0), 0.0)
    return base


def _group_sum(k, values, K: int) -> np.ndarray:
    """Per-group sums of ``values`` for group indices ``k`` given in ascending order:
    ``np.bincount(k, values, K)`` by one segment reduction (pairwise summation, several
    times faster than the scattered accumulation)."""
    return _Groups(k, K).sum(values)


class _Groups:
    """Per-group sums over one ascending array of group indices ``k`` (K groups), its segment
    starts found once for all the sums taken over it (:func:`_group_sum`)."""

    def __init__(self, k, K: int):
        self.K = int(K)
        self.n = np.asarray(k).size
        if self.n and self.K:
            starts = np.searchsorted(k, np.arange(self.K))
            self.filled = starts < np.append(starts[1:], self.n)
            # each non-empty group's segment runs to the next non-empty group's start (to
            # the end for the last one, also when empty groups follow it)
            self.first = starts[self.filled]

    def sum(self, values) -> np.ndarray:
        """``np.bincount(k, values, K)`` by one segment reduction."""
        values = np.asarray(values)
        out = np.zeros(self.K)
        if values.size == 0 or self.K == 0:
            return out
        out[self.filled] = np.add.reduceat(values.astype(np.float64, copy=False), self.first)
        return out


def _axis_moments(img, k, lx, ly, K, x0, y0, x_default, y_default):
    """Axis of K streaks from the first and second moments of the positive change ``img``
    on their pixels (crop ``k``, position ``lx, ly`` in a crop whose corner is x0, y0):
    centre (xm, ym) [px] and slope dx/dy [px/px]; streaks without positive change get the
    defaults and slope 0."""
    fx, fy = lx.astype(np.float64), ly.astype(np.float64)
    wts = np.maximum(img, 0.0)
    g = _Groups(k, K)
    s0 = g.sum(wts)
    sx = g.sum(wts * fx)
    sy = g.sum(wts * fy)
    safe = np.where(s0 > 0, s0, 1.0)
    xm_l, ym_l = sx / safe, sy / safe
    dy = fy - ym_l[k]
    myy = g.sum(wts * dy * dy) / safe
    mxy = g.sum(wts * (fx - xm_l[k]) * dy) / safe
    slope = np.where(myy > 1e-9, mxy / np.where(myy > 1e-9, myy, 1.0), 0.0)
    xm = np.where(s0 > 0, xm_l + x0, x_default)
    ym = np.where(s0 > 0, ym_l + y0, y_default)
    slope = np.where(s0 > 0, slope, 0.0)
    return xm, ym, slope


def _cross_width(ks, o, img_s, row_width, K, sigma_min, groups=None):
    """Apparent width w' of K streaks from their change ``img_s`` at offsets ``o`` across
    the axis [px] (streak ``ks``); ``row_width`` the detected width across [px].

    Three passes of the second moment: the whole band, then windows of w'/2 + 1.5 px
    about the centre (the far pixels only add noise to the second moment; the edges of a
    sharp or uniformly defocused streak end within 1 px of w'/2), w' = sqrt(12 (var -
    1/12 - s_min^2)); then refined by least squares (:func:`_refine_box_width`: the moment
    is noisy on faint streaks, it weighs the far pixels' noise by their squared offset).
    ``groups`` the :class:`_Groups` of ``ks`` when already made.
    Returns (centre [px], w' [px], total change c0)."""
    g = _Groups(ks, K) if groups is None else groups
    win = np.full(K, np.inf)
    cen_o = np.zeros(K)
    for i in range(3):
        # the first pass takes the whole band (an infinite window)
        v = img_s if i == 0 else np.where(np.abs(o - cen_o[ks]) <= win[ks], img_s, 0.0)
        vo = v * o
        c0 = g.sum(v)
        c1 = g.sum(vo)
        c2 = g.sum(vo * o)
        with np.errstate(all="ignore"):
            cen = c1 / c0
            var = c2 / c0 - cen ** 2
            w_app = np.sqrt(12.0 * np.maximum(var - 1.0 / 12.0 - sigma_min ** 2, 0.0))
        good = np.isfinite(w_app) & (c0 > 0)
        w_lim = np.clip(np.where(good, w_app, row_width), 0.5 * row_width - 1.0, row_width + 2.0)
        win = np.where(good, 0.5 * w_lim + 1.5, win)
        cen_o = np.where(good, cen, cen_o)
    w_app = _refine_box_width(ks, o, img_s, cen, w_app, K)
    return cen, w_app, c0


def _masked_row_median(a: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Median of each row of ``a`` over the entries where ``mask`` is true (NaN for none);
    the mean of the two middle values for an even count, as ``np.nanmedian``."""
    srt = np.sort(np.where(mask, a, np.inf), axis=1)
    n = mask.sum(axis=1)
    ar = np.arange(a.shape[0])
    lo = srt[ar, np.maximum((n - 1) // 2, 0)]
    hi = srt[ar, np.maximum(n // 2, 0)]
    with np.errstate(invalid="ignore"):
        med = np.where(n % 2 == 1, lo, (lo + hi) / 2.0)
    return np.where(n > 0, med, np.nan)


def measure_streak_table(change: np.ndarray, labels: np.ndarray, stats: np.ndarray, select, *,
                         valid: np.ndarray | None = None, margin_px: int = 4,
                         sigma_min: float = SHARP_SIGMA_PX, cur: np.ndarray | None = None,
                         prev: np.ndarray | None = None, contrast=None, noise_sigma: float = 2.0,
                         baseline: bool = True, engine: str | None = None) -> dict:
    """Closed-form measurement of many uniform streaks at once (no iteration, no loop over streaks).

    The same quantities as :class:`StreakProps` (``shape="uniform"``), from moments instead
    of fits:

    * axis and slope: first and second moments of the positive change of the streak's pixels;
    * apparent width w': the second moment across the axis of the change on the plateau
      rows, w' = sqrt(12 (var - 1/12 - s_min^2)) (a box of width w' has the variance
      w'^2/12; the pixel's own box adds 1/12), the definition of ``width_apparent``
      of :func:`fit_cross_profile`;
    * ends: half-plateau crossings of the 3-row smoothed row sums, moved inwards by
      :func:`cap_offset_px` (exact for a uniform streak, independent of noise on average);
      motion = bottom - top;
    * plateau: median of the row sums on the middle half of the streak.

    Parameters
    ----------
    change : (M, N) float32 array, or (prev, cur, nxt)
        I_n - (I_{n-1} + I_{n+1}) / 2 [gray levels], or the three linearised frames
        (the change is then computed only under the streaks; float32, or the uint8 frames
        of a linear camera, read as the same numbers).
    labels, stats : from :func:`detect_streaks`.
    select : (K,) int array
        Labels to measure.
    valid : (n + 1,) bool array, optional
        Which labels are streaks (masked out of each other's measurement).
    cur, prev : (M, N) float32 (or a linear camera's uint8) arrays, optional
        Frames n and n-1: mean background under each streak and the photometric slope of Eq. (18).
    contrast : (float, float), optional
        (E_r, C_ref): divide the change by the local contrast E_r - I_b and scale to C_ref
        (Eq. 18), removing the background's texture from the profiles; needs ``cur``.
    noise_sigma : float
        Noise of the change [gray levels] (for ``chi2``).
    baseline : bool
        Subtract each streak's local baseline (:func:`_flank_baseline`): the change of the
        pixels beside it, a line along the fall.  A wide, faint defocused drop near the
        camera over frame n-1 or n+1 lowers I_n - (I_{n-1} + I_{n+1}) / 2 under a
        focused streak of frame n by a smooth offset (over n raises it); the flanks of the
        streak see the same offset, so the plateau, the width and the ends are measured
        on the streak's own change.
    engine : {"compiled", "arrays"}, optional
        How the per-streak profiles are computed: one compiled loop per streak
        (:mod:`raingauge.gauge._kernels`, needs numba; the default when it is installed) or
        whole-frame array operations (the reference; the default without numba).  They
        agree up to the order of summation.

    Returns
    -------
    dict of (K,) arrays: ``label, xm, ym, slope, width_apparent, top, bottom, motion,
    plateau, background_dn, beta, row_width`` (detected pixels per row), ``chi2`` (mean squared residual of the plateau rows
    against the box of width w', in units of the noise: ~1 for a streak, large for the
    two-signed changes of moving scenery), ``ok`` and the streaks' own pixels ``own_k, own_y, own_x``
    (index into the K streaks, row, column).
    """
    L = np.asarray(select, dtype=np.int64)
    if valid is None:
        valid = stats[:, 4] > 0
    if baseline and L.size and _use_compiled(engine):
        return _compiled_table(change, labels, stats, L, valid, margin_px=margin_px, sigma_min=sigma_min, cur=cur,
                               prev=prev, contrast=contrast, noise_sigma=noise_sigma)
    own = _own_streak_pixels(change, labels, stats, L, margin_px=margin_px, cur=cur, prev=prev, contrast=contrast,
                             engine=engine)
    kw = dict(margin_px=margin_px, sigma_min=sigma_min, cur=cur, contrast=contrast, noise_sigma=noise_sigma,
              engine=engine)
    if not baseline:
        return _profile_pass(change, labels, valid, own, **kw)
    # against the flanks just beyond the detected pixels; a faint, wide (defocused) streak is
    # detected only along its core, and its flanks there lie on it: measured again against
    # the flanks beyond the width found (its own pixels, axis and Eq. 18 fit are those of the
    # first pass)
    first = _profile_pass(change, labels, valid, own, baseline_width=np.zeros(L.size), **kw)
    wide = np.flatnonzero(np.nan_to_num(first["width_apparent"]) > first["row_width"] + WIDE_MARGIN_PX)
    if wide.size:
        again = _profile_pass(change, labels, valid, _subset_streaks(own, wide),
                              baseline_width=first["width_apparent"][wide], **kw)
        for key in PER_STREAK_KEYS:
            first[key][wide] = again[key]
    return first


def _streak_boxes(stats, L, margin_px: int, M: int):
    """The boxes x, y, w, h of the streaks ``L`` (int64), the corner x0, y0 of the crop in
    which their moments are taken (the crop of the pass without a wider baseline), and the
    rows y0..y1 - 1 (ch of them) the passes measure, ``margin_px`` beyond the box."""
    x, y, w, h = (stats[L, k].astype(np.int64) for k in range(4))
    m = int(margin_px)
    x0 = np.maximum(x - (m + 2), 0)
    y0 = np.maximum(y - m, 0)
    y1 = np.minimum(y + h + m, M)
    return x, y, w, h, x0, y0, y1, y1 - y0


def _compiled_table(change, labels, stats, L, valid, *, margin_px, sigma_min, cur, prev, contrast,
                    noise_sigma) -> dict:
    """:func:`measure_streak_table` (with its baseline) by the compiled loop: each streak's own
    pixels (:func:`_own_streak_pixels`) and both passes of :func:`_profile_pass` one streak
    after the other, so that its pixels are still in the cache when measured again."""
    x, y, w, h, x0, y0, y1, ch = _streak_boxes(stats, L, margin_px, labels.shape[0])
    m = int(margin_px)
    (xm, ym, slope, row_width, bg_dn, beta, own_k, own_y, own_x, w_app, top_r, bot_r, plateau, chi2,
     ok) = _kernels.streak_table(change, labels, valid, L, x, y, w, h, x0, y0, y1, ch, cur=cur, prev=prev,
                                 contrast=contrast, margin_px=m, sigma_min=sigma_min, noise_sigma=noise_sigma,
                                 factors=_BOX_FACTORS, flank_gap=FLANK_GAP_PX, flank_min=FLANK_MIN_PIXELS,
                                 flank_half_rows=FLANK_HALF_ROWS, wide_margin=WIDE_MARGIN_PX)
    w_cap = np.where(np.isfinite(w_app), w_app, 1.0)
    cap = cap_offset_px(w_cap) - slant_end_shift_px(w_cap, slope)
    top = top_r + cap
    bot = bot_r - cap
    return {"label": L, "xm": xm, "ym": ym, "slope": slope, "width_apparent": w_app, "top": top, "bottom": bot,
            "motion": bot - top, "plateau": plateau, "background_dn": bg_dn, "beta": beta, "chi2": chi2, "ok": ok,
            "row_width": row_width, "own_k": own_k, "own_y": own_y, "own_x": own_x}


#: Per-streak entries of :func:`_own_streak_pixels` (the others list its own pixels).
_OWN_PER_STREAK = ("L", "x", "y", "w", "h", "y0", "y1", "ch", "xm", "ym", "slope", "row_width",
                   "background_dn", "beta")


def _use_compiled(engine: str | None) -> bool:
    """Whether :func:`measure_streak_table` runs its compiled per-streak loop."""
    if engine is None:
        return _kernels.AVAILABLE
    if engine == "arrays":
        return False
    if engine == "compiled":
        if not _kernels.AVAILABLE:
            raise ImportError("engine='compiled' needs numba. Fix: pip install numba, or use engine='arrays'")
        return True
    raise ValueError(f"engine must be 'compiled' or 'arrays', got {engine!r}")


def _own_streak_pixels(change, labels, stats, L, *, margin_px, cur, prev, contrast, engine=None) -> dict:
    """What a streak's own (detected) pixels give, once for both passes of
    :func:`measure_streak_table`: its box and rows, its axis from the moments of their
    positive change, the detected width along a row, and the background and photometric
    slope of Eq. (18) on them."""
    K = L.size
    M, N = labels.shape
    x, y, w, h, x0, y0, y1, ch = _streak_boxes(stats, L, margin_px, M)
    if _use_compiled(engine):
        xm, ym, slope, row_width, bg_dn, beta, ko, oy, ox = _kernels.own_pixels(
            change, labels, L, x, y, w, h, x0, y0, cur=cur, prev=prev, contrast=contrast)
        return {"L": L, "x": x, "y": y, "w": w, "h": h, "y0": y0, "y1": y1, "ch": ch, "xm": xm, "ym": ym,
                "slope": slope, "row_width": row_width, "background_dn": bg_dn, "beta": beta,
                "own_k": ko, "own_y": oy, "own_x": ox}
    box = _crop_pixels(x, x + w, y, y + h)
    kq, gyq, gxq = box[4], box[7], box[8]
    flat_q = gyq * N + gxq
    io = np.flatnonzero(np.take(labels, flat_q) == L[kq])
    flat_o = flat_q[io]
    img_o, raw_o, cur_o = _pixel_values(change, flat_o, cur, contrast)
    ko = kq[io]
    oy, ox = gyq[io], gxq[io]
    xm, ym, slope = _axis_moments(img_o, ko, ox - x0[ko], oy - y0[ko], K, x0, y0, x + w / 2.0, y + h / 2.0)
    # -- width of the detected pixels along a row
    rstart = np.concatenate(([0], np.cumsum(ch)[:-1]))
    R = int(ch.sum())
    row_k = np.repeat(np.arange(K), ch)
    own_rows = np.bincount(rstart[ko] + (oy - y0[ko]), minlength=R) > 0
    n_rows = _group_sum(row_k, own_rows, K)
    row_width = np.bincount(ko, minlength=K) / np.maximum(n_rows, 1)
    # -- background and the photometric slope of Eq. (18) on the own pixels
    bg_dn = np.full(K, np.nan)
    beta = np.full(K, np.nan)
    if cur is not None:
        n_own = np.bincount(ko, minlength=K)
        g_o = _Groups(ko, K)
        with np.errstate(all="ignore"):
            bg_dn = g_o.sum(cur_o - raw_o) / n_own
        if prev is not None:
            b = np.take(prev, flat_o).astype(np.float64)
            d = cur_o - b
            sb = g_o.sum(b)
            sbb = g_o.sum(b * b)
            sd = g_o.sum(d)
            sbd = g_o.sum(b * d)
            with np.errstate(all="ignore"):
                n = np.maximum(n_own, 1)
                vb = sbb / n - (sb / n) ** 2
                cov = sbd / n - sb * sd / n ** 2
                fit = (n_own >= 6) & (vb >= 16.0)
                beta = np.where(fit, -cov / np.where(fit, vb, 1.0), np.nan)
    return {"L": L, "x": x, "y": y, "w": w, "h": h, "y0": y0, "y1": y1, "ch": ch, "xm": xm, "ym": ym,
            "slope": slope, "row_width": row_width, "background_dn": bg_dn, "beta": beta,
            "own_k": ko, "own_y": oy, "own_x": ox}


def _subset_streaks(own: dict, keep: np.ndarray) -> dict:
    """The per-streak entries of :func:`_own_streak_pixels` for the streaks ``keep`` (the
    list of own pixels is not needed by a second pass and is left out)."""
    return {k: own[k][keep] for k in _OWN_PER_STREAK}


def _profile_pass(change, labels, valid, own, *, margin_px: int = 4, sigma_min: float = SHARP_SIGMA_PX,
                  cur=None, contrast=None, noise_sigma: float = 2.0, baseline_width=None,
                  engine: str | None = None) -> dict:
    """One pass of :func:`measure_streak_table` over the streaks of ``own``
    (:func:`_own_streak_pixels`); with ``baseline_width`` (K,) [px] the band reaches beyond
    half of max(detected row width, baseline_width) and its flanks there set each streak's
    baseline."""
    L = own["L"]
    K = L.size
    M, N = labels.shape
    empty = np.zeros(0)
    if K == 0:
        out = {k: empty for k in ("xm", "ym", "slope", "width_apparent", "top", "bottom", "motion",
                                  "plateau", "background_dn", "beta", "chi2", "row_width")}
        out.update(ok=np.zeros(0, bool), label=L, own_k=L, own_y=L, own_x=L)
        return out
    x, y, w, h = own["x"], own["y"], own["w"], own["h"]
    y0, y1, ch = own["y0"], own["y1"], own["ch"]
    xm, ym, slope, row_width = own["xm"], own["ym"], own["slope"], own["row_width"]
    if _use_compiled(engine):
        w_app, top_r, bot_r, plateau, chi2, ok = _kernels.profile_pass(
            change, labels, valid, own, margin_px=margin_px, sigma_min=sigma_min, cur=cur, contrast=contrast,
            noise_sigma=noise_sigma, baseline_width=baseline_width, factors=_BOX_FACTORS,
            flank_gap=FLANK_GAP_PX, flank_min=FLANK_MIN_PIXELS, flank_half_rows=FLANK_HALF_ROWS)
        w_cap = np.where(np.isfinite(w_app), w_app, 1.0)
        cap = cap_offset_px(w_cap) - slant_end_shift_px(w_cap, slope)
        top = top_r + cap
        bot = bot_r - cap
        empty_i = np.zeros(0, np.int64)
        return {"label": L, "xm": xm, "ym": ym, "slope": slope, "width_apparent": w_app, "top": top,
                "bottom": bot, "motion": bot - top, "plateau": plateau, "background_dn": own["background_dn"],
                "beta": own["beta"], "chi2": chi2, "ok": ok, "row_width": row_width,
                "own_k": own.get("own_k", empty_i), "own_y": own.get("own_y", empty_i),
                "own_x": own.get("own_x", empty_i)}
    m = int(margin_px)
    # the band used below reaches 0.5 w_row + 1.5 + m/2 px from the axis, which lies inside
    # the detected pixels: m + 2 px beyond the box hold it
    mh = m + 2
    if baseline_width is not None:
        bw = np.nan_to_num(np.asarray(baseline_width, dtype=np.float64), nan=0.0, posinf=0.0)
        bw = np.clip(bw, 0.0, 4.0 * np.maximum(w, 1) + 8.0)
        mh = mh + np.ceil(0.5 * bw).astype(np.int64)
    x0 = np.maximum(x - mh, 0)
    x1 = np.minimum(x + w + mh, N)
    rstart = np.concatenate(([0], np.cumsum(ch)[:-1]))
    R = int(ch.sum())
    row_k = np.repeat(np.arange(K), ch)
    # -- the band around the axis (|offset| <= half, inside the crop [x0, x1) and not on
    # another streak), built row by row from the axis, row sums
    band_width = row_width if baseline_width is None else np.maximum(row_width, bw)
    half = 0.5 * band_width + 1.5 + m / 2
    row_y = y0[row_k] + (np.arange(R) - rstart[row_k])
    axis_x = xm[row_k] + slope[row_k] * (row_y - ym[row_k])
    bx0 = np.clip(np.floor(axis_x - half[row_k]).astype(np.int64), x0[row_k], x1[row_k])
    bx1 = np.clip(np.ceil(axis_x + half[row_k]).astype(np.int64) + 1, bx0, x1[row_k])
    n_b = bx1 - bx0
    rb = np.repeat(np.arange(R), n_b)
    gxb = np.repeat(bx0, n_b) + (np.arange(rb.size) - np.repeat(np.cumsum(n_b) - n_b, n_b))
    kb = row_k[rb]
    gyb_i = row_y[rb]
    ob = gxb - axis_x[rb]
    flat_b = gyb_i * N + gxb
    lab_b = np.take(labels, flat_b)
    ib = np.flatnonzero((np.abs(ob) <= half[kb]) & ~((lab_b != 0) & (lab_b != L[kb]) & valid[lab_b]))
    kb, rb, ob, gyb = kb[ib], rb[ib], ob[ib], gyb_i[ib].astype(np.float64)
    img_b = _pixel_values(change, flat_b[ib], cur, contrast)[0]
    if baseline_width is not None:
        flank = np.abs(ob) > (0.5 * band_width + FLANK_GAP_PX)[kb]
        img_b = img_b - _flank_baseline(rb, flank, img_b, row_k, rstart, ch, K)[rb]
    row_sum = _group_sum(rb, img_b, R)
    H = int(ch.max())
    col = np.arange(R) - rstart[row_k]
    S = np.zeros((K, H + 2))
    S[row_k, col + 1] = row_sum
    sm = (S[:, :-2] + S[:, 1:-1] + S[:, 2:]) / 3.0            # 3-row smoothing ('same', zero padded)
    rows_g = y0[:, None] + np.arange(H)[None, :]
    inside = np.arange(H)[None, :] < ch[:, None]
    inner = inside & (rows_g >= (y + 0.25 * h)[:, None]) & (rows_g <= (y + 0.75 * h)[:, None])
    few = inner.sum(axis=1) < 2
    inner[few] = inside[few]
    plateau = _masked_row_median(sm, inner)
    lvl = 0.5 * plateau
    above = (sm >= lvl[:, None]) & inside
    has = above.any(axis=1) & (plateau > 0)
    i0 = np.argmax(above, axis=1)
    i1 = H - 1 - np.argmax(above[:, ::-1], axis=1)
    ar = np.arange(K)
    with np.errstate(all="ignore"):
        a_, b_ = sm[ar, np.maximum(i0 - 1, 0)], sm[ar, i0]
        first = np.where(i0 > 0, i0 - 1 + np.where(b_ != a_, (lvl - a_) / (b_ - a_), 1.0), 0.0)
        a_, b_ = sm[ar, i1], sm[ar, np.minimum(i1 + 1, H - 1)]
        last = np.where(i1 < ch - 1, i1 + np.where(a_ != b_, (a_ - lvl) / (a_ - b_), 0.0), ch - 1.0)
    top_r = first + y0
    bot_r = last + y0
    # -- cross profile on the plateau rows: second moment of the change across the axis
    cos_t = 1.0 / np.sqrt(1.0 + slope ** 2)
    w_guess = np.maximum(band_width * cos_t - 2.0, 1.0)
    lo_r = top_r + 0.5 * w_guess + 1.0
    hi_r = bot_r - 0.5 * w_guess - 1.0
    n_plateau_rows = np.floor(np.minimum(hi_r, y1 - 1.0)) - np.ceil(np.maximum(lo_r, y0)) + 1
    enough = n_plateau_rows >= 2
    mid = 0.5 * (top_r + bot_r)
    sel = np.where(enough[kb], (gyb >= lo_r[kb]) & (gyb <= hi_r[kb]), np.abs(gyb - mid[kb]) <= 1.0)
    js = np.flatnonzero(sel)
    ks, img_s = kb[js], img_b[js]
    o = ob[js] * cos_t[ks]
    n_cross = np.bincount(ks, minlength=K)
    g_s = _Groups(ks, K)
    cen, w_app, c0 = _cross_width(ks, o, img_s, band_width * cos_t, K, sigma_min, groups=g_s)
    ok = has & (c0 > 0) & (n_cross >= 6) & np.isfinite(w_app) & (w_app > 0)
    # goodness of the uniform model: the change on the plateau rows against a box of width
    # w' (pixel-integrated) holding the same total, per pixel in units of the noise
    n_r = _group_sum(row_k, np.bincount(rb[js], minlength=R) > 0, K)
    with np.errstate(all="ignore"):
        amp = c0 / (np.maximum(n_r, 1) * w_app)
        hw = 0.5 * w_app[ks]
        u = o - cen[ks]
        cover = np.clip(np.minimum(u + 0.5, hw) - np.maximum(u - 0.5, -hw), 0.0, None)
        res = img_s - amp[ks] * cover
        chi2 = g_s.sum(res * res) / (np.maximum(n_cross, 1) * max(noise_sigma, 1e-3) ** 2)
    chi2 = np.where(ok & np.isfinite(chi2), chi2, np.inf)
    w_cap = np.where(np.isfinite(w_app), w_app, 1.0)
    cap = cap_offset_px(w_cap) - slant_end_shift_px(w_cap, slope)
    top = top_r + cap
    bot = bot_r - cap
    motion = bot - top
    empty_i = np.zeros(0, np.int64)
    return {"label": L, "xm": xm, "ym": ym, "slope": slope, "width_apparent": w_app, "top": top,
            "bottom": bot, "motion": motion, "plateau": plateau, "background_dn": own["background_dn"],
            "beta": own["beta"], "chi2": chi2, "ok": ok, "row_width": row_width,
            "own_k": own.get("own_k", empty_i), "own_y": own.get("own_y", empty_i),
            "own_x": own.get("own_x", empty_i)}
