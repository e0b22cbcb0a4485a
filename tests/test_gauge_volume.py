"""Sample volume of the gauge: depth range of the focus test, field of view, edge clipping."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raingauge.gauge.volume import (
    SampleVolume,
    effective_area_rate_px2_s,
    pass_probability,
    whole_streak_area_px2,
)
from raingauge.profile import default_profile

CAM = default_profile().replace(width_px=320, height_px=240)


@pytest.fixture(scope="module")
def volume():
    return SampleVolume(CAM, velocity_model="gunn_kinzer")


def test_focused_drops_pass_and_far_ones_do_not(volume):
    """A 2-mm drop passes at z0 and not at z0/2 or 2 z0; its accepted depths bracket z0."""
    z0 = CAM.focus_distance_m
    p = pass_probability(1e-3, [z0, 0.5 * z0, 2 * z0], CAM, velocity_model="gunn_kinzer")["p"]
    assert p[0] > 0.95 and p[1] < 0.01 and p[2] < 0.01
    lo, hi = volume.depth_range_m(1e-3)
    assert lo < z0 < hi
    assert hi - lo < 0.5 * z0


def test_kappa_against_monte_carlo(volume):
    """kappa(a) x frame area equals a Monte Carlo count of drops placed uniformly in the
    viewing frustum and accepted with the pass probability (independent sampling)."""
    rng = np.random.default_rng(0)
    a = 0.8e-3
    f = CAM.focal_length_px
    M, N = CAM.shape
    z_lo, z_hi = 1.5, 4.0
    # uniform positions in the box enclosing the frustum between z_lo and z_hi
    half_x = N / 2 / f * z_hi
    half_y = M / 2 / f * z_hi
    n = 400_000
    pts = np.column_stack([rng.uniform(-half_x, half_x, n), rng.uniform(-half_y, half_y, n),
                           rng.uniform(z_lo, z_hi, n)])
    inside = (np.abs(pts[:, 0] * f / pts[:, 2]) < N / 2) & (np.abs(pts[:, 1] * f / pts[:, 2]) < M / 2)
    p = pass_probability(a, pts[inside, 2], CAM, velocity_model="gunn_kinzer")["p"]
    box = (2 * half_x) * (2 * half_y) * (z_hi - z_lo)
    mc_volume = box * p.sum() / n
    assert volume.kappa(a) * M * N == pytest.approx(mc_volume, rel=0.03)


def test_whole_streak_area_edge_clipping():
    """A streak w + |dx| by w + |dy| is whole only from a smaller rectangle of starts."""
    area = whole_streak_area_px2((10.0, 60.0), 4.0, (240, 320), margin_px=0.0)
    assert area == pytest.approx((320 - 14) * (240 - 64))
    assert whole_streak_area_px2((0.0, 300.0), 4.0, (240, 320)) == 0.0


@pytest.mark.parametrize("motion", [(0.0, 40.0), (15.0, 80.0), (0.0, 200.0)])
def test_effective_area_rate_against_simulation(motion):
    """Distinct drops counted once if whole in at least one frame: the formula
    [W_R H_R - (W_R - |d_x|)+ (H_R - |d_y|)+] / Delta against drops simulated crossing a frame."""
    rng = np.random.default_rng(1)
    shape = (240, 320)
    T, delta = 0.004, 1 / 30
    w = 3.0
    dx, dy = motion
    ux, uy = dx / T, dy / T
    rate = effective_area_rate_px2_s(motion, w, shape, exposure_s=T, frame_interval_s=delta, margin_px=0.0)
    # density 1 drop per px^2 of image plane; drops start over a big area and move for 40 frames
    duration = 40 * delta
    n = 300_000
    span_x = (-abs(ux) * duration - 20, shape[1] + 20)
    span_y = (-abs(uy) * duration - 20, shape[0] + 20)
    x0 = rng.uniform(*span_x, n)
    y0 = rng.uniform(*span_y, n)
    density = n / ((span_x[1] - span_x[0]) * (span_y[1] - span_y[0]))
    seen = np.zeros(n, bool)
    for k in range(40):
        x = x0 + ux * k * delta
        y = y0 + uy * k * delta
        whole = (x - w / 2 >= 0) & (x + dx + w / 2 <= shape[1]) & (y - w / 2 >= 0) & (y + dy + w / 2 <= shape[0])
        seen |= whole
    # drops that could have entered before the first frame are excluded by the start area
    # chosen so that every counted drop crosses during the 40 frames; compare per second
    expected = density * rate * duration
    assert seen.sum() == pytest.approx(expected, rel=0.08)


def test_volume_grows_with_drop_size_then_clipping_bites(volume):
    """Bigger drops are sampled over a deeper range (the test scales with the image size)."""
    k = volume.kappa([0.4e-3, 0.8e-3, 1.5e-3])
    assert k[0] < k[1] < k[2]
    assert volume.kappa(0.05e-3) == 0.0  # below one pixel: not measurable


def test_volume_against_simulator_drops():
    """Monte Carlo with the simulator's own streak renderer: drops of 1.6 mm drawn at depths
    where the pass probability is ~1 are accepted by the gauge's measurement, and where it
    is ~0 they are not."""
    pytest.importorskip("raingauge.render.simulator")
    from raingauge.gauge import RainGauge
    from raingauge.physics.drops import fall_velocity
    from raingauge.render.simulator import compose_rain, render_streaks, streak_capsules

    a = 0.8e-3
    v = float(fall_velocity(2 * a, model="gunn_kinzer"))
    z0 = CAM.focus_distance_m
    probs = {}
    for z in (z0 - 0.02, z0 + 0.02, 0.8 * z0, 1.35 * z0):
        probs[z] = float(pass_probability(a, [z], CAM, velocity_model="gunn_kinzer")["p"][0])
    rng = np.random.default_rng(5)
    bg = np.full(CAM.shape, 60.0, np.float32)
    for z, p in probs.items():
        if 0.1 < p < 0.9:
            continue
        start = np.array([[0.0, -0.012, z]])
        end = start + np.array([[0.0, v * CAM.exposure_s, 0.0]])
        caps = streak_capsules(start, end, [a], focal_length_px=CAM.focal_length_px,
                               principal_point_px=CAM.principal_point, f_number=CAM.f_number,
                               focus_distance_m=z0, pixel_pitch_m=CAM.pixel_pitch_m)
        beta, _ = render_streaks(CAM.shape, caps["p0"], caps["p1"], caps["radius_px"], caps["area_px"])
        frames = [bg + rng.normal(0, 1.0, bg.shape) for _ in range(3)]
        frames[1] = compose_rain(frames[1], beta)
        g = RainGauge(CAM, velocity_model="gunn_kinzer", window_s=1.0, step_s=1.0, keep_drops=True)
        # seed the drop-brightness estimate with a sharp drop first
        g._brightness.extend([200.0] * 10)
        for fr in frames:
            g.process(np.clip(np.rint(fr), 0, 255).astype(np.uint8))
        g.flush()
        accepted = len(g.drops) == 1
        assert accepted == (p > 0.5), (z, p, len(g.drops))
