"""Camera geometry: projection, image velocity, blur circle, depth of field, z_m, rain-visible region."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raingauge.physics import camera

F_PX = 7000.0
PITCH = 5e-6
CP = (640.0, 360.0)


def test_project_pinhole_and_shapes():
    pts = np.array([[[0.0, 0.0, 2.0], [0.1, -0.2, 4.0]]])  # (1, 2, 3)
    uv = camera.project(pts, focal_length_px=F_PX, principal_point_px=CP)
    assert uv.shape == (1, 2, 2)
    assert np.allclose(uv[0, 0], CP)
    assert np.allclose(uv[0, 1], [640 + 7000 * 0.1 / 4, 360 - 7000 * 0.2 / 4])
    behind = camera.project([0.0, 0.0, -1.0], focal_length_px=F_PX, principal_point_px=CP)
    assert np.all(np.isnan(behind))
    with pytest.raises(ValueError):
        camera.project([1.0, 2.0], focal_length_px=F_PX, principal_point_px=CP)
    with pytest.raises(ValueError, match="focal_length_px"):
        camera.project([0, 0, 1.0], focal_length_px=0.0, principal_point_px=CP)


def test_back_project_round_trip():
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50), rng.uniform(0.5, 20, 50)])
    uv = camera.project(pts, focal_length_px=F_PX, principal_point_px=CP)
    back = camera.back_project(uv, pts[:, 2], focal_length_px=F_PX, principal_point_px=CP)
    assert np.allclose(back, pts)


def test_image_velocity_is_the_derivative_of_projection():
    p = np.array([0.3, -0.1, 3.0])
    w = np.array([0.5, 7.0, -0.4])
    dt = 1e-6
    fd = (camera.project(p + w * dt, focal_length_px=F_PX, principal_point_px=CP)
          - camera.project(p - w * dt, focal_length_px=F_PX, principal_point_px=CP)) / (2 * dt)
    assert np.allclose(camera.image_velocity_px_s(p, w, focal_length_px=F_PX), fd, rtol=1e-6)
    # a drop falling straight down: v_i = f v / z (Appendix 10.2)
    vi = camera.image_velocity_px_s([0, 0, 2.0], [0, 6.0, 0], focal_length_px=F_PX)
    assert vi[1] == pytest.approx(F_PX * 6.0 / 2.0) and vi[0] == 0


def _blur_by_ray_optics(z, f_m, n, z0):
    # independent: image distances from the lens equation, blur = aperture x defocus / image distance
    s_img = f_m * z / (z - f_m)
    s_sensor = f_m * z0 / (z0 - f_m)
    return (f_m / n) * abs(s_sensor - s_img) / s_img


@pytest.mark.parametrize("z", [0.5, 1.0, 2.49, 4.0, 30.0])
def test_blur_circle_matches_ray_optics(z):
    f_m = F_PX * PITCH
    got = camera.blur_circle_px(z, focal_length_px=F_PX, f_number=2.0, focus_distance_m=2.5, pixel_pitch_m=PITCH)
    assert got == pytest.approx(_blur_by_ray_optics(z, f_m, 2.0, 2.5) / PITCH, rel=1e-9)


def test_blur_circle_limits():
    kw = dict(focal_length_px=F_PX, f_number=2.0, focus_distance_m=2.5, pixel_pitch_m=PITCH)
    assert camera.blur_circle_px(2.5, **kw) == 0.0
    # stopping down (larger N) shrinks the blur in proportion
    b2 = camera.blur_circle_px(5.0, **kw)
    b8 = camera.blur_circle_px(5.0, **{**kw, "f_number": 8.0})
    assert b8 == pytest.approx(b2 / 4)
    # at infinity the blur tends to f_m^2 / (N p (z0 - f_m))
    f_m = F_PX * PITCH
    assert camera.blur_circle_px(1e9, **kw) == pytest.approx(f_m ** 2 / (2 * PITCH * (2.5 - f_m)), rel=1e-6)
    with pytest.raises(ValueError, match="focus_distance_m"):
        camera.blur_circle_px(1.0, **{**kw, "focus_distance_m": 0.01})


def test_depth_of_field_edges_have_the_chosen_blur():
    kw = dict(focal_length_px=F_PX, f_number=2.0, focus_distance_m=2.5, pixel_pitch_m=PITCH)
    near, far = camera.depth_of_field_m(coc_px=2.0, **kw)
    assert near < 2.5 < far
    assert camera.blur_circle_px(near, **kw) == pytest.approx(2.0)
    assert camera.blur_circle_px(far, **kw) == pytest.approx(2.0)
    # wider circle of confusion, deeper field
    near1, far1 = camera.depth_of_field_m(coc_px=1.0, **kw)
    assert near1 > near and far1 < far


def test_depth_of_field_beyond_hyperfocal_is_infinite():
    f_m = 2000 * PITCH
    n, c = 8.0, 1.0
    hyperfocal = f_m ** 2 / (n * c * PITCH) + f_m
    near, far = camera.depth_of_field_m(focal_length_px=2000, f_number=n, focus_distance_m=hyperfocal * 1.01,
                                        pixel_pitch_m=PITCH, coc_px=c)
    assert far == math.inf and near == pytest.approx(hyperfocal / 2, rel=0.02)


def test_z_m_and_streak_width():
    # the paper's camera: f = 3155..8000 px; a_min = 0.5 mm -> z_m = 2 f a
    assert camera.z_m(0.5e-3, focal_length_px=3155) == pytest.approx(3.155)
    assert camera.z_m(0.5e-3, focal_length_px=8000) == pytest.approx(8.0)
    zm = float(camera.z_m(1e-3, focal_length_px=F_PX))
    w = camera.streak_width_px(1e-3, np.array([zm / 4, zm / 2, zm, 2 * zm]), focal_length_px=F_PX)
    assert np.allclose(w, [4.0, 2.0, 1.0, 1.0])
    assert np.isnan(camera.streak_width_px(1e-3, 0.0, focal_length_px=F_PX))


def test_streak_length():
    # v T in the image plus the drop's own diameter
    got = camera.streak_length_px(6.0, 2.0, 0.004, focal_length_px=F_PX, radius_m=1e-3)
    assert got == pytest.approx(F_PX * (6.0 * 0.004 + 2e-3) / 2.0)
    # T -> 0: the streak shrinks to the drop's image
    assert camera.streak_length_px(6.0, 2.0, 0.0, focal_length_px=F_PX, radius_m=1e-3) == pytest.approx(7.0)


def test_rain_visible_region_edge_is_where_the_change_meets_the_threshold():
    a, v, t = 1e-3, 6.5, 0.004
    contrast, threshold = 120.0, 3.0
    rz = camera.rain_visible_distance_m(a, v, focal_length_px=F_PX, exposure_s=t,
                                        contrast_dn=contrast, threshold_dn=threshold)
    zm = 2 * F_PX * a
    assert rz > zm
    # Eq. (22) evaluated at R z_m equals the threshold; Eq. (21) holds inside z_m
    di_far = 4 * F_PX * a ** 2 / (rz * v * t) * contrast
    assert di_far == pytest.approx(threshold)
    di_near = (2 * a / (v * t)) * contrast
    assert 4 * F_PX * a ** 2 / (zm * v * t) * contrast == pytest.approx(di_near)
    # longer exposures shrink the region as 1/T
    rz2 = camera.rain_visible_distance_m(a, v, focal_length_px=F_PX, exposure_s=2 * t,
                                         contrast_dn=contrast, threshold_dn=threshold)
    assert rz2 == pytest.approx(rz / 2)
    # an undetectable drop has no visible region
    assert camera.rain_visible_distance_m(a, v, focal_length_px=F_PX, exposure_s=t,
                                          contrast_dn=1.0, threshold_dn=threshold) == 0.0


@pytest.mark.parametrize("name", ["focal_length_px", "f_number", "focus_distance_m", "pixel_pitch_m"])
@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_blur_circle_and_depth_of_field_check_every_lens_parameter(name, bad):
    kw = dict(focal_length_px=F_PX, f_number=2.0, focus_distance_m=2.5, pixel_pitch_m=PITCH)
    kw[name] = bad
    with pytest.raises(ValueError, match=name):
        camera.blur_circle_px(3.0, **kw)
    with pytest.raises(ValueError, match=name):
        camera.depth_of_field_m(**kw)
