"""Defocus rejection: (a, v) against the velocity law, with a tolerance set by the measurement error."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raingauge.gauge.rejection import (
    exposure_area_px2,
    law_tolerance,
    passes_blur,
    passes_velocity_law,
    photometric_focus,
    velocity_log_ratio,
)
from raingauge.physics.drops import FALL_VELOCITY_MODELS, fall_velocity
from raingauge.profile import default_profile

CAM = default_profile()


@pytest.mark.parametrize("model", FALL_VELOCITY_MODELS)
def test_focused_drop_passes_every_law(model):
    """A drop at z0 measured exactly obeys its own law: it passes, for every registered law."""
    f, z0, T = CAM.focal_length_px, CAM.focus_distance_m, CAM.exposure_s
    for d_mm in (0.8, 1.5, 3.0):
        a = d_mm / 2e3
        v = float(fall_velocity(d_mm * 1e-3, model=model))
        w = 2 * f * a / z0
        motion = f * v * T / z0
        assert passes_velocity_law(a, v, w, motion, model=model)
        assert abs(velocity_log_ratio(a, v, model=model)) < 1e-9


def test_paper_law_is_200_sqrt_a():
    """With the paper's law, v = 200 sqrt(a) gives r = 0 and 10 % faster gives ln 1.1."""
    a = 1e-3
    assert velocity_log_ratio(a, 200 * math.sqrt(a)) == pytest.approx(0.0, abs=1e-12)
    assert velocity_log_ratio(a, 1.1 * 200 * math.sqrt(a)) == pytest.approx(math.log(1.1))


def test_defocused_drop_is_rejected():
    """A 2-mm drop at 0.75 z0 measured as if at z0, its streak fattened by the blur
    (w' = w + b, Eq. 23), violates the law; the same drop at z0 does not."""
    from raingauge.physics.camera import blur_circle_px

    f, z0, T = CAM.focal_length_px, CAM.focus_distance_m, CAM.exposure_s
    a = 1e-3
    v = float(fall_velocity(2 * a, model="paper"))
    z = 0.75 * z0
    b = float(blur_circle_px(z, focal_length_px=f, f_number=CAM.f_number, focus_distance_m=z0,
                             pixel_pitch_m=CAM.pixel_pitch_m))
    w_app = 2 * f * a / z + b
    motion = f * v * T / z
    a_app = w_app * z0 / (2 * f)
    v_app = motion * z0 / (f * T)
    assert not passes_velocity_law(a_app, v_app, w_app, motion)


def test_tolerance_widens_for_narrow_streaks():
    """The tolerance follows the measurement error: narrower streaks, larger relative
    width error, wider tolerance; never below the floor."""
    a = np.array([0.2e-3, 0.5e-3, 2e-3])
    w = 2 * CAM.focal_length_px * a / CAM.focus_distance_m
    tol = law_tolerance(a, w, np.full(3, 50.0), floor=0.08)
    assert np.all(np.diff(tol) < 0)
    assert np.all(tol >= 0.08)


def test_unknown_law_is_rejected_with_list():
    with pytest.raises(ValueError, match="gunn_kinzer"):
        velocity_log_ratio(1e-3, 6.0, model="nonsense")


def test_photometric_focus_is_one_in_focus_and_drops_with_blur():
    """Q = pi a_i^2 C for any blur; q = (2 a_i / w')^2: 1 in focus, (w / (w + b))^2 blurred."""
    a_i, c, motion = 2.5, 140.0, 60.0
    for b in (0.0, 1.0, 3.0):
        w_app = 2 * a_i + b
        capsule = w_app * motion + math.pi * w_app ** 2 / 4
        beta = math.pi * a_i ** 2 / capsule
        plateau = beta * c * w_app
        q = photometric_focus(exposure_area_px2(plateau, motion, w_app), w_app, c)
        assert q == pytest.approx((2 * a_i / w_app) ** 2, rel=1e-9)


def test_blur_test_relative_to_width():
    assert passes_blur(1.5, 3.0)
    assert not passes_blur(3.0, 3.0)
    assert passes_blur(3.0, 10.0)
    assert not passes_blur(float("nan"), 10.0)


