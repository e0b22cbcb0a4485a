"""The streaming camera rain gauge (Sec. 8 [GargNayar2007]).

Frames go in one at a time; a record comes out every ``step_s`` seconds over
the last ``window_s`` seconds::

    gauge = RainGauge(profile)
    for i, frame in enumerate(frames):
        for record in gauge.process(frame):
            print(record["rain_rate_mm_h"])
    records = gauge.flush()

Per frame n (analysed when frame n+1 arrives): the spike image of Eq. (19)
(exact in int16 from the 8-bit frames of a linear camera) smoothed along the
fall (the direction follows the measured streaks, so wind-slanted rain is
smoothed along its slant; until drops are counted, the long streaks that passed
the velocity law give it), labelled streaks with pieces merged
(:func:`raingauge.gauge.streaks.detect_streaks`), a cheap size/speed screen
from the labels' boxes, then all screened streaks of the frame measured at
once in closed form (:func:`raingauge.gauge.streaks.measure_streak_table`:
moments, a least-squares box width, end crossings; no iteration and no loop
over streaks; the change I_n - (I_{n-1} + I_{n+1}) / 2 is computed only in
the streaks' boxes) on the change divided by the local contrast E_r - I_b
(Eq. 18: this removes the background's texture from the streak's profile),
the whole-streak test, the velocity-law test, the photometric test of
Eq. (18) where the background has texture, the cross-profile test (a streak
is one positive box across; moving scenery leaves two-signed changes), the
photometric focus test (:mod:`raingauge.gauge.rejection`), and tracks: a
drop seen in an earlier frame (predicted from the image velocity both
sightings measure, over the real time between the frames) continues its
track.  The ``pillbox`` defocus
model keeps the fitted measurement (:class:`raingauge.gauge.streaks.StreakProps`),
which separates blur from width.

Every analysed frame is a snapshot of the sample volume.  Each accepted streak
carries Delta / (kappa(a) A_R (1 - p)) [s m^-3] (:mod:`raingauge.gauge.volume`):
kappa(a) the volume per image pixel in which the tests accept a drop of radius
a in one frame, A_R the area in which its streak lies whole, p the chance that
another streak of the frame touched it (merged or hidden streaks are not
measured).  With the completeness probe (the default) p is in the probe's
correction of kappa: its drops go into the frame with its rain and merge as the
real ones do.  Without it p is :func:`merge_probability` (Poisson coverage from
the frame's measured streak density; in a cross wind the streaks are
parallelograms slanted alike, and their row widths, not their boxes, set the
coverage).  In a cross wind u a
drop crosses each pixel faster and its streak is dimmer by cos(theta),
tan(theta) = u / v(a), to the detection's per-pixel tests; the measurement, on the
rows across the streak, holds the same signal over 1 / cos(theta) as many pixels and
loses sqrt(cos(theta)) of its signal to noise: kappa is the wind's
(:meth:`raingauge.gauge.volume.SampleVolume.in_wind`), as is the model's population
of the drop brightness's reference.  So each frame estimates the density over one frame period
Delta, and a window's rate divides by the frames actually analysed: frames
missing from the stream (``dropped_frames``) leave the rate unbiased, and a
drop accepted in some of the frames that show it whole weighs what kappa says
(counting it once per stream would favour drops with several chances).  The
tracks make the counting statistics (``drops_counted``, the interval) those of
distinct drops.  The accumulation fills gaps of up to :data:`MAX_FILLED_GAP_S`
with the rain of the frames on either side; frames around a longer outage are
not analysed.  A window of counted drops gives the products
(:mod:`raingauge.gauge.products`).  Drops too faint
against the window's background (Eq. 18: beta (E_r - I_b) under the detection
threshold or under twice the noise) are missing from the count: the record
gives the smallest diameter seen (``min_detectable_diameter_mm``), flags
``low_contrast`` and widens the upper limit of the interval by the share of
the rate the hidden drops may carry.  Sizes counted nowhere in the window (their
sample volume under the floor everywhere) are completed: the exponential spectrum
fitted to the sizes seen well is continued into them, and the record's rate, spectrum
and accumulation include it (``completed_share``; :meth:`RainGauge._completion`).
The record takes every drop of its window at the completeness probe's latest
correction, and the accumulation adds each drop so, once, when it is first reported.

Notes
-----
The drop brightness E_r is not known in advance (unless given); it is read
from E_b + 4 Q / (pi w'^2) over the recent law-abiding streaks (defocus only
dims a streak, Eq. 24): a percentile of the samples the focus test keeps,
referenced to the same percentile of the sample volume model's measured focus
(:func:`drop_brightness_dn`).  Until ten such streaks were seen, the
photometric focus test is not applied.  Each streak is measured against the
change beside it (the flanks of
:func:`raingauge.gauge.streaks.measure_streak_table`): in rain, wide faint
drops near the camera over the neighbouring frames shift the change under it.
In frames whose drops have little contrast (``low_contrast``) and whose scene
is still, streaks are detected with hysteresis along the fall
(:func:`raingauge.gauge.streaks.detect_streaks`), so that a streak passing the
threshold only in patches is measured whole; the sample volume of those frames
says so (:class:`raingauge.gauge.volume.SampleVolume` ``grow``).

kappa(a) comes from a model of a streak over a locally uniform background.  A
textured scene breaks streaks where the background's contrast changes, moving
objects hide the rain in front of them from the three-frame test, noise biases
faint streaks, and in heavy rain streaks merge: the completeness probe
(:class:`raingauge.gauge.completeness.CompletenessProbe`) injects artificial
drops of known size and depth into crops of the gauge's own frames, runs them
through the same detection, tests and sizing, and multiplies kappa(a) by the
share of the modelled rain the gauge made of them.  Frames are kept back until
it has its first estimate (at most until the next record).
"""

from __future__ import annotations

import math
from collections import Counter, deque

import numpy as np

from raingauge.errors import InputError
from raingauge.gauge import products as _products
from raingauge.gauge._numeric import clip as _clip
from raingauge.gauge.completeness import CLASS_EDGES_M, CompletenessProbe
from raingauge.gauge.rejection import (
    exposure_area_px2,
    passes_blur,
    change_noise_dn,
    passes_velocity_law,
    photometric_focus,
    streak_errors_px,
    velocity_log_ratio,
)
from raingauge.gauge.streaks import (
    StreakProps,
    detect_streaks,
    fit_batch,
    measure_streak_table,
    spike_image,
    wind_slopes,
)
from raingauge.gauge.volume import (
    BRIGHTNESS_PERCENTILE,
    BRIGHTNESS_PRIOR_MAX_MM_H,
    BRIGHTNESS_PRIOR_RATE_MM_H,
    DEFOCUS_MODELS,
    DETECTION_GROW,
    EDGE_MARGIN_PX,
    SampleVolume,
    background_histogram,
    effective_area_rate_px2_s,
    whole_streak_area_px2,
)

__all__ = ["RainGauge", "RECORD_KEYS", "QUALITY_FLAGS", "merge_probability"]

#: Drop brightness E_r assumed before any drop was measured [gray levels] (an overcast
#: sky seen through the drop, Sec. 4.2.3), only for the ``low_contrast`` flag.
NOMINAL_DROP_BRIGHTNESS_DN = 200.0
#: Brightness samples behind the estimate of E_r before it replaces the nominal one in the
#: ``low_contrast`` flag [-].  The flag turns the detection's hysteresis growth on, which
#: finds the faint streaks the estimate is made of: from 10 samples over a textured wall at
#: 3 gray levels of noise in a 3 m/s wind it read 230 for 200, the frames were taken as
#: clear, the drops were no longer found and the estimate never grew (12 samples and 3
#: drops in a minute of 0.5 mm/h, 0.01 of the rain).
FLAG_BRIGHTNESS_SAMPLES = 100

#: Relative standard uncertainty of the rate beyond the counting statistics, from the
#: validation matrix (benchmarks/bench_gauge_accuracy.py, 60-s clips at 1280x720: the
#: scatter of measured/true left when the counting variance is taken out): 3 % on a dark,
#: still scene; where a window is flagged ``low_contrast`` or ``scene_motion`` it is
#: CONDITION_UNCERTAINTY[0] at a frame noise up to CONDITION_NOISE_DN[0] and
#: CONDITION_UNCERTAINTY[1] from CONDITION_NOISE_DN[1] up, linear between (streaks
#: broken by texture, moving objects and noise are what the sample volume's model and
#: the completeness probe know least well).  Over the 24 flagged clips of each noise
#: (textured, bright and moving scenes, 2-100 mm/h, two spectra) the rms of ln(measured /
#: true) was 4.6 % at noise 1 and 8.1 % at noise 3, 3.0 % and 6.7 % beyond the counting;
#: the values are about twice that, for the scenes the matrix does not hold [-].
BASE_UNCERTAINTY = 0.03
CONDITION_UNCERTAINTY = (0.07, 0.15)
CONDITION_NOISE_DN = (1.5, 2.5)

#: Relative standard uncertainty a cross wind adds (in quadrature) to the rate beyond the
#: counting statistics: the wind clips of the validation matrix (3 m/s on a dark backdrop,
#: 2-100 mm/h, noise 1 and 3, 60-s clips) read 0.88-1.15 of the truth, an rms error of
#: 8.4 %, 7.5 % beyond the counting (0.74-1.18 and 14 % with an earlier probe).  Linear in the drift up to
#: WIND_UNCERTAINTY_M_S, held above it (no stronger wind was validated) [-, m/s].
WIND_UNCERTAINTY = 0.12
WIND_UNCERTAINTY_M_S = 3.0

#: Share of a window's frames that must carry a flag for the window to carry it [-].
FLAG_SHARES = (("overexposed", 0.1), ("underexposed", 0.5), ("scene_motion", 0.2),
               ("lens_obscured", 0.05), ("dropped_frames", 0.0), ("low_contrast", 0.5))


#: Completion of the spectrum below the smallest counted size (:meth:`RainGauge._completion`):
#: drops needed above the fitted size [-], the share of its sample volume over the nominal
#: dark background a size keeps to be fitted [-], and the largest rain the completion adds,
#: relative to the counted rain [-]: more would rest on the extrapolation rather than on
#: the drops, and is clipped to it (the interval's upper end keeps the whole
#: extrapolation).  Left out instead, the rate fell from 1.00 to 0.68 of the truth on one
#: minute of 2 mm/h against a bright sky when the drop brightness moved by 0.3 %.  The slope
#: of 30 drops has a standard error of 18 %, and the completed rain about 2.4 times that
#: (the interval's upper end holds the whole extrapolation); with 100 drops needed, minutes
#: of 0.5 mm/h against a bright sky or a textured wall at 3 gray levels of noise (100-300
#: counted drops, fewer above the fitted size) were not completed, and read 0.55-0.61 of
#: the rain (with 30: 0.67-0.83).
COMPLETION_MIN_DROPS = 30
#: ... completed only where the smallest counted diameter exceeds the smallest measurable
#: one by this factor (over a dark background at 1 gray level of noise it lies 10 % above it,
#: at 3 gray levels 29 %) [-]
COMPLETION_MIN_CUT = 1.15
COMPLETION_FIT_VOLUME = 0.5
COMPLETION_MAX_ADDED = 0.5
#: ... and at most this many times the rain Marshall-Palmer's spectrum holds in the completed
#: sizes beside the counted rain (:meth:`RainGauge._completion_bound`) [-]
COMPLETION_MP_FACTOR = 1.0

#: The completeness probe remembers its injections over this many windows [-].
PROBE_MEMORY_WINDOWS = 1.25
#: Analysed frames between two settings of the probe's effort [-].
PROBE_ADAPT_FRAMES = 30


def condition_uncertainty(quality, noise_dn: float, wind_m_s: float = 0.0) -> float:
    """Relative standard uncertainty of a window's rate beyond its counting statistics [-]
    (:data:`CONDITION_UNCERTAINTY`, :data:`WIND_UNCERTAINTY`): ``quality`` the window's
    flags, ``noise_dn`` the frames' noise [gray levels], ``wind_m_s`` the drops' drift
    across the image [m/s] (either sign)."""
    if not ({"low_contrast", "scene_motion"} & set(quality)):
        u = BASE_UNCERTAINTY
    else:
        lo, hi = CONDITION_NOISE_DN
        x = float(noise_dn) if np.isfinite(noise_dn) else hi
        t = min(max((x - lo) / (hi - lo), 0.0), 1.0)
        u = CONDITION_UNCERTAINTY[0] + t * (CONDITION_UNCERTAINTY[1] - CONDITION_UNCERTAINTY[0])
    wind = abs(float(wind_m_s)) if np.isfinite(wind_m_s) else 0.0
    if wind > 0.0:
        u = math.hypot(u, WIND_UNCERTAINTY * min(wind / WIND_UNCERTAINTY_M_S, 1.0))
    return u


#: Law-abiding streaks needed before the drop brightness E_r is used (by the completeness
#: probe) [-].
MATURE_BRIGHTNESS_SAMPLES = 30

#: Law-abiding streaks needed before the frames' drops are decided (sized and put to the
#: defocus test) with the drop brightness E_r; the frames are kept back until then (at
#: most until the next record).  The rate moves several times as much as the contrast
#: E_r - E_b, and from 30 samples E_r was 6-14 % of the contrast off at 2 mm/h (the first
#: 20 s of a minute against a moving scene read 0.67 of the rain), from 300 within 2 % [-].
DECIDE_BRIGHTNESS_SAMPLES = 300

#: Brightness samples kept for the drop brightness E_r (the latest; in heavy rain most are
#: pieces of defocused drops, and the estimate needs ~100 focused ones) [-].
BRIGHTNESS_SAMPLES = 2000

#: Focus samples of the completeness probe's drops from which their percentile replaces
#: the model's reference q_ref in the drop brightness E_r (:meth:`RainGauge._drop_brightness`) [-].
PROBE_FOCUS_SAMPLES = 400

#: The wind the reference of the drop brightness is taken at is rounded to this step [m/s]
#: (the measured drift wanders by less between the drops counted).
BRIGHTNESS_WIND_STEP_M_S = 0.05

#: Per-pixel signal to noise of a streak's change below which its width and ends scatter
#: beyond the velocity law's tolerance (dark scenes: drops read ~2.3 and are counted;
#: a mid-gray scene at 3 gray levels of noise: ~1.3 and most are lost).
MEASURABLE_SNR = 2.0

#: Largest mean squared residual (in noise units) of a streak's plateau rows against the
#: uniform box across it: drops read 1-4, the two-signed changes of moving scenery 15-600.
MAX_CROSS_CHI2 = 8.0

#: Least length over width of a law-abiding streak whose direction is taken for the rain's
#: while no drop was counted yet [-].
LAW_SLOPE_MIN_ASPECT = 4.0
#: ... and least diameter [m] of the drop whose focused streak (at the focus distance, on
#: the velocity law) is as long as the shortest of them.  The streaks that smoothed noise
#: leaves in a low-contrast scene are as long as a small drop's (15-35 px where a 1-mm
#: drop's is 45 px, of either slant about the vertical: over a textured wall at 3 gray
#: levels, 17 per frame searched along all directions, 1 % of them 40 px or longer);
#: taken with them, the direction of a 3 m/s wind's drops (0.4-0.6 px/px) read 0.1-0.2.
LAW_SLOPE_MIN_DIAMETER_M = 1.0e-3
#: Law-abiding streaks per searched frame and megapixel in the noise's twin of the frames
#: (frame n mirrored about the mean of its neighbours: no rain, as much noise) over which
#: the search's streaks show the direction only from :data:`LAW_SLOPE_MIN_DIAMETER_M` on.
#: Over the textured wall at 3 gray levels ~17 per frame at 1280x720, none at 1; where there are none,
#: the shorter streaks of small drops are kept (in light rain, the long ones are few:
#: at 0.5 mm/h the direction came 20 s later and the rate read 0.6 for 0.87).
SEARCH_NOISE_STREAKS = 0.5

#: The rain's direction in the image is learned from a second detection of a frame, smoothed
#: along all of these directions dx/dy [px/px] (slants of up to 1.5: drops of 0.5 mm and
#: more in cross winds up to about 3 m/s), :data:`~raingauge.gauge.streaks.WIND_SLOPE_STEP`
#: apart (:meth:`RainGauge._search_direction`): on the first :data:`DIRECTION_SEARCH_FRAMES`
#: frames and every :data:`DIRECTION_SEARCH_EVERY`-th after them until
#: :data:`DIRECTION_KNOWN_STREAKS` law-abiding streaks long enough to show the direction
#: (:meth:`RainGauge._shows_direction`) were found so (the search costs several
#: times the frame's own detection: in a dry scene it goes on), then on every
#: :data:`DIRECTION_CHECK_EVERY`-th (the wind turns).  Taken from the frames'
#: own detection, smoothed along one direction, the direction stayed there: a slanted
#: streak smoothed straight down falls apart into short upright pieces, and a faint one is
#: not detected at all.  (The drops are counted from the frames' own detection only, the
#: one the sample volume models: counted from the search's, the completeness probe found
#: 0.5-0.85 of its drops of every size on a dark backdrop.)  At 0.5 mm/h in a 3 m/s wind, 9-11 drops were
#: counted in a minute and the rate read 0.04-0.05 of the truth (over a dark backdrop at 3
#: gray levels of noise, and over a textured wall at 1).
DIRECTION_SEARCH_SLOPES = tuple(float(x) for x in np.arange(-6, 7) * 0.25)
DIRECTION_SEARCH_FRAMES = 30
DIRECTION_SEARCH_EVERY = 5
DIRECTION_CHECK_EVERY = 300
#: Law-abiding streaks of the search after which the direction is known (searched only every
#: :data:`DIRECTION_CHECK_EVERY`-th frame; their drift is then taken from the frames' own
#: detection).  Five give a first direction; among five over a bright sky at 3 gray levels
#: at 0.5 mm/h, three were noise streaks and held the direction at 0.08 where the drops
#: slanted by 0.6.
DIRECTION_KNOWN_STREAKS = 15
#: Probe drops counted in a cross wind, each with its measured over its placed drift,
#: before their median corrects the drift of the counted drops
#: (:meth:`RainGauge._counted_drift`) [-]; the least drift they are taken at [m/s]; and the
#: span the correction is held to [-].
PROBE_DRIFT_MIN_DROPS = 15
PROBE_DRIFT_MIN_M_S = 0.3
PROBE_DRIFT_BIAS_SPAN = (0.8, 1.25)
#: The drift test in a cross wind (:meth:`RainGauge._drift_consistent`): a streak's horizontal
#: motion may fall short of the one the drops' drift gives at the focus distance by this
#: share of it [-] and these pixels [px] (33.6 - 7 px in 3 m/s with the default camera; whole
#: streaks of drops within 3 cm of focus moved 0.89-1.08 of it, 10th to 90th percentile, at
#: 2 mm/h over the bright sky at 3 gray levels); and the counted drops' drifts it needs [-].
DRIFT_TOL_REL = 0.15
DRIFT_TOL_PX = 2.0
DRIFT_TEST_MIN_DROPS = 20

