"""Close-up drops in the rain simulator: oscillating-drop streaks (Sec. 9) for drops near the camera.

A drop whose focused image is wide and sharp enough is drawn as the ray-traced
streak of an oscillating drop instead of the uniform capsule.  These tests
hold that to the physics the rest of the project relies on: the pattern
repeats every fall distance per oscillation period, the deposited exposure is
the uniform model's (Eqs. 15-17), drops that do not qualify are drawn exactly
as before, and the same seed gives the same video.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from signal_helpers import period_of
from raingauge.cli import main
from raingauge.physics import drops
from raingauge.render.oscillation import rayleigh_frequency_hz
from raingauge.render.simulator import (
    DEFAULT_DROP_BRIGHTNESS_DN,
    closeup_selection,
    render_closeup_drops,
    render_clip,
    render_streaks,
    simulate,
    small_profile,
)

BACKLIGHT = (math.radians(150.0), math.radians(90.0))


def _still(amp=0.09):
    return {"amp_axisymmetric": [amp], "amp_transverse": [0.0], "phase_axisymmetric": [0.0],
            "phase_transverse": [0.0], "transverse_azimuth": [0.0]}


@pytest.fixture(scope="module")
def near_drop():
    """One D = 1 mm drop, 8 px wide, falling at its terminal speed for 10 ms (3.5 oscillations)."""
    a, exposure, f_over_z = 0.5e-3, 0.010, 8000.0
    v = float(drops.fall_velocity(2 * a, "gunn_kinzer"))
    fall = v * exposure * f_over_z
    p0 = np.array([[40.0, 20.0]])
    p1 = p0 + [[0.0, fall]]
    shape = (int(fall) + 60, 80)
    cov, rad, info = render_closeup_drops(shape, p0, p1, [a], [a * f_over_z], [0.0], exposure_s=exposure,
                                          drop_brightness_dn=DEFAULT_DROP_BRIGHTNESS_DN, oscillation=_still(),
                                          light=BACKLIGHT)
    return dict(a=a, T=exposure, v=v, fall=fall, p0=p0, p1=p1, shape=shape, a_i=a * f_over_z,
                cov=cov, rad=rad, info=info)


def test_near_drop_pattern_repeats_every_fall_per_oscillation(near_drop):
    nd = near_drop
    # the fall per oscillation period: v / f_2 in the image, = fall / (T f_2) (Rayleigh's f_2 of the drop)
    expected = nd["fall"] / (nd["T"] * float(rayleigh_frequency_hz(nd["a"])))
    assert expected == pytest.approx(4.03 / 343.5 * 8000.0, rel=2e-3)     # 11.7 mm per period, 93.8 px
    # the drawn period (radius quantised to a 4 % grid: f_2 within 3 %)
    assert nd["info"]["period_px"][0] == pytest.approx(expected, rel=0.03)
    rows = slice(int(nd["p0"][0, 1]) + 12, int(nd["p1"][0, 1]) - 12)
    body = nd["rad"][rows]
    profile = body.sum(axis=1)
    assert profile.std() > 0.05 * profile.mean()                # a visible pattern along the streak
    for prof in (profile, body.max(axis=1)):
        assert period_of(prof, expected) == pytest.approx(nd["info"]["period_px"][0], rel=0.03)
    # without oscillation the streak is flat along its length
    _, rad0, _ = render_closeup_drops(nd["shape"], nd["p0"], nd["p1"], [nd["a"]], [nd["a_i"]], [0.0],
                                         exposure_s=nd["T"], drop_brightness_dn=DEFAULT_DROP_BRIGHTNESS_DN,
                                         oscillation=_still(0.0), light=BACKLIGHT)
    flat = rad0[rows].sum(axis=1)
    assert flat.std() < 0.3 * profile.std()


def test_closeup_deposit_equals_the_uniform_capsule(near_drop):
    """Eqs. (15)-(17): sum over pixels of the change = pi a_i^2 (E_r - I_b), as for the uniform capsule."""
    nd = near_drop
    e_b = 60.0
    area = math.pi * nd["a_i"] ** 2
    closeup_deposit = float(np.sum(nd["rad"] - nd["cov"] * e_b, dtype=np.float64))
    beta, _ = render_streaks(nd["shape"], nd["p0"], nd["p1"], [nd["a_i"]], [area])
    uniform_deposit = float(np.sum(beta * (DEFAULT_DROP_BRIGHTNESS_DN - e_b), dtype=np.float64))
    assert uniform_deposit == pytest.approx(area * (DEFAULT_DROP_BRIGHTNESS_DN - e_b), rel=2e-3)
    assert closeup_deposit == pytest.approx(uniform_deposit, rel=2e-3)
    # the tracer's own exposure area before normalisation agrees with pi a_i^2 (oblate drop, sampling)
    assert 0.9 < nd["info"]["raw_area_ratio"][0] < 1.05
    # a pixel is never covered for more than the whole exposure, nor brighter than the light allows
    assert nd["cov"].max() <= 1.0
    # defocus (a disc of the blur circle, Eq. 23) spreads the streak by b_c and keeps the deposit
    blur = 4.0
    cov_b, rad_b, _ = render_closeup_drops(nd["shape"], nd["p0"], nd["p1"], [nd["a"]], [nd["a_i"]], [blur],
                                           exposure_s=nd["T"], drop_brightness_dn=DEFAULT_DROP_BRIGHTNESS_DN,
                                           oscillation=_still(), light=BACKLIGHT)
    assert float(np.sum(rad_b - cov_b * e_b, dtype=np.float64)) == pytest.approx(closeup_deposit, rel=2e-3)
    # across the streak the coverage is the drop's chord (variance a_i^2 / 4 about the centre line);
    # the disc of diameter b adds its variance (b / 2)^2 / 4 (and the pixel sampling ~1/12 px^2)
    rows = slice(int(nd["p0"][0, 1]) + 12, int(nd["p1"][0, 1]) - 12)
    x = np.arange(nd["shape"][1]) - nd["p0"][0, 0]

    def variance(c):
        prof = c[rows].sum(axis=0)
        return float(np.sum(prof * x ** 2) / prof.sum())

    assert variance(nd["cov"]) == pytest.approx(nd["a_i"] ** 2 / 4 + 1 / 12, rel=0.1)
    assert variance(cov_b) - variance(nd["cov"]) == pytest.approx((blur / 2) ** 2 / 4 + 1 / 12, rel=0.08)


def test_selection_rule():
    w = np.array([5.9, 6.0, 10.0, 10.0, 40.0])
    b = np.array([0.0, 3.0, 5.0, 5.1, 1.0])
    np.testing.assert_array_equal(closeup_selection(w, b), [False, True, True, False, True])


def _near_profile():
    """A 240x180 crop of gauge-default focused at 1 m, F/8: a few drops per clip qualify."""
    return small_profile(240, 180, focal_length_px=7000.0, pixel_pitch_m=5e-6, focus_distance_m=1.0,
                         f_number=8.0, noise_sigma_dn=0.0)


@pytest.fixture(scope="module")
def near_clip():
    prof = _near_profile()
    kw = dict(n_frames=3, rain_rate_mm_h=30.0, seed=1, return_drops=True, truth_linear=True)
    on = list(simulate(prof, n_frames=3, rain_rate_mm_h=30.0, seed=1, closeup=True, truth_linear=True))
    off = list(simulate(prof, n_frames=3, rain_rate_mm_h=30.0, seed=1, truth_linear=True))
    again, truth_again = render_clip(prof, closeup=True, **kw)
    return prof, on, off, again, truth_again


def test_clip_draws_qualifying_drops_closeup_and_keeps_the_rest(near_clip):
    prof, on, off, again, _ = near_clip
    f = prof.focal_length_px
    n_closeup = 0
    for (frame_on, ft_on), (frame_off, ft_off) in zip(on, off):
        d = ft_on["drops"]
        # the same drops either way
        np.testing.assert_array_equal(d["id"], ft_off["drops"]["id"])
        rule = closeup_selection(2 * f * d["radius_m"] / d["depth_m"], d["blur_px"])
        ids = ft_on["closeup"]["id"]
        np.testing.assert_array_equal(np.sort(ids), np.sort(d["id"][rule]))
        n_closeup += ids.size
        changed = np.abs(ft_on["linear"] - ft_off["linear"]) > 1e-3
        # only pixels near the close-up drops' streaks change
        near = np.zeros(prof.shape, bool)
        for i in np.nonzero(rule)[0]:
            (x0, y0), (x1, y1) = d["streak_px"][i]
            r = 0.5 * (d["width_px"][i] + d["blur_px"][i]) + 3
            ys = slice(max(int(min(y0, y1) - r), 0), max(int(max(y0, y1) + r) + 1, 0))
            xs = slice(max(int(min(x0, x1) - r), 0), max(int(max(x0, x1) + r) + 1, 0))
            near[ys, xs] = True
        assert not np.any(changed & ~near)
        # and the deposit over the frame is the uniform model's (uniform background): the close-up
        # drops' own deposit pi a_i^2 (E_r - I_b) is kept to within what the frame's border cuts differently
        dep_on = float(np.sum(ft_on["linear"] - ft_on["linear_clean"], dtype=np.float64))
        dep_off = float(np.sum(ft_off["linear"] - ft_off["linear_clean"], dtype=np.float64))
        a_i = f * d["radius_m"][rule] / d["depth_m"][rule]
        own = float(np.sum(math.pi * a_i ** 2)) * (DEFAULT_DROP_BRIGHTNESS_DN - 60.0)
        assert abs(dep_on - dep_off) <= 0.03 * own
    assert n_closeup >= 1
    # a drop's oscillation is its own: its amplitudes are the same in every frame it appears in
    amps = {}
    for _, ft in on:
        for i, drop_id in enumerate(ft["closeup"]["id"]):
            key = (ft["closeup"]["amp_axisymmetric"][i], ft["closeup"]["amp_transverse"][i])
            assert amps.setdefault(int(drop_id), key) == key


def test_same_seed_same_closeup_video(near_clip):
    _, on, _, again, truth = near_clip
    np.testing.assert_array_equal(np.stack([fr for fr, _ in on]), again)
    assert truth["rendering"]["closeup"]["min_width_px"] == 6.0
    for (_, ft), per in zip(on, truth["frames"]):
        assert len(ft["drops"]) == len(per["drops"])


def test_no_qualifying_drops_gives_bit_identical_frames():
    prof = small_profile(160, 120, noise_sigma_dn=2.0)       # gauge-default scaled: drops <= ~1 px wide
    on, t_on = render_clip(prof, n_frames=6, rain_rate_mm_h=25.0, seed=3, closeup=True, return_drops=True,
                           closeup_light=BACKLIGHT)
    off, t_off = render_clip(prof, n_frames=6, rain_rate_mm_h=25.0, seed=3, return_drops=True)
    assert sum(len(fr["drops"]) for fr in t_on["frames"]) > 50
    np.testing.assert_array_equal(on, off)
    assert t_on["rain_rate_mm_h"] == t_off["rain_rate_mm_h"]
    assert "closeup" not in t_off["rendering"] and "closeup" in t_on["rendering"]


def test_cli_closeup_options(tmp_path, capsys):
    out = tmp_path / "rain.mkv"
    assert main(["simulate", str(out), "--seconds", "0.1", "--rate", "5", "--size", "96x64",
                 "--closeup", "--light-theta", "150", "--light-phi", "90"]) == 0
    import json

    truth = json.loads((tmp_path / "rain.mkv.truth.json").read_text())
    assert truth["rendering"]["closeup"]["light_theta_phi_rad"] == pytest.approx(list(BACKLIGHT))
    assert main(["simulate", str(tmp_path / "plain.mkv"), "--seconds", "0.1", "--rate", "5",
                 "--size", "96x64", "--no-closeup"]) == 0
    truth = json.loads((tmp_path / "plain.mkv.truth.json").read_text())
    assert "closeup" not in truth["rendering"]
    from raingauge.errors import RaingaugeError

    with pytest.raises(RaingaugeError):
        simulate(_near_profile(), n_frames=1, rain_rate_mm_h=1.0, closeup=True, closeup_light=(1.0,))
