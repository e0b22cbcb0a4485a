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
           "multi_frame_hits", "free_runs", "ArrayWindow", "RUNS"]

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
    R = dict(zip(range(-2, 3), rises))
    F = dict(zip(range(-2, 3), falls))
    pre = np.zeros_like(rises[2])
    for a, e in RUNS:
        pre |= run_pair(R[a], F[e])
    return pre


def run_pair(rise: np.ndarray, fall: np.ndarray, *, work: tuple | None = None,
             out: np.ndarray | None = None) -> np.ndarray:
    """Pixels that may lie in the run [a, e]: a rise at a, a fall at e, and two such neighbours (3 x 3).

    Parameters
    ----------
    rise, fall : (M, N) bool arrays
        ``I_a - I_{a-1} >= c`` and ``I_e - I_{e+1} >= c``.
    work : tuple of two (M, N) uint8 arrays, optional
        Scratch space for the intermediates (overwritten).
    out : (M, N) uint8 array, optional
        Receives the result (returned as a bool view); neither ``rise`` nor ``fall``.
    """
    import cv2

    count_buf, ok_buf = (None, None) if work is None else work
    # 0/1 uint8 throughout (bool views); a 3 x 3 count is at most 9, so it fits in uint8
    run = cv2.bitwise_and(rise.view(np.uint8), fall.view(np.uint8), dst=out)
    count = _count3x3(run, count_buf, ok_buf)
    ok = cv2.compare(count, 3, cv2.CMP_GE, ok_buf)
    run = cv2.bitwise_and(run, ok, dst=run)
    return run.view(bool)


def _count3x3(x: np.ndarray, out: np.ndarray | None = None, tmp: np.ndarray | None = None) -> np.ndarray:
    """Sum of the 3 x 3 neighbourhood of every pixel of a 0/1 uint8 image, zeros outside, uint8.

    The unnormalised 3 x 3 box filter with a zero border, as sums of shifted
    rows and columns (exact: the sums are at most 9).  ``out`` receives the
    result and ``tmp`` the row sums when given (uint8 arrays like ``x``).
    """
    import cv2

    h, w = x.shape
    if h < 3 or w < 3:
        return cv2.boxFilter(x, cv2.CV_8U, (3, 3), out, normalize=False, borderType=cv2.BORDER_CONSTANT)
    if out is None:
        out = np.empty_like(x)
    if tmp is None:
        tmp = np.empty_like(x)
    mid = tmp[:, 1:-1]
    cv2.add(x[:, :-2], x[:, 2:], dst=mid)
    cv2.add(mid, x[:, 1:-1], dst=mid)
    np.add(x[:, 0], x[:, 1], out=tmp[:, 0])
    np.add(x[:, -1], x[:, -2], out=tmp[:, -1])
    body = out[1:-1]
    cv2.add(tmp[:-2], tmp[2:], dst=body)
    cv2.add(body, tmp[1:-1], dst=body)
    np.add(tmp[0], tmp[1], out=out[0])
    np.add(tmp[-1], tmp[-2], out=out[-1])
    return out


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


def runs_in_values(v: np.ndarray, *, c: float, tol: float | None = None, c_inner: float | None = None,
                   steady: bool = False):
    """The run test of :func:`find_runs` on a (7, P) matrix of pixel values.

    Parameters
    ----------
    v : (7, P) array
        Luminance of frames n-3 .. n+3 at P pixels [gray levels].
    c : float
        Threshold of the centre frame over both unaffected frames [gray levels].
    tol : float, optional
        Largest difference between the two unaffected frames [gray levels].
    c_inner : float, optional
        Threshold of the run's other frames [gray levels]; default ``c``.  A
        lower value also finds a pixel crossed by a faint drop in the frame
        next to a bright one, whose change there is below c.
    steady : bool
        Also ask the background to hold one frame further out, on one side
        at least (with ``tol``): a moving texture changes every frame.

    Returns the bool (P,) hit mask and, for the hits, the indices (0-6) of the
    unaffected frames before and after the run.
    """
    P = v.shape[1]
    before = np.full(P, -1, np.int64)
    after = np.full(P, -1, np.int64)
    todo = np.ones(P, bool)
    c_in = c if c_inner is None else c_inner
    for a, e in RUNS:
        ia, ie = 3 + a, 3 + e
        outer = np.maximum(v[ia - 1], v[ie + 1])
        if c_in == c:
            ok = todo & (v[ia:ie + 1].min(axis=0) - outer >= c)
        else:
            others = np.concatenate([v[ia:3], v[4:ie + 1]]).min(axis=0)
            ok = todo & (v[3] - outer >= c) & (others - outer >= c_in)
        if tol is not None:
            ok &= np.abs(v[ia - 1] - v[ie + 1]) <= tol
            if steady:
                # the background also holds one frame further out on one side at least
                st = np.zeros(P, bool)
                if ia - 2 >= 0:
                    st |= np.abs(v[ia - 2] - v[ia - 1]) <= tol
                if ie + 2 <= 6:
                    st |= np.abs(v[ie + 2] - v[ie + 1]) <= tol
                ok &= st
        before[ok] = ia - 1
        after[ok] = ie + 1
        todo &= ~ok
    hit = before >= 0
    return hit, before[hit], after[hit]


