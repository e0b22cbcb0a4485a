"""Predict how visible rain is for given camera settings (Eq. 27 of Garg & Nayar 2007).

Prints sigma_r, the standard deviation that rain adds to a pixel's intensity,
in relative units (the drop contrast k0 (L_r - L_b) = 1; one drop of the
reference radius per cubic metre, or the Marshall-Palmer DSD of
``--rain-rate``).  Settings default to the profile's; exposures up to the
profile's exposure_range_s are accepted (beyond the frame interval a
camcorder's slow shutter lowers the frame rate).

    raingauge visibility --camera canon_xl1 --exposure-s 0.066 --f-number 14 --focus-m 10 --json
    raingauge visibility --camera canon_xl1 --sweep f-number --png n.png
    raingauge visibility --camera canon_xl1 --fig15 figdir/

``--fig15 DIR`` draws the three panels of Fig. 15 with the caption's settings
(sigma_r against T, 8-125 ms, f = 3155 px, N = 5.6, z0 = 10 m; against N,
1.8-8, f = 8000 px, T = 16 ms, z0 = 14 m; against z0, 4-40 m, f = 8000 px,
T = 16 ms, N = 6.7) on the profile's pixel pitch.
"""

from __future__ import annotations

import argparse

SWEEPS = ("exposure", "f-number", "focus")

#: Fig. 15 of [GargNayar2007]: panel -> (swept, (lo, hi), fixed settings).
FIG15_PANELS = {
    "a": ("exposure", (0.008, 0.125), dict(focal_length_px=3155.0, f_number=5.6, focus_distance_m=10.0)),
    "b": ("f-number", (1.8, 8.0), dict(focal_length_px=8000.0, exposure_s=0.016, focus_distance_m=14.0)),
    "c": ("focus", (4.0, 40.0), dict(focal_length_px=8000.0, exposure_s=0.016, f_number=6.7)),
}
_KEY = {"exposure": "exposure_s", "f-number": "f_number", "focus": "focus_distance_m"}
_SHORT = {"focal_length_px": "f", "f_number": "N", "focus_distance_m": "z0 [m]", "exposure_s": "T [s]"}
#: largest drop radius [mm]: the paper's a_max (Appendix 10.2) and the end of its velocity law
MAX_RADIUS_MM = 3.5
_LABEL = {"exposure": "exposure time T [ms]", "f-number": "F-number N", "focus": "focus distance z0 [m]"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--camera", default=None, metavar="PROFILE",
                        help="camera profile TOML or shipped name (default: gauge-default)")
    parser.add_argument("--exposure-s", type=float, default=None, metavar="T", help="exposure time [s]")
    parser.add_argument("--f-number", type=float, default=None, metavar="N", help="F-number")
    parser.add_argument("--focus-m", type=float, default=None, metavar="Z0", help="focus distance [m]")
    parser.add_argument("--focal-length-px", type=float, default=None, metavar="F",
                        help="focal length [px] (default: the profile's; a zoom lens changes it)")
    parser.add_argument("--radius-mm", type=float, default=0.5,
                        help="drop radius of the single-size prediction, mm (default 0.5)")
    parser.add_argument("--rain-rate", type=float, default=None, metavar="MM_H",
                        help="integrate over a Marshall-Palmer DSD of this rate instead of a single size")
    parser.add_argument("--sweep", choices=SWEEPS, default=None, help="draw sigma_r against one setting")
    parser.add_argument("--png", default=None, metavar="OUT", help="PNG file for --sweep")
    parser.add_argument("--fig15", default=None, metavar="DIR", help="write Fig. 15 (a)-(c) as PNGs into DIR")
    parser.add_argument("--json", action="store_true", help="print a JSON record")


