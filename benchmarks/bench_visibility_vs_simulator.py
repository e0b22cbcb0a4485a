"""Eq. (27) against the rain simulator: per-pixel sigma_r on rendered static scenes.

For each camera setting (T, N, z0) a static uniform scene is rendered with
rain of a single drop size (a narrow bin at D = 2 mm) filling the depths
[z_near, R z_m] that Eq. (27) integrates over, and the per-pixel temporal
variance is measured as in Sec. 6.2 of [GargNayar2007]: the variance of each
pixel over the clip, averaged over pixels, minus the camera-noise variance of
a rain-free clip (the paper's note 23).  Three predictions are printed:

``eq27``      sigma_r of Eq. (27) (:func:`raingauge.physics.visibility.sigma_r`)
              with the simulator's contrast k0 (L_r - L_b) = E_r - I_b;
``pi/4 eq27`` the same times pi/4: the renderer uses the exact exposure area
              pi a_i^2 of a drop where Eqs. (21)-(22) use the bounding square
              (tau = 2a/v on the streak's centre line), a constant factor;
``capsule``   the depth integral redone as the renderer images a drop, without
              two approximations of Eqs. (24)-(25): (i) v_i T >> b_c: a streak
              is a capsule of diameter d = w + b_c and length L = v_i T, area
              A = d L + pi d^2 / 4, every point inside changed by pi a_i^2 / A;
              (ii) point-like pixels: a pixel integrates the streak over its
              area, so a band of width d crossing it at a random offset covers
              it partly, and the mean square change is (1 - 1/(3d)) of the
              point-sampled one.  sigma^2 = contrast^2 rho integral
              (z/f)^2 pi^2 a_i^4 (1 - 1/(3d)) / A dz.  Relative to pi/4 Eq. (27)
              the variance at depth z is scaled by (1 - 1/(3d)) / (1 + pi d / (4 L)):
              thin, focused streaks (d ~ 1 px) lose up to a third of it.

The test of the issue is sim / (pi/4 eq27) within 15 %; where it is not, the
benchmark prints the capsule model's prediction for that ratio and the
depth-weighted d / L and d that explain it (short exposures make streaks no
longer than they are wide; focused streaks about a pixel wide are shared
between neighbouring pixels).
It also compares the *ratios* to a base setting (the advisor's reduction
factors), in which the constant cancels.

    python benchmarks/bench_visibility_vs_simulator.py            # one-at-a-time sweeps (9 settings)
    python benchmarks/bench_visibility_vs_simulator.py --full     # all 45 settings

Slow shutter: T = 66 and 125 ms exceed the 1/30 s frame interval; the clip is
rendered at 1/T frames per second, as a camcorder's slow shutter does.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time

import numpy as np

EXPOSURES = (0.008, 0.016, 0.033, 0.066, 0.125)
F_NUMBERS = (2.0, 4.0, 8.0)
FOCUS = (4.0, 14.0, 40.0)
BASE = (0.016, 4.0, 14.0)
DIAMETER_M = 2.0e-3
BACKGROUND_DN = 20.0
DROP_DN = 255.0


def capsule_sigma(*, contrast, density_m3, radius_m, velocity_m_s, exposure_s, f_number, focus_distance_m,
                  focal_length_px, pixel_pitch_m, z_near_m, z_far_m, n=4000):
    """sigma_r of the capsule model (module docstring), its variance-weighted mean d/L and median d [px]."""
    from scipy.integrate import simpson

    from raingauge.physics import camera

    z = np.geomspace(z_near_m, z_far_m, n)
    f = focal_length_px
    a_i = f * radius_m / z
    w = np.maximum(2.0 * a_i, 1.0)
    b = camera.blur_circle_px(z, focal_length_px=f, f_number=f_number, focus_distance_m=focus_distance_m,
                              pixel_pitch_m=pixel_pitch_m)
    d = w + b
    length = f * velocity_m_s * exposure_s / z
    area = d * length + math.pi * d * d / 4.0
    # a pixel integrates over its area: a band of width d >= 1 px crossing at a random
    # offset covers the pixels it touches partly; the mean square coverage is (d - 1/3) / d
    # of the point-sampled value (box filter), so the variance falls by 1 - 1/(3 d)
    integrand = (z / f) ** 2 * math.pi**2 * a_i**4 / area * (1.0 - 1.0 / (3.0 * d))
    var = contrast**2 * density_m3 * simpson(integrand, x=z)
    weight = integrand / np.sum(integrand)
    d_median = float(d[np.searchsorted(np.cumsum(weight), 0.5)])
    return math.sqrt(var), float(np.sum(weight * d / length)), d_median


def measure(profile, *, dsd, depth_range_m, n_frames, seed, var_noise):
    from raingauge.render.simulator import render_clip

    frames, truth = render_clip(profile, n_frames=n_frames, dsd=dsd, seed=seed, depth_range_m=depth_range_m,
                                background=f"uniform:{BACKGROUND_DN:g}", velocity_model="gunn_kinzer",
                                drop_brightness_dn=DROP_DN)
    var = float(frames.astype(np.float64).var(axis=0).mean())
    return math.sqrt(max(var - var_noise, 0.0)), truth


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="all 5 x 3 x 3 settings (default: sweeps around a base)")
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=120)
    ap.add_argument("--frames", type=int, default=48, help="frames per setting (halved for T > 1/30 s)")
    ap.add_argument("--density", type=float, default=200.0, help="drops of the size per m^3")
    ap.add_argument("--tolerance", type=float, default=0.15)
    args = ap.parse_args(argv)

    from raingauge.physics import drops
    from raingauge.physics import visibility as vis
    from raingauge.render.simulator import render_clip, small_profile

    # The Canon XL1 at 320x240 (field of view kept), cropped to the centre: f = 3556 px.
    base = small_profile(320, 240, base="canon_xl1").replace(width_px=args.width, height_px=args.height,
                                                              noise_sigma_dn=0.5)
    f = base.focal_length_px
    pitch = base.pixel_pitch_m
    a = DIAMETER_M / 2.0
    half_bin = 0.05e-3
    dsd = drops.BinnedDSD(np.array([DIAMETER_M - half_bin, DIAMETER_M + half_bin]),
                          np.array([args.density / (2 * half_bin)]))
    v = float(drops.fall_velocity(DIAMETER_M, model="gunn_kinzer"))
    z_far = float(vis.rain_visible_limit_m(a, focal_length_px=f))
    z_near = vis.Z_NEAR_M
    contrast = DROP_DN - BACKGROUND_DN
    noise_frames, _ = render_clip(base, n_frames=args.frames, rain_rate_mm_h=0.0, seed=99,
                                  background=f"uniform:{BACKGROUND_DN:g}")
    var_noise = float(noise_frames.astype(np.float64).var(axis=0).mean())

    if args.full:
        settings = list(itertools.product(EXPOSURES, F_NUMBERS, FOCUS))
    else:
        settings = [BASE] + [(t, BASE[1], BASE[2]) for t in EXPOSURES if t != BASE[0]] \
            + [(BASE[0], n, BASE[2]) for n in F_NUMBERS if n != BASE[1]] \
            + [(BASE[0], BASE[1], z) for z in FOCUS if z != BASE[2]]
    print(f"camera: XL1 scaled, {args.width}x{args.height} px, f = {f:.0f} px, pitch = {pitch:.3g} m; "
          f"D = {DIAMETER_M * 1e3:g} mm, rho = {args.density:g} m^-3, v = {v:.2f} m/s (Gunn-Kinzer); "
          f"depths {z_near:g}-{z_far:.1f} m (R z_m); contrast {contrast:g} DN; noise variance {var_noise:.3f} DN^2")
    print(f"{'T ms':>6} {'N':>4} {'z0 m':>5} {'frames':>6} {'sim':>7} {'eq27':>7} {'pi/4eq27':>8} "
          f"{'capsule':>7} {'sim/(pi/4 eq27)':>15} {'sim/capsule':>11} {'d/L':>6} {'d px':>5} {'secs':>5}")
    rows = []
    t_all = time.time()
    for k, (t_exp, n_num, z0) in enumerate(settings):
        prof = base.replace(exposure_s=t_exp, f_number=n_num, focus_distance_m=z0,
                            frame_rate_hz=min(base.frame_rate_hz, 1.0 / t_exp))
        n_frames = args.frames if t_exp <= base.frame_interval_s else max(args.frames // 2, 12)
        t0 = time.time()
        s_sim, _ = measure(prof, dsd=dsd, depth_range_m=(z_near, z_far), n_frames=n_frames, seed=k + 1,
                           var_noise=var_noise)
        secs = time.time() - t0
        s27 = contrast * vis.sigma_r(exposure_s=t_exp, f_number=n_num, focus_distance_m=z0, focal_length_px=f,
                                     pixel_pitch_m=pitch, radius_m=a, density_m3=args.density,
                                     velocity_model="gunn_kinzer", z_near_m=z_near)
        s_cap, d_over_l, d_mean = capsule_sigma(contrast=contrast, density_m3=args.density, radius_m=a, velocity_m_s=v,
                                        exposure_s=t_exp, f_number=n_num, focus_distance_m=z0,
                                        focal_length_px=f, pixel_pitch_m=pitch, z_near_m=z_near, z_far_m=z_far)
        r27 = s_sim / (math.pi / 4 * s27)
        rows.append(dict(t=t_exp, n=n_num, z0=z0, sim=s_sim, eq27=s27, cap=s_cap, r27=r27, d_l=d_over_l, d=d_mean))
        print(f"{t_exp * 1e3:6.0f} {n_num:4g} {z0:5g} {n_frames:6d} {s_sim:7.3f} {s27:7.3f} {math.pi / 4 * s27:8.3f} "
              f"{s_cap:7.3f} {r27:15.3f} {s_sim / s_cap:11.3f} {d_over_l:6.2f} {d_mean:5.1f} {secs:5.1f}", flush=True)

    print(f"\ntotal {time.time() - t_all:.0f} s")
    base_row = next(r for r in rows if (r["t"], r["n"], r["z0"]) == BASE)
    print("\nreduction factors against the base setting "
          f"(T = {BASE[0] * 1e3:g} ms, N = {BASE[1]:g}, z0 = {BASE[2]:g} m): measured vs Eq. (27)")
    for r in rows:
        if r is base_row:
            continue
        meas = r["sim"] / base_row["sim"]
        pred = r["eq27"] / base_row["eq27"]
        print(f"  T {r['t'] * 1e3:5.0f} ms N {r['n']:3g} z0 {r['z0']:4g} m: measured {meas:.3f}  "
              f"Eq. (27) {pred:.3f}  ratio {meas / pred:.3f}")
    bad = [r for r in rows if abs(r["r27"] - 1.0) > args.tolerance]
    print(f"\n{len(rows) - len(bad)} of {len(rows)} settings agree with (pi/4) Eq. (27) within "
          f"{100 * args.tolerance:g} %.")
    if bad:
        print("Where they part, and why (Eq. (24) assumes streaks much longer than their defocused width,"
              " v_i T >> b_c, and Eq. (25) point-like pixels; see the capsule model):")
        for r in bad:
            print(f"  T {r['t'] * 1e3:5.0f} ms N {r['n']:3g} z0 {r['z0']:4g} m: sim/(pi/4 eq27) = {r['r27']:.3f}, "
                  f"depth-weighted d/L = {r['d_l']:.2f}, d = {r['d']:.1f} px -> capsule model predicts {r['cap'] / (math.pi / 4 * r['eq27']):.3f}"
                  f", simulator/capsule = {r['sim'] / r['cap']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
