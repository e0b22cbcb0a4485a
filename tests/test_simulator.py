"""Tests of the rain simulator (raingauge.render.simulator, raingauge simulate).

The simulator is the ground truth for the detector, the gauge and the
visibility checks, so these tests hold it to the paper's photometry
(Eqs. 17-18, 22-24), its statistics (Poisson counts, Eq. 27 / Fig. 15) and
to honest bookkeeping (truth = Eq. 28 on the generated drops).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from raingauge.errors import ConfigError, InputError, ProfileError, RaingaugeError
from raingauge.physics import drops
from raingauge.profile import load_profile
from raingauge.render.simulator import (
    DEFAULT_DROP_BRIGHTNESS_DN,
    compose_rain,
    render_clip,
    render_streaks,
    simulate,
    small_profile,
    streak_capsules,
)


def _camera(profile):
    return dict(focal_length_px=profile.focal_length_px, principal_point_px=profile.principal_point,
                f_number=profile.f_number, focus_distance_m=profile.focus_distance_m,
                pixel_pitch_m=profile.pixel_pitch_m)


def _one_drop(profile, *, x_m=0.0, y_m=-0.05, z_m=None, diameter_m=2e-3, velocity_model="gunn_kinzer"):
    """Capsule of one drop falling at its terminal speed during the profile's exposure."""
    z = profile.focus_distance_m if z_m is None else z_m
    v = float(drops.fall_velocity(diameter_m, velocity_model))
    start = np.array([[x_m, y_m, z]])
    end = start + np.array([[0.0, v * profile.exposure_s, 0.0]])
    return streak_capsules(start, end, [diameter_m / 2], **_camera(profile)), v