def sigma_curve(which: str, values, *, focal_length_px, pixel_pitch_m, exposure_s=None, f_number=None,
                focus_distance_m=None, radius_m=None, dsd=None, velocity_model=None):
    """sigma_r (Eq. 27) along one swept setting; the others fixed.

    Parameters
    ----------
    which : {"exposure", "f-number", "focus"}
    values : sequence of float
        Swept values [s], [-] or [m].
    focal_length_px, pixel_pitch_m : float [px], [m]
    exposure_s, f_number, focus_distance_m : float
        The fixed settings (the swept one is ignored).
    radius_m, dsd, velocity_model
        As :func:`raingauge.physics.visibility.sigma_r`.

    Returns
    -------
    ndarray of sigma_r [relative units]
    """
    import numpy as np

    from raingauge.physics import visibility as vis

    if which not in SWEEPS:
        raise ValueError(f"unknown sweep {which!r}; valid: {', '.join(SWEEPS)}")
    base = dict(exposure_s=exposure_s, f_number=f_number, focus_distance_m=focus_distance_m)
    extra = {}
    if radius_m is not None:
        extra["radius_m"] = radius_m
    if dsd is not None:
        extra["dsd"] = dsd
    if velocity_model is not None:
        extra["velocity_model"] = velocity_model
    out = []
    for v in values:
        kw = dict(base)
        kw[_KEY[which]] = float(v)
        out.append(vis.sigma_r(focal_length_px=focal_length_px, pixel_pitch_m=pixel_pitch_m, **kw, **extra))
    return np.asarray(out)


def fig15_curves(pixel_pitch_m: float, *, n_points: int = 60, radius_m=None) -> dict:
    """The three curves of Fig. 15: panel -> (which, x values, sigma_r values)."""
    import numpy as np

    out = {}
    for panel, (which, (lo, hi), fixed) in FIG15_PANELS.items():
        xs = np.linspace(lo, hi, n_points)
        out[panel] = (which, xs, sigma_curve(which, xs, pixel_pitch_m=pixel_pitch_m, radius_m=radius_m, **fixed))
    return out