def test_tolerance_follows_each_streaks_own_errors():
    """Two streaks with the same (a, v), one measured well and one poorly: the law's
    tolerance follows each one's own error, so a pair 25 % slow fails when measured to
    0.05 px and passes when its ends are uncertain by 4 px."""
    f, z0, T = CAM.focal_length_px, CAM.focus_distance_m, CAM.exposure_s
    a = 0.6e-3
    w = 2 * f * a / z0
    v = 0.75 * float(fall_velocity(2 * a, model="gunn_kinzer"))
    motion = f * v * T / z0
    sharp = passes_velocity_law(a, v, w, motion, model="gunn_kinzer", width_sigma_px=0.05, motion_sigma_px=0.3)
    blurry = passes_velocity_law(a, v, w, motion, model="gunn_kinzer", width_sigma_px=0.05, motion_sigma_px=4.0)
    assert not sharp and blurry
    tol = law_tolerance(np.full(3, a), np.full(3, w), np.full(3, motion), model="gunn_kinzer",
                        width_sigma_px=np.array([0.05, 0.3, 0.3]), motion_sigma_px=np.array([0.3, 0.3, 3.0]))
    assert tol[0] < tol[1] < tol[2]


def test_streak_errors_fall_with_signal_and_width():
    """The streak's own errors: four times the signal (and its squared noise term) makes
    the motion error smaller, a narrow streak's width is less certain than a wide one's
    (the pixel grid), and a streak without signal has no finite error."""
    from raingauge.gauge.rejection import streak_errors_px

    sw1, sl1 = streak_errors_px(3.0, 45.0, 20.0, 3.0)
    sw4, sl4 = streak_errors_px(3.0, 45.0, 80.0, 3.0)
    assert sl4 < 0.3 * sl1 and sw4 < sw1
    narrow, _ = streak_errors_px(1.3, 25.0, 1.3 * 40.0, 1.0)
    wide, _ = streak_errors_px(3.0, 25.0, 3.0 * 40.0, 1.0)
    assert narrow > 5 * wide
    bad_w, bad_l = streak_errors_px(3.0, 45.0, 0.0, 1.0)
    assert np.isinf(bad_w) and np.isinf(bad_l)


def test_streak_change_is_the_drops_exposure_area_spread_over_the_streak():
    """beta (E_r - E_b) over a capsule w' wide around the motion L holds the drop's
    exposure area pi a_i^2 times the contrast: Q of :func:`exposure_area_px2` from the
    row-sum plateau A w' gives back pi a_i^2 C (Eqs. 17, 23)."""
    from raingauge.gauge.rejection import streak_change_dn

    a_i, w_app, motion, c = 1.4, 3.5, 40.0, 150.0
    change = float(streak_change_dn(a_i, w_app, motion, c))
    q_total = float(exposure_area_px2(change * w_app, motion, w_app))
    assert q_total == pytest.approx(math.pi * a_i ** 2 * c, rel=1e-12)
    # a focused streak (w' = 2 a_i) of a 4 ms exposure changes a pixel by a few percent of C
    assert 0.01 < change / c < 0.1


def test_detection_probability_limits():
    """Eq. (19): a change far above c is always detected, far below never; at
    A - sigma / sqrt(pi) = c one try is a coin toss, and a longer streak offers more tries."""
    from raingauge.gauge.rejection import detection_probability

    kw = dict(threshold_dn=3.0, noise_sigma_dn=2.0)
    assert detection_probability(20.0, 3.0, **kw) > 0.999
    assert detection_probability(0.5, 3.0, **kw) < 1e-3
    half = 3.0 + 2.0 / math.sqrt(math.pi)
    assert detection_probability(half, 3.0, **kw) == pytest.approx(0.5, abs=1e-9)
    p_long = detection_probability(half, 3.0, length_px=50.0, **kw)
    assert p_long == pytest.approx(1 - 0.5 ** 10, rel=1e-9)
    # a streak narrower than a pixel column shares its change between two columns
    assert detection_probability(half, 1.2, **kw) < 0.5


