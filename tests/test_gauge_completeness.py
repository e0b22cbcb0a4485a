"""The completeness probe: artificial drops in the gauge's own frames measure how it reads
the rain of each drop size in the scene, and correct the sample volume by it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raingauge.gauge import RainGauge
from raingauge.gauge.completeness import CLASS_EDGES_M, CompletenessProbe
from raingauge.gauge.volume import SampleVolume
from raingauge.profile import default_profile

CAM = default_profile().replace(width_px=320, height_px=240)


@pytest.fixture(scope="module")
def volume():
    return SampleVolume(CAM, velocity_model="gunn_kinzer")


def _probe(volume, **kw):
    return CompletenessProbe(CAM, volume, "gunn_kinzer", **kw)


def test_depth_span_holds_the_sample_volume(volume):
    """kappa(a) integrates p(a, z) (z / f)^2 over the depth span: a drop passes nowhere
    outside it, and the span narrows around z0 for smaller drops (less blur tolerated)."""
    z0 = CAM.focus_distance_m
    a = np.array([0.3e-3, 0.6e-3, 1.2e-3])
    near, far = volume.depth_span(a)
    assert np.all(near < z0) and np.all(far > z0)
    assert np.all(np.diff(far - near) > 0)
    from raingauge.gauge.volume import pass_probability

    for ai, lo, hi in zip(a, near, far):
        z_out = np.array([0.9 * lo, 1.1 * hi])
        p = pass_probability(float(ai), z_out, CAM, velocity_model="gunn_kinzer", contrast_dn=160.0)["p"]
        assert np.all(p < 1e-2)


@pytest.mark.parametrize("a_mm, contrast, noise", [(0.5, 160.0, None), (0.9, 60.0, 3.3), (0.33, 100.0, 2.4)])
def test_pass_probability_table_matches_the_model(volume, a_mm, contrast, noise):
    """The volume's tabulated p(a, z, C, sigma) agrees with :func:`pass_probability`
    evaluated directly, and integrates back to kappa."""
    from raingauge.gauge.volume import pass_probability

    a = a_mm * 1e-3
    near, far = volume.depth_span(a)
    z = np.linspace(float(near), float(far), 41)
    direct = pass_probability(a, z, CAM, velocity_model="gunn_kinzer", contrast_dn=contrast,
                              noise_sigma_dn=noise if noise is not None else CAM.noise_sigma_dn)["p"]
    table = np.array([volume.pass_probability_at(a, zi, contrast, noise) for zi in z])
    assert np.max(np.abs(table - direct)) < 0.05 + 0.1 * direct.max()
    f = CAM.focal_length_px
    kap = np.trapezoid(table * (z / f) ** 2, z)
    assert kap == pytest.approx(float(volume.kappa(a, contrast_dn=contrast, noise_dn=noise)), rel=0.15)


def test_pass_probability_over_pixels_is_their_mean(volume):
    """p averaged over the pixels behind a drop through their contrast weights (the average
    kappa makes over a frame) is the mean of p over the pixels, taken one by one; a
    uniform background gives p at its contrast, and pixels darker than the drop's
    brightness by less than the grid's lowest contrast hide it."""
    a, z, noise = 0.7e-3, CAM.focus_distance_m * 1.01, 1.5
    rng = np.random.default_rng(3)
    contrasts = np.concatenate([rng.uniform(25.0, 180.0, 200), [1.0, 2.0]])
    one_by_one = np.mean([volume.pass_probability_at(a, z, c, noise) for c in contrasts])
    over = volume.pass_probability_over(a, z, volume.contrast_weights(contrasts), noise)
    assert over == pytest.approx(one_by_one, rel=1e-9, abs=1e-12)
    assert volume.pass_probability_over(a, z, volume.contrast_weights([90.0]), noise) == pytest.approx(
        volume.pass_probability_at(a, z, 90.0, noise), rel=1e-9)
    # p is not linear in the contrast: the mean over a two-level background differs from
    # p at its mean contrast
    two = volume.contrast_weights([30.0, 150.0])
    mixed = volume.pass_probability_over(a, z, two, noise)
    assert mixed == pytest.approx(0.5 * (volume.pass_probability_at(a, z, 30.0, noise)
                                         + volume.pass_probability_at(a, z, 150.0, noise)), rel=1e-9)
    assert abs(mixed - volume.pass_probability_at(a, z, 90.0, noise)) > 0.01