def _work(window, name, shape, dtype):
    """A scratch array from the window when it keeps some (frame loops), else None (allocate)."""
    scratch = getattr(window, "scratch", None)
    return None if scratch is None else scratch(name, shape, dtype)


class ArrayWindow:
    """Seven frames n-3 .. n+3 already aligned to frame n, as full arrays.

    The interface :func:`remove_window` reads: ``shape``, ``centre_lum``,
    ``lum_at(k, idx)``, ``lin_at(k, idx)``, ``run_candidates(c)`` and,
    optionally, ``centre_steps(c)`` (None: no restriction) and
    ``scratch(name, shape, dtype)`` (frame-sized arrays for temporaries,
    reused from frame to frame; without it they are allocated).
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

    def centre_steps(self, c: float) -> np.ndarray:
        """Pixels of frame n at least ``c`` above frame n-1 or frame n+1 [gray levels], (M, N) bool."""
        c32 = np.float32(c)
        return (self.lum[3] - self.lum[2] >= c32) | (self.lum[3] - self.lum[4] >= c32)

    def run_candidates(self, c: float) -> np.ndarray:
        # the runs start at n-2 .. n and end at n .. n+2: three rises and
        # three falls are all :func:`run_prefilter` reads
        c32 = np.float32(c)
        rises = {a: self.lum[3 + a] - self.lum[2 + a] >= c32 for a in (-2, -1, 0)}
        falls = {e: self.lum[3 + e] - self.lum[4 + e] >= c32 for e in (0, 1, 2)}
        pre = np.zeros(self.shape, bool)
        for a, e in RUNS:
            pre |= run_pair(rises[a], falls[e])
        return pre


def remove_window(window, rain: np.ndarray, region: np.ndarray, *, c: float, runs: bool = True,
                  tol: float | None = None, grow_px: int = 1, grow_threshold: float | None = None,
                  beta_max: float | None = None, noise_sigma: float = 1.0, min_pixels: int = 5,
                  near_px: int = 0, c_inner: float | None = None, free_out: list | None = None,
                  rain_idx: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The rules of Sec. 5.2 on a window of frames; see :func:`remove_rain`.

    ``free_out`` (a list) receives the free-standing runs of frame n found
    by :func:`free_runs`, ``(flat, before, after)``, for the detection to share.
    ``rain_idx``: the flat indices of the pixels of ``rain`` (increasing), when known.

    Returns
    -------
    idx : (P,) int array
        Flat indices of the replaced pixels of frame n.
    values : (P, C) float32 array
        Their background estimates [gray levels].
    """
    import cv2

    single = _work(window, "rw_single", rain.shape, np.bool_)
    single = rain & region if single is None else np.logical_and(rain, region, out=single)
    if rain_idx is not None and region.dtype == np.bool_:
        idx = rain_idx[region.ravel()[rain_idx]]
    else:
        idx = np.flatnonzero(single.ravel())
    examine = None
    # frames n-1 and n+1 at idx, kept for the background when they are the
    # frames themselves (gray video: lin_at is lum_at)
    keep = getattr(window, "lin_is_lum", False)
    v2 = v4 = None
    if tol is not None and idx.size:
        # (I_{n-1} + I_{n+1}) / 2 is the background only where the two agree;
        # elsewhere a drop hit a neighbouring frame too (left to the run tests)
        v2, v4 = window.lum_at(2, idx), window.lum_at(4, idx)
        unsteady = np.abs(v2 - v4) > tol
        if unsteady.any():
            examine = idx[unsteady]
            single.ravel()[examine] = False
            idx = idx[~unsteady]
            v2, v4 = v2[~unsteady], v4[~unsteady]
    if grow_px > 0 and idx.size:
        k = 2 * int(grow_px) + 1
        near = cv2.dilate(single.view(np.uint8), np.ones((k, k), np.uint8),
                          _work(window, "rw_near", single.shape, np.uint8)).view(bool)
        np.logical_and(near, region, out=near)
        np.greater(near, single, out=near)          # and not single
        nidx = np.flatnonzero(near.ravel())
        thr = 0.5 * c if grow_threshold is None else grow_threshold
        n2, n4 = window.lum_at(2, nidx), window.lum_at(4, nidx)
        change = window.centre_lum.ravel()[nidx] - 0.5 * (n2 + n4)
        up = change > thr
        grown = nidx[up]
        if grown.size:
            single.ravel()[grown] = True
            idx = np.concatenate([idx, grown])
            if v2 is not None:
                v2, v4 = np.concatenate([v2, n2[up]]), np.concatenate([v4, n4[up]])
    if not idx.size:
        values = None
    elif keep and v2 is not None:
        values = (0.5 * (v2 + v4))[:, None]
    else:
        values = 0.5 * (window.lin_at(2, idx) + window.lin_at(4, idx))
    out_idx, out_vals = [idx], [values]
    if runs and np.any(region):
        flat, before, after = multi_frame_hits(window, single, c=c, where=region, tol=tol, beta_max=beta_max,
                                               noise_sigma=noise_sigma, min_pixels=min_pixels, near_px=near_px,
                                               c_inner=c_inner, examine=examine, free_out=free_out)
        if flat.size:
            out_idx.append(flat)
            out_vals.append(_run_values(window, flat, before, after))
    idx_all = np.concatenate(out_idx)
    vals = [x for x in out_vals if x is not None]
    vals_all = np.concatenate(vals) if vals else np.zeros((0, 1), np.float32)
    return idx_all, vals_all.astype(np.float32, copy=False)


