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
