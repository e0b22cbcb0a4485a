"""Detection of a slanted streak when the change is smoothed along several slants.

In a cross wind u each drop size slants by its own u / v(a), and
:func:`raingauge.gauge.streaks.detect_streaks` smooths the spike image
min(I_n - I_{n-1}, I_n - I_{n+1}) (Eq. 19 [GargNayar2007]) along each slant of
:func:`raingauge.gauge.streaks.wind_slopes` and thresholds the largest of the smoothed
values.  At a pixel of the streak that largest is

    S = max_k (A c_k + N_k),

A the streak's per-pixel change, c_k the share of it that slant k's kernel gathers
(the whole of it along the streak's own slant, less along others, which leave the
streak at their ends) and N_k the smoothed noise.  The spike's noise
e_n - max(e_{n-1}, e_{n+1}) of each pixel is independent of its neighbours', with mean
-sigma / sqrt(pi) and variance sigma^2 (2 - 1 / pi); every kernel sums to one, so each
N_k has that mean, and N_j, N_k the covariance sigma^2 (2 - 1 / pi) <K_j, K_k> of the
kernels' weights (all of them share the centre pixel; neighbouring slants share most
of their pixels).  Noise lifts the largest of several such values above any one of
them: a faint streak is found more often than along its own slant alone (at 3 gray
levels of noise and of contrast about twice as often in a 3 m/s wind,
``benchmarks/diag_slant_lift.py``).

The chance P = P(S >= c) is computed from a fixed set of draws of the N_k: S >= c
exactly when A >= X = min_k (c - N_k) / c_k, so P is the distribution of X at A, read off
the sorted draws.  Below the draws' reach P keeps to the best single slant's Gaussian
tail (P(S >= c) is at least each slant's own).  Gaussian noise is the model's only
approximation: over 5 rows the sum of the skewed spike noise is near enough to it
(the rates it gives match those of the smoothed noise frames to a few per cent,
``tests/test_gauge_slants.py``).

The sample volume (:mod:`raingauge.gauge.volume`) does not take it yet: with it the
gauge's completion no longer overshoots in a cross wind, and the error it had made up
for, the drop brightness E_r the completeness probe's drops are drawn with, shows; the
wind's clips read fewer within target (``benchmarks/VALIDATION.md``, "The detection's
largest over the wind's slants, modelled").
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

__all__ = ["slant_kernels", "slant_captures", "slant_margin", "SLANT_DRAWS", "SLANT_WIDTH_NODES"]

#: Draws of the smoothed noise the chance of detection is read from [-].
SLANT_DRAWS = 4096
#: Streak widths across the rows [px] at which the slants' captures are computed (the
#: chance is linear in log width between them; 2 px, from which a straight streak covers
#: its best pixel whole, is one of them).
SLANT_WIDTH_NODES = tuple(float(x) for x in np.concatenate([np.geomspace(1.0, 2.0, 5)[:-1],
                                                             np.geomspace(2.0, 24.0, 15)]))
#: Sub-pixel places of a streak's centre on its best column over which captures are averaged.
_OFFSETS = (np.arange(8) + 0.5) / 8.0 - 0.5


@lru_cache(maxsize=64)
def slant_kernels(slopes: tuple, smooth_px: int) -> np.ndarray:
    """The smoothing kernels of ``slopes`` (:func:`raingauge.gauge.streaks.fall_kernel`) on a
    common grid centred on the pixel they are applied at: (K, smooth_px, 2 R + 1)."""
    from raingauge.gauge.streaks import fall_kernel

    ks = [fall_kernel(int(smooth_px), float(s)) for s in slopes]
    reach = max(k.shape[1] for k in ks) // 2
    out = np.zeros((len(ks), int(smooth_px), 2 * reach + 1))
    for i, k in enumerate(ks):
        r = k.shape[1] // 2
        out[i, :, reach - r:reach + r + 1] = k
    return out


def slant_captures(width_px: float, streak_slope: float, slopes, smooth_px: int = 5) -> np.ndarray:
    """The share c_k of a straight streak's per-pixel change that each slant's kernel gathers
    at the streak's best pixel [-].

    The streak is a band ``width_px`` wide across the rows along dx/dy = ``streak_slope``,
    each pixel changed by the part of it the band covers; the kernels sample it at the
    pixel nearest its centre line, averaged over the centre's sub-pixel place.

    Parameters
    ----------
    width_px : float
        The streak's width across the rows [px] (w' / cos(theta) for a streak w' wide
        slanted by theta).
    streak_slope : float
        Its slant dx/dy [px/px].
    slopes : sequence of float
        The slants the change is smoothed along [px/px].
    smooth_px : int
        Rows of the smoothing.
    """
    kern = slant_kernels(tuple(float(s) for s in slopes), int(smooth_px))
    n, cols = kern.shape[1:]
    reach = cols // 2
    rows = np.arange(n) - n // 2
    x = np.arange(cols) - reach                                          # pixel centres
    half = 0.5 * float(width_px)
    resp = np.zeros(kern.shape[0])
    for d in _OFFSETS:
        centre = float(streak_slope) * rows[:, None] + d                # (n, 1)
        lo = np.maximum(x[None, :] - 0.5, centre - half)
        hi = np.minimum(x[None, :] + 0.5, centre + half)
        val = np.clip(hi - lo, 0.0, 1.0)                                 # (n, cols)
        resp += np.einsum("kij,ij->k", kern, val)
    return resp / len(_OFFSETS)


@lru_cache(maxsize=256)
def _node_captures(streak_slope: float, slopes: tuple, smooth_px: int) -> np.ndarray:
    """:func:`slant_captures` at each of :data:`SLANT_WIDTH_NODES`: (n_nodes, K)."""
    return np.array([slant_captures(w, streak_slope, slopes, smooth_px) for w in SLANT_WIDTH_NODES])


@lru_cache(maxsize=16)
def _unit_draws(slopes: tuple, smooth_px: int) -> np.ndarray:
    """Draws of the smoothed spike noise along each slant in units of the per-pixel spike
    noise's standard deviation, centred: (SLANT_DRAWS, K), correlated as the kernels."""
    kern = slant_kernels(slopes, smooth_px).reshape(len(slopes), -1)
    cov = kern @ kern.T
    vals, vecs = np.linalg.eigh(cov)
    root = vecs * np.sqrt(np.clip(vals, 0.0, None))
    z = np.random.default_rng(20070727).standard_normal((SLANT_DRAWS, len(slopes)))
    return z @ root.T


