"""Frame rate of the instrument loop (`raingauge run`) on the simulated camera.

Three measurements in one process, on the same profile (gauge-default,
1280x720 at 30 Hz unless --size) and simulated rain (10 mm/h):

1. baseline, serial: render a frame, then run the gauge on it, on one thread
   (how the loop worked when the camera was rendered on the loop's machine
   thread): frames/s and the cost of each stage [ms/frame];
2. the instrument as ``raingauge run --fast`` builds it: the simulated camera
   rendering ahead in its own process, the gauge on the loop; frames/s and the
   ratio to the baseline;
3. the instrument paced at the camera's 30 frames/s (``raingauge run`` without
   --fast) for --seconds of camera time: wall time, frames measured and frames
   dropped (explicitly, flagged) - the default's behaviour when the gauge is
   slower than the camera.

Target: (2) at least the gauge's own rate (rendering off the critical path);
(3) wall time about the camera time plus start-up.

With ``--gaps``: why the grabber drops its whole backlog at once.  The gauge
measures one 11-s clip (320x240, 30 mm/h) fed with every frame, with evenly
thinned frames (every 2nd, 3rd) and with runs of consecutive frames between
gaps (what dropping the backlog gives); printed: rate, drops counted and the
ratio to the all-frames rate (counting noise about +-10 %).

    python benchmarks/bench_run_rate.py [--frames 150] [--seconds 20] [--size 1280x720] [--gaps]
"""

from __future__ import annotations

import argparse
import time


def _instrument(profile, *, realtime: bool, frames: int | None):
    from raingauge.instrument.loop import Instrument
    from raingauge.instrument.sources import Grabber, SimulatedSource

    src = SimulatedSource(10.0, profile, realtime=realtime, limit_frames=frames)
    return Instrument(profile, Grabber(src, shape=profile.shape), window_s=60.0, step_s=10.0)


def gaps() -> None:
    import numpy as np

    from raingauge.gauge import RainGauge
    from raingauge.instrument.sources import scaled_profile
    from raingauge.profile import load_profile
    from raingauge.render.simulator import render_clip

    profile = scaled_profile(load_profile("gauge-default"), 320, 240)
    frames, truth = render_clip(profile, seconds=11, rain_rate_mm_h=30.0, seed=2)
    n = len(frames)
    patterns = {
        "every frame": np.arange(n),
        "every 2nd": np.arange(0, n, 2),
        "every 3rd": np.arange(0, n, 3),
        "runs of 32, gaps of 16": np.array([i for i in range(n) if i % 48 < 32]),
        "runs of 8, gaps of 8": np.array([i for i in range(n) if i % 16 < 8]),
    }
    print(f"gauge on 11 s of simulated rain, 320x240, nominal {truth['rain_rate_mm_h']:.1f} mm/h; first 10-s record")
    base = None
    for name, idx in patterns.items():
        gauge = RainGauge(profile, window_s=10.0, step_s=10.0)
        recs = []
        for i in idx:
            recs += gauge.process(frames[i], t_s=i / profile.frame_rate_hz)
        recs += gauge.flush()
        r = recs[0]
        base = base or r["rain_rate_mm_h"]
        print(f"  {name:24s} {int(np.sum(idx < 300)):4d} frames  rate {r['rain_rate_mm_h']:6.2f} mm/h  "
              f"drops {r['drops_counted']:4d}  ratio {r['rain_rate_mm_h'] / base:.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=150, help="frames for the serial and --fast measurements")
    ap.add_argument("--seconds", type=float, default=20.0, help="camera time of the paced run [s]")
    ap.add_argument("--size", default=None, help="WxH of the simulated frames (default: the profile's)")
    ap.add_argument("--gaps", action="store_true", help="only the dropped-frame pattern comparison")
    args = ap.parse_args(argv)
    if args.gaps:
        gaps()
        return 0

    from raingauge.gauge import RainGauge
    from raingauge.instrument.sources import scaled_profile
    from raingauge.profile import load_profile
    from raingauge.render.simulator import simulate

    profile = load_profile("gauge-default")
    if args.size:
        w, h = (int(v) for v in args.size.lower().split("x"))
        profile = scaled_profile(profile, w, h)
    n = args.frames
    print(f"camera {profile.width_px}x{profile.height_px} at {profile.frame_rate_hz:g} Hz, simulated rain 10 mm/h")

    # 1. serial baseline
    gauge = RainGauge(profile, window_s=60.0, step_s=10.0)
    t_render = t_gauge = 0.0
    it = iter(simulate(profile, n_frames=n, rain_rate_mm_h=10.0, seed=0, truth_drops=False))
    t0 = time.perf_counter()
    for k in range(n):
        a = time.perf_counter()
        frame, _ = next(it)
        b = time.perf_counter()
        gauge.process(frame, t_s=k / profile.frame_rate_hz)
        c = time.perf_counter()
        t_render += b - a
        t_gauge += c - b
    serial_fps = n / (time.perf_counter() - t0)
    print(f"1. serial render + gauge : {serial_fps:6.1f} frames/s  (render {1e3 * t_render / n:.1f} ms, "
          f"gauge {1e3 * t_gauge / n:.1f} ms per frame)")

    # 2. instrument, unpaced (--fast)
    inst = _instrument(profile, realtime=False, frames=n)
    s = inst.run()
    print(f"2. instrument --fast     : {s['frames_per_s']:6.1f} frames/s  (gauge {s['gauge_ms_per_frame']} ms per "
          f"frame, {s['frames']} frames, wall {s['wall_s']} s with start-up)  ratio to 1: "
          f"{s['frames_per_s'] / serial_fps:.2f}")

    # 3. instrument, paced at the camera's rate
    inst = _instrument(profile, realtime=True, frames=int(round(args.seconds * profile.frame_rate_hz)))
    s = inst.run()
    slip = inst.grabber.clock_slip_s
    print(f"3. instrument, paced     : {args.seconds:g} s of camera time in {s['wall_s']} s of wall time "
          f"(camera clock slip {slip:.1f} s); measured {s['frames']} frames ({s['frames_per_s']} frames/s), "
          f"dropped {s['dropped_frames']} (flagged dropped_frames)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
