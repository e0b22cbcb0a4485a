"""Advise camera settings that reduce rain in a picture, or enhance it for the gauge.

Goal ``reduce`` (Sec. 7 and Table 1 of Garg & Nayar 2007): the exposure,
F-number and focus that make rain least visible (Eq. 27) while the scene stays
sharp (motion blur within a pixel, the scene inside the depth of field, gain
keeping brightness, Eq. 20).  Describe the scene with Table 1's categories or
numbers:

    raingauge advise --camera canon_xl1 --goal reduce --motion slow --near close --depth large
    raingauge advise --camera canon_xl1 --goal reduce --motion 40 --near 30 --depth 10 --json
    raingauge advise --camera canon_xl1 --table1

``--motion`` slow (15 px/s) | fast (125 px/s) | PX_PER_S; ``--near`` close |
far (against the rain-visible limit R z_m, 24 m for the XL1) | METRES;
``--depth`` small (half the near distance) | large (to the horizon) | METRES
(``inf`` allowed).  "X" (infeasible) is answered where no setting helps.

Goal ``gauge`` (Sec. 8): focus z0 <= 2 f a_min, the widest aperture, a short
exposure; prints the sample volume per drop-size class, the drops expected
per minute and the counting uncertainty of the rate at 1, 10 and 50 mm/h.

JSON keys: exposure_s, f_number, focus_distance_m, predicted_reduction
(reduce) or sample_volume_m3 (gauge), feasible, reason.
"""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--camera", default=None, metavar="PROFILE",
                        help="camera profile TOML or shipped name (default: gauge-default)")
    parser.add_argument("--goal", choices=("reduce", "gauge"), default="reduce")
    parser.add_argument("--motion", default="slow", help="slow | fast | image motion in px/s (default slow)")
    parser.add_argument("--near", default="far", help="close | far | nearest scene distance in m (default far)")
    parser.add_argument("--depth", default="small", help="small | large | depth range in m (default small)")
    parser.add_argument("--rain-rate", type=float, default=None, metavar="MM_H",
                        help="known rain rate; heavy rain (>= 7.6 mm/h) allows the slow shutter")
    parser.add_argument("--slow-shutter", choices=("auto", "always", "never"), default="auto",
                        help="exposures longer than the frame interval (default auto)")
    parser.add_argument("--a-min-mm", type=float, default=0.5,
                        help="gauge: radius of the smallest drop to size, mm (default 0.5)")
    parser.add_argument("--table1", action="store_true", help="print Table 1 (rows a-h) for this camera")
    parser.add_argument("--json", action="store_true", help="print a JSON record")


def _fmt_settings(a) -> str:
    if not a.feasible:
        return "X"
    s = a.settings
    return f"T = {s.exposure_s * 1e3:.3g} ms, N = {s.f_number:.3g}, z0 = {s.focus_distance_m:.3g} m"


def run(args: argparse.Namespace) -> int:
    import json
    import math

    from raingauge import advisor
    from raingauge.errors import ConfigError
    from raingauge.profile import load_profile

    profile = load_profile(args.camera)
    if args.rain_rate is not None and not (args.rain_rate >= 0 and math.isfinite(args.rain_rate)):
        raise ConfigError(f"--rain-rate must be >= 0 mm/h, got {args.rain_rate}")
    if args.table1:
        rows = advisor.table1(profile, rain_rate_mm_h=args.rain_rate, slow_shutter=args.slow_shutter)
        if args.json:
            print(json.dumps({k: a.to_dict() for k, a in rows.items()}, indent=2))
            return 0
        print(f"Table 1 for {profile.name} (rain-visible limit R z_m = "
              f"{advisor.rain_visible_limit_m(profile):.3g} m)")
        print(f"{'row':4s}{'motion':8s}{'near':7s}{'depth':7s}{'advised':42s}{'paper':16s}")
        for k, a in rows.items():
            motion, near, depth, t, n = advisor.TABLE1_ROWS[k]
            paper = "X" if t is None else f"{t * 1e3:g} ms, N {n:g}"
            print(f"({k}) {motion:8s}{near:7s}{depth:7s}{_fmt_settings(a):42s}{paper}")
        return 0
    if args.goal == "reduce":
        scene = advisor.make_scene(profile, motion=args.motion, near=args.near, depth=args.depth)
        advice = advisor.advise_reduce(profile, scene, rain_rate_mm_h=args.rain_rate,
                                       slow_shutter=args.slow_shutter)
    else:
        if not (args.a_min_mm > 0):
            raise ConfigError(f"--a-min-mm must be > 0, got {args.a_min_mm}")
        advice = advisor.advise_gauge(profile, a_min_m=args.a_min_mm * 1e-3)
    record = advice.to_dict()
    if args.json:
        print(json.dumps(record, indent=2))
        return 0
    print(f"camera {profile.name}, goal {advice.goal}")
    if advice.goal == "reduce":
        sc = advice.scene
        far = "inf" if math.isinf(sc.far_m) else f"{sc.far_m:.3g}"
        print(f"scene: motion {sc.motion_px_s:g} px/s, {sc.near_m:.3g}-{far} m"
              + (f" ({sc.label})" if sc.label else ""))
    print(f"settings: {_fmt_settings(advice)}")
    if advice.goal == "reduce" and advice.feasible:
        print(f"predicted reduction of rain visibility: x{advice.predicted_reduction:.3f}")
    if advice.goal == "gauge" and advice.feasible:
        print(f"sample volume (D = {record['sample_volume_for_d_mm']:g} mm): {record['sample_volume_m3']:.4g} m^3")
        print("  D [mm]   volume [m^3]   depth range [m]")
        for c in record["per_class"]:
            rng = "-" if c["z_lo_m"] is None else f"{c['z_lo_m']:.3g}-{c['z_hi_m']:.3g}"
            print(f"  {c['d_mm']:6.3f}   {c['volume_m3']:12.4g}   {rng}")
        for c in record["counting"]:
            print(f"  {c['rain_rate_mm_h']:g} mm/h (Marshall-Palmer): {c['drops_per_minute']:.0f} drops/min, "
                  f"{c['drops_per_frame']:.1f} per frame, rate +-{100 * c['rate_rel_uncertainty']:.2f}% "
                  f"(1 sigma, {c['window_s']:g} s); sized drops carry {c['rate_measured_mm_h']:.3g} of "
                  f"{c['rate_dsd_mm_h']:.3g} mm/h")
    print("why: " + advice.reason.replace("; ", "\n     "))
    return 0
