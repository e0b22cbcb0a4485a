"""Render a close-up rain streak of an oscillating drop (Sec. 9 of Garg & Nayar 2007).

The drop (equilibrium shape plus the oblate-prolate and transverse oscillation
modes at Rayleigh's frequency) is ray-traced at many instants while it falls
and averaged over the exposure.  Angles in degrees: --light-theta 0 lights the
drop from behind the camera, 180 from behind the drop; --light-phi is measured
in the image plane from right towards up; --view-theta is the camera's
elevation below the horizontal.

    raingauge render-streak --radius-mm 1.5 --light-theta 150 --light-phi 90 --view-theta 0 --out s.png
    raingauge render-streak --radius-mm 1 --light-theta 60 --light-phi 30 --view-theta 10 \\
        --length-px 300 --width-px 20 --exposure-ms 4 --out s.png

The PNG is scaled so the brightest pixel of the composite is white (or by
--gain); --npy also saves the linear radiance and coverage (relative to the
light's radiance 1).
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--radius-mm", type=float, required=True, help="drop radius, mm (0.1-4)")
    parser.add_argument("--light-theta", type=float, default=60.0, help="light polar angle, deg (0-180)")
    parser.add_argument("--light-phi", type=float, default=90.0, help="light azimuth, deg")
    parser.add_argument("--view-theta", type=float, default=0.0,
                        help="camera elevation below the horizontal, deg (-80..80)")
    parser.add_argument("--out", required=True, help="output PNG")
    parser.add_argument("--length-px", type=float, default=200.0, help="streak length, px (default 200)")
    parser.add_argument("--width-px", type=float, default=16.0, help="drop image diameter, px (default 16)")
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument("--exposure-ms", type=float, default=None,
                        help="exposure time, ms (the fall speed then follows from the length)")
    timing.add_argument("--fall-speed", type=float, default=None, metavar="M_S",
                        help="fall speed, m/s (default: terminal speed, Gunn-Kinzer)")
    parser.add_argument("--amp-axisymmetric", type=float, default=0.05,
                        help="amplitude of the oblate-prolate (2,0) mode, fraction of the radius (default 0.05)")
    parser.add_argument("--amp-transverse", type=float, default=0.03,
                        help="amplitude of the transverse (2,1) mode, fraction of the radius (default 0.03)")
    parser.add_argument("--phase-axisymmetric", type=float, default=0.0, help="phase of the (2,0) mode, deg")
    parser.add_argument("--phase-transverse", type=float, default=90.0, help="phase of the (2,1) mode, deg")
    parser.add_argument("--light-size", type=float, default=3.0, metavar="DEG",
                        help="angular radius of the light, deg (default 3)")
    parser.add_argument("--ambient", type=float, default=0.05,
                        help="sky radiance relative to the light (default 0.05)")
    parser.add_argument("--no-light", action="store_true", help="ambient (and --envmap) lighting only")
    parser.add_argument("--envmap", default=None,
                        help="equirectangular environment image (camera frame), added to the lighting")
    parser.add_argument("--background", type=float, default=0.0, metavar="RADIANCE",
                        help="background radiance behind the streak, relative to the light (default 0: "
                             "the streak alone, as in a streak database)")
    parser.add_argument("--gain", type=float, default=None,
                        help="PNG value = 255 * gain * radiance (default: brightest pixel -> 255)")
    parser.add_argument("--supersample", type=int, default=2, help="rays per pixel side (default 2)")
    parser.add_argument("--npy", default=None, metavar="FILE",
                        help="also save radiance and coverage as a (2, H, W) float32 .npy")


def run(args: argparse.Namespace) -> int:
    import math

    import cv2
    import numpy as np

    from raingauge.errors import ConfigError, InputError
    from raingauge.render.closeup import closeup_streak

    for name in ("radius_mm", "light_theta", "light_phi", "view_theta", "length_px", "width_px", "exposure_ms",
                 "fall_speed", "amp_axisymmetric", "amp_transverse", "phase_axisymmetric", "phase_transverse",
                 "light_size", "ambient", "background", "gain"):
        value = getattr(args, name)
        if value is not None and not math.isfinite(value):
            raise ConfigError(f"--{name.replace('_', '-')} must be a finite number, got {value}")
    if not 0.1 <= args.radius_mm <= 4.0:
        raise ConfigError(f"--radius-mm must be between 0.1 and 4 mm (raindrops), got {args.radius_mm}")
    if not 0.0 <= args.light_theta <= 180.0:
        raise ConfigError(f"--light-theta must be between 0 and 180 degrees, got {args.light_theta}")
    if not -80.0 <= args.view_theta <= 80.0:
        raise ConfigError(f"--view-theta must be between -80 and 80 degrees, got {args.view_theta}")
    if not 2.0 <= args.width_px <= 400.0:
        raise ConfigError(f"--width-px must be between 2 and 400 px, got {args.width_px}")
    if not args.width_px <= args.length_px <= 5000.0:
        raise ConfigError(f"--length-px must be between --width-px ({args.width_px}) and 5000 px, "
                          f"got {args.length_px}")
    if args.exposure_ms is not None and not args.exposure_ms > 0:
        raise ConfigError(f"--exposure-ms must be > 0, got {args.exposure_ms}")
    if args.fall_speed is not None and not 0 < args.fall_speed < 20:
        raise ConfigError(f"--fall-speed must be between 0 and 20 m/s, got {args.fall_speed}")
    if abs(args.amp_axisymmetric) + abs(args.amp_transverse) >= 0.5:
        raise ConfigError("--amp-axisymmetric + --amp-transverse must stay below 0.5 (fractions of the radius)")
    if not 0.1 <= args.light_size <= 45:
        raise ConfigError(f"--light-size must be between 0.1 and 45 degrees, got {args.light_size}")
    if not 1 <= args.supersample <= 8:
        raise ConfigError(f"--supersample must be between 1 and 8, got {args.supersample}")
    if args.ambient < 0:
        raise ConfigError(f"--ambient must be >= 0, got {args.ambient}")
    if args.background < 0:
        raise ConfigError(f"--background must be >= 0, got {args.background}")
    if args.gain is not None and not args.gain > 0:
        raise ConfigError(f"--gain must be > 0, got {args.gain}; leave it out to scale the brightest pixel to 255")
    out = Path(args.out)
    if not out.parent.exists():
        raise ConfigError(f"output folder {out.parent} does not exist; create it or choose another --out")
    if not cv2.haveImageWriter(str(out)):
        raise ConfigError(f"--out {out}: OpenCV writes no image of that extension; use .png or .tif")
    if args.npy and not Path(args.npy).parent.is_dir():
        raise ConfigError(f"--npy {args.npy}: the folder {Path(args.npy).parent} does not exist; "
                          "create it or choose another path")
    env = None
    if args.envmap:
        path = Path(args.envmap)
        img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) if path.is_file() else None
        if img is None:
            raise InputError(f"cannot read the environment map {path}; give an equirectangular image file")
        env = img.astype(np.float32) / 255.0

    streak = closeup_streak(
        args.radius_mm * 1e-3, length_px=args.length_px, width_px=args.width_px,
        light_dir=None if args.no_light else (math.radians(args.light_theta), math.radians(args.light_phi)),
        view_theta=math.radians(args.view_theta),
        exposure_s=None if args.exposure_ms is None else args.exposure_ms * 1e-3,
        fall_speed_m_s=args.fall_speed, amp_axisymmetric=args.amp_axisymmetric,
        amp_transverse=args.amp_transverse, phase_axisymmetric=math.radians(args.phase_axisymmetric),
        phase_transverse=math.radians(args.phase_transverse), environment=env,
        ambient=args.ambient, light_size_rad=math.radians(args.light_size), supersample=args.supersample)
    image = streak.composite(args.background)
    gain = args.gain if args.gain is not None else 1.0 / max(float(image.max()), 1e-12)
    png = np.clip(np.rint(255.0 * gain * image), 0, 255).astype(np.uint8)
    if not cv2.imwrite(str(out), png):
        raise InputError(f"cannot write {out}; use an image extension OpenCV knows (.png, .tif)")
    if args.npy:
        try:
            np.save(args.npy, np.stack([streak.radiance, streak.coverage]).astype(np.float32))
        except OSError as exc:
            raise InputError(f"cannot write {args.npy} ({exc.strerror}); choose a writable path") from None
    print(f"wrote {out} ({png.shape[1]}x{png.shape[0]} px): oscillation {streak.frequency_hz:.1f} Hz, "
          f"fall {streak.fall_speed_m_s:.2f} m/s, exposure {streak.exposure_s * 1e3:.2f} ms, "
          f"pattern period {streak.period_px:.1f} px, peak radiance {streak.radiance.max():.4g}")
    return 0
