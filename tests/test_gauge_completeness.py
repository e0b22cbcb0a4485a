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


def test_plan_places_drops_uniformly_along_the_rain(volume):
    """The drops land anywhere in the frame, as real drops do (no place is kept from them,
    not even frame n's streaks), each inside its crop, along the rain's direction, in its
    radius class."""
    probe = _probe(volume, per_frame=12)
    M, N = CAM.shape
    xs, ys = [], []
    for _ in range(60):
        for p in probe.plan(CAM.shape, slope=0.1):
            x0, y0, cw, ch = p["box"]
            (xa, ya), (xb, yb) = p["p0"], p["p1"]
            assert (xb - xa) == pytest.approx(0.1 * (yb - ya))
            assert y0 + p["radius_px"] < ya < yb < y0 + ch - p["radius_px"]
            assert x0 >= 1 and y0 >= 1 and x0 + cw < N and y0 + ch < M
            lo, hi = CLASS_EDGES_M[p["class"]], CLASS_EDGES_M[p["class"] + 1]
            assert lo <= p["radius_m"] <= hi
            xs.append(p["centre"][0])
            ys.append(p["centre"][1])
    xs = np.asarray(xs)
    assert xs.size >= 400
    # the centres fill the frame's width evenly (a crop keeps its streak off the borders)
    counts, _ = np.histogram(xs, bins=4, range=(0.0, N))
    assert counts.min() > 0.75 * counts.mean()
    assert np.ptp(ys) > 0.5 * M
    # in wind each drop slants by its drift over its own fall speed: small drops more
    windy = probe.plan(CAM.shape, slope=0.0, drift_m_s=2.0)
    assert windy
    for p in windy:
        (xa, ya), (xb, yb) = p["p0"], p["p1"]
        assert (xb - xa) / (yb - ya) == pytest.approx(2.0 / p["velocity_m_s"])