# ------------------------------------------------------------------ photometry
def test_streak_change_is_linear_in_background_with_slope_beta():
    """Eq. (18): dI = -beta I_b + alpha along a streak, beta = tau / T, alpha = tau E_r."""
    prof = small_profile(200, 200, noise_sigma_dn=0.0, focal_length_px=7000.0)
    caps, v = _one_drop(prof, diameter_m=2.5e-3, y_m=-0.016)
    levels = np.array([10.0, 50.0, 90.0, 130.0, 170.0])
    # the streak crosses horizontal stripes of five background levels (Fig. 8(b) scene)
    rows = np.arange(200)
    bg = levels[np.minimum(rows * 5 // 200, 4)][:, None] * np.ones((1, 200), np.float32)
    beta_map, beta_in = render_streaks(prof.shape, caps["p0"], caps["p1"], caps["radius_px"], caps["area_px"])
    rainy = compose_rain(bg, beta_map, drop_brightness_dn=DEFAULT_DROP_BRIGHTNESS_DN)
    inside = beta_map > 0.999 * beta_in[0]
    assert inside.sum() > 50
    d_i = (rainy - bg)[inside]
    i_b = bg[inside]
    slope, intercept = np.polyfit(i_b, d_i, 1)
    assert slope == pytest.approx(-beta_in[0], rel=1e-4)
    assert intercept == pytest.approx(beta_in[0] * DEFAULT_DROP_BRIGHTNESS_DN, rel=1e-4)
    assert np.max(np.abs(d_i - (slope * i_b + intercept))) < 1e-3   # exactly linear
    # beta from first principles: the disc's area pi a_i^2 over the streak's area (w l + pi w^2 / 4)
    f, a = prof.focal_length_px, 1.25e-3
    a_i = f * a / prof.focus_distance_m
    w, length = 2 * a_i, f * v * prof.exposure_s / prof.focus_distance_m
    assert beta_in[0] == pytest.approx(math.pi * a_i ** 2 / (w * length + math.pi * w * w / 4), rel=0.02)
    # Eq. (29): tau < 4 a / v, so beta < 4 a / (v T); a long streak's mean tau tends to (pi/4) 2a/v
    # (Sec. 6.1's centre-line 2a/v averaged over the streak width) from below, the end caps taking some
    tau = beta_in[0] * prof.exposure_s
    assert tau < 4 * a / v
    assert 0.9 * (math.pi / 4) * 2 * a / v < tau < (math.pi / 4) * 2 * a / v


def test_streak_photometry_through_the_whole_pipeline():
    """A rendered, quantised clip over stripes keeps Eq. (18) per drawn drop (slope = its beta)."""
    prof = small_profile(240, 240, noise_sigma_dn=0.0, f_number=8.0, focal_length_px=7000.0)
    z0 = prof.focus_distance_m
    frames, truth = render_clip(prof, n_frames=16, rain_rate_mm_h=30.0, seed=4, noise=False,
                                background="stripes:20:60:100:140:180", depth_range_m=(0.9 * z0, 1.1 * z0),
                                return_clean=True, return_drops=True)
    fits = 0
    for k, fr in enumerate(truth["frames"]):
        table = fr["drops"]
        for i in np.argsort(table["beta"])[::-1][:3]:
            drop = table[int(i)]
            if drop["beta"] < 0.03:
                continue
            beta, _ = render_streaks(prof.shape, [drop["streak_px"][0]], [drop["streak_px"][1]],
                                     [(drop["width_px"] + drop["blur_px"]) / 2],
                                     [math.pi * (prof.focal_length_px * drop["radius_m"] / drop["depth_m"]) ** 2])
            alone = (beta > 0.999 * drop["beta"])
            d_i = frames[k].astype(float) - truth["clean"][k]
            i_b = truth["clean"][k].astype(float)
            sel = alone & (np.abs(d_i - drop["beta"] * (DEFAULT_DROP_BRIGHTNESS_DN - i_b)) < 1.5)
            if sel.sum() < 20 or np.ptp(i_b[sel]) < 60:
                continue
            slope, _ = np.polyfit(i_b[sel], d_i[sel], 1)
            assert slope == pytest.approx(-drop["beta"], abs=0.15 * drop["beta"] + 0.004)
            fits += 1
    assert fits >= 2


def test_far_subpixel_drop_matches_eq22_and_defocus_matches_eq24():
    """Eq. (22): a sub-pixel drop changes its 1-px-wide streak by pi f a^2 / (z v T) (dL);
    Eq. (24): defocus scales a long streak's change by w / (w + b_c)."""
    prof = small_profile(200, 200, noise_sigma_dn=0.0, focal_length_px=7000.0, exposure_s=1 / 30)
    z0 = prof.focus_distance_m
    far = prof.replace(focus_distance_m=6.0 * z0)
    a = 0.3e-3
    caps, v = _one_drop(far, z_m=6.0 * z0, diameter_m=2 * a, y_m=-0.02)
    assert np.hypot(*(caps["p1"][0] - caps["p0"][0])) > 30
    assert caps["image_radius_px"][0] < 0.5 and caps["blur_px"][0] == pytest.approx(0.0, abs=1e-9)
    beta, _ = render_streaks(far.shape, caps["p0"], caps["p1"], caps["radius_px"], caps["area_px"])
    mid_row = int(round((caps["p0"][0, 1] + caps["p1"][0, 1]) / 2))
    across = beta[mid_row].sum()          # the streak's change summed across its width
    z = 6.0 * z0
    eq22 = math.pi * prof.focal_length_px * a ** 2 / (z * v * far.exposure_s)   # paper: 4 f a^2 / (z v T)
    length = np.hypot(*(caps["p1"][0] - caps["p0"][0]))
    caps_share = length / (length + math.pi / 4)     # the rounded ends of the 1-px streak hold the rest
    assert across == pytest.approx(eq22 * caps_share, rel=0.003)
    # defocus of a near, long streak
    a = 1.0e-3
    near = prof.replace(exposure_s=1.0 / 30.0, f_number=16.0)      # long streak: v_i T >> b_c
    focused, v = _one_drop(near, diameter_m=2 * a, y_m=-0.12)
    defocused_prof = near.replace(focus_distance_m=1.4 * z0)
    defocused = streak_capsules(np.array([[0.0, -0.12, z0]]), np.array([[0.0, -0.12 + v * near.exposure_s, z0]]),
                                [a], **_camera(defocused_prof))
    _, b_f = render_streaks(near.shape, focused["p0"], focused["p1"], focused["radius_px"], focused["area_px"])
    _, b_d = render_streaks(near.shape, defocused["p0"], defocused["p1"], defocused["radius_px"],
                            defocused["area_px"])
    w, b_c = defocused["width_px"][0], defocused["blur_px"][0]
    length = np.hypot(*(defocused["p1"][0] - defocused["p0"][0]))
    assert b_c > 2 and length > 20 * (w + b_c)
    assert b_d[0] / b_f[0] == pytest.approx(w / (w + b_c), rel=0.06)


def test_exposure_area_is_conserved_and_partial_pixels_add_up():
    """Every streak deposits exactly pi a_i^2 pixel-exposures, wherever it falls (Eqs. 15, 22, 23)."""
    rng = np.random.default_rng(2)
    p0 = rng.uniform(30, 70, (60, 2))
    p1 = p0 + rng.normal(0, 8, (60, 2))
    r = rng.uniform(0.5, 5.0, 60)
    area = rng.uniform(0.05, 20.0, 60)
    for i in range(60):
        beta, beta_in = render_streaks((100, 100), p0[i:i + 1], p1[i:i + 1], r[i:i + 1], area[i:i + 1])
        assert beta.sum() == pytest.approx(area[i], rel=1e-4)
        assert beta.max() <= beta_in[0] * (1 + 1e-4)
    beta, _ = render_streaks((100, 100), p0, p1, r, area)
    assert beta.sum() == pytest.approx(area.sum(), rel=1e-4)


# ------------------------------------------------------------------ statistics
@pytest.mark.parametrize("wind, direction", [(0.0, 0.0), (6.0, 35.0), (4.0, -120.0)])
def test_drop_counts_in_a_volume_are_poisson_with_the_dsd_density(wind, direction):
    """Sec. 3: counts in a fixed volume are Poisson (dispersion index ~1) with mean rho V, at all times."""
    prof = small_profile(160, 120)
    sim = simulate(prof, seconds=40.0, rain_rate_mm_h=12.0, seed=11, wind_m_s=wind, wind_dir_deg=direction)
    box = sim.reference_box_m
    volume = sim.reference_volume_m3
    assert volume == pytest.approx(float(np.prod(box[:, 1] - box[:, 0])))
    dsd = drops.MarshallPalmer(12.0)
    expected = {lim: volume * dsd.concentration_m3() * (1 - dsd.cdf(lim)) for lim in (0.1e-3, 1.0e-3)}
    times = np.arange(0.0, 40.0, 0.2)
    counts = {0.1e-3: [], 1.0e-3: []}
    for pop in sim.population(times):
        inside = np.all((pop["position_m"] >= box[:, 0]) & (pop["position_m"] < box[:, 1]), axis=1)
        for lim in counts:
            counts[lim].append(int(np.sum(inside & (pop["diameter_m"] > lim))))
    for lim, c in counts.items():
        c = np.asarray(c, float)
        assert c.mean() == pytest.approx(expected[lim], rel=4 * math.sqrt(expected[lim] / c.size) / expected[lim] + 0.02)
        assert 0.75 < c.var(ddof=1) / c.mean() < 1.3
        # no drift: the second half holds as many drops as the first
        half = c.size // 2
        assert abs(c[:half].mean() - c[half:].mean()) < 5 * math.sqrt(2 * expected[lim] / half)


def test_drops_left_out_could_not_change_a_pixel_by_the_threshold():
    """The rain-visible region (Sec. 6.1) is honest: a drop just outside the depth range
    generated for its size changes no pixel by render_threshold_dn (drawn with the renderer)."""
    prof = small_profile(320, 240)
    sim = simulate(prof, n_frames=1, rain_rate_mm_h=10.0, seed=0, background="uniform:60")
    rendering = sim.truth["rendering"]
    threshold, contrast = rendering["render_threshold_dn"], rendering["contrast_dn"]
    assert threshold == 0.25 and contrast == pytest.approx(DEFAULT_DROP_BRIGHTNESS_DN - 60.0)
    edges = np.asarray(rendering["bin_edges_mm"]) * 1e-3
    checked = 0
    for k in range(0, edges.size - 1, 5):
        lo_hi = rendering["visible_depth_m"][k]
        d = edges[k + 1]
        for z, inside in ((None if lo_hi[0] is None else lo_hi[1] * 1.03, False),
                          (None if lo_hi[0] is None or lo_hi[0] <= 0.05 else lo_hi[0] / 1.03, False)):
            if z is None:
                continue
            caps, _ = _one_drop(prof, z_m=z, diameter_m=d, y_m=-0.01 * z)
            beta, _ = render_streaks(prof.shape, caps["p0"], caps["p1"], caps["radius_px"], caps["area_px"])
            assert beta.max() * contrast < threshold
            checked += 1
        if lo_hi[0] is not None:          # and inside the range the largest drops of the bin do reach it
            z_mid = math.sqrt(lo_hi[0] * lo_hi[1])
            caps, _ = _one_drop(prof, z_m=z_mid, diameter_m=d, y_m=-0.01 * z_mid)
            _, beta_in = render_streaks(prof.shape, caps["p0"], caps["p1"], caps["radius_px"], caps["area_px"])
            assert beta_in[0] * contrast > 0.9 * threshold
    assert checked >= 8


def test_drops_persist_and_move_exactly_with_their_velocity():
    """A drop keeps its id across frames and advances by v / frame rate; its streak is its projection."""
    prof = small_profile(160, 120, base="canon_xl1")
    sim = simulate(prof, n_frames=6, rain_rate_mm_h=15.0, seed=5, wind_m_s=3.0, wind_dir_deg=20.0)
    tables = [ft["drops"] for _, ft in sim]
    matched = 0
    for k in range(len(tables) - 1):
        a, b = tables[k], tables[k + 1]
        common, ia, ib = np.intersect1d(a["id"], b["id"], return_indices=True)
        for i, j in zip(ia, ib):
            expect = a["position_m"][i] + a["velocity_m_s"][i] / prof.frame_rate_hz
            assert np.allclose(b["position_m"][j], expect, atol=1e-9)
            assert np.allclose(a["velocity_m_s"][i], b["velocity_m_s"][j])
            matched += 1
    assert matched > 20
    t = tables[3]
    f = prof.focal_length_px
    cx, cy = prof.principal_point
    p = t["position_m"]
    assert np.allclose(t["streak_px"][:, 0, 0], f * p[:, 0] / p[:, 2] + cx)
    assert np.allclose(t["streak_px"][:, 0, 1], f * p[:, 1] / p[:, 2] + cy)
    # the fall speed is the velocity law's, the wind the one asked for
    v = drops.fall_velocity(t["diameter_m"], "gunn_kinzer")
    assert np.allclose(t["velocity_m_s"][:, 1], v)
    # every drawn drop keeps within the bound of Eq. (29), tau < 4 a / v
    from raingauge.physics.streaks import tau_bound_s

    assert np.all(t["tau_s"] < tau_bound_s(t["radius_m"], np.linalg.norm(t["velocity_m_s"], axis=1)))
    assert np.allclose(t["velocity_m_s"][:, 0], 3.0 * math.cos(math.radians(20.0)))


def _rendered_sigma(f, n_number, z0, exposure, *, rho, n_frames=60, seed=0):
    """Temporal std of a static uniform scene in rain of 1 mm drops vs Eq. (27) (Fig. 15 setup)."""
    from raingauge.physics import visibility

    prof = load_profile("canon_xl1").replace(
        width_px=48, height_px=36, focal_length_px=f, f_number=n_number, focus_distance_m=z0,
        exposure_s=exposure, frame_rate_hz=min(30.0, 1.0 / exposure), noise_sigma_dn=0.0)
    a = 0.5e-3
    dsd = drops.BinnedDSD([2 * a - 2e-6, 2 * a + 2e-6], [rho / 4e-6])
    r_visible, z_near = 3.0, 0.1
    sim = simulate(prof, n_frames=n_frames, dsd=dsd, velocity_model="paper",
                   depth_range_m=(z_near, r_visible * 2 * f * a), background="uniform:60", noise=False,
                   truth_drops=False, truth_linear=True, seed=seed)
    lin = np.stack([ft["linear"] for _, ft in sim])
    rendered = float(np.sqrt(lin.var(axis=0).mean()))
    reference = visibility.sigma_r(exposure_s=exposure, f_number=n_number, focus_distance_m=z0, focal_length_px=f,
                                   pixel_pitch_m=prof.pixel_pitch_m, radius_m=a, density_m3=rho,
                                   velocity_model="paper", contrast=DEFAULT_DROP_BRIGHTNESS_DN - 60.0,
                                   r_visible=r_visible, z_near_m=z_near)
    return rendered, reference


def test_rain_variance_follows_eq27_exposure_aperture_and_focus():
    """Eq. (27), Fig. 15: sigma_r ~ 1/sqrt(T) (a), and the N (b) and z0 (c) dependence of the
    depth integral of Eq. (26) (numerical reference: raingauge.physics.visibility).

    The rendered sigma is a constant fraction of Eq. (27): pi/4 because a drop's
    disc has area pi a^2 where Eqs. (22), (26) take the square 4 a^2, and a
    further ~0.9 because real pixels integrate a 1-px streak that straddles two
    of them (Eq. 26 assumes it covers exactly w pixels).  What Fig. 15 tests,
    the dependence on T, N and z0, must agree.
    """
    ratios = []
    # (a) exposure, f = 3155, N = 5.6, z0 = 10; density scaled with 1/T to keep the work per frame
    sig_t = []
    for t in (0.008, 0.032, 0.125):
        rho = 2000.0 * 0.008 / t
        s, ref = _rendered_sigma(3155.0, 5.6, 10.0, t, rho=rho)
        sig_t.append(s * math.sqrt(t / rho))
        ratios.append(s / ref)
    assert max(sig_t) / min(sig_t) < 1.12          # sigma sqrt(T / rho) constant: the 1/sqrt(T) law
    # (b) F-number, f = 8000, T = 16 ms, z0 = 14: sigma rises with N
    sig_n = []
    for n_number in (1.8, 4.0, 8.0):
        s, ref = _rendered_sigma(8000.0, n_number, 14.0, 0.016, rho=1000.0)
        sig_n.append(s)
        ratios.append(s / ref)
    assert sig_n[0] < sig_n[1] < sig_n[2]
    # (c) focus distance, f = 8000, T = 16 ms, N = 6.7: a maximum in between
    sig_z = []
    for z0 in (4.0, 14.0, 40.0):
        s, ref = _rendered_sigma(8000.0, 6.7, z0, 0.016, rho=1000.0)
        sig_z.append(s)
        ratios.append(s / ref)
    assert sig_z[1] > sig_z[0] and sig_z[1] > sig_z[2]
    ratios = np.array(ratios)
    assert ratios.max() / ratios.min() < 1.12      # same dependence as Eq. (26) integrated
    assert 0.6 < ratios.mean() < 0.8               # ~ (pi/4) x 0.9


# ------------------------------------------------------------------ truth
def test_truth_rate_is_eq28_on_the_generated_drops():
    """The truth's rate and DSD are Eq. (28) on the drops actually inside the reference volume."""
    prof = small_profile(160, 120)
    sim = simulate(prof, seconds=4.0, rain_rate_mm_h=8.0, dsd="gamma", dsd_params={"mu": 3.0}, seed=21,
                   truth_window_s=2.0)
    truth = sim.truth
    box = np.array(truth["reference_volume"]["box_m"])
    volume = truth["reference_volume"]["volume_m3"]
    fps, exposure = prof.frame_rate_hz, prof.exposure_s
    times = np.arange(sim.n_frames) / fps + exposure / 2
    rates, counts, z6, d34 = [], [], [], []
    for pop in sim.population(times):
        inside = np.all((pop["position_m"] >= box[:, 0]) & (pop["position_m"] < box[:, 1]), axis=1)
        d = pop["diameter_m"][inside]
        rates.append(drops.rain_rate_from_drops(d, pop["velocity_m_s"][inside, 1], volume))
        counts.append(np.histogram(d * 1e3, bins=drops.PARSIVEL_D_EDGES_MM)[0])
        z6.append(np.sum((d * 1e3) ** 6) / volume)
        d34.append([np.sum((d * 1e3) ** 3), np.sum((d * 1e3) ** 4)])
    rates, counts, z6, d34 = np.array(rates), np.array(counts), np.array(z6), np.array(d34)
    assert truth["rain_rate_mm_h"] == pytest.approx(rates.mean(), rel=1e-9)
    assert len(truth["windows"]) == 2
    half = sim.n_frames // 2
    for w, sl in zip(truth["windows"], (slice(0, half), slice(half, None))):
        assert w["rain_rate_mm_h"] == pytest.approx(rates[sl].mean(), rel=1e-9)
        n = np.asarray(w["dsd_n_m3_mm"]) * drops.PARSIVEL_D_WIDTHS_MM * volume
        assert np.allclose(n, counts[sl].mean(axis=0))
        assert set(w) >= {"t_start_s", "t_end_s", "rain_rate_mm_h", "dsd_d_mm", "dsd_n_m3_mm"}
        assert w["z_dbz"] == pytest.approx(10 * math.log10(z6[sl].mean()), abs=1e-9)
        assert w["dm_mm"] == pytest.approx(d34[sl, 1].sum() / d34[sl, 0].sum(), rel=1e-9)
    # the nominal rate is reported beside it, not forced onto it
    assert truth["nominal_rain_rate_mm_h"] == 8.0
    assert truth["ratio_to_nominal"] == pytest.approx(truth["rain_rate_mm_h"] / 8.0)
    assert truth["rain_rate_mm_h"] != 8.0
    assert 0.5 < truth["ratio_to_nominal"] < 1.5


def test_truth_rate_converges_to_the_dsd_rate():
    """Over a longer clip the generated rain's Eq. (28) rate approaches the DSD's own."""
    prof = small_profile(96, 72, base="canon_xl1", frame_rate_hz=10.0)
    sim = simulate(prof, seconds=30.0, rain_rate_mm_h=10.0, dsd="gamma", dsd_params={"mu": 2.0}, seed=8)
    truth = sim.truth      # drawing-free pass
    assert truth["rain_rate_mm_h"] == pytest.approx(10.0, rel=0.12)
    assert truth["accumulation_mm"] == pytest.approx(truth["rain_rate_mm_h"] * 30.0 / 3600.0)


def test_rain_mask_marks_pixels_changed_by_one_gray_level():
    prof = small_profile(160, 120)
    frames, truth = render_clip(prof, n_frames=5, rain_rate_mm_h=30.0, seed=3, noise=False,
                                return_masks=True, return_clean=True, truth_linear=True)
    masks, clean = truth["rain_masks"], truth["clean"]
    changed = np.abs(frames.astype(int) - clean) >= 1
    assert masks.any()
    assert np.all(changed[masks])                     # >= 1 gray level of change is always visible
    assert masks.sum() <= changed.sum()
    assert clean.std() == 0 and clean[0, 0, 0] == 60  # the uniform:60 scene


def test_same_seed_same_video_and_truth():
    prof = small_profile(120, 90)
    a, ta = render_clip(prof, n_frames=8, rain_rate_mm_h=10.0, seed=7, wind_m_s=2.0)
    b, tb = render_clip(prof, n_frames=8, rain_rate_mm_h=10.0, seed=7, wind_m_s=2.0)
    c, _ = render_clip(prof, n_frames=8, rain_rate_mm_h=10.0, seed=8, wind_m_s=2.0)
    assert np.array_equal(a, b)
    assert json.dumps(ta) == json.dumps(tb)
    assert not np.array_equal(a, c)
    # the truth read before iterating equals the truth after
    sim = simulate(prof, n_frames=8, rain_rate_mm_h=10.0, seed=7, wind_m_s=2.0)
    early = json.dumps(sim.truth)
    sim._truth = None
    for _ in sim:
        pass
    assert json.dumps(sim.truth) == early == json.dumps(ta)


def test_sensor_noise_response_and_compression():
    prof = small_profile(120, 90, noise_sigma_dn=3.0)
    frames, _ = render_clip(prof, n_frames=4, rain_rate_mm_h=0.0, seed=1, background="uniform:100")
    assert frames.std() == pytest.approx(3.0, rel=0.05)
    assert abs(frames.mean() - 100) < 0.1
    jpeg, _ = render_clip(prof, n_frames=4, rain_rate_mm_h=0.0, seed=1, background="uniform:100", jpeg_quality=30)
    assert not np.array_equal(jpeg, frames)
    # a gamma-like response table: code values follow the inverse of the table
    table = 255.0 * (np.arange(256) / 255.0) ** 2.2
    gamma_prof = prof.replace(noise_sigma_dn=0.0)
    gamma_prof = type(gamma_prof)(**{**{f: getattr(gamma_prof, f) for f in gamma_prof.__dataclass_fields__},
                                     "response": "table.txt", "response_table": table})
    frames_g, _ = render_clip(gamma_prof, n_frames=2, rain_rate_mm_h=0.0, seed=1, background="uniform:100")
    assert np.all(frames_g == 100)                    # the scene's code value survives the round trip


# ------------------------------------------------------------------ scenes
def test_backgrounds_and_scene_motion(tmp_path):
    import cv2

    from raingauge.render.scenes import Scene

    prof = small_profile(96, 72)
    still = Scene(prof, "camera")
    assert still.static and still.frame(0).shape == (72, 96) and np.ptp(still.frame(0)) > 50
    img = (np.arange(50 * 80) % 255).reshape(50, 80).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "bg.png"), img)
    assert Scene(prof, str(tmp_path / "bg.png")).frame(3).shape == (72, 96)
    for item in ("pan:40", "objects:2:80", "ripples:0.2", "foliage:3"):
        sc = Scene(prof, "astronaut", motion=item, seed=1)
        assert not sc.static
        assert np.abs(sc.frame(0) - sc.frame(15)).mean() > 0.05, item
    # a video background plays its frames
    from raingauge.videoio import FrameWriter

    with FrameWriter(tmp_path / "bg_frames", fps=30) as w:
        for k in range(3):
            w.write(np.full((40, 60), 40 + 50 * k, np.uint8))
    vid = Scene(prof, str(tmp_path / "bg_frames"))
    assert [round(float(vid.frame(k).mean())) for k in range(4)] == [40, 90, 140, 40]


