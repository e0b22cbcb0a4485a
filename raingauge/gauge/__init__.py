"""raingauge.gauge: the camera rain gauge of Sec. 8 [GargNayar2007].

``RainGauge`` is the streaming instrument (frames in, records out); the
pieces are importable on their own: per-streak measurement
(:mod:`~raingauge.gauge.streaks`), defocus rejection
(:mod:`~raingauge.gauge.rejection`), sample volume
(:mod:`~raingauge.gauge.volume`), its correction by artificial drops in the
frames (:mod:`~raingauge.gauge.completeness`; checked against drops the simulator
renders into the video by :mod:`~raingauge.gauge.fidelity`) and window products
(:mod:`~raingauge.gauge.products`).
"""

from raingauge.gauge.completeness import CompletenessProbe
from raingauge.gauge.gauge import QUALITY_FLAGS, RECORD_KEYS, RainGauge
from raingauge.gauge.products import (
    intensity_class,
    intensity_code,
    poisson_interval,
    rate_interval,
    synop_4680,
    window_products,
)
from raingauge.gauge.rejection import passes_blur, passes_velocity_law, velocity_log_ratio
from raingauge.gauge.streaks import (
    StreakProps,
    change_images,
    detect_streaks,
    measure_streak_table,
    measure_streaks,
    radius_from_width_m,
    spike_image,
    velocity_from_length_m_s,
)
from raingauge.gauge.volume import SampleVolume, effective_area_rate_px2_s, pass_probability

__all__ = [
    "RainGauge", "RECORD_KEYS", "QUALITY_FLAGS", "CompletenessProbe",
    "StreakProps", "change_images", "spike_image", "detect_streaks", "measure_streaks",
    "measure_streak_table",
    "radius_from_width_m", "velocity_from_length_m_s",
    "passes_velocity_law", "passes_blur", "velocity_log_ratio",
    "SampleVolume", "pass_probability", "effective_area_rate_px2_s",
    "window_products", "rate_interval", "poisson_interval",
    "intensity_class", "intensity_code", "synop_4680",
]
