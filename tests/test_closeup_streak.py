"""Close-up streaks of oscillating drops (Sec. 9 of Garg & Nayar 2007; Garg & Nayar 2006)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from raingauge.cli import main
from raingauge.render.closeup import (cached_closeup_streak, closeup_streak, light_direction,
                                      light_scene, render_closeup_drop, render_closeup_streak)
from raingauge.render.oscillation import OscillatingDrop, rayleigh_frequency_hz
from signal_helpers import period_of

A = 1.5e-3            # drop radius [m]
WIDTH = 8.0           # drop image diameter [px]
BACKLIGHT = (math.radians(150.0), math.radians(90.0))
LIGHT_SIZE = math.radians(6.0)


def test_rayleigh_frequency():
    # f_2 = (1/2pi) sqrt(8 sigma / (rho a^3)): 121 Hz for a = 1 mm, and f ~ a^-3/2
    assert rayleigh_frequency_hz(1e-3) == pytest.approx(math.sqrt(8 * 0.0728 / (1000 * 1e-9)) / (2 * math.pi))
    assert rayleigh_frequency_hz(1e-3) == pytest.approx(121.5, abs=0.5)
    assert rayleigh_frequency_hz(2e-3) / rayleigh_frequency_hz(1e-3) == pytest.approx(2 ** -1.5)
    with pytest.raises(ValueError):
        rayleigh_frequency_hz(1e-3, n=1)


def test_shape_is_equilibrium_plus_periodic_modes():
    drop = OscillatingDrop(A, amp_axisymmetric=0.08, amp_transverse=0.05)
    rest = OscillatingDrop(A)
    rng = np.random.default_rng(0)
    u = rng.normal(size=(500, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    t = 0.0013
    np.testing.assert_allclose(drop.radius(u, t + drop.period_s), drop.radius(u, t), rtol=1e-9)
    assert np.abs(drop.radius(u, t) / rest.radius(u) - 1).max() <= 0.08 + 0.05 + 1e-9
    # at zero phase the shape is the equilibrium shape
    np.testing.assert_allclose(drop.radius(u, 0.0), rest.radius(u), rtol=1e-12)
    # the equilibrium shape is oblate with the Beard-Chuang axis ratio
    from raingauge.physics.drops import axis_ratio
    up, down, side = np.array([[0, 1.0, 0]]), np.array([[0, -1.0, 0]]), np.array([[1.0, 0, 0]])
    ratio = (rest.radius(up) + rest.radius(down)) / (2 * rest.radius(side))
    assert ratio[0] == pytest.approx(float(axis_ratio(2 * A)), abs=0.03)
    # the (2, 0) mode at its peak stretches the drop vertically (prolate) and then flattens it
    quarter = drop.period_s / 4
    axis = OscillatingDrop(A, amp_axisymmetric=0.08)
    assert axis.radius(up, quarter)[0] > rest.radius(up)[0] > axis.radius(up, 3 * quarter)[0]


@pytest.fixture(scope="module")
def still_streak():
    return closeup_streak(A, length_px=WIDTH + 40, width_px=WIDTH, light_dir=BACKLIGHT,
                          light_size_rad=LIGHT_SIZE, amp_axisymmetric=0.0, amp_transverse=0.0,
                          fall_speed_m_s=2.0, supersample=2, time_samples_per_px=8)


def test_zero_amplitude_streak_is_the_still_drop_smeared(still_streak):
    s = still_streak
    drop = OscillatingDrop(A)
    scene = light_scene(light_direction(*BACKLIGHT, 0.0), light_size_rad=LIGHT_SIZE)
    h, w = s.radiance.shape
    # the still drop sampled every 1/8 px down the column (four shifted 2 x 2 renders)
    renders = [render_closeup_drop(drop, width_px=WIDTH, shape=(16, w), center_px=((w - 1) / 2, 7.5 + dy),
                                   scene=scene, supersample=2) for dy in (-0.375, -0.125, 0.125, 0.375)]
    still = np.mean([r[0] for r in renders], axis=0)
    cov = np.mean([r[1] for r in renders], axis=0)
    # a row the whole drop passes over sees its column integral spread over the fall
    expected = still.sum(axis=0) / s.fall_px
    expected_cov = cov.sum(axis=0) / s.fall_px
    mid = slice(int(WIDTH) + 2, h - int(WIDTH) - 2)
    strong = expected > 0.2 * expected.max()
    for row in s.radiance[mid]:
        np.testing.assert_allclose(row[strong], expected[strong], rtol=0.04)
    for row in s.coverage[mid]:
        np.testing.assert_allclose(row[strong], expected_cov[strong], rtol=0.04)
    # no pattern along the streak without oscillation
    profile = s.radiance[mid].sum(axis=1)
    assert profile.std() < 0.005 * profile.mean()


def _mirror_pair(**kw):
    left = closeup_streak(A, length_px=WIDTH + 24, width_px=WIDTH, light_size_rad=LIGHT_SIZE,
                          light_dir=(math.radians(120), math.radians(30)), fall_speed_m_s=2.0,
                          supersample=2, **kw)
    right = closeup_streak(A, length_px=WIDTH + 24, width_px=WIDTH, light_size_rad=LIGHT_SIZE,
                           light_dir=(math.radians(120), math.radians(150)), fall_speed_m_s=2.0,
                           supersample=2, **kw)
    return left.radiance, right.radiance


def test_streak_is_symmetric_under_mirrored_lighting():
    left, right = _mirror_pair(amp_axisymmetric=0.0, amp_transverse=0.0)
    assert np.abs(left - left[:, ::-1]).max() > 0.05 * left.max()      # the lighting is not symmetric
    np.testing.assert_allclose(left, right[:, ::-1], atol=1e-4 * left.max())
    # the axisymmetric mode keeps the symmetry; the transverse mode (in the X-Y plane) breaks it
    left, right = _mirror_pair(amp_axisymmetric=0.08, amp_transverse=0.0)
    np.testing.assert_allclose(left, right[:, ::-1], atol=1e-4 * left.max())
    left, right = _mirror_pair(amp_axisymmetric=0.0, amp_transverse=0.08)
    assert np.abs(left - right[:, ::-1]).max() > 0.02 * left.max()


@pytest.mark.parametrize("frequency_scale, view_theta", [(1.0, 0.0), (1.6, 0.4)])
def test_pattern_spacing_is_fall_distance_per_period(frequency_scale, view_theta):
    f = rayleigh_frequency_hz(A) * frequency_scale
    scale = WIDTH / (2 * A)
    # 37.3 px per period at the Rayleigh rate, seen from the side
    speed = 37.3 * f / scale / frequency_scale / math.cos(view_theta)
    s = closeup_streak(A, length_px=WIDTH + 3.3 * 37.3, width_px=WIDTH, light_dir=BACKLIGHT,
                       light_size_rad=LIGHT_SIZE, amp_axisymmetric=0.08, amp_transverse=0.05,
                       frequency_hz=f, fall_speed_m_s=speed, view_theta=view_theta, supersample=2)
    # the fall per period, v / f, foreshortened by the camera's elevation, in pixels
    expected = speed / f * math.cos(view_theta) * scale
    assert s.period_px == pytest.approx(expected)
    assert s.period_px == pytest.approx(37.3 / frequency_scale)
    body = s.radiance[int(WIDTH) + 2:-int(WIDTH) - 2]
    assert body.sum(axis=1).std() > 0.01 * body.sum(axis=1).mean()      # there is a pattern
    for profile in (body.sum(axis=1), body.max(axis=1)):
        assert period_of(profile, expected) == pytest.approx(expected, abs=1.0)
    # and no streak is brighter than the light it refracts
    assert s.radiance.max() <= s.max_scene_radiance
    assert np.all(s.radiance <= s.coverage * s.max_scene_radiance + 1e-6)


def test_no_drop_is_brighter_than_its_light(still_streak):
    s = still_streak
    assert s.radiance.max() <= s.max_scene_radiance
    assert np.all(s.radiance <= s.coverage * s.max_scene_radiance + 1e-6)
    drop = OscillatingDrop(A, amp_axisymmetric=0.1, amp_transverse=0.08)
    light = light_scene(light_direction(*BACKLIGHT, 0.2), light_size_rad=LIGHT_SIZE, view_theta=0.2)
    sky = light_scene(None, ambient=0.3)
    for t in np.linspace(0, drop.period_s, 4, endpoint=False):
        rad, cov = render_closeup_drop(drop, t_s=t, width_px=24, view_theta=0.2, scene=light, supersample=2)
        assert rad.max() <= light.max_radiance
        assert rad.max() > 0.3 * light.max_radiance           # the glint of the light is there
        # under a uniform sky a lossless drop is invisible: radiance = sky x coverage
        rad, cov = render_closeup_drop(drop, t_s=t, width_px=24, view_theta=0.2, scene=sky, supersample=2)
        # away from the grazing rim (where paths with many internal reflections are cut)
        full = binary_erosion(cov == 1.0, iterations=2)
        assert full.sum() > 100
        np.testing.assert_allclose(rad[full], 0.3, atol=2e-3)
        assert np.all(rad <= 0.3 * cov + 1e-6)                 # light may be lost at grazing, never made
        assert rad.sum() == pytest.approx(0.3 * cov.sum(), rel=0.01)


def test_environment_map_lighting():
    # a uniform environment map (no light): the drop vanishes into it, at any instant
    env = np.full((32, 64), 0.2)
    s = closeup_streak(1e-3, length_px=18, width_px=6, light_dir=None, environment=env, ambient=0.0,
                       amp_axisymmetric=0.1, supersample=2)
    body = s.coverage > 0.999
    np.testing.assert_allclose(s.radiance[body], 0.2, atol=2e-3)
    assert np.all(s.radiance <= 0.2 * s.coverage + 1e-6)
    # a bright upper sky seen through the drop lights its lower part (the drop inverts)
    env[:16] = 1.0
    drop = OscillatingDrop(1e-3)
    rad, cov = render_closeup_drop(drop, width_px=20, scene=light_scene(None, ambient=0.0, environment=env),
                                   supersample=2)
    inside = cov == 1.0
    rows = np.nonzero(inside.any(axis=1))[0]
    upper = rad[rows[:len(rows) // 3]][inside[rows[:len(rows) // 3]]].mean()
    lower = rad[rows[-len(rows) // 3:]][inside[rows[-len(rows) // 3:]]].mean()
    assert lower > upper + 0.3


def test_render_closeup_streak_returns_the_radiance_patch():
    patch = render_closeup_streak(1e-3, length_px=20, width_px=6, light_dir=BACKLIGHT, view_theta=0.1,
                                  supersample=1)
    assert patch.dtype == np.float32 and patch.shape[0] >= 22 and patch.shape[1] >= 8
    assert patch.max() > 0
    a = cached_closeup_streak(1e-3, length_px=20, width_px=6, light_dir=BACKLIGHT, view_theta=0.1,
                              supersample=1)
    # the drop's centre moves by the fall; its whole image stays inside the patch
    assert a.centre_end_px[1] - a.centre_start_px[1] == pytest.approx(a.fall_px)
    assert a.fall_px == pytest.approx(20 - 6, abs=0.25)
    assert a.coverage[0].max() == 0 and a.coverage[-1].max() == 0
    assert a.coverage[:, 0].max() == 0 and a.coverage[:, -1].max() == 0
    rows = np.nonzero(a.coverage.max(axis=1) > 0)[0]
    assert rows[0] < a.centre_start_px[1] - 2 and rows[-1] > a.centre_end_px[1] + 2
    assert cached_closeup_streak(1e-3, length_px=20, width_px=6, light_dir=BACKLIGHT, view_theta=0.1,
                                 supersample=1) is a
    np.testing.assert_array_equal(a.radiance, patch)
    assert not a.radiance.flags.writeable
    with pytest.raises(ValueError, match="length_px"):
        render_closeup_streak(1e-3, length_px=4, width_px=6, light_dir=BACKLIGHT, view_theta=0.0)
    with pytest.raises(ValueError, match="not both"):
        closeup_streak(1e-3, length_px=20, width_px=6, exposure_s=0.01, fall_speed_m_s=3.0)


def test_render_streak_cli(tmp_path, capsys):
    out = tmp_path / "s.png"
    assert main(["render-streak", "--radius-mm", "1", "--light-theta", "150", "--light-phi", "90",
                 "--view-theta", "5", "--length-px", "30", "--width-px", "6", "--supersample", "1",
                 "--out", str(out)]) == 0
    img = cv2.imread(str(out), cv2.IMREAD_GRAYSCALE)
    assert 32 <= img.shape[0] <= 36 and img.max() == 255
    assert "pattern period" in capsys.readouterr().out
    env = tmp_path / "sky.png"
    cv2.imwrite(str(env), np.tile(np.linspace(255, 0, 16, dtype=np.uint8)[:, None], (1, 32)))
    npy = tmp_path / "s.npy"
    assert main(["render-streak", "--radius-mm", "1", "--no-light", "--envmap", str(env), "--length-px", "20",
                 "--width-px", "6", "--supersample", "1", "--out", str(out), "--npy", str(npy)]) == 0
    radiance, coverage = np.load(npy)
    assert radiance.shape == coverage.shape and 22 <= radiance.shape[0] <= 26
    assert np.all(radiance <= coverage * (1.0 + 0.05) + 1e-6)     # map peak 1 + ambient 0.05


@pytest.mark.parametrize("args, message", [
    (["--radius-mm", "10"], "--radius-mm"),
    (["--radius-mm", "1", "--length-px", "5", "--width-px", "8"], "--length-px"),
    (["--radius-mm", "1", "--light-theta", "200"], "--light-theta"),
    (["--radius-mm", "1", "--amp-axisymmetric", "0.4", "--amp-transverse", "0.3"], "below 0.5"),
    (["--radius-mm", "1", "--envmap", "nope.png"], "environment map"),
])
def test_render_streak_cli_bad_input(tmp_path, capsys, args, message):
    assert main(["render-streak", *args, "--out", str(tmp_path / "s.png")]) == 2
    assert message in capsys.readouterr().err


def test_render_streak_cli_missing_output_folder(tmp_path, capsys):
    assert main(["render-streak", "--radius-mm", "1", "--out", str(tmp_path / "no" / "s.png")]) == 2
    assert "does not exist" in capsys.readouterr().err


@pytest.mark.parametrize("args, message", [
    (["--light-phi", "nan"], "--light-phi must be a finite number"),
    (["--amp-axisymmetric", "nan"], "--amp-axisymmetric must be a finite number"),
    (["--gain", "0"], "--gain"),
    (["--background", "-1"], "--background"),
    (["--out", "{tmp}/s.xyz"], "no image of that extension"),
    (["--npy", "{tmp}/missing/s.npy"], "does not exist"),
    (["--radius-mm", "abc"], "invalid float value: 'abc'"),
    (["--exposure-ms", "4", "--fall-speed", "3"], "not allowed with"),
    (["--envmap", "{tmp}/garbage.png"], "cannot read the environment map"),
    (["--envmap", "{tmp}"], "cannot read the environment map"),
])
def test_render_streak_cli_refuses_before_rendering(tmp_path, cli_error, args, message):
    (tmp_path / "garbage.png").write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    cli_error(["render-streak", "--radius-mm", "1", "--length-px", "20", "--width-px", "6", "--supersample", "1",
               "--out", tmp_path / "s.png", *[a.format(tmp=tmp_path) for a in args]], message)
    assert not list(tmp_path.glob("s.*"))
