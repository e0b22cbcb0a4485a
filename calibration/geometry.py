"""Geometric calibration from checkerboard views (step 1 of ``raingauge calibrate``).

The pinhole model with OpenCV's radial/tangential distortion [Zhang2000]:
views of a planar checkerboard give, through ``cv2.findChessboardCorners``,
``cv2.cornerSubPix`` and ``cv2.calibrateCamera``, the focal length in pixels,
the principal point, the distortion coefficients and the RMS reprojection
error.  The gauge needs the focal length to turn streak widths into drop
sizes and depths (Eq. (26) [GargNayar2007]: w = 2 f a / z) and to place the
plane of focus (Sec. 8: z0 <= 2 f a_min).

Views come from a folder of images, a video file, or a live camera
(``camera:0``), taken in the camera mode (resolution, zoom, focus) the gauge
will run in: the profile's image size is the views' size.  Too few views, or views that do not constrain the focal
length (all facing the camera square-on), raise
:class:`GeometryQualityError` with a message saying how many more views to
take and how to hold the board.
"""

from __future__ import annotations

import dataclasses
import math
import re
import time
from pathlib import Path
from typing import Iterable

import numpy as np

from calibration.frames import camera_device, is_camera
from raingauge.errors import InputError, SourceError

__all__ = [
    "GeometryResult",
    "GeometryQualityError",
    "parse_pattern",
    "read_views",
    "find_corners",
    "calibrate_views",
    "calibrate_geometry",
    "capture_views",
    "MIN_VIEWS",
    "RECOMMENDED_VIEWS",
]

#: Fewest views with the pattern found that the calibration accepts.
MIN_VIEWS = 5
#: Views a good calibration should have.
RECOMMENDED_VIEWS = 10
#: Tilt of the board against the image plane [deg] above which a view constrains f.
MIN_TILT_DEG = 10.0

_DISTORTION_MODELS = {
    # name -> extra calibrateCamera flags
    "k1k2p1p2": "fix_k3",
    "k1k2k3p1p2": "",
    "rational": "rational",
    "none": "zero",
}


class GeometryQualityError(InputError):
    """Too few checkerboard views, or views that do not constrain the camera."""


@dataclasses.dataclass
class GeometryResult:
    """Outcome of a geometric calibration.

    Attributes
    ----------
    focal_length_px : float
        Mean of fx and fy [px].
    fx_px, fy_px : float
        Focal lengths along x and y [px].
    principal_point_px : (cx, cy) [px]
    distortion : tuple of float
        OpenCV distortion coefficients (k1, k2, p1, p2, k3[, ...]).
    rms_px : float
        RMS reprojection error over all corners [px].
    per_view_rms_px : list of float
        RMS reprojection error per used view [px].
    focal_length_std_px : float
        One-sigma uncertainty of f from ``calibrateCameraExtended`` [px].
    image_size : (width, height) [px]
    views_used : list of str
        Names of the views whose pattern was found.
    views_rejected : list of str
        Names of the views without the pattern.
    tilts_deg : list of float
        Tilt of the board against the image plane in each used view [deg].
    coverage : float
        Fraction of the image area inside the convex hull of all corners [-].
    advice : list of str
        Suggestions to improve the calibration (empty when it is good).
    """

    focal_length_px: float
    fx_px: float
    fy_px: float
    principal_point_px: tuple[float, float]
    distortion: tuple[float, ...]
    rms_px: float
    per_view_rms_px: list[float]
    focal_length_std_px: float
    image_size: tuple[int, int]
    views_used: list[str]
    views_rejected: list[str]
    tilts_deg: list[float]
    coverage: float
    advice: list[str]

    def summary(self) -> str:
        """A few lines for the technician."""
        cx, cy = self.principal_point_px
        lines = [
            f"focal length      {self.focal_length_px:.2f} px (+/- {self.focal_length_std_px:.2f}; fx {self.fx_px:.2f}, fy {self.fy_px:.2f})",
            f"principal point   ({cx:.1f}, {cy:.1f}) px for a {self.image_size[0]}x{self.image_size[1]} image",
            "distortion        " + ", ".join(f"{v:.4g}" for v in self.distortion),
            f"RMS reprojection  {self.rms_px:.3f} px over {len(self.views_used)} views "
            f"({len(self.views_rejected)} without the pattern)",
            f"board tilts       {', '.join(f'{t:.0f}' for t in self.tilts_deg)} deg; image coverage {self.coverage:.0%}",
        ]
        lines += [f"advice: {a}" for a in self.advice]
        return "\n".join(lines)

    def to_provenance(self) -> dict:
        return {
            "calibrated": True,
            "focal_length_px": round(self.focal_length_px, 4),
            "focal_length_std_px": round(self.focal_length_std_px, 4),
            "rms_reprojection_px": round(self.rms_px, 5),
            "n_views": len(self.views_used),
            "n_views_without_pattern": len(self.views_rejected),
            "coverage": round(self.coverage, 3),
            "advice": list(self.advice),
        }


