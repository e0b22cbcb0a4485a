"""Lens and focus plan: z0 <= 2 f a_min, the widest aperture, and the volume it samples."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.focus_plan import frustum_volume_m3, plan_focus, standard_f_numbers
from raingauge.errors import InputError
from raingauge.physics import camera
from raingauge.profile import load_profile


@pytest.fixture(scope="module")
def profile():
    return load_profile("gauge-default")


def test_fig18_camera_focus_satisfies_sec8():
    """Fig. 18(c): f = 3300 px, focused at 3 m <= 2 f a_min = 3.3 m (a_min = 0.5 mm)."""
    cam = load_profile("canon_xl1").replace(focal_length_px=3300.0, focus_range_m=[0.5, 200.0])
    plan = plan_focus(cam, f_numbers=[1.8, 2.8, 4.0])
    assert plan.z_max_m == pytest.approx(3.3)
    assert plan.focus_distance_m == pytest.approx(3.3)
    assert 3.0 <= plan.focus_distance_m


def test_plan_picks_the_widest_aperture_and_2fa_min(profile):
    plan = plan_focus(profile, f_numbers=[4.0, 2.0, 2.8, 8.0], a_min_m=0.5e-3)
    assert plan.f_number == 2.0
    assert plan.focus_distance_m == pytest.approx(2 * profile.focal_length_px * 0.5e-3)
    assert plan.focal_length_mm == pytest.approx(profile.focal_length_px * profile.pixel_pitch_m * 1e3)
    # At the depth-of-field limits the blur circle is one pixel (independent thin-lens check).
    for z in (plan.near_m, plan.far_m):
        b = camera.blur_circle_px(z, focal_length_px=profile.focal_length_px, f_number=plan.f_number,
                                  focus_distance_m=plan.focus_distance_m, pixel_pitch_m=profile.pixel_pitch_m)
        assert float(b) == pytest.approx(1.0, rel=1e-6)
    assert plan.near_m < plan.focus_distance_m < plan.far_m
    assert plan.sample_volume_m3 > 0 and plan.counting
    assert "F/2" in plan.summary()


def test_wider_aperture_gives_a_thinner_volume(profile):
    wide = plan_focus(profile, f_numbers=[1.4])
    narrow = plan_focus(profile, f_numbers=[4.0])
    assert wide.far_m - wide.near_m < narrow.far_m - narrow.near_m
    assert wide.dof_volume_m3 < narrow.dof_volume_m3


def test_focus_clipped_by_the_lens_and_refused_when_too_near(profile):
    far_limited = profile.replace(focus_range_m=[0.3, 2.0])
    plan = plan_focus(far_limited, f_numbers=[2.0])
    assert plan.focus_distance_m == pytest.approx(2.0)
    assert any("no farther" in n for n in plan.notes)
    near_limited = profile.replace(focus_range_m=[20.0, 100.0])
    with pytest.raises(InputError, match="2 f a_min"):
        plan_focus(near_limited, f_numbers=[2.0])


def test_frustum_volume_is_the_integral_of_the_view_area():
    w, h, f = 640, 480, 1000.0
    z = np.linspace(2.0, 3.0, 200001)
    area = (w / f * z) * (h / f * z)
    numeric = float(np.sum((area[1:] + area[:-1]) / 2 * np.diff(z)))
    assert frustum_volume_m3(2.0, 3.0, width_px=w, height_px=h, focal_length_px=f) == pytest.approx(numeric, rel=1e-8)
    assert frustum_volume_m3(3.0, 2.0, width_px=w, height_px=h, focal_length_px=f) == 0.0


def test_bad_lens_inputs(profile):
    with pytest.raises(InputError, match="F-numbers"):
        plan_focus(profile, f_numbers=[])
    with pytest.raises(InputError, match="pixel_pitch_m"):
        plan_focus(profile, f_numbers=[2.0], pixel_pitch_m=-1.0)


def test_standard_stops():
    assert standard_f_numbers(1.4, 4.0) == [1.4, 1.6, 1.8, 2.0, 2.2, 2.5, 2.8, 3.2, 3.5, 4.0]
    assert standard_f_numbers(1.7, 2.0)[0] == 1.7
    assert math.isclose(max(standard_f_numbers(2, 16)), 16.0)