def slant_margin(change_dn, width_px, *, threshold_dn: float, noise_sigma_dn, slopes, streak_slope: float,
                 smooth_px: int = 5) -> np.ndarray:
    """The detection margin of a slanted streak when the largest of its change smoothed
    along each of ``slopes`` is thresholded: Phi^-1(P(S >= c)) (module docstring), the
    margin of :func:`raingauge.gauge.rejection.detection_margin` that gives the same
    chance [-].

    Parameters
    ----------
    change_dn : array_like
        A, the streak's per-pixel change (its contrast already dimmed by the slant) [gray levels].
    width_px : array_like
        Its apparent width w' across its direction [px] (broadcast with ``change_dn``).
    threshold_dn : float
        c of Eq. (19) [gray levels].
    noise_sigma_dn : array_like
        Noise of one frame [gray levels] (broadcast; few distinct values are expected:
        the draws are sorted once for each).
    slopes : sequence of float
        The slants the detection smooths along [px/px].
    streak_slope : float
        The streak's own slant u / v(a) [px/px].
    smooth_px : int
        Rows of the smoothing.

    Returns
    -------
    ndarray of the broadcast shape: the margin (a chance below the draws' reach is the
    best single slant's Gaussian tail; one slant is its Gaussian margin, for a streak at
    least 2 px wide along the column :func:`raingauge.gauge.rejection.detection_margin`).
    """
    from scipy.special import ndtri

    slopes = tuple(float(s) for s in slopes)
    n_s = max(int(smooth_px), 1)
    a, w, sig = np.broadcast_arrays(np.asarray(change_dn, dtype=float), np.asarray(width_px, dtype=float),
                                    np.asarray(noise_sigma_dn, dtype=float))
    s0 = float(streak_slope)
    w_h = np.maximum(w, 1.0) * math.sqrt(1.0 + s0 * s0)      # across the rows
    sig = np.maximum(sig, 0.3)
    spike_sd = math.sqrt(2.0 - 1.0 / math.pi)
    draws = _unit_draws(slopes, n_s)
    kern = slant_kernels(slopes, n_s).reshape(len(slopes), -1)
    unit_sd = np.sqrt(np.sum(kern * kern, axis=1))                     # (K,)
    nodes = np.log(np.asarray(SLANT_WIDTH_NODES))
    caps = _node_captures(s0, slopes, n_s)                               # (n_nodes, K)
    lw = np.log(np.clip(w_h, SLANT_WIDTH_NODES[0], SLANT_WIDTH_NODES[-1]))
    j = np.clip(np.searchsorted(nodes, lw, side="right") - 1, 0, nodes.size - 2)
    t = (lw - nodes[j]) / (nodes[j + 1] - nodes[j])
    # the best single slant's Gaussian margin: the floor under the draws' reach
    cap_pt = (1.0 - t)[..., None] * caps[j] + t[..., None] * caps[j + 1]
    mean_n = -sig / math.sqrt(math.pi)
    single = (a[..., None] * cap_pt + mean_n[..., None] - float(threshold_dn)) / (
        (sig * spike_sd)[..., None] * unit_sd)
    m_floor = single.max(axis=-1)
    if len(slopes) == 1:
        # one direction: its own Gaussian margin
        return m_floor
    p = np.zeros(a.size)
    a_f, j_f, t_f = a.ravel(), j.ravel(), t.ravel()
    levels = (np.arange(SLANT_DRAWS) + 0.5) / SLANT_DRAWS
    values, inverse = np.unique(sig.ravel(), return_inverse=True)
    for i_s, s_val in enumerate(values):
        at_s = np.nonzero(inverse.ravel() == i_s)[0]
        noise = s_val * (spike_sd * draws - 1.0 / math.sqrt(math.pi))          # (D, K)
        need = float(threshold_dn) - noise
        j_s = j_f[at_s]
        for node in np.unique(np.concatenate([j_s, j_s + 1])):
            c_k = caps[node]
            use = c_k > 1e-6
            if not use.any():
                continue
            x = np.sort(np.min(need[:, use] / c_k[use], axis=1))
            # each point between its two width nodes, linear in log width
            for pts, wt in ((at_s[j_s == node], None), (at_s[j_s + 1 == node], 1)):
                if pts.size:
                    pr = np.interp(a_f[pts], x, levels, left=0.0, right=1.0)
                    p[pts] += pr * (t_f[pts] if wt else 1.0 - t_f[pts])
    p = p.reshape(a.shape)
    with np.errstate(divide="ignore"):
        m = ndtri(np.clip(p, 0.0, 1.0 - 0.5 / SLANT_DRAWS))
    m = np.where(p >= 2.0 / SLANT_DRAWS, np.maximum(m, m_floor), m_floor)
    return m