#: The counted drops give the rain's direction and drift unless the search's law-abiding
#: streaks drift otherwise by more than this [m/s] or this share of their drift [-], the
#: larger (their drift is taken at the focus distance and reads 0.7 of the counted drops'
#: at 3 m/s; the slants of both differ with their mix of sizes, u / v(a)).
DIRECTION_DRIFT_AGREEMENT = (1.0, 0.5)

#: Longest span [s] between a frame and either neighbour over which the three-frame test of
#: Eq. (19) is still applied: across a longer outage the scene (light, wet surfaces) may
#: change, so the frames on either side of it are not analysed (and not counted as observed).
MAX_TRIPLE_GAP_S = 1.0

#: Longest gap [s] between analysed frames whose rain is filled into the accumulation from
#: the frames on either side of it; a longer outage is left out of the accumulation (flagged
#: ``dropped_frames``).
MAX_FILLED_GAP_S = 1.0

#: Smallest sample volume, relative to the largest over all sizes (for the same frame), in
#: which a drop is still counted [-]: kappa(a) falls to zero at the ends of the measurable
#: sizes, and a drop sized there (or a false streak sized there) would carry an unbounded
#: weight 1 / kappa (one such streak on a textured scene read 5e8 mm/h).
KAPPA_FLOOR_REL = 0.02

#: The record contract (the keys every record carries, in order).
RECORD_KEYS: tuple[str, ...] = (
    "t_start_s", "t_end_s", "rain_rate_mm_h", "rain_rate_ci95_mm_h", "accumulation_mm",
    "drops_counted", "drops_rejected_defocus", "dsd_d_mm", "dsd_n_m3_mm", "nt_m3", "dm_mm",
    "z_dbz", "intensity_class", "synop_4680", "quality",
)

#: Quality flags a record may carry, and what they mean.
QUALITY_FLAGS: dict[str, str] = {
    "partial_window": "the record covers less than one window (short video or start-up)",
    "too_few_drops": "fewer drops than needed for a stable rate (the interval is wide)",
    "overexposed": "frames with many saturated pixels: drops over bright parts are missed",
    "underexposed": "dark frames: drops are too faint to measure",
    "scene_motion": "strong scene or camera motion: many one-frame changes that are not rain",
    "lens_obscured": "sudden loss of sharpness: water or dirt on the lens",
    "dropped_frames": "gaps in the frame timestamps (the rate is over the frames observed; frames around "
                      "an outage longer than MAX_TRIPLE_GAP_S are not analysed)",
    "no_visible_drops": "no drop size is bright enough against the background to be seen: the rate "
                        "is not measured (the interval has no upper limit)",
    "low_contrast": "drops barely brighter than the background: small drops are missed, the rate reads "
                    "low (the interval's upper limit covers them; see min_detectable_diameter_mm)",
}


_VOLUMES: dict = {}


def _sample_volume(profile, velocity_model: str, defocus_model: str, grow: float = DETECTION_GROW) -> SampleVolume:
    """The sample volume of a profile (computed once per profile and options)."""
    try:
        key = (profile, velocity_model, defocus_model, grow)
        hash(key)
    except TypeError:
        return SampleVolume(profile, velocity_model=velocity_model, defocus_model=defocus_model, grow=grow)
    if key not in _VOLUMES:
        if len(_VOLUMES) > 16:
            _VOLUMES.clear()
        _VOLUMES[key] = SampleVolume(profile, velocity_model=velocity_model, defocus_model=defocus_model, grow=grow)
    return _VOLUMES[key]


def merge_probability(width_px, height_px, other_widths_px, other_heights_px, shape, *,
                      self_included=None, slope: float = 0.0, area_px=None, other_area_px=None) -> np.ndarray:
    """Chance that a streak touches another one in the same frame [-] (Poisson coverage).

    Streaks lie in the frame as a Poisson germ-grain process: with lambda the density of
    streaks and G their shapes, a streak S is touched by none with probability
    exp(-lambda E|S (+) G|) [Hall1988], (+) the Minkowski sum.  For boxes w x h grown by the
    one pixel of 8-connectivity, |S (+) G| = (w_S + w_G + 2)(h_S + h_G + 2), and the frame's
    own streaks measure lambda E|S (+) G| as sum_G |S (+) G| / (M N).  Merged or hidden
    streaks are not measured, so the isolated ones are counted up by 1 / (1 - p).

    Parameters
    ----------
    width_px, height_px : (K,) array_like
        Boxes of the streaks whose chance is wanted [px].
    other_widths_px, other_heights_px : (G,) array_like
        Boxes of the frame's detected streaks (the density) [px].
    shape : (M, N)
        Frame shape [px].
    self_included : (K,) bool array_like, optional
        Whether each streak is itself among the others (its own term is then removed).
    slope : float
        The rain's direction dx/dy [-].  From 0.05 on (a cross wind) the streaks are
        parallelograms, not boxes: with ``area_px`` and ``other_area_px`` (their pixel
        counts) each has its own row width area / h and slant (w - area / h) / h, and two
        of them cover (r_S + r_G + 2)(h_S + h_G + 2) + |s_S - s_G| h_S h_G; without, all
        share the slant ``slope``.
    area_px, other_area_px : (K,), (G,) array_like, optional
        Pixels of the streaks [px].

    Returns
    -------
    (K,) ndarray [-], capped at 0.8 (a frame that crowded measures little)
    """
    ws = np.asarray(width_px, dtype=float)
    hs = np.asarray(height_px, dtype=float)
    wg = np.asarray(other_widths_px, dtype=float)
    hg = np.asarray(other_heights_px, dtype=float)
    M, N = shape
    s = abs(float(slope)) if abs(float(slope)) >= 0.05 else 0.0
    if s and area_px is not None and other_area_px is not None:
        # slanted streaks (the wind) are parallelograms of row width r = area / h slanted by
        # their own |s_i| = (w - r) / h (small drops slant more): the Minkowski sum of two
        # (grown by the pixel of 8-connectivity) has the area
        # (r_S + r_G + 2)(h_S + h_G + 2) + |s_S - s_G| h_S h_G
        hs1, hg1 = np.maximum(hs, 1.0), np.maximum(hg, 1.0)
        rs = _clip(np.asarray(area_px, dtype=float) / hs1, 1.0, np.maximum(ws, 1.0))
        rg = _clip(np.asarray(other_area_px, dtype=float) / hg1, 1.0, np.maximum(wg, 1.0))
        ss = np.maximum(ws - rs, 0.0) / hs1
        sg = np.maximum(wg - rg, 0.0) / hg1
        pair = ((rs[:, None] + rg[None, :] + 2.0) * (hs[:, None] + hg[None, :] + 2.0)
                + np.abs(ss[:, None] - sg[None, :]) * hs[:, None] * hg[None, :])
        total = pair.sum(axis=1)
        if self_included is not None:
            own = np.asarray(self_included, bool)
            total = total - np.where(own, (2.0 * rs + 2.0) * (2.0 * hs + 2.0), 0.0)
        return np.minimum(1.0 - np.exp(-np.maximum(total, 0.0) / float(M * N)), 0.8)
    if s:
        # streaks slanted alike are parallelograms: their Minkowski sum is one whose rows
        # are the sum of their row widths, the box's width less the slant
        ws = np.maximum(ws - s * hs, 1.0)
        wg = np.maximum(wg - s * hg, 1.0)
    ws = ws + 2.0
    hs = hs + 2.0
    n = wg.size
    total = n * ws * hs + ws * hg.sum() + hs * wg.sum() + float(np.sum(wg * hg))
    if self_included is not None:
        own = np.asarray(self_included, bool)
        total = total - np.where(own, (ws + ws - 2.0) * (hs + hs - 2.0), 0.0)
    return np.minimum(1.0 - np.exp(-np.maximum(total, 0.0) / float(M * N)), 0.8)


def drop_brightness_dn(samples_dn, background_dn, *, q_min: float = 0.6, q_ref: float = 1.0,
                       percentile: float = 75.0, iterations: int = 50) -> float:
    """The drop brightness E_r from the streaks that pass the velocity law [gray levels].

    Each law-abiding streak gives E_b + 4 Q / (pi w'^2) = E_b + q' (E_r - E_b)
    (:func:`raingauge.gauge.rejection.photometric_focus`): the drop's contrast over the
    background E_b behind it times its measured photometric focus q' (q <= 1, plus its
    error).  At a trial brightness E the streak's focus is q'(E) = d / (E - E_b) (d the
    sample less its background), and E_r is the E at which the focus of the streaks the
    defocus test would keep has the reference percentile,

        m(E) = P{ q'(E) : q'(E) >= q_min m(E) } = q_ref(E - median E_b),

    with q_ref the same fixed point of the model's distribution of q'
    (:attr:`raingauge.gauge.volume.SampleVolume.brightness_q`: the errors of q' lift the
    percentile above the in-focus q = 1).  In heavy rain many law-abiding detections are
    pieces of defocused drops with q' near 0, and their share would move any fixed
    percentile of all samples; the fixed point takes the percentile of those above the
    test's cut (iterated from the percentile of all of them, the map contracts: raising m
    drops faint samples whose percentile stays below it).  Over a uniform background
    m(E) (E - E_b) is the fixed point D of the contrasts d and E_r = E_b + D / q_ref.  Over
    a textured one each streak is taken against its own background: the streaks seen lie
    mostly over the darker parts (their contrast is larger), and a percentile of the
    contrasts taken against the median background would put E_r too high there by the
    ratio of their contrasts.  E is iterated as E_b + (E - E_b) m(E) / q_ref from the
    uniform background's value (E_b the median; one step over a uniform background).

    Parameters
    ----------
    samples_dn : (n,) array_like
        E_b + 4 Q / (pi w'^2) of each streak [gray levels].
    background_dn : (n,) array_like
        E_b behind each streak [gray levels].
    q_min : float
        Photometric focus of the defocus test [-].
    q_ref : float or callable
        The model's fixed point of the percentile [-]; or that fixed point as a function of
        the contrast E_r - E_b [gray levels] (the errors of q' grow as the contrast falls;
        called with None for a first guess).
    percentile : float
        Percentile P [%].
    iterations : int
        Most fixed-point steps (of the percentile, and of E).

    Returns
    -------
    float
        E_r [gray levels]; NaN without samples.
    """
    x = np.asarray(samples_dn, dtype=np.float64).ravel()
    b = np.asarray(background_dn, dtype=np.float64).ravel()
    ok = np.isfinite(x) & np.isfinite(b)
    x, b = x[ok], b[ok]
    if x.size == 0:
        return float("nan")
    d = x - b
    median_b = float(np.median(b))
    e = _sorted_fixed_point(np.sort(d), q_min, percentile, iterations)
    if not np.isfinite(e):
        return float("nan")
    c = _contrast_of_percentile(e, q_ref)
    if not np.ptp(b) > 0 or not c > 0:
        return median_b + c
    for _ in range(int(iterations)):
        # each streak against its own background (a background within a quarter of the
        # contrast of E, or above it, is taken a quarter of the contrast below it)
        m = _sorted_fixed_point(np.sort(d / np.maximum(median_b + c - b, 0.25 * c)), q_min, percentile,
                                iterations)
        ref = float(q_ref(c)) if callable(q_ref) else float(q_ref)
        c_new = c * m / ref
        if not (np.isfinite(c_new) and c_new > 0):
            break
        if abs(c_new - c) <= 1e-7 * max(c, 1.0):
            c = c_new
            break
        c = c_new
    return median_b + c


def _sorted_fixed_point(s: np.ndarray, q_min: float, percentile: float, iterations: int = 50) -> float:
    """The fixed point D = P{ s : s >= q_min D } of an increasing array ``s`` (each step's
    percentile read off its tail, without sorting again); NaN when empty."""
    if s.size == 0:
        return float("nan")
    e = _percentile_of_sorted(s, 0, percentile)
    for _ in range(int(iterations)):
        lo = int(np.searchsorted(s, q_min * e, side="left"))
        if lo >= s.size:
            break
        e_new = _percentile_of_sorted(s, lo, percentile)
        if abs(e_new - e) <= 1e-4 * max(abs(e), 1.0):
            e = e_new
            break
        e = e_new
    return float(e)


def _contrast_of_percentile(e: float, q_ref) -> float:
    """The model's part of :func:`drop_brightness_dn`: the contrast E_r - E_b from the
    samples' fixed point D = ``e`` and the reference q_ref (a number, or a function of the
    contrast) [gray levels]."""
    if not callable(q_ref):
        return e / float(q_ref)
    # C = e / q(C): q falls slowly with C (the map contracts), a few steps suffice
    c = e / float(q_ref(None))
    for _ in range(20):
        c_new = e / float(q_ref(c))
        if abs(c_new - c) <= 1e-3:
            c = c_new
            break
        c = c_new
    return c


def _law_max_diameter(model: str) -> float:
    """The largest diameter the fall-velocity law ``model`` is defined at [m]."""
    from raingauge.physics.drops import FALL_VELOCITY_RANGES_M

    return float(FALL_VELOCITY_RANGES_M.get(model, (0.0, 7.0e-3))[1])


def _mean_linear(frame: np.ndarray, step: int) -> float:
    """``np.mean(frame[::step, ::step])`` of the frame as linear float32 intensities
    (8-bit frames of a linear camera as ``frame.astype(np.float32)``) [gray levels].

    Float32 sums of 8-bit values are exact while they stay below 2^24, in whatever order
    they are taken: then the mean of the samples' float32 copy is that of the float32
    frame's strided samples, to the bit."""
    sub = frame[::step, ::step]
    if sub.dtype == np.float32:
        return float(np.mean(sub))
    if sub.dtype == np.uint8 and sub.size * 255 < 2 ** 24:
        return float(np.mean(sub.astype(np.float32)))
    return float(np.mean(frame.astype(np.float32)[::step, ::step]))


def _percentile_of_sorted(s: np.ndarray, lo: int, percentile: float) -> float:
    """``np.percentile(s[lo:], percentile)`` of an increasing array (the same linear
    interpolation, in the same arithmetic), without sorting again."""
    n = s.size - lo
    pos = (n - 1) * (float(percentile) / 100.0)
    i = int(math.floor(pos))
    t = pos - i
    a = float(s[lo + i])
    b = float(s[lo + min(i + 1, n - 1)])
    # numpy's lerp: from the nearer end
    return b - (b - a) * (1.0 - t) if t >= 0.5 else a + (b - a) * t


def focus_percentile(q, weights=None, *, q_min: float = 0.6, percentile: float = 75.0,
                     iterations: int = 50) -> float:
    """The fixed point m = P{ q' : q' >= q_min m } of measured photometric focus values q'
    [-] (weighted: the percentile of the weights' distribution, linear between the sorted
    values), the sample counterpart of the model's
    :func:`raingauge.gauge.volume._brightness_percentile_q`; NaN without samples.  With
    equal weights it is the fixed point :func:`drop_brightness_dn` takes of contrasts."""
    q = np.asarray(q, dtype=np.float64).ravel()
    w = np.ones_like(q) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    ok = np.isfinite(q) & np.isfinite(w) & (w > 0)
    q, w = q[ok], w[ok]
    if q.size == 0:
        return float("nan")
    order = np.argsort(q, kind="stable")
    q, w = q[order], w[order]
    cw = np.cumsum(w)

    def pct(lo: int) -> float:
        # the weighted percentile of q[lo:], each sample at the middle of its weight
        c = cw[lo:] - (cw[lo - 1] if lo > 0 else 0.0)
        mid = c - 0.5 * w[lo:]
        return float(np.interp(percentile / 100.0 * c[-1], mid, q[lo:]))

    m = pct(0)
    for _ in range(int(iterations)):
        lo = int(np.searchsorted(q, q_min * m, side="left"))
        if lo >= q.size:
            break
        m_new = pct(lo)
        if abs(m_new - m) <= 1e-5 * max(abs(m), 1.0):
            m = m_new
            break
        m = m_new
    return m


