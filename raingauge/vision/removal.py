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

__all__ = ["replace_single", "find_runs", "run_prefilter", "remove_rain", "RUNS"]

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
    operations.  A pixel without any such neighbour (3 x 3) is an
    isolated noise coincidence, not part of a streak, and is dropped.
    """
    import cv2

    R = dict(zip(range(-2, 3), rises))
    F = dict(zip(range(-2, 3), falls))
    pre = np.zeros_like(rises[2])
    for a, e in RUNS:
        pre |= R[a] & F[e]
    u8 = pre.view(np.uint8)
    count = cv2.boxFilter(u8, -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
    return pre & (count >= 2)


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
    if flat.size == 0:
        e = np.zeros(0, np.int64)
        return e, e, e
    v = np.stack([x.ravel()[flat] for x in lum])  # (7, P)
    before = np.full(flat.size, -1, np.int64)
    after = np.full(flat.size, -1, np.int64)
    todo = np.ones(flat.size, bool)
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
    return flat[hit], before[hit], after[hit]


def remove_rain(frames: np.ndarray, lum: np.ndarray, rain: np.ndarray, region: np.ndarray, *, c: float,
                runs: bool = True, tol: float | None = None, grow_px: int = 1,
                grow_threshold: float | None = None, beta_max: float | None = None,
                noise_sigma: float = 1.0, min_pixels: int = 5,
                run_candidates: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
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
    run_candidates : (M, N) bool array, optional
        Pixels that may hold a run (:func:`run_prefilter`); default computed
        from ``lum``.

    Returns
    -------
    derained : array like ``frames[3]`` (float32)
    replaced : (M, N) bool array
        Pixels that were changed.
    """
    import cv2

    frames = [np.asarray(x, dtype=np.float32) for x in frames]
    lum = [np.asarray(x, dtype=np.float32) for x in lum]
    if len(frames) != 7 or len(lum) != 7:
        raise ValueError("remove_rain needs the 7 frames n-3 .. n+3")
    single = rain & region
    if grow_px > 0 and np.any(single):
        k = 2 * int(grow_px) + 1
        near = cv2.dilate(single.view(np.uint8), np.ones((k, k), np.uint8)).astype(bool) & region & ~single
        thr = 0.5 * c if grow_threshold is None else grow_threshold
        change = lum[3] - 0.5 * (lum[2] + lum[4])
        single = single | (near & (change > thr))
    out = replace_single(frames[2], frames[3], frames[4], single)
    replaced = single.copy()
    if runs and np.any(region):
        if run_candidates is None:
            c32 = np.float32(c)
            rises = [lum[k] - lum[k - 1] >= c32 for k in range(1, 6)]
            falls = [lum[k] - lum[k + 1] >= c32 for k in range(1, 6)]
            run_candidates = run_prefilter(rises, falls)
        flat, before, after = find_runs(lum, c=c, where=region & ~single & run_candidates, tol=tol)
        if flat.size and beta_max is not None:
            from raingauge.vision.photometric import photometric_filter

            vals_l = np.stack([x.ravel()[flat] for x in lum])
            cols = np.arange(flat.size)
            bg_before = lum[3].copy()
            bg_after = lum[3].copy()
            bg_before.ravel()[flat] = vals_l[before, cols]
            bg_after.ravel()[flat] = vals_l[after, cols]
            m = np.zeros(lum[3].shape, bool)
            m.ravel()[flat] = True
            ok, _ = photometric_filter(bg_before, lum[3], bg_after, m, beta_max=beta_max,
                                       noise_sigma=noise_sigma, min_pixels=min_pixels)
            keep = ok.ravel()[flat]
            flat, before, after = flat[keep], before[keep], after[keep]
        if flat.size:
            n_pix = lum[3].size
            fv = np.stack([x.reshape(n_pix, -1)[flat] for x in frames])  # (7, P, C)
            cols = np.arange(flat.size)
            vals = 0.5 * (fv[before, cols] + fv[after, cols])
            o = out.reshape(n_pix, -1)
            o[flat] = vals
            replaced.ravel()[flat] = True
    return out, replaced
