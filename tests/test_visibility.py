"""Visibility of rain, Eqs. (20)-(27) [GargNayar2007]: parts, closed forms, Fig. 15, simulator."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import quad

from raingauge.cli import main
from raingauge.physics import camera, drops
from raingauge.physics import visibility as vis

PITCH = 6.7e-6  # Canon XL1 profile


def geo(f=8000.0, n=5.6, z0=10.0):
    return dict(focal_length_px=f, f_number=n, focus_distance_m=z0, pixel_pitch_m=PITCH)


# ------------------------------------------------------------------ Eq. 20
def test_gain_keeps_brightness_across_settings():
    k0 = 3.0
    for t, n in [(0.008, 2.4), (0.033, 6.0), (0.125, 14.0)]:
        k = vis.gain_for_brightness(k0, exposure_s=t, f_number=n)
        assert vis.image_intensity(10.0, exposure_s=t, f_number=n, gain=k) == pytest.approx(30.0)
    # doubling T at fixed gain doubles the intensity; doubling N quarters it
    i = vis.image_intensity(1.0, exposure_s=0.016, f_number=4.0)
    assert vis.image_intensity(1.0, exposure_s=0.032, f_number=4.0) == pytest.approx(2 * i)
    assert vis.image_intensity(1.0, exposure_s=0.016, f_number=8.0) == pytest.approx(i / 4)


# -------------------------------------------------------------- Eqs. 21-24
def test_near_and_far_intensity_changes_meet_at_z_m():
    a, v, t, f = 1e-3, 6.3, 0.016, 8000.0
    zm = 2 * f * a
    near = vis.delta_i_near(a, velocity_m_s=v, exposure_s=t)
    far = vis.delta_i_far(a, zm, velocity_m_s=v, exposure_s=t, focal_length_px=f)
    assert far == pytest.approx(near)
    # Eq. (21) does not depend on z; Eq. (22) falls as 1/z; both as 1/T
    z = np.array([0.5 * zm, zm, 2 * zm, 4 * zm])
    d = vis.delta_i_focused(a, z, velocity_m_s=v, exposure_s=t, focal_length_px=f)
    assert d[0] == pytest.approx(d[1])
    assert d[2] == pytest.approx(d[1] / 2) and d[3] == pytest.approx(d[1] / 4)
    assert vis.delta_i_near(a, velocity_m_s=v, exposure_s=2 * t) == pytest.approx(near / 2)
    # tau = 2a/v, a few tenths of a millisecond, far below T (Sec. 6.1)
    assert vis.residence_time_s(a, v) == pytest.approx(2e-3 / 6.3)


def test_defocus_spreads_the_change():
    d = vis.delta_i_defocused(1.0, width_px=2.0, blur_px=0.0)
    assert d == pytest.approx(1.0)
    assert vis.delta_i_defocused(1.0, width_px=2.0, blur_px=6.0) == pytest.approx(0.25)
    # Eq. (23) tends to Eq. (24) for streaks much longer than the blur circle
    eq23 = vis.delta_i_defocused(1.0, width_px=2.0, blur_px=6.0, streak_length_px=1e6)
    assert eq23 == pytest.approx(0.25, rel=1e-5)
    assert vis.delta_i_defocused(1.0, width_px=2.0, blur_px=6.0, streak_length_px=6.0) == pytest.approx(0.125)


def test_layer_variance_is_the_assembled_eq26():
    a, rho, v, t = 1e-3, 50.0, 6.3, 0.016
    g = geo()
    z = np.geomspace(0.5, 60.0, 40)
    got = vis.layer_variance_density(z, radius_m=a, density_m3=rho, velocity_m_s=v, exposure_s=t, **g)
    w = np.maximum(2 * g["focal_length_px"] * a / z, 1.0)
    b = camera.blur_circle_px(z, **g)
    want = 16 * a**4 * rho * g["focal_length_px"] / (v * t * z * (w + b))
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # Eq. (31): drops per pixel in a layer
    assert vis.mean_drops_per_pixel(rho, 10.0, 0.1, velocity_m_s=v, exposure_s=t, focal_length_px=8000.0) == \
        pytest.approx(rho * 10.0 / 8000.0 * v * t * 0.1)


# ---------------------------------------------------------- G(f, N, z0)
CASES = [(f, n, z0, a) for f in (3155.0, 8000.0) for n in (1.6, 2.4, 6.7, 14.0)
         for z0 in (0.3, 3.0, 8.0, 14.0, 40.0, 150.0) for a in (0.25e-3, 0.5e-3, 1.5e-3)]


def test_closed_form_g_matches_numerical_integral():
    worst = 0.0
    for f, n, z0, a in CASES:
        kw = geo(f, n, z0)
        g_num = vis.visibility_g(a, method="numerical", **kw)
        g_closed = vis.visibility_g(a, **kw)
        worst = max(worst, abs(g_closed / g_num - 1))
        if vis.Z_NEAR_M < z0:
            assert vis.visibility_g_cases(a, **kw) == pytest.approx(g_num, rel=1e-6)
    # both are exact: they agree to the quadrature's tolerance, not merely to a per cent
    assert worst < 1e-6
    # the vectorised closed form over radii equals the scalar one
    radii = np.array([0.3e-3, 0.8e-3, 2.0e-3])
    many = vis.visibility_g(radii, **geo())
    assert many == pytest.approx([vis.visibility_g(r, **geo()) for r in radii], rel=1e-12)


@pytest.mark.parametrize("z_near", [0.0, 0.1, 1.0])
def test_closed_form_g_covers_focus_nearer_than_the_first_layer(z_near):
    # case 4 (z0 < z1, not in the paper) and z1 = 0 (every drop down to the lens)
    for f, z0, a in [(8000.0, 0.06, 0.5e-3), (3155.0, 0.5, 0.25e-3), (3155.0, 0.05, 1.5e-3)]:
        kw = dict(geo(f, 2.0, z0), z_near_m=z_near)
        g_num = vis.visibility_g(a, method="numerical", **kw)
        assert g_num > 0
        # (the quadrature starts at 1 um where z1 = 0: a few 1e-6 of G below the closed form)
        assert vis.visibility_g(a, **kw) == pytest.approx(g_num, rel=1e-5)


def test_paper_cases_are_each_exercised():
    f, a = 8000.0, 0.5e-3
    zm = 2 * f * a
    seen = set()
    for z0 in (0.5 * zm, 2 * zm, 10 * zm):
        case = 1 if z0 > vis.R_VISIBLE * zm else (2 if z0 > zm else 3)
        seen.add(case)
        g_num = vis.visibility_g(a, method="numerical", **geo(f, 4.0, z0))
        assert vis.visibility_g_cases(a, **geo(f, 4.0, z0)) == pytest.approx(g_num, rel=1e-6)
    assert seen == {1, 2, 3}


def test_g_without_defocus_is_the_pinhole_limit():
    # N -> infinity: no blur, G = f ((z_m - z1)/z_m + ln R) from w = max(z_m/z, 1) alone
    f, a, z1 = 8000.0, 0.5e-3, 0.1
    zm = 2 * f * a
    g = vis.visibility_g(a, **geo(f, 1e7, 10.0), z_near_m=z1)
    assert g == pytest.approx(f * ((zm - z1) / zm + math.log(vis.R_VISIBLE)), rel=1e-4)
    # defocus can only lower G
    assert vis.visibility_g(a, **geo(f, 2.0, 10.0)) < g


def test_g_rejects_bad_input():
    with pytest.raises(ValueError, match="valid: closed_form, numerical"):
        vis.visibility_g(1e-3, method="simpson", **geo())
    with pytest.raises(ValueError, match="radius_m"):
        vis.visibility_g(-1e-3, **geo())
    with pytest.raises(ValueError, match="focus"):
        vis.visibility_g(1e-3, **geo(z0=0.01))


# --------------------------------------------------------------- Eq. 27
def test_sigma_r_scaling_laws():
    base = dict(exposure_s=0.016, **geo(), radius_m=1e-3, density_m3=10.0)
    s = vis.sigma_r(**base)
    assert vis.sigma_r(**{**base, "exposure_s": 0.064}) == pytest.approx(s / 2)          # 1/sqrt(T)
    assert vis.sigma_r(**{**base, "density_m3": 40.0}) == pytest.approx(2 * s)           # sqrt(rho)
    assert vis.sigma_r(**base, contrast=30.0) == pytest.approx(30 * s)                   # (L_r - L_b)
    # a^2 / sqrt(v(a)) G(a)^(1/2): check against the parts
    g = vis.visibility_g(1e-3, **geo())
    v = float(drops.fall_velocity(2e-3, model="paper"))
    assert s == pytest.approx(math.sqrt(16 * 1e-12 * 10.0 * g / (v * 0.016)))


def test_sigma_r_over_a_dsd_matches_independent_quadrature():
    dsd = drops.MarshallPalmer(10.0)
    kw = dict(exposure_s=0.016, **geo())
    got = vis.sigma_r(**kw, dsd=dsd, velocity_model="gunn_kinzer")

    def integrand(d):
        a = d / 2
        v = float(drops.fall_velocity(d, model="gunn_kinzer"))
        return float(dsd.number_density(d)) * 16 * a**4 * vis.visibility_g(a, **geo()) / v

    var, _ = quad(integrand, dsd.d_min_m, dsd.d_max_m, limit=200, epsrel=1e-8)
    assert got == pytest.approx(math.sqrt(var / 0.016), rel=1e-3)


def test_narrow_dsd_equals_single_size():
    d, half, rho = 2.0e-3, 1e-6, 30.0
    narrow = drops.BinnedDSD(np.array([d - half, d + half]), np.array([rho / (2 * half)]))
    kw = dict(exposure_s=0.033, **geo(8000.0, 4.0, 14.0), velocity_model="paper")
    assert vis.sigma_r(**kw, dsd=narrow, n_sizes=41) == pytest.approx(
        vis.sigma_r(**kw, radius_m=d / 2, density_m3=rho), rel=1e-3)


# ---------------------------------------------------------------- Fig. 15
def test_fig15_shapes():
    from raingauge.commands.visibility import fig15_curves

    curves = fig15_curves(PITCH, n_points=40)
    # (a) sigma_r falls exactly as 1/sqrt(T)
    _, t, s = curves["a"]
    assert np.all(np.diff(s) < 0)
    np.testing.assert_allclose(s * np.sqrt(t), s[0] * np.sqrt(t[0]), rtol=1e-9)
    # (b) rises with N, then flattens: monotone, concave, final slope a fraction of the first
    _, n, s = curves["b"]
    slope = np.diff(s) / np.diff(n)
    assert np.all(slope > 0)
    assert np.all(np.diff(slope) < 0)
    assert slope[-1] < 0.35 * slope[0]
    # (c) one interior maximum in z0 over 4-40 m
    _, z, s = curves["c"]
    k = int(np.argmax(s))
    assert 0 < k < len(s) - 1
    assert np.all(np.diff(s[: k + 1]) > 0) and np.all(np.diff(s[k:]) < 0)
    assert s[0] < 0.9 * s[k] and s[-1] < 0.9 * s[k]


def test_fig15_command_writes_three_pngs(tmp_path, capsys):
    assert main(["visibility", "--camera", "canon_xl1", "--fig15", str(tmp_path)]) == 0
    pngs = sorted(tmp_path.glob("fig15*.png"))
    assert [p.name[:6] for p in pngs] == ["fig15a", "fig15b", "fig15c"]
    for p in pngs:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000


# ----------------------------------------------------------------- command
def test_visibility_command_json_and_sweep(tmp_path, capsys):
    args = ["visibility", "--camera", "canon_xl1", "--exposure-s", "0.066", "--f-number", "14", "--focus-m", "10",
            "--json"]
    assert main(args) == 0
    rec = json.loads(capsys.readouterr().out)
    want = vis.sigma_r(exposure_s=0.066, **geo(8000.0, 14.0, 10.0))
    assert rec["sigma_r"] == pytest.approx(want)
    assert rec["effective_frame_rate_hz"] == pytest.approx(1 / 0.066)  # slow shutter
    png = tmp_path / "n.png"
    assert main(["visibility", "--camera", "canon_xl1", "--sweep", "f-number", "--png", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_visibility_command_rejects_impossible_settings(capsys):
    assert main(["visibility", "--camera", "canon_xl1", "--exposure-s", "0.5"]) == 2
    assert "exposure" in capsys.readouterr().err
    assert main(["visibility", "--camera", "canon_xl1", "--sweep", "focus"]) == 2
    assert "--png" in capsys.readouterr().err


# ------------------------------------------------------------- simulator
def test_simulator_agrees_with_eq27_on_a_small_scene():
    """Per-pixel sigma_r of rendered rain vs Eq. (27) (benchmarks/ has the full grid).

    The renderer uses the exact exposure area pi a_i^2 of a drop where
    Eqs. (21)-(22) use the bounding square, so it should give pi/4 of Eq. (27);
    the ratio of two exposures must follow 1/sqrt(T).
    """
    from raingauge.render.simulator import render_clip, small_profile

    base = small_profile(320, 240, base="canon_xl1").replace(width_px=128, height_px=96, noise_sigma_dn=0.5,
                                                              f_number=4.0, focus_distance_m=14.0)
    d, rho = 2e-3, 200.0
    dsd = drops.BinnedDSD(np.array([d - 0.05e-3, d + 0.05e-3]), np.array([rho / 1e-4]))
    z_far = float(vis.rain_visible_limit_m(d / 2, focal_length_px=base.focal_length_px))
    noise, _ = render_clip(base, n_frames=40, rain_rate_mm_h=0.0, seed=5, background="uniform:20")
    var0 = noise.astype(float).var(axis=0).mean()
    measured, predicted = {}, {}
    for t in (0.016, 0.033):
        prof = base.replace(exposure_s=t)
        frames, _ = render_clip(prof, n_frames=32, dsd=dsd, seed=7, depth_range_m=(vis.Z_NEAR_M, z_far),
                                background="uniform:20", drop_brightness_dn=255.0, velocity_model="gunn_kinzer")
        measured[t] = math.sqrt(frames.astype(float).var(axis=0).mean() - var0)
        predicted[t] = 235.0 * vis.sigma_r(exposure_s=t, focal_length_px=prof.focal_length_px, f_number=4.0,
                                           focus_distance_m=14.0, pixel_pitch_m=prof.pixel_pitch_m,
                                           radius_m=d / 2, density_m3=rho, velocity_model="gunn_kinzer")
        assert measured[t] / (math.pi / 4 * predicted[t]) == pytest.approx(1.0, abs=0.15)
    assert measured[0.033] / measured[0.016] == pytest.approx(predicted[0.033] / predicted[0.016], rel=0.15)


@pytest.mark.parametrize("args, message", [
    (["--radius-mm", "50"], "larger than any raindrop"),
    (["--radius-mm", "0"], "--radius-mm"),
    (["--f-number", "nan"], "--f-number"),
    (["--focus-m", "0.001"], "inside the focal length"),
    (["--rain-rate", "-1"], "--rain-rate"),
    (["--camera", "no-such-camera"], "no-such-camera"),
    (["--exposure-s", "abc"], "invalid float value: 'abc'"),
    (["--fig15", "{file}"], "is a file, not a folder"),
    (["--sweep", "focus", "--png", "{missing}/n.png"], "does not exist"),
    (["--sweep", "focus", "--png", "{tmp}/n.xyz"], "cannot write the plot"),
])
def test_visibility_command_bad_input(tmp_path, cli_error, args, message):
    (tmp_path / "f.txt").write_text("x")
    fill = dict(file=str(tmp_path / "f.txt"), missing=str(tmp_path / "missing"), tmp=str(tmp_path))
    argv = ["visibility", "--camera", "canon_xl1", *[a.format(**fill) for a in args]]
    if args[:2] == ["--camera", "no-such-camera"]:
        argv = ["visibility", *args]
    cli_error(argv, message)
    assert not (tmp_path / "missing").exists() and not list(tmp_path.glob("n.*"))