def test_change_noise_is_the_sensor_noise_without_the_streaks():
    """The change image I_n - (I_{n-1} + I_{n+1}) / 2 of three frames with noise sigma has
    the noise sqrt(1.5) sigma; bright streaks on 2 % of the pixels do not inflate it."""
    from raingauge.gauge.rejection import change_noise_dn

    rng = np.random.default_rng(7)
    shape = (240, 320)
    frames = [60.0 + rng.normal(0.0, 2.0, shape) for _ in range(3)]
    cur = frames[1].copy()
    cur[:, ::50] += 40.0                       # streak columns
    est = change_noise_dn(frames[0], cur, frames[2])
    assert est == pytest.approx(2.0 * math.sqrt(1.5), rel=0.05)


@pytest.mark.parametrize("sigma", [0.8, 3.0])
def test_change_noise_of_8_bit_frames_equals_that_of_their_float_copies(sigma):
    """8-bit frames take the histogram path (no sort); it gives the noise of the same
    frames as float32 (to float rounding), streaks, clipping and all."""
    from raingauge.gauge.rejection import change_noise_dn

    rng = np.random.default_rng(11)
    shape = (270, 480)
    base = rng.uniform(20.0, 220.0, shape)
    frames = []
    for _ in range(3):
        f = base + rng.normal(0.0, sigma, shape) + 45.0 * (rng.random(shape) < 0.02)
        frames.append(np.clip(np.rint(f), 0, 255).astype(np.uint8))
    as_u8 = change_noise_dn(*frames)
    as_f32 = change_noise_dn(*(f.astype(np.float32) for f in frames))
    assert as_u8 == pytest.approx(as_f32, rel=1e-5)
    assert as_u8 == pytest.approx(sigma * math.sqrt(1.5), rel=0.25)


@pytest.mark.skipif(not __import__("raingauge.gauge._kernels", fromlist=["AVAILABLE"]).AVAILABLE,
                    reason="numba not installed")
def test_compiled_change_histogram_equals_numpy():
    """The compiled histogram of 2 I_n - I_{n-1} - I_{n+1} over the sampled pixels is
    np.bincount's, and the noise taken of it is the array form's to the bit (frame sizes
    off the sampling steps included)."""
    from raingauge.gauge import _kernels
    from raingauge.gauge.rejection import _change_noise_u8, change_noise_dn

    rng = np.random.default_rng(12)
    for shape in ((270, 480), (31, 45), (1, 3)):
        frames = [rng.integers(0, 256, shape).astype(np.uint8) for _ in range(3)]
        sub = [f[::3, ::4] for f in frames]
        c2 = 2 * sub[1].astype(np.int64) - sub[0] - sub[2]
        np.testing.assert_array_equal(_kernels.change_histogram(*frames, 3, 4),
                                      np.bincount((c2 + 510).ravel(), minlength=1021))
        assert change_noise_dn(*frames) == _change_noise_u8(*sub, 3)


def test_tolerance_is_capped_for_poorly_measured_streaks():
    """A streak measured too poorly to place within a factor of two of the law says nothing
    about it: the tolerance stops at the cap (faint moving texture would pass any wider
    test), and a streak twice too slow fails however large its errors."""
    from raingauge.gauge.rejection import DEFAULT_TOLERANCE_CAP, law_tolerance, passes_velocity_law

    a = 0.8e-3
    v = float(fall_velocity(2 * a, model="gunn_kinzer"))
    w, m = 2 * CAM.focal_length_px * a / 2.5, CAM.focal_length_px * v * CAM.exposure_s / 2.5
    tight = law_tolerance(a, w, m, model="gunn_kinzer", width_sigma_px=0.1, motion_sigma_px=0.3)
    loose = law_tolerance(a, w, m, model="gunn_kinzer", width_sigma_px=5.0, motion_sigma_px=20.0)
    assert tight < DEFAULT_TOLERANCE_CAP
    assert loose == pytest.approx(DEFAULT_TOLERANCE_CAP)
    assert not passes_velocity_law(a, 0.45 * v, w, 0.45 * m, model="gunn_kinzer", width_sigma_px=5.0,
                                   motion_sigma_px=20.0)
    assert passes_velocity_law(a, 0.7 * v, w, 0.7 * m, model="gunn_kinzer", width_sigma_px=5.0,
                               motion_sigma_px=20.0)

