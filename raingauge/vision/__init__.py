"""raingauge.vision: detection and removal of rain in video, Sec. 5 [GargNayar2007].

Frame-stack algorithms, no I/O.  Frames are linearised float arrays in gray
levels, (M, N) per frame and (T, M, N) per stack.
"""

from raingauge.vision.candidates import candidates, hysteresis_candidates, luminance, spike_change
from raingauge.vision.photometric import (
    Streak, StreakFits, beta_max_for_exposure, fit_streaks, label_streaks, photometric_filter,
)
from raingauge.vision.dynamics import (
    ORIENTATIONS_DEG, DynamicsField, RainDynamics, dominant_direction_deg, needle_map, oriented_masks,
    rain_pixel_energies,
)
from raingauge.vision.motion import MOTION_MODELS, MotionTracker, estimate_motion, warp_to
from raingauge.vision.removal import find_runs, remove_rain, replace_single
from raingauge.vision.baselines import MOG2Detector, mog2_derain, temporal_median
from raingauge.vision.pipeline import DerainedFrame, Derainer, derain_clip, detect_streaks, estimate_noise_sigma

__all__ = [
    "candidates", "luminance", "spike_change", "hysteresis_candidates",
    "label_streaks", "photometric_filter", "fit_streaks", "Streak", "StreakFits", "beta_max_for_exposure",
    "ORIENTATIONS_DEG", "oriented_masks", "rain_pixel_energies", "RainDynamics", "DynamicsField",
    "needle_map", "dominant_direction_deg",
    "MOTION_MODELS", "MotionTracker", "estimate_motion", "warp_to",
    "replace_single", "find_runs", "remove_rain",
    "temporal_median", "MOG2Detector", "mog2_derain",
    "detect_streaks", "Derainer", "DerainedFrame", "derain_clip", "estimate_noise_sigma",
]