def test_plan_keeps_clear_of_detected_streaks(volume):
    probe = _probe(volume, per_frame=12)
    occupied = np.zeros(CAM.shape, bool)
    occupied[:, 150:] = True
    plan = probe.plan(CAM.shape, occupied, slope=0.1)
    assert len(plan) >= 6
    from raingauge.gauge.completeness import CLEARANCE_PX

    for p in plan:
        x0, y0, cw, ch = p["box"]
        # the streak and its clearance are clear of the detected streaks
        (xa, ya), (xb, yb) = p["p0"], p["p1"]
        reach = p["radius_px"] + CLEARANCE_PX
        assert max(xa, xb) + reach < 150
        assert not occupied[int(ya - reach):int(yb + reach) + 1, int(min(xa, xb) - reach):int(max(xa, xb) + reach) + 1].any()
        # the streak lies inside its crop, along the rain's direction
        assert (xb - xa) == pytest.approx(0.1 * (yb - ya))
        assert y0 + p["radius_px"] < ya < yb < y0 + ch - p["radius_px"]
        lo, hi = CLASS_EDGES_M[p["class"]], CLASS_EDGES_M[p["class"] + 1]
        assert lo <= p["radius_m"] <= hi
    full = probe.plan(CAM.shape, np.ones(CAM.shape, bool), slope=0.0)
    assert full == []
    # in wind each drop slants by its drift over its own fall speed: small drops more
    windy = probe.plan(CAM.shape, np.zeros(CAM.shape, bool), slope=0.0, drift_m_s=2.0)
    for p in windy:
        (xa, ya), (xb, yb) = p["p0"], p["p1"]
        assert (xb - xa) / (yb - ya) == pytest.approx(2.0 / p["velocity_m_s"])


def test_canvas_adds_the_eq17_streak_to_frame_n_only(volume):
    """Frames n-1 and n+1 are copied unchanged; frame n gains beta (E_r - I_b), whose sum
    over the streak is its exposure area pi a_i^2 times the contrast (Eqs. 15-17)."""
    rng = np.random.default_rng(1)
    probe = _probe(volume, per_frame=5)
    bg = rng.uniform(30.0, 90.0, CAM.shape).astype(np.float32)
    plan = probe.plan(CAM.shape, np.zeros(CAM.shape, bool), slope=0.0)
    lin, raw, centres = probe.canvas((bg, bg, bg), plan, 200.0)
    assert raw is None and len(centres) == len(plan)
    prev, cur, nxt = lin
    assert np.array_equal(prev, nxt)
    change = cur - prev
    assert change.min() >= -1e-4
    x = 2
    for p, (cx, cy) in zip(plan, centres):
        x0, y0, cw, ch = p["box"]
        assert np.array_equal(prev[:ch, x:x + cw], bg[y0:y0 + ch, x0:x0 + cw])
        part = change[:ch, x:x + cw]
        contrast = 200.0 - prev[:ch, x:x + cw]
        beta = part / contrast
        assert beta.sum() == pytest.approx(p["area_px"], rel=1e-3)
        # the streak is centred where the canvas says
        yy, xx = np.nonzero(beta > 0)
        assert np.average(xx + x, weights=beta[yy, xx]) == pytest.approx(cx, abs=0.05)
        assert np.average(yy, weights=beta[yy, xx]) == pytest.approx(cy, abs=0.05)
        x += cw + 2


