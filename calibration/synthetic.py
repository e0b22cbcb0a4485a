"""Synthetic calibration captures with a known truth.

Used by the tests and by ``raingauge calibrate --demo``.  Every renderer
returns the images *and* the truth it rendered them from, so that a test
compares what the calibration recovers with what was actually generated:

- :func:`render_checkerboard_views` -- a planar checkerboard seen through a
  pinhole camera with OpenCV's radial/tangential distortion.  Each output
  pixel is traced back through the inverse distortion
  (``cv2.undistortPointsIter``) and the board's homography onto the board
  plane; the board is sampled there, 3x super-sampled and box-filtered, so
  edges are anti-aliased like a real sensor.  The true corner positions come
  from ``cv2.projectPoints`` with the same camera.
- :func:`render_exposure_bracket` -- one still scene taken at several
  exposure times through a known non-linear camera response
  (:data:`RESPONSE_MODELS`).
- :func:`render_still_frames` -- frames of a still scene with sensor noise of
  known standard deviation, constant or signal dependent
  (sigma^2 = read^2 + gain * I).
- :func:`render_dry_clip` -- rain-free frames, optionally with a scene that
  drifts (for the dry-run motion warning).
- :func:`write_demo_captures` -- all of the above written as image folders in
  the layout ``raingauge calibrate`` reads.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = [
    "RESPONSE_MODELS",
    "camera_response",
    "inverse_response_table",
    "render_checkerboard_views",
    "render_exposure_bracket",
    "render_still_frames",
    "render_dry_clip",
    "write_demo_captures",
]


# --------------------------------------------------------------------- responses
def _gamma_response(x: np.ndarray) -> np.ndarray:
    """sRGB-like power law, code = 255 x^(1/2.2)."""
    return 255.0 * np.power(np.clip(x, 0.0, 1.0), 1.0 / 2.2)


def _film_response(x: np.ndarray) -> np.ndarray:
    """A smooth S-shaped (toe and shoulder) response, code = 255 * x^0.6 / (x^0.6 + 0.35) * 1.35."""
    x = np.clip(x, 0.0, 1.0)
    y = np.power(x, 0.6)
    return 255.0 * y / (y + 0.35) * 1.35


def _linear_response(x: np.ndarray) -> np.ndarray:
    return 255.0 * np.clip(x, 0.0, 1.0)


#: Known camera responses: irradiance x exposure (1.0 = saturation) -> code value (float, 0..255).
RESPONSE_MODELS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "gamma2.2": _gamma_response,
    "film": _film_response,
    "linear": _linear_response,
}


def camera_response(exposure: np.ndarray, *, model: str = "gamma2.2") -> np.ndarray:
    """Apply a known camera response to a relative exposure.

    Parameters
    ----------
    exposure : array
        Irradiance times exposure time, relative to the saturation exposure
        (1.0 saturates) [-].
    model : str
        One of :data:`RESPONSE_MODELS`.

    Returns
    -------
    array of float code values [gray levels], before quantisation.
    """
    if model not in RESPONSE_MODELS:
        raise ValueError(f"unknown response model {model!r}; valid: {', '.join(RESPONSE_MODELS)}")
    return RESPONSE_MODELS[model](np.asarray(exposure, dtype=np.float64))


def inverse_response_table(model: str = "gamma2.2") -> np.ndarray:
    """The exact linearisation table of a known response: 255 x the exposure giving each code.

    Parameters
    ----------
    model : str
        One of :data:`RESPONSE_MODELS`.

    Returns
    -------
    (256,) float64 [gray levels], 255 at the saturation exposure.
    """
    x = np.linspace(0.0, 1.0, 400001)
    return 255.0 * np.interp(np.arange(256.0), camera_response(x, model=model), x)


def _quantise(codes: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(codes), 0, 255).astype(np.uint8)


# -------------------------------------------------------------------- checkerboard
def _rodrigues(rvec: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))[0]


def _board_pose(rng: np.random.Generator, *, board_w_m: float, board_h_m: float,
                centre_m: np.ndarray, fov_x: float, fov_y: float, max_tilt_deg: float):
    """A random pose: board tilted by up to max_tilt about x and y, rolled a little,
    at a distance where it fills about half the field of view."""
    tilt_x = math.radians(rng.uniform(-max_tilt_deg, max_tilt_deg))
    tilt_y = math.radians(rng.uniform(-max_tilt_deg, max_tilt_deg))
    roll = math.radians(rng.uniform(-15, 15))
    rx = _rodrigues(np.array([tilt_x, 0.0, 0.0]))
    ry = _rodrigues(np.array([0.0, tilt_y, 0.0]))
    rz = _rodrigues(np.array([0.0, 0.0, roll]))
    rot = ry @ rx @ rz
    fill = rng.uniform(0.45, 0.65)
    dist = max(board_w_m / (fill * 2 * math.tan(fov_x / 2)), board_h_m / (fill * 2 * math.tan(fov_y / 2)))
    # Offset the board centre within the field of view so corners cover the image.
    off_x = rng.uniform(-0.22, 0.22) * 2 * math.tan(fov_x / 2) * dist
    off_y = rng.uniform(-0.22, 0.22) * 2 * math.tan(fov_y / 2) * dist
    target = np.array([off_x, off_y, dist])
    tvec = target - rot @ centre_m
    rvec = _rvec(rot)
    return rvec, tvec


def _rvec(rot: np.ndarray) -> np.ndarray:
    """Rotation matrix -> Rodrigues vector (3,)."""
    import cv2

    return cv2.Rodrigues(np.asarray(rot, dtype=np.float64))[0].ravel()


def _pixel_rays(width: int, height: int, s: int, k: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Undistorted normalised rays (x, y, 1) through every super-sampled pixel centre, (H*s*W*s, 3)."""
    import cv2

    us = (np.arange(width * s) + 0.5) / s - 0.5
    vs = (np.arange(height * s) + 0.5) / s - 0.5
    uu, vv = np.meshgrid(us, vs)
    pts = np.stack([uu.ravel(), vv.ravel()], axis=1).reshape(-1, 1, 2)
    norm = cv2.undistortPointsIter(
        pts, k, dist, None, None, (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 60, 1e-12)
    ).reshape(-1, 2)
    return np.column_stack([norm, np.ones(len(norm))])