# ------------------------------------------------------------------ errors
def test_clear_errors_for_impossible_requests(tmp_path):
    prof = small_profile(64, 48)
    with pytest.raises(ConfigError, match="rain rate"):
        simulate(prof, seconds=1, rain_rate_mm_h=-2.0)
    with pytest.raises(ConfigError, match="rain rate"):
        simulate(prof, seconds=1, rain_rate_mm_h=float("nan"))
    bad = tmp_path / "broken.png"
    bad.write_bytes(b"not an image")
    with pytest.raises(InputError, match="unreadable image"):
        simulate(prof, seconds=1, rain_rate_mm_h=5.0, background=str(bad))
    with pytest.raises(InputError, match="no such file"):
        simulate(prof, seconds=1, rain_rate_mm_h=5.0, background=str(tmp_path / "missing.png"))
    toml = tmp_path / "cam.toml"
    toml.write_text(Path(load_profile("gauge-default").source).read_text().replace(
        "exposure_s = 0.004", "exposure_s = 0.5"))
    with pytest.raises(ProfileError, match="exposure_s"):
        simulate(str(toml), seconds=1, rain_rate_mm_h=5.0)
    with pytest.raises(ConfigError, match="velocity model"):
        simulate(prof, seconds=1, rain_rate_mm_h=5.0, velocity_model="fast")
    with pytest.raises(ConfigError, match="scene motion"):
        simulate(prof, seconds=1, rain_rate_mm_h=5.0, motion="earthquake")
    with pytest.raises(ConfigError, match="seconds"):
        simulate(prof, seconds=0, rain_rate_mm_h=5.0)
    with pytest.raises(RaingaugeError):
        simulate(prof, seconds=1)


