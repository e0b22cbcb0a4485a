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

import numpy as np

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
    import cv2

    frames = np.asarray(frames, dtype=np.float32)
    t, m, n = frames.shape
    window = cv2.createHanningWindow((n, m), cv2.CV_32F)
    limit = 4.0 * math.sqrt(2.0) * max(noise_sigma_dn, 0.5)
    changed = [float(np.mean(np.abs(frames[i + 1] - frames[i - 1]) > limit)) for i in range(1, t - 1)]
    shifts = []
    for i in range(t - 1):
        # phaseCorrelate may apply the window in place: give it copies.
        (dx, dy), _resp = cv2.phaseCorrelate(frames[i].copy(), frames[i + 1].copy(), window)
        shifts.append(math.hypot(dx, dy))
    return float(np.median(shifts)), float(np.mean(changed))


def dry_run(
    frames: np.ndarray,
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
    frames : (T, M, N) uint8 (or float, already linear)
        Rain-free frames from the installed camera.
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

    frames = np.asarray(frames)
    if frames.ndim != 3:
        raise InputError(f"dry run: expected gray frames (T, M, N), got shape {frames.shape}")
    t = frames.shape[0]
    if t < MIN_FRAMES:
        raise InputError(f"dry run: {t} frame(s); at least {MIN_FRAMES} are needed (a few seconds of video). "
                         "Fix: record 10 s or more of the view without rain")
    if frames.dtype == np.uint8 and table is not None:
        lin = np.asarray(table, dtype=np.float32)[frames]
    else:
        lin = frames.astype(np.float32)
    beta_max = beta_max_for_exposure(exposure_s)
    false = 0
    cand_frac = []
    for i in range(1, t - 1):
        mask = candidates(lin[i - 1], lin[i], lin[i + 1], c=c_dn)
        cand_frac.append(float(mask.mean()))
        if not mask.any():
            continue
        labels = label_streaks(mask)
        _accepted, fits = photometric_filter(lin[i - 1], lin[i], lin[i + 1], mask, beta_max=beta_max,
                                             labels=labels, noise_sigma=noise_sigma_dn)
        false += int(np.count_nonzero(fits.accepted))
    seconds = (t - 2) / frame_rate_hz
    shift, changed = scene_motion(lin, noise_sigma_dn=noise_sigma_dn)
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
