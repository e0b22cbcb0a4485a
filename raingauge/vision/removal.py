"""Removal of rain from video, Sec. 5.2 [GargNayar2007].

Only pixels detected as rain *and* lying inside the segmented rain regions are
changed.  A pixel hit in frame n alone gets the background estimate
(I_{n-1} + I_{n+1}) / 2 (Fig. 9(b)).  A pixel hit by drops in two or three
consecutive frames -- which the one-frame test of Eq. (19) cannot see (note 16)
-- gets the mean of its nearest unaffected frames on either side.

Colour video: detection runs on luminance, and the replacement is applied to
every channel with the same pixels and the same neighbouring frames.
"""

from __future__ import annotations

import numpy as np

__all__ = ["replace_single", "find_runs", "run_prefilter", "run_pair", "runs_in_values", "remove_rain", "remove_window",
           "ArrayWindow", "RUNS"]

#: Runs of consecutive rain frames containing the centre (offsets relative to it),
#: shortest first: two frames, then three.
RUNS: tuple[tuple[int, int], ...] = ((-1, 0), (0, 1), (-2, 0), (-1, 1), (0, 2))


def replace_single(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Replace the rain pixels of frame n by (I_{n-1} + I_{n+1}) / 2, Sec. 5.2 [GargNayar2007].

    Parameters
    ----------
    prev, cur, nxt : (M, N) or (M, N, C) float arrays
        Linearised frames n-1, n, n+1 aligned to frame n [gray levels].
    mask : (M, N) bool array
        Pixels to replace.

    Returns
    -------
    Array like ``cur`` (a copy).
    """
    cur = np.asarray(cur, dtype=np.float32)
    out = cur.copy()
    idx = np.flatnonzero(np.asarray(mask).ravel())
    if idx.size:
        n = mask.size
        o = out.reshape(n, -1)
        o[idx] = 0.5 * (np.asarray(prev, np.float32).reshape(n, -1)[idx] + np.asarray(nxt, np.float32).reshape(n, -1)[idx])
    return out


def run_prefilter(rises: list, falls: list) -> np.ndarray:
    """Pixels that may lie in a 2- or 3-frame run through the centre frame.

    Parameters
    ----------
    rises : list of 5 (M, N) bool arrays
        ``I_k - I_{k-1} >= c`` for frames k = n-2 .. n+2.
    falls : list of 5 (M, N) bool arrays
        ``I_k - I_{k+1} >= c`` for frames k = n-2 .. n+2.

    Every run [a, e] needs a rise at a and a fall at e; these one-sided tests
    are by-products of Eq. (19) for each frame, so this costs a few boolean
    operations.  The pixels of one streak share its run [a, e]: a pixel with
    fewer than two neighbours (3 x 3) of the same run is an isolated noise
    coincidence, not part of a streak, and is dropped.  (Testing each run on
    its own rather than their union keeps noisy cameras, where one-sided
    changes of c are common, from flooding the run test.)
    """
    import cv2

    R = dict(zip(range(-2, 3), rises))
    F = dict(zip(range(-2, 3), falls))
    pre = np.zeros_like(rises[2])
    for a, e in RUNS:
        pre |= run_pair(R[a], F[e])
    return pre


def run_pair(rise: np.ndarray, fall: np.ndarray) -> np.ndarray:
    """Pixels that may lie in the run [a, e]: a rise at a, a fall at e, and two such neighbours (3 x 3).

    Parameters
    ----------
    rise, fall : (M, N) bool arrays
        ``I_a - I_{a-1} >= c`` and ``I_e - I_{e+1} >= c``.
    """
    import cv2

    run = rise & fall
    count = cv2.boxFilter(run.view(np.uint8), cv2.CV_16U, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
    run &= count >= 3
    return run


def find_runs(lum, *, c: float, where: np.ndarray | None = None, tol: float | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels of the centre frame hit by rain in 2 or 3 consecutive frames.

    A run of frames [a, e] containing the centre is rain when every frame of the
    run is brighter by at least ``c`` than both unaffected frames a-1 and e+1
    (Eq. (19) widened to a run).

    Parameters
    ----------
    lum : sequence of 7 (M, N) float arrays
        Linearised luminance of frames n-3 .. n+3 aligned to frame n [gray levels].
    c : float
        Detection threshold [gray levels].
    where : (M, N) bool array, optional
        Only these pixels are examined (e.g. the rain region, less the pixels
        already handled, and :func:`run_prefilter`).
    tol : float, optional
        Largest allowed difference between the two unaffected frames [gray levels].

    Returns
    -------
    flat : (P,) int array
        Flat indices of the pixels with a run.
    before, after : (P,) int arrays
        Indices into ``lum`` of the unaffected frames on either side.
    """
    lum = [np.asarray(x, dtype=np.float32) for x in lum]
    if len(lum) != 7 or lum[3].ndim != 2:
        raise ValueError(f"find_runs needs 7 (M, N) frames (n-3 .. n+3), got {len(lum)}")
    if where is None:
        where = np.ones(lum[3].shape, bool)
    flat = np.flatnonzero(np.asarray(where).ravel())
    v = np.stack([x.ravel()[flat] for x in lum]) if flat.size else np.zeros((7, 0), np.float32)
    hit, before, after = runs_in_values(v, c=c, tol=tol)
    return flat[hit], before, after


def runs_in_values(v: np.ndarray, *, c: float, tol: float | None = None):
    """The run test of :func:`find_runs` on a (7, P) matrix of pixel values.

    Returns the bool (P,) hit mask and, for the hits, the indices (0-6) of the
    unaffected frames before and after the run.
    """
    P = v.shape[1]
    before = np.full(P, -1, np.int64)
    after = np.full(P, -1, np.int64)
    todo = np.ones(P, bool)
    for a, e in RUNS:
        ia, ie = 3 + a, 3 + e
        inner = v[ia:ie + 1].min(axis=0)
        outer = np.maximum(v[ia - 1], v[ie + 1])
        ok = todo & (inner - outer >= c)
        if tol is not None:
            ok &= np.abs(v[ia - 1] - v[ie + 1]) <= tol
        before[ok] = ia - 1
        after[ok] = ie + 1
        todo &= ~ok
    hit = before >= 0
    return hit, before[hit], after[hit]


class ArrayWindow:
    """Seven frames n-3 .. n+3 already aligned to frame n, as full arrays.

    The interface :func:`remove_window` reads: ``shape``, ``centre_lum``,
    ``lum_at(k, idx)``, ``lin_at(k, idx)`` and ``run_candidates(c)``.
    """

    def __init__(self, frames, lum):
        self.frames = [np.asarray(x, dtype=np.float32) for x in frames]
        self.lum = [np.asarray(x, dtype=np.float32) for x in lum]
        if len(self.frames) != 7 or len(self.lum) != 7:
            raise ValueError("the removal needs the 7 frames n-3 .. n+3")
        self.shape = self.lum[3].shape
        self.centre_lum = self.lum[3]
        self.centre_lin = self.frames[3]

    def lum_at(self, k: int, idx: np.ndarray) -> np.ndarray:
        return self.lum[k].ravel()[idx]

    def lin_at(self, k: int, idx: np.ndarray) -> np.ndarray:
        return self.frames[k].reshape(self.lum[3].size, -1)[idx]

    def run_candidates(self, c: float) -> np.ndarray:
        c32 = np.float32(c)
        rises = [self.lum[k] - self.lum[k - 1] >= c32 for k in range(1, 6)]
        falls = [self.lum[k] - self.lum[k + 1] >= c32 for k in range(1, 6)]
        return run_prefilter(rises, falls)


def remove_window(window, rain: np.ndarray, region: np.ndarray, *, c: float, runs: bool = True,
                  tol: float | None = None, grow_px: int = 1, grow_threshold: float | None = None,
                  beta_max: float | None = None, noise_sigma: float = 1.0, min_pixels: int = 5
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The rules of Sec. 5.2 on a window of frames; see :func:`remove_rain`.

    Returns
    -------
    idx : (P,) int array
        Flat indices of the replaced pixels of frame n.
    values : (P, C) float32 array
        Their background estimates [gray levels].
    """
    import cv2

    single = rain & region
    idx = np.flatnonzero(single.ravel())
    if grow_px > 0 and idx.size:
        k = 2 * int(grow_px) + 1
        near = cv2.dilate(single.view(np.uint8), np.ones((k, k), np.uint8)).astype(bool) & region & ~single
        nidx = np.flatnonzero(near.ravel())
        thr = 0.5 * c if grow_threshold is None else grow_threshold
        change = window.centre_lum.ravel()[nidx] - 0.5 * (window.lum_at(2, nidx) + window.lum_at(4, nidx))
        grown = nidx[change > thr]
        if grown.size:
            single.ravel()[grown] = True
            idx = np.concatenate([idx, grown])
    values = 0.5 * (window.lin_at(2, idx) + window.lin_at(4, idx)) if idx.size else None
    out_idx, out_vals = [idx], [values]
    if runs and np.any(region):
        where = region & ~single & window.run_candidates(c)
        flat = np.flatnonzero(where.ravel())
        if flat.size:
            v = np.stack([window.centre_lum.ravel()[flat] if k == 3 else window.lum_at(k, flat) for k in range(7)])
            hit, before, after = runs_in_values(v, c=c, tol=tol)
            flat, v = flat[hit], v[:, hit]
            if flat.size and beta_max is not None:
                from raingauge.vision.photometric import photometric_filter

                cols = np.arange(flat.size)
                centre = window.centre_lum
                # only the run pixels are read: no need to fill the rest
                bg_before = np.empty_like(centre)
                bg_after = np.empty_like(centre)
                bg_before.ravel()[flat] = v[before, cols]
                bg_after.ravel()[flat] = v[after, cols]
                m = np.zeros(centre.shape, bool)
                m.ravel()[flat] = True
                ok, _ = photometric_filter(bg_before, centre, bg_after, m, beta_max=beta_max,
                                           noise_sigma=noise_sigma, min_pixels=min_pixels)
                keep = ok.ravel()[flat]
                flat, before, after = flat[keep], before[keep], after[keep]
            if flat.size:
                vals = np.empty((flat.size, window.lin_at(3, flat[:1]).shape[-1]), np.float32)
                for kb in np.unique(before):
                    for ka in np.unique(after[before == kb]):
                        sel = (before == kb) & (after == ka)
                        vals[sel] = 0.5 * (window.lin_at(int(kb), flat[sel]) + window.lin_at(int(ka), flat[sel]))
                out_idx.append(flat)
                out_vals.append(vals)
    idx_all = np.concatenate(out_idx)
    vals = [x for x in out_vals if x is not None]
    vals_all = np.concatenate(vals) if vals else np.zeros((0, 1), np.float32)
    return idx_all, vals_all.astype(np.float32, copy=False)


def remove_rain(frames: np.ndarray, lum: np.ndarray, rain: np.ndarray, region: np.ndarray, *, c: float,
                runs: bool = True, tol: float | None = None, grow_px: int = 1,
                grow_threshold: float | None = None, beta_max: float | None = None,
                noise_sigma: float = 1.0, min_pixels: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Derain the centre frame of a 7-frame window, Sec. 5.2 [GargNayar2007].

    Parameters
    ----------
    frames : sequence of 7 (M, N) or (M, N, C) float arrays
        Linearised frames n-3 .. n+3 aligned to frame n [gray levels]; every
        channel is cleaned.
    lum : sequence of 7 (M, N) float arrays
        Their luminance [gray levels].
    rain : (M, N) bool array
        Rain pixels of frame n (accepted streaks, the binary field b).
    region : (M, N) bool array
        Rain region (segmentation of Sec. 5.1); nothing outside it changes.
    c : float
        Detection threshold [gray levels].
    runs : bool
        Also remove drops that hit a pixel in 2 or 3 consecutive frames.
    tol : float, optional
        Stationarity tolerance of the run test [gray levels].
    grow_px : int
        Also replace pixels within this distance of a rain streak whose
        change over (I_{n-1} + I_{n+1}) / 2 exceeds ``grow_threshold``: the faint
        rim of a streak below c.  0 follows the paper exactly.
    grow_threshold : float, optional
        Default c / 2 [gray levels].
    beta_max : float, optional
        When given, the multi-frame runs are grouped into streaks and must pass
        the photometric test of Eq. (18) too, with the unaffected frames as
        background (see :func:`raingauge.vision.photometric.photometric_filter`).
    noise_sigma : float
        Camera noise for that test [gray levels].
    min_pixels : int
        Smallest streak of runs [px].

    Returns
    -------
    derained : array like ``frames[3]`` (float32)
    replaced : (M, N) bool array
        Pixels that were changed.
    """
    win = ArrayWindow(frames, lum)
    idx, vals = remove_window(win, rain, region, c=c, runs=runs, tol=tol, grow_px=grow_px,
                              grow_threshold=grow_threshold, beta_max=beta_max, noise_sigma=noise_sigma,
                              min_pixels=min_pixels)
    out = win.centre_lin.copy()
    n = win.centre_lum.size
    out.reshape(n, -1)[idx] = vals.reshape(idx.size, -1)
    replaced = np.zeros(win.shape, bool)
    replaced.ravel()[idx] = True
    return out, replaced