def test_correction_is_one_until_mature_then_the_measured_ratio(volume):
    probe = _probe(volume, per_frame=16, min_injections=200)
    occupied = np.zeros(CAM.shape, bool)
    f = CAM.focal_length_px
    while not probe.mature:
        # a gauge that reads drops below 0.6 mm radius at half their rain, the others fully
        assert float(probe.correction(0.3e-3)) == 1.0
        plan = probe.plan(CAM.shape, occupied, slope=0.0)
        assert plan
        expected = np.array([(2 * p["radius_m"]) ** 3 * p["velocity_m_s"] / ((p["depth_m"] / f) ** 2 * p["span_m"])
                             for p in plan])
        est = np.array([0.5 if p["radius_m"] < 0.6e-3 else 1.0 for p in plan]) * expected
        probe.record(plan, est, expected, np.full(len(plan), 0.3))
    assert 200 <= probe.injected < 216
    ratio, n = probe.class_ratios()
    live = n > 0
    centres = np.sqrt(CLASS_EDGES_M[:-1] * CLASS_EDGES_M[1:])
    expect = np.where(CLASS_EDGES_M[1:] <= 0.6e-3, 0.5, 1.0)
    # shrunk toward the pooled ratio by 30 injections in ~30 per class
    assert np.all(np.abs(ratio[live] - expect[live]) < 0.3)
    big = live & (CLASS_EDGES_M[:-1] >= 0.6e-3)
    assert np.all(ratio[big] > 0.9)
    assert float(probe.correction(centres[big][-1])) == pytest.approx(ratio[big][-1])
    fresh = _probe(volume)
    assert float(fresh.correction(1e-3)) == 1.0


def test_relative_error_of_the_correction_is_the_ratio_estimators(volume):
    """Drops counted at twice their expectation half of the time (ratio 1): the relative
    standard error of each class is ~1/sqrt(n), and a rate spread over k classes gets
    1/sqrt(k) of it."""
    rng = np.random.default_rng(3)
    probe = _probe(volume, per_frame=16, min_injections=100, history=20000)
    while probe.injected < 6000:
        plan = probe.plan(CAM.shape, np.zeros(CAM.shape, bool), slope=0.0)
        expected = np.ones(len(plan))
        est = 2.0 * (rng.random(len(plan)) < 0.5) * expected
        # the log holds dv-weighted values: give every drop the same volume element
        for p in plan:
            p["depth_m"], p["span_m"] = CAM.focal_length_px, 1.0
        probe.record(plan, est, expected, np.full(len(plan), 0.5))
    ratio, n = probe.class_ratios()
    rel = probe.class_relative_sd()
    live = n > 0
    assert np.all(np.abs(ratio[live] - 1.0) < 4.0 * rel[live] + 0.02)
    assert rel[live] == pytest.approx(1.0 / np.sqrt(n[live]), rel=0.15)
    k = int(live.sum())
    centres = np.sqrt(CLASS_EDGES_M[:-1] * CLASS_EDGES_M[1:])[live]
    spread = probe.rate_relative_sd(centres, np.ones(k))
    assert spread == pytest.approx(float(np.sqrt(np.sum(rel[live] ** 2)) / k), rel=1e-9)
    assert probe.rate_relative_sd([centres[-1]], [1.0]) == pytest.approx(float(rel[live][-1]))


def test_probe_leaves_a_dark_uniform_scene_alone():
    """Where the model of the sample volume holds (a dark, uniform, still scene), the probe
    finds the gauge reads the injected drops of every size as the model expects (which
    checks the model of detection, measurement and sizing against the rendered streaks)."""
    sim = pytest.importorskip("raingauge.render.simulator")
    cam = CAM.replace(noise_sigma_dn=1.0)
    frames, truth = sim.render_clip(cam, seconds=12.0, rain_rate_mm_h=20.0, seed=5, background="uniform:40")
    g = RainGauge(cam, window_s=12.0, step_s=12.0, velocity_model="gunn_kinzer")
    for fr in frames:
        g.process(fr)
    g.flush()
    assert g.probe.injected > 600
    ratio, n = g.probe.class_ratios()
    live = n > 0
    assert live.sum() >= 5
    assert np.all((ratio[live] > 0.8) & (ratio[live] < 1.2))