# ------------------------------------------------------------------ command line
def test_cli_writes_video_and_truth(tmp_path, capsys):
    from raingauge.cli import main
    from raingauge.profile import write_profile
    from raingauge.videoio import read_frames

    cam = write_profile(small_profile(128, 96), tmp_path / "small.toml")
    out = tmp_path / "rain.mkv"
    rc = main(["simulate", str(out), "--camera", str(cam), "--seconds", "0.4", "--rate", "12", "--seed", "3",
               "--masks", "--drops", "--wind", "2"])
    assert rc == 0
    video = read_frames(out)
    assert video.shape == (12, 96, 128)
    truth = json.loads((tmp_path / "rain.mkv.truth.json").read_text())
    assert truth["camera"]["width_px"] == 128 and truth["n_frames"] == 12
    assert len(truth["frames_truth"]) == 12 and truth["windows"]
    masks = read_frames(tmp_path / "rain.masks.mkv")
    assert masks.shape == video.shape and set(np.unique(masks)) <= {0, 255}
    frames, again = render_clip(cam, seconds=0.4, rain_rate_mm_h=12, seed=3, wind_m_s=2.0)
    assert np.array_equal(frames, video)           # lossless FFV1, same seed
    assert again["rain_rate_mm_h"] == pytest.approx(truth["rain_rate_mm_h"])
    rc = main(["simulate", str(tmp_path / "x.mkv"), "--camera", str(cam), "--seconds", "1", "--rate", "-1"])
    assert rc == 2 and "rain rate" in capsys.readouterr().err