def parse_pattern(text: str) -> tuple[int, int]:
    """Parse ``COLSxROWS`` (inner corners, e.g. ``9x6``) into (cols, rows)."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX*,]\s*(\d+)\s*", str(text))
    if not m:
        raise InputError(
            f"checkerboard pattern {text!r} is not COLSxROWS. Fix: count the inner corners "
            "(where four squares meet) along a row and a column, e.g. --pattern 9x6"
        )
    cols, rows = int(m.group(1)), int(m.group(2))
    if cols < 3 or rows < 3:
        raise InputError(f"checkerboard pattern {text!r}: needs at least 3x3 inner corners. Fix: e.g. --pattern 9x6")
    if cols == rows:
        raise InputError(
            f"checkerboard pattern {text!r} is square: its orientation is ambiguous. "
            "Fix: use a board with different numbers of inner corners per row and column, e.g. 9x6"
        )
    return cols, rows


# ------------------------------------------------------------------------ input
def read_views(source: str | Path, *, every: int | None = None, limit: int = 60) -> list[tuple[str, np.ndarray]]:
    """Read checkerboard views as (name, gray uint8) pairs.

    Parameters
    ----------
    source : str or Path
        A folder of images (all are used, in name order) or a video file
        (one frame in ``every``, default so that about 30 frames are taken).
    limit : int
        Most frames taken from a video.

    Raises
    ------
    InputError
        The folder does not exist, holds no images, an image cannot be read,
        or the images differ in size.
    """
    import cv2

    from raingauge.videoio import IMAGE_SUFFIXES, FrameReader

    path = Path(source)
    if not path.exists():
        raise InputError(f"checkerboard views {path}: no such folder or file. Fix: give the folder of checkerboard images")
    views: list[tuple[str, np.ndarray]] = []
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file() and not p.name.startswith("."))
        images = [p for p in files if p.suffix.lower() in IMAGE_SUFFIXES]
        if not images:
            raise InputError(
                f"checkerboard views {path}: the folder holds no images ({', '.join(IMAGE_SUFFIXES)}). "
                "Fix: point --checkerboard at the folder of checkerboard photographs"
            )
        for p in images:
            img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
            if img is None or img.size == 0:
                raise InputError(
                    f"checkerboard view {p}: cannot be read as an image. Fix: delete or re-export it (PNG or JPEG)"
                )
            views.append((p.name, img))
    else:
        reader = FrameReader(path, mode="gray")
        n = reader.n_frames or limit
        step = every or max(1, n // 30)
        for i, frame in enumerate(reader):
            if i % step == 0:
                views.append((f"{path.name}#{i}", frame))
            if len(views) >= limit:
                break
        if not views:
            raise InputError(f"checkerboard video {path}: no frame could be read. Fix: check the file")
    sizes = {img.shape for _, img in views}
    if len(sizes) > 1:
        desc = ", ".join(f"{s[1]}x{s[0]}" for s in sorted(sizes))
        raise InputError(
            f"checkerboard views {path}: images of different sizes ({desc}). "
            "Fix: take all views with the same camera mode and resolution"
        )
    return views


def capture_views(
    device: str | int,
    pattern: tuple[int, int],
    *,
    n_views: int = RECOMMENDED_VIEWS,
    min_move: float = 0.08,
    timeout_s: float = 120.0,
    on_view=None,
) -> list[tuple[str, np.ndarray]]:
    """Collect checkerboard views live from a camera.

    A frame is kept when the pattern is found and the board has moved by at
    least ``min_move`` of the image diagonal since the last kept view (so the
    views differ).  Stops after ``n_views`` views or ``timeout_s``.

    Parameters
    ----------
    device : str or int
        ``"camera:0"``, an integer device index, or anything ``cv2.VideoCapture`` opens.
    on_view : callable(count, n_views), optional
        Called after each kept view (progress display).
    """
    import cv2

    if isinstance(device, str) and is_camera(device):
        device = camera_device(device)
    cap = cv2.VideoCapture(device)
    if not cap.isOpened():
        raise SourceError(f"camera {device!r} cannot be opened. Fix: check the cable/driver, or give a folder of images")
    views: list[tuple[str, np.ndarray]] = []
    last = None
    t0 = time.monotonic()
    try:
        while len(views) < n_views and time.monotonic() - t0 < timeout_s:
            ok, frame = cap.read()
            if not ok:
                break
            gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
            corners = find_corners(gray, pattern, refine=False)
            if corners is None:
                continue
            centre = corners.reshape(-1, 2).mean(axis=0)
            diag = math.hypot(*gray.shape)
            if last is not None and np.linalg.norm(centre - last) < min_move * diag:
                continue
            last = centre
            views.append((f"live_{len(views):02d}", gray.copy()))
            if on_view is not None:
                on_view(len(views), n_views)
    finally:
        cap.release()
    if not views:
        raise SourceError(
            f"camera {device!r}: the {pattern[0]}x{pattern[1]} pattern was never seen in {timeout_s:.0f} s. "
            "Fix: hold the whole board in view, well lit, and check --pattern"
        )
    return views


# ---------------------------------------------------------------- calibration
def find_corners(gray: np.ndarray, pattern: tuple[int, int], *, refine: bool = True) -> np.ndarray | None:
    """Inner corners of a checkerboard, sub-pixel refined, or None when not found.

    Parameters
    ----------
    gray : (M, N) uint8
    pattern : (cols, rows) inner corners

    Returns
    -------
    (cols*rows, 1, 2) float32 corner positions [px] in OpenCV's order, or None.
    """
    import cv2

    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, corners = cv2.findChessboardCorners(gray, tuple(pattern), flags=flags)
    if not ok:
        return None
    if refine:
        # Search window: a third of the smallest square side, between 3 and 11 px.
        pts = corners.reshape(pattern[1], pattern[0], 2)
        side = min(np.linalg.norm(np.diff(pts, axis=0), axis=2).min(), np.linalg.norm(np.diff(pts, axis=1), axis=2).min())
        win = int(np.clip(side / 3, 3, 11))
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 60, 1e-4)
        corners = cv2.cornerSubPix(gray, corners, (win, win), (-1, -1), criteria)
    return corners


def _board_points(pattern: tuple[int, int], square_m: float) -> np.ndarray:
    cols, rows = pattern
    obj = np.zeros((rows * cols, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    return obj


def _coverage(corner_sets: Iterable[np.ndarray], image_size: tuple[int, int]) -> float:
    import cv2

    pts = np.concatenate([c.reshape(-1, 2) for c in corner_sets]).astype(np.float32)
    hull = cv2.convexHull(pts)
    return float(cv2.contourArea(hull) / (image_size[0] * image_size[1]))


def calibrate_views(
    views: list[tuple[str, np.ndarray]],
    pattern: tuple[int, int],
    square_m: float,
    *,
    distortion_model: str = "k1k2p1p2",
    min_views: int = MIN_VIEWS,
    max_rms_px: float = 1.0,
    max_focal_std: float = 0.01,
) -> GeometryResult:
    """Calibrate a camera from checkerboard views.

    Parameters
    ----------
    views : list of (name, (M, N) uint8)
    pattern : (cols, rows)
        Inner corners per row and per column.
    square_m : float
        Side of one square [m] (sets the scale of the board poses only; the
        focal length in pixels does not depend on it).
    distortion_model : str
        ``"k1k2p1p2"`` (k3 fixed at 0, the default for few views),
        ``"k1k2k3p1p2"``, ``"rational"`` or ``"none"``.
    min_views : int
        Fewest views with the pattern found.
    max_rms_px : float
        Largest acceptable RMS reprojection error [px].
    max_focal_std : float
        Largest acceptable relative one-sigma uncertainty of f [-].

    Raises
    ------
    GeometryQualityError
        Pattern found in too few views, views without tilt, RMS error or
        focal-length uncertainty too large; the message says how many more
        views to take and what kind.
    """
    import cv2

    if distortion_model not in _DISTORTION_MODELS:
        raise ValueError(f"unknown distortion model {distortion_model!r}; valid: {', '.join(_DISTORTION_MODELS)}")
    if not (isinstance(square_m, (int, float)) and math.isfinite(square_m) and square_m > 0):
        raise InputError(f"square size {square_m!r} m is not a positive length. Fix: measure one square, e.g. --square-m 0.025")
    if not views:
        raise GeometryQualityError("no checkerboard views. Fix: take at least "
                                   f"{RECOMMENDED_VIEWS} photographs of the board at different tilts")
    cols, rows = pattern
    height, width = views[0][1].shape[:2]
    image_size = (width, height)
    obj = _board_points(pattern, square_m)
    names, found, rejected = [], [], []
    for name, img in views:
        corners = find_corners(img, pattern)
        if corners is None:
            rejected.append(name)
        else:
            names.append(name)
            found.append(corners)
    how = (f"hold the whole {cols + 1}x{rows + 1}-square board in view, sharp and evenly lit, "
           "tilted 20-40 degrees in different directions and placed over different parts of the image")
    if not found:
        raise GeometryQualityError(
            f"the {cols}x{rows} checkerboard pattern was not found in any of the {len(views)} views. "
            f"Fix: check --pattern (inner corners, e.g. a board of 10x7 squares is 9x6) and {how}"
        )
    if len(found) < min_views:
        more = RECOMMENDED_VIEWS - len(found)
        raise GeometryQualityError(
            f"the pattern was found in only {len(found)} of {len(views)} views; the calibration needs at least "
            f"{min_views}. Fix: take {more} more views ({RECOMMENDED_VIEWS} in all): {how}"
        )

    flags = 0
    kind = _DISTORTION_MODELS[distortion_model]
    if kind == "fix_k3":
        flags |= cv2.CALIB_FIX_K3
    elif kind == "rational":
        flags |= cv2.CALIB_RATIONAL_MODEL
    elif kind == "zero":
        flags |= cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    (rms, k, dist, rvecs, tvecs, std_intr, _std_extr, per_view) = cv2.calibrateCameraExtended(
        [obj] * len(found), found, image_size, None, None, flags=flags, criteria=criteria
    )
    fx, fy = float(k[0, 0]), float(k[1, 1])
    f = 0.5 * (fx + fy)
    std = np.asarray(std_intr).ravel()
    f_std = float(0.5 * math.hypot(std[0], std[1])) if std.size >= 2 else float("nan")
    tilts = []
    for rv in rvecs:
        rot = cv2.Rodrigues(rv)[0]
        tilts.append(math.degrees(math.acos(min(1.0, abs(rot[2, 2])))))
    coverage = _coverage(found, image_size)
    per_view = [float(v) for v in np.asarray(per_view).ravel()]

    n_tilted = sum(t >= MIN_TILT_DEG for t in tilts)
    if n_tilted < 3:
        raise GeometryQualityError(
            f"only {n_tilted} of {len(found)} views show the board tilted by {MIN_TILT_DEG:.0f} degrees or more; "
            "square-on views do not determine the focal length. "
            f"Fix: take {3 - n_tilted + 2} more views with the board tilted 20-40 degrees, "
            "some about the vertical axis and some about the horizontal axis"
        )
    if not math.isfinite(rms) or rms > max_rms_px:
        worst = sorted(zip(per_view, names), reverse=True)[: max(1, len(names) // 4)]
        raise GeometryQualityError(
            f"RMS reprojection error {rms:.2f} px is above {max_rms_px:g} px. "
            f"Worst views: {', '.join(f'{n} ({e:.2f} px)' for e, n in worst)}. "
            "Fix: retake those views sharp and without motion blur (tripod, shorter exposure), "
            "keep the board flat, and check --pattern and the lens setting did not change between views"
        )
    rel = f_std / f if math.isfinite(f_std) else float("inf")
    if rel > max_focal_std:
        need = int(math.ceil(len(found) * (rel / max_focal_std) ** 2)) - len(found)
        raise GeometryQualityError(
            f"the focal length is uncertain by {rel:.1%} (limit {max_focal_std:.1%}) with {len(found)} views. "
            f"Fix: take about {max(need, 2)} more views with the board tilted 20-40 degrees and filling "
            "different parts of the image"
        )

    advice = []
    if len(found) < RECOMMENDED_VIEWS:
        advice.append(f"{RECOMMENDED_VIEWS - len(found)} more views would make the calibration more robust")
    if coverage < 0.35:
        advice.append(f"the corners cover {coverage:.0%} of the image; add views with the board near the image "
                      "corners and edges so that the distortion is measured everywhere")
    if rejected:
        advice.append(f"pattern not found in {len(rejected)} views ({', '.join(rejected[:5])}"
                      f"{'...' if len(rejected) > 5 else ''})")
    if rms > 0.5 * max_rms_px:
        advice.append(f"RMS error {rms:.2f} px is high; retake blurred views")

    return GeometryResult(
        focal_length_px=f,
        fx_px=fx,
        fy_px=fy,
        principal_point_px=(float(k[0, 2]), float(k[1, 2])),
        distortion=tuple(float(v) for v in np.asarray(dist).ravel()),
        rms_px=float(rms),
        per_view_rms_px=per_view,
        focal_length_std_px=f_std,
        image_size=image_size,
        views_used=names,
        views_rejected=rejected,
        tilts_deg=tilts,
        coverage=coverage,
        advice=advice,
    )


def calibrate_geometry(
    source: str | Path,
    pattern: tuple[int, int] | str,
    square_m: float,
    *,
    n_live_views: int = RECOMMENDED_VIEWS,
    on_view=None,
    **kwargs,
) -> GeometryResult:
    """Read views from a folder, video file or ``camera:N`` and calibrate (see :func:`calibrate_views`).

    ``on_view(count, n_live_views)`` reports progress of a live capture.
    """
    if isinstance(pattern, str):
        pattern = parse_pattern(pattern)
    if is_camera(source):
        views = capture_views(str(source), pattern, n_views=n_live_views, on_view=on_view)
    else:
        views = read_views(source)
    return calibrate_views(views, pattern, square_m, **kwargs)