def render_checkerboard_views(
    *,
    pattern: tuple[int, int] = (9, 6),
    square_m: float = 0.025,
    n_views: int = 8,
    image_size: tuple[int, int] = (640, 480),
    focal_length_px: float = 700.0,
    principal_point_px: tuple[float, float] | None = None,
    distortion: tuple[float, ...] = (-0.12, 0.05, 0.0005, -0.0004, 0.0),
    max_tilt_deg: float = 35.0,
    supersample: int = 3,
    noise_sigma_dn: float = 1.0,
    seed: int = 0,
) -> tuple[list[np.ndarray], dict]:
    """Render gray views of a checkerboard through a known distorting camera.

    Parameters
    ----------
    pattern : (cols, rows)
        Inner corners per row and per column, as OpenCV counts them.
    square_m : float
        Side of one square [m].
    n_views : int
        Number of views, each at a random tilted pose.
    image_size : (width, height)
        Image size [px].
    focal_length_px : float
        Focal length [px] (square pixels).
    principal_point_px : (cx, cy), optional
        Principal point [px]; default slightly off the image centre.
    distortion : tuple
        OpenCV distortion coefficients (k1, k2, p1, p2, k3) [-].
    max_tilt_deg : float
        Largest tilt of the board about the x and y axes [deg].
    supersample : int
        Super-sampling factor per axis for anti-aliasing.
    noise_sigma_dn : float
        Gaussian sensor noise [gray levels].
    seed : int
        Random seed.

    Returns
    -------
    images : list of (M, N) uint8 arrays
    truth : dict
        ``camera_matrix`` (3x3), ``distortion``, ``focal_length_px``,
        ``principal_point_px``, ``rvecs``, ``tvecs``, ``corners_px`` (per view,
        (cols*rows, 2) from ``cv2.projectPoints``), ``pattern``, ``square_m``,
        ``image_size``.
    """
    import cv2

    cols, rows = int(pattern[0]), int(pattern[1])
    width, height = int(image_size[0]), int(image_size[1])
    if principal_point_px is None:
        principal_point_px = (width / 2.0 + 6.5, height / 2.0 - 4.0)
    cx, cy = principal_point_px
    k = np.array([[focal_length_px, 0, cx], [0, focal_length_px, cy], [0, 0, 1]], dtype=np.float64)
    dist = np.array(distortion, dtype=np.float64)
    rng = np.random.default_rng(seed)

    # Normalised, undistorted ray direction of every (super-sampled) pixel centre:
    # the same for all views, so computed once.
    s = int(supersample)
    ray = _pixel_rays(width, height, s, k, dist)
    rx, ry = ray[:, 0].copy(), ray[:, 1].copy()
    del ray

    obj = np.zeros((rows * cols, 3), np.float64)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    # The board: (cols+1) x (rows+1) squares around the inner corners plus a white margin.
    board_w = (cols + 1) * square_m
    board_h = (rows + 1) * square_m
    centre = np.array([(cols - 1) * square_m / 2, (rows - 1) * square_m / 2, 0.0])
    fov_x = 2 * math.atan(width / 2 / focal_length_px)
    fov_y = 2 * math.atan(height / 2 / focal_length_px)

    images, rvecs, tvecs, corners = [], [], [], []
    attempts = 0
    while len(images) < n_views:
        attempts += 1
        if attempts > 50 * n_views:
            raise RuntimeError("could not place the board inside the image; use a smaller pattern or wider lens")
        rvec, tvec = _board_pose(rng, board_w_m=board_w + 2 * square_m, board_h_m=board_h + 2 * square_m,
                                 centre_m=centre, fov_x=fov_x, fov_y=fov_y, max_tilt_deg=max_tilt_deg)
        # The whole board with its margin must be in the image.
        outline = np.array([[-1.5, -1.5], [cols + 0.5, -1.5], [cols + 0.5, rows + 0.5], [-1.5, rows + 0.5]]) * square_m
        outline3 = np.column_stack([outline, np.zeros(4)])
        proj_outline, _ = cv2.projectPoints(outline3, rvec, tvec, k, dist)
        po = proj_outline.reshape(-1, 2)
        if po[:, 0].min() < 4 or po[:, 1].min() < 4 or po[:, 0].max() > width - 5 or po[:, 1].max() > height - 5:
            continue
        rot = _rodrigues(rvec)
        # The board plane z_b = 0 maps to normalised image coordinates by the homography
        # H = [r1 r2 t]; its inverse takes every pixel's ray back to board coordinates.
        hinv = np.linalg.inv(np.column_stack([rot[:, 0], rot[:, 1], tvec]))
        w = hinv[2, 0] * rx + hinv[2, 1] * ry + hinv[2, 2]
        bx = (hinv[0, 0] * rx + hinv[0, 1] * ry + hinv[0, 2]) / (w * square_m)
        by = (hinv[1, 0] * rx + hinv[1, 1] * ry + hinv[1, 2]) / (w * square_m)
        # Rays that meet the plane behind the camera (ray . n and n . t of opposite sign).
        n = rot[:, 2]
        behind = (n[0] * rx + n[1] * ry + n[2]) * (n @ tvec) <= 0
        # Squares are indexed so that square (i, j) spans [i-1, i] x [j-1, j] around inner corners.
        parity = (np.floor(bx) + np.floor(by)).astype(np.int64) % 2
        inside = (bx >= -1) & (bx < cols) & (by >= -1) & (by < rows)
        margin = (bx >= -2) & (bx < cols + 1) & (by >= -2) & (by < rows + 1)
        value = np.full(bx.shape, 110.0, dtype=np.float32)  # background
        value[margin] = 225.0  # white margin
        value[inside & (parity == 0)] = 25.0  # black squares (corner square is black)
        value[inside & (parity == 1)] = 225.0
        value[behind] = 110.0
        big = value.reshape(height * s, width * s).astype(np.float32)
        img = cv2.resize(big, (width, height), interpolation=cv2.INTER_AREA).astype(np.float64)
        if noise_sigma_dn > 0:
            img = img + rng.normal(0.0, noise_sigma_dn, img.shape)
        images.append(_quantise(img))
        proj, _ = cv2.projectPoints(obj, rvec, tvec, k, dist)
        corners.append(proj.reshape(-1, 2))
        rvecs.append(np.asarray(rvec).ravel())
        tvecs.append(np.asarray(tvec).ravel())

    truth = {
        "camera_matrix": k,
        "distortion": dist,
        "focal_length_px": float(focal_length_px),
        "principal_point_px": (float(cx), float(cy)),
        "rvecs": rvecs,
        "tvecs": tvecs,
        "corners_px": corners,
        "pattern": (cols, rows),
        "square_m": float(square_m),
        "image_size": (width, height),
    }
    return images, truth


