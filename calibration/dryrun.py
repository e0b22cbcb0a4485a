"""Dry run: false detections without rain (step 5 of ``raingauge calibrate``).

Some seconds of the installed camera's view without rain go through the
gauge's detector: candidates of Eq. (19) [GargNayar2007] at the calibrated
threshold c, grouped into streaks and filtered by the photometric constraint
of Eq. (18).  Every streak accepted here is a false detection; their rate per
minute is what the gauge would count as rain in a dry hour.

The detector assumes a still background (Sec. 5.1).  Scene motion -- a
swaying tree, a camera on a vibrating mast -- is measured two ways: the
global image shift between frames (``cv2.phaseCorrelate``) and the fraction
of pixels whose frames n-1 and n+1 differ by more than noise explains.
Either above its limit gives a warning.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Iterable

import numpy as np

from calibration.frames import linear_gray_frames
from raingauge.errors import InputError

__all__ = ["DryRunResult", "dry_run", "scene_motion"]

#: Global shift above which the scene counts as moving [px/frame].
MAX_SHIFT_PX = 0.25
#: Fraction of non-stationary pixels above which the scene counts as moving [-].
MAX_CHANGED_FRACTION = 0.02
#: Fewest frames for a dry run.
MIN_FRAMES = 5


@dataclasses.dataclass
class DryRunResult:
    """Outcome of the dry run.

    Attributes
    ----------
    false_per_minute : float
        Accepted (false) streaks per minute of video [1/min].
    false_streaks : int
        Accepted streaks in the whole clip.
    candidate_fraction : float
        Mean fraction of pixels that were Eq. (19) candidates per frame [-].
    seconds : float
        Duration analysed [s].
    n_frames : int
    shift_px_per_frame : float
        Median global shift between consecutive frames [px].
    changed_fraction : float
        Mean fraction of pixels with |I_{n+1} - I_{n-1}| above 4 sqrt(2) sigma [-].
    threshold_c_dn : float
        Threshold used [gray levels].
    warnings : list of str
    """

    false_per_minute: float
    false_streaks: int
    candidate_fraction: float
    seconds: float
    n_frames: int
    shift_px_per_frame: float
    changed_fraction: float
    threshold_c_dn: float
    warnings: list[str]

    def summary(self) -> str:
        lines = [
            f"false detections  {self.false_per_minute:.2f} per minute ({self.false_streaks} streaks in "
            f"{self.seconds:.1f} s, {self.n_frames} frames, c = {self.threshold_c_dn:.2f})",
            f"candidate pixels  {self.candidate_fraction:.3%} per frame",
            f"scene motion      {self.shift_px_per_frame:.3f} px/frame; {self.changed_fraction:.2%} of pixels not still",
        ]
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def to_provenance(self) -> dict:
        return {
            "calibrated": True,
            "false_detections_per_min": round(self.false_per_minute, 4),
            "false_streaks": self.false_streaks,
            "seconds": round(self.seconds, 3),
            "candidate_fraction": float(f"{self.candidate_fraction:.4g}"),
            "shift_px_per_frame": round(self.shift_px_per_frame, 4),
            "changed_fraction": float(f"{self.changed_fraction:.4g}"),
            "threshold_c_dn": round(self.threshold_c_dn, 3),
            "warnings": list(self.warnings),
        }


def scene_motion(frames: np.ndarray, *, noise_sigma_dn: float) -> tuple[float, float]:
    """Global shift and non-stationary fraction of a clip.

    Parameters
    ----------
    frames : (T, M, N) float
        Linearised frames [gray levels].
    noise_sigma_dn : float
        Sensor noise [gray levels].

    Returns
    -------
    shift : float
        Median magnitude of the frame-to-frame global shift [px/frame].
    changed : float
        Mean fraction of pixels with |I_{n+1} - I_{n-1}| > 4 sqrt(2) sigma [-].
    """
    meter = _MotionMeter(noise_sigma_dn)
    for frame in np.asarray(frames, dtype=np.float32):
        meter.add(frame)
    return meter.result()


class _MotionMeter:
    """Accumulates the global shift and the non-stationary fraction frame by frame."""

    def __init__(self, noise_sigma_dn: float):
        self.limit = np.float32(4.0 * math.sqrt(2.0) * max(noise_sigma_dn, 0.5))
        self.window = None
        self.prev: list[np.ndarray] = []
        self.shifts: list[float] = []
        self.changed: list[float] = []

    def add(self, frame: np.ndarray) -> None:
        import cv2

        if self.window is None:
            m, n = frame.shape
            self.window = cv2.createHanningWindow((n, m), cv2.CV_32F)
        if self.prev:
            # phaseCorrelate may apply the window in place: give it copies.
            (dx, dy), _resp = cv2.phaseCorrelate(self.prev[-1].copy(), frame.copy(), self.window)
            self.shifts.append(math.hypot(dx, dy))
        if len(self.prev) == 2:
            self.changed.append(float(np.mean(np.abs(frame - self.prev[0]) > self.limit)))
        self.prev = (self.prev + [frame])[-2:]

    def result(self) -> tuple[float, float]:
        return (float(np.median(self.shifts)) if self.shifts else 0.0,
                float(np.mean(self.changed)) if self.changed else 0.0)


def dry_run(
    frames: Iterable[np.ndarray],
    *,
    frame_rate_hz: float,
    exposure_s: float,
    c_dn: float,
    noise_sigma_dn: float,
    table: np.ndarray | None = None,
) -> DryRunResult:
    """False detections per minute on rain-free frames.

    Parameters
    ----------
    frames : (T, M, N) array or iterable of (M, N) arrays
        Rain-free frames from the installed camera, uint8 codes (or floats
        already linear) [gray levels]; read one at a time.
    frame_rate_hz : float
        Frame rate [1/s].
    exposure_s : float
        Exposure time [s] (sets beta_max of Eq. (18)).
    c_dn : float
        Detection threshold of Eq. (19) [gray levels].
    noise_sigma_dn : float
        Sensor noise [gray levels].
    table : (256,) float, optional
        Linearisation table for uint8 frames [gray levels].
    """
    from raingauge.vision.candidates import candidates
    from raingauge.vision.photometric import beta_max_for_exposure, label_streaks, photometric_filter

    if isinstance(frames, np.ndarray) and frames.ndim != 3:
        raise InputError(f"dry run: expected gray frames (T, M, N), got shape {frames.shape}")
    beta_max = beta_max_for_exposure(exposure_s)
    meter = _MotionMeter(noise_sigma_dn)
    win: list[np.ndarray] = []
    false = 0
    cand_frac = []
    t = 0
    for lin, _codes in linear_gray_frames(frames, table=table, dtype=np.float32, step="dry run"):
        t += 1
        meter.add(lin)
        win = (win + [lin])[-3:]
        if len(win) < 3:
            continue
        prev, cur, nxt = win
        mask = candidates(prev, cur, nxt, c=c_dn)
        cand_frac.append(float(mask.mean()))
        if not mask.any():
            continue
        labels = label_streaks(mask)
        _accepted, fits = photometric_filter(prev, cur, nxt, mask, beta_max=beta_max,
                                             labels=labels, noise_sigma=noise_sigma_dn)
        false += int(np.count_nonzero(fits.accepted))
    if t < MIN_FRAMES:
        raise InputError(f"dry run: {t} frame(s); at least {MIN_FRAMES} are needed (a few seconds of video). "
                         "Fix: record 10 s or more of the view without rain")
    seconds = (t - 2) / frame_rate_hz
    shift, changed = meter.result()
    warnings = []
    if shift > MAX_SHIFT_PX:
        warnings.append(f"the view shifts by {shift:.2f} px per frame (limit {MAX_SHIFT_PX}): the camera or "
                        "scene moves; fix the mount, or enable motion compensation")
    if changed > MAX_CHANGED_FRACTION:
        warnings.append(f"{changed:.1%} of the pixels change between frames n-1 and n+1 more than noise explains "
                        f"(limit {MAX_CHANGED_FRACTION:.0%}): scene motion (foliage, traffic, flicker) will "
                        "cause false detections; point the camera at a still background")
    if seconds < 5:
        warnings.append(f"only {seconds:.1f} s analysed; record 10 s or more for a usable false-detection rate")
    return DryRunResult(
        false_per_minute=false / seconds * 60.0,
        false_streaks=false,
        candidate_fraction=float(np.mean(cand_frac)),
        seconds=seconds,
        n_frames=t,
        shift_px_per_frame=shift,
        changed_fraction=changed,
        threshold_c_dn=float(c_dn),
        warnings=warnings,
    )
