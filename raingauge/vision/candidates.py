"""Candidate rain pixels: the one-frame positive spike of Eq. (19) [GargNayar2007].

A drop stays over a pixel for tau < 1.18 ms, far less than the exposure, so it
brightens that pixel in a single frame only (Sec. 4.3, Fig. 9(b)).  With a
stationary background the frames before and after agree, and the rain pixel
stands out from both by at least the detection threshold c.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["candidates", "spike_change", "luminance", "hysteresis_candidates"]

def luminance(frame: np.ndarray) -> np.ndarray:
    """Luminance of a frame [gray levels], float32 (M, N).

    Parameters
    ----------
    frame : (M, N) or (M, N, 3) array
        Gray or BGR frame (linearised or 8-bit) [gray levels].

    Notes
    -----
    ITU-R BT.601 weights (0.299 R + 0.587 G + 0.114 B).  Colour video is
    detected on luminance and cleaned on every channel.  For a linearised frame
    the weighted sum is a linear luminance.
    """
    frame = np.asarray(frame)
    if frame.ndim == 2:
        return frame.astype(np.float32, copy=False)
    if frame.ndim == 3 and frame.shape[2] == 3:
        import cv2

        return cv2.cvtColor(frame.astype(np.float32, copy=False), cv2.COLOR_BGR2GRAY)
    raise ValueError(f"expected a (M, N) or (M, N, 3) frame, got shape {frame.shape}")


def _check_triplet(prev, cur, nxt):
    prev = np.asarray(prev)
    cur = np.asarray(cur)
    nxt = np.asarray(nxt)
    if cur.ndim != 2:
        raise ValueError(f"candidates works on (M, N) luminance frames, got shape {cur.shape}; "
                         "use raingauge.vision.luminance() on colour frames first")
    if prev.shape != cur.shape or nxt.shape != cur.shape:
        raise ValueError(f"frames must share one shape, got {prev.shape}, {cur.shape}, {nxt.shape}")
    f32 = np.float32
    return (prev.astype(f32, copy=False), cur.astype(f32, copy=False), nxt.astype(f32, copy=False))


def spike_change(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray) -> np.ndarray:
    """The one-frame change min(I_n - I_{n-1}, I_n - I_{n+1}) [gray levels], float32 (M, N).

    Parameters
    ----------
    prev, cur, nxt : (M, N) arrays
        Linearised frames n-1, n, n+1 [gray levels].
    """
    prev, cur, nxt = _check_triplet(prev, cur, nxt)
    return np.minimum(cur - prev, cur - nxt)


def candidates(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray, *, c: float = 3.0,
               tol: float | None = None, valid: np.ndarray | None = None) -> np.ndarray:
    """Candidate rain pixels of frame n, Eq. (19) [GargNayar2007].

    ``Delta I = I_n - I_{n-1} = I_n - I_{n+1} >= c``: a positive spike of one
    frame against both neighbours.

    Parameters
    ----------
    prev, cur, nxt : (M, N) float arrays
        Linearised frames n-1, n and n+1 [gray levels], aligned to frame n.
    c : float
        Detection threshold [gray levels]; the paper uses 3.
    tol : float, optional
        Largest allowed |I_{n-1} - I_{n+1}| [gray levels], the stationarity
        half of Eq. (19).  ``None`` (the default, as in the paper's Fig. 11(a))
        does not test it.
    valid : (M, N) bool array, optional
        Pixels where all three frames hold data (after motion compensation);
        others are never candidates.

    Returns
    -------
    (M, N) bool array
    """
    if not np.isfinite(c) or c <= 0:
        raise ValueError(f"threshold c must be a positive number of gray levels, got {c!r}")
    prev, cur, nxt = _check_triplet(prev, cur, nxt)
    thr = cur - np.float32(c)
    mask = (prev <= thr) & (nxt <= thr)
    if tol is not None:
        mask &= np.abs(prev - nxt) <= np.float32(tol)
    if valid is not None:
        mask &= valid
    return mask



def hysteresis_candidates(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray, *, c: float = 3.0, c_low: float,
                          tol: float | None = None, valid: np.ndarray | None = None,
                          slack: np.ndarray | None = None, min_high: int = 1) -> np.ndarray:
    """Candidate rain pixels by hysteresis: Eq. (19) at c_low, kept where a streak reaches c.

    The one-frame spike test of Eq. (19) [GargNayar2007] is applied with a
    lower threshold ``c_low``; its 8-connected components are kept when they
    hold at least ``min_high`` pixels that pass the test at ``c``.  A faint
    streak (or the faint rim of a bright one), whose pixels straddle c in the
    noise, is then found whole instead of as scattered fragments, while noise
    alone passes the weaker test only at isolated pixels, which reach c
    rarely.  The components still go through the photometric test of Eq. (18).
    This is the hysteresis thresholding of edge detection [Canny1986] applied
    to the temporal spike.

    Parameters
    ----------
    prev, cur, nxt : (M, N) float arrays
        Linearised frames n-1, n, n+1 aligned to frame n [gray levels].
    c : float
        Eq. (19) threshold [gray levels].
    c_low : float
        Lower threshold, 0 < c_low <= c [gray levels].
    tol : float, optional
        Largest |I_{n-1} - I_{n+1}| [gray levels] (stationarity half of Eq. (19)).
        A pixel at c beyond it is no candidate.  A fainter pixel beyond it is
        no candidate either, but it still links its neighbours into one
        component: about one pixel in 150 of a faint streak fails a 3-sigma
        test, and in a streak one or two pixels wide one missing pixel would
        cut it into pieces, most without a pixel at c.
    valid : (M, N) bool array, optional
        Pixels where all three frames hold data.
    slack : (M, N) float array, optional
        Extra threshold per pixel [gray levels] (registration error of warped
        neighbours), added to both thresholds.
    min_high : int
        Pixels at c a component needs [px].

    Returns
    -------
    (M, N) bool array
    """
    import cv2

    if not (math.isfinite(c) and c > 0):
        raise ValueError(f"threshold c must be a positive number of gray levels, got {c!r}")
    if not (math.isfinite(c_low) and 0 < c_low <= c):
        raise ValueError(f"c_low must lie in (0, c] gray levels, got {c_low!r} (c = {c!r})")
    prev, cur, nxt = _check_triplet(prev, cur, nxt)
    spike = np.minimum(cur - prev, cur - nxt)
    if slack is not None:
        spike -= np.asarray(slack, np.float32)
    low = spike >= np.float32(c_low)
    idx = np.flatnonzero(low.ravel())
    moved = None
    if tol is not None and idx.size:
        moved = np.abs(prev.ravel()[idx] - nxt.ravel()[idx]) > np.float32(tol)
        drop = moved & (spike.ravel()[idx] >= np.float32(c))
        if c_low == c:
            drop = moved
        low.ravel()[idx[drop]] = False
        idx, moved = idx[~drop], moved[~drop]
    if valid is not None:
        inside = np.asarray(valid, dtype=bool).ravel()[idx]
        low &= np.asarray(valid, dtype=bool)
        idx = idx[inside]
        moved = moved[inside] if moved is not None else None
    if c_low == c or idx.size == 0:
        return low
    n, lab = cv2.connectedComponents(low.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    li = lab.ravel()[idx]
    high = spike.ravel()[idx] >= np.float32(c)
    keep = np.bincount(li[high], minlength=n) >= max(int(min_high), 1)
    keep[0] = False
    take = keep[li]
    if moved is not None:
        take &= ~moved          # they link the streak but are not candidates themselves
    out = np.zeros(low.shape, bool)
    out.ravel()[idx[take]] = True
    return out
