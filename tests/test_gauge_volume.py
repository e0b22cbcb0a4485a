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
        # the drop brightness is known (the simulator's)
        g = RainGauge(CAM, velocity_model="gunn_kinzer", window_s=1.0, step_s=1.0, keep_drops=True,
                      drop_brightness_dn=200.0)
        for fr in frames:
            g.process(np.clip(np.rint(fr), 0, 255).astype(np.uint8))
        g.flush()
        accepted = len(g.drops) == 1
        assert accepted == (p > 0.5), (z, p, len(g.drops))


def _round_trip(profile, diameter_m, *, n_frames, background_dn, drop_brightness_dn, seed, cols=6, rows=2):
    """Isolated drops of one size at random depths around z0, rendered by the simulator and
    fed to the gauge between rain-free frames: (accepted, expected by the volume model, placed)."""
    from raingauge.gauge import RainGauge
    from raingauge.physics.drops import fall_velocity
    from raingauge.render.simulator import compose_rain, render_streaks, streak_capsules

    rng = np.random.default_rng(seed)
    f, z0, T = profile.focal_length_px, profile.focus_distance_m, profile.exposure_s
    a = 0.5 * diameter_m
    v = float(fall_velocity(diameter_m, model="gunn_kinzer"))
    contrast = drop_brightness_dn - background_dn
    # depths: where the model accepts anything, widened by a third on each side
    zz = np.linspace(0.85 * z0, 1.2 * z0, 700)
    pz = pass_probability(a, zz, profile, velocity_model="gunn_kinzer", contrast_dn=contrast)["p"]
    on = zz[pz > 1e-3]
    half = 0.5 * (on[-1] - on[0])
    lo, hi = on[0] - 0.3 * half, on[-1] + 0.3 * half
    M, N = profile.shape
    gauge = RainGauge(profile, velocity_model="gunn_kinzer", window_s=1e3, step_s=1e3, keep_drops=True,
                      drop_brightness_dn=drop_brightness_dn)    # the drop brightness, as if calibrated
    bg = np.full(profile.shape, background_dn, np.float32)
    n = cols * rows
    k = 0

    def feed(lin):
        nonlocal k
        noisy = lin + rng.normal(0.0, profile.noise_sigma_dn, lin.shape)
        gauge.process(np.clip(np.rint(noisy), 0, 255).astype(np.uint8), t_s=k / profile.frame_rate_hz)
        k += 1

    placed = []
    feed(bg)
    for _ in range(n_frames):
        z = rng.uniform(lo, hi, n)
        cx = (np.arange(n) % cols + rng.uniform(0.3, 0.7, n)) * N / cols
        cy = (np.arange(n) // cols + rng.uniform(0.35, 0.65, n)) * M / rows
        start = np.column_stack([(cx - profile.principal_point[0]) * z / f,
                                 (cy - profile.principal_point[1]) * z / f - 0.5 * v * T, z])
        caps = streak_capsules(start, start + np.array([0.0, v * T, 0.0]), np.full(n, a), focal_length_px=f,
                               principal_point_px=profile.principal_point, f_number=profile.f_number,
                               focus_distance_m=z0, pixel_pitch_m=profile.pixel_pitch_m)
        beta, _ = render_streaks(profile.shape, caps["p0"], caps["p1"], caps["radius_px"], caps["area_px"])
        placed.append((k, cx, cy, z))
        feed(compose_rain(bg.copy(), beta, drop_brightness_dn=drop_brightness_dn))
        feed(bg)
    gauge.flush()
    by_frame = {}
    for d in gauge.drops:
        by_frame.setdefault(int(round(d["t"] * profile.frame_rate_hz)), []).append(d)
    accepted, expected = 0, 0.0
    for frame_k, cx, cy, z in placed:
        expected += float(pass_probability(a, z, profile, velocity_model="gunn_kinzer",
                                           contrast_dn=contrast)["p"].sum())
        for d in by_frame.get(frame_k, []):
            if np.min(np.hypot(cx - d["x"], cy - d["y"])) < 6.0:
                accepted += 1
    return accepted, expected, n * n_frames


@pytest.mark.parametrize("diameter_mm, noise, background_dn, drop_dn", [
    (0.55, 1.0, 40.0, 200.0),      # a streak of ~1.5 px: the pixel grid limits its sizing
    (0.85, 3.0, 40.0, 200.0),      # faint against the noise: wide tolerance, loose focus
    (1.5, 2.0, 40.0, 200.0),
    (1.0, 1.0, 150.0, 250.0),      # a bright background: less contrast
])
def test_round_trip_accepted_fraction_equals_pass_probability(diameter_mm, noise, background_dn, drop_dn):
    """The sample volume is the accepted fraction: drops of one size placed at random depths
    around z0 (rendered by the simulator's Eqs. 15-24, isolated, whole in the frame) are
    accepted by the gauge as often as the volume model's pass probability says, within
    the counting error (3 sigma of the binomial count plus 10 % of the model's calibration)."""
    prof = CAM.replace(noise_sigma_dn=noise)
    accepted, expected, placed = _round_trip(prof, diameter_mm * 1e-3, n_frames=14, background_dn=background_dn,
                                             drop_brightness_dn=drop_dn, seed=int(diameter_mm * 100 + noise))
    assert expected > 20
    p = expected / placed
    sigma = math.sqrt(placed * p * (1 - p))
    assert abs(accepted - expected) <= 3 * sigma + 0.1 * expected, (accepted, expected, placed)


@pytest.mark.parametrize("grow, small_share", [(1.0, 0.05), (0.5, 0.2)])
def test_contrast_sets_which_sizes_are_seen(grow, small_share):
    """Eqs. (17)-(19): a drop's streak changes its pixels by beta (E_r - E_b); with less
    contrast the small drops vanish first, while the large ones are still sampled (with the
    detection's hysteresis, which measures faint streaks whole, the small ones fade later)."""
    vol = SampleVolume(CAM, velocity_model="gunn_kinzer", grow=grow)
    a = np.array([0.3e-3, 1.5e-3])
    dark = vol.kappa(a, 160.0)
    dim = vol.kappa(a, 80.0)
    none = vol.kappa(a, 1.5)
    assert np.all(dark > 0)
    assert dim[0] < small_share * dark[0] and dim[1] > 0.5 * dark[1]
    assert np.all(none < 1e-6 * dark)


def test_frame_volume_averages_its_backgrounds(volume):
    """A frame half dark, half as bright as the drops samples each size in the mean of the
    two volumes: the visible half counts, the invisible half does not (no sizes lost, none
    inflated)."""
    from raingauge.gauge.volume import background_histogram

    frame = np.full((240, 320), 40.0, np.float32)
    frame[:, 160:] = 199.0
    hist = background_histogram(frame)
    assert hist.sum() == frame[::8, ::8].size
    w = volume.histogram_weights(hist, 200.0)
    a = np.array([0.4e-3, 1.0e-3])
    # the nearest grid contrasts of 160 and ~1 gray levels
    dark_only = volume.histogram_weights(background_histogram(np.full((240, 320), 40.0, np.float32)), 200.0)
    assert volume.kappa(a, weights=w) == pytest.approx(0.5 * volume.kappa(a, weights=dark_only), rel=1e-9)
    assert volume.visible_fraction(a, weights=w) == pytest.approx(
        0.5 * volume.visible_fraction(a, weights=dark_only), rel=1e-9)


def test_histogram_weights_average_the_contrast_weights_of_the_pixels(volume):
    """A frame's weights are the mean of contrast_weights over its pixels: from the
    histogram of its backgrounds they equal contrast_weights of every sampled pixel's
    contrast (bin centres) taken one by one."""
    from raingauge.gauge.volume import BACKGROUND_BIN_DN, background_histogram

    rng = np.random.default_rng(4)
    frame = np.clip(rng.normal(120.0, 60.0, (240, 320)), 0, 255).astype(np.float32)
    hist = background_histogram(frame)
    centres = (np.arange(hist.size) + 0.5) * BACKGROUND_BIN_DN
    for e_r in (90.0, 200.0, 400.0):
        per_pixel = np.repeat(e_r - centres, hist.astype(int))
        assert volume.histogram_weights(hist, e_r) == pytest.approx(volume.contrast_weights(per_pixel),
                                                                   rel=1e-12, abs=1e-15)


def test_contrast_weights_of_many_sets_are_each_sets_own(volume):
    """The weights of several sets of contrasts taken in one pass are, row by row, those of
    each set alone, to the bit: sets below, inside and above the grid, with NaNs, empty and
    all-NaN ones."""
    rng = np.random.default_rng(9)
    lo, hi = volume.contrasts_dn[0], volume.contrasts_dn[-1]
    sets = [rng.uniform(0.5 * lo, 1.5 * hi, int(rng.integers(1, 300))).astype(np.float32) for _ in range(12)]
    sets[3][::7] = np.nan
    sets += [np.zeros(0, np.float32), np.full(5, np.nan, np.float32), np.full(4, 0.1 * lo),
             np.full(6, 10.0 * hi), rng.uniform(lo, hi, (7, 9))]
    each = volume.contrast_weights_each(sets)
    assert each.shape == (len(sets), volume.contrasts_dn.size)
    for row, c in zip(each, sets):
        np.testing.assert_array_equal(row, volume.contrast_weights(c))
    assert each[-3].sum() == 0.0 and each[-2].sum() == pytest.approx(1.0)
    assert volume.contrast_weights_each([]).shape == (0, volume.contrasts_dn.size)


def test_hidden_share_from_the_background(volume):
    """Against a dark background every measurable size is visible (nothing hidden); against a
    background as bright as the drops nothing is, and the share of the rate hidden is all."""
    from raingauge.gauge.volume import background_histogram

    dark = volume.histogram_weights(background_histogram(np.full((240, 320), 40.0)), 200.0)
    d_det, share = volume.hidden_share(dark, 10.0)
    assert share < 0.01 and d_det <= 2.2 * volume.min_radius_m
    bright = volume.histogram_weights(background_histogram(np.full((240, 320), 200.0)), 200.0)
    d_det, share = volume.hidden_share(bright, 10.0)
    assert share == 1.0 and math.isinf(d_det)


def test_gauge_says_when_no_drop_can_be_seen():
    """A background as bright as the drops hides every size: the record flags it and gives
    no upper limit, instead of a confident zero."""
    from raingauge.gauge import RainGauge

    prof = CAM.replace(noise_sigma_dn=1.0)
    rng = np.random.default_rng(3)
    gauge = RainGauge(prof, velocity_model="gunn_kinzer", window_s=1.0, step_s=1.0)
    recs = []
    for k in range(20):
        frame = np.clip(np.rint(205.0 + rng.normal(0, 1.0, prof.shape)), 0, 255).astype(np.uint8)
        recs += gauge.process(frame)
    recs += gauge.flush()
    rec = recs[-1]
    assert "no_visible_drops" in rec["quality"]
    assert rec["rain_rate_ci95_mm_h"][1] is None


def test_noisier_frames_sample_small_drops_less(volume):
    """In heavy rain the flicker of the faint defocused drops (Eq. 27) adds to the sensor's
    noise: the small drops' streaks sink into it and their sample volume shrinks, while
    the large ones are still sampled."""
    base = volume.noises_dn[0]
    a = np.array([0.3e-3, 2.0e-3])
    quiet = volume.kappa(a, noise_dn=base)
    noisy = volume.kappa(a, noise_dn=3.0 * base)
    assert noisy[0] < 0.5 * quiet[0]
    assert noisy[1] > 0.7 * quiet[1]


def test_brightness_reference_follows_the_contrast(volume):
    """The reference q of the E_r estimate at another drop contrast: the same as at the
    volume's own contrast there, larger as the contrast falls against the noise (the errors
    of q' grow, and faint streaks are seen where they are brightest), and the same as a
    volume built for that contrast (independent computation, on the full grid of q')
    within 0.005."""
    noise = float(volume.noises_dn[2])
    c0 = volume.contrast_dn
    assert volume.brightness_q_at(noise, c0) == volume.brightness_q_at(noise)
    assert volume.brightness_q_at(noise, None) == volume.brightness_q_at(noise)
    qs = [volume.brightness_q_at(noise, c) for c in (c0, 0.7 * c0, 0.5 * c0, 0.3 * c0)]
    assert np.all(np.diff(qs) > 0)
    for c in (0.5 * c0, 0.3 * c0):
        other = SampleVolume(CAM, velocity_model="gunn_kinzer", contrast_dn=c)
        assert volume.brightness_q_at(noise, c) == pytest.approx(other.brightness_q_at(noise), abs=0.005)
    # between the half-octave nodes the reference moves smoothly
    grid = np.geomspace(0.3 * c0, c0, 25)
    q = np.array([volume.brightness_q_at(noise, c) for c in grid])
    assert np.max(np.abs(np.diff(q))) < 0.02


def test_brightness_reference_from_the_model(volume):
    """The model's reference for the E_r estimate: the focus test's share of law-abiding
    streaks (p <= p_law), q = (2 a_i / w')^2 with its error, and the percentile fixed point
    of the measured q', near 1 (in focus, lifted by the errors, lowered by the defocused
    drops the velocity law keeps)."""
    z = np.linspace(2.3, 2.7, 41)
    res = pass_probability(0.8e-3, z, CAM, velocity_model="gunn_kinzer", contrast_dn=160.0)
    assert np.all(res["p"] <= res["p_law"] + 1e-12)
    a_img = CAM.focal_length_px * 0.8e-3 / z
    w_app = 2 * res["apparent_radius_m"] * CAM.focal_length_px / CAM.focus_distance_m
    assert res["q"] == pytest.approx((2 * a_img / w_app) ** 2, rel=1e-9)
    assert np.all(res["q_sigma"] > 0)
    assert 0.8 < volume.brightness_q < 1.1
    assert volume.brightness_q_by_noise.shape == volume.noises_dn.shape
    assert volume.brightness_q_at(None) == volume.brightness_q
    mid = 0.5 * (volume.noises_dn[1] + volume.noises_dn[2])
    assert volume.brightness_q_at(mid) == pytest.approx(0.5 * (volume.brightness_q_by_noise[1]
                                                              + volume.brightness_q_by_noise[2]))


def test_population_factor_carries_the_probes_sizes_to_the_models(volume):
    """The factor from the completeness probe's population (uniform in log a over its
    sizes) to the model's (Marshall-Palmer): at a node of the grid the ratio of the two
    fixed points computed directly on the model's parts (independent computation), 1 when
    the probe's sizes are the model's prior restricted to one radius, linear between the
    nodes, and larger than 1 against a faint backdrop at high noise, where the many small
    drops of the Marshall-Palmer population measure their focus with larger errors."""
    from raingauge.gauge.volume import BRIGHTNESS_Q_NODES, _Q_GRID_COARSE, _brightness_percentile_q

    span = (0.15e-3, 2.8e-3)
    c0 = volume.contrast_dn
    node, i_n = -2, 1
    parts = [(a, wt[i_n, node - BRIGHTNESS_Q_NODES[0]], q[i_n, node - BRIGHTNESS_Q_NODES[0]],
              sq[i_n, node - BRIGHTNESS_Q_NODES[0]]) for a, wt, q, sq in volume._q_node_parts]
    direct = (_brightness_percentile_q(parts, volume.q_min, y=_Q_GRID_COARSE)
              / _brightness_percentile_q(parts, volume.q_min, y=_Q_GRID_COARSE, flat_between=span))
    c_node = c0 * 2.0 ** (0.5 * node)
    f_node = volume.brightness_q_population_factor(float(volume.noises_dn[i_n]), c_node, span)
    assert f_node == pytest.approx(direct, rel=1e-9)
    # one radius alone: both populations are that radius's
    a1 = float(volume.radii_m[len(volume.radii_m) // 2])
    one = (a1 * 0.999, a1 * 1.001)
    parts1 = [p for p in parts if one[0] <= p[0] <= one[1]]
    assert _brightness_percentile_q(parts1, volume.q_min, y=_Q_GRID_COARSE) == pytest.approx(
        _brightness_percentile_q(parts1, volume.q_min, y=_Q_GRID_COARSE, flat_between=one), rel=1e-12)
    # halfway between two contrast nodes: the mean of the two
    c_a, c_b = c0 * 2.0 ** (0.5 * -3), c0 * 2.0 ** (0.5 * -2)
    noise = float(volume.noises_dn[i_n])
    mid = volume.brightness_q_population_factor(noise, c_a * 2.0 ** 0.25, span)
    assert mid == pytest.approx(0.5 * (volume.brightness_q_population_factor(noise, c_a, span)
                                       + volume.brightness_q_population_factor(noise, c_b, span)), rel=1e-9)
    faint = volume.brightness_q_population_factor(float(volume.noises_dn[-1]), 0.25 * c0, span)
    assert faint > 1.0


def test_population_factor_follows_the_rate_of_its_prior(volume):
    """The factor for a Marshall-Palmer prior of another rate: the default is the prior of
    brightness_q (10 mm/h, to the bit, and one cached node), any other rate the ratio of the
    two fixed points computed directly on the model's parts; against a faint backdrop at
    high noise it falls as the rain grows (more big drops, whose focus is measured best)."""
    from raingauge.gauge.volume import (
        BRIGHTNESS_PRIOR_RATE_MM_H, BRIGHTNESS_Q_NODES, _Q_GRID_COARSE, _brightness_percentile_q,
    )

    span = (0.15e-3, 2.8e-3)
    noise = float(volume.noises_dn[-1])
    c = 0.25 * volume.contrast_dn
    base = volume.brightness_q_population_factor(noise, c, span)
    assert volume.brightness_q_population_factor(noise, c, span, BRIGHTNESS_PRIOR_RATE_MM_H) == base
    n_nodes = len(volume._q_nodes)
    volume.brightness_q_population_factor(noise, c, span, BRIGHTNESS_PRIOR_RATE_MM_H)
    assert len(volume._q_nodes) == n_nodes
    # at a node of the grid: the direct ratio for 50 mm/h
    node, i_n = -4, len(volume.noises_dn) - 1
    j = node - BRIGHTNESS_Q_NODES[0]
    parts = [(a, wt[i_n, j], q[i_n, j], sq[i_n, j]) for a, wt, q, sq in volume._q_node_parts]
    direct = (_brightness_percentile_q(parts, volume.q_min, y=_Q_GRID_COARSE, prior_rate_mm_h=50.0)
              / _brightness_percentile_q(parts, volume.q_min, y=_Q_GRID_COARSE, flat_between=span))
    c_node = volume.contrast_dn * 2.0 ** (0.5 * node)
    assert volume.brightness_q_population_factor(noise, c_node, span, 50.0) == pytest.approx(direct, rel=1e-9)
    by_rate = [volume.brightness_q_population_factor(noise, c, span, r) for r in (10.0, 30.0, 100.0, 200.0)]
    assert all(b > a for a, b in zip(by_rate[1:], by_rate[:-1]))
    assert by_rate[0] == base


def test_wind_dims_each_size_as_its_streak_slants(volume):
    """A drop drifting at u across its fall v(a) draws a streak slanted by u / v(a) and
    crosses each pixel faster: the simulator's exposure integral (render_streaks) gives the
    slanted streak's pixels cos(theta) of the straight one's change, the factor
    wind_dimming predicts; the small, slow drops slant and dim the most."""
    from raingauge.physics.drops import fall_velocity
    from raingauge.render.simulator import render_streaks

    a = np.array([0.25e-3, 0.6e-3, 1.2e-3, 2.0e-3])
    dim = volume.wind_dimming(a, 3.0)
    assert np.all(np.diff(dim) > 0) and np.all(dim < 1.0) and dim[0] < 0.6
    assert np.array_equal(volume.wind_dimming(a, 0.0), np.ones(a.size))
    v = fall_velocity(2 * a, model="gunn_kinzer")
    r, L = 3.0, 60.0
    for d, vi in zip(dim, v):
        dx = L * 3.0 / vi
        straight = render_streaks((160, 200), [(100.0, 40.0)], [(100.0, 40.0 + L)], [r], [math.pi * r * r])[0]
        slanted = render_streaks((160, 200), [(100.0 - dx / 2, 40.0)], [(100.0 + dx / 2, 40.0 + L)], [r],
                                 [math.pi * r * r])[0]
        # a capsule's change is its area over that of the whole capsule (Eq. 17): the
        # slanted one is longer by 1 / cos(theta) between the same end caps
        ratio = slanted.max() / straight.max()
        cap = math.pi * r * r
        assert ratio == pytest.approx((2 * r * L + cap) / (2 * r * L / d + cap), rel=0.01)
        # wind_dimming leaves out the end caps (a few % of a streak this long)
        assert ratio == pytest.approx(d, rel=0.04)
        # the exposure itself is conserved: the drop's area spread over a longer path
        assert slanted.sum() == pytest.approx(straight.sum(), rel=0.01)


def test_slanted_streak_is_detected_dimmed_and_measured_at_the_square_root():
    """A streak slanting by theta changes each pixel by cos(theta) of an upright one's: the
    detection's per-pixel tests see that dimmed change, while the measurement on the rows
    across it (the same signal over 1 / cos(theta) as many pixels) sees the upright
    streak's at sqrt(cos(theta)) of it: its focus error and the velocity test's."""
    z = np.linspace(2.40, 2.60, 9)
    g, c = 0.6, 120.0
    kw = dict(velocity_model="gunn_kinzer", noise_sigma_dn=3.0)
    for a in (0.3e-3, 0.5e-3, 1.0e-3):
        slanted = pass_probability(a, z, CAM, contrast_dn=c, slant_cos=g, **kw)
        dimmed = pass_probability(a, z, CAM, contrast_dn=c * g, **kw)
        rows = pass_probability(a, z, CAM, contrast_dn=c * math.sqrt(g), **kw)
        np.testing.assert_allclose(slanted["p_detect"], dimmed["p_detect"], rtol=1e-12)
        np.testing.assert_allclose(slanted["change_dn"], dimmed["change_dn"], rtol=1e-12)
        np.testing.assert_allclose(slanted["q_sigma"], rows["q_sigma"], rtol=1e-12)
        # in focus: detected as the dimmed streak, measured better than it (off focus the
        # larger errors of a dimmer measurement let more blurred drops through)
        k = 4
        assert dimmed["p"][k] - 1e-12 <= slanted["p"][k] <= pass_probability(a, z, CAM, contrast_dn=c, **kw)["p"][k] + 1e-12
    # falling straight down changes nothing
    upright = pass_probability(0.4e-3, z, CAM, contrast_dn=c, **kw)
    same = pass_probability(0.4e-3, z, CAM, contrast_dn=c, slant_cos=1.0, **kw)
    for key in ("p", "p_law", "p_detect", "q_sigma"):
        np.testing.assert_array_equal(upright[key], same[key])


def test_kappa_in_a_wind_is_the_wind_volumes(volume):
    """In a cross wind kappa integrates the pass probability of each size's own slant
    (wind_dimming) over depth, as computed here on a finer grid of depths; the pass
    probability over a set of backgrounds (the completeness probe's) is the slanted
    streak's; between the steps of WIND_STEP_M_S both are linear in the wind; no wind
    changes nothing; the small drops, slanting most, are sampled less, but more than if
    their measurement were dimmed as their detection is."""
    from raingauge.gauge.volume import WIND_STEP_M_S

    f, z0 = CAM.focal_length_px, CAM.focus_distance_m
    c = float(volume.contrasts_dn[12])                      # a node of the table's grid
    w = volume.contrast_weights([c])
    wind = 6 * WIND_STEP_M_S
    # (radii of the table's grid: between them kappa is interpolated in log a)
    for a in volume.radii_m[np.searchsorted(volume.radii_m, [0.3e-3, 0.8e-3, 1.5e-3])]:
        a = float(a)
        g = float(volume.wind_dimming(a, wind))
        lo, hi = volume.depth_span(a)
        z = np.linspace(0.98 * float(lo), 1.02 * float(hi), 4000)
        p = pass_probability(a, z, CAM, velocity_model="gunn_kinzer", contrast_dn=c, slant_cos=g,
                             q_min=volume.q_min, grow=volume.grow)["p"]
        direct = float(np.sum(p * (z / f) ** 2) * (z[1] - z[0]))
        assert float(volume.kappa(a, weights=w, wind_m_s=wind)) == pytest.approx(direct, rel=0.01)
        at_z0 = pass_probability(a, np.array([z0]), CAM, velocity_model="gunn_kinzer", contrast_dn=c,
                                 slant_cos=g, q_min=volume.q_min, grow=volume.grow)["p"][0]
        assert volume.pass_probability_over(a, z0, w, wind_m_s=wind) == pytest.approx(at_z0, abs=0.01)
        assert volume.kappa(a, weights=w, wind_m_s=0.0) == volume.kappa(a, weights=w)
        half = wind - 0.5 * WIND_STEP_M_S
        assert float(volume.kappa(a, weights=w, wind_m_s=half)) == pytest.approx(
            0.5 * float(volume.kappa(a, weights=w, wind_m_s=wind)
                        + volume.kappa(a, weights=w, wind_m_s=wind - WIND_STEP_M_S)), rel=1e-12)
    small = 0.3e-3
    dimmed_all = float(volume.kappa(small, contrast_dn=c * float(volume.wind_dimming(small, wind))))
    windy = float(volume.kappa(small, weights=w, wind_m_s=wind))
    assert dimmed_all < windy < 0.8 * float(volume.kappa(small, weights=w))
    assert volume.in_wind(wind) is volume.in_wind(wind) and volume.in_wind(0.0) is volume


def test_population_factor_in_a_wind_is_the_wind_volumes(volume):
    """The factor that carries the probe's reference of the drop brightness to the rain's
    sizes is, in a cross wind, that of the wind's volume (the small drops leave both
    populations, Marshall-Palmer's the more), linear between the wind's steps, and moves
    from the factor without wind."""
    from raingauge.gauge.volume import WIND_STEP_M_S

    span = (0.15e-3, 2.8e-3)
    wind = 6 * WIND_STEP_M_S
    for noise, c in ((float(volume.noises_dn[0]), volume.contrast_dn), (float(volume.noises_dn[2]), 40.0)):
        calm = volume.brightness_q_population_factor(noise, c, span)
        windy = volume.brightness_q_population_factor(noise, c, span, wind_m_s=wind)
        assert windy == volume.in_wind(wind).brightness_q_population_factor(noise, c, span, wind_m_s=wind)
        assert abs(windy / calm - 1.0) > 2e-3
        assert volume.brightness_q_population_factor(noise, c, span, wind_m_s=0.0) == calm
        mid = volume.brightness_q_population_factor(noise, c, span, wind_m_s=wind - 0.25 * WIND_STEP_M_S)
        below = volume.brightness_q_population_factor(noise, c, span, wind_m_s=wind - WIND_STEP_M_S)
        assert mid == pytest.approx(0.75 * windy + 0.25 * below, rel=1e-12)


def test_fast_clip_is_numpys():
    """The per-streak clip gives np.clip's values, types and NaNs, with either bound None."""
    from raingauge.gauge._numeric import clip

    rng = np.random.default_rng(0)
    x = rng.normal(size=50) * 3
    x[3] = np.nan
    for lo, hi in ((-1.0, 2.0), (None, 0.5), (0.0, None), (2, 1)):
        np.testing.assert_array_equal(clip(x, lo, hi), np.clip(x, lo, hi))
    k = np.arange(-5, 6)
    assert clip(k, 0, 3).dtype == np.clip(k, 0, 3).dtype
    assert float(clip(7.5, 0.0, 2.0)) == 2.0 and int(clip(-3, 0, 9)) == 0