def test_probe_meets_the_rain_of_all_three_frames(volume):
    """Frames n-1 and n+1 hold rain over the left half of the frame (a drop of frame n is
    hidden there by the three-frame test); frame n holds streaks 3 px wide every 24 columns
    over the right half.  An injected drop is found where a real drop of frame n would be:
    in the right half, unless its streak touches one of frame n's (the merge the probe
    measures for the gauge); never in the left half."""
    from raingauge.gauge.streaks import detect_streaks, spike_image

    rng = np.random.default_rng(2)
    M, N = CAM.shape
    base = (40.0 + rng.standard_normal((3, M, N))).astype(np.float32)
    prev, cur, nxt = base
    prev[:, :N // 2] += 150.0
    nxt[:, :N // 2] += 150.0
    rain = np.zeros(N, bool)
    for x in range(N // 2 + 10, N - 3, 24):
        rain[x:x + 3] = True
    cur[:, rain] += 150.0
    probe = _probe(volume, per_frame=16)
    found = touching = free = total = 0
    agree = 0
    for _ in range(10):
        plan = [p for p in probe.plan(CAM.shape, slope=0.0) if p["radius_m"] > 0.4e-3]
        lin, _raw, centres = probe.canvas((prev, cur, nxt), plan, 220.0, noise_dn=1.0)
        labels, stats = detect_streaks(spike_image(*lin), c=3.0)
        for p, (cx, cy) in zip(plan, centres):
            total += 1
            lab = labels[int(round(cy)), int(round(cx))]
            x = p["centre"][0]
            # found whole: its component holds none of frame n's rain columns
            ox = int(round(cx - x))
            hit = bool(lab > 0 and stats[lab, 4] >= 6
                       and not rain[max(stats[lab, 0] - ox, 0):max(stats[lab, 0] + stats[lab, 2] - ox, 0)].any())
            r = p["radius_px"] + 1.0
            touches = bool(rain[max(int(math.floor(x - r)), 0):int(math.floor(x + r)) + 1].any())
            visible = x > N // 2 + 2 and not touches
            touching += x > N // 2 + 2 and touches
            free += visible
            found += hit
            agree += hit == visible
    assert total >= 60 and touching >= 0.2 * total and free >= 0.2 * total
    assert agree >= 0.9 * total
    assert found == pytest.approx(free, abs=0.08 * total)


def test_blobs_are_the_drops_components_and_the_frames_streaks_merged_in_them(volume):
    """Each injected drop lies in the canvas component its axis crosses; the frame's streaks
    under that component are its partners: the rain column a drop touches, none for a drop
    clear of the rain.  The compiled loop gives the reference's labels."""
    from raingauge.gauge import _kernels
    from raingauge.gauge.streaks import detect_streaks, spike_image

    rng = np.random.default_rng(2)
    M, N = CAM.shape
    prev, cur, nxt = (40.0 + rng.standard_normal((3, M, N))).astype(np.float32)
    rain = np.zeros(N, bool)
    for x in range(10, N - 3, 24):
        rain[x:x + 3] = True
    cur[:, rain] += 150.0
    frame_labels, _ = detect_streaks(spike_image(prev, cur, nxt), c=3.0)
    probe = _probe(volume, per_frame=16)
    touching = clear = 0
    for _ in range(6):
        plan = [p for p in probe.plan(CAM.shape, slope=0.0) if p["radius_m"] > 0.4e-3]
        lin, _raw, centres = probe.canvas((prev, cur, nxt), plan, 220.0, noise_dn=1.0)
        labels, stats = detect_streaks(spike_image(*lin), c=3.0)
        blob, partners = CompletenessProbe.blobs(labels, stats, frame_labels, plan, engine="arrays")
        if _kernels.AVAILABLE:
            blob2, partners2 = CompletenessProbe.blobs(labels, stats, frame_labels, plan, engine="compiled")
            np.testing.assert_array_equal(blob2, blob)
            assert partners2 == partners
        for j, (p, (cx, cy)) in enumerate(zip(plan, centres)):
            at_centre = labels[int(round(cy)), int(round(cx))]
            if at_centre > 0:
                assert blob[j] == at_centre
            else:
                # a faint defocused drop found only in pieces: the piece on its axis, if any
                (x0, y0), (x1, y1) = (np.array(q) + (np.array(cx_cy) - np.array(p["centre"]))
                                      for q, cx_cy in ((p["p0"], (cx, cy)), (p["p1"], (cx, cy))))
                ys = np.arange(int(math.ceil(y0)), int(math.floor(y1)) + 1)
                on_axis = set(labels[ys, np.rint(x0 + (ys - y0) * (x1 - x0) / max(y1 - y0, 1e-9)).astype(int)].tolist())
                assert blob[j] == 0 or blob[j] in on_axis
            # the rain columns under the drop's capsule, and those near it
            x, r = p["centre"][0], p["radius_px"]
            cols = np.flatnonzero(rain & (np.abs(np.arange(N) - x) <= r - 0.5))
            near = np.flatnonzero(rain & (np.abs(np.arange(N) - x) <= r + 3.0))
            assert 0 not in partners[j] and list(partners[j]) == sorted(set(partners[j]))
            if cols.size:
                touching += 1
                assert {int(frame_labels[M // 2, c]) for c in cols} <= set(partners[j])
            elif near.size == 0:
                clear += 1
                assert partners[j] == ()
    assert touching >= 10 and clear >= 10


def test_a_drop_merged_with_a_streak_the_crop_cuts_is_lost(volume):
    """In the canvas a long streak of the frame is cut to its crop, and a drop merged with
    it looks smaller than the blob the frame holds: every component reaching its crop's
    border is marked (the gauge drops them), the injected streaks alone are not."""
    from raingauge.gauge.completeness import CompletenessProbe
    from raingauge.gauge.streaks import detect_streaks, spike_image

    rng = np.random.default_rng(4)
    M, N = CAM.shape
    prev, cur, nxt = (40.0 + rng.standard_normal((3, M, N))).astype(np.float32)
    probe = _probe(volume, per_frame=12)
    plan = [p for p in probe.plan(CAM.shape, slope=0.0) if p["radius_m"] > 0.4e-3]
    assert len(plan) >= 4
    # a long streak through the first drop's crop, touching the drop
    x0, y0, cw, ch = plan[0]["box"]
    xs = int(round(plan[0]["centre"][0] + plan[0]["radius_px"])) - 1
    cur[:, xs:xs + 3] += 150.0
    lin, _raw, centres = probe.canvas((prev, cur, nxt), plan, 220.0, noise_dn=1.0)
    labels, stats = detect_streaks(spike_image(*lin), c=3.0)
    cut = CompletenessProbe.cut_components(stats, plan)
    assert not cut[0]
    for i, (p, (cx, cy)) in enumerate(zip(plan, centres)):
        lab = labels[int(round(cy)), int(round(cx))]
        assert lab > 0
        other = (p["box"][0] <= xs + 2 and xs <= p["box"][0] + p["box"][2])
        assert bool(cut[lab]) == (i == 0 or other), i


def test_crops_grow_to_hold_the_frames_streaks_whole(volume):
    """A streak of the frame reaching into a crop is held whole by the grown crop: a drop
    merged with it meets all of it in the canvas, as in the frame, and is not marked cut.
    A blob many times the crop (a moving object) is left cut, and the crops stay inside
    the frame."""
    from raingauge.gauge.streaks import detect_streaks, spike_image

    rng = np.random.default_rng(5)
    M, N = CAM.shape
    prev, cur, nxt = (40.0 + rng.standard_normal((3, M, N))).astype(np.float32)
    probe = _probe(volume, per_frame=12)
    plan = [p for p in probe.plan(CAM.shape, slope=0.0) if p["radius_m"] > 0.4e-3]
    # the first drop with room for the streak above and below its crop
    plan.sort(key=lambda p: not (p["box"][1] >= 30 and p["box"][1] + p["box"][3] <= M - 30))
    assert len(plan) >= 2
    p0, p1 = plan[0], plan[1]
    x0, y0, cw, ch = p0["box"]
    assert y0 >= 30 and y0 + ch <= M - 30
    # a streak touching the first drop, running 15 rows past its crop's top and bottom
    xs = int(round(p0["centre"][0] + p0["radius_px"])) - 1
    top, bottom = y0 - 15, y0 + ch + 15
    cur[top:bottom, xs:xs + 3] += 150.0
    _, stats = detect_streaks(spike_image(prev, cur, nxt), c=3.0)
    boxes = [p["box"] for p in plan]
    probe.enlarge(plan, stats, CAM.shape)
    for p, old in zip(plan, boxes):
        nx, ny, nw, nh = p["box"]
        assert 1 <= nx and 1 <= ny and nx + nw <= N - 1 and ny + nh <= M - 1
        # a grown crop still holds the old one
        assert nx <= old[0] and ny <= old[1] and nx + nw >= old[0] + old[2] and ny + nh >= old[1] + old[3]
    nx, ny, nw, nh = p0["box"]
    assert ny <= top and ny + nh >= bottom
    lin, _raw, centres = probe.canvas((prev, cur, nxt), plan, 220.0, noise_dn=1.0)
    labels, stats_c = detect_streaks(spike_image(*lin), c=3.0)
    cut = CompletenessProbe.cut_components(stats_c, plan)
    lab = labels[int(round(centres[0][1])), int(round(centres[0][0]))]
    assert lab > 0 and not cut[lab]
    # the merged blob spans the streak's rows (the canvas puts the crop's top at row 0)
    assert stats_c[lab, 3] >= bottom - top - 2

    # a blob across the whole frame's width through the second drop's crop is not taken
    # in: it stays cut there
    cur = prev.copy()
    bx0, by0, bcw, bch = p1["box"]
    cur[by0 + 2:by0 + 8, :] += 150.0
    _, stats = detect_streaks(spike_image(prev, cur, nxt), c=3.0)
    assert stats[1:, 2].max() > 4 * bcw
    probe.enlarge([p1], stats, CAM.shape)
    assert p1["box"] == (bx0, by0, bcw, bch)
    lin, _raw, centres = probe.canvas((prev, cur, nxt), [p1], 220.0, noise_dn=1.0)
    labels, stats_c = detect_streaks(spike_image(*lin), c=3.0)
    cut = CompletenessProbe.cut_components(stats_c, [p1])
    lab1 = labels[5, p1["canvas_box"][0] + 1]
    assert lab1 > 0 and cut[lab1]


def test_canvas_adds_the_eq17_streak_to_frame_n_only(volume):
    """Frames n-1 and n+1 are copied unchanged; frame n gains beta (E_r - I_b), whose sum
    over the streak is its exposure area pi a_i^2 times the contrast (Eqs. 15-17)."""
    rng = np.random.default_rng(1)
    probe = _probe(volume, per_frame=5)
    bg = rng.uniform(30.0, 90.0, CAM.shape).astype(np.float32)
    plan = probe.plan(CAM.shape, slope=0.0)
    lin, raw, centres = probe.canvas((bg, bg, bg), plan, 200.0)
    assert raw is None and len(centres) == len(plan)
    prev, cur, nxt = lin
    assert np.array_equal(prev, nxt)
    change = cur - prev
    assert change.min() >= -1e-4
    placed = np.zeros(prev.shape, bool)
    for p, (cx, cy) in zip(plan, centres):
        x0, y0, cw, ch = p["box"]
        x, y, w, h = p["canvas_box"]
        assert (w, h) == (cw, ch)
        # the crops do not overlap, and keep clear of each other (nothing detected between)
        assert not placed[max(y - 2, 0):y + ch + 2, max(x - 2, 0):x + cw + 2].any()
        placed[y:y + ch, x:x + cw] = True
        assert np.array_equal(prev[y:y + ch, x:x + cw], bg[y0:y0 + ch, x0:x0 + cw])
        part = change[y:y + ch, x:x + cw]
        contrast = 200.0 - prev[y:y + ch, x:x + cw]
        beta = part / contrast
        assert beta.sum() == pytest.approx(p["area_px"], rel=1e-3)
        # the streak is centred where the canvas says
        yy, xx = np.nonzero(beta > 0)
        assert np.average(xx + x, weights=beta[yy, xx]) == pytest.approx(cx, abs=0.05)
        assert np.average(yy + y, weights=beta[yy, xx]) == pytest.approx(cy, abs=0.05)
    # nothing changes outside the crops
    assert np.all(change[~placed] == 0)
    # packed in shelves, the canvas is not much larger than its crops
    assert prev.size <= 1.6 * placed.sum()


def test_correction_is_one_until_mature_then_the_measured_ratio(volume):
    probe = _probe(volume, per_frame=16, min_injections=200)
    f = CAM.focal_length_px
    while not probe.mature:
        # a gauge that reads drops below 0.6 mm radius at half their rain, the others fully
        assert float(probe.correction(0.3e-3)) == 1.0
        plan = probe.plan(CAM.shape, slope=0.0)
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
        plan = probe.plan(CAM.shape, slope=0.0)
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
    checks the model of detection, measurement and sizing against the rendered streaks),
    to within the probe's own counting error."""
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
    # within 20 %, or the class's own counting error where it has few drops that pass
    rel = g.probe.class_relative_sd()
    assert np.all(np.abs(ratio[live] - 1.0) < np.maximum(0.2, 2.5 * rel[live]))


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

    def spy(shape, slope, drift_m_s=None):
        out = plan(shape, slope, drift_m_s=drift_m_s)
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
    the gauge reads low; the probe measures the loss and the reading comes back (most of
    the way: on this scene the gauge counts fewer of the drops it can see than the probe's
    drops, README "Known limits")."""
    sim = pytest.importorskip("raingauge.render.simulator")
    cam = CAM.replace(noise_sigma_dn=1.0)
    frames, truth = sim.render_clip(cam, seconds=15.0, rain_rate_mm_h=30.0, seed=1, background="skimage:coffee")
    true = truth["rain_rate_mm_h"]
    reads, ci = {}, {}
    for probe in (False, True):
        g = RainGauge(cam, window_s=15.0, step_s=15.0, velocity_model="gunn_kinzer", completeness_probe=probe)
        recs = []
        for fr in frames:
            recs += g.process(fr)
        recs += g.flush()
        reads[probe] = recs[-1]["rain_rate_mm_h"] / true
        ci[probe] = recs[-1]["rain_rate_ci95_mm_h"]
        if probe:
            ratio, n = g.probe.class_ratios()
            big = (CLASS_EDGES_M[:-1] >= 0.6e-3) & (n > 0)
            assert np.all(ratio[big] < 0.95)
    assert reads[False] < 0.85
    # the probe gives back a large part of what was lost (here over a third), and its
    # interval holds the truth
    assert reads[True] - reads[False] > 0.3 * (1.0 - reads[False])
    assert reads[True] < 1.25
    assert ci[True][0] <= true <= ci[True][1]


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


def test_class_counts_are_the_counted_drops_against_the_models_expectation(volume):
    """Drops of one class counted with a chance of 0.3 where the model says 0.6: the
    count-based completeness counted / expected is 0.5 in it, 1 in the others."""
    rng = np.random.default_rng(8)
    probe = _probe(volume, per_frame=16, min_injections=100, history=20000)
    injected, counted, expected = probe.class_counts()
    assert injected.sum() == 0 and counted.sum() == 0 and expected.sum() == 0
    while probe.injected < 6000:
        plan = probe.plan(CAM.shape, slope=0.0)
        cls = np.array([p["class"] for p in plan])
        chance = np.where(cls == 3, 0.3, 0.6)
        est = (rng.random(len(plan)) < chance).astype(float)
        probe.record(plan, est, np.ones(len(plan)), np.full(len(plan), 0.6))
    injected, counted, expected = probe.class_counts()
    assert injected.sum() == probe.injected and counted.sum() == probe.passed
    live = injected > 0
    assert live[3] and live.sum() >= 3
    ratio = counted[live] / expected[live]
    want = np.where(np.arange(injected.size)[live] == 3, 0.5, 1.0)
    np.testing.assert_allclose(ratio, want, atol=0.12)


def test_canvas_without_the_linear_copies_gives_the_same_8bit_canvas(volume):
    """The gauge of a linear 8-bit camera works on the 8-bit canvases alone and asks for no
    linear ones (``linear=False``): the 8-bit canvases and the streaks' places are those of
    the full call, drawn with the same random numbers."""
    rng = np.random.default_rng(11)
    lin_frames = tuple(rng.uniform(30.0, 120.0, CAM.shape).round().astype(np.float32) for _ in range(3))
    raws = tuple(f.astype(np.uint8) for f in lin_frames)
    outs = []
    for linear in (True, False):
        probe = _probe(volume, per_frame=16, seed=9)
        plan = probe.plan(CAM.shape, slope=0.1)
        outs.append(probe.canvas(lin_frames, plan, 180.0, raws=raws, delinearize=CAM.delinearize,
                                 noise_dn=2.0, linear=linear))
    (lin_a, raw_a, c_a), (lin_b, raw_b, c_b) = outs
    assert lin_b is None and len(lin_a) == 3
    for a, b in zip(raw_a, raw_b):
        np.testing.assert_array_equal(a, b)
    assert c_a == c_b
    assert np.count_nonzero(raw_a[1] != raw_a[0]) > 100
    np.testing.assert_array_equal(lin_a[1], raw_a[1].astype(np.float32))


def test_canvas_rounds_a_faint_streak_once_and_keeps_the_pixels_noise(volume):
    """A linear camera rounds each pixel once.  Frame n's 8-bit copy was rounded already;
    the canvas draws the value within the code's rounding interval before rounding the
    streak again, so a faint streak changes the codes as the camera would have: on average
    by its Eq. (17) change (rounded twice it would be a whole number of gray levels at
    every pixel), and less where the pixel's noise had rounded it up (its value lay in the
    lower part of the code's interval, as the neighbour frames say) than where it had
    rounded it down (drawn uniformly in the interval, as often either way).  Over a noisy
    background the streak pixels keep the frame's noise (I_b + beta (E_r - I_b) alone
    keeps 1 - beta of it)."""
    M, N = CAM.shape
    probe = _probe(volume, per_frame=16, seed=4)
    rng = np.random.default_rng(3)
    flat = np.full(CAM.shape, 100.0, np.float32)
    got, want, up = [], [], []
    for _ in range(12):
        plan = probe.plan(CAM.shape, slope=0.0)
        # the streaks' exact change at E_r = 110 over a flat background: under a gray level
        exact, _r, _c = probe.canvas((flat, flat, flat), plan, 110.0)
        change = exact[1] - 100.0
        # the camera's three frames at 1 gray level of noise, and frame n with the streaks
        # as the camera makes it (the same noise, rounded once)
        x = 100.0 + rng.standard_normal((3, M, N))
        raws = tuple(np.rint(f).astype(np.uint8) for f in x)
        lin, raw, _c = probe.canvas(tuple(r.astype(np.float32) for r in raws), plan, 110.0, raws=raws,
                                    delinearize=CAM.delinearize, noise_dn=1.0)
        # frame n's noisy values where the canvas holds its crops
        x1 = np.zeros(change.shape)
        for p in plan:
            (cx, cy, cw, ch), (bx, by) = p["canvas_box"], p["box"][:2]
            x1[cy:cy + ch, cx:cx + cw] = x[1][by:by + ch, bx:bx + cw]
        code = np.rint(x1)
        # the pixels whose change is under half a gray level: rounded twice they would not
        # change at all
        on = (change > 0.05) & (change < 0.5)
        got.append(raw[1][on].astype(float) - code[on])
        want.append(np.rint(x1[on] + change[on]) - code[on])
        up.append(code[on] > 0.5 * (raw[0][on].astype(float) + raw[2][on]))
        assert np.array_equal(lin[1], raw[1].astype(np.float32))
    got, want, up = np.concatenate(got), np.concatenate(want), np.concatenate(up)
    assert got.size > 4000 and 0.15 < want.mean() < 0.5
    assert got.mean() == pytest.approx(want.mean(), abs=0.03)
    assert want[up].mean() < want[~up].mean() - 0.1
    assert got[up].mean() == pytest.approx(want[up].mean(), abs=0.04)
    assert got[~up].mean() == pytest.approx(want[~up].mean(), abs=0.04)

    # the noise of the pixels under the streak, with beta as large as a slow drop's
    rng = np.random.default_rng(8)
    sigma = 3.0
    bg = np.full(CAM.shape, 60.0, np.float32)
    res, betas = [], []
    for _ in range(8):
        plan = probe.plan(CAM.shape, slope=0.0)
        for p in plan:
            p["area_px"] *= 6.0            # beta six times a falling drop's
        exact, _r, _c = probe.canvas((bg, bg, bg), plan, 200.0)
        beta = (exact[1] - 60.0) / 140.0
        noisy = (bg + sigma * rng.standard_normal(CAM.shape)).astype(np.float32)
        lin, _raw, _c = probe.canvas((noisy, noisy, noisy), plan, 200.0, noise_dn=sigma)
        on = beta > 0.2
        res.append((lin[1] - exact[1])[on])
        betas.append(beta[on])
    res, betas = np.concatenate(res), np.concatenate(betas)
    assert res.size > 2000 and np.mean(1 - (1 - betas) ** 2) > 0.3
    assert np.var(res) == pytest.approx(sigma ** 2, rel=0.08)


def test_probe_effort_follows_the_counting_error(volume):
    """Until mature every frame is probed; then the interval between probed frames scales
    with (target / probe error)^2, the target half the rest of the rate's error, between
    ``fastest`` and ``every`` frames."""
    from raingauge.gauge.completeness import PROBE_SD_SHARE

    probe = _probe(volume, per_frame=16, every=6, fastest=1, min_injections=16)
    assert probe.interval == 6
    assert probe.adapt(float("nan"), float("nan")) == 1
    assert all(probe.due(k) for k in range(5))
    plan = probe.plan(CAM.shape, slope=0.0)
    probe.record(plan, np.ones(len(plan)), np.ones(len(plan)), np.full(len(plan), 0.5))
    assert probe.mature
    # the probe's error well under the target: probe less often, at most every 6th frame
    assert probe.adapt(0.005, 0.04) == 6
    assert probe.due(12) and not probe.due(13)
    # at the target: stay
    assert probe.adapt(PROBE_SD_SHARE * 0.04, 0.04) == 6
    # twice the target: a quarter of the interval
    assert probe.adapt(2 * PROBE_SD_SHARE * 0.04, 0.04) == 1
    assert probe.adapt(0.5 * PROBE_SD_SHARE * 0.04, 0.04) == 4
    # no rate to compare with: unchanged
    assert probe.adapt(0.01, float("nan")) == 4
    # at most every 2nd frame by default once mature
    capped = _probe(volume, per_frame=16, every=6, min_injections=16)
    plan = capped.plan(CAM.shape, slope=0.0)
    capped.record(plan, np.ones(len(plan)), np.ones(len(plan)), np.full(len(plan), 0.5))
    assert capped.adapt(1.0, 0.01) == capped.fastest == 2


def test_probe_forgets_injections_older_than_its_memory(volume):
    """With frame times, the correction rests on the injections of the last ``memory_s``:
    a scene where the gauge read the drops at half their rain, then fully, is corrected by
    the latter alone once the first part is forgotten."""
    probe = _probe(volume, per_frame=16, min_injections=16, memory_s=10.0)
    for k in range(100):
        plan = probe.plan(CAM.shape, slope=0.0)
        expected = np.ones(len(plan))
        est = (0.5 if k < 50 else 1.0) * expected
        probe.record(plan, est, expected, np.full(len(plan), 0.5), t_s=float(k))
        if k == 49:
            ratio, _n = probe.class_ratios()
            assert np.nanmax(np.abs(ratio - 0.5)) < 1e-9
    assert probe.injected == 100 * 16
    injected, _c, _e = probe.class_counts()
    assert injected.sum() == 11 * 16               # t = 89 ... 99
    ratio, _n = probe.class_ratios()
    assert np.nanmax(np.abs(ratio - 1.0)) < 1e-9
    with pytest.raises(ValueError, match="memory_s"):
        _probe(volume, memory_s=0.0)


def test_window_rate_takes_every_drop_at_the_latest_correction(monkeypatch):
    """A drop is weighted, when its frame is decided, by the probe's correction of the
    injections made until then; the window's record takes all its drops at the correction
    of all the injections so far (the early ones' corrections rest on few injections)."""
    from raingauge.gauge import gauge as gauge_module

    # frames decided as soon as the probe is mature (this small clip has too few streaks
    # for the gauge's own threshold before its end, when every frame is decided at once)
    monkeypatch.setattr(gauge_module, "DECIDE_BRIGHTNESS_SAMPLES", 30)
    sim = pytest.importorskip("raingauge.render.simulator")
    cam = CAM.replace(noise_sigma_dn=2.0)
    frames, _truth = sim.render_clip(cam, seconds=8.0, rain_rate_mm_h=30.0, seed=3, background="skimage:brick")
    g = RainGauge(cam, window_s=8.0, step_s=8.0, keep_drops=True)
    recs = []
    for fr in frames:
        recs += g.process(fr)
    recs += g.flush()
    rec = recs[-1]
    assert g.probe.mature and len(g.drops) > 50
    d = np.array([x["diameter_m"] for x in g.drops])
    v = np.array([x["velocity_m_s"] for x in g.drops])
    w = np.array([x["weight_s_m3"] for x in g.drops])
    used = np.array([x["probe_correction"] for x in g.drops])
    now = g.probe.correction(0.5 * d)
    stored = np.sum(d ** 3 * v * w)
    latest = np.sum(d ** 3 * v * w * used / now)
    # the corrections moved while the drops were counted (the early ones' most)
    assert np.max(np.abs(used / now - 1.0)) > 0.05
    duration = len(g._frames) * cam.frame_interval_s
    rate = 3.6e6 * math.pi / 6.0 * latest / duration
    # (the record adds the completion of the sizes the brick hides, from the same drops)
    counted = rec["rain_rate_mm_h"] * (1.0 - rec["completed_share"])
    assert counted == pytest.approx(rate, rel=1e-6)
    assert abs(latest / stored - 1.0) > 1e-3


def test_pinned_probe_injects_one_size_at_one_depth(volume):
    """Pinned, every drop has the given radius and depth and weighs in its class and depth
    span; unpinned, the drops are drawn over the classes again; a pin outside the classes
    or at no depth is refused with the reason."""
    probe = _probe(volume, per_frame=10)
    a, z = 0.5e-3, 2.48
    probe.pin(a, z)
    near, far = volume.depth_span(a)
    plan = probe.plan(CAM.shape, slope=0.0)
    assert len(plan) == 10
    for p in plan:
        assert p["radius_m"] == a and p["depth_m"] == z
        assert CLASS_EDGES_M[p["class"]] <= a < CLASS_EDGES_M[p["class"] + 1]
        assert p["span_m"] == pytest.approx(float(far - near))
    probe.pin(None, None)
    radii = [p["radius_m"] for _ in range(5) for p in probe.plan(CAM.shape, slope=0.0)]
    assert len(set(radii)) > 20
    with pytest.raises(ValueError, match="outside the probe's classes"):
        probe.pin(5e-3, 2.5)
    with pytest.raises(ValueError, match="positive radius and depth"):
        probe.pin(0.5e-3, 0.0)


def test_outcomes_log_every_injection(volume):
    """With ``outcomes`` a list, each recorded drop leaves its radius, depth, whether it was
    counted, the model's p and the gauge's estimate; the sums are those recorded either way."""
    probe = _probe(volume, per_frame=4)
    probe.pin(0.6e-3, 2.5)
    probe.outcomes = []
    plan = probe.plan(CAM.shape, slope=0.0)
    probe.record(plan, estimate=[0.0, 2.0, 0.0, 1.0], expected=[1.0, 1.0, 1.0, 1.0], p_pass=[0.1, 0.2, 0.3, 0.4])
    assert probe.outcomes == [(0.6e-3, 2.5, False, 0.1, 0.0), (0.6e-3, 2.5, True, 0.2, 2.0),
                              (0.6e-3, 2.5, False, 0.3, 0.0), (0.6e-3, 2.5, True, 0.4, 1.0)]
    injected, counted, expected = probe.class_counts()
    assert injected.sum() == 4 and counted.sum() == 2 and expected.sum() == pytest.approx(1.0)


@pytest.mark.parametrize("background, e_r, a_mm, z_m, seconds", [
    ("ramp:150:190", 250.0, 0.5, 2.5, 30.0),     # the bright sky, at its smallest counted sizes
    ("uniform:40", 200.0, 0.25, 2.49, 20.0),     # the dark backdrop, at its smallest
])
def test_probe_counts_its_drops_as_the_gauge_counts_the_same_drops_in_the_video(background, e_r, a_mm, z_m,
                                                                              seconds):
    """The probe's correction is only as good as its drops are like the real ones: drops of
    one size and depth rendered into a rain clip by the simulator, where the gauge counts a
    fifth of them, are counted as often as the probe's own drops of that size and depth
    (within four standard errors of the two binomial counts), and credited with as much
    rain on average (within four standard errors of the two means)."""
    from raingauge.gauge.fidelity import probe_fidelity

    cam = CAM.replace(noise_sigma_dn=3.0)
    res = probe_fidelity(cam, radius_m=a_mm * 1e-3, depth_m=z_m, background=background, drop_brightness_dn=e_r,
                         seconds=seconds, coverage=0.04)
    (rh, rt), (ph, pt) = res["real"], res["probe"]
    assert rt > 2000 and pt > 2000
    real, prb = rh / rt, ph / pt
    assert 0.1 < real < 0.4
    sd = math.sqrt(real * (1 - real) / rt + prb * (1 - prb) / pt)
    assert abs(real - prb) < 4.0 * sd
    (m_real, se_real), (m_prb, se_prb) = res["real_share"], res["probe_share"]
    assert m_real > 0 and m_prb > 0
    assert abs(m_real - m_prb) < 4.0 * math.hypot(se_real, se_prb)


@pytest.mark.parametrize("wind", [0.0, 3.0])
def test_probe_drops_are_as_sharp_as_the_same_drops_in_the_video(wind):
    """The probe's focus samples set the reference of the drop brightness E_r, so its drops
    must look as sharp as the rain's: sharp 1-mm drops rendered into a clip over the brick
    wall, upright and slanted by a 3 m/s wind, give the same photometric focus q' (the
    percentile fixed point E_r is taken at, and the median) as the probe's drops pinned to
    them, within a percent, and are counted as often."""
    from raingauge.gauge.fidelity import probe_fidelity

    res = probe_fidelity(CAM.replace(noise_sigma_dn=1.0), radius_m=1e-3, depth_m=2.5, background="skimage:brick",
                         drop_brightness_dn=200.0, rain_rate_mm_h=0.3, seconds=10.0, coverage=0.04,
                         wind_m_s=wind, seed=5)
    (rh, rt), (ph, pt) = res["real"], res["probe"]
    real, prb = rh / rt, ph / pt
    assert 0.5 < real < 0.95
    assert abs(real - prb) < 4.0 * math.sqrt(real * (1 - real) / rt + prb * (1 - prb) / pt)
    (p_s, med_s, n_s), (p_p, med_p, n_p) = res["focus_streaks"], res["focus_probe"]
    assert n_s > 300 and n_p > 300
    assert 0.95 < med_s < 1.1 and p_s > med_s
    assert p_s == pytest.approx(p_p, abs=0.01)
    assert med_s == pytest.approx(med_p, abs=0.01)
    # what the gauge's tests turned away of the video's streaks: the clip's defocused rain
    # fails the velocity law, and the drift test acts only in a wind
    turned = res["rejections"]
    assert all(isinstance(n, int) and n >= 0 for n in turned.values())
    assert turned.get("velocity_law", 0) > 0
    if wind == 0.0:
        assert turned.get("drift", 0) == 0


def test_drift_is_corrected_by_what_the_gauge_makes_of_the_probes():
    """A drop's drift is measured as its slant times its speed at the depth of its measured
    size, so a size measured small drifts slow.  The probe's counted drops, placed with a
    known drift, tell what the gauge makes of one, class by class of measured size; the
    counted drops' drift is divided by it drop by drop (their own class where it has
    enough probe drops, else all of them), within the span it is held to."""
    from raingauge.gauge.gauge import PROBE_DRIFT_BIAS_SPAN, PROBE_DRIFT_MIN_DROPS

    g = RainGauge(CAM, window_s=8.0, step_s=8.0, velocity_model="gunn_kinzer")
    mid = np.sqrt(CLASS_EDGES_M[:-1] * CLASS_EDGES_M[1:])
    small, large = float(mid[1]), float(mid[4])
    g._drifts.extend([2.88] * 30 + [3.0] * 20)
    g._drift_radii.extend([small] * 30 + [large] * 20)
    assert g._counted_drift() == pytest.approx(2.88)
    g._probe_drift_ratios[1].extend([0.96] * PROBE_DRIFT_MIN_DROPS)
    g._probe_drift_ratios[4].extend([1.0] * PROBE_DRIFT_MIN_DROPS)
    assert g._counted_drift() == pytest.approx(3.0)
    # a class with too few probe drops takes the median of all of them
    g._probe_drift_ratios[4].clear()
    g._probe_drift_ratios[4].extend([1.0] * (PROBE_DRIFT_MIN_DROPS - 1))
    np.testing.assert_allclose(g._probe_drift_bias([small, large]), [0.96, float(np.median(
        [0.96] * PROBE_DRIFT_MIN_DROPS + [1.0] * (PROBE_DRIFT_MIN_DROPS - 1)))])
    # held to its span
    g._probe_drift_ratios[1].extend([0.5] * 60)
    assert g._probe_drift_bias([small])[0] == PROBE_DRIFT_BIAS_SPAN[0]


def test_the_wind_follows_every_sample_it_is_taken_from():
    """The rain's direction and drift are kept between frames until a sample is added to the
    logs they are taken from: the law-abiding streaks' while fewer than five drops were
    counted, the counted drops' from then on, and a full log whose oldest sample gives way
    to a new one reads the new median."""
    g = RainGauge(CAM, velocity_model="gunn_kinzer")
    assert (g._rain_slope(), g._wind_m_s()) == (0.0, 0.0)
    g._law_slopes.extend([0.3] * 5)
    g._law_drifts.extend([2.0] * 5)
    assert (g._rain_slope(), g._wind_m_s()) == (0.3, 2.0)
    g._law_drifts.extend([2.5] * 6)
    assert g._wind_m_s() == 2.5
    g._slopes.extend([0.4] * 5)
    g._drifts.extend([2.6] * 5)
    g._drift_radii.extend([1e-3] * 5)
    assert g._counted_direction() and (g._rain_slope(), g._wind_m_s()) == (0.4, 2.6)
    g._drifts.extend([2.8] * 50)                 # the logs are full: the 2.6s give way
    g._drift_radii.extend([1e-3] * 50)
    assert g._wind_m_s() == 2.8
    g._slopes.extend([0.01] * 50)                # falling straight down in the image
    assert (g._rain_slope(), g._wind_m_s()) == (0.01, 0.0)


def test_drift_test_rejects_streaks_that_move_across_otherwise():
    """In a cross wind every drop drifts with the air, so a whole streak of a drop near focus
    moves across by u f T / z0; a piece of a far drop's streak, detected where the noise
    lifts it, moves across by the piece's share.  The test is off without wind and until
    enough drops were counted; then a streak may fall short of the counted drops' measured
    drift by its tolerance, and move across further (a nearer drop) as far as it likes,
    whichever way the wind blows."""
    from raingauge.gauge.gauge import DRIFT_TEST_MIN_DROPS, DRIFT_TOL_PX, DRIFT_TOL_REL

    g = RainGauge(CAM, velocity_model="gunn_kinzer")
    dx_e = 3.0 * CAM.focal_length_px * CAM.exposure_s / CAM.focus_distance_m   # 33.6 px
    share = np.array([1.0, 0.9, 1.15, 1.6, 0.7, 0.5, 0.0, -1.0])
    assert g._drift_consistent(share * dx_e).all()                 # no wind
    g._slopes.extend([0.6] * (DRIFT_TEST_MIN_DROPS - 1))
    g._drifts.extend([3.0] * (DRIFT_TEST_MIN_DROPS - 1))
    g._drift_radii.extend([1e-3] * (DRIFT_TEST_MIN_DROPS - 1))
    assert g._wind_m_s() == pytest.approx(3.0)
    assert g._drift_consistent(share * dx_e).all()                 # too few drops counted
    g._slopes.append(0.6)
    g._drifts.append(3.0)
    g._drift_radii.append(1e-3)
    np.testing.assert_array_equal(g._drift_consistent(share * dx_e),
                                  [True, True, True, True, False, False, False, False])
    tol = DRIFT_TOL_REL * dx_e + DRIFT_TOL_PX
    np.testing.assert_array_equal(g._drift_consistent([dx_e - 0.99 * tol, dx_e - 1.01 * tol]), [True, False])
    # the wind from the other side
    for ring, value in ((g._drifts, -3.0), (g._slopes, -0.6)):
        n = len(ring)
        ring.clear()
        ring.extend([value] * n)
    np.testing.assert_array_equal(g._drift_consistent(-share * dx_e),
                                  [True, True, True, True, False, False, False, False])
    for ring, value in ((g._drifts, 3.0), (g._slopes, 0.6)):
        n = len(ring)
        ring.clear()
        ring.extend([value] * n)
    # the drift compared with is the counted drops' measured one, not the corrected one
    g._probe_drift_ratios[3].extend([0.9] * 60)
    assert g._wind_m_s() == pytest.approx(3.0 / 0.9)
    assert g._drift_consistent([dx_e])[0]


def test_probe_drops_drift_as_placed_and_are_placed_with_the_corrected_drift():
    """In a 3 m/s cross wind the probe's counted drops read about the drift they were
    placed with; once they have, and drops were counted, later drops are placed with the
    counted drops' drift corrected by them, which reads the wind."""
    sim = pytest.importorskip("raingauge.render.simulator")
    cam = CAM.replace(noise_sigma_dn=1.0)
    frames, _truth = sim.render_clip(cam, seconds=18.0, rain_rate_mm_h=30.0, seed=4, background="ramp:150:190",
                                     drop_brightness_dn=250.0, wind_m_s=3.0)
    # (the drops wait for the probe to mature and E_r to be known: counted here from 14 s on)
    g = RainGauge(cam, window_s=12.0, step_s=12.0, velocity_model="gunn_kinzer")
    placed = []
    plan = g.probe.plan

    def spy(shape, slope, drift_m_s=None):
        if sum(len(d) for d in g._probe_drift_ratios) >= 40 and g._counted_direction() and len(g._drifts) >= 5:
            placed.append((drift_m_s, g._counted_drift()))
        return plan(shape, slope, drift_m_s=drift_m_s)

    g.probe.plan = spy
    for fr in frames:
        g.process(fr)
    ratios = np.concatenate([list(d) for d in g._probe_drift_ratios])
    assert ratios.size >= 40
    assert np.median(ratios) == pytest.approx(1.0, abs=0.05)
    assert placed
    for used, corrected in placed:
        assert used == pytest.approx(corrected, rel=1e-12)
    assert g._wind_m_s() == pytest.approx(3.0, abs=0.08)
