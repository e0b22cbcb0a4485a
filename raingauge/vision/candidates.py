"""Candidate rain pixels: the one-frame positive spike of Eq. (19) [GargNayar2007].

A drop stays over a pixel for tau < 1.18 ms, far less than the exposure, so it
brightens that pixel in a single frame only (Sec. 4.3, Fig. 9(b)).  With a
stationary background the frames before and after agree, and the rain pixel
stands out from both by at least the detection threshold c.
"""

from __future__ import annotations

import numpy as np

__all__ = ["candidates", "spike_change", "luminance"]

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