class _SampleRing:
    """The latest ``size`` pairs (E_b, E_r estimate) of law-abiding streaks, in two
    preallocated arrays; ``version`` changes with every addition.  Only order-free
    statistics (percentiles, medians) are taken of them, so the ring is not unrolled."""

    def __init__(self, size: int):
        self._a = np.empty(int(size))
        self._b = np.empty(int(size))
        self._n = 0          # samples held
        self._head = 0       # next slot written
        self.version = 0

    def __len__(self) -> int:
        return self._n

    def extend(self, first, second) -> None:
        first = np.asarray(first, dtype=np.float64).ravel()
        second = np.asarray(second, dtype=np.float64).ravel()
        size = self._a.size
        if first.size > size:
            first, second = first[-size:], second[-size:]
        k = first.size
        if k == 0:
            return
        idx = (self._head + np.arange(k)) % size
        self._a[idx] = first
        self._b[idx] = second
        self._head = int((self._head + k) % size)
        self._n = min(self._n + k, size)
        self.version += 1

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(first, second) of the samples held (in ring order)."""
        return self._a[:self._n], self._b[:self._n]


class _Log(deque):
    """A bounded log of the latest samples whose ``version`` changes with every addition,
    so what is derived from it can be kept until it does."""

    def __init__(self, maxlen: int):
        super().__init__(maxlen=maxlen)
        self.version = 0

    def append(self, x) -> None:
        super().append(x)
        self.version += 1

    def extend(self, xs) -> None:
        super().extend(xs)
        self.version += 1

    def clear(self) -> None:
        super().clear()
        self.version += 1


class RainGauge:
    """A camera rain gauge on a stream of frames.

    Parameters
    ----------
    profile : CameraProfile
        The camera (focal length, focus distance, F-number, exposure, noise, response).
    window_s : float
        Averaging window [s] (default 60).
    step_s : float
        Interval between records [s] (default 10).
    velocity_model : str
        The fall-velocity law of the defocus test (``raingauge.physics.drops.FALL_VELOCITY_MODELS``).
        Default ``"gunn_kinzer"``, the measured law real rain follows [GunnKinzer1949]; the
        paper's v = 200 sqrt(a) (``"paper"``) is the large-drop law, 1.5-2.8 times too fast
        below 0.8 mm, so with it drops under ~1 mm fail the test and the rate reads low.
    clock_start_s : float
        Time of the first frame [s]; records fall on multiples of ``step_s`` after it.
    detection_threshold_dn : float, optional
        c of Eq. (19) [gray levels] (default: the profile's, raised to 1.2 sigma of its noise).
    smooth_px : int
        Length of the along-fall smoothing before detection [px].
    min_drops : int
        Fewer counted drops in a window raise the ``too_few_drops`` flag.
    keep_drops : bool
        Keep every counted drop (``self.drops``) for inspection.
    defocus_model : str
        How defocus shows in a streak: ``"uniform"`` (the paper's Eqs. (23)-(24):
        spread evenly over a wider streak; the velocity law rejects it) or
        ``"pillbox"`` (convolution with the blur circle: soft edges, also bounded
        by a blur test).  See :mod:`raingauge.gauge.volume`.
    overlap_correction : bool
        Count isolated drops up by the chance that a streak of their shape would have
        touched another one in the same frame (merged streaks are not measured;
        :func:`merge_probability`).  Without the completeness probe only: the probe's drops
        meet the frame's rain as the real ones do, and its correction holds the merges.
    volume : SampleVolume, optional
        A precomputed sample volume for this profile and these options.
    drop_brightness_dn : float, optional
        The drop brightness E_r [gray levels] when it is known (a calibrated scene);
        default: estimated from the streaks as they come (:func:`drop_brightness_dn`).
    completeness_probe : bool
        Measure the share of the modelled sample volume the gauge achieves in this scene with
        artificial drops injected into its frames, and correct kappa(a) by it
        (:class:`raingauge.gauge.completeness.CompletenessProbe`; uniform defocus model only).
        Frames are kept back until it has its first estimate (at most until the next record).
    probe_seed : int, optional
        Seed of the completeness probe's random draws (where its drops go, their sizes and
        depths, the rounding of their pixels); default the probe's own.  Two seeds on one
        clip show how much the reading moves with the probe's draws alone.
    """

    def __init__(self, profile, *, window_s: float = 60.0, step_s: float = 10.0,
                 velocity_model: str = "gunn_kinzer", clock_start_s: float = 0.0,
                 detection_threshold_dn: float | None = None, smooth_px: int = 5, min_drops: int = 20,
                 keep_drops: bool = False, defocus_model: str = "uniform",
                 overlap_correction: bool = True, volume: SampleVolume | None = None,
                 drop_brightness_dn: float | None = None, completeness_probe: bool = True,
                 probe_seed: int | None = None):
        from raingauge.gauge import _kernels
        from raingauge.physics.drops import FALL_VELOCITY_MODELS

        # the measurement loops compiled before the first frame (a live camera's frames would
        # wait for it), for the frames it measures (a linear camera's 8-bit ones as they are)
        _kernels.warm_up(frames_8bit=bool(profile.is_linear) and defocus_model == "uniform")
        if velocity_model not in FALL_VELOCITY_MODELS:
            raise ValueError(f"unknown velocity model {velocity_model!r}; valid: {list(FALL_VELOCITY_MODELS)}")
        if not (window_s > 0 and step_s > 0):
            raise ValueError(f"window_s and step_s must be > 0 s, got {window_s!r}, {step_s!r}")
        if step_s > window_s:
            raise ValueError(f"step_s ({step_s} s) must not exceed window_s ({window_s} s)")
        self.profile = profile
        self.window_s = float(window_s)
        self.step_s = float(step_s)
        self.velocity_model = velocity_model
        self.clock_start_s = float(clock_start_s)
        noise = float(profile.noise_sigma_dn)
        self.c = float(detection_threshold_dn if detection_threshold_dn is not None
                       else max(profile.detection_threshold_dn, 1.2 * noise))
        self.smooth_px = int(smooth_px)
        self.min_drops = int(min_drops)
        from raingauge.physics.drops import fall_velocity

        #: least length [px] of the streaks the rain's direction is taken from
        self._law_min_motion_px = float(profile.focal_length_px * profile.exposure_s / profile.focus_distance_m *
                                        fall_velocity(LAW_SLOPE_MIN_DIAMETER_M, model=velocity_model))
        self.noise_change = max(noise, 0.5) * math.sqrt(1.5)
        self._motion_dn = max(30.0, 8.0 * noise)       # a change no raindrop makes [gray levels]
        if defocus_model not in DEFOCUS_MODELS:
            raise ValueError(f"unknown defocus model {defocus_model!r}; valid: {list(DEFOCUS_MODELS)}")
        self.defocus_model = defocus_model
        self.overlap_correction = bool(overlap_correction)
        self._shape = "uniform" if defocus_model == "uniform" else "chord"
        self.volume = volume if volume is not None else _sample_volume(profile, velocity_model, defocus_model)
        # frames whose drops stand out clearly, or with scene motion, are detected without
        # hysteresis, and sampled by the volume that says so
        self._volume_still = (volume if volume is not None or self.volume.grow >= 1.0
                              else _sample_volume(profile, velocity_model, defocus_model, grow=1.0))
        self.keep_drops = keep_drops
        #: the completeness probe (None when off or for the pillbox defocus model)
        probe_kw = {} if probe_seed is None else {"seed": int(probe_seed)}
        self.probe = (CompletenessProbe(profile, self.volume, velocity_model,
                                        memory_s=PROBE_MEMORY_WINDOWS * self.window_s, **probe_kw)
                      if completeness_probe and defocus_model == "uniform" else None)
        # the probe's drops merge with the frame's rain as the real ones do: its correction
        # holds the merges, and the analytic chance of one would count them twice
        self._overlap_on = self.overlap_correction and self.probe is None
        if drop_brightness_dn is not None and not (math.isfinite(drop_brightness_dn) and drop_brightness_dn > 0):
            raise ValueError(f"drop_brightness_dn must be a positive number of gray levels, got {drop_brightness_dn!r}")
        self.fixed_drop_brightness_dn = None if drop_brightness_dn is None else float(drop_brightness_dn)
        self.drops: list[dict] = []
        self._frame_interval = profile.frame_interval_s
        self._buffer: deque = deque(maxlen=3)          # (t, linear frame, frame index)
        self._n_in = 0
        self._reported_mm = 0.0           # accumulation of the drops reported so far [mm]
        self._reported_until = -math.inf
        self._completed_mm = 0.0          # accumulation of the completed spectrum [mm]
        self._completed_until = -math.inf
        self._frames: deque = deque()                   # (t, flags, rejected)
        self._window_drops: deque = deque()             # (t, D, v, weight)
        self._recent: deque = deque()                   # tracks of the drops seen in the last frames
        self._n_tracks = 0
        self._next_boundary = self.clock_start_s + self.step_s
        self._emitted = 0
        self._last_t = None
        self._t_in = None                               # time of the last frame fed
        self._t_decided = None                          # time of the last frame whose drops were counted
        self._prev_counted: list = []                   # the drops of that frame
        self._gaps: deque = deque()                     # (t_before, t_after) of gaps in the frame times
        self._noise_log: deque = deque(maxlen=300)      # noise of the recent frames [gray levels]
        self._n_noise = 0                               # frames logged in it
        self._noise_median = (0, None)                  # (frames logged, median of the log) when last taken
        self._sharpness: deque = deque(maxlen=int(max(10 * profile.frame_rate_hz, 10)))
        self._brightness = _SampleRing(BRIGHTNESS_SAMPLES)   # (E_b, E_b + q' (E_r - E_b)) of law-abiding streaks
        # (q', weight) of the completeness probe's measured drops (their own E_r is known)
        self._probe_focus = _SampleRing(BRIGHTNESS_SAMPLES)
        # rate of the size prior that carries the probe's focus percentile to the rain's
        # (:meth:`_brightness_q_of_contrast`), from the drops counted over the window [mm/h]
        self._prior_rate = BRIGHTNESS_PRIOR_RATE_MM_H
        #: why measured streaks were not counted (diagnostics)
        self.rejections: Counter = Counter()
        self._dilated = None
        self._slopes = _Log(50)                         # streak direction dx/dy of counted drops
        self._drifts = _Log(50)                         # their horizontal speed [m/s] (the wind)
        self._drift_radii = _Log(50)                    # and the radius each was measured at [m]
        # streak directions of the law-abiding streaks, measured before their drops are decided
        # (the rain's direction while the drop brightness E_r is still unknown)
        # (found by the search along all directions, DIRECTION_SEARCH_SLOPES)
        self._law_slopes = _Log(50)
        self._law_drifts = _Log(50)                      # and their drift dx z0 / (f T) [m/s]
        # the probe's counted drops' measured over placed drift, by the class of their measured size
        self._probe_drift_ratios = [_Log(60) for _ in range(len(CLASS_EDGES_M) - 1)]
        self._direction_cache = (None, None)             # (versions of the logs above, their direction)
        self._n_searched = 0                             # frames searched for the direction
        self._n_search_noise = 0                         # and the law-abiding streaks of their noise's twins
        self._n_searched_unknown = 0                     # frames analysed before the direction was known
        self._frame_slope = 0.0                         # the direction the last frame was smoothed along
        self._pending: list = []                        # frames awaiting the E_r estimate
        self._rng = np.random.default_rng(12345)
        self._empty_scale = self._typical_drop_rate()
        # a linear camera: Eq. (19) on the 8-bit frames themselves, exactly, in int16
        self._linear_u8 = bool(profile.is_linear)
        # (the pillbox model's measurement takes the change of float32 frames)
        self._u8_direct = self._linear_u8 and defocus_model == "uniform"
        self._white_dn = float(profile.linearize(np.array([[255]], np.uint8))[0, 0])

    # ------------------------------------------------------------------ public
    def process(self, frame, t_s: float | None = None) -> list[dict]:
        """Feed one frame; return the records whose step boundary has passed.

        Parameters
        ----------
        frame : (M, N) or (M, N, 3) array
            8-bit frame (BGR colour is converted to luminance) of the profile's shape.
        t_s : float, optional
            Capture time of the frame [s] (default ``clock_start_s + index / frame_rate``);
            times must increase.  Pass them when frames may be missing: gaps are found from
            the times, rounded to whole frame periods of the profile's frame rate.
        """
        frame = np.asarray(frame)
        if frame.ndim == 3:
            import cv2

            if frame.shape[2] != 3:
                raise InputError(f"frames must be gray (M, N) or BGR (M, N, 3), got shape {frame.shape}")
            frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        if frame.ndim != 2:
            raise InputError(f"frames must be gray (M, N) or BGR (M, N, 3), got shape {frame.shape}")
        if frame.shape != self.profile.shape:
            raise InputError(
                f"frame shape {frame.shape} does not match the camera profile {self.profile.name!r} "
                f"({self.profile.shape[0]} x {self.profile.shape[1]}); use the profile of the camera "
                f"that recorded the video (profile.replace(width_px=..., height_px=...))")
        if t_s is None:
            t_s = self.clock_start_s + self._n_in / self.profile.frame_rate_hz
        t_s = float(t_s)
        if not math.isfinite(t_s) or (self._t_in is not None and t_s <= self._t_in):
            raise InputError(
                f"frame time t_s = {t_s!r} s does not come after the previous frame's ({self._t_in!r} s); "
                f"frame times must increase: pass each frame's capture time (or none, for "
                f"index / frame rate)")
        if self._t_in is not None and t_s - self._t_in > 1.5 * self._frame_interval:
            self._gaps.append((self._t_in, t_s))
        self._t_in = t_s
        self._n_in += 1
        if self._u8_direct and frame.dtype == np.uint8:
            # a linear camera's 8-bit codes are its linear intensities: the measurement reads
            # them as they are, and a float32 image is made only of the parts used as one
            lin = frame
        else:
            lin = self.profile.linearize(frame)
            if lin.dtype != np.float32:
                lin = lin.astype(np.float32)
        self._buffer.append((t_s, lin, frame if frame.dtype == np.uint8 else lin))
        out: list[dict] = []
        if len(self._buffer) == 3:
            (tp, prev, raw_p), (tc, cur, raw), (tn, nxt, raw_n) = self._buffer
            gap = (tc - tp > 1.5 * self._frame_interval) or (tn - tc > 1.5 * self._frame_interval)
            out.extend(self._emit_until(tc))
            if tc - tp > MAX_TRIPLE_GAP_S or tn - tc > MAX_TRIPLE_GAP_S:
                # the three-frame test across a long outage would compare different scenes:
                # the frame is not analysed and not counted as observed time
                return out
            raws = (raw_p, raw, raw_n) if self._linear_u8 else None
            self._analyse(prev, cur, nxt, raw, tc, gap, raws=raws)
        return out

    def flush(self) -> list[dict]:
        """End of stream: the pending records, then one record over the tail (ending at the
        last frame) when at least half a step has passed since the last record; a stream
        shorter than one window gives one record over what there is, flagged
        ``partial_window``."""
        out: list[dict] = []
        self._resolve_pending()
        if not self._frames:
            return out
        t_end = self._frames[-1][0] + self._frame_interval
        out.extend(self._emit_until(t_end - 1e-9))
        last_end = self._next_boundary - self.step_s
        if self._emitted == 0:
            # one record over what there is; partial unless the stream filled a window
            t0 = self._frames[0][0]
            full = t_end - (t0 - self._frame_interval) >= self.window_s - 2.5 * self._frame_interval
            out.append(self._record(t0, t_end, partial=not full))
            self._emitted += 1
        elif t_end - last_end >= 0.5 * self.step_s:
            # the tail of the stream after the last step: one more record, ending at the last frame
            t0 = max(t_end - self.window_s, self._frames[0][0])
            out.append(self._record(t0, t_end, partial=t_end - t0 < self.window_s - 2.5 * self._frame_interval))
            self._emitted += 1
        return out

    # ---------------------------------------------------------------- analysis
    def _typical_drop_rate(self) -> float:
        """Rate one 1-mm drop per minute would give [mm/h] (scale of an empty window's bound)."""
        a = 0.5e-3
        prof = self.profile
        from raingauge.physics.drops import fall_velocity

        v = float(fall_velocity(2 * a, model=self.velocity_model))
        u = prof.focal_length_px * v / prof.focus_distance_m * prof.exposure_s
        w = 2 * prof.focal_length_px * a / prof.focus_distance_m
        area = float(effective_area_rate_px2_s((0.0, u), w, prof.shape, exposure_s=prof.exposure_s,
                                               frame_interval_s=self._frame_interval))
        kap = float(self.volume.kappa(a))
        if area <= 0 or kap <= 0:
            return 0.0
        weight = 1.0 / (area * kap)
        return 3.6e6 * math.pi / 6 * (2 * a) ** 3 * v * weight / self.window_s

    def _frame_flags(self, raw: np.ndarray, cur: np.ndarray, neighbour_change: np.ndarray,
                     gap: bool) -> set:
        import cv2

        flags = set()
        sub = raw[::4, ::4]
        self._last_mean_bg = _mean_linear(cur, 4)
        e_r = (self._drop_brightness() if self._brightness_known(FLAG_BRIGHTNESS_SAMPLES)
               else NOMINAL_DROP_BRIGHTNESS_DN)
        # a focused streak changes a pixel by ~5 % of the drop's contrast (beta ~ pi w / 4 L)
        if e_r - self._last_mean_bg < 30.0 * self.c:
            flags.add("low_contrast")
        if float(np.mean(sub >= 250)) > 0.05:
            flags.add("overexposed")
        if float(np.mean(sub)) < 12.0:
            flags.add("underexposed")
        # a drop changes a pixel by a fraction beta < 0.1 of its contrast: large changes between
        # the neighbouring frames n-1 and n+1 over many pixels are scene or camera motion
        size = neighbour_change if neighbour_change.dtype.kind == "u" else np.abs(neighbour_change)
        if size.dtype == np.uint8:
            # (integer codes: >= the threshold is >= its ceiling)
            thr = math.ceil(self._motion_dn)
            n_big = cv2.countNonZero(cv2.compare(size, float(thr), cv2.CMP_GE)) if thr <= 255 else 0
        else:
            n_big = np.count_nonzero(size >= self._motion_dn)
        if n_big / size.size > 0.005:
            flags.add("scene_motion")
        half = cur[::2, ::2]
        lap = cv2.Laplacian(cv2.GaussianBlur(half if half.dtype == np.float32 else half.astype(np.float32), (3, 3), 0),
                            cv2.CV_32F)
        sharp = cv2.norm(lap, cv2.NORM_L1) / lap.size
        # (the median is taken only where the frame is under 0.6 of the sharpest: nowhere else
        # can it be under 0.6 of the median)
        if len(self._sharpness) >= 10 and sharp < 0.6 * max(self._sharpness):
            ref = float(np.median(self._sharpness))
            if ref > 1.0 and sharp < 0.6 * ref:
                flags.add("lens_obscured")
        self._sharpness.append(sharp)
        if gap:
            flags.add("dropped_frames")
        return flags

    def _analyse(self, prev, cur, nxt, raw, t, gap, raws=None):
        prof = self.profile
        u8 = raws is not None and all(r.dtype == np.uint8 for r in raws)
        if not u8 and any(a.dtype == np.uint8 for a in (prev, cur, nxt)):
            # 8-bit frames of a linear camera beside float ones: all as linear float32
            prev, cur, nxt = (a.astype(np.float32) if a.dtype == np.uint8 else a for a in (prev, cur, nxt))
        # (8-bit frames: the spike image is summed along the fall as it is taken)
        spike = tuple(raws) if u8 else spike_image(prev, cur, nxt)
        # the change I_n - (I_{n-1} + I_{n+1}) / 2 is computed only where it is used (the
        # frames are 8-bit for a linear camera: the same numbers)
        change = (prev, cur, nxt)
        if u8:
            import cv2

            # a linear 8-bit camera: |I_{n+1} - I_{n-1}| exactly, in 8 bits (only its size is used)
            neighbour_change = cv2.absdiff(raws[2], raws[0])[::2, ::2]
        else:
            neighbour_change = nxt[::2, ::2] - prev[::2, ::2]
        # the noise streaks are measured in: the sensor's and the flicker of rain too faint to
        # detect (Eq. 27); it sets each streak's errors and the frame's sample volume (first:
        # the flags' drop brightness E_r then is the one the streaks are measured with)
        noise = change_noise_dn(*raws) if u8 else change_noise_dn(prev, cur, nxt)   # (8 bits: the same)
        self._frame_noise_change = max(noise, self.noise_change)
        self._noise_log.append(self._frame_noise_change / math.sqrt(1.5))
        self._n_noise += 1
        flags = self._frame_flags(raw, cur, neighbour_change, gap)
        slope = self._rain_slope()
        self._frame_slope = slope
        self._frame_slopes = self._detection_slopes(slope)
        vol = self.sample_volume(flags)
        labels, stats = detect_streaks(spike, c=self.c, smooth_px=self.smooth_px, slope=slope,
                                       slopes=self._frame_slopes, grow=vol.grow)
        rejected = 0
        ref_bg = None
        contrast = None
        probing = (self.probe is not None and self._brightness_known(MATURE_BRIGHTNESS_SAMPLES) and
                   self.probe.due(self._n_in))
        if np.any(stats[1:, 4] > 0) or probing:
            if self.defocus_model == "uniform" and self._brightness_known(10):
                # Eq. (18): a streak changes a pixel by beta (E_r - I_b); dividing by the local
                # contrast removes the background's texture from the streak's profile
                e_r = self._drop_brightness()
                if u8:
                    # the same median from the histogram of the 8-bit sums I_{n-1} + I_{n+1}
                    hist = np.bincount((raws[0][::4, ::4].astype(np.uint16) + raws[2][::4, ::4]).ravel(),
                                       minlength=511)
                    cum = np.cumsum(hist)
                    n_px = int(cum[-1])
                    lo_hi = np.searchsorted(cum, [(n_px - 1) // 2 + 1, n_px // 2 + 1])
                    ref_bg = float(np.float32(0.25) * np.float32(lo_hi[0] + lo_hi[1]))
                else:
                    ref_bg = float(np.median(0.5 * (prev[::4, ::4] + nxt[::4, ::4])))
                c_ref = e_r - ref_bg
                if c_ref > 5.0 * self.c:
                    contrast = (e_r, c_ref)
                else:
                    ref_bg = None
        if np.any(stats[1:, 4] > 0):
            if self.defocus_model == "uniform":
                prepared, rejected = self._measure_table(labels, stats, change, prev, cur, t, ref_bg=ref_bg,
                                                         contrast=contrast)
            else:
                prepared, rejected = self._measure(labels, stats, cur - 0.5 * (prev + nxt), prev, cur, t)
        else:
            prepared = []
        # (of the long ones: a short or blurred streak's axis is ill defined, its moments
        # lean towards the vertical)
        # the drift: from the search until it gave the direction, then from the frame's own
        # detection along it (the search's more sensitive one also finds the faint far drops,
        # whose drift at the focus distance reads low: 1.8-2.5 m/s in 3 m/s)
        own = [c for c in prepared if self._shows_direction(c)]
        known = len(self._law_slopes) >= DIRECTION_KNOWN_STREAKS
        if self.defocus_model != "uniform":
            axial = own
        elif self._direction_search_due():
            axial = self._search_direction(spike, slope, vol, change, prev, cur, t, ref_bg, contrast)
        else:
            axial = []
        self._law_slopes.extend(c["slope"] for c in axial)
        k_drift = prof.focus_distance_m / (prof.focal_length_px * prof.exposure_s)
        self._law_drifts.extend(c["dx"] * k_drift for c in (own if known else axial))
        # the backgrounds E_b behind the streaks (a neighbour frame): the drop sizes they leave
        # visible set this frame's sample volume (raingauge.gauge.volume.SampleVolume.kappa)
        entry = [t, flags, rejected, self._last_mean_bg, background_histogram(prev),
                 self._frame_noise_change / math.sqrt(1.5)]
        for c in prepared:
            c["vol"] = vol
            c["bg_hist"] = entry[4]
            c["noise_dn"] = self._frame_noise_change / math.sqrt(1.5)
        self._frames.append(entry)
        self._pending.append((entry, prepared))
        self._last_t = t
        if probing:
            self._run_probe((prev, cur, nxt), raws if u8 else None, slope, vol, t, (labels, stats, prepared),
                            ref_bg=ref_bg,
                            contrast=contrast, hist=entry[4], noise_dn=self._frame_noise_change / math.sqrt(1.5))
        if self.defocus_model != "uniform" or (self._brightness_known(DECIDE_BRIGHTNESS_SAMPLES) and
                                               (self.probe is None or self.probe.mature)):
            self._resolve_pending()
        if self.probe is not None and self._n_in % PROBE_ADAPT_FRAMES == 0:
            self._adapt_probe(t)

    def _adapt_probe(self, t: float) -> None:
        """Probe as often as the correction's sampling error needs: under half the rest of
        the error of the rate over the last window, its counting error and the base
        uncertainty :data:`BASE_UNCERTAINTY` in quadrature (:meth:`CompletenessProbe.adapt`);
        at the least effort while no drop is counted (nothing to correct)."""
        probe = self.probe
        if not probe.mature:
            probe.adapt(math.nan, math.nan)
            return
        drops = [d for d in self._window_drops if d["t"] >= t - self.window_s - 1e-9]
        share = np.array([d["diameter_m"] ** 3 * d["velocity_m_s"] * d["weight_s_m3"] for d in drops])
        ok = np.isfinite(share) & (share > 0)
        if np.count_nonzero(ok) < self.min_drops:
            probe.interval = probe.every
            return
        share = share[ok]
        self._prior_rate = self._window_prior_rate(t, float(np.sum(share)))
        count_sd = float(np.sqrt(np.sum(share ** 2)) / np.sum(share))
        radius = np.array([0.5 * d["diameter_m"] for d in drops])[ok]
        probe.adapt(probe.rate_relative_sd(radius, share), math.hypot(count_sd, BASE_UNCERTAINTY))

    def _window_prior_rate(self, t: float, volume_sum: float) -> float:
        """The rate of the size prior of the drop brightness (:meth:`_brightness_q_of_contrast`)
        [mm/h]: the rate of the drops counted over the window (``volume_sum``, the sum of
        their D^3 v weight [m/s]), uncorrected, in steps of half an octave (the factor is
        computed once per step), held between :data:`BRIGHTNESS_PRIOR_RATE_MM_H` and
        :data:`BRIGHTNESS_PRIOR_MAX_MM_H`.  Below the first the streaks of the matrix of
        simulated clips needed a factor near the prior's at that rate, not the larger one of
        a lighter prior (at 2 mm/h on a bright sky at noise 3, 1.05 against 1.06 at 10 mm/h
        and 1.09 at 2 mm/h)."""
        n_frames = sum(1 for fr in self._frames if fr[0] >= t - self.window_s - 1e-9)
        if n_frames == 0 or not volume_sum > 0:
            return self._prior_rate
        rate = 3.6e6 * math.pi / 6.0 * volume_sum / (n_frames * self._frame_interval)
        step = 2.0 ** (round(2.0 * math.log2(rate)) / 2.0)
        return float(min(max(step, BRIGHTNESS_PRIOR_RATE_MM_H), BRIGHTNESS_PRIOR_MAX_MM_H))

    def _direction_search_due(self) -> bool:
        """Whether this frame is searched for the rain's direction (:meth:`_search_direction`):
        while it is not known, each of the first :data:`DIRECTION_SEARCH_FRAMES` analysed
        frames and then every :data:`DIRECTION_SEARCH_EVERY`-th; once known
        (:data:`DIRECTION_KNOWN_STREAKS`), every :data:`DIRECTION_CHECK_EVERY`-th."""
        if len(self._law_slopes) >= DIRECTION_KNOWN_STREAKS:
            return self._n_in % DIRECTION_CHECK_EVERY == 0
        self._n_searched_unknown += 1
        return (self._n_searched_unknown <= DIRECTION_SEARCH_FRAMES or
                self._n_in % DIRECTION_SEARCH_EVERY == 0)

    def _search_direction(self, spike, slope, vol, change, prev, cur, t, ref_bg, contrast) -> list:
        """The law-abiding streaks of this frame long enough to show their direction, found by
        a detection smoothed along all directions :data:`DIRECTION_SEARCH_SLOPES` and
        measured (nothing logged): the streaks the rain's direction is learned from
        (:meth:`_rain_slope`).  The frame's own detection, which counts its drops, is the
        one the sample volume models (smoothed along the rain's direction only)."""
        found = self._search_streaks(spike, slope, vol, change, prev, cur, t, ref_bg, contrast)
        # the noise's twin: frame n mirrored about the mean of its neighbours, I'_n = I_{n-1} +
        # I_{n+1} - I_n, changes by -(I_n - (I_{n-1} + I_{n+1}) / 2): the rain (which only
        # brightens, Eq. 19) is gone from it and the noise streaks are as many
        p, c, n = (np.asarray(a, dtype=np.float32) for a in change)
        twin = p + n - c
        noise = self._search_streaks(spike_image(p, twin, n), slope, vol, (p, twin, n), p, twin, t, ref_bg,
                                     contrast)
        self._n_searched += 1
        self._n_search_noise += len(noise)
        return [c for c in found if self._shows_direction(c)]

    def _search_streaks(self, spike, slope, vol, change, prev, cur, t, ref_bg, contrast) -> list:
        """The law-abiding streaks over :data:`LAW_SLOPE_MIN_ASPECT` times as long as wide of a
        detection smoothed along all directions :data:`DIRECTION_SEARCH_SLOPES`."""
        labels, stats = detect_streaks(spike, c=self.c, smooth_px=self.smooth_px, slope=slope,
                                       slopes=DIRECTION_SEARCH_SLOPES, grow=vol.grow)
        if not np.any(stats[1:, 4] > 0):
            return []
        found, _ = self._measure_table(labels, stats, change, prev, cur, t, ref_bg=ref_bg, contrast=contrast,
                                       probe=True)
        return [c for c in found if c["mot"] >= LAW_SLOPE_MIN_ASPECT * c["w_app"]]

    def _noise_streaks(self) -> bool:
        """Whether the search finds noise streaks that pass the velocity law: over
        :data:`SEARCH_NOISE_STREAKS` per searched frame and megapixel in the noise's twin of
        the frames (:meth:`_search_direction`)."""
        mpx = self.profile.width_px * self.profile.height_px * 1e-6
        return self._n_search_noise > SEARCH_NOISE_STREAKS * mpx * self._n_searched

    def _shows_direction(self, c: dict) -> bool:
        """Whether a law-abiding streak is long enough to show the rain's direction: over
        :data:`LAW_SLOPE_MIN_ASPECT` times its width, and, where the search finds noise
        streaks (:meth:`_noise_streaks`), at least as long as the focused streak of a drop
        of :data:`LAW_SLOPE_MIN_DIAMETER_M`."""
        least = LAW_SLOPE_MIN_ASPECT * c["w_app"]
        if self._noise_streaks():
            least = max(least, self._law_min_motion_px)
        return c["mot"] >= least

    def _direction(self) -> tuple[bool, float, float]:
        """(:meth:`_counted_direction`, :meth:`_rain_slope`, :meth:`_wind_m_s`), kept until
        one of the drift and direction logs they are taken from changes (they are asked for
        several times a frame, and each asks for medians of up to 50 samples)."""
        key = (self._slopes.version, self._drifts.version, self._drift_radii.version,
               self._law_slopes.version, self._law_drifts.version,
               tuple(d.version for d in self._probe_drift_ratios))
        if self._direction_cache[0] != key:
            counted = self._find_counted_direction()
            slope = self._find_rain_slope(counted)
            self._direction_cache = (key, (counted, slope, self._find_wind_m_s(counted, slope)))
        return self._direction_cache[1]

    def _counted_direction(self) -> bool:
        """Whether the counted drops give the rain's direction (see
        :meth:`_find_counted_direction`)."""
        return self._direction()[0]

    def _rain_slope(self) -> float:
        """The rain's direction in the image, dx/dy [-] (see :meth:`_find_rain_slope`)."""
        return self._direction()[1]

    def _wind_m_s(self) -> float:
        """The drops' drift across the image [m/s] the sample volume is taken at (see
        :meth:`_find_wind_m_s`)."""
        return self._direction()[2]

    def _find_counted_direction(self) -> bool:
        """Whether the counted drops give the rain's direction (:meth:`_rain_slope`): five
        were counted, and the search's law-abiding streaks do not drift otherwise
        (:data:`DIRECTION_DRIFT_AGREEMENT`) or drift less far.  What either gets wrong
        pulls its drift towards zero: the counted drops' a detection smoothed straight
        down (slanted drops fall apart into upright pieces), the search's the noise
        streaks of a textured scene at 3 gray levels (near upright, of either slant;
        held to them, the drops of a 3 m/s wind over a textured wall read 0.2-0.3 of the
        rain at 10 mm/h)."""
        if len(self._slopes) < 5:
            return False
        if len(self._law_drifts) < 5:
            return True
        law = float(np.median(self._law_drifts))
        counted = float(np.median(self._drifts))
        tol = max(DIRECTION_DRIFT_AGREEMENT[0], DIRECTION_DRIFT_AGREEMENT[1] * abs(law))
        return abs(counted - law) <= tol or abs(counted) >= abs(law)

    def _find_rain_slope(self, counted: bool) -> float:
        """The rain's direction in the image, dx/dy [-], that the detection smooths along
        (``counted``: :meth:`_find_counted_direction`).

        The median direction of the last streaks that passed the velocity law on the frames
        searched along all directions (:data:`DIRECTION_SEARCH_SLOPES`; their drops may
        still wait for the drop brightness E_r), taken from 0.05 on (below it the detection
        smooths straight down anyway); the median of the last counted drops' where they
        agree with them (:meth:`_counted_direction`); 0 until five either were seen.  In a
        cross wind the streaks slant by u / v(a): smoothing straight down, a faint slanted
        streak would not be detected, and the drops it would have counted not be counted
        either."""
        if counted:
            return float(np.median(self._slopes))
        if len(self._law_slopes) >= 5:
            s = float(np.median(self._law_slopes))
            return s if abs(s) >= 0.05 else 0.0
        return 0.0

    def _detection_slopes(self, slope: float):
        """The directions the detection smooths along besides ``slope`` [px/px]: in a cross
        wind those of :func:`raingauge.gauge.streaks.wind_slopes` for the drift the sample
        volume is taken at, so each drop size is smoothed along about its own slant
        u / v(a) (the sample volume's detection assumes it is); None with no wind."""
        wind = self._wind_m_s()
        if wind == 0.0:
            return None
        return wind_slopes(wind, self.volume.rain_velocity_model or self.volume.velocity_model)

    def _find_wind_m_s(self, counted: bool, slope: float) -> float:
        """The drops' drift across the image [m/s] the sample volume is taken at
        (:meth:`raingauge.gauge.volume.SampleVolume.wind_dimming`): the last counted drops'
        (:meth:`_counted_drift`) where their direction is the rain's (:meth:`_rain_slope`), else of
        the law-abiding streaks' at z0 on the searched frames; 0 while the rain falls
        straight down in the image (:meth:`_rain_slope` under 0.05; ``counted`` and ``slope``
        are :meth:`_find_counted_direction`'s and :meth:`_find_rain_slope`'s)."""
        if abs(slope) < 0.05:
            return 0.0
        if counted and len(self._drifts) >= 5:
            return self._counted_drift()
        if len(self._law_drifts) >= 5:
            return float(np.median(self._law_drifts))
        return 0.0

    def _counted_drift(self) -> float:
        """The drops' drift [m/s] from the last counted drops' (five at least): the median of
        their measured drifts, each divided by what the gauge makes of a known drift at its
        measured size (:meth:`_probe_drift_bias`, from the probe's drops, placed with a known
        drift and measured as the real ones are).  A drop's drift is measured as its slant
        times its speed, and its speed at the depth of its measured size: a drop measured
        small reads slow, and drifts slow (0.4 mm drops at 1 gray level read 3 % small and
        drift 2.94 m/s in a 3 m/s wind); and the slant, the regression of x on y over the
        streak's pixels, reads short by the drop's disc (dy^2 / (dy^2 + 12 s^2), s^2 the
        disc's second moment: 5 % for a near drop's streak 6 px wide and 24 px down).
        Placed with the uncorrected drift, the probe's drops slanted less than the rain's and
        were found more often (pinned at 0.4 mm and 2.5 m over the bright sky, 0.41 of them
        against 0.38 of the same drops in the video; 0.379 against 0.377 corrected).
        The correction is the sizes' own, not one for all: the probe spreads its drops
        evenly over the classes, the rain's counted drops are mostly small."""
        drifts = np.asarray(self._drifts, dtype=float)
        ratio = self._probe_drift_bias(np.asarray(self._drift_radii, dtype=float))
        return float(np.median(drifts / ratio))

    def _probe_drift_bias(self, radii) -> np.ndarray:
        """What the gauge makes of a known drift [-] at each measured radius of ``radii`` [m]:
        the median measured over placed drift of the probe's counted drops of that size
        class, where it has :data:`PROBE_DRIFT_MIN_DROPS` of them, else of all of them, else 1;
        held to :data:`PROBE_DRIFT_BIAS_SPAN`."""
        radii = np.asarray(radii, dtype=float)
        lo, hi = PROBE_DRIFT_BIAS_SPAN
        pooled = [r for d in self._probe_drift_ratios for r in d]
        every = float(np.median(pooled)) if len(pooled) >= PROBE_DRIFT_MIN_DROPS else 1.0
        by_class = np.array([float(np.median(d)) if len(d) >= PROBE_DRIFT_MIN_DROPS else every
                             for d in self._probe_drift_ratios])
        k = np.clip(np.searchsorted(CLASS_EDGES_M, radii, side="right") - 1, 0, by_class.size - 1)
        return np.clip(by_class[k], lo, hi)

    def _drift_consistent(self, dx_px) -> np.ndarray:
        """Whether each streak's horizontal motion ``dx_px`` [px] reaches the drops' drift's
        (bool array; all True with no wind, or before :data:`DRIFT_TEST_MIN_DROPS` drops
        were counted in it).

        In a cross wind every drop drifts with the air whatever its size, so a streak's
        horizontal motion is a second measure of its depth and wholeness beside the velocity
        law's: u f T / z for a drop at depth z, whole.  A piece of a faint far drop's streak,
        detected where the noise lifts it, is short and narrow like a near small drop's and
        passes the law, but moves across by the piece's share of the drop's motion.  Over the
        bright sky at 3 gray levels and 2 mm/h in 3 m/s, drops more than 10 cm from focus
        (the probe places drops of radius 0.6 mm within 12 cm of it) gave 37 % of the
        law-abiding streaks, 26 % without wind; theirs moved across 0.43-1.01 of the drift
        (10th to 90th percentile, median 0.68), the whole streaks of drops within 3 cm of
        focus 0.89-1.08.
        Their low focus q' pulled the drop brightness E_r 2-5 gray levels low and the rate
        high.  The test is one-sided: a piece falls short, while a whole streak of a drop
        nearer than focus moves further, u f T / z, and its defocus is the velocity law's
        and the photometric test's to judge, as the model of the sample volume expects (on
        32 clips in 3 m/s, Marshall-Palmer rain of 2-100 mm/h, 28 were within 15 % tested
        one way, 26 both ways, 27 untested).  The drift compared with is the counted drops' measured
        median (the streak's own measure has the same bias); their drifts are logged before
        this test, so it does not feed itself."""
        dx = np.asarray(dx_px, dtype=float)
        if self._wind_m_s() == 0.0 or len(self._drifts) < DRIFT_TEST_MIN_DROPS:
            return np.ones(dx.shape, bool)
        prof = self.profile
        dx_e = float(np.median(self._drifts)) * prof.focal_length_px * prof.exposure_s / prof.focus_distance_m
        with np.errstate(invalid="ignore"):
            return math.copysign(1.0, dx_e) * (dx - dx_e) >= -(DRIFT_TOL_REL * abs(dx_e) + DRIFT_TOL_PX)

    def _run_probe(self, frames, raws, slope, vol, t, frame_streaks, *, ref_bg, contrast, hist,
                   noise_dn) -> None:
        """Inject the completeness probe's artificial drops into crops of this frame, run them
        through the frame's detection, measurement and tests, and log what the gauge makes
        of them (:class:`raingauge.gauge.completeness.CompletenessProbe`).
        ``frame_streaks``: the frame's own (labels, stats, measured streaks).

        Each crop is grown to hold whole the frame's streaks reaching into it
        (:meth:`CompletenessProbe.enlarge`).  A drop merged with streaks of the frame is
        credited with its share of the merged blob: when those streaks were counted alone
        (drops of the rain), the blob is split fairly between them, each with its own part
        and half of what the merge gained or lost, (s_blob - s_streaks + s_drop) / 2, s_drop
        what the drop counts for alone (the model's expectation times the probe's ratio), so
        that over all drops the credits add up to what the gauge counts; otherwise (streaks
        not counted alone are no drops of the sample volume) the drop takes the blob."""
        frame_labels, stats, frame_prepared = frame_streaks
        probe = self.probe
        prof = self.profile
        f = prof.focal_length_px
        e_r = self._drop_brightness()
        # the drops drift with the wind: a slower (smaller) drop slants more.  The drift of
        # the counted drops; until five were counted (the first injections come before any
        # drop is counted: the drops wait for the probe), that of the law-abiding streaks
        if self._counted_direction() and len(self._drifts) >= 5:
            drift = self._counted_drift()
        elif len(self._law_drifts) >= 5 and abs(slope) >= 0.05:
            drift = float(np.median(self._law_drifts))
        else:
            drift = None
        plan = probe.plan(prof.shape, slope, drift_m_s=drift)
        if not plan:
            return
        probe.enlarge(plan, stats, prof.shape)
        lin, raw, centres = probe.canvas(frames, plan, min(e_r, self._white_dn), raws=raws,
                                         delinearize=prof.delinearize, noise_dn=noise_dn, linear=raws is None)
        spike = tuple(raw) if raw is not None else spike_image(*lin)
        lab_c, st_c = detect_streaks(spike, c=self.c, smooth_px=self.smooth_px, slope=slope,
                                     slopes=self._frame_slopes, grow=vol.grow)
        # a drop merged with what the grown crop still cuts (a blob many times its size, a
        # streak the frame's edge cuts) is lost, as it would be in the frame
        st_c = st_c.copy()
        st_c[probe.cut_components(st_c, plan), 4] = 0
        weights = self.volume.histogram_weights(hist, min(e_r, self._white_dn))
        wind = self._wind_m_s()
        floor = self._kappa_floor(weights, vol, wind)
        # what the model expects the gauge to make of each drop: p(a, z) at the contrast
        # behind it, times its share of the rate (2 a)^3 v / kappa(a)
        expected = np.zeros(len(plan))
        p_pass = np.zeros(len(plan))
        kaps = np.atleast_1d(np.asarray(vol.kappa(np.array([p["radius_m"] for p in plan]), weights=weights,
                                                  noise_dn=noise_dn, wind_m_s=wind), dtype=float))
        behinds = []
        for j, p in enumerate(plan):
            x0, y0, cw, ch = p["box"]
            r = int(math.ceil(p["radius_px"]))
            xa = int(round(min(p["p0"][0], p["p1"][0]))) - r
            xb = int(round(max(p["p0"][0], p["p1"][0]))) + r + 1
            behind = frames[0][int(p["p0"][1]):int(p["p1"][1]) + 1, max(xa, 0):xb].astype(np.float32, copy=False)
            if behind.size and float(kaps[j]) >= floor:
                behinds.append((j, min(e_r, self._white_dn) - behind))
        # p over the pixels behind each drop, averaged as kappa averages it over the frame's
        # pixels: the ratio then corrects that kappa and no other model of it
        local = vol.contrast_weights_each([b for _j, b in behinds])
        for (j, _b), w_j in zip(behinds, local):
            p = plan[j]
            p_pass[j] = vol.pass_probability_over(p["radius_m"], p["depth_m"], w_j, noise_dn, wind_m_s=wind)
            expected[j] = p_pass[j] * (2.0 * p["radius_m"]) ** 3 * p["velocity_m_s"] / float(kaps[j])
        # what the gauge makes of each injected drop: its share of the rate,
        # (2 a)^3 v / kappa(a) with a, v and kappa as measured (0 when it is not counted)
        estimate = np.zeros(len(plan))
        # the measured focus of the drops, weighted to drops spread uniformly in log a over
        # the probe's sizes (each class has as many drops, over its own span of log a) and
        # over the depths (each drop stands for the volume (z / f)^2 Z of its depth span)
        e_inj = min(e_r, self._white_dn)
        focus_q, focus_w = [], []
        lo, hi = probe.class_bounds
        span_log = np.log(hi / lo)
        pop_w = (span_log[[p["class"] for p in plan]]
                 * np.array([(p["depth_m"] / f) ** 2 * p["span_m"] for p in plan]))
        def share(c, drift_test=True):
            # the rain share of a measured streak as the gauge counts it (0: not counted)
            if drift_test and not c.get("drift_ok", True):
                return 0.0
            a = self._drop_radius(c, e_r, vol)
            if a is None:
                return 0.0
            kap = float(vol.kappa(a, weights=weights, noise_dn=noise_dn, wind_m_s=wind))
            if not kap >= floor:
                return 0.0
            v = c["mot"] * float(vol.depth_m(a)) / (f * prof.exposure_s)
            return (2.0 * a) ** 3 * v / kap

        def focus_sample(c, j):
            # a measured streak's focus q' against the brightness its drop was drawn with
            if c["photo"] is not None and c["w_app"] >= 2.5 and c.get("drift_ok", True):
                ib, total = c["photo"]
                focus_q.append(4.0 * total / (math.pi * c["w_app"] ** 2) / (e_inj - ib))
                focus_w.append(pop_w[j])

        # the blob each drop lies in (the label most of its axis crosses) and the frame's
        # streaks merged in it (the frame's labels under the blob's pixels)
        blob, partners = probe.blobs(lab_c, st_c, frame_labels, plan)
        merged = np.array([bool(pr) for pr in partners])
        frame_share = {}
        if merged.any():
            by_label = {c["label"]: c for c in frame_prepared if "label" in c}
            for lab in {v for pr in partners for v in pr}:
                frame_share[lab] = share(by_label[lab]) if lab in by_label else 0.0
        ratios = probe.class_ratios()[0] if probe.mature else None
        if np.any(st_c[1:, 4] > 0):
            cx = np.array([c[0] for c in centres])
            cy = np.array([c[1] for c in centres])
            # a streak measured of an unmerged injected drop lies on it (a real drop of frame
            # n is rarely whole and counted within that reach of it)
            reach_y = np.array([0.25 * p["motion_px"] + 2.0 for p in plan])
            reach_x = np.array([p["radius_px"] + 2.0 + 0.25 * abs(p["p1"][0] - p["p0"][0]) for p in plan])
            # only the merged blobs and the labels whose box meets an injected drop's reach
            # can be matched to one: the frame's own streaks in the crops are not measured
            sx, sy = st_c[:, 0:1].astype(float), st_c[:, 1:2].astype(float)
            ex, ey = sx + st_c[:, 2:3], sy + st_c[:, 3:4]
            keep = ((sx <= cx + reach_x) & (ex - 1 >= cx - reach_x)
                    & (sy <= cy + reach_y) & (ey - 1 >= cy - reach_y)).any(axis=1)
            keep[blob[merged]] = True
            # (the 8-bit canvases of a linear camera are the float ones' numbers)
            canvas = raw if raw is not None else lin
            prepared, _ = self._measure_table(lab_c, st_c, canvas, canvas[0], canvas[1], t, ref_bg=ref_bg,
                                              contrast=contrast, probe=True, keep=keep)
            blob_share = {}
            merged_blobs = set(blob[merged].tolist())
            for c in prepared:
                if c["label"] in merged_blobs:
                    blob_share[c["label"]] = blob_share.get(c["label"], 0.0) + share(c)
                    focus_sample(c, int(np.flatnonzero(merged & (blob == c["label"]))[0]))
                    continue
                near = np.flatnonzero((np.abs(cx - c["xc"]) <= reach_x) & (np.abs(cy - c["yc"]) <= reach_y)
                                      & ~merged)
                if near.size == 0:
                    continue
                j = int(near[np.argmin(np.hypot(cx[near] - c["xc"], cy[near] - c["yc"]))])
                focus_sample(c, j)
                s_c = share(c)
                estimate[j] += s_c
                # (logged before the drift test, as the real drops' drifts are)
                if (drift is not None and abs(drift) >= PROBE_DRIFT_MIN_M_S
                        and (s_c > 0 or share(c, drift_test=False) > 0)):
                    # the drift the gauge measures of a drop placed with a known one
                    a_c = self._drop_radius(c, e_r, vol)
                    z_c = float(vol.depth_m(a_c))
                    k_c = int(np.clip(np.searchsorted(CLASS_EDGES_M, a_c, side="right") - 1, 0,
                                      len(self._probe_drift_ratios) - 1))
                    self._probe_drift_ratios[k_c].append(c["dx"] * z_c / (f * prof.exposure_s) / drift)
            for j in np.flatnonzero(merged):
                s_blob = blob_share.get(int(blob[j]), 0.0)
                s_streaks = sum(frame_share[v] for v in partners[j])
                if s_streaks > 0:
                    r = float(ratios[plan[j]["class"]]) if ratios is not None else 1.0
                    s_drop = expected[j] * (r if np.isfinite(r) else 1.0)
                    estimate[j] = 0.5 * (s_blob - s_streaks + s_drop)
                else:
                    estimate[j] = s_blob
        if focus_q:
            self._probe_focus.extend(focus_q, focus_w)
        probe.record(plan, estimate, expected, p_pass, t_s=t)

    def _resolve_pending(self) -> None:
        """Decide the frames kept back until the drop brightness E_r was known well enough."""
        if not self._pending:
            return
        if self.defocus_model == "uniform" and self._brightness_known(10):
            # the drop brightness E_r from the law-abiding streaks (defocus only dims)
            e_r = self._drop_brightness()
        else:
            e_r = float("nan")
        for entry, prepared in self._pending:
            # whole frame periods since the last analysed frame (timestamps jitter; frames drop
            # whole): the first frame of the stream sees every drop as new
            t = entry[0]
            steps = (math.inf if self._t_decided is None
                     else max(int(round((t - self._t_decided) / self._frame_interval)), 1))
            self._t_decided = t
            counted, rejected = self._decide(prepared, e_r, steps=steps)
            entry[2] += rejected
            # the frame before the gap carries the other half of the unobserved periods
            half = self._half_gap(steps)
            for d in self._prev_counted:
                extra = d["accum_base_mm"] * half
                d["accum_mm"] += extra
                if d["t"] < self._reported_until - 1e-9:
                    # (its frame was reported already: the accumulation takes the rest now)
                    self._reported_mm += extra
            self._prev_counted = counted
            for d in counted:
                self._window_drops.append(d)
                if self.keep_drops:
                    self.drops.append(d)
        self._pending.clear()

    def _screen(self, stats, shape=None) -> np.ndarray:
        """Labels worth measuring: whole (in an image of ``shape``, default the frame's), long
        enough, roughly on the velocity law."""
        prof = self.profile
        M, N = prof.shape if shape is None else shape
        x, y, w, h, area = (stats[1:, k].astype(float) for k in range(5))
        whole = (x > EDGE_MARGIN_PX) & (y > EDGE_MARGIN_PX) & (x + w < N - EDGE_MARGIN_PX) & \
                (y + h < M - EDGE_MARGIN_PX)
        width = np.maximum(area / np.maximum(h, 1), 0.5)
        motion = h - width - (self.smooth_px - 1)
        idx = np.flatnonzero(whole & (h >= 6) & (motion > 1) & (area > 0))
        a = width[idx] * prof.focus_distance_m / (2 * prof.focal_length_px)
        # the box estimates read wide (threshold halo, slant): the largest drops' crude size
        # lies beyond the law's largest (in a 3 m/s cross wind area / height read 1.19 times
        # the width of a 5.2-mm drop), where its r is undefined.  Taken at the law's largest
        # size, they are left to the measured width's test
        a = np.minimum(a, 0.5 * _law_max_diameter(self.velocity_model))
        v = np.maximum(motion[idx], 1e-3) * prof.focus_distance_m / (prof.focal_length_px * prof.exposure_s)
        r = velocity_log_ratio(a, v, model=self.velocity_model)
        # accepted drops lie within [-0.75, 0.35] of this crude r; keep a margin
        return idx[np.isfinite(r) & (r > -0.95) & (r < 0.55)] + 1

    def _measure_table(self, labels, stats, change, prev, cur, t, *, ref_bg=None, contrast=None,
                       probe: bool = False, keep=None):
        """Closed-form measurement of all screened streaks of a frame at once
        (:func:`raingauge.gauge.streaks.measure_streak_table`), then the velocity law, the
        photometric test of Eq. (18) and the overlap chance, all as arrays.  With ``probe``
        (the completeness probe's canvas, of the labels' shape) nothing is logged: no
        rejection counts, no brightness samples, no overlap chance.  ``keep`` (bool over the
        labels) limits the measurement to those labels."""
        prof = self.profile
        f = prof.focal_length_px
        z0 = prof.focus_distance_m
        T = prof.exposure_s
        M, N = labels.shape if probe else prof.shape
        from raingauge.physics.streaks import beta_max

        bmax = beta_max(T)
        valid = stats[:, 4] > 0
        sel = self._screen(stats, shape=(M, N))
        if keep is not None:
            sel = sel[np.asarray(keep, bool)[sel]]
        rejections = Counter() if probe else self.rejections
        tab = measure_streak_table(change, labels, stats, sel, valid=valid, cur=cur, prev=prev,
                                   contrast=contrast, noise_sigma=self.noise_change)
        w_app, mot, plat = tab["width_apparent"], tab["motion"], tab["plateau"]
        with np.errstate(all="ignore"):
            measurable = tab["ok"] & np.isfinite(w_app) & np.isfinite(mot) & (mot > 0) & (w_app > 0) & (plat > 0)
        n_unmeas = int(np.count_nonzero(~measurable))
        rejections["unmeasurable"] += n_unmeas
        rejected = n_unmeas
        slope = tab["slope"]
        dx = slope * mot
        yc = 0.5 * (tab["top"] + tab["bottom"])
        xc = tab["xm"] + slope * (yc - tab["ym"])
        half_w = 0.5 * (w_app + np.abs(dx)) + EDGE_MARGIN_PX
        half_h = 0.5 * (w_app + mot) + EDGE_MARGIN_PX
        with np.errstate(all="ignore"):
            clipped = measurable & ((xc - half_w < 0) | (xc + half_w > N - 1) | (yc - half_h < 0) |
                                    (yc + half_h > M - 1))
        rejections["clipped"] += int(np.count_nonzero(clipped))
        live = measurable & ~clipped
        with np.errstate(all="ignore"):
            a_app = w_app * z0 / (2 * f)
            v_app = mot * z0 / (f * T)
            law = np.zeros(live.shape, bool)
            if live.any():
                # each streak's own errors: its signal (back in gray levels where the change
                # was divided by the local contrast) against the noise of the change
                sig_scale = np.ones(live.shape) if contrast is None else np.nan_to_num(
                    np.maximum(contrast[0] - tab["background_dn"], 0.25 * contrast[1]) / contrast[1], nan=1.0)
                noise_ch = getattr(self, "_frame_noise_change", self.noise_change)
                err_w, err_l = streak_errors_px(w_app, mot, plat * sig_scale, noise_ch)
                law[live] = passes_velocity_law(a_app[live], v_app[live], w_app[live], mot[live],
                                                model=self.velocity_model, width_sigma_px=err_w[live],
                                                motion_sigma_px=err_l[live])
        n_law = int(np.count_nonzero(live & ~law))
        rejections["velocity_law"] += n_law
        rejected += n_law
        live &= law
        beta = tab["beta"]
        with np.errstate(all="ignore"):
            eq18 = live & np.isfinite(beta) & ~((beta >= -0.05) & (beta <= bmax + 0.05))
        n18 = int(np.count_nonzero(eq18))
        rejections["photometric_eq18"] += n18
        rejected += n18
        live &= ~eq18
        # a streak's change is one positive box across it (Eqs. 17, 23); moving scenery
        # leaves two-signed changes that fit it badly
        with np.errstate(all="ignore"):
            shapeless = live & ~(tab["chi2"] <= MAX_CROSS_CHI2)
        n_shape = int(np.count_nonzero(shapeless))
        rejections["cross_profile"] += n_shape
        rejected += n_shape
        live &= ~shapeless
        idx = np.nonzero(live)[0]
        if idx.size == 0:
            return [], rejected
        ib = tab["background_dn"][idx] if ref_bg is None else np.full(idx.size, ref_bg)
        total = exposure_area_px2(plat[idx], mot[idx], w_app[idx])
        focused = 4.0 * total / (math.pi * w_app[idx] ** 2)
        # (flagged, not dropped: the direction search and the drift take them all)
        drift_ok = self._drift_consistent(dx[idx])
        if not probe:
            # the brightness samples as the camera saw them, each over its own background:
            # where the change was divided by the local contrast at the E_r of the moment and
            # scaled to C_ref, that is undone (on the mean background under the streak).  Kept
            # scaled, a sample would carry the E_r it was measured with, and over a textured
            # scene, where the streaks seen lie mostly over its darker parts, an E_r too high
            # would lift the samples that estimate it (against a moving scene in light rain
            # the estimate started at 228-260 gray levels for 200 and was still 210 a minute
            # later)
            if contrast is None:
                b_s, d_s = ib, focused
            else:
                b_s = tab["background_dn"][idx]
                with np.errstate(invalid="ignore"):
                    d_s = focused * np.maximum(contrast[0] - b_s, 0.25 * contrast[1]) / contrast[1]
            bright = np.isfinite(b_s) & np.isfinite(d_s) & (w_app[idx] >= 2.5) & drift_ok
            self._brightness.extend(b_s[bright], (b_s + d_s)[bright])
        p_over = (self._overlap_probabilities(labels, valid, tab, idx, stats=stats)
                  if self._overlap_on and not probe else np.zeros(idx.size))
        prepared = []
        for n, k in enumerate(idx):
            prepared.append({"t": t, "w_app": float(w_app[k]), "mot": float(mot[k]), "dx": float(dx[k]),
                             "xc": float(xc[k]), "yc": float(yc[k]), "photo": (float(ib[n]), float(total[n])),
                             "p_overlap": float(p_over[n]), "blur_px": float("nan"),
                             "width_px": float(w_app[k]), "chi2": float(tab["chi2"][k]),
                             "slope": float(slope[k]), "label": int(tab["label"][k]),
                             "drift_ok": bool(drift_ok[n])})
        return prepared, rejected

    def _overlap_probabilities(self, labels, valid, tab, idx, stats=None) -> np.ndarray:
        """For each streak in ``idx``: the chance that another streak of this frame touches it
        (and is merged with it, or hides it) [-], by :func:`merge_probability` over the frame's
        detected streaks (their boxes are the measured density of the Poisson process)."""
        if stats is None:
            import cv2

            stats = cv2.connectedComponentsWithStats((labels > 0).astype(np.uint8), connectivity=8)[2]
            valid = np.ones(stats.shape[0], bool)
        stats = np.asarray(stats)
        box_w = stats[:, 2].astype(float)
        box_h = stats[:, 3].astype(float)
        others = np.asarray(valid, bool).copy()
        others[0] = False
        others &= stats[:, 4] > 0
        area = stats[:, 4].astype(float)
        return merge_probability(box_w[idx], box_h[idx], box_w[others], box_h[others], labels.shape,
                                 self_included=others[idx], slope=self._frame_slope,
                                 area_px=area[idx], other_area_px=area[others])

    def _measure(self, labels, stats, change, prev, cur, t, ref_bg=None):
        prof = self.profile
        f = prof.focal_length_px
        z0 = prof.focus_distance_m
        T = prof.exposure_s
        from raingauge.physics.streaks import beta_max

        bmax = beta_max(T)
        rejected = 0
        valid = stats[:, 4] > 0
        props = [StreakProps(int(lab), stats[lab, :4], change, labels, prof, noise_sigma=self.noise_change,
                             prev=prev, cur=cur, shape=self._shape, valid=valid) for lab in self._screen(stats)]
        # widths of all, then lengths only of those a rough length keeps near the law
        fit_batch(props, shape=self._shape, along=False)
        near = []
        for sp in props:
            w_app = sp.apparent_width_px
            mot = sp.rough_motion_y_px
            if not (np.isfinite(w_app) and np.isfinite(mot) and mot > 0 and w_app > 0):
                near.append(sp)
                continue
            r = float(velocity_log_ratio(w_app * z0 / (2 * f), mot * z0 / (f * T), model=self.velocity_model))
            if np.isfinite(r) and abs(r) > 0.3 + 3.0 / mot:
                rejected += 1
                self.rejections["velocity_law"] += 1
                continue
            near.append(sp)
        props = near
        fit_batch(props, shape=self._shape)
        M, N = prof.shape
        cands = []
        for sp in props:
            w_app = sp.apparent_width_px
            mot = sp.motion_y_px
            plat = sp.row_plateau
            if not (np.isfinite(w_app) and np.isfinite(mot) and mot > 0 and w_app > 0 and plat > 0):
                rejected += 1
                self.rejections["unmeasurable"] += 1
                continue
            dx = sp.axis[2] * mot
            # whole streak, by the fitted geometry
            xc, yc = sp.centroid_px
            half_w = 0.5 * (w_app + abs(dx)) + EDGE_MARGIN_PX
            half_h = 0.5 * (w_app + mot) + EDGE_MARGIN_PX
            if xc - half_w < 0 or xc + half_w > N - 1 or yc - half_h < 0 or yc + half_h > M - 1:
                self.rejections["clipped"] += 1
                continue
            a_app = w_app * z0 / (2 * f)
            v_app = mot * z0 / (f * T)
            if not bool(passes_velocity_law(a_app, v_app, w_app, mot, model=self.velocity_model,
                                            width_sigma_px=sp.width_err_px, motion_sigma_px=sp.motion_err_px)):
                rejected += 1
                self.rejections["velocity_law"] += 1
                continue
            bf = sp.beta_fit
            if bf is not None and not (-0.05 <= bf[0] <= bmax + 0.05):
                rejected += 1
                self.rejections["photometric_eq18"] += 1
                continue
            if self.defocus_model == "pillbox":
                if not bool(passes_blur(sp.blur_px, sp.width_px)):
                    rejected += 1
                    self.rejections["blur"] += 1
                    continue
                cands.append((sp, w_app, mot, dx, xc, yc, None))
                continue
            ib = sp.background_dn if ref_bg is None else ref_bg
            total = float(exposure_area_px2(plat, mot, w_app))
            focused_contrast = 4.0 * total / (math.pi * w_app * w_app)
            if np.isfinite(ib) and w_app >= 2.5:
                self._brightness.extend([float(ib)], [float(ib + focused_contrast)])
            cands.append((sp, w_app, mot, dx, xc, yc, (ib, total)))
        prepared = []
        for sp, w_app, mot, dx, xc, yc, photo in cands:
            p_over = self._overlap_probability(labels, sp) if self._overlap_on else 0.0
            prepared.append({"t": t, "w_app": w_app, "mot": mot, "dx": dx, "xc": xc, "yc": yc,
                             "photo": photo, "p_overlap": p_over, "blur_px": sp.blur_px,
                             "width_px": sp.width_px, "chi2": sp.cross_fit.get("chi2"),
                             "slope": sp.axis[2]})
        return prepared, rejected

    def _decide(self, prepared: list, e_r: float, steps: float = 1) -> tuple[list, int]:
        """Photometric focus, sizes, tracks and weights of one frame's candidates.

        Every analysed frame is a snapshot of the sample volume: a drop whose streak is
        whole in it weighs Delta / (kappa(a) A_R) (A_R the whole-streak area,
        :func:`raingauge.gauge.volume.whole_streak_area_px2`), so each frame's weighted count
        estimates the density over one frame period Delta, whatever the gap before it.
        ``steps`` is the number of frame periods since the last analysed frame (``inf`` for
        the first): the accumulation fills the unobserved periods with this frame's rain.
        """
        prof = self.profile
        f = prof.focal_length_px
        T = prof.exposure_s
        counted = []
        rejected = 0
        # the accumulation fills the unobserved frame periods before this frame, half with
        # its rain, half with the rain of the frame before the gap (trapezoid rule)
        fill = 1.0 + self._half_gap(steps)
        wind = self._wind_m_s()
        if prepared:
            self._prune_tracks(prepared[0]["t"])
        qs = self._photometric_qs(prepared, e_r)
        radii = self._drop_radii(prepared, e_r, qs)
        sized = [k for k, a in enumerate(radii) if a is not None]
        n_photo = len(prepared) - len(sized)
        rejected += n_photo
        self.rejections["defocus_photometric"] += n_photo
        # the sizes' kappa, whole-streak areas, probe corrections and depths, as arrays over
        # the frame's candidates (they share its volume, backgrounds and noise)
        kaps, areas, floors, c_probes, depths = self._decide_arrays([prepared[k] for k in sized],
                                                                    np.array([radii[k] for k in sized]), e_r, wind)
        for n, k in enumerate(sized):
            c, a = prepared[k], radii[k]
            t, w_app, mot, dx, xc, yc = c["t"], c["w_app"], c["mot"], c["dx"], c["xc"], c["yc"]
            kap, area = float(kaps[n]), float(areas[n])
            if not kap >= floors[n] or area <= 0:
                rejected += 1
                self.rejections["no_volume"] += 1
                continue
            c_probe = 1.0
            if self.probe is not None:
                # the share of the modelled volume the probe's drops of this size found
                c_probe = float(c_probes[n])
                kap *= c_probe
            # a drop whose streak touched another one is lost to the merge: count the
            # isolated ones up by the chance of isolation at this streak's size and frame
            area *= 1.0 - c["p_overlap"]
            z = float(depths[n])
            v = mot * z / (f * T)
            weight = 1.0 / (kap * area)
            if not c.get("drift_ok", True):
                # a piece of a far drop's streak (:meth:`_drift_consistent`); its direction
                # and drift are logged all the same, so the drift it was tested against
                # is the one measured without the test
                self._slopes.append(c["slope"])
                self._drifts.append(dx * z / (f * T))
                self._drift_radii.append(a)
                rejected += 1
                self.rejections["drift"] += 1
                continue
            # the same drop seen in an earlier frame continues its track (one drop for the
            # counting statistics); every sighting adds its own snapshot estimate
            track = self._match_track(t, xc, yc, dx, mot, w_app)
            if track != self._n_tracks - 1:
                self.rejections["seen_before"] += 1
            d = {"t": t, "track": track, "x": xc, "y": yc, "ux": dx / T, "uy": mot / T, "w": w_app,
                 "diameter_m": 2 * a,
                 "velocity_m_s": v, "weight_s_m3": weight, "probe_correction": c_probe,
                 "blur_px": c["blur_px"], "width_px": c["width_px"],
                 "apparent_width_px": w_app, "motion_px": mot, "chi2": c["chi2"],
                 "accum_base_mm": 1e3 * math.pi / 6 * (2 * a) ** 3 * v * weight}
            d["accum_mm"] = d["accum_base_mm"] * fill
            self._slopes.append(c["slope"])
            self._drifts.append(dx * z / (f * T))
            self._drift_radii.append(a)
            counted.append(d)
        return counted, rejected

    def _photometric_qs(self, prepared: list, e_r: float) -> list:
        """The photometric focus q of Eq. (18) of each candidate of ``prepared`` with a
        photometric measurement, at once (:func:`photometric_focus` is elementwise: the same
        numbers one by one); None for the others and without a drop brightness."""
        idx = [i for i, c in enumerate(prepared) if c["photo"] is not None]
        qs = [None] * len(prepared)
        if not idx or not np.isfinite(e_r):
            return qs
        ib = np.array([prepared[i]["photo"][0] for i in idx], dtype=float)
        total = np.array([prepared[i]["photo"][1] for i in idx], dtype=float)
        w_app = np.array([prepared[i]["w_app"] for i in idx], dtype=float)
        for i, q in zip(idx, photometric_focus(total, w_app, e_r - ib).tolist()):
            qs[i] = q
        return qs

    def _drop_radii(self, prepared: list, e_r: float, qs: list) -> list:
        """:meth:`_drop_radius` of each candidate of ``prepared`` with its focus ``qs``
        (:meth:`_photometric_qs`), at once where they share one volume (the same numbers)."""
        vols = [c.get("vol", self.volume) for c in prepared]
        if not prepared or any(v is not vols[0] for v in vols):
            return [self._drop_radius(c, e_r, v, q=q) for c, v, q in zip(prepared, vols, qs)]
        vol = vols[0]
        prof = self.profile
        f = prof.focal_length_px
        z0 = prof.focus_distance_m
        out = [None] * len(prepared)
        plain = [k for k, c in enumerate(prepared) if c["photo"] is None]
        if plain:
            w = np.array([prepared[k]["w_app"] for k in plain], dtype=float)
            for k, a in zip(plain, np.asarray(vol.true_radius_m(w * z0 / (2 * f)), dtype=float).tolist()):
                out[k] = a
        focus = [k for k, c in enumerate(prepared) if c["photo"] is not None]
        q = np.array([qs[k] if qs[k] is not None else (
            float(photometric_focus(prepared[k]["photo"][1], prepared[k]["w_app"], e_r - prepared[k]["photo"][0]))
            if np.isfinite(e_r) else 1.0) for k in focus], dtype=float)
        sharp = q >= vol.q_min
        keep = [k for k, ok in zip(focus, sharp.tolist()) if ok]
        if keep:
            w_true = np.array([prepared[k]["w_app"] for k in keep], dtype=float) * np.sqrt(np.minimum(q[sharp], 1.0))
            a0 = w_true * z0 / (2 * f)
            for k, a in zip(keep, (w_true * np.asarray(vol.depth_m(a0), dtype=float) / (2 * f)).tolist()):
                out[k] = a
        return out

    def _drop_radius(self, c: dict, e_r: float, vol, q: float | None = None) -> float | None:
        """The radius a [m] of a measured streak ``c``: the photometric focus q of Eq. (18)
        takes the blur out of its width, and the depth its size is typically seen at sets
        the scale; None when q fails the defocus test.  ``q``: the focus when already taken
        (:meth:`_photometric_qs`)."""
        prof = self.profile
        f = prof.focal_length_px
        z0 = prof.focus_distance_m
        w_app = c["w_app"]
        if c["photo"] is None:
            return float(vol.true_radius_m(w_app * z0 / (2 * f)))
        ib, total = c["photo"]
        if q is None:
            q = float(photometric_focus(total, w_app, e_r - ib)) if np.isfinite(e_r) else 1.0
        if not q >= vol.q_min:
            return None
        w_true = w_app * math.sqrt(min(q, 1.0))
        a0 = w_true * z0 / (2 * f)
        return w_true * float(vol.depth_m(a0)) / (2 * f)

    def sample_volume(self, flags) -> SampleVolume:
        """The sample volume a frame with these quality flags is measured in: the detection
        grows streaks by hysteresis only where the drops' contrast is low (their streaks pass
        the threshold in patches) and the scene is still (moving texture would grow into
        streaks), and each detection has its own volume."""
        grow_here = "low_contrast" in flags and "scene_motion" not in flags
        return self.volume if grow_here else self._volume_still

    @property
    def noise_estimate_dn(self) -> float:
        """The frames' noise the gauge works with now [gray levels]: the median over the
        recent frames of each frame's change noise over sqrt(1.5) (the sensor's noise and
        the flicker of rain too faint to detect, Eq. 27; at least the profile's), as the
        sample volume and the streaks' errors take it; NaN before the first analysed frame."""
        noise = self._median_noise()
        return float("nan") if noise is None else noise

    @property
    def drop_brightness_estimate_dn(self) -> float:
        """The drop brightness E_r the gauge works with now [gray levels]: the given one,
        else the estimate from the streaks so far (:func:`drop_brightness_dn`); NaN before
        10 law-abiding streaks were measured."""
        return self._drop_brightness() if self._brightness_known(10) else float("nan")

    def _brightness_known(self, n_samples: int) -> bool:
        """Whether E_r is given or has at least ``n_samples`` brightness samples behind it."""
        return self.fixed_drop_brightness_dn is not None or len(self._brightness) >= n_samples

    def _brightness_q_of_contrast(self):
        """The reference q_ref of the drop brightness E_r (:func:`drop_brightness_dn`) and a
        key of it.

        The sample volume's q_ref (:meth:`~raingauge.gauge.volume.SampleVolume.brightness_q_at`)
        at the median noise of the recent frames, as a function of the drop contrast [gray
        levels]; once the completeness probe measured :data:`PROBE_FOCUS_SAMPLES` of its
        drops, the same percentile of their measured focus q' (:func:`focus_percentile`;
        their E_r is the one they were drawn with) instead, carried from the probe's
        population of sizes (uniform in log a) to the model's by the model's own ratio
        (:meth:`~raingauge.gauge.volume.SampleVolume.brightness_q_population_factor`, for
        Marshall-Palmer rain of the rate counted over the window, :meth:`_window_prior_rate`;
        the probe's share of small drops is far smaller, and its percentile far steadier).  In
        heavy rain a streak is often lit further by the drops it overlaps, and the streaks'
        percentile rises above the model's (the estimate of E_r from the model's reference
        ran 3-5 % high at 100 mm/h); the probe's drops, overlapping the same rain, rise
        alike."""
        vol = self.volume
        noise = self._median_noise()
        # (in a cross wind the model's populations are the wind's, Marshall-Palmer's and the
        # probe's alike: the wind takes the small drops, which slant most, out of both)
        wind = abs(self._wind_m_s())
        wind = BRIGHTNESS_WIND_STEP_M_S * round(wind / BRIGHTNESS_WIND_STEP_M_S) if np.isfinite(wind) else 0.0
        ring = self._probe_focus
        if self.probe is not None and len(ring) >= PROBE_FOCUS_SAMPLES:
            cached = getattr(self, "_probe_q_cache", None)
            if cached is None or cached[0] != ring.version:
                q, w = ring.arrays()
                self._probe_q_cache = (ring.version, focus_percentile(q, w, q_min=vol.q_min,
                                                                      percentile=BRIGHTNESS_PERCENTILE))
            q_emp = self._probe_q_cache[1]
            span = self.probe.radius_range
            if np.isfinite(q_emp) and q_emp > 0 and np.isfinite(span[0]):
                prior = self._prior_rate
                return ((lambda c: q_emp * vol.brightness_q_population_factor(noise, c, span, prior, wind)),
                        ("probe", ring.version, id(vol), noise, prior, wind))
        return (lambda c: vol.brightness_q_at(noise, c, wind)), (id(vol), noise, wind)

    def _median_noise(self) -> float | None:
        """The median noise of the recent frames [gray levels] (None before the first), taken
        once per frame logged."""
        if not self._noise_log:
            return None
        if self._noise_median[0] != self._n_noise:
            self._noise_median = (self._n_noise, float(np.median(self._noise_log)))
        return self._noise_median[1]

    def _drop_brightness(self) -> float:
        """The drop brightness E_r [gray levels] from the law-abiding streaks' samples
        (:func:`drop_brightness_dn`)."""
        if self.fixed_drop_brightness_dn is not None:
            return self.fixed_drop_brightness_dn
        q_ref, q_key = self._brightness_q_of_contrast()
        # the same samples give the same estimate: computed once per new sample set (the
        # last sample is alive in the deque, so its identity marks the set)
        key = (self._brightness.version, q_key)
        cached = getattr(self, "_brightness_cache", None)
        if cached is not None and cached[0] == key:
            return cached[1]
        backgrounds, samples = self._brightness.arrays()
        e_r = drop_brightness_dn(samples, backgrounds, q_min=self.volume.q_min, q_ref=q_ref,
                                 percentile=BRIGHTNESS_PERCENTILE)
        self._brightness_cache = (key, e_r)
        return e_r

    def _half_gap(self, steps: float) -> float:
        """Half the unobserved frame periods before a frame ``steps`` periods after the last
        analysed one (none for the first frame; at most :data:`MAX_FILLED_GAP_S`) [-]."""
        if not math.isfinite(steps):
            return 0.0
        cap = max(int(round(MAX_FILLED_GAP_S / self._frame_interval)), 1)
        return 0.5 * (min(steps, cap) - 1)

    def _kappa_floor(self, weights, volume=None, wind_m_s: float = 0.0) -> float:
        """:data:`KAPPA_FLOOR_REL` times the largest kappa over the sizes, for a frame's
        contrast weights (None: the volume's nominal contrast) and the wind [m^3/px^2]."""
        vol = self.volume if volume is None else volume
        key = (None if weights is None else id(weights), id(vol), wind_m_s)
        cached = getattr(self, "_kappa_floor_cache", None)
        if cached is None or cached[0] != key or cached[1] is not weights:
            grid = np.geomspace(0.05e-3, 5e-3, 120)
            peak = float(np.nanmax(vol.kappa(grid, weights=weights, wind_m_s=wind_m_s)))
            self._kappa_floor_cache = (key, weights, KAPPA_FLOOR_REL * peak if peak > 0 else math.inf)
        return self._kappa_floor_cache[2]

    def _prune_tracks(self, t: float) -> None:
        """Forget the counted drops that can no longer be whole in a frame at time t [s]
        (their predicted streak has left the frame, or a second has passed)."""
        M = self.profile.shape[0]
        T = self.profile.exposure_s
        keep = deque()
        for r in self._recent:
            dt = t - r["t"]
            if dt > 1.0 or r["y"] + r["mot"] * dt / T - 0.5 * r["mot"] > M:
                continue
            keep.append(r)
        self._recent = keep

    def _match_track(self, t: float, xc: float, yc: float, dx: float, mot: float, w_app: float) -> int:
        """The track of a streak at (xc, yc) [px] of motion (dx, mot) per exposure [px] and
        width w_app [px]: that of a drop seen in an earlier frame (the track moves here), or
        a new one.

        The displacement since the track's last sighting, over the real time between the
        frames (however many were dropped), must match the image motion both streaks measure:
        along the fall within the motion's measurement error (-10 % to +20 % of the length, and
        3 px) scaled by the frames' separation dt / T, and the position error (3 px); across
        it within half the width and the slant's error.  Each track takes at most one streak
        per frame, the closest.
        """
        T = self.profile.exposure_s
        best, best_r = None, 1.0
        for r in self._recent:
            dt = t - r["t"]
            if dt <= 0:
                continue
            s = dt / T
            m = 0.5 * (mot + r["mot"])
            if not 0.6 < (w_app + 1) / (r["w"] + 1) < 1.6:
                continue
            ry = abs(yc - r["y"] - m * s) / (3.0 + (3.0 + 0.2 * m) * s)
            rx = abs(xc - r["x"] - 0.5 * (dx + r["dx"]) * s) / max(2.0, 0.5 * w_app + 1.5 + 0.02 * m * s)
            q = max(rx, ry)
            if q <= best_r:
                best, best_r = r, q
        if best is None:
            self._recent.append({"id": self._n_tracks, "t": t, "x": xc, "y": yc, "dx": dx, "mot": mot,
                                 "w": w_app, "n": 1})
            self._n_tracks += 1
            return self._n_tracks - 1
        n = best["n"]
        best.update(t=t, x=xc, y=yc, dx=(n * best["dx"] + dx) / (n + 1), mot=(n * best["mot"] + mot) / (n + 1),
                    n=n + 1)
        return best["id"]

    def _overlap_probability(self, labels, sp) -> float:
        """Chance that this streak's own pixels, placed at random in this frame, would touch
        another detected streak (and be merged with it) [-]."""
        import cv2

        if self._dilated is None or self._dilated[0] is not labels:
            mask = sp._valid[labels].astype(np.uint8) if sp._valid is not None else (labels > 0).astype(np.uint8)
            self._dilated = (labels, cv2.dilate(mask, np.ones((3, 3), np.uint8)).astype(bool))
        grown = self._dilated[1]
        x0, y0, img, own, other = sp._crop
        ys_o, xs_o = np.nonzero(own)
        if ys_o.size == 0:
            return 0.0
        ys_o -= ys_o.min()
        xs_o -= xs_o.min()
        M, N = labels.shape
        h, w = int(ys_o.max()) + 1, int(xs_o.max()) + 1
        if h >= M or w >= N:
            return 0.0
        k = 24
        oy = self._rng.integers(0, M - h + 1, k)
        ox = self._rng.integers(0, N - w + 1, k)
        hits = grown[oy[:, None] + ys_o[None, :], ox[:, None] + xs_o[None, :]].any(axis=1)
        own_share = ys_o.size * 9.0 / float(M * N)     # a placement onto the streak itself
        return float(min(max(np.mean(hits) - own_share, 0.0), 0.8))

    # ----------------------------------------------------------------- records
    def _emit_until(self, t_now: float) -> list[dict]:
        out = []
        while t_now >= self._next_boundary - 1e-9:
            b = self._next_boundary
            if b - self.clock_start_s >= self.window_s - 1e-9:
                # a record is due: the frames kept back are decided with what is known now
                self._resolve_pending()
                out.append(self._record(b - self.window_s, b))
                self._emitted += 1
            self._next_boundary += self.step_s
        # drop what no future window needs
        horizon = self._next_boundary - self.window_s
        while self._frames and self._frames[0][0] < horizon - 1e-9:
            self._frames.popleft()
        while self._window_drops and self._window_drops[0]["t"] < horizon - 1e-9:
            d = self._window_drops.popleft()
            if d["t"] >= self._reported_until - 1e-9:
                # in no reported window (a step longer than the window): into the accumulation
                self._reported_mm += self._reweighted([d])[0]["accum_mm"]
        while self._gaps and self._gaps[0][1] < horizon - 1e-9:
            self._gaps.popleft()
        return out

    def _reweighted(self, drops: list) -> list:
        """The window's drops with the completeness probe's latest correction: each drop was
        weighted, when its frame was decided, by the correction of the injections up to then;
        the window's rate takes every drop at the correction of all the injections so far,
        which the probe remembers over about a window (copies)."""
        if self.probe is None or not self.probe.mature or not drops:
            return drops
        a = np.array([0.5 * d["diameter_m"] for d in drops])
        now = np.asarray(self.probe.correction(a), dtype=float)
        out = []
        for d, c in zip(drops, now):
            used = d.get("probe_correction", 1.0)
            if c > 0 and used > 0 and c != used:
                d = dict(d, weight_s_m3=d["weight_s_m3"] * used / c, accum_mm=d["accum_mm"] * used / c,
                         accum_base_mm=d["accum_base_mm"] * used / c, probe_correction=float(c))
            out.append(d)
        return out

    def _record(self, t0: float, t1: float, *, partial: bool = False) -> dict:
        frames = [fr for fr in self._frames if t0 - 1e-9 <= fr[0] < t1 - 1e-9]
        drops = self._reweighted([d for d in self._window_drops if t0 - 1e-9 <= d["t"] < t1 - 1e-9])
        duration = len(frames) * self._frame_interval
        quality: list[str] = []
        if partial or duration < self.window_s - 2.5 * self._frame_interval:
            quality.append("partial_window")
        completion = None
        if duration <= 0:
            prod = _products.window_products([], [], [], 1.0)
            prod["rain_rate_ci95_mm_h"] = [0.0, float("nan")]
        else:
            dd = [d["diameter_m"] for d in drops]
            vv = [d["velocity_m_s"] for d in drops]
            ww = [d["weight_s_m3"] for d in drops]
            completion = self._completion(frames, drops, duration)
            if completion is not None:
                dd += list(completion["diameter_m"])
                vv += list(completion["velocity_m_s"])
                ww += list(completion["weight_s_m3"])
            prod = _products.window_products(dd, vv, ww, duration,
                                             empty_scale_mm_h=self._empty_scale * self.window_s / duration)
        n_frames = max(len(frames), 1)
        frame_flags = [flag for flag, share in FLAG_SHARES
                       if sum(1 for fr in frames if flag in fr[1]) > share * n_frames]
        # the rate's relative standard uncertainties: its counting statistics, the completeness
        # probe's sampling and the scatter the validation found in the window's conditions
        rsd = {"counting": None, "probe": None, "conditions": None}
        if drops and duration > 0:
            # a drop seen in several frames adds a snapshot estimate from each: the counting
            # statistics are those of the distinct drops (tracks), each with its summed share
            tracks = np.unique([d["track"] for d in drops], return_inverse=True)[1]
            share = np.array([d["diameter_m"] ** 3 * d["velocity_m_s"] * d["weight_s_m3"] for d in drops])
            ok = np.isfinite(share) & (share > 0)
            per_drop = np.bincount(tracks[ok], 3.6e6 * math.pi / 6 * share[ok] / duration)
            # beyond the counting: the scatter the validation found in this window's
            # conditions, and the completeness probe's own sampling error
            noises = [fr[5] for fr in frames if len(fr) > 5 and np.isfinite(fr[5])]
            systematic = condition_uncertainty(frame_flags, float(np.median(noises)) if noises else float("nan"),
                                               self._wind_m_s())
            counted_rate = per_drop[per_drop > 0]
            rsd["conditions"] = systematic
            rsd["counting"] = (float(np.sqrt(np.sum(counted_rate ** 2)) / np.sum(counted_rate))
                               if counted_rate.size else None)
            if self.probe is not None:
                probe_sd = self.probe.rate_relative_sd([0.5 * d["diameter_m"] for d in drops], share)
                systematic = math.hypot(systematic, probe_sd)
                rsd["probe"] = float(probe_sd)
            lo, hi = _products.rate_interval(per_drop[per_drop > 0],
                                             empty_scale=self._empty_scale * self.window_s / duration,
                                             systematic_rel=systematic)
            if completion is not None:
                # the completed rain rests on the spectrum's shape: the interval runs from the
                # counted rain's lower limit to the upper one of the counted rain with the
                # whole extrapolation (also where the completion was clipped)
                full = prod["rain_rate_mm_h"] + completion["extrapolated_rate_mm_h"] - completion["rate_mm_h"]
                hi *= full / max(float(per_drop.sum()), 1e-300)
            prod["rain_rate_ci95_mm_h"] = [lo, hi]
            prod["drops_counted"] = int(np.count_nonzero(per_drop > 0))
        rate = prod["rain_rate_mm_h"]
        counted = prod["drops_counted"]
        if 0 < counted < self.min_drops or (counted == 0 and duration <= 0):
            quality.append("too_few_drops")
        quality += frame_flags
        if "dropped_frames" not in quality and any(a < t1 - 1e-9 and b > t0 + 1e-9 for a, b in self._gaps):
            # frames missing in the window, analysed or not (the rate counts only the time
            # observed; a long outage is not analysed at all)
            quality.append("dropped_frames")
        # drops too faint to be detected against this background (Eq. 18: a focused streak
        # changes a pixel by beta (E_r - I_b)) are missing from the rate: the upper limit
        # covers the share of the rate they may carry
        d_det, miss = self._missed_share(frames, rate)
        lo_hi = list(prod["rain_rate_ci95_mm_h"])
        if miss > 0.0 and lo_hi[1] is not None and np.isfinite(lo_hi[1]):
            floor = self._empty_scale * self.window_s / max(duration, self._frame_interval)
            lo_hi[1] = max(lo_hi[1], floor) / max(1.0 - miss, 1e-3)
            if miss >= 1.0:
                # no drop size is visible against this background (for the drop brightness
                # assumed or measured): the rate has no upper limit
                lo_hi[1] = float("nan")
                if counted == 0:
                    quality.append("no_visible_drops")
            prod["rain_rate_ci95_mm_h"] = lo_hi
            if miss > 0.1 and "low_contrast" not in quality:
                quality.append("low_contrast")
        cls = _products.intensity_class(rate)

        def num(x):
            return None if x is None or not np.isfinite(x) else float(x)

        return {
            "t_start_s": float(t0),
            "t_end_s": float(t1),
            "rain_rate_mm_h": float(rate),
            "rain_rate_ci95_mm_h": [num(v) for v in prod["rain_rate_ci95_mm_h"]],
            "accumulation_mm": float(self._reported_accumulation(t1) +
                                     self._completed_accumulation(t0, t1, completion, partial)),
            "drops_counted": int(counted),
            "drops_rejected_defocus": int(sum(fr[2] for fr in frames)),
            "dsd_d_mm": prod["dsd_d_mm"],
            "dsd_n_m3_mm": prod["dsd_n_m3_mm"],
            "nt_m3": float(prod["nt_m3"]),
            "dm_mm": num(prod["dm_mm"]),
            "z_dbz": num(prod["z_dbz"]),
            "intensity_class": cls,
            "synop_4680": _products.synop_4680(rate, prod["dm_mm"]),
            "quality": quality,
            # beyond the contract: the other disdrometer moments
            "nw_mm1_m3": num(prod["nw_mm1_m3"]),
            "lwc_g_m3": float(prod["lwc_g_m3"]),
            "ke_flux_j_m2_h": float(prod["ke_flux_j_m2_h"]),
            "z_mm6_m3": float(prod["z_mm6_m3"]),
            "min_detectable_diameter_mm": num(1e3 * d_det),
            "completed_share": 0.0 if completion is None else float(completion["rate_mm_h"] / rate),
            "rain_rate_counting_rsd": num(rsd["counting"]),
            "rain_rate_probe_rsd": num(rsd["probe"]),
            "rain_rate_conditions_rsd": num(rsd["conditions"]),
        }

    def _completed_accumulation(self, t0: float, t1: float, completion, partial: bool) -> float:
        """The accumulation the spectrum's completion added up to t1 [mm]: each stretch of
        time once, at the completed rain of the first full window reported over it."""
        if completion is not None and not partial:
            start = max(self._completed_until, t0)
            if t1 > start:
                self._completed_mm += completion["rate_mm_h"] * (t1 - start) / 3600.0
                self._completed_until = t1
        return self._completed_mm

    def _completion(self, frames, drops, duration: float):
        """The rain of the sizes the window's frames leave uncounted, from the spectrum of the
        counted ones; None where every measurable size is counted.

        A size is counted where its sample volume over the window's backgrounds (their
        contrast histogram, noise and the wind) stays above the floor
        (:data:`KAPPA_FLOOR_REL`); against a bright sky at 3 gray levels of noise the
        smallest counted diameter is 0.7-1 mm, and the sizes below it carry 5-30 % of the
        rain (Marshall-Palmer at 30-2 mm/h).  The counted drops of the sizes that keep at
        least :data:`COMPLETION_FIT_VOLUME` of the volume they have over the nominal dark
        background (:meth:`SampleVolume.visible_fraction`) fix the slope Lambda of an
        exponential spectrum N(D) = N_f Lambda exp(-Lambda (D - D_f)) (the maximum
        likelihood estimate of the truncated exponential: 1 / Lambda is the density-weighted
        mean of D - D_f; N_f their density), which is continued down to the smallest
        measurable diameter.  Marshall-Palmer spectra are exponential; a gamma spectrum of
        mu = 3 holds fewer small drops than its continued tail, and its completion adds
        about a third more than the missing rain (12.5 % of the rain below 0.75 mm at
        2 mm/h, completed as 17 %).

        The completion adds at most :data:`COMPLETION_MAX_ADDED` of the counted rain (the
        spectrum's density scaled down to it); ``extrapolated_rate_mm_h`` is what the
        continued spectrum holds in full.

        Returns
        -------
        None, or a dict: ``diameter_m, velocity_m_s, weight_s_m3`` arrays of the completed
        sizes as entries of the window (``weight_s_m3`` = density x duration), their
        ``rate_mm_h`` (as added), ``extrapolated_rate_mm_h``, the fitted ``lambda_per_mm``
        and the smallest counted ``d_cut_m``.
        """
        from raingauge.physics.drops import fall_velocity

        hists = [fr[4] for fr in frames if len(fr) > 4 and fr[4] is not None]
        if self.defocus_model != "uniform" or not hists or not drops or not self._brightness_known(10):
            return None
        e_r = min(self._drop_brightness(), self._white_dn)
        flags = [flag for flag, share in FLAG_SHARES if sum(1 for fr in frames if flag in fr[1]) > share * len(frames)]
        vol = self.sample_volume(flags)
        weights = vol.histogram_weights(np.sum(hists, axis=0), e_r)
        noises = [fr[5] for fr in frames if len(fr) > 5 and np.isfinite(fr[5])]
        noise = float(np.median(noises)) if noises else None
        wind = self._wind_m_s()
        d_min = 2.0 * float(vol.min_radius_m)
        grid = np.geomspace(d_min, 8e-3, 160)
        kap = np.nan_to_num(np.asarray(vol.kappa(0.5 * grid, weights=weights, noise_dn=noise, wind_m_s=wind),
                                       dtype=float))
        counted = kap >= self._kappa_floor(weights, vol, wind)
        if not counted.any():
            return None
        d_cut = float(grid[np.argmax(counted)])
        if d_cut <= COMPLETION_MIN_CUT * d_min:
            # (the volume falls to zero at the smallest measurable size on any background)
            return None
        best = np.nan_to_num(np.asarray(vol.kappa(0.5 * grid), dtype=float))
        well = counted & (kap >= COMPLETION_FIT_VOLUME * best)
        if not well.any():
            return None
        d_fit = max(float(grid[np.argmax(well)]), d_cut)
        d = np.array([x["diameter_m"] for x in drops])
        rho = np.array([x["weight_s_m3"] for x in drops]) / duration
        sel = np.isfinite(d) & np.isfinite(rho) & (rho > 0) & (d >= d_fit)
        if np.count_nonzero(sel) < COMPLETION_MIN_DROPS:
            return None
        n_fit = float(rho[sel].sum())
        mean_excess = float(np.sum(rho[sel] * (d[sel] - d_fit))) / n_fit
        if not mean_excess > 0:
            return None
        lam = 1.0 / mean_excess                                          # [1/m]
        edges = np.linspace(d_min, d_cut, 25)
        dc = 0.5 * (edges[1:] + edges[:-1])
        dens = n_fit * lam * np.exp(-lam * (dc - d_fit)) * np.diff(edges)     # [m^-3]
        v = np.nan_to_num(np.asarray(fall_velocity(dc, model=self.velocity_model), dtype=float), nan=0.0)
        rate = float(3.6e6 * math.pi / 6.0 * np.sum(dc ** 3 * v * dens))
        counted_rate = float(3.6e6 * math.pi / 6.0 * np.sum(
            np.array([x["diameter_m"] ** 3 * x["velocity_m_s"] for x in drops]) * rho))
        if not (rate > 0 and counted_rate > 0):
            return None
        # more than COMPLETION_MAX_ADDED of the counted rain is clipped to it (a step from
        # all of it to none would make the rate jump with the smallest change of the fit),
        # and more than Marshall-Palmer's share of the sizes to it
        bound = self._completion_bound(counted_rate, d_min, d_cut)
        scale = min(1.0, COMPLETION_MAX_ADDED * counted_rate / rate, bound / rate)
        return {"diameter_m": dc, "velocity_m_s": v, "weight_s_m3": dens * duration * scale,
                "rate_mm_h": rate * scale, "extrapolated_rate_mm_h": rate,
                "lambda_per_mm": 1e-3 * lam, "d_cut_m": d_cut, "bound_mm_h": bound}

    def _completion_bound(self, counted_rate: float, d_min: float, d_cut: float) -> float:
        """The most rain the completion adds [mm/h]: :data:`COMPLETION_MP_FACTOR` times what
        the Marshall-Palmer spectrum that holds the completed rate (the counted rain
        ``counted_rate`` [mm/h] above ``d_cut`` [m] and this between ``d_min`` and it, at the
        gauge's velocity law) holds between ``d_min`` and ``d_cut``.

        Natural spectra hold no more small drops than Marshall-Palmer's exponential, most of
        them fewer (gamma spectra of mu > 0, the real Parsivel minutes), while an exponential
        continued from the sizes whose sample volume is smallest and least certain can hold
        far more: over the bright sky at 3 gray levels in a 3 m/s wind, counted from 1.07 mm
        on in gamma rain of 10 mm/h, the continued slope of 3.1 /mm put 4.3 mm/h below the
        cut, where the clip holds 1.05 and Marshall-Palmer 1.9.  (The nominal rate of
        Marshall-Palmer's Lambda = 4.1 R^-0.21 /mm is found so that its spectrum holds the
        completed rate: it does not close, and at 10 mm/h holds 11.7 mm/h.)"""
        from raingauge.physics.drops import MarshallPalmer, fall_velocity

        # (midpoints of 100 classes below the cut and 300 above it)
        edges = np.concatenate([np.linspace(d_min, d_cut, 101), np.linspace(d_cut, 8e-3, 301)[1:]])
        d = 0.5 * (edges[1:] + edges[:-1])
        w = 3.6e6 * math.pi / 6.0 * d ** 3 * np.nan_to_num(
            np.asarray(fall_velocity(d, model=self.velocity_model), dtype=float)) * np.diff(edges)
        below = np.arange(d.size) < 100
        if not counted_rate > 0:
            return 0.0
        nominal, bound = counted_rate, 0.0
        for _ in range(8):
            rain = w * MarshallPalmer.N0_M4 * np.exp(-MarshallPalmer.LAMBDA_COEFF_M * nominal ** -0.21 * d)
            above = float(rain[~below].sum())
            if not above > 0:
                return 0.0
            bound = counted_rate * float(rain[below].sum()) / above
            step = (counted_rate + bound) / float(rain.sum())
            nominal *= step
            if abs(step - 1.0) < 1e-4:
                break
        return COMPLETION_MP_FACTOR * bound

    def _decide_arrays(self, cands: list, radii: np.ndarray, e_r: float, wind: float):
        """For candidates of sizes ``radii`` [m] (:meth:`_decide`): their kappa at their frame's
        backgrounds and noise, whole-streak areas per frame period, the kappa floor, the
        probe's corrections (1 without the probe) and the mean depths; one array each, taken
        together where the candidates share their frame's volume, backgrounds and noise (the
        same numbers as one at a time)."""
        prof = self.profile
        n = len(cands)
        if n == 0:
            return (np.zeros(0),) * 5
        vols = [c.get("vol", self.volume) for c in cands]
        weights = [self._frame_weights(c, e_r) for c in cands]
        noises = [c.get("noise_dn") for c in cands]
        shared = all(v is vols[0] for v in vols) and all(w is weights[0] for w in weights) and \
            all(x == noises[0] or (x is None and noises[0] is None) for x in noises)
        if shared:
            vol = vols[0]
            kaps = np.asarray(vol.kappa(radii, weights=weights[0], noise_dn=noises[0], wind_m_s=wind), dtype=float)
            floors = np.full(n, self._kappa_floor(weights[0], vol, wind))
            depths = np.asarray(vol.depth_m(radii), dtype=float)
        else:
            kaps = np.array([float(v.kappa(a, weights=w, noise_dn=x, wind_m_s=wind))
                             for v, w, x, a in zip(vols, weights, noises, radii.tolist())])
            floors = np.array([self._kappa_floor(w, v, wind) for v, w in zip(vols, weights)])
            depths = np.array([float(v.depth_m(a)) for v, a in zip(vols, radii.tolist())])
        motion = np.array([(c["dx"], c["mot"]) for c in cands], dtype=float)
        areas = np.asarray(whole_streak_area_px2(motion, np.array([c["w_app"] for c in cands], dtype=float),
                                                 prof.shape), dtype=float) / self._frame_interval
        c_probes = (np.ones(n) if self.probe is None
                    else np.asarray(self.probe.correction(radii), dtype=float))
        return kaps, areas, floors, c_probes, depths

    def _frame_weights(self, c: dict, e_r: float):
        """Contrast weights of the frame of candidate ``c`` (:meth:`SampleVolume.histogram_weights`),
        cached per frame; None (the volume's nominal contrast) without a drop brightness."""
        hist = c.get("bg_hist")
        if hist is None or not np.isfinite(e_r):
            return None
        key = (id(hist), e_r)
        if getattr(self, "_weights_key", None) != key:
            self._weights_key = key
            self._weights = self.volume.histogram_weights(hist, min(e_r, self._white_dn))
        return self._weights

    def _missed_share(self, frames, rate_mm_h: float) -> tuple[float, float]:
        """Smallest detectable drop diameter [m] over a window's frames, and the share of the
        rain rate that drops below it may carry [-].

        A focused drop of radius a streaks with beta = pi r^2 / (2 r L + pi r^2) (r = f a / z0,
        L = f V(2a) T / z0 [px]; Eqs. 17, 23 [GargNayar2007]) and changes its pixels by
        beta (E_r - I_b); it is detected when that is at least 1.5 c, and measured well enough
        for the velocity-law test when it is :data:`MEASURABLE_SNR` times the noise of the
        change (fainter streaks' ends and widths scatter beyond the law's tolerance).  The
        share is that of the Marshall-Palmer spectrum at the measured rate [MarshallPalmer1948]
        (steeper, richer in small drops, than at the true, higher rate), so the upper limit of
        the interval covers what the background hides; the share is capped at 98 % (a gauge
        that sees only the largest drops bounds the rate within 50 times its reading).
        """
        from raingauge.physics.drops import fall_velocity

        bgs = [fr[3] for fr in frames if len(fr) > 3 and fr[3] is not None and np.isfinite(fr[3])]
        if not bgs:
            return float("nan"), 0.0
        prof = self.profile
        e_r = (self._drop_brightness() if self._brightness_known(10)
               else NOMINAL_DROP_BRIGHTNESS_DN)
        # faint streaks are accepted when noise brightens them, which inflates E_r: it cannot
        # exceed the sensor's white
        e_r = min(e_r, self._white_dn)
        hists = [fr[4] for fr in frames if len(fr) > 4 and fr[4] is not None]
        if self.defocus_model == "uniform" and hists:
            # the sizes the window's backgrounds leave visible anywhere are counted up by the
            # share of the frame they are visible in; only the sizes invisible everywhere are
            # missing (raingauge.gauge.volume.SampleVolume.hidden_share)
            weights = self.volume.histogram_weights(np.sum(hists, axis=0), e_r)
            return self.volume.hidden_share(weights, rate_mm_h, velocity_model=self.velocity_model)
        contrast = e_r - float(np.median(bgs))
        d = np.geomspace(0.1e-3, 8e-3, 200)
        a = 0.5 * d
        f, z0, T = prof.focal_length_px, prof.focus_distance_m, prof.exposure_s
        v = np.nan_to_num(fall_velocity(d, model=self.velocity_model), nan=0.0)
        r = f * a / z0
        length = f * v * T / z0
        beta = math.pi * r * r / (2 * r * length + math.pi * r * r)
        seen = (beta * max(contrast, 0.0) >= max(1.5 * self.c, MEASURABLE_SNR * self.noise_change)) & (v > 0)
        d_min = 2.0 * float(self.volume.min_radius_m)
        if not seen.any():
            return float("inf"), 0.98
        d_det = max(float(d[np.argmax(seen)]), d_min)
        if d_det <= d_min * 1.05:
            return d_det, 0.0
        # Marshall-Palmer's slope at the measured (low) rate: steeper than at the true one
        lam = 4.1e3 * max(rate_mm_h, 0.5) ** -0.21                # [1/m]
        w = d ** 3 * v * np.exp(-lam * d) * np.gradient(d)
        above = d >= d_det
        measurable = d >= d_min
        total = float(w[measurable].sum())
        share = 1.0 - float(w[above].sum()) / total if total > 0 else 1.0
        return d_det, float(min(max(share, 0.0), 0.98))

    def _reported_accumulation(self, t1: float) -> float:
        """Accumulation of the counted drops since the start of the stream up to t1 [mm]: the
        drops since the last record are added at the completeness probe's latest correction,
        as the record's rate takes them (a drop's correction when its frame was decided rests
        on the injections until then; early in a stream, on few)."""
        if t1 > self._reported_until:
            new = [d for d in self._window_drops if self._reported_until - 1e-9 <= d["t"] < t1 - 1e-9]
            self._reported_mm += sum(d["accum_mm"] for d in self._reweighted(new))
            self._reported_until = t1
        return self._reported_mm