def test_probe_slants_its_first_drops_with_the_wind():
    """The first injections come before any drop is counted (the drops wait for the probe to
    mature): in a cross wind they already drift at the speed the law-abiding streaks measure,
    each slanted by drift / v(a) as the real drops are, the small ones most; not all at one
    direction, which would slant the small drops too little and find them too easily."""
    sim = pytest.importorskip("raingauge.render.simulator")
    from raingauge.physics.drops import fall_velocity

    cam = CAM.replace(noise_sigma_dn=1.0)
    frames, truth = sim.render_clip(cam, seconds=8.0, rain_rate_mm_h=30.0, seed=3, background="uniform:40",
                                    wind_m_s=3.0)
    g = RainGauge(cam, window_s=8.0, step_s=8.0, velocity_model="gunn_kinzer")
    first = []
    plan = g.probe.plan

    def spy(shape, occupied, slope, drift_m_s=None):
        out = plan(shape, occupied, slope, drift_m_s=drift_m_s)
        if not first and out and g.probe.injected == 0:
            first.append((drift_m_s, out))
        return out

    g.probe.plan = spy
    for fr in frames:
        g.process(fr)
        if first:
            break
    assert first, "the probe never ran before the first drop was counted"
    drift, out = first[0]
    assert drift == pytest.approx(3.0, rel=0.15)
    for p in out:
        slant = (p["p1"][0] - p["p0"][0]) / (p["p1"][1] - p["p0"][1])
        v = float(fall_velocity(2 * p["radius_m"], model="gunn_kinzer"))
        assert slant == pytest.approx(drift / v, rel=1e-6)
    slants = [(p["p1"][0] - p["p0"][0]) / (p["p1"][1] - p["p0"][1]) for p in out]
    assert max(slants) > 1.5 * min(slants)


def test_probe_corrects_a_textured_scene():
    """Over a textured photograph streaks cross changing backgrounds and are detected in
    pieces the model of a locally uniform background does not foresee: without the probe
    the gauge reads low; the probe measures the loss and the reading comes back."""
    sim = pytest.importorskip("raingauge.render.simulator")
    cam = CAM.replace(noise_sigma_dn=1.0)
    frames, truth = sim.render_clip(cam, seconds=15.0, rain_rate_mm_h=30.0, seed=1, background="skimage:coffee")
    true = truth["rain_rate_mm_h"]
    reads = {}
    for probe in (False, True):
        g = RainGauge(cam, window_s=15.0, step_s=15.0, velocity_model="gunn_kinzer", completeness_probe=probe)
        recs = []
        for fr in frames:
            recs += g.process(fr)
        recs += g.flush()
        reads[probe] = recs[-1]["rain_rate_mm_h"] / true
        if probe:
            ratio, n = g.probe.class_ratios()
            big = (CLASS_EDGES_M[:-1] >= 0.6e-3) & (n > 0)
            assert np.all(ratio[big] < 0.95)
    assert reads[False] < 0.85
    assert abs(reads[True] - 1.0) < abs(reads[False] - 1.0)
    assert reads[True] == pytest.approx(1.0, abs=0.25)


def test_probe_is_deterministic_and_optional():
    sim = pytest.importorskip("raingauge.render.simulator")
    frames, _ = sim.render_clip(CAM, seconds=3.0, rain_rate_mm_h=30.0, seed=2)
    out = []
    for _ in range(2):
        g = RainGauge(CAM, window_s=3.0, step_s=3.0)
        recs = [r for fr in frames for r in g.process(fr)] + g.flush()
        out.append(recs[-1]["rain_rate_mm_h"])
    assert out[0] == out[1]
    g = RainGauge(CAM, completeness_probe=False)
    assert g.probe is None
    with pytest.raises(ValueError, match="per_frame"):
        CompletenessProbe(CAM, g.volume, "gunn_kinzer", per_frame=0)
    assert math.isfinite(out[0])
