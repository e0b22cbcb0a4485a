"""Frame sources of the calibration steps: live cameras named ``camera:N`` and linearised gray frames.

Every step that reads frames (geometry, noise, dry run) names a live camera
the same way and checks the frames the same way: gray (M, N), one size for
the whole capture, 8-bit codes linearised through the profile's response
table.
"""

from __future__ import annotations

from typing import Iterable, Iterator

import numpy as np

from raingauge.errors import InputError

__all__ = ["is_camera", "camera_device", "linear_gray_frames"]


def is_camera(source) -> bool:
    """True when ``source`` names a live camera, ``camera:N`` (or ``camera:/dev/video0``)."""
    return str(source).startswith("camera:")


def camera_device(source: str) -> int | str:
    """The ``cv2.VideoCapture`` argument of ``camera:N``: the device index N, or the text after the colon."""
    spec = str(source).split(":", 1)[1]
    return int(spec) if spec.isdigit() else spec


def linear_gray_frames(frames: Iterable[np.ndarray], *, table: np.ndarray | None = None,
                       dtype=np.float64, step: str, what: str = "frames") -> Iterator[np.ndarray]:
    """Yield the frames as linear gray levels, one at a time, checking their shape.

    Parameters
    ----------
    frames : iterable of (M, N) arrays, or a (T, M, N) array
        uint8 codes, or floats already linear [gray levels].
    table : (256,) float, optional
        Linearisation table for uint8 frames [gray levels].
    dtype : numpy dtype
        Type of the yielded frames.
    step, what : str
        Names used in the error messages ("noise step", "still frames").

    Yields
    ------
    (frame, quantised) : ((M, N) array of ``dtype`` [gray levels], bool)
        The linear frame, and whether it came from 8-bit codes.

    Raises
    ------
    InputError
        A frame is not 2-D, or the frames differ in size.
    """
    lut = None if table is None else np.asarray(table, dtype=dtype)
    shape = None
    for frame in frames:
        frame = np.asarray(frame)
        if frame.ndim != 2:
            raise InputError(f"{step}: expected gray (M, N) frames, got shape {frame.shape}")
        if shape is None:
            shape = frame.shape
        elif frame.shape != shape:
            raise InputError(f"{step}: the {what} differ in size. Fix: keep the camera mode fixed")
        quantised = frame.dtype == np.uint8
        yield (lut[frame] if (lut is not None and quantised) else frame.astype(dtype)), quantised
