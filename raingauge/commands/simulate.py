"""Render physically based rain video with its ground truth.

Drops of a size distribution (or replayed from a Parsivel disdrometer file)
fall through the view of a camera profile; the clip is written losslessly
(FFV1 in .mkv, or a folder of PNG images) and the truth beside it as
OUT.truth.json: the camera, the rain rate and DSD computed by Eq. (28) from
the drops actually generated, per window; with --drops the per-frame drop
lists, with --masks a video of the rain masks (pixels changed by at least one
gray level), with --clean the rain-free video.

Examples:
  raingauge simulate rain.mkv --camera gauge-default --seconds 10 --rate 10
  raingauge simulate rain.mkv --seconds 20 --rate 25 --dsd gamma --mu 3 --wind 4 --wind-dir 0
  raingauge simulate frames/ --seconds 60 --parsivel locarno.dat.gz --start 2018-10-28T10:00:00
  raingauge simulate busy.mkv --seconds 5 --rate 10 --background astronaut --motion pan:40 --motion ripples
  raingauge simulate near.mkv --seconds 2 --rate 10 --closeup --light-theta 150 --light-phi 90
"""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", help="output video (.mkv, FFV1) or folder for PNG frames")
    parser.add_argument("--camera", default=None, help="camera profile TOML or shipped name (default gauge-default)")
    parser.add_argument("--seconds", type=float, required=True, help="clip length [s]")
    parser.add_argument("--size", default=None, metavar="WxH",
                        help="render at this frame size, the field of view kept (focal length and pixel "
                             "pitch scaled with the width), e.g. 320x240")
    rain = parser.add_argument_group("rain (--rate or --parsivel)")
    rain.add_argument("--rate", type=float, default=None, help="nominal rain rate [mm/h]")
    rain.add_argument("--dsd", default="marshall_palmer",
                      help="drop size distribution: marshall_palmer (default), gamma, normalized_gamma")
    rain.add_argument("--mu", type=float, default=None, help="gamma shape parameter (with --dsd gamma)")
    rain.add_argument("--parsivel", default=None, help="Parsivel telegram file to replay")
    rain.add_argument("--start", default=None, help="first Parsivel record to replay (ISO time, UTC)")
    rain.add_argument("--velocity-model", default="gunn_kinzer",
                      help="fall-velocity law: gunn_kinzer (default), paper, atlas1973, beard1976")
    rain.add_argument("--wind", type=float, default=0.0, help="horizontal wind speed [m/s]")
    rain.add_argument("--wind-dir", type=float, default=0.0,
                      help="direction the wind blows to [deg]: 0 = image right, 90 = away from the camera")
    scene = parser.add_argument_group("scene and sensor")
    scene.add_argument("--background", default="uniform:60",
                       help="uniform:LEVEL, ramp:LO:HI, stripes:L1:L2:..., a scikit-image scene "
                            "(camera, astronaut, ...), an image, or a video (default uniform:60)")
    scene.add_argument("--motion", action="append", default=None,
                       help="scene motion, repeatable: pan:SPEED[:DIR], objects:N[:SPEED], ripples[:AMP], foliage[:AMP]")
    scene.add_argument("--drop-brightness", type=float, default=None,
                       help="linear brightness E_r of a drop [gray levels] (default 200)")
    scene.add_argument("--jpeg-quality", type=int, default=None, help="JPEG-compress every frame (1-100)")
    scene.add_argument("--no-noise", action="store_true", help="leave out the sensor noise")
    close = parser.add_argument_group("close-up drops (Sec. 9)")
    close.add_argument("--closeup", action=argparse.BooleanOptionalAction, default=False,
                       help="draw drops whose focused image is >= 6 px wide and sharp (blur circle <= half "
                            "that width) as ray-traced streaks of oscillating drops, with the same deposited "
                            "exposure as the uniform streak. Off by default: each such streak costs ~0.2 s "
                            "of CPU (gauge-default at 10 mm/h: ~5 frames/s instead of ~48)")
    close.add_argument("--light-theta", type=float, default=None, metavar="DEG",
                       help="with --closeup: light polar angle [deg], 0 = from behind the camera, 180 = "
                            "from behind the drop (a light 100x the sky); default: overcast sky only")
    close.add_argument("--light-phi", type=float, default=90.0, metavar="DEG",
                       help="with --light-theta: light azimuth [deg] from image right towards image up "
                            "(default 90, from above)")
    out = parser.add_argument_group("truth")
    out.add_argument("--seed", type=int, default=0, help="random seed (same seed, same video)")
    out.add_argument("--masks", action="store_true", help="also write OUT.masks.* (rain masks, 255 = rain)")
    out.add_argument("--clean", action="store_true", help="also write OUT.clean.* (the rain-free frames)")
    out.add_argument("--drops", action="store_true", help="put the per-frame drop lists into OUT.truth.json")
    out.add_argument("--window", type=float, default=10.0, help="truth window length [s] (default 10)")


