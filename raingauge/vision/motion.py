"""Global camera-motion compensation before the three-frame test.

Eq. (19) [GargNayar2007] assumes a background that is stationary over frames
n-1, n, n+1 (note 12).  A slowly panning camera or a mast shaking in the wind
breaks that assumption everywhere at once; estimating the global image motion
between frames and warping the neighbours into frame n restores it.  This goes
beyond the paper, which assumes a static background.

Transforms are 3x3 homogeneous matrices ``M`` that map pixel coordinates
(x right, y down) of the *reference* frame to those of the *moving* frame, so
that ``aligned(x) = moving(M x)`` (OpenCV's ``WARP_INVERSE_MAP`` convention).

Motion models form a registry, :data:`MOTION_MODELS`:

``none``         the camera is static.
``translation``  phase correlation [Kuglin1975] on a central crop, refined by Gauss-Newton
                 [Lucas1981]: pans, tilts, jitter.  A shift of a pixel or more is kept only
                 when it aligns the scene clearly better than none: over a featureless
                 scene the peak is one of the noise or of the rain's own fall.
``euclidean``    ECC maximisation [Evangelidis2008] (rotation + translation), seeded by
                 phase correlation and kept only when it aligns better: a mast
                 that shakes and twists.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "MOTION_MODELS",
    "WARP_MIN_SHIFT_PX",
    "estimate_motion",
    "warp_to",
    "MotionTracker",
    "transform_magnitude_px",
    "is_affine",
    "is_translation",
]

MOTION_MODELS = ("none", "translation", "euclidean")

#: Displacements below this are not compensated [px] (see :func:`warp_to`).
WARP_MIN_SHIFT_PX = 0.3


def _check_model(model: str) -> str:
    if model not in MOTION_MODELS:
        raise ValueError(f"unknown motion model {model!r}; valid models: {', '.join(MOTION_MODELS)}")
    return model


def _reduce(frame: np.ndarray, width: int) -> tuple[np.ndarray, float]:
    """Central crop, at full resolution, at most ``width`` x ``3/4 width`` [px].

    Returns the crop and 1.0 (the scale of its pixels); cropping instead of
    down-sampling keeps the sub-pixel accuracy that the three-frame test needs.
    """
    import cv2

    frame = np.asarray(frame)
    if frame.ndim == 3:
        frame = cv2.cvtColor(frame.astype(np.float32, copy=False), cv2.COLOR_BGR2GRAY)
    frame = frame.astype(np.float32, copy=False)
    h, w = frame.shape
    cw = min(w, int(width))
    ch = min(h, int(width * 3 // 4))
    x0 = (w - cw) // 2
    y0 = (h - ch) // 2
    return np.array(frame[y0:y0 + ch, x0:x0 + cw], dtype=np.float32, copy=True), 1.0


def _refine_translation(ref: np.ndarray, mov: np.ndarray, dx: float, dy: float, *, iterations: int = 8,
                        tol_px: float = 2e-3) -> tuple[float, float]:
    """Gauss-Newton refinement of a translation [Lucas1981]: ``mov(x + d) ~ ref(x)`` in least squares.

    Inverse-compositional form [Baker2004]: the gradient and the 2 x 2 normal
    matrix are those of ``ref``, computed once; each iteration warps ``mov``
    by the current shift (bicubic, Keys' a = -0.5, exact on ramps) and solves
    for the step.  For a translation it converges to the least-squares shift
    as the forward-additive form does, without a gradient per iteration.
    Intensities are taken about their means, so a change of exposure does not
    bias the shift.
    """
    import cv2

    h, w = ref.shape
    m = max(4, int(math.ceil(max(abs(dx), abs(dy)))) + 3)
    if h <= 2 * m + 8 or w <= 2 * m + 8:
        return dx, dy
    inner = (slice(m, h - m), slice(m, w - m))
    r = ref[inner]
    r = r - np.float32(r.mean())
    # the gradient on the inner part (and the one pixel around it that its 3 x 3 kernel reads),
    # contiguous for the dot products
    grown = ref[m - 1:h - m + 1, m - 1:w - m + 1]
    gx = np.ascontiguousarray(cv2.Sobel(grown, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)[1:-1, 1:-1])
    gy = np.ascontiguousarray(cv2.Sobel(grown, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)[1:-1, 1:-1])
    H = np.array([[np.vdot(gx, gx), np.vdot(gx, gy)], [np.vdot(gx, gy), np.vdot(gy, gy)]], np.float64)
    if not np.linalg.det(H) > 1e-9 * max(H[0, 0] * H[1, 1], 1e-30):
        return dx, dy
    H_inv = np.linalg.inv(H)
    for _ in range(iterations):
        warped = _translate_cubic(mov, dx, dy, a=-0.5)[inner]
        e = warped - np.float32(warped.mean()) - r
        step = -(H_inv @ np.array([np.vdot(gx, e), np.vdot(gy, e)], np.float64))
        dx, dy = dx + float(step[0]), dy + float(step[1])
        if max(abs(step[0]), abs(step[1])) < tol_px:
            break
    return dx, dy


def _phase_translation(ref_small: np.ndarray, mov_small: np.ndarray, window: np.ndarray,
                       min_response: float, refine: bool = True) -> tuple[float, float, float]:
    """Phase correlation [Kuglin1975], refined by Gauss-Newton [Lucas1981] on the same crop.

    The sub-pixel peak of phase correlation is biased by a few tenths of a
    pixel on smooth scenes; a few Gauss-Newton iterations seeded by it bring
    the error to a few hundredths, which the three-frame test needs.
    """
    import cv2

    # cv2.phaseCorrelate (OpenCV 4.x) multiplies its inputs by the window in
    # place: always hand it copies.
    (dx, dy), response = cv2.phaseCorrelate(ref_small.copy(), mov_small.copy(), window)
    if not (math.isfinite(dx) and math.isfinite(dy)) or response < min_response:
        return 0.0, 0.0, float(response)
    if refine and max(abs(dx), abs(dy)) >= 0.5 * WARP_MIN_SHIFT_PX:
        # (a static camera needs no refinement: its frames are not warped)
        rx, ry = _refine_translation(ref_small, mov_small, dx, dy)
        if math.isfinite(rx) and math.isfinite(ry) and abs(rx - dx) < 2 and abs(ry - dy) < 2:
            dx, dy = rx, ry
    if max(abs(dx), abs(dy)) >= CHECKED_SHIFT_PX and not _aligns_better(ref_small, mov_small, dx, dy):
        # a peak of the rain itself or of noise, not of the scene
        return 0.0, 0.0, float(response)
    return float(dx), float(dy), float(response)


#: Shifts of at least this size must align the scene better than none (:func:`_aligns_better`) [px].
CHECKED_SHIFT_PX = 1.0

#: ... their median absolute difference at most this fraction of the unshifted one [-].
ALIGNMENT_GAIN = 0.8


def _aligns_better(ref: np.ndarray, mov: np.ndarray, dx: float, dy: float) -> bool:
    """Whether ``mov`` shifted by (dx, dy) matches ``ref`` clearly better than unshifted.

    The phase-correlation peak of a featureless or smooth scene (a dark
    background, an overcast sky) is one of its noise, and in dense rain over
    such a scene it can be the rain's own fall between the frames: shifts of
    pixels to tens of pixels that align nothing of the background.  The median
    absolute difference (intensities about their means) is that of the
    background, which most pixels show even in heavy rain: a true shift lowers
    it well below that of no shift; a false one leaves it where it was (or
    raises it).  "No shift" is the fraction of the shift alone, whose
    interpolation smooths the noise as much (by up to a fifth of its median).
    """
    h, w = ref.shape
    # where mov(x + d) lies inside mov (2 px clear of its edges, which the shift replicates)
    x0, x1 = max(0, -math.floor(dx)) + 2, min(w, w - math.ceil(dx)) - 2
    y0, y1 = max(0, -math.floor(dy)) + 2, min(h, h - math.ceil(dy)) - 2
    if x1 - x0 < 16 or y1 - y0 < 16:
        return False
    inner = (slice(y0, y1, 2), slice(x0, x1, 2))     # every other pixel is plenty for a median
    r = ref[inner] - np.float32(ref[inner].mean())

    def mad(sx, sy):
        moved = _translate_cubic(mov, sx, sy, a=-0.5)[inner]
        return float(np.median(np.abs(moved - np.float32(moved.mean()) - r)))

    # against the fraction of the shift alone (under half a pixel: no motion to speak of),
    # which smooths the noise as the whole shift does
    return mad(dx, dy) < ALIGNMENT_GAIN * mad(dx - round(dx), dy - round(dy))


def estimate_motion(ref: np.ndarray, moving: np.ndarray, *, model: str = "translation",
                    work_width: int = 256, min_response: float = 0.05) -> np.ndarray:
    """Global motion from ``ref`` to ``moving``, a 3x3 matrix [px].

    Parameters
    ----------
    ref, moving : (M, N) or (M, N, 3) arrays
        Two frames of the same size [gray levels].
    model : str
        One of :data:`MOTION_MODELS`.
    work_width : int
        Width of the central crop used for estimation [px]; shifts up to
        about a quarter of it are found.
    min_response : float
        Phase-correlation peaks weaker than this (flat or featureless scenes)
        count as no motion.

    Returns
    -------
    (3, 3) float64 array
        ``M`` with ``aligned(x) = moving(M x)`` aligning ``moving`` onto ``ref``.
    """
    import cv2

    _check_model(model)
    ref = np.asarray(ref)
    moving = np.asarray(moving)
    if ref.shape[:2] != moving.shape[:2]:
        raise ValueError(f"frames differ in size: {ref.shape} and {moving.shape}")
    if model == "none":
        return np.eye(3)
    r, scale = _reduce(ref, work_width)
    m, _ = _reduce(moving, work_width)
    window = cv2.createHanningWindow(r.shape[::-1], cv2.CV_32F)
    dx, dy, _resp = _phase_translation(r, m, window, min_response)
    M = np.eye(3)
    M[0, 2], M[1, 2] = dx * scale, dy * scale
    if model == "translation":
        return M
    warp_mode = cv2.MOTION_EUCLIDEAN
    W0 = np.array([[1, 0, dx], [0, 1, dy]], dtype=np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-5)
    try:
        _, W = cv2.findTransformECC(r, m, W0.copy(), warp_mode, criteria, None, 1)
    except cv2.error:
        return M  # ECC did not converge: keep the phase-correlation shift
    # Keep ECC only when it aligns the crops better than the pure translation.
    h, w = r.shape
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    inner = (slice(h // 8, h - h // 8), slice(w // 8, w - w // 8))
    err_t = np.mean(np.abs(cv2.warpAffine(m, W0, (w, h), flags=flags) - r)[inner])
    err_e = np.mean(np.abs(cv2.warpAffine(m, W, (w, h), flags=flags) - r)[inner])
    if not err_e < err_t:
        return M
    # W maps crop coordinates of ref to those of moving; move to frame coordinates.
    H, Wd = ref.shape[:2]
    x0 = (Wd - w) // 2
    y0 = (H - h) // 2
    C = np.array([[1, 0, x0], [0, 1, y0], [0, 0, 1]], dtype=np.float64)
    Wf = np.vstack([W.astype(np.float64), [0, 0, 1]])
    return C @ Wf @ np.linalg.inv(C)


def is_affine(M: np.ndarray) -> bool:
    """The 3x3 transform has no perspective part (last row 0, 0, 1)."""
    r = M[2]
    return abs(float(r[0])) < 1e-12 and abs(float(r[1])) < 1e-12 and abs(float(r[2]) - 1.0) < 1e-12


def is_translation(M: np.ndarray) -> bool:
    """The 3x3 transform is a pure translation (to 1e-9)."""
    return (is_affine(M) and abs(float(M[0, 0]) - 1.0) < 1e-9 and abs(float(M[1, 1]) - 1.0) < 1e-9
            and abs(float(M[0, 1])) < 1e-9 and abs(float(M[1, 0])) < 1e-9)


def transform_magnitude_px(M: np.ndarray, shape: tuple[int, int]) -> float:
    """Largest displacement [px] that ``M`` applies to the corners of a (rows, cols) frame."""
    if is_translation(M):       # the same shift everywhere
        return float(math.hypot(float(M[0, 2]), float(M[1, 2])))
    h, w = shape
    corners = np.array([[0, 0, 1], [w - 1, 0, 1], [0, h - 1, 1], [w - 1, h - 1, 1]], dtype=np.float64).T
    moved = M @ corners
    moved = moved[:2] / moved[2]
    return float(np.max(np.hypot(*(moved - corners[:2]))))


def _cubic_weights(t: float, a: float = -0.5) -> np.ndarray:
    """Cubic-convolution weights [Keys1981] of the samples at -1, 0, 1, 2 for offset t.

    a = -0.5 (Keys' choice) reproduces quadratics exactly; OpenCV's a = -0.75
    does not even reproduce a ramp, and moves it by up to 0.04 px, which
    biases the sub-pixel registration.
    """
    def k(x):
        x = abs(x)
        if x <= 1.0:
            return (a + 2.0) * x ** 3 - (a + 3.0) * x ** 2 + 1.0
        return a * x ** 3 - 5.0 * a * x ** 2 + 8.0 * a * x - 4.0 * a
    return np.array([k(1.0 + t), k(t), k(1.0 - t), k(2.0 - t)], dtype=np.float32)


def _translate_cubic(src: np.ndarray, dx: float, dy: float, *, a: float = -0.75,
                     work: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
    """``out(x, y) = src(x + dx, y + dy)``, bicubic, replicated border: the translation case of warp_to
    (float32 out of a float32 or uint8 ``src``).

    A separable 4-tap filter for the fraction and a whole-pixel shift (a
    slice, the uncovered side replicated): the cubic convolution of
    ``cv2.warpAffine`` with ``INTER_CUBIC`` (a = -0.75, the sharper kernel,
    used to align neighbours for the three-frame test) at a fraction of its
    cost and with an exact fraction (OpenCV quantises it to 1/32 px).
    Registration uses a = -0.5, which moves a ramp exactly.  ``work`` (float32,
    the shape of ``src``) holds the intermediate of a shift of two pixels or
    more when given, ``out`` the result.
    """
    import cv2

    h, w = src.shape[:2]
    ix, iy = math.floor(dx), math.floor(dy)
    if abs(ix) >= w - 1 or abs(iy) >= h - 1:
        return cv2.warpAffine(src.astype(np.float32, copy=False), np.array([[1, 0, dx], [0, 1, dy]]), (w, h),
                              flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
    kx = _cubic_weights(dx - ix, a)
    ky = _cubic_weights(dy - iy, a)
    if -2 <= ix <= 1 and -2 <= iy <= 1:
        # a shift of less than two pixels: the whole pixels go into the anchor,
        # dst(x) = sum_j k[j] src(x + i + j - 1) in one pass, and only the
        # uncovered side is replicated afterwards (from the first covered
        # row / column, as the slice below would)
        out = cv2.sepFilter2D(src, cv2.CV_32F, kx, ky, dst=out, anchor=(1 - ix, 1 - iy),
                              borderType=cv2.BORDER_REPLICATE)
        if ix < 0:
            out[:, :-ix] = out[:, -ix:1 - ix]
        elif ix > 0:
            out[:, w - ix:] = out[:, w - ix - 1:w - ix]
        if iy < 0:
            out[:-iy] = out[-iy:1 - iy]
        elif iy > 0:
            out[h - iy:] = out[h - iy - 1:h - iy]
        return out
    # the fraction: dst(x) = sum_j k[j] src(x + j - 1), anchor 1 puts the weights on offsets -1..2
    frac = cv2.sepFilter2D(src, cv2.CV_32F, kx, ky, dst=work, anchor=(1, 1), borderType=cv2.BORDER_REPLICATE)
    # the whole pixels: a slice, the uncovered side replicated
    view = frac[max(0, iy):h + min(0, iy), max(0, ix):w + min(0, ix)]
    return cv2.copyMakeBorder(view, max(0, -iy), max(0, iy), max(0, -ix), max(0, ix), cv2.BORDER_REPLICATE, out)


def warp_to(frame: np.ndarray, M: np.ndarray, *, min_shift_px: float | None = None,
            with_valid: bool = True, work: np.ndarray | None = None,
            out: np.ndarray | None = None, valid_out: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray | None]:
    """Warp ``frame`` into the reference frame: ``aligned(x) = frame(M x)``.

    Parameters
    ----------
    frame : (M, N) or (M, N, C) array
    M : (3, 3) array
        Transform from :func:`estimate_motion` (or a composition of them).
    min_shift_px : float
        Below this displacement [px] the frame is returned unwarped: no
        interpolation blur on a static camera, whose phase-correlation
        estimates scatter by a tenth of a pixel or so.  A uniform residual
        misalignment raises a pixel above one neighbour and lowers it below
        the other, so it creates no one-frame spike.
    with_valid : bool
        Also return the (M, N) bool mask of pixels that fall inside ``frame``.
    work : float32 array like ``frame``, optional
        Scratch space for the intermediate of a translation (its contents
        are overwritten); saves an allocation per call in a frame loop.
    out : float32 array like ``frame``, optional
        Where to write a translated frame (other warps allocate their own).
    valid_out : (M, N) bool array, optional
        Where to write the valid mask of a translation.

    Returns
    -------
    aligned : array like ``frame`` (float32 when warped)
    valid : (M, N) bool array or None (None means every pixel is valid)
    """
    import cv2

    h, w = frame.shape[:2]
    if min_shift_px is None:
        min_shift_px = WARP_MIN_SHIFT_PX
    if transform_magnitude_px(M, (h, w)) < min_shift_px:
        return frame, None
    flags = cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP
    src = frame if frame.dtype in (np.uint8, np.float32) else frame.astype(np.float32)
    affine = is_affine(M)
    translation = affine and is_translation(M)
    if translation:
        # (an 8-bit frame is filtered straight into float32: the same values as filtering
        # its float32 copy, with a quarter of the memory read)
        if work is not None and (work.shape != src.shape or work.dtype != np.float32):
            work = None
        if out is not None and (out.shape != src.shape or out.dtype != np.float32):
            out = None
        out = _translate_cubic(src, float(M[0, 2]), float(M[1, 2]), work=work, out=out)
    elif affine:
        out = cv2.warpAffine(src, M[:2].astype(np.float64), (w, h), flags=flags,
                             borderMode=cv2.BORDER_REPLICATE)
    else:
        out = cv2.warpPerspective(src, M, (w, h), flags=flags, borderMode=cv2.BORDER_REPLICATE)
    valid = None
    if with_valid:
        if translation:
            dx, dy = M[0, 2], M[1, 2]
            if valid_out is not None and valid_out.shape == (h, w) and valid_out.dtype == np.bool_:
                valid = valid_out
                valid.fill(False)
            else:
                valid = np.zeros((h, w), dtype=bool)
            x0 = max(int(math.ceil(-dx)), 0)
            x1 = min(int(math.floor(w - 1 - dx)), w - 1)
            y0 = max(int(math.ceil(-dy)), 0)
            y1 = min(int(math.floor(h - 1 - dy)), h - 1)
            if x1 >= x0 and y1 >= y0:
                valid[y0:y1 + 1, x0:x1 + 1] = True
        else:
            ones = np.ones((h, w), dtype=np.uint8)
            if affine:
                v = cv2.warpAffine(ones, M[:2], (w, h), flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            else:
                v = cv2.warpPerspective(ones, M, (w, h), flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                        borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            valid = cv2.erode(v, np.ones((3, 3), np.uint8)).astype(bool)
    return out, valid


class MotionTracker:
    """Chain frame-to-frame motion estimates through a stream.

    ``add(frame)`` registers the next frame and returns its index; ``between(j, n)``
    is the transform that warps frame j into frame n (``aligned(x) = I_j(M x)``).

    Parameters
    ----------
    model : str
        One of :data:`MOTION_MODELS`.
    work_width : int
        Width of the central crop used for estimation [px].
    """

    def __init__(self, *, model: str = "translation", work_width: int = 256, min_response: float = 0.05):
        self.model = _check_model(model)
        self.work_width = int(work_width)
        self.min_response = float(min_response)
        self._prev_small = None
        self._prev_full = None
        self._window = None
        self._G: dict[int, np.ndarray] = {}
        self._between: dict[tuple[int, int], np.ndarray] = {}
        self._count = 0

    def add(self, frame: np.ndarray) -> int:
        """Register the next frame (gray or BGR); returns its index."""
        import cv2

        k = self._count
        self._count += 1
        if self.model == "none":
            self._G[k] = np.eye(3)
            return k
        small, _ = _reduce(frame, self.work_width)
        if self._prev_small is None or self._prev_small.shape != small.shape:
            self._G[k] = np.eye(3)
            self._window = cv2.createHanningWindow(small.shape[::-1], cv2.CV_32F)
        elif self.model == "translation":
            dx, dy, _ = _phase_translation(self._prev_small, small, self._window, self.min_response)
            # Maps frame k coordinates to frame k-1 coordinates.
            P = np.array([[1, 0, -dx], [0, 1, -dy], [0, 0, 1]], dtype=np.float64)
            self._G[k] = self._G[k - 1] @ P
        else:
            M = estimate_motion(self._prev_full, frame, model=self.model, work_width=self.work_width,
                                min_response=self.min_response)
            self._G[k] = self._G[k - 1] @ np.linalg.inv(M)
        self._prev_small = small
        if self.model not in ("none", "translation"):
            self._prev_full = np.asarray(frame)
        old = k - 64   # keep memory bounded
        if old in self._G:
            del self._G[old]
            for key in [key for key in self._between if old in key]:
                del self._between[key]
        return k

    def between(self, j: int, n: int) -> np.ndarray:
        """Transform warping frame j into frame n."""
        M = self._between.get((j, n))
        if M is None:
            Gj, Gn = self._G[j], self._G[n]
            if is_translation(Gj) and is_translation(Gn):
                # G_j^-1 G_n of two translations: the difference of their shifts
                M = np.eye(3)
                M[:2, 2] = Gn[:2, 2] - Gj[:2, 2]
            else:
                M = np.linalg.solve(Gj, Gn)
            self._between[(j, n)] = M
        return M.copy()
