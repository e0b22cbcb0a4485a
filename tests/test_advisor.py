"""The camera-parameter advisor: Table 1, Fig. 16, constraints, the gauge goal [GargNayar2007]."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from raingauge import advisor
from raingauge.advisor import Scene, Settings
from raingauge.cli import main
from raingauge.errors import ConfigError
from raingauge.physics import camera, drops
from raingauge.profile import load_profile


@pytest.fixture(scope="module")
def xl1():
    # f = 8000 px (the long end of the XL1 zoom, as in Figs. 15(b, c)), pitch 6.7 um
    return load_profile("canon_xl1")


@pytest.fixture(scope="module")
def table(xl1):
    return advisor.table1(xl1)


def test_rain_visible_limit_is_note27(xl1):
    # note 27: R z_m ~ 24 m for the Canon XL1
    assert advisor.rain_visible_limit_m(xl1) == pytest.approx(24.0)
    close = advisor.make_scene(xl1, near="close")
    far = advisor.make_scene(xl1, near="far")
    assert close.near_m < 24.0 < far.near_m


# Table 1 of the paper, rows (a)-(h): exposure [ms] and F-number, or X
@pytest.mark.parametrize("row", list("abcdefgh"))
def test_table1_rows(table, row):
    motion, near, depth, t_paper, n_paper = advisor.TABLE1_ROWS[row]
    advice = table[row]
    if t_paper is None:
        assert not advice.feasible and advice.reason.startswith("X")
        assert advice.to_dict()["exposure_s"] is None
        return
    assert advice.feasible
    s = advice.settings
    # 1/15 s, 1/30 s and 1/125 s against the table's 66, 33 and 8 ms
    assert s.exposure_s == pytest.approx(t_paper, rel=0.02)
    # the F-number follows from the depth of field; row (h) lists 2.4 where the same
    # scene geometry gives 2.0 in row (d), so it gets a wider tolerance
    assert s.f_number == pytest.approx(n_paper, rel=0.2 if row == "h" else 0.06)


# Fig. 16 (I)-(IV): (current, new) settings, the paper's predicted and measured (+- margin) factors
FIG16 = {
    "I":   (Settings(0.008, 12.0, 100.0), Settings(0.008, 2.4, 100.0), 0.4944, 0.4541, 0.0884),
    "II":  (Settings(0.016, 14.0, 10.0), Settings(0.066, 14.0, 10.0), 0.5, 0.4615, 0.0818),
    "III": (Settings(0.016, 12.0, 50.0), Settings(0.033, 6.0, 50.0), 0.4944, 0.5496, 0.094),
    "IV":  (Settings(0.016, 4.0, 10.0), Settings(0.120, 4.0, 10.0), 0.3536, 0.3763, 0.0824),
}


@pytest.mark.parametrize("scenario", list(FIG16))
def test_fig16_predicted_reduction_within_measured_margin(xl1, scenario):
    current, new, paper_pred, measured, margin = FIG16[scenario]
    factor = advisor.reduction_factor(xl1, current, new)
    print(f"Fig. 16({scenario}): predicted {factor:.4f}, paper predicted {paper_pred}, "
          f"measured {measured} +- {margin}")
    assert measured - margin <= factor <= measured + margin


def test_fig16_exposure_scenarios_are_pure_square_roots(xl1):
    # only T changes in (II) and (IV): the factor is sqrt(T_old / T_new) exactly
    for key in ("II", "IV"):
        cur, new = FIG16[key][:2]
        assert advisor.reduction_factor(xl1, cur, new) == pytest.approx(math.sqrt(cur.exposure_s / new.exposure_s))


SCENES = [Scene(40.0, 30.0, 15.0), Scene(5.0, 8.0, 4.0), Scene(2.0, 60.0, math.inf), Scene(100.0, 50.0, 10.0)]


@pytest.mark.parametrize("scene", SCENES)
def test_advice_keeps_the_scene_sharp_and_is_optimal(xl1, scene):
    a = advisor.advise_reduce(xl1, scene)
    assert a.feasible, a.reason
    s = a.settings
    assert scene.motion_px_s * s.exposure_s <= 1.0 + 1e-9
    near, far = camera.depth_of_field_m(focal_length_px=xl1.focal_length_px, f_number=s.f_number,
                                        focus_distance_m=s.focus_distance_m, pixel_pitch_m=xl1.pixel_pitch_m)
    assert near <= scene.near_m * (1 + 1e-6) and far >= scene.far_m * (1 - 1e-6)
    assert xl1.exposure_range_s[0] <= s.exposure_s <= xl1.exposure_range_s[1]
    assert xl1.f_number_range[0] <= s.f_number <= xl1.f_number_range[1]
    # Eq. (20): the gain change keeps k pi T / (4 N^2)
    k_ratio = (s.f_number**2 / s.exposure_s) / (xl1.f_number**2 / xl1.exposure_s)
    assert a.gain_change_db == pytest.approx(20 * math.log10(k_ratio))
    # no randomly drawn sharp setting at the same exposure shows less rain
    rng = np.random.default_rng(1)
    best = a.sigma_r
    tried = 0
    z_span = np.log([scene.near_m, min(scene.far_m, xl1.focus_range_m[1])])
    for _ in range(1500):
        n = float(np.exp(rng.uniform(*np.log(xl1.f_number_range))))
        z0 = float(np.exp(rng.uniform(*z_span)))  # a sharp focus lies inside the scene
        lo, hi = camera.depth_of_field_m(focal_length_px=xl1.focal_length_px, f_number=n, focus_distance_m=z0,
                                         pixel_pitch_m=xl1.pixel_pitch_m)
        if lo > scene.near_m or hi < scene.far_m:
            continue
        tried += 1
        other = advisor.sigma_r_for(xl1, Settings(s.exposure_s, n, z0))
        assert other >= best * (1 - 1e-6)
    assert tried > 20


def test_slow_shutter_policy(xl1):
    small = Scene(5.0, 30.0, 10.0)
    auto = advisor.advise_reduce(xl1, small)
    assert auto.settings.exposure_s == pytest.approx(xl1.frame_interval_s)
    assert auto.effective_frame_rate_hz == pytest.approx(xl1.frame_rate_hz)
    always = advisor.advise_reduce(xl1, small, slow_shutter="always")
    assert always.settings.exposure_s == pytest.approx(xl1.exposure_range_s[1])   # 125 ms, 5 px/s allows 200
    assert always.predicted_reduction == pytest.approx(auto.predicted_reduction * math.sqrt(1 / 30 / 0.125))
    heavy = advisor.advise_reduce(xl1, small, rain_rate_mm_h=40.0)                 # Fig. 16(IV)
    assert heavy.settings.exposure_s == pytest.approx(0.125)
    never = advisor.advise_reduce(xl1, advisor.make_scene(xl1, motion="slow", near="close", depth="large"),
                                  slow_shutter="never")
    assert never.settings.exposure_s <= xl1.frame_interval_s + 1e-12
    with pytest.raises(ConfigError, match="auto, always, never"):
        advisor.advise_reduce(xl1, small, slow_shutter="sometimes")


def test_infeasible_answers(xl1):
    too_fast = advisor.advise_reduce(xl1, Scene(1000.0, 50.0, 10.0))     # needs T <= 1 ms < 4 ms
    assert not too_fast.feasible and "shortest" in too_fast.reason
    too_deep = advisor.advise_reduce(xl1, Scene(5.0, 1.0, math.inf))     # 1 m to the horizon at f = 54 mm
    assert not too_deep.feasible and "depth of field" in too_deep.reason


def test_scene_input_errors(xl1):
    with pytest.raises(ConfigError, match="slow, fast"):
        advisor.make_scene(xl1, motion="quick")
    with pytest.raises(ConfigError, match=">= 0"):
        advisor.make_scene(xl1, near=-3)
    scene = advisor.make_scene(xl1, motion="12", near="30", depth="inf")
    assert (scene.motion_px_s, scene.near_m, scene.depth_m) == (12.0, 30.0, math.inf)


# ------------------------------------------------------------------- gauge
def test_gauge_settings_follow_sec8(xl1):
    g = advisor.advise_gauge(xl1)
    s = g.settings
    assert s.focus_distance_m <= 2 * xl1.focal_length_px * 0.5e-3 + 1e-9       # z0 <= 2 f a_min
    assert s.f_number == xl1.f_number_range[0]                                  # shallow depth of field
    assert s.exposure_s == xl1.exposure_range_s[0]                              # short exposure (4 ms)
    d = g.to_dict()
    assert d["sample_volume_m3"] > 0 and d["feasible"]
    vols = [c["volume_m3"] for c in d["per_class"] if c["d_mm"] > 1.0]
    assert np.all(np.diff(vols) > 0)                  # bigger drops are sized over a deeper range
    assert all(c["volume_m3"] == 0 for c in d["per_class"] if c["d_mm"] < 1.0)   # below a_min: not sized
    counts = d["counting"]
    assert [c["rain_rate_mm_h"] for c in counts] == [1.0, 10.0, 50.0]
    per_min = [c["drops_per_minute"] for c in counts]
    unc = [c["rate_rel_uncertainty"] for c in counts]
    assert per_min[0] < per_min[1] < per_min[2]
    assert unc[0] > unc[1] > unc[2] > 0


def test_gauge_sample_volume_by_independent_integration(xl1):
    s = Settings(0.004, 1.6, 8.0)
    d = 2.375e-3
    vol, area, z_lo, z_hi = advisor.gauge_sample_volumes(xl1, s, [d])
    # depths where the blur circle is at most the focused width 2 f a / z (and that width >= 1 px)
    z = np.linspace(1.0, 20.0, 400001)
    b = camera.blur_circle_px(z, focal_length_px=xl1.focal_length_px, f_number=1.6, focus_distance_m=8.0,
                              pixel_pitch_m=xl1.pixel_pitch_m)
    w = 2 * xl1.focal_length_px * (d / 2) / z
    ok = (b <= w) & (w >= 1)
    dz = z[1] - z[0]
    frustum = xl1.width_px * xl1.height_px * z**2 / xl1.focal_length_px**2
    assert vol[0] == pytest.approx(np.sum(frustum[ok]) * dz, rel=1e-3)
    assert z_lo[0] == pytest.approx(z[ok].min(), abs=1e-3) and z_hi[0] == pytest.approx(z[ok].max(), abs=1e-3)


def test_gauge_counting_uncertainty_is_poisson(xl1):
    # one class, checked by drawing Poisson counts
    s = Settings(0.004, 1.6, 8.0)
    out = advisor.gauge_counting(xl1, s, 10.0, window_s=60.0)
    centres = drops.PARSIVEL_D_CENTRES_MM * 1e-3
    widths = drops.PARSIVEL_D_WIDTHS_MM * 1e-3
    keep = (centres >= 1e-4) & (centres <= drops.DEFAULT_D_MAX_M)
    c, w = centres[keep], widths[keep]
    _, area, _, _ = advisor.gauge_sample_volumes(xl1, s, c)
    v = drops.fall_velocity(c, model="gunn_kinzer")
    lam = drops.MarshallPalmer(10.0).number_density(c) * w * v * area * 60.0
    per = np.where(area > 0, 3.6e6 * np.pi / 6 * c**3 / np.where(area > 0, area, 1) / 60.0, 0.0)
    rng = np.random.default_rng(0)
    rates = (rng.poisson(lam, size=(4000, lam.size)) * per).sum(axis=1)
    assert out["rate_measured_mm_h"] == pytest.approx(rates.mean(), rel=0.01)
    assert out["rate_rel_uncertainty"] == pytest.approx(rates.std() / rates.mean(), rel=0.05)
    assert out["drops_per_minute"] == pytest.approx(lam.sum(), rel=1e-9)


# ----------------------------------------------------------------- command
def test_advise_command_json(capsys):
    assert main(["advise", "--camera", "canon_xl1", "--goal", "reduce", "--motion", "slow", "--near", "far",
                 "--depth", "small", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    for key in ("exposure_s", "f_number", "focus_distance_m", "predicted_reduction", "feasible", "reason"):
        assert key in rec
    assert rec["feasible"] and rec["exposure_s"] == pytest.approx(1 / 30)
    assert main(["advise", "--camera", "canon_xl1", "--goal", "reduce", "--motion", "fast", "--near", "close",
                 "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["feasible"] is False and rec["reason"].startswith("X")
    assert main(["advise", "--camera", "canon_xl1", "--goal", "gauge", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["sample_volume_m3"] > 0 and rec["focus_distance_m"] == pytest.approx(8.0)


def test_advise_command_errors(capsys):
    assert main(["advise", "--camera", "canon_xl1", "--motion", "zippy"]) == 2
    assert "slow, fast" in capsys.readouterr().err
    assert main(["advise", "--camera", "gauge-default", "--goal", "gauge", "--a-min-mm", "-1"]) == 2
    assert "--a-min-mm" in capsys.readouterr().err


@pytest.mark.parametrize("args, message", [
    (["--near", "inf"], "finite number of metres"),
    (["--near", "0"], "finite number of metres"),
    (["--motion", "nan"], "scene motion"),
    (["--depth", "-1"], "depth range"),
    (["--rain-rate", "-3"], "--rain-rate"),
    (["--rain-rate", "abc"], "invalid float value: 'abc'"),
    (["--goal", "gauge", "--a-min-mm", "nan"], "--a-min-mm"),
    (["--camera", "no-such-camera"], "no-such-camera"),
])
def test_advise_command_bad_input(cli_error, args, message):
    argv = ["advise", *args] if args[0] == "--camera" else ["advise", "--camera", "canon_xl1", *args]
    cli_error(argv, message)
