"""Detection and removal of rain in a frame stream, Sec. 5 [GargNayar2007].

``detect_streaks`` is the per-frame part the gauge runs on every frame:
candidates (Eq. 19), streaks and the photometric test (Eq. 18).

``Derainer`` is the whole algorithm on a stream: global motion compensation,
detection, the dynamics of the binary field (R_b, needle map, segmentation)
and removal (Sec. 5.2).  It takes frames one by one and returns each output
frame a few frames later (the removal looks three frames ahead), one output
for every input, the first and the last included.  A frame that repeats its
predecessor (frame-rate conversion) cannot show a one-frame spike; repeats are
set aside, the algorithm runs on the distinct frames, and a repeat gets the
output of the frame it repeats.

Beyond the paper: a rain region can hold a moving object (rain falls in
front of it).  Sec. 5.2 would replace its one-frame spikes and its 2- and
3-frame "runs" (a pattern a few frames wide crossing a pixel) by the
neighbouring frames, smearing the object; the removal leaves alone the parts
of frame n that local motion sweeps densely (:func:`local_motion_mask`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Iterable, Iterator

import numpy as np

from raingauge.vision.candidates import candidates, hysteresis_candidates, luminance
from raingauge.vision.dynamics import DynamicsField, RainDynamics
from raingauge.vision.motion import (WARP_MIN_SHIFT_PX, MotionTracker, is_affine, is_translation,
                                     transform_magnitude_px, warp_to)
from raingauge.vision.photometric import StreakFits, _accepted_mask, beta_max_for_exposure, photometric_filter
from raingauge.vision.removal import RUNS, multi_frame_hits, remove_window, run_pair

__all__ = ["detect_streaks", "Derainer", "DerainedFrame", "derain_clip", "estimate_noise_sigma",
           "local_motion_mask", "registration_slack"]


def detect_streaks(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray, *, c: float = 3.0, beta_max: float,
                   noise_sigma: float = 1.0, min_pixels: int = 5, tol: float | None = None,
                   valid: np.ndarray | None = None, max_relative_residual: float = 0.35,
                   residual_sigmas: float = 3.0, slope_sigmas: float = 2.0) -> tuple[np.ndarray, StreakFits]:
    """Rain streaks of frame n: Eq. (19) candidates, then the Eq. (18) test [GargNayar2007].

    Parameters
    ----------
    prev, cur, nxt : (M, N) float arrays
        Linearised luminance of frames n-1, n, n+1, aligned to frame n [gray levels].
    c : float
        Eq. (19) threshold [gray levels].
    beta_max : float
        Largest Eq. (18) slope, tau_max / T (``beta_max_for_exposure(profile.exposure_s)``).
    noise_sigma : float
        Camera noise [gray levels].
    min_pixels, max_relative_residual, residual_sigmas, slope_sigmas
        See :func:`raingauge.vision.photometric.fit_streaks`.
    tol, valid
        See :func:`raingauge.vision.candidates.candidates`.

    Returns
    -------
    mask : (M, N) bool array
        Pixels of the accepted streaks (the binary rain field b of frame n).
    streaks : StreakFits
        Every streak of at least ``min_pixels`` with its fit; ``streaks.accepted``
        flags the rain streaks and ``streaks.accepted_only()`` lists them.
    """
    f32 = np.float32
    prev = np.asarray(prev, dtype=f32)
    cur = np.asarray(cur, dtype=f32)
    nxt = np.asarray(nxt, dtype=f32)
    cand = candidates(prev, cur, nxt, c=c, tol=tol, valid=valid)
    return photometric_filter(prev, cur, nxt, cand, beta_max=beta_max, noise_sigma=noise_sigma,
                              min_pixels=min_pixels, max_relative_residual=max_relative_residual,
                              residual_sigmas=residual_sigmas, slope_sigmas=slope_sigmas)


def estimate_noise_sigma(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray) -> float:
    """Camera noise [gray levels] from three frames: robust spread of I_n - (I_{n-1} + I_{n+1}) / 2.

    The median absolute deviation ignores the sparse rain and moving pixels;
    the difference has variance 1.5 sigma^2 for independent noise.
    """
    d = np.asarray(cur, np.float32) - 0.5 * (np.asarray(prev, np.float32) + np.asarray(nxt, np.float32))
    d = d[::2, ::2]
    mad = float(np.median(np.abs(d - np.median(d))))
    return max(1.4826 * mad / math.sqrt(1.5), 0.1)


@dataclasses.dataclass
class DerainedFrame:
    """One output frame of :class:`Derainer`.

    Attributes
    ----------
    index : int
        Position of the frame in the input stream (0-based).
    frame : uint8 array
        The derained frame, same shape as the input frame.
    rain : (M, N) bool
        Pixels replaced (rain detected inside a rain region).
    detected : (M, N) bool
        Rain pixels of the frame, before segmentation: the binary field b
        (accepted streaks) and, inside the rain region and away from local
        scene motion, the pixels hit by drops in 2 or 3 consecutive frames
        (:func:`raingauge.vision.removal.multi_frame_hits`, Sec. 5.2).
    region : (M, N) bool
        The rain region used.
    field : DynamicsField or None
        The correlation field (needle map) used.
    repeat : bool
        The input frame repeated its predecessor.
    b : (M, N) bool or None
        The binary rain field b alone (Eq. 19 and Eq. 18, one-frame spikes).
    """

    index: int
    frame: np.ndarray
    rain: np.ndarray
    detected: np.ndarray
    region: np.ndarray
    field: DynamicsField | None
    repeat: bool = False
    b: np.ndarray | None = None


@dataclasses.dataclass
class _Unique:
    k: int
    raw: np.ndarray          # input frame, uint8
    lin: np.ndarray          # linearised, float32 (M, N) or (M, N, 3)
    lum: np.ndarray          # luminance, float32 (M, N)
    inputs: list             # input indices showing this frame
    b: np.ndarray | None = None
    b_idx: np.ndarray | None = None   # flat indices of the pixels of b, when known
    n_streaks: int = 0       # accepted streaks (the label image is not kept)
    rise: np.ndarray | None = None   # I_n - I_{n-1} >= c (own coordinates)
    fall: np.ndarray | None = None   # I_n - I_{n+1} >= c
    warped: bool = False
    moving: np.ndarray | None = None   # local scene motion (see local_motion_mask)
    aligned: tuple | None = None       # luminance of units k-1, k+1 warped into this one
    pooled: list = dataclasses.field(default_factory=list)   # arrays handed back to the pool when done
    sub: np.ndarray | None = None      # every 4th pixel of lum, every 4th row (the repeat test)


class Derainer:
    """Streaming rain detection and removal, Sec. 5 [GargNayar2007].

    Parameters
    ----------
    profile : CameraProfile, optional
        Camera: linearisation, exposure (for beta_max), noise and threshold c.
        Default: a linear camera with a 1/30 s exposure and the noise
        estimated from the video.
    c : float, optional
        Eq. (19) threshold [gray levels]; default the profile's
        ``detection_threshold_dn`` (3).  Without a profile the default is
        max(3, 2 sigma) with sigma the noise estimated from the first frames:
        c is "the minimum change due to a drop that is detectable in the
        presence of noise" (Sec. 5.1), and 3 gray levels assumes a quiet camera.
    l, f : int
        Correlation neighbourhood [px] and window [frames] (11 and 30).
    motion : str
        Global motion model (see :data:`raingauge.vision.motion.MOTION_MODELS`).
    beta_max : float, optional
        Override tau_max / T.
    noise_sigma : float or "auto", optional
        Camera noise [gray levels]; "auto" estimates it from the first frames.
    min_pixels : int
        Smallest streak [px].
    grow_px : int
        Also clean the faint rim of detected streaks (see :func:`remove_rain`).
    runs : bool
        Remove drops that hit a pixel in 2 or 3 consecutive frames.
    tol : float, "auto" or None
        Largest |I_{n-1} - I_{n+1}| of a candidate [gray levels]: Eq. (19)
        asks the two neighbours to be equal (a stationary background).
        "auto" allows three standard deviations of the noise of their
        difference, 3 sqrt(2) sigma; None does not test it.
    repeat_tol : float
        Frames whose mean absolute luminance difference to the previous one is
        below this are repeats [gray levels].
    dynamics : dict, optional
        Extra arguments of :class:`RainDynamics` (cell, smooth, min_ratio, ...).
    segment_every : int
        Recompute the direction field and segmentation every this many frames
        (it integrates f frames, so it changes slowly).
    registration_px : float
        Registration error allowed for warped neighbours [px]: when the camera
        moves, c is raised by this times the local gradient magnitude.
    c_low : float, optional
        Hysteresis: candidates are the connected one-frame spikes of at least
        ``c_low`` [gray levels] that reach c somewhere (see
        :func:`raingauge.vision.candidates.hysteresis_candidates`), so faint
        streaks and rims are found whole.  Default min(c, max(c / 2,
        2 sigma)); c_low >= c is the paper's single threshold.
    warmup : int, optional
        Distinct frames gathered before the first output, so that the first
        frames are segmented with a correlation built over several frames
        (default f // 2; 0 gives the smallest latency, 3 frames).
    motion_window_px, motion_min_px, motion_contrast
        Local scene motion left alone by the removal (see
        :func:`local_motion_mask`): windows of ``motion_window_px`` pixels
        [px] holding at least ``motion_min_px`` pixels [px] swept through three
        values, with changes of ``motion_contrast`` times c and the
        stationarity tolerance.  A window of 0 turns the test off.
    near_px : int
        Reach of the relaxed run test of the detection [px]: within this
        distance of the streaks of b, a pixel whose centre frame is c above
        the unaffected frames of a 2- or 3-frame run (the run's other frames
        c / 2) is rain (see :func:`raingauge.vision.removal.multi_frame_hits`);
        0 keeps only the free-standing runs.  The removal keeps the paper's
        rule.

    Notes
    -----
    Cost.  The temporaries of each frame live in frame-sized scratch arrays
    kept from frame to frame (about 40 bytes per pixel in all), and the
    arrays of finished frames (linearised frame, warped neighbours, one-sided
    tests, run masks) are reused for the next ones, so a stream allocates
    almost no frame-sized memory once it runs.  The results do not depend on it.
    """

    LOOKAHEAD = 3

    def __init__(self, profile=None, *, c: float | None = None, l: int = 11, f: int = 30,
                 motion: str = "translation", beta_max: float | None = None,
                 noise_sigma: float | str | None = None, min_pixels: int = 5, grow_px: int = 1,
                 runs: bool = True, repeat_tol: float = 0.1, tol: float | str | None = "auto",
                 dynamics: dict | None = None, segment_every: int = 6, warmup: int | None = None,
                 registration_px: float = 0.15, c_low: float | None = None, motion_window_px: int = 15,
                 motion_min_px: int = 30, motion_contrast: float = 2.5, near_px: int = 1):
        self.profile = profile
        self._c_auto = c is None and profile is None
        if c is None:
            c = profile.detection_threshold_dn if profile is not None else 3.0
        if not (math.isfinite(c) and c > 0):
            raise ValueError(f"threshold c must be a positive number of gray levels, got {c!r}")
        self.c = float(c)
        if beta_max is None:
            beta_max = beta_max_for_exposure(profile.exposure_s if profile is not None else 1.0 / 30.0)
        self.beta_max = float(beta_max)
        if noise_sigma is None:
            noise_sigma = profile.noise_sigma_dn if profile is not None else "auto"
        self._noise_auto = noise_sigma == "auto"
        self.noise_sigma = 1.0 if self._noise_auto else float(noise_sigma)
        self.l, self.f = int(l), int(f)
        self.min_pixels = int(min_pixels)
        self.grow_px = int(grow_px)
        self.runs = bool(runs)
        self.repeat_tol = float(repeat_tol)
        self._tol_auto = tol == "auto"
        self.tol = None if self._tol_auto else tol
        self._dyn_kw = dict(dynamics or {})
        self._tracker = MotionTracker(model=motion)
        self._dyn: RainDynamics | None = None
        self._units: dict[int, _Unique] = {}
        self._n_units = 0
        self._n_inputs = 0
        self._next_remove = 0
        self._shape = None
        self._field: DynamicsField | None = None
        self._since_field = 0
        self.segment_every = int(segment_every)
        self.registration_px = float(registration_px)
        if c_low is not None and not (math.isfinite(c_low) and c_low > 0):
            raise ValueError(f"c_low must be a positive number of gray levels, got {c_low!r}")
        self.c_low = c_low
        self.warmup = self.f // 2 if warmup is None else int(warmup)
        self.motion_window_px = int(motion_window_px)
        self.motion_min_px = int(motion_min_px)
        self.motion_contrast = float(motion_contrast)
        self.near_px = int(near_px)

        self.streak_log: list[tuple[int, int]] = []   # (frame index, accepted streaks)
        self._run_cache: dict[tuple[int, int], np.ndarray] = {}
        self._bufs: dict[str, np.ndarray] = {}   # frame-sized scratch arrays, reused frame after frame
        self._pool: dict[tuple, list] = {}       # frame-sized arrays of finished frames, for the next ones
        self._moves: dict[tuple[int, int], bool] = {}   # (j, n): warping unit j into n moves pixels
        self._levels: dict[tuple, tuple | None] = {}    # thresholds of the gray-level tests

    # ----------------------------------------------------------------- helpers
    def _linearize(self, frame: np.ndarray) -> np.ndarray:
        if self.profile is not None:
            return self.profile.linearize(frame)
        if frame.dtype == np.uint8:
            out = self._take(frame.shape, np.float32)
            np.copyto(out, frame)         # exact, as astype
            return out
        return np.asarray(frame, dtype=np.float32)

    def _moved(self, j: int, n: int, M: np.ndarray) -> bool:
        """``M`` (unit j into unit n) displaces some pixel by ``WARP_MIN_SHIFT_PX`` or more."""
        hit = self._moves.get((j, n))
        if hit is None:
            hit = self._moves[(j, n)] = transform_magnitude_px(M, self._shape[:2]) >= WARP_MIN_SHIFT_PX
        return hit

    def _take(self, shape: tuple, dtype) -> np.ndarray:
        """A frame-sized array (contents undefined): one a finished frame gave back, or a new one."""
        free = self._pool.get((tuple(shape), np.dtype(dtype)))
        return free.pop() if free else np.empty(shape, dtype)

    def _give(self, arrays) -> None:
        """Hand arrays no longer referenced anywhere back to the pool (a few of each kind are kept)."""
        for a in arrays:
            if a.dtype == np.bool_:
                a = a.view(np.uint8)
            free = self._pool.setdefault((a.shape, a.dtype), [])
            if len(free) < 4 and all(a.ctypes.data != b.ctypes.data for b in free):
                free.append(a)

    def _to_uint8(self, lin: np.ndarray) -> np.ndarray:
        if self.profile is not None:
            return self.profile.delinearize(lin)
        return np.clip(np.rint(lin), 0, 255).astype(np.uint8)

    def _aligned(self, j: int, n: int, what: str, valid_name: str = "valid"):
        u = self._units[j]
        arr = getattr(u, what)
        if j == n:
            return arr, None
        M = self._tracker.between(j, n)
        if not self._moved(j, n, M):
            return arr, None
        out = self._take(arr.shape, np.float32)
        if what == "lum" and self.profile is None and u.raw.dtype == np.uint8 and u.raw.ndim == 2:
            arr = u.raw     # the luminance of a gray 8-bit frame is its values: warped from 8 bits
        res = warp_to(arr, M, min_shift_px=0.0, work=self._scratch("warp", arr.shape, np.float32), out=out,
                      valid_out=self._scratch(valid_name, arr.shape[:2], np.bool_))
        if res[0] is not out:
            self._give([out])
        return res

    def _scratch(self, name: str, shape: tuple, dtype) -> np.ndarray:
        """A frame-sized array for a temporary of one step (contents undefined), reused across frames."""
        buf = self._bufs.get(name)
        if buf is None or buf.shape != tuple(shape) or buf.dtype != dtype:
            buf = self._bufs[name] = np.empty(shape, dtype)
        return buf

    def _gray_level_tests(self, tol, tol_motion):
        """The float32 threshold tests of :meth:`_detect` as tests on whole gray levels, or None.

        For frames whose luminance is their 8-bit value, ``I_{n-1} <= I_n - c``
        (float32) holds exactly when I_n - I_{n-1} >= d, ``|I_{n-1} - I_{n+1}|
        <= tol`` when the gray-level difference is at most t_still, and
        ``> tol_motion`` when it is at least t_ends: (d, t_still, t_ends), each
        found by running the float32 test itself on the 256 gray levels.  None
        when the step is not the same for every level (a c within rounding of
        a whole number).
        """
        key = (self.c, tol, tol_motion)
        hit = self._levels.get(key, False)
        if hit is not False:
            return hit
        import cv2

        g = np.arange(256, dtype=np.float32).reshape(1, 256)
        thr = cv2.subtract(g, float(self.c))
        # I_{n-1} = p passes for I_n = q when p <= floor(thr[q]): a step of q - floor(thr[q])
        steps = np.arange(256) - np.floor(thr[0].astype(np.float64)).astype(np.int64)
        res = None
        if np.all(steps == steps[0]) and 1 <= steps[0] <= 255:
            still = cv2.compare(g, float(tol if tol is not None else 0.0), cv2.CMP_LE)[0] > 0
            ends = cv2.compare(g, float(tol_motion), cv2.CMP_GT)[0] > 0
            n_still, n_ends = int(still.sum()), int(ends.sum())
            # monotone in the level (a prefix and a suffix): thresholds
            if still[:n_still].all() and ends[256 - n_ends:].all():
                res = (int(steps[0]), n_still - 1, 256 - n_ends)
        self._levels[key] = res
        return res

    def _c_low(self) -> float:
        """Lower threshold of the hysteresis [gray levels]."""
        if self.c_low is not None:
            return min(float(self.c_low), self.c)
        return min(self.c, max(0.5 * self.c, 2.0 * self.noise_sigma))

    def _reflect(self, i: int, last: int) -> int:
        """Reflect an index into [0, last] (reflect-101)."""
        if last <= 0:
            return 0
        period = 2 * last
        i = abs(i) % period
        return period - i if i > last else i

    # ----------------------------------------------------------------- stream
    def push(self, frame: np.ndarray) -> list[DerainedFrame]:
        """Add the next input frame; returns the output frames that became final (in order)."""
        frame = np.asarray(frame)
        if frame.dtype != np.uint8:
            raise ValueError(f"frames must be uint8, got {frame.dtype}")
        if self._shape is None:
            self._shape = frame.shape
            self._dyn = RainDynamics(frame.shape[:2], l=self.l, f=self.f, **self._dyn_kw)
        elif frame.shape != self._shape:
            raise ValueError(f"frame {self._n_inputs} has shape {frame.shape}, the stream started with {self._shape}")
        idx = self._n_inputs
        self._n_inputs += 1
        lin = self._linearize(frame)
        lum = luminance(lin)
        sub = np.ascontiguousarray(lum[::4, ::4])
        if self._n_units:
            last = self._units[self._n_units - 1]
            # a repeat: the mean absolute difference (on every 4th pixel) is below repeat_tol
            diff = np.subtract(sub, last.sub)
            if float(np.mean(np.abs(diff, out=diff))) < self.repeat_tol:
                last.inputs.append(idx)
                if self.profile is None and frame.dtype == np.uint8:
                    self._give([lin])
                return []
        k = self._n_units
        self._n_units += 1
        self._units[k] = _Unique(k=k, raw=frame, lin=lin, lum=lum, inputs=[idx], sub=sub)
        self._tracker.add(lum)
        if k == 2:
            if self._noise_auto:
                self.noise_sigma = estimate_noise_sigma(self._units[0].lum, self._units[1].lum, self._units[2].lum)
            if self._c_auto:
                self.c = max(self.c, 2.0 * self.noise_sigma)
            self._detect(0, 1, 2, boundary=True)   # first frame: both neighbours from the future
        if k >= 2:
            self._detect(k - 1, k - 2, k)
        out = []
        while self._next_remove + self.LOOKAHEAD <= k and k >= self.warmup:
            out.extend(self._finish(self._next_remove, last=None))
            self._next_remove += 1
        return out

    def flush(self) -> list[DerainedFrame]:
        """End of stream: finish every frame still held back."""
        out: list[DerainedFrame] = []
        n = self._n_units
        if n == 0:
            return out
        if n >= 3 and self._units[n - 1].b is None:
            self._detect(n - 1, n - 2, n - 3, boundary=True)   # last frame: both neighbours from the past
        while self._next_remove < n:
            out.extend(self._finish(self._next_remove, last=n - 1))
            self._next_remove += 1
        return out

    def process(self, frames: Iterable[np.ndarray]) -> Iterator[DerainedFrame]:
        """Derain a whole sequence lazily: one output per input, in order."""
        for fr in frames:
            yield from self.push(fr)
        yield from self.flush()

    # --------------------------------------------------------------- the work
    def _detect(self, n: int, i: int, j: int, boundary: bool = False) -> None:
        """Detect rain in unit n against units i and j.

        At the two ends of the stream both neighbours lie on one side; such a
        detection is weaker evidence and does not enter the dynamics.
        """
        prev, v1 = self._aligned(i, n, "lum", "valid_prev")
        nxt, v2 = self._aligned(j, n, "lum", "valid_next")
        # (the valid masks are scratch arrays: read in this detection only)
        valid = v1 if v2 is None else (v2 if v1 is None else np.logical_and(v1, v2, out=v1))
        u = self._units[n]
        cur = u.lum
        import cv2

        # Elementwise tests with OpenCV (vectorised, no float64 and no
        # temporary per comparison); masks are 0/1 uint8 viewed as bool.
        shape = cur.shape
        tol = self.tol
        if self._tol_auto:
            tol = 3.0 * math.sqrt(2.0) * self.noise_sigma
        k_motion = self.motion_contrast
        tol_motion = k_motion * 3.0 * math.sqrt(2.0) * self.noise_sigma
        apn = ends = None
        levels = slack = None
        if v1 is None and v2 is None and self.profile is None and u.raw.ndim == 2:
            # the luminance of the three frames is their 8-bit values (a gray
            # video, no warp): the same tests on whole gray levels (see _gray_level_tests)
            levels = self._gray_level_tests(tol, tol_motion)
        if levels is not None:
            d, t_still, t_ends = levels
            p8, q8, n8 = self._units[i].raw, u.raw, self._units[j].raw
            step = self._scratch("step8", shape, np.uint8)
            # I_n - I_{n-1} >= c  <=>  the saturated difference of the gray levels reaches d
            rise = np.greater_equal(cv2.subtract(q8, p8, dst=step), d, out=self._take(shape, np.uint8).view(bool))
            fall = np.greater_equal(cv2.subtract(q8, n8, dst=step), d, out=self._take(shape, np.uint8).view(bool))
            cand = np.bitwise_and(rise, fall, out=self._scratch("cand", shape, np.uint8).view(bool))    # Eq. (19)
            apn8 = cv2.absdiff(p8, n8, dst=self._scratch("apn8", shape, np.uint8))
            if tol is not None:                 # ... with I_{n-1} = I_{n+1}
                if t_still < 0:
                    cand.fill(False)
                elif t_still < 255:
                    still = np.less_equal(apn8, t_still, out=self._scratch("still", shape, np.uint8).view(bool))
                    np.bitwise_and(cand, still, out=cand)
            if self.motion_window_px > 0:
                ends = self._scratch("ends", shape, np.uint8)
                if t_ends <= 0:
                    ends.fill(255)
                elif t_ends > 255:
                    ends.fill(0)
                else:
                    cv2.compare(apn8, t_ends - 1, cv2.CMP_GT, ends)
        else:
            # the temporaries of this frame live in scratch arrays (no frame-sized allocations)
            thr = cv2.subtract(cur, float(self.c), dst=self._scratch("thr", shape, np.float32))
            slack = None
            if valid is not None and self.registration_px > 0:
                # Warped neighbours carry a registration error of a fraction of a
                # pixel, i.e. an intensity error proportional to the local gradient:
                # thin bright lines would otherwise look like one-frame spikes.
                slack = _registration_slack(u.raw if (self.profile is None and u.raw.ndim == 2) else cur,
                                            registration_px=self.registration_px, scratch=self._scratch)
                thr = cv2.subtract(thr, slack, dst=thr, dtype=cv2.CV_32F)
            # (0/1 bool results written straight into uint8 arrays of the pool)
            rise = np.less_equal(prev, thr, out=self._take(shape, np.uint8).view(bool))
            fall = np.less_equal(nxt, thr, out=self._take(shape, np.uint8).view(bool))
            cand = np.bitwise_and(rise, fall, out=self._scratch("cand", shape, np.uint8).view(bool))    # Eq. (19)
            if tol is not None:                     # ... with I_{n-1} = I_{n+1}
                apn = cv2.absdiff(prev, nxt, dst=self._scratch("apn", shape, np.float32))
                still = cv2.compare(apn, float(tol), cv2.CMP_LE, dst=self._scratch("still", shape, np.uint8))
                c8 = cand.view(np.uint8)
                cv2.bitwise_and(c8, still, dst=c8)      # 0/1 and 0/255: 0/1
        if valid is not None:
            cand &= valid
        cand = _drop_isolated(cand, self.min_pixels, scratch=self._scratch("near", shape, np.uint8))
        labels_buf = self._scratch("labels", shape, np.int32)
        b, n_streaks, b_idx = _accepted_mask(prev, cur, nxt, cand, beta_max=self.beta_max,
                                             noise_sigma=self.noise_sigma, min_pixels=self.min_pixels,
                                             labels_out=labels_buf, with_index=True)
        c_low = self._c_low()
        if c_low < self.c and cand.any():
            # Hysteresis: faint streaks and rims found whole.  A component that
            # merges a bright streak with its surroundings and fails Eq. (18)
            # keeps the streak accepted at c.
            hyst = hysteresis_candidates(prev, cur, nxt, c=self.c, c_low=c_low, tol=tol, valid=valid,
                                         slack=None if slack is None else slack.astype(np.float32, copy=False))
            b_low, n_low = _accepted_mask(prev, cur, nxt, np.ascontiguousarray(hyst), beta_max=self.beta_max,
                                          noise_sigma=self.noise_sigma, min_pixels=self.min_pixels,
                                          labels_out=labels_buf)
            b |= b_low
            b_idx = None
            n_streaks = max(n_streaks, n_low)
        warped = [a for a, v in ((prev, v1), (nxt, v2)) if v is not None]
        if not boundary:
            u.rise, u.fall = rise, fall
            if v1 is not None or v2 is not None:
                u.aligned = (prev, nxt)   # read again by the removal of this frame
                u.pooled = warped
        if self.motion_window_px > 0:
            k = self.motion_contrast
            moving = local_motion_mask(prev, cur, nxt, c=k * self.c, tol=tol_motion,
                                       window_px=self.motion_window_px, min_px=self.motion_min_px, ends_diff=apn,
                                       work=(self._scratch("ends", shape, np.uint8),
                                             self._scratch("ends01", shape, np.uint8)), ends=ends)
            u.moving = moving if moving.any() else None
        u.warped = v1 is not None or v2 is not None
        u.b = b
        u.b_idx = b_idx
        u.n_streaks = n_streaks
        if not boundary:
            self._dyn.update(b, flat=b_idx)
        else:   # nothing of this detection is kept
            self._give(warped + [rise, fall])

    def _finish(self, n: int, last: int | None) -> list[DerainedFrame]:
        u = self._units[n]
        top = self._n_units - 1 if last is None else last
        if self._field is None or self._since_field >= self.segment_every:
            self._field = self._dyn.field()
            self._region = self._field.region_mask(dilate_px=self.l // 2)
            self._since_field = 0
        self._since_field += 1
        field = self._field
        region = self._region
        if u.b is None:  # fewer than 3 distinct frames: nothing can be detected
            u.b = np.zeros(u.lum.shape, bool)
        out_frame = u.raw.copy()
        replaced = np.zeros(u.lum.shape, bool)
        work = region
        if u.moving is not None:
            # Sec. 5.2 changes the rain pixels of rain regions only: dense local
            # scene motion inside a rain region is left alone
            work = np.greater(region, u.moving)     # region and not moving
        detected = u.b
        if top >= 2 and np.any(work):
            ids = [self._reflect(n + o, top) for o in range(-3, 4)]
            window = _StreamWindow(self, n, ids)
            tol = 3.0 * math.sqrt(2.0) * self.noise_sigma if self._tol_auto else self.tol
            free: list = []
            idx, vals = remove_window(window, u.b, work, c=self.c, runs=self.runs, tol=tol,
                                      grow_px=self.grow_px, beta_max=self.beta_max,
                                      noise_sigma=self.noise_sigma, min_pixels=self.min_pixels, free_out=free,
                                      rain_idx=u.b_idx)
            if idx.size:
                n_pix = replaced.size
                out_frame.reshape(n_pix, -1)[idx] = self._to_uint8(vals).reshape(idx.size, -1)
                replaced.ravel()[idx] = True
            if self.runs:
                # Sec. 5.2: pixels hit by drops in 2 or 3 consecutive frames show
                # no one-frame spike (note 16) but are rain.  Like the removal,
                # only inside rain regions and away from local scene motion:
                # elsewhere camera noise, moving texture and ripples pass the
                # run tests too.  The free-standing runs the removal found are
                # shared; the relaxed test next to the streaks is added.
                flat, _, _ = multi_frame_hits(window, u.b, c=self.c, where=work, tol=tol, beta_max=self.beta_max,
                                              noise_sigma=self.noise_sigma, min_pixels=self.min_pixels,
                                              near_px=self.near_px, free=free[0] if free else None)
                if flat.size:
                    detected = u.b.copy()
                    detected.ravel()[flat] = True
        self.streak_log.append((u.inputs[0], u.n_streaks))
        results = [DerainedFrame(index=i, frame=out_frame, rain=replaced, detected=detected, region=region,
                                 field=field, repeat=(r > 0), b=u.b) for r, i in enumerate(u.inputs)]
        u.aligned = None
        self._give(u.pooled)              # the warped neighbours
        u.pooled = []
        # drop what is no longer needed (frames n-3 and older)
        old = n - self.LOOKAHEAD
        if old in self._units:
            gone = self._units.pop(old)
            for key in [key for key in self._moves if old in key]:
                del self._moves[key]
            self._give(gone.pooled + [a for a in (gone.rise, gone.fall) if a is not None])
            if self.profile is None and gone.raw.dtype == np.uint8:
                self._give([gone.lin])
        return results


def registration_slack(image: np.ndarray, *, registration_px: float) -> np.ndarray:
    """Intensity error of a registration error of ``registration_px`` pixels, (M, N) [gray levels].

    ``registration_px`` times the gradient magnitude (3 x 3 Sobel).  An 8-bit
    gray frame takes a fast integer path: the L1 norm |g_x| + |g_y| (at most
    sqrt(2) above the magnitude, never below it), rounded to whole gray levels,
    uint8.  Other frames give the float32 magnitude.

    Parameters
    ----------
    image : (M, N) uint8 or float array
        Frame n [gray levels].
    registration_px : float
        Registration error allowed [px].
    """
    return _registration_slack(image, registration_px=registration_px,
                               scratch=lambda name, shape, dtype: np.empty(shape, dtype))


def _registration_slack(image, *, registration_px, scratch):
    """:func:`registration_slack` with its arrays from ``scratch(name, shape, dtype)``."""
    import cv2

    scale = 0.125 * float(registration_px)
    shape = image.shape[:2]
    if image.dtype == np.uint8:
        dx, dy = cv2.spatialGradient(image, scratch("slack_dx", shape, np.int16), scratch("slack_dy", shape, np.int16))
        ax = cv2.convertScaleAbs(dx, scratch("slack_ax", shape, np.uint8), alpha=scale)
        ay = cv2.convertScaleAbs(dy, scratch("slack_ay", shape, np.uint8), alpha=scale)
        return cv2.add(ax, ay, dst=scratch("slack", shape, np.uint8))
    img = np.asarray(image, np.float32)
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, scratch("slack_gx", shape, np.float32), ksize=3, scale=scale)
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, scratch("slack_gy", shape, np.float32), ksize=3, scale=scale)
    return cv2.magnitude(gx, gy, scratch("slack", shape, np.float32))


def local_motion_mask(prev: np.ndarray, cur: np.ndarray, nxt: np.ndarray, *, c: float, tol: float,
                      window_px: int = 15, min_px: int = 30, ends_diff: np.ndarray | None = None,
                      work: tuple | None = None, ends: np.ndarray | None = None) -> np.ndarray:
    """Pixels near local scene motion in frame n: a moving object is not rain, (M, N) bool.

    Rain changes a pixel for one frame (Sec. 4.3 [GargNayar2007]): a drop in
    frame n-1 leaves I_n = I_{n+1}, a drop in frame n+1 leaves I_{n-1} = I_n,
    and a drop in frame n leaves I_{n-1} = I_{n+1} (Eq. 19).  A moving edge or
    texture sweeps a pixel through three different values instead:
    ``|I_{n+1} - I_{n-1}| > tol`` with I_n more than ``c`` away from both.
    A window of ``window_px`` x ``window_px`` pixels holding ``min_px`` such
    pixels or more is local motion (the global motion is already compensated).

    Parameters
    ----------
    prev, cur, nxt : (M, N) float32 arrays
        Luminance of frames n-1, n, n+1 aligned to frame n [gray levels].
    c : float
        Least change from I_n to each neighbour [gray levels].
    tol : float
        Stationarity tolerance of the two neighbours [gray levels].
    window_px : int
        Side of the counting window [px].
    min_px : int
        Sweeping pixels that make a window moving [px].
    ends_diff : (M, N) float32 array, optional
        ``|I_{n+1} - I_{n-1}|`` when already computed.
    work : tuple of two (M, N) uint8 arrays, optional
        Scratch space for the intermediates (overwritten).
    ends : (M, N) uint8 array, optional
        ``|I_{n+1} - I_{n-1}| > tol`` as 0 / 255 when already computed (overwritten).
    """
    import cv2

    e, where = _sweeping(prev, cur, nxt, c=c, tol=tol, ends_diff=ends_diff, work=work, ends=ends)
    n_e = where.size if where is not None else cv2.countNonZero(e)
    if n_e < int(min_px):   # no window can hold min_px sweeping pixels
        return np.zeros(e.shape, bool)
    w = int(window_px)
    if w * w <= 257 and where is not None:
        sparse = _window_count_sparse(e, where, window_px=w, min_px=int(min_px))
        if sparse is not None:
            return sparse
    if w * w <= 257:   # counts of 255 fit in uint16: compare without leaving it
        count = cv2.boxFilter(e, cv2.CV_16U, (w, w), normalize=False, borderType=cv2.BORDER_CONSTANT)
        m = cv2.compare(count, 255 * int(min_px), cv2.CMP_GE)
        return np.bitwise_and(m, 1, out=m).view(bool)
    count = cv2.boxFilter(e, cv2.CV_32F, (w, w), normalize=False, borderType=cv2.BORDER_CONSTANT)
    return count >= 255.0 * int(min_px) - 0.5


def _window_count_sparse(e, where, *, window_px, min_px, max_blocks=256):
    """``local_motion_mask``'s window count on a sparse ``e``, block by block; None when too dense.

    The output pixels are split into blocks of ``window_px`` x ``window_px``;
    the window of every pixel of a block lies within the 2 x 2 cells of a
    grid shifted by half a window, so a block whose 2 x 2 cells hold fewer
    than ``min_px`` sweeping pixels has no moving pixel.  The others get the
    exact count of the whole-frame box filter, on a patch one half-window
    larger than the block (the frame's edges are the zero border).

    Parameters
    ----------
    e : (M, N) uint8 array
        0 / 255 sweeping pixels.
    where : (P,) int array
        Flat indices of the non-zero pixels of ``e``.
    """
    import cv2

    H, W = e.shape
    w = int(window_px)
    h = w // 2
    gh, gw = (H + 2 * h) // w + 2, (W + 2 * h) // w + 2
    ys, xs = np.divmod(where, W)
    cells = np.bincount(((ys + h) // w) * gw + (xs + h) // w, minlength=gh * gw).reshape(gh, gw)
    pairs = cells[:-1, :-1] + cells[1:, :-1] + cells[:-1, 1:] + cells[1:, 1:]
    hot = np.argwhere(pairs >= min_px)
    if hot.shape[0] > max_blocks:
        return None
    out = np.zeros((H, W), np.uint8)
    for gi, gj in hot.tolist():
        r0, c0 = gi * w, gj * w
        if r0 >= H or c0 >= W:
            continue
        r1, c1 = min(r0 + w, H), min(c0 + w, W)
        pr0, pc0 = max(r0 - h, 0), max(c0 - h, 0)
        patch = e[pr0:min(r1 + h, H), pc0:min(c1 + h, W)]
        count = cv2.boxFilter(patch, cv2.CV_16U, (w, w), normalize=False, borderType=cv2.BORDER_CONSTANT)
        out[r0:r1, c0:c1] = count[r0 - pr0:r1 - pr0, c0 - pc0:c1 - pc0] >= 255 * min_px
    return out.view(bool)


def _sweeping(prev, cur, nxt, *, c, tol, ends_diff=None, work=None, ends=None):
    """0/255 uint8: |I_{n+1} - I_{n-1}| > tol and I_n more than c from both; and the flat
    indices of its pixels when they came cheaply (None otherwise).  ``ends``: the
    first test, 0 / 255, when already computed (it becomes the result)."""
    import cv2

    ends_buf, bits_buf = (None, None) if work is None else work
    if ends is None:
        if ends_diff is None:
            ends_diff = cv2.absdiff(prev, nxt)
        ends = cv2.compare(ends_diff, float(tol), cv2.CMP_GT, ends_buf)
    if cv2.countNonZero(ends) > ends.size // 16:    # much motion: whole-frame operations
        near = cv2.min(cv2.absdiff(cur, prev), cv2.absdiff(cur, nxt))
        return cv2.bitwise_and(ends, cv2.compare(near, float(c), cv2.CMP_GT)), None
    # the ends differ at few pixels (a static scene): test I_n there only
    flat = ends.reshape(-1)
    idx = np.flatnonzero(np.bitwise_and(flat, 1, out=None if bits_buf is None else bits_buf.reshape(-1)).view(bool))
    cn = np.take(np.asarray(cur).reshape(-1), idx)
    pn = np.take(np.asarray(prev).reshape(-1), idx)
    c32 = np.float32(c)
    near = np.abs(cn - pn) > c32
    on = np.flatnonzero(near)        # I_{n+1} read where I_n is already c from I_{n-1}
    nn = np.take(np.asarray(nxt).reshape(-1), np.take(idx, on))
    near[on] = np.abs(np.take(cn, on) - nn) > c32
    flat[idx[~near]] = 0
    return ends, idx[near]


def _shift_nearest(mask: np.ndarray, dx: float, dy: float, out: np.ndarray | None = None) -> np.ndarray:
    """``out(x, y) = mask(x + dx, y + dy)`` to the nearest pixel, False outside (a slice copy).

    ``out`` (like ``mask``, not ``mask`` itself) receives the result when given.
    """
    ix, iy = int(round(dx)), int(round(dy))
    if ix == 0 and iy == 0:
        return mask
    h, w = mask.shape
    if out is None:
        out = np.zeros_like(mask)
    elif abs(ix) >= w or abs(iy) >= h:
        out.fill(0)
    else:   # only the uncovered strips need clearing
        out[:max(0, -iy)] = 0
        out[h - max(0, iy):] = 0
        out[:, :max(0, -ix)] = 0
        out[:, w - max(0, ix):] = 0
    if abs(ix) >= w or abs(iy) >= h:
        return out
    out[max(0, -iy):h - max(0, iy), max(0, -ix):w - max(0, ix)] = \
        mask[max(0, iy):h - max(0, -iy), max(0, ix):w - max(0, -ix)]
    return out


def _drop_isolated(mask: np.ndarray, min_pixels: int, scratch: np.ndarray | None = None) -> np.ndarray:
    """``mask`` without its isolated pixels (no 8-neighbour), when streaks need 2 pixels or more.

    Camera noise makes most candidates single pixels; removing them before
    the labelling changes no streak of ``min_pixels >= 2`` and saves most of
    the per-pixel work.  With ``scratch`` (a uint8 array of the mask's shape
    for the dilation) ``mask`` is changed in place.
    """
    import cv2

    if min_pixels < 2:
        return mask
    ring = np.ones((3, 3), np.uint8)
    ring[1, 1] = 0
    # a neighbour within the 8 around: dilation by the ring (much cheaper than counting)
    near = cv2.dilate(mask.view(np.uint8), ring, dst=scratch, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    if scratch is None:
        return mask & near.view(bool)
    return np.bitwise_and(mask, near.view(bool), out=mask)   # a scratch mask: in place


#: Width of the coordinate maps handed to cv2.remap (which limits map sizes) [px].
_MAP_WIDTH = 1024


def _affine_map(M: np.ndarray, row: int, cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Coordinate ``row`` (0: x, 1: y) of ``M (x, y, 1)`` for float32 maps of columns and rows."""
    a, b, t = float(M[row, 0]), float(M[row, 1]), float(M[row, 2])
    if a == 1.0 and b == 0.0:
        return cols + np.float32(t)
    if a == 0.0 and b == 1.0:
        return rows + np.float32(t)
    return np.float32(a) * cols + np.float32(b) * rows + np.float32(t)


def _sample_bilinear(img: np.ndarray, M: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Values of ``img`` at ``M (x, y)`` for the flat pixels ``idx`` of the reference frame, (P, C)."""
    h, w = img.shape[:2]
    flat = img.reshape(h * w, -1)
    if is_translation(M) and h > 1 and w > 1:
        # a translation: one integer offset and one pair of weights for every pixel
        ix, iy = math.floor(M[0, 2]), math.floor(M[1, 2])
        fx, fy = np.float32(M[0, 2] - ix), np.float32(M[1, 2] - iy)
        r = idx // w + iy
        cc = idx % w + ix
        r0 = np.clip(r, 0, h - 1)
        r1 = np.clip(r + 1, 0, h - 1)
        c0 = np.clip(cc, 0, w - 1)
        c1 = np.clip(cc + 1, 0, w - 1)
        return ((1 - fy) * ((1 - fx) * flat[r0 * w + c0] + fx * flat[r0 * w + c1])
                + fy * ((1 - fx) * flat[r1 * w + c0] + fx * flat[r1 * w + c1]))
    rows = (idx // w).astype(np.float64)
    cols = (idx % w).astype(np.float64)
    x = M[0, 0] * cols + M[0, 1] * rows + M[0, 2]
    y = M[1, 0] * cols + M[1, 1] * rows + M[1, 2]
    if not is_affine(M):
        z = M[2, 0] * cols + M[2, 1] * rows + M[2, 2]
        x, y = x / z, y / z
    x = np.clip(x, 0, w - 1)
    y = np.clip(y, 0, h - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), w - 2 if w > 1 else 0)
    y0 = np.minimum(np.floor(y).astype(np.int64), h - 2 if h > 1 else 0)
    fx = (x - x0)[:, None].astype(np.float32)
    fy = (y - y0)[:, None].astype(np.float32)
    i00 = y0 * w + x0
    x1 = 1 if w > 1 else 0
    y1 = w if h > 1 else 0
    return ((1 - fy) * ((1 - fx) * flat[i00] + fx * flat[i00 + x1])
            + fy * ((1 - fx) * flat[i00 + y1] + fx * flat[i00 + y1 + x1]))


class _StreamWindow:
    """Frames n-3 .. n+3 of a :class:`Derainer`, aligned to frame n lazily, pixel by pixel.

    Only the pixels the removal touches are resampled: no full-frame warps.
    The luminance of frames n-1 and n+1 aligned to frame n, warped once for
    the three-frame test, is read directly.
    """

    def __init__(self, d: "Derainer", n: int, ids: list[int]):
        self.d, self.n, self.ids = d, n, ids
        self.units = [d._units[j] for j in ids]
        u = d._units[n]
        self.shape = u.lum.shape
        self.centre_lum = u.lum
        self.centre_lin = u.lin
        self._M = [d._tracker.between(j, n) for j in ids]
        self._moved = [d._moved(j, n, M) for j, M in zip(ids, self._M)]
        # frames n-1 and n+1 as the three-frame test saw them (None: not warped or not those frames)
        self._aligned = {}
        self._coord_cache = None
        self._runs_memo = None
        if u.aligned is not None and ids[2] == n - 1 and ids[4] == n + 1:
            self._aligned = {2: u.aligned[0], 4: u.aligned[1]}

    def _at(self, arr, k, idx):
        if not self._moved[k]:
            if arr.ndim == 2:     # np.take on the flat frame: much cheaper than row indexing
                return np.take(arr.reshape(-1), idx)[:, None]
            return np.take(arr.reshape(arr.shape[0] * arr.shape[1], -1), idx, axis=0)
        M = self._M[k]
        if not is_affine(M):
            return _sample_bilinear(arr, M, idx)
        # bilinear resampling of the few pixels in C (cv2.remap), on the
        # coordinates of ``idx`` computed once for all the frames of the window
        cols, rows, pad = self._coords(idx)
        mx = _affine_map(M, 0, cols, rows)
        my = _affine_map(M, 1, cols, rows)
        import cv2

        out = cv2.remap(arr, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        ch = 1 if arr.ndim == 2 else arr.shape[2]
        return out.reshape(-1, ch)[:idx.size]

    @property
    def lin_is_lum(self) -> bool:
        """``lin_at(k, idx)`` is ``lum_at(k, idx)[:, None]`` (gray video)."""
        return all(u.lin is u.lum for u in self.units)

    def scratch(self, name: str, shape: tuple, dtype) -> np.ndarray:
        """Scratch space for the removal's temporaries (see :meth:`Derainer._scratch`)."""
        return self.d._scratch(name, shape, dtype)

    def _coords(self, idx):
        """Columns and rows of the flat pixels ``idx`` as (R, 1024) float32 maps (padded)."""
        hit = self._coord_cache
        if hit is not None and hit[0] is idx:
            return hit[1]
        w = self.shape[1]
        P = idx.size
        R = max(-(-P // _MAP_WIDTH), 1)
        pad = R * _MAP_WIDTH - P
        full = np.concatenate([idx, np.zeros(pad, idx.dtype)]) if pad else idx
        rows, cols = np.divmod(full, w)
        res = (cols.astype(np.float32).reshape(R, _MAP_WIDTH), rows.astype(np.float32).reshape(R, _MAP_WIDTH), pad)
        self._coord_cache = (idx, res)
        return res

    def lum_at(self, k: int, idx: np.ndarray) -> np.ndarray:
        al = self._aligned.get(k)
        if al is not None and self._moved[k]:
            return np.take(al.reshape(-1), idx)
        if not self._moved[k]:
            return np.take(self.units[k].lum.reshape(-1), idx)
        return self._at(self.units[k].lum, k, idx)[:, 0]

    def lin_at(self, k: int, idx: np.ndarray) -> np.ndarray:
        unit = self.units[k]
        if unit.lin is unit.lum:          # a gray frame: its luminance
            return self.lum_at(k, idx)[:, None]
        return self._at(unit.lin, k, idx)

    def _carry(self, mask: np.ndarray, src: int, dst: int, out: np.ndarray | None = None) -> np.ndarray:
        """A mask of unit ``src`` in the coordinates of unit ``dst`` (nearest pixel, False outside).

        A translated mask is written into ``out`` when given (a bool array like
        ``mask``, not ``mask`` itself); the mask itself is returned when it does not move.
        """
        import cv2

        if src == dst:
            return mask
        M = self.d._tracker.between(src, dst)
        if not self.d._moved(src, dst, M):
            return mask
        if is_translation(M):
            return _shift_nearest(mask, M[0, 2], M[1, 2], out=out)
        h, w = self.shape
        return cv2.warpAffine(mask.view(np.uint8), M[:2], (w, h),
                              flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP).view(bool)

    def _carry_or(self, acc: np.ndarray, mask: np.ndarray, src: int, dst: int) -> None:
        """``acc |= self._carry(mask, src, dst)``, a translation without the intermediate mask."""
        M = self.d._tracker.between(src, dst)
        if src == dst or not self.d._moved(src, dst, M):
            np.bitwise_or(acc, mask, out=acc)
        elif is_translation(M):
            ix, iy = int(round(M[0, 2])), int(round(M[1, 2]))
            h, w = self.shape
            if abs(ix) < w and abs(iy) < h:     # (else nothing of the mask lands inside)
                part = acc[max(0, -iy):h - max(0, iy), max(0, -ix):w - max(0, ix)]
                np.bitwise_or(part, mask[max(0, iy):h - max(0, -iy), max(0, ix):w - max(0, -ix)], out=part)
        else:
            np.bitwise_or(acc, self._carry(mask, src, dst), out=acc)

    def centre_steps(self, c: float) -> np.ndarray | None:
        """Frame n at least c above frame n-1 or n+1 (the one-sided tests of its Eq. (19)), or None."""
        u = self.d._units[self.n]
        if u.rise is None or u.fall is None:
            return None
        return np.bitwise_or(u.rise, u.fall, out=self.d._scratch("steps", self.shape, np.bool_))

    def run_candidates(self, c: float) -> np.ndarray:
        hit = self._runs_memo
        if hit is not None and hit[0] == c:
            return hit[1]
        pre = self._run_candidates(c)
        self._runs_memo = (c, pre)
        return pre

    def _run_candidates(self, c: float) -> np.ndarray:
        near = self.units[1:6]
        if self.ids[1:6] != list(range(self.n - 2, self.n + 3)) or any(
                v.rise is None or v.fall is None for v in near):
            return np.zeros(self.shape, bool)   # the two ends of the stream: no runs
        # The run masks are those of absolute frame pairs [a, e], kept in the
        # coordinates of frame a: three of the five are shared with the next
        # frame's window, and only the result is carried into frame n.
        cache = self.d._run_cache
        scratch = self.d._scratch
        work = (scratch("run_count", self.shape, np.uint8), scratch("run_ok", self.shape, np.uint8))
        by_start: dict[int, list] = {}
        for a, e in RUNS:
            ja, je = self.n + a, self.n + e
            m = cache.get((ja, je))
            if m is None:
                fall = self._carry(near[e + 2].fall, je, ja, out=scratch("carry", self.shape, np.bool_))
                m = cache[(ja, je)] = run_pair(near[a + 2].rise, fall, work=work,
                                               out=self.d._take(self.shape, np.uint8))
            by_start.setdefault(ja, []).append(m)
        # one carry per starting frame; the unions live in scratch arrays (the
        # cached masks are only read), and so does the result (read within
        # this frame's removal only)
        pre = scratch("run_pre", self.shape, np.bool_)
        first = True
        for k, (ja, ms) in enumerate(by_start.items()):
            m = ms[0]
            if len(ms) > 1:
                m = np.bitwise_or(ms[0], ms[1], out=scratch(f"run_start{k}", self.shape, np.bool_))
                for extra in ms[2:]:
                    np.bitwise_or(m, extra, out=m)
            if first:
                m = self._carry(m, ja, self.n, out=pre)
                if m is not pre:
                    np.copyto(pre, m)
                first = False
            else:
                self._carry_or(pre, m, ja, self.n)
        for key in [key for key in cache if key[0] < self.n - 1]:
            self.d._give([cache.pop(key)])
        return pre


def derain_clip(frames: np.ndarray | Iterable[np.ndarray], profile=None, **kwargs) -> tuple[np.ndarray, np.ndarray]:
    """Derain a whole clip: (T, M, N[, 3]) uint8 -> (derained, rain masks (T, M, N) bool).

    Keyword arguments go to :class:`Derainer`.
    """
    d = Derainer(profile, **kwargs)
    outs, masks = [], []
    for r in d.process(frames):
        outs.append(r.frame)
        masks.append(r.rain)
    return np.stack(outs), np.stack(masks)