# ------------------------------------------------------------------ measured rain
@pytest.mark.shared_data
def test_parsivel_replay_follows_the_records(shared_data):
    """Replaying real Parsivel records: each 30 s window's rain is that record's spectrum."""
    disdrometer = pytest.importorskip("raingauge.disdrometer")
    path = shared_data / "parsivel" / "locarno_2018-10-29.dat.gz"
    if not path.exists():
        pytest.skip(f"{path} not found")
    pf = disdrometer.read_parsivel(path)
    recs = sorted(pf.records, key=lambda r: r.time)
    rainy = [i for i in range(len(recs) - 1)
             if recs[i].reported_rate_mm_h > 5 and recs[i + 1].reported_rate_mm_h > 5
             and (recs[i + 1].time - recs[i].time).total_seconds() == 30]
    assert rainy
    i = rainy[len(rainy) // 2]
    prof = small_profile(96, 72, base="canon_xl1", frame_rate_hz=10.0)
    sim = simulate(prof, seconds=60.0, parsivel=pf, start=recs[i].time, seed=2)
    truth = sim.truth
    assert [w["t_start_s"] for w in truth["windows"]] == [0.0, 30.0]
    for w, rec in zip(truth["windows"], recs[i:i + 2]):
        n_m4 = disdrometer.record_density_m4(rec.counts, interval_s=30.0)
        edges = drops.PARSIVEL_D_EDGES_MM * 1e-3
        lo, hi = drops.FALL_VELOCITY_RANGES_M["gunn_kinzer"]
        keep = (edges[:-1] >= lo - 1e-9) & (edges[1:] <= hi + 1e-9)
        dsd = drops.BinnedDSD(edges[:-1][keep].tolist() + [edges[1:][keep][-1]], np.asarray(n_m4)[keep])
        expect = drops.rain_rate_mm_h(dsd, "gunn_kinzer")
        assert w["rain_rate_mm_h"] == pytest.approx(expect, rel=0.3)
        assert w["nominal_rain_rate_mm_h"] == pytest.approx(rec.reported_rate_mm_h)


@pytest.mark.parametrize("size", ["0x0", "32x0", "4x-3"])
def test_cli_refuses_an_empty_frame_size(tmp_path, cli_error, size):
    out = tmp_path / "x.mkv"
    cli_error(["simulate", out, "--seconds", "0.1", "--rate", "5", "--size", size],
              f"--size '{size}': width and height must be at least 1 pixel")
    assert not out.exists()


@pytest.mark.parametrize("name", ["rain.mkv", "frames"])
def test_cli_refuses_an_output_that_cannot_be_created(tmp_path, cli_error, name):
    blocker = tmp_path / "afile"
    blocker.write_text("not a folder")
    out = blocker / name
    kind = "video" if name.endswith(".mkv") else "folder"
    _, err = cli_error(["simulate", out, "--seconds", "0.1", "--rate", "5", "--size", "32x24"],
                       f"{out}: cannot create the output {kind}")
    assert "Fix: give a path in a writable folder" in err