# ---------------------------------------------------------------- exposure bracket
def _scene_radiance(shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """A still scene whose relative radiance spans about 3 decades (log-uniform
    ramps plus smooth texture), values in (0, 1]."""
    m, n = shape
    x = np.linspace(0.0, 1.0, n)
    y = np.linspace(0.0, 1.0, m)
    xx, yy = np.meshgrid(x, y)
    log_r = -3.0 + 3.0 * (0.75 * xx + 0.25 * yy)
    log_r += 0.08 * np.sin(9.0 * xx + 3.0 * rng.uniform()) * np.cos(7.0 * yy)
    return np.power(10.0, np.clip(log_r, -3.2, 0.0))


def render_exposure_bracket(
    *,
    exposures_s: tuple[float, ...] = (1 / 1000, 1 / 500, 1 / 250, 1 / 125, 1 / 60, 1 / 30),
    shape: tuple[int, int] = (60, 80),
    response: str = "gamma2.2",
    saturation_exposure: float = 1 / 60,
    noise_sigma_dn: float = 0.3,
    seed: int = 0,
) -> tuple[list[np.ndarray], dict]:
    """An exposure bracket of one still scene through a known camera response.

    Parameters
    ----------
    exposures_s : tuple of float
        Exposure times [s].
    shape : (M, N)
        Image shape [px].
    response : str
        Camera response model, one of :data:`RESPONSE_MODELS`.
    saturation_exposure : float
        Exposure time at which the brightest scene point saturates [s].
    noise_sigma_dn : float
        Gaussian noise added before quantisation [gray levels].
    seed : int

    Returns
    -------
    images : list of (M, N) uint8
    truth : dict
        ``radiance`` ((M, N), relative; exposure = radiance * t / saturation_exposure),
        ``exposures_s``, ``response`` (model name), ``saturation_exposure``.
    """
    rng = np.random.default_rng(seed)
    radiance = _scene_radiance(shape, rng)
    images = []
    for t in exposures_s:
        codes = camera_response(radiance * t / saturation_exposure, model=response)
        if noise_sigma_dn > 0:
            codes = codes + rng.normal(0.0, noise_sigma_dn, codes.shape)
        images.append(_quantise(codes))
    truth = {
        "radiance": radiance,
        "exposures_s": tuple(float(t) for t in exposures_s),
        "response": response,
        "saturation_exposure": float(saturation_exposure),
    }
    return images, truth


# ------------------------------------------------------------------ still frames
def render_still_frames(
    *,
    n_frames: int = 12,
    shape: tuple[int, int] = (64, 96),
    read_sigma_dn: float = 2.0,
    shot_gain_dn: float = 0.0,
    levels: tuple[float, float] = (20.0, 235.0),
    response: str = "linear",
    seed: int = 0,
) -> tuple[np.ndarray, dict]:
    """Frames of a still scene with sensor noise of known standard deviation.

    The scene is a horizontal ramp of linear intensity from ``levels[0]`` to
    ``levels[1]`` [gray levels, 255 = saturation].  Noise variance at
    intensity I is ``read_sigma_dn**2 + shot_gain_dn * I`` [gray levels^2],
    added in the linear domain; the camera ``response`` (one of
    :data:`RESPONSE_MODELS`) then maps linear intensity to codes.

    Returns
    -------
    frames : (T, M, N) uint8
    truth : dict with ``clean`` ((M, N) float), ``read_sigma_dn``, ``shot_gain_dn``
        and ``sigma_dn`` (the RMS noise over the scene, before quantisation).
    """
    rng = np.random.default_rng(seed)
    m, n = shape
    clean = np.tile(np.linspace(levels[0], levels[1], n), (m, 1))
    sigma_map = np.sqrt(read_sigma_dn ** 2 + shot_gain_dn * clean)
    frames = np.empty((n_frames, m, n), np.uint8)
    for i in range(n_frames):
        linear = clean + rng.normal(0.0, 1.0, shape) * sigma_map
        frames[i] = _quantise(camera_response(linear / 255.0, model=response))
    truth = {
        "clean": clean,
        "read_sigma_dn": float(read_sigma_dn),
        "shot_gain_dn": float(shot_gain_dn),
        "sigma_dn": float(np.sqrt(np.mean(sigma_map ** 2))),
    }
    return frames, truth


def render_dry_clip(
    *,
    n_frames: int = 60,
    shape: tuple[int, int] = (72, 96),
    sigma_dn: float = 1.5,
    drift_px_per_frame: float = 0.0,
    response: str = "linear",
    seed: int = 0,
) -> tuple[np.ndarray, dict]:
    """Rain-free frames of a textured scene, optionally drifting sideways.

    Parameters
    ----------
    n_frames : int
    shape : (M, N)
    sigma_dn : float
        Sensor noise, added to the linear intensity [gray levels].
    drift_px_per_frame : float
        Scene motion [px/frame] (0 for a still scene).
    response : str
        Camera response (one of :data:`RESPONSE_MODELS`).

    Returns
    -------
    frames : (T, M, N) uint8
    truth : dict with ``sigma_dn`` and ``drift_px_per_frame``.
    """
    import cv2

    rng = np.random.default_rng(seed)
    m, n = shape
    pad = int(abs(drift_px_per_frame) * n_frames) + 8
    texture = rng.uniform(40, 200, (m // 4 + 2, (n + pad) // 4 + 2)).astype(np.float32)
    texture = cv2.resize(texture, ((n + pad), m), interpolation=cv2.INTER_CUBIC)
    texture = cv2.GaussianBlur(texture, (0, 0), 1.5)
    frames = np.empty((n_frames, m, n), np.uint8)
    for i in range(n_frames):
        shift = drift_px_per_frame * i
        mat = np.float32([[1, 0, shift], [0, 1, 0]])
        moved = cv2.warpAffine(texture, mat, (n + pad, m), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        linear = moved[:, :n] + rng.normal(0.0, sigma_dn, (m, n))
        frames[i] = _quantise(camera_response(linear / 255.0, model=response))
    return frames, {"sigma_dn": float(sigma_dn), "drift_px_per_frame": float(drift_px_per_frame)}


# ------------------------------------------------------------------------ demo
def _write_images(folder: Path, images, names) -> None:
    import cv2

    folder.mkdir(parents=True, exist_ok=True)
    for img, name in zip(images, names):
        if not cv2.imwrite(str(folder / name), img):
            raise OSError(f"cannot write {folder / name}")


def exposure_file_name(exposure_s: float) -> str:
    """The bracket file name convention: ``exp_<seconds>s.png`` (e.g. ``exp_0.004s.png``)."""
    return f"exp_{exposure_s:.6g}s.png"


def write_demo_captures(folder: str | Path, *, seed: int = 0, image_size: tuple[int, int] = (400, 300),
                        n_views: int = 8, supersample: int = 3) -> dict:
    """Write a full set of synthetic captures for ``raingauge calibrate``.

    Layout::

        FOLDER/checkerboard/view_00.png ...   (pattern 9x6, square 0.025 m)
        FOLDER/bracket/exp_0.001s.png ...     (exposure in the file name)
        FOLDER/still/frame_000.png ...
        FOLDER/dry/frame_000.png ...
        FOLDER/truth.json

    The camera has f = 1.17 x the image width [px] and a gamma-2.2 response;
    the still frames carry 2 gray levels of noise (linear units).
    Returns the truth dict (also written to ``truth.json``).
    """
    folder = Path(folder)
    size = (int(image_size[0]), int(image_size[1]))
    f_px = round(1.17 * size[0], 1)
    views, gtruth = render_checkerboard_views(pattern=(9, 6), square_m=0.025, n_views=n_views, image_size=size,
                                              focal_length_px=f_px, supersample=supersample, seed=seed)
    _write_images(folder / "checkerboard", views, [f"view_{i:02d}.png" for i in range(len(views))])
    times = (1 / 1000, 1 / 500, 1 / 250, 1 / 125, 1 / 60, 1 / 30)
    bracket, btruth = render_exposure_bracket(exposures_s=times, shape=(size[1], size[0]), seed=seed)
    _write_images(folder / "bracket", bracket, [exposure_file_name(t) for t in times])
    # Still and dry frames come through the same non-linear camera as the bracket.
    still, struth = render_still_frames(n_frames=12, shape=(size[1], size[0]), read_sigma_dn=2.0,
                                        response=btruth["response"], seed=seed)
    _write_images(folder / "still", list(still), [f"frame_{i:03d}.png" for i in range(len(still))])
    dry, dtruth = render_dry_clip(n_frames=45, shape=(size[1], size[0]), sigma_dn=1.5, response=btruth["response"],
                                  seed=seed)
    _write_images(folder / "dry", list(dry), [f"frame_{i:03d}.png" for i in range(len(dry))])
    truth = {
        "geometry": {
            "focal_length_px": gtruth["focal_length_px"],
            "principal_point_px": list(gtruth["principal_point_px"]),
            "distortion": [float(v) for v in gtruth["distortion"]],
            "image_size": list(gtruth["image_size"]),
            "pattern": "9x6",
            "square_m": 0.025,
        },
        "bracket": {"response": btruth["response"], "exposures_s": list(btruth["exposures_s"])},
        "still": {"sigma_dn": struth["sigma_dn"]},
        "dry": dtruth,
    }
    (folder / "truth.json").write_text(json.dumps(truth, indent=2))
    return truth
