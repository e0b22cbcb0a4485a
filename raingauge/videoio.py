"""Reading and writing frame sequences: video files and folders of images.

Frames are numpy arrays, (M, N) for gray or (M, N, 3) in OpenCV's BGR order,
dtype uint8.  A "video" is either a file OpenCV reads (lossless output is FFV1
in ``.mkv``) or a folder of images taken in name order.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterator

import numpy as np

from raingauge.errors import InputError

__all__ = ["FrameReader", "FrameWriter", "read_frames", "is_image_folder_path", "IMAGE_SUFFIXES"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")
VIDEO_FOURCC = {".mkv": "FFV1", ".avi": "FFV1", ".mp4": "mp4v"}


def is_image_folder_path(path: str | os.PathLike) -> bool:
    """True when ``path`` names (or should name) a folder of images rather than a video file."""
    p = Path(path)
    return p.is_dir() or p.suffix.lower() not in VIDEO_FOURCC


def _to_mode(frame: np.ndarray, mode: str) -> np.ndarray:
    import cv2

    if mode == "gray":
        if frame.ndim == 3:
            return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        return frame
    if mode == "bgr":
        if frame.ndim == 2:
            return cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        return frame
    return frame


class FrameReader:
    """Iterate over the frames of a video file or an image folder.

    Parameters
    ----------
    path : str or Path
        Video file, or folder of images (sorted by name).
    mode : {"auto", "gray", "bgr"}
        ``auto`` gives gray frames when the source is gray (a colour video whose
        three channels are equal counts as gray), BGR otherwise.

    Attributes
    ----------
    fps : float or None
        Frame rate stored in the video (``None`` for image folders).
    n_frames : int or None
        Number of frames when known in advance.
    corrupt_frames : int
        Images in a folder that could not be decoded and were skipped.
    """

    def __init__(self, path: str | os.PathLike, *, mode: str = "auto"):
        import cv2

        if mode not in ("auto", "gray", "bgr"):
            raise ValueError(f"mode must be 'auto', 'gray' or 'bgr', got {mode!r}")
        self.path = Path(path)
        self.mode = mode
        self.corrupt_frames = 0
        self._files: list[Path] | None = None
        self.fps: float | None = None
        if not self.path.exists():
            raise InputError(f"{self.path}: no such file or folder. Fix: give a video file or a folder of images")
        if self.path.is_dir():
            files = sorted(p for p in self.path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
            if not files:
                raise InputError(
                    f"{self.path}: folder holds no images ({', '.join(IMAGE_SUFFIXES)}). "
                    "Fix: point at the folder that holds the frames"
                )
            self._files = files
            self.n_frames = len(files)
        else:
            cap = cv2.VideoCapture(str(self.path))
            ok = cap.isOpened()
            if ok:
                self.fps = float(cap.get(cv2.CAP_PROP_FPS)) or None
                n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
                self.n_frames = n if n > 0 else None
            cap.release()
            if not ok:
                raise InputError(
                    f"{self.path}: OpenCV cannot open this video. Fix: convert it (e.g. to FFV1 .mkv) "
                    "or give a folder of images"
                )

    def __len__(self) -> int:
        if self.n_frames is None:
            raise TypeError("frame count unknown for this video")
        return self.n_frames

    def _raw(self) -> Iterator[np.ndarray]:
        import cv2

        if self._files is not None:
            for f in self._files:
                img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
                if img is None or img.size == 0:
                    self.corrupt_frames += 1
                    continue
                if img.dtype != np.uint8:
                    img = (img / 257).astype(np.uint8) if img.dtype == np.uint16 else img.astype(np.uint8)
                if img.ndim == 3 and img.shape[2] == 4:
                    img = img[:, :, :3]
                yield img
        else:
            cap = cv2.VideoCapture(str(self.path))
            try:
                while True:
                    ok, img = cap.read()
                    if not ok:
                        break
                    yield img
            finally:
                cap.release()

    def __iter__(self) -> Iterator[np.ndarray]:
        mode = self.mode
        for frame in self._raw():
            if mode == "auto":
                if frame.ndim == 3:
                    same = np.array_equal(frame[..., 0], frame[..., 1]) and np.array_equal(frame[..., 1], frame[..., 2])
                    mode = "gray" if same else "bgr"
                else:
                    mode = "gray"
            yield _to_mode(frame, mode)


def read_frames(path: str | os.PathLike, *, mode: str = "auto", limit: int | None = None) -> np.ndarray:
    """Read a whole clip into a (T, M, N) or (T, M, N, 3) uint8 array."""
    frames = []
    for i, f in enumerate(FrameReader(path, mode=mode)):
        if limit is not None and i >= limit:
            break
        frames.append(f)
    if not frames:
        raise InputError(f"{path}: no frame could be read. Fix: check the file is a valid video")
    return np.stack(frames)


class FrameWriter:
    """Write frames to a video file (FFV1 ``.mkv``: lossless) or a folder of PNG images.

    The kind follows the path: a known video suffix (``.mkv``, ``.avi``,
    ``.mp4``) writes a video, anything else a folder ``00001.png, 00002.png, ...``.
    Use as a context manager.
    """

    def __init__(self, path: str | os.PathLike, *, fps: float = 30.0, image_suffix: str = ".png"):
        self.path = Path(path)
        self.fps = float(fps)
        self.image_suffix = image_suffix
        self.count = 0
        self._writer = None
        self._folder = is_image_folder_path(self.path)
        try:
            if self._folder:
                self.path.mkdir(parents=True, exist_ok=True)
            else:
                self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"{self.path}: cannot create the output {'folder' if self._folder else 'video'} "
                             f"({exc.strerror or exc}). Fix: give a path in a writable folder") from None

    def write(self, frame: np.ndarray) -> None:
        import cv2

        frame = np.asarray(frame)
        if frame.dtype != np.uint8:
            raise ValueError(f"frames must be uint8, got {frame.dtype}")
        if self._folder:
            name = self.path / f"{self.count + 1:05d}{self.image_suffix}"
            if not cv2.imwrite(str(name), frame):
                raise InputError(f"{name}: could not write image (disk full or no permission?)")
        else:
            if self._writer is None:
                color = frame.ndim == 3
                fourcc = cv2.VideoWriter_fourcc(*VIDEO_FOURCC[self.path.suffix.lower()])
                h, w = frame.shape[:2]
                self._writer = cv2.VideoWriter(str(self.path), fourcc, self.fps, (w, h), color)
                if not self._writer.isOpened():
                    raise InputError(f"{self.path}: OpenCV cannot write this video kind. Fix: use .mkv or a folder")
            self._writer.write(frame)
        self.count += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.release()
            self._writer = None

    def __enter__(self) -> "FrameWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
