"""Simple methods the paper's algorithm is compared with.

``temporal_median``  median filtering over time, Fig. 10 [GargNayar2007]: removes
                     some rain and also alters everything that moves.
``MOG2Detector``     OpenCV's adaptive Gaussian-mixture background subtraction
                     [Zivkovic2004]: calls every change rain, including motion.
"""

from __future__ import annotations

import numpy as np

__all__ = ["temporal_median", "median_frame", "MOG2Detector", "mog2_derain"]


def median_frame(window: np.ndarray) -> np.ndarray:
    """Median over the first axis of a (T, M, N[, C]) window, same dtype as the input."""
    window = np.asarray(window)
    med = np.median(window, axis=0)
    if window.dtype == np.uint8:
        return np.rint(med).astype(np.uint8)
    return med.astype(window.dtype, copy=False)


def temporal_median(frames: np.ndarray, *, radius: int = 2) -> np.ndarray:
    """Median filter over time, Fig. 10 [GargNayar2007].

    Parameters
    ----------
    frames : (T, M, N) or (T, M, N, C) array
    radius : int
        Half window [frames]; the window is 2 radius + 1 frames, shortened at
        the ends of the clip.

    Returns
    -------
    Array like ``frames``: one output frame per input frame.
    """
    frames = np.asarray(frames)
    if radius < 1:
        raise ValueError(f"radius must be at least 1 frame, got {radius!r}")
    T = frames.shape[0]
    out = np.empty_like(frames)
    for t in range(T):
        lo, hi = max(0, t - radius), min(T, t + radius + 1)
        out[t] = median_frame(frames[lo:hi])
    return out


class MOG2Detector:
    """Rain pixels as OpenCV MOG2 foreground [Zivkovic2004].

    Parameters
    ----------
    history : int
        Frames the mixture model remembers.
    var_threshold : float
        Squared Mahalanobis distance for a pixel to be foreground.
    """

    def __init__(self, *, history: int = 30, var_threshold: float = 16.0):
        import cv2

        self._sub = cv2.createBackgroundSubtractorMOG2(history=history, varThreshold=var_threshold,
                                                       detectShadows=False)

    def apply(self, frame: np.ndarray) -> np.ndarray:
        """Update with a uint8 frame and return its foreground as an (M, N) bool mask."""
        frame = np.asarray(frame)
        if frame.dtype != np.uint8:
            frame = np.clip(np.rint(frame), 0, 255).astype(np.uint8)
        return self._sub.apply(frame) > 0

    def background(self) -> np.ndarray:
        """The current background image (uint8)."""
        return self._sub.getBackgroundImage()


def mog2_derain(frames: np.ndarray, *, history: int = 30, var_threshold: float = 16.0
                ) -> tuple[np.ndarray, np.ndarray]:
    """Replace MOG2 foreground pixels by the MOG2 background image.

    Parameters
    ----------
    frames : (T, M, N) or (T, M, N, 3) uint8 array

    Returns
    -------
    derained : array like ``frames``
    masks : (T, M, N) bool array of foreground pixels
    """
    det = MOG2Detector(history=history, var_threshold=var_threshold)
    frames = np.asarray(frames)
    out = frames.copy()
    masks = np.zeros(frames.shape[:3], bool)
    for t, fr in enumerate(frames):
        m = det.apply(fr)
        masks[t] = m
        bg = det.background()
        if bg is not None and bg.shape == fr.shape:
            out[t][m] = bg[m]
    return out, masks