def multi_frame_hits(window, rain: np.ndarray, *, c: float, where: np.ndarray | None = None,
                     tol: float | None = None, beta_max: float | None = None, noise_sigma: float = 1.0,
                     min_pixels: int = 5, near_px: int = 2, c_inner: float | None = None,
                     examine: np.ndarray | None = None, free: tuple | None = None,
                     free_out: list | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels of frame n hit by drops in 2 or 3 consecutive frames, Sec. 5.2 and note 16 [GargNayar2007].

    Two tests, both on the run of frames [a, e] through n against the
    unaffected frames a-1 and e+1 (:func:`runs_in_values`):

    - next to the rain pixels of frame n (within ``near_px``), the centre
      frame must be c above both unaffected frames and the run's other
      frames ``c_inner`` above them: where a streak of frame n crosses a drop
      of frame n-1 or n+1, the streak has a gap that the one-frame test of
      Eq. (19) leaves, and the other drop is often faint (skipped when the
      window says ``free_runs = False``, next to local scene motion, where a
      moving texture passes it as easily);
    - elsewhere every frame of the run must be c above both (the pixels
      :meth:`run_candidates` proposes), and when ``beta_max`` is given the
      runs are grouped into streaks that must pass the photometric test of
      Eq. (18) with the unaffected frames as background.

    Parameters
    ----------
    window : ArrayWindow or a window with the same interface
        Frames n-3 .. n+3 aligned to frame n.
    rain : (M, N) bool array
        One-frame rain pixels of frame n (the binary field b).
    c : float
        Detection threshold [gray levels].
    where : (M, N) bool array, optional
        Only these pixels are examined (e.g. the rain region); default all.
    tol : float, optional
        Largest difference between the two unaffected frames [gray levels].
    beta_max : float, optional
        Largest Eq. (18) slope [dimensionless].
    noise_sigma : float
        Camera noise [gray levels].
    min_pixels : int
        Smallest streak of runs [px].
    near_px : int
        Reach of the first test [px]; 0 leaves only the second (the paper's rule).
        Only the pixels where frame n is c above frame n-1 or n+1
        (``window.centre_steps(c)``, when the window has it) and where frame
        n+1 (n-1) is ``c_inner`` above frame n-1 (n+1) are sampled in all 7
        frames: the relaxed test finds the runs that begin or end at n; the
        3-frame run [n-1, n+1] is left to the second test.
    c_inner : float, optional
        Default c / 2 [gray levels].
    examine : (M, N) bool array or (Q,) int array of flat indices, optional
        More pixels for the first test, wherever they lie (e.g. pixels of b
        whose neighbouring frames disagree: a drop in two consecutive frames).
    free : tuple of three (P,) int arrays, optional
        The second test already run (:func:`free_runs`, over these pixels or
        more): its hits are kept where ``where`` holds and the first test
        found nothing, so that detection and removal share it.
    free_out : list, optional
        Receives the hits of the second test, ``(flat, before, after)``.

    Returns
    -------
    flat : (P,) int array
        Flat indices of the pixels (none of them in ``rain``).
    before, after : (P,) int arrays
        Indices (0-6) of the unaffected frames on either side.
    """
    import cv2

    rain = np.ascontiguousarray(rain, dtype=bool)
    if where is None:
        where = np.ones(rain.shape, bool)
    empty = np.zeros(0, np.int64)
    found = [(empty, empty, empty)]
    done = rain
    known: dict = {}      # rows of the 7-frame values already gathered at ``flat``
    # next to local scene motion (a window that allows no free-standing runs)
    # a moving texture passes the relaxed test as easily as a crossing drop
    if ((near_px > 0 and rain.any()) or examine is not None) and getattr(window, "free_runs", True):
        if near_px > 0:
            k = 2 * int(near_px) + 1
            near = cv2.dilate(rain.view(np.uint8), np.ones((k, k), np.uint8),
                              _work(window, "mfh_near", rain.shape, np.uint8)).view(bool)
            # the centre frame c above both unaffected frames: a run that starts
            # at n rises there, one that ends at n falls there (the centre
            # frame's own one-sided tests of Eq. 19); only those pixels are
            # sampled in 7 frames
            steps = window.centre_steps(c) if hasattr(window, "centre_steps") else None
            if steps is not None:
                near &= steps
        flat = empty
        if near_px > 0:
            np.logical_and(near, where, out=near)
            np.greater(near, rain, out=near)        # and not rain
            flat = np.flatnonzero(near.ravel())
            if flat.size:
                # frames n-1 and n+1 first: a run that starts at n has frame
                # n+1 inside it (c_inner above frame n-1) unless it is n alone,
                # and one that ends at n has frame n-1 inside it
                ci = np.float32(0.5 * c if c_inner is None else c_inner)
                c32 = np.float32(c)
                v3 = window.centre_lum.ravel()[flat]
                v2 = window.lum_at(2, flat)
                v4 = window.lum_at(4, flat)
                ok = ((v3 - v2 >= c32) & (v4 - v2 >= ci)) | ((v3 - v4 >= c32) & (v2 - v4 >= ci))
                flat = flat[ok]
                known = {2: v2[ok], 3: v3[ok], 4: v4[ok]}     # (read again below)
        if examine is not None:
            extra = np.flatnonzero(examine.ravel()) if examine.dtype == bool else np.asarray(examine, np.int64)
            ok = where.ravel()[extra] & ~rain.ravel()[extra]
            if near_px > 0:
                ok &= ~near.ravel()[extra]
            flat = np.sort(np.concatenate([flat, extra[ok]]))
            known = {}
        if flat.size:
            c_in = 0.5 * c if c_inner is None else c_inner
            v, pos = _run_rows(window, flat, c=c, c_in=c_in, tol=tol, known=known)
            flat = flat[pos]
            hit, before, after = runs_in_values(v, c=c, tol=tol, c_inner=c_in, steady=True)
            flat = flat[hit]
            if flat.size:
                found.append((flat, before, after))
    hits = found[-1][0]     # increasing flat indices (the first test's, or none)
    if free is None:
        if hits.size:
            done = _work(window, "mfh_done", rain.shape, np.bool_)
            if done is None:
                done = rain.copy()
            else:
                np.copyto(done, rain)
            done.ravel()[hits] = True
        free = free_runs(window, done, c=c, where=where, tol=tol, beta_max=beta_max, noise_sigma=noise_sigma,
                         min_pixels=min_pixels)
    else:
        flat, before, after = free
        keep = where.ravel()[flat] & ~rain.ravel()[flat]
        if hits.size and flat.size:   # ... and not found by the first test
            at = np.minimum(np.searchsorted(hits, flat), hits.size - 1)
            keep &= hits[at] != flat
        free = (flat[keep], before[keep], after[keep])
    if free_out is not None:
        free_out.append(free)
    found.append(free)
    return tuple(np.concatenate([f[i] for f in found]).astype(np.int64) for i in range(3))


def free_runs(window, rain: np.ndarray, *, c: float, where: np.ndarray | None = None, tol: float | None = None,
              beta_max: float | None = None, noise_sigma: float = 1.0, min_pixels: int = 5
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Free-standing 2- and 3-frame runs through frame n, the second test of :func:`multi_frame_hits`.

    Every frame of the run [a, e] is at least ``c`` above both unaffected
    frames a-1 and e+1 (Sec. 5.2 and note 16 [GargNayar2007]), among the
    pixels ``window.run_candidates(c)`` proposes (a rise at a, a fall at e);
    with ``beta_max`` the runs are grouped into streaks that must pass the
    photometric test of Eq. (18) with the unaffected frames as background.

    Parameters
    ----------
    window : ArrayWindow or a window with the same interface
        Frames n-3 .. n+3 aligned to frame n.
    rain : (M, N) bool array
        Pixels already known (left out).
    c, tol, beta_max, noise_sigma, min_pixels
        See :func:`multi_frame_hits`.
    where : (M, N) bool array, optional
        Only these pixels are examined; default all.

    Returns
    -------
    flat, before, after : (P,) int arrays
        Flat indices of the pixels and the indices (0-6) of the unaffected frames.
    """
    empty = np.zeros(0, np.int64)
    pre = window.run_candidates(c)
    if pre.dtype == np.bool_ and rain.dtype == np.bool_:     # pre and not rain, without a temporary
        sel = np.greater(pre, rain, out=_work(window, "fr_sel", rain.shape, np.bool_))
    else:
        sel = pre & ~rain
    if where is not None:
        np.logical_and(sel, where, out=sel)
    flat = np.flatnonzero(sel.ravel())
    if not flat.size:
        return empty, empty, empty
    v, pos = _run_rows(window, flat, c=c, c_in=c, tol=tol)
    flat = flat[pos]
    hit, before, after = runs_in_values(v, c=c, tol=tol)
    flat, v = flat[hit], v[:, hit]
    if flat.size and beta_max is not None:
        from raingauge.vision.photometric import _accept_pixels

        # the runs' streaks with the unaffected frames as background, on the
        # run pixels alone (no frame-sized images or labelling)
        cols = np.arange(flat.size)
        keep = _accept_pixels(flat, v[before, cols], v[3], v[after, cols], window.shape, beta_max=beta_max,
                              noise_sigma=noise_sigma, min_pixels=min_pixels)
        flat, before, after = flat[keep], before[keep], after[keep]
    return flat.astype(np.int64), before.astype(np.int64), after.astype(np.int64)


def _run_rows(window, flat, *, c, c_in, tol=None, known=None):
    """The (7, Q) luminance of frames n-3 .. n+3 at the pixels of ``flat`` that may hold a run, and their
    positions in ``flat``: the rows :func:`runs_in_values` reads, without sampling every frame everywhere.

    Every run [a, e] holds frame n, which must be ``c`` above both unaffected
    frames a-1 and e+1, and its other frames ``c_in`` above them (and the two
    within ``tol`` of each other); frames n-2 .. n+2 alone rule out most
    pixels.  A difference of two values rounds no higher than that of a larger
    and a smaller value, so no pixel with a run is left out.  ``known`` maps
    frame offsets 0-6 to rows already gathered at ``flat``.
    """
    known = known or {}

    def row(k, at):
        if k in known:
            return known[k]
        return window.centre_lum.ravel()[at] if k == 3 else window.lum_at(k, at)

    v1, v2, v3, v4, v5 = (row(k, flat) for k in (1, 2, 3, 4, 5))
    # (the tests below run in the type of the stacked rows)
    dt = np.result_type(v1, v2, v3, v4, v5)
    v1, v2, v3, v4, v5 = (x.astype(dt, copy=False) for x in (v1, v2, v3, v4, v5))
    d31, d34, d32, d35 = v3 - v1 >= c, v3 - v4 >= c, v3 - v2 >= c, v3 - v5 >= c
    t14 = t25 = t15 = True
    if tol is not None:
        t14, t25, t15 = np.abs(v1 - v4) <= tol, np.abs(v2 - v5) <= tol, np.abs(v1 - v5) <= tol
    may = d31 & d34 & (v2 - v1 >= c_in) & (v2 - v4 >= c_in) & t14         # [n-1, n]
    may |= d32 & d35 & (v4 - v2 >= c_in) & (v4 - v5 >= c_in) & t25        # [n, n+1]
    may |= d34 & (v1 - v4 >= c_in) & (v2 - v4 >= c_in)                    # [n-2, n]
    may |= (d31 & d35 & (v2 - v1 >= c_in) & (v2 - v5 >= c_in) & (v4 - v1 >= c_in)
            & (v4 - v5 >= c_in) & t15)                                      # [n-1, n+1]
    may |= d32 & (v4 - v2 >= c_in) & (v5 - v2 >= c_in)                    # [n, n+2]
    pos = np.flatnonzero(may)
    sub = flat[pos]
    v0, v6 = window.lum_at(0, sub), window.lum_at(6, sub)
    if np.result_type(dt, v0, v6) != dt:     # frames n-3, n+3 of a wider type: every pixel, as it is
        pos = np.arange(flat.size)
        return np.stack([row(k, flat) for k in range(7)]), pos
    return np.stack([v0, v1[pos], v2[pos], v3[pos], v4[pos], v5[pos], v6]), pos


def _run_values(window, flat, before, after):
    """Mean of the unaffected frames on either side of each run, (P, C) float32."""
    vals = np.empty((flat.size, window.lin_at(3, flat[:1]).shape[-1]), np.float32)
    for kb in np.unique(before):
        for ka in np.unique(after[before == kb]):
            sel = (before == kb) & (after == ka)
            vals[sel] = 0.5 * (window.lin_at(int(kb), flat[sel]) + window.lin_at(int(ka), flat[sel]))
    return vals


def remove_rain(frames: np.ndarray, lum: np.ndarray, rain: np.ndarray, region: np.ndarray, *, c: float,
                runs: bool = True, tol: float | None = None, grow_px: int = 1,
                grow_threshold: float | None = None, beta_max: float | None = None,
                noise_sigma: float = 1.0, min_pixels: int = 5, near_px: int = 0,
                c_inner: float | None = None) -> tuple[np.ndarray, np.ndarray]:
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
    near_px : int
        Within this distance of the rain pixels of frame n [px], a 2- or
        3-frame run needs only its centre frame c above the unaffected
        frames, the others ``c_inner``: the pixels where the streak crosses
        a faint drop of the neighbouring frame (:func:`multi_frame_hits`).
        0 (the default) follows the paper.  On a static scene 2 removes
        more rain; next to moving objects the unaffected frames, two frames
        apart, are a worse background than the moving texture's own.
    c_inner : float, optional
        Default c / 2 [gray levels].

    Returns
    -------
    derained : array like ``frames[3]`` (float32)
    replaced : (M, N) bool array
        Pixels that were changed.
    """
    win = ArrayWindow(frames, lum)
    idx, vals = remove_window(win, rain, region, c=c, runs=runs, tol=tol, grow_px=grow_px,
                              grow_threshold=grow_threshold, beta_max=beta_max, noise_sigma=noise_sigma,
                              min_pixels=min_pixels, near_px=near_px, c_inner=c_inner)
    out = win.centre_lin.copy()
    n = win.centre_lum.size
    if idx.size:
        out.reshape(n, -1)[idx] = vals.reshape(idx.size, -1)
    replaced = np.zeros(win.shape, bool)
    replaced.ravel()[idx] = True
    return out, replaced