def _plot(path, which, xs, ys, title, current=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    scale = 1e3 if which == "exposure" else 1.0
    fig, ax = plt.subplots(figsize=(5.5, 4.0), constrained_layout=True)
    ax.plot(np.asarray(xs) * scale, ys, color="C0", lw=1.6, label="Eq. (27)")
    if current is not None:
        ax.plot([current[0] * scale], [current[1]], "o", color="C3", label="these settings")
    ax.set_xlabel(_LABEL[which])
    ax.set_ylabel("sigma_r [relative]")
    ax.set_title(title, fontsize=9)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    import json
    import math
    from pathlib import Path

    import numpy as np

    from raingauge.errors import ConfigError
    from raingauge.physics import visibility as vis
    from raingauge.profile import load_profile

    profile = load_profile(args.camera)
    if profile.pixel_pitch_m is None:
        raise ConfigError(f"camera profile {profile.name!r} has no pixel_pitch_m, needed for the blur circle. "
                          "Fix: add pixel_pitch_m to its [camera] table")
    pitch = profile.pixel_pitch_m
    if args.fig15 is not None:
        out_dir = Path(args.fig15)
        if out_dir.exists() and not out_dir.is_dir():
            raise ConfigError(f"--fig15 {out_dir} is a file, not a folder. Fix: give a folder for the three PNGs")
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ConfigError(f"--fig15 {out_dir}: cannot create the folder ({exc.strerror}). "
                              "Fix: choose a writable folder") from None
        curves = fig15_curves(pitch)
        written = []
        for panel, (which, xs, ys) in curves.items():
            fixed = FIG15_PANELS[panel][2]
            desc = ", ".join(f"{_SHORT[k]}={v:g}" for k, v in fixed.items())
            path = out_dir / f"fig15{panel}_{which}.png"
            _plot(path, which, xs, ys, f"Fig. 15({panel}): {desc}")
            written.append(str(path))
        if args.json:
            print(json.dumps({p: {"which": w, "x": list(map(float, x)), "sigma_r": list(map(float, y))}
                              for p, (w, x, y) in curves.items()}, indent=2))
        else:
            print("\n".join(written))
        return 0

    t = profile.exposure_s if args.exposure_s is None else args.exposure_s
    n = profile.f_number if args.f_number is None else args.f_number
    z0 = profile.focus_distance_m if args.focus_m is None else args.focus_m
    f = profile.focal_length_px if args.focal_length_px is None else args.focal_length_px
    exp_range = profile.exposure_range_s or (0.0, profile.frame_interval_s)
    if not (math.isfinite(t) and exp_range[0] * (1 - 1e-9) <= t <= exp_range[1] * (1 + 1e-9)) or t <= 0:
        raise ConfigError(f"--exposure-s {t} is outside what camera {profile.name!r} allows "
                          f"({exp_range[0]:g}-{exp_range[1]:g} s). Fix: pick a value in that range "
                          "(or widen exposure_range_s in the profile)")
    for name, value in (("--f-number", n), ("--focus-m", z0), ("--focal-length-px", f), ("--radius-mm", args.radius_mm)):
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(f"{name} must be a positive number, got {value}")
    if profile.f_number_range and not (profile.f_number_range[0] * (1 - 1e-9) <= n <= profile.f_number_range[1] * (1 + 1e-9)):
        raise ConfigError(f"--f-number {n} is outside the lens range {profile.f_number_range}. Fix: pick one inside")
    if z0 <= f * pitch:
        raise ConfigError(f"--focus-m {z0} m is inside the focal length {f * pitch:.3g} m. Fix: focus farther")
    if args.radius_mm > MAX_RADIUS_MM:
        raise ConfigError(f"--radius-mm {args.radius_mm} is larger than any raindrop (radius <= "
                          f"{MAX_RADIUS_MM:g} mm; larger drops break up). Fix: give a radius of 0-{MAX_RADIUS_MM:g} mm")
    if args.sweep is not None:
        if args.png is None:
            raise ConfigError("--sweep needs --png OUT (the file to draw the curve into)")
        if not Path(args.png).parent.is_dir():
            raise ConfigError(f"--png {args.png}: the folder {Path(args.png).parent} does not exist. "
                              "Fix: create it or choose another path")
    dsd = None
    velocity_model = "paper"
    if args.rain_rate is not None:
        if not (math.isfinite(args.rain_rate) and args.rain_rate > 0):
            raise ConfigError(f"--rain-rate must be > 0 mm/h, got {args.rain_rate}")
        from raingauge.physics.drops import MarshallPalmer

        dsd = MarshallPalmer(args.rain_rate)
        velocity_model = "gunn_kinzer"
    radius = args.radius_mm * 1e-3
    common = dict(focal_length_px=f, pixel_pitch_m=pitch, radius_m=radius, dsd=dsd, velocity_model=velocity_model)
    s = vis.sigma_r(exposure_s=t, f_number=n, focus_distance_m=z0, **common)
    frame_note = t > profile.frame_interval_s * (1 + 1e-9)
    record = {
        "camera": profile.name, "exposure_s": t, "f_number": n, "focus_distance_m": z0,
        "focal_length_px": f, "sigma_r": s,
        "model": ("marshall_palmer" if dsd is not None else "single_size"),
        "radius_m": None if dsd is not None else radius,
        "rain_rate_mm_h": args.rain_rate,
        "g": float(vis.visibility_g(radius, focal_length_px=f, f_number=n, focus_distance_m=z0, pixel_pitch_m=pitch)),
        "rain_visible_limit_m": float(vis.rain_visible_limit_m(radius, focal_length_px=f)),
        "effective_frame_rate_hz": min(profile.frame_rate_hz, 1.0 / t),
    }
    if args.sweep is not None:
        lo_hi = {
            "exposure": exp_range if exp_range[0] > 0 else (profile.frame_interval_s / 10, exp_range[1]),
            "f-number": profile.f_number_range or (max(1.0, n / 4), n * 4),
            "focus": (max(f * pitch * 1.5, (profile.focus_range_m or (0.5, 100.0))[0]),
                      (profile.focus_range_m or (0.5, 100.0))[1]),
        }[args.sweep]
        xs = np.geomspace(lo_hi[0], lo_hi[1], 80)
        ys = sigma_curve(args.sweep, xs, exposure_s=t, f_number=n, focus_distance_m=z0, **common)
        cur_x = {"exposure": t, "f-number": n, "focus": z0}[args.sweep]
        try:
            _plot(args.png, args.sweep, xs, ys,
                  f"{profile.name}: f={f:g} px, T={t * 1e3:g} ms, N={n:g}, z0={z0:g} m", current=(cur_x, s))
        except (ValueError, OSError) as exc:
            raise ConfigError(f"--png {args.png}: cannot write the plot ({exc}). "
                              "Fix: give a writable .png path") from None
        record["png"] = args.png
    if args.json:
        print(json.dumps(record, indent=2))
        return 0
    print(f"camera {profile.name}: T = {t * 1e3:.4g} ms, N = {n:g}, z0 = {z0:g} m, f = {f:g} px")
    print(f"sigma_r = {s:.6g} (relative units; {record['model']})")
    print(f"G(f, N, z0) = {record['g']:.6g}, rain-visible limit R z_m = {record['rain_visible_limit_m']:.3g} m")
    if frame_note:
        print(f"note: exposure exceeds the frame interval; slow shutter, effective {1.0 / t:.3g} frames/s")
    if args.sweep is not None:
        print(f"wrote {args.png}")
    return 0