def _companion(out, tag: str):
    from pathlib import Path

    from raingauge.videoio import is_image_folder_path

    p = Path(out)
    if is_image_folder_path(p):
        return p.with_name(p.name.rstrip("/") + f".{tag}")
    return p.with_name(f"{p.stem}.{tag}{p.suffix}")


def run(args: argparse.Namespace) -> int:
    import json
    import math
    import sys
    import time
    from pathlib import Path

    from raingauge.errors import ConfigError
    from raingauge.render.simulator import DEFAULT_DROP_BRIGHTNESS_DN, simulate
    from raingauge.videoio import FrameWriter

    if args.parsivel is None and args.rate is None:
        raise ConfigError("give --rate MM_PER_H or --parsivel FILE")
    dsd_params = {}
    if args.mu is not None:
        if args.dsd not in ("gamma", "normalized_gamma"):
            raise ConfigError("--mu applies to --dsd gamma or normalized_gamma")
        dsd_params["mu"] = args.mu
    light = None
    if args.light_theta is not None:
        if not args.closeup:
            raise ConfigError("--light-theta lights the close-up drops: add --closeup")
        light = (math.radians(args.light_theta), math.radians(args.light_phi))
    camera = args.camera
    if args.size is not None:
        from raingauge.render.simulator import small_profile

        try:
            w, h = (int(v) for v in args.size.lower().split("x"))
        except ValueError:
            raise ConfigError(f"--size {args.size!r}: expected WIDTHxHEIGHT, e.g. 320x240") from None
        if w < 1 or h < 1:
            raise ConfigError(f"--size {args.size!r}: width and height must be at least 1 pixel. Fix: e.g. --size 320x240")
        camera = small_profile(w, h, base=camera or "gauge-default")
    sim = simulate(
        camera, seconds=args.seconds, rain_rate_mm_h=args.rate,
        dsd=None if args.parsivel else args.dsd, dsd_params=dsd_params or None,
        parsivel=args.parsivel, start=args.start, velocity_model=args.velocity_model,
        wind_m_s=args.wind, wind_dir_deg=args.wind_dir, background=args.background, motion=args.motion,
        seed=args.seed, truth_masks=args.masks, truth_clean=args.clean, truth_drops=args.drops,
        drop_brightness_dn=DEFAULT_DROP_BRIGHTNESS_DN if args.drop_brightness is None else args.drop_brightness,
        truth_window_s=args.window, jpeg_quality=args.jpeg_quality, noise=not args.no_noise,
        closeup=args.closeup, closeup_light=light)
    out = Path(args.out)
    fps = sim.profile.frame_rate_hz
    writers = {"frames": FrameWriter(out, fps=fps)}
    if args.masks:
        writers["masks"] = FrameWriter(_companion(out, "masks"), fps=fps)
    if args.clean:
        writers["clean"] = FrameWriter(_companion(out, "clean"), fps=fps)
    per_frame = []
    t0 = time.perf_counter()
    try:
        for frame, ft in sim:
            writers["frames"].write(frame)
            if args.masks:
                writers["masks"].write(ft["rain_mask"].astype("uint8") * 255)
            if args.clean:
                writers["clean"].write(ft["clean"])
            if args.drops:
                entry = {"index": ft["index"], "t_s": ft["t_s"], "drops": ft["drops"].to_json()}
                if args.closeup:
                    entry["closeup"] = {k: [int(x) if k in ("id", "phase_index") else float(x) for x in v]
                                        for k, v in ft["closeup"].items()}
                per_frame.append(entry)
    finally:
        for w in writers.values():
            w.close()
    elapsed = time.perf_counter() - t0
    truth = dict(sim.truth)
    truth["video"] = str(out)
    if args.masks:
        truth["rain_masks_video"] = str(_companion(out, "masks"))
    if args.clean:
        truth["clean_video"] = str(_companion(out, "clean"))
    if args.drops:
        truth["frames_truth"] = per_frame
    truth_path = Path(str(out).rstrip("/") + ".truth.json")
    truth_path.write_text(json.dumps(truth, indent=1))
    ratio = truth["ratio_to_nominal"]
    print(f"wrote {sim.n_frames} frames to {out} ({sim.n_frames / max(elapsed, 1e-9):.1f} frames/s) "
          f"and {truth_path}", file=sys.stderr)
    print(f"truth rain rate {truth['rain_rate_mm_h']:.3f} mm/h"
          + (f" (nominal {truth['nominal_rain_rate_mm_h']:.3f} mm/h, ratio {ratio:.3f})" if ratio else ""))
    return 0
