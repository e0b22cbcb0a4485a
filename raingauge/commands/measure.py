"""Measure rain in a video: rain rate, accumulation and drop size distribution.

Runs the camera rain gauge (Sec. 8 of Garg & Nayar, "Vision and Rain") over
VIDEO (a video file or a folder of images) taken with the camera described by
PROFILE, and prints one record every --step seconds over the last --window
seconds on stdout, as JSON lines (default) or CSV.  A progress bar goes to
stderr.  A video shorter than one window gives one record over what there is,
flagged "partial_window".

Record fields: t_start_s, t_end_s, rain_rate_mm_h, rain_rate_ci95_mm_h
([lo, hi], 95 % interval from the counting statistics, widened for drop sizes
too faint to see against the background; hi is null when no size is visible,
flagged "no_visible_drops"), accumulation_mm,
drops_counted, drops_rejected_defocus, dsd_d_mm and dsd_n_m3_mm (N(D) in the
32 Parsivel classes, m^-3 mm^-1), nt_m3, dm_mm, z_dbz, intensity_class,
synop_4680, quality (flags), then nw_mm1_m3, lwc_g_m3, ke_flux_j_m2_h, z_mm6_m3,
min_detectable_diameter_mm (the smallest drop visible against the background) and
completed_share (the share of the rate, the spectrum and the accumulation that continues
the counted spectrum into the sizes the background leaves uncounted; 0 when none is), and
the rate's relative standard uncertainties behind its interval: rain_rate_counting_rsd (the
counting statistics of the drops counted), rain_rate_probe_rsd (the completeness probe's
sampling) and rain_rate_conditions_rsd (the scatter the validation found in the window's
conditions); null when no drop was counted.

Example:
    raingauge measure rain.mkv --camera gauge-default --window 60 --step 10
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("video", help="video file (any format OpenCV reads) or a folder of images")
    parser.add_argument("--camera", required=True, metavar="PROFILE",
                        help="camera profile: TOML file or shipped name (e.g. gauge-default)")
    parser.add_argument("--window", type=float, default=60.0, metavar="S",
                        help="averaging window [s] (default 60)")
    parser.add_argument("--step", type=float, default=10.0, metavar="S",
                        help="interval between records [s] (default 10)")
    parser.add_argument("--format", choices=("jsonl", "csv"), default="jsonl",
                        help="output format (default jsonl)")
    parser.add_argument("--velocity-model", default="gunn_kinzer", metavar="NAME",
                        help="fall-velocity law of the defocus test: gunn_kinzer (default, measured), "
                             "paper (v = 200 sqrt(a), too fast for drops < 1 mm), atlas1973, beard1976")
    parser.add_argument("--fps", type=float, default=None,
                        help="frame rate [1/s] (default: the profile's)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    parser.add_argument("--no-probe", action="store_true",
                        help="no completeness probe (artificial drops that measure how the scene hides "
                             "rain; faster, but textured and moving scenes then read low)")


def _csv_row(record: dict, keys: list[str]) -> list[str]:
    out = []
    for k in keys:
        v = record.get(k)
        if isinstance(v, list):
            out.append(" ".join("" if x is None else f"{x:.6g}" if isinstance(x, float) else str(x) for x in v))
        elif v is None:
            out.append("")
        elif isinstance(v, float):
            out.append(f"{v:.6g}")
        else:
            out.append(str(v))
    return out


class _Progress:
    def __init__(self, total: int | None, enabled: bool):
        self.total = total
        self.enabled = enabled and sys.stderr is not None
        self.n = 0

    def update(self, n: int = 1) -> None:
        self.n += n
        if not self.enabled or (self.n % 15 and self.n != self.total):
            return
        if self.total:
            frac = min(self.n / self.total, 1.0)
            bar = "#" * int(30 * frac)
            sys.stderr.write(f"\rmeasuring [{bar:<30}] {self.n}/{self.total} frames")
        else:
            sys.stderr.write(f"\rmeasuring {self.n} frames")
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.n:
            sys.stderr.write("\n")
            sys.stderr.flush()


def run(args: argparse.Namespace) -> int:
    import csv
    import json

    from raingauge.errors import ConfigError, InputError
    from raingauge.gauge import RainGauge
    from raingauge.gauge.gauge import RECORD_KEYS
    from raingauge.profile import load_profile
    from raingauge.videoio import FrameReader

    import math

    if not (args.window > 0 and args.step > 0 and math.isfinite(args.window) and math.isfinite(args.step)):
        raise ConfigError(f"--window and --step must be > 0 s, got {args.window} and {args.step}. "
                          "Fix: e.g. --window 60 --step 10")
    if args.step > args.window:
        raise ConfigError(f"--step ({args.step} s) must not exceed --window ({args.window} s). "
                          "Fix: e.g. --window 60 --step 10")
    if args.fps is not None and not (args.fps > 0 and math.isfinite(args.fps)):
        raise ConfigError(f"--fps {args.fps}: the frame rate must be a positive number [1/s]. "
                          "Fix: e.g. --fps 30, or leave it out to use the profile's")
    profile = load_profile(args.camera)
    if args.fps is not None:
        profile = profile.replace(frame_rate_hz=float(args.fps))
    reader = FrameReader(args.video, mode="gray")
    try:
        gauge = RainGauge(profile, window_s=args.window, step_s=args.step, velocity_model=args.velocity_model,
                          completeness_probe=not args.no_probe)
    except ValueError as exc:
        raise ConfigError(f"{exc}. Fix: choose a valid --velocity-model") from None
    keys = list(RECORD_KEYS) + ["nw_mm1_m3", "lwc_g_m3", "ke_flux_j_m2_h", "z_mm6_m3", "min_detectable_diameter_mm",
                                "completed_share", "rain_rate_counting_rsd", "rain_rate_probe_rsd",
                                "rain_rate_conditions_rsd"]
    writer = csv.writer(sys.stdout, lineterminator="\n") if args.format == "csv" else None
    if writer is not None:
        writer.writerow(keys)

    def emit(records):
        for rec in records:
            if writer is None:
                sys.stdout.write(json.dumps({k: rec[k] for k in keys}) + "\n")
            else:
                writer.writerow(_csv_row(rec, keys))
        if records:
            sys.stdout.flush()

    progress = _Progress(reader.n_frames, not args.no_progress)
    n = 0
    try:
        for frame in reader:
            if frame.shape[:2] != profile.shape:
                raise InputError(
                    f"{args.video}: frames are {frame.shape[1]}x{frame.shape[0]} but the camera profile "
                    f"{profile.name!r} is {profile.width_px}x{profile.height_px}. Fix: use the profile of "
                    f"the camera that recorded the video")
            emit(gauge.process(frame))
            n += 1
            progress.update()
    finally:
        progress.close()
    if n < 3:
        raise InputError(f"{args.video}: {n} frame(s); the gauge needs at least 3 consecutive frames. "
                         "Fix: give a longer video")
    emit(gauge.flush())
    return 0
