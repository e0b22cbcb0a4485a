"""Speed of the gauge pipeline at 1280x720 on one core, beside OpenCV's MOG2 on the same frames.

The pipeline per frame: linearise, Eq. (19) spike image, streak labelling,
screening, sub-pixel measurement, defocus rejection, de-duplication and the
sliding window (:class:`raingauge.gauge.RainGauge`), with the completeness probe
(artificial drops in the frames, :mod:`raingauge.gauge.completeness`) and, beside
it, without.  The target is >= 60
frames/s (twice real time for a 30 frames/s camera).  MOG2.apply (a learned
per-pixel Gaussian mixture background model [Zivkovic2004]) runs on the same
frames as the baseline.  Also prints the peak memory (Python allocations and
the process's maximum resident set).

One table per background: the textured ``skimage:brick`` and the dark uniform
``uniform:40``, the worst case (on a dark background most defocused drops are
bright enough to be detected, and each is measured before the velocity law
rejects it).  Frames per second are counted in the process's CPU time (one
core, OpenCV and BLAS held to one thread).  The gauge, the gauge without the probe
and MOG2 take each frame in turn, so a change in the machine's speed during the
run slows all three alike; the ratio gauge/MOG2 is the figure to compare
between runs.

Two speeds are printed.  ``start`` is over the first ``--settle`` frames of a
fresh gauge: the probe then runs on every frame until it has made its first
injections, and the frames wait for a settled drop brightness.  ``steady`` is
over the frames after them, the speed the gauge keeps up while it runs (a live
camera's queue takes up the start).  The target applies to the steady speed.

    python benchmarks/bench_gauge_speed.py --frames 360 --settle 120 --rates 0,10,50
    python benchmarks/bench_gauge_speed.py --frames 40 --settle 20 --backgrounds uniform:40
    python benchmarks/bench_gauge_speed.py --rates 100 --backgrounds uniform:40 --wind 3
"""

from __future__ import annotations

import argparse
import os
import resource
import time
import tracemalloc

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=360, help="frames per clip")
    ap.add_argument("--settle", type=int, default=120,
                    help="frames of the start (the steady speed is over the frames after them)")
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--rates", default="0,10,50", help="rain rates of the test clips [mm/h]")
    ap.add_argument("--backgrounds", default="skimage:brick,uniform:40",
                    help="simulator backgrounds of the test clips, comma-separated (one table each)")
    ap.add_argument("--wind", type=float, default=0.0,
                    help="cross wind of the test clips [m/s] (in wind the gauge also searches the rain's "
                         "direction and tests each streak's drift)")
    args = ap.parse_args(argv)
    if not 0 < args.settle < args.frames:
        ap.error(f"--settle must be between 1 and --frames - 1 ({args.frames - 1}), got {args.settle}")

    import cv2
    import numpy as np

    cv2.setNumThreads(1)
    from raingauge.gauge import RainGauge
    from raingauge.profile import default_profile
    from raingauge.render.simulator import render_clip

    w, h = (int(v) for v in args.size.lower().split("x"))
    profile = default_profile().replace(width_px=w, height_px=h)
    # the compiled measurement loops are compiled (or loaded from numba's cache) once per
    # process: on a short clip before the timings
    t0 = time.process_time()
    warm, _ = render_clip(profile, n_frames=40, rain_rate_mm_h=30.0, seed=1, background="uniform:40")
    t_render = time.process_time() - t0
    t0 = time.process_time()
    g = RainGauge(profile, window_s=60.0, step_s=10.0, velocity_model="gunn_kinzer")
    for fr in warm:
        g.process(fr)
    g.flush()
    print(f"# warm-up, a gauge on 40 frames (its sample volume built, the measurement loops compiled or "
          f"loaded): {time.process_time() - t0:.1f} s CPU (rendering them {t_render:.1f} s)")
    del warm, g
    print(f"# gauge speed at {w}x{h}, one core (cv2 threads {cv2.getNumThreads()}), {args.frames} frames per clip "
          f"(start: the first {args.settle}; steady: the rest), cross wind {args.wind:g} m/s, CPU time; the gauge, the gauge without the probe "
          f"and MOG2 take each frame in turn")
    for background in args.backgrounds.split(","):
        print(f"## background {background}")
        print(f"{'rate':>6} {'start fps':>10} {'steady fps':>11} {'no probe':>9} {'MOG2 fps':>9} {'ratio':>6} "
              f"{'probe every':>11} {'streaks/frame':>13} {'counted':>8}")
        for rate in (float(r) for r in args.rates.split(",")):
            frames, _truth = render_clip(profile, n_frames=args.frames, rain_rate_mm_h=rate, seed=7,
                                         background=background, wind_m_s=args.wind)
            gauge = RainGauge(profile, window_s=60.0, step_s=10.0, velocity_model="gunn_kinzer", keep_drops=True)
            # the same without the completeness probe (its share of the time)
            plain = RainGauge(profile, window_s=60.0, step_s=10.0, velocity_model="gunn_kinzer",
                              completeness_probe=False)
            mog = cv2.createBackgroundSubtractorMOG2(history=500, varThreshold=16, detectShadows=False)
            times = np.zeros((len(frames), 3))
            clock = time.process_time
            for i, fr in enumerate(frames):
                t0 = clock()
                gauge.process(fr)
                t1 = clock()
                plain.process(fr)
                t2 = clock()
                mog.apply(fr)
                times[i] = (t1 - t0, t2 - t1, clock() - t2)
            t0 = clock()
            recs = gauge.flush()
            t_flush = clock() - t0
            plain.flush()
            s = args.settle
            start = times[:s].sum(axis=0)
            steady = times[s:].sum(axis=0)
            fps_start = s / (start[0] + t_flush)
            n_st = len(frames) - s
            fps_g, fps_p, fps_m = (n_st / t for t in steady)
            rejected = sum(r["drops_rejected_defocus"] for r in recs)
            # (the probe's interval once it runs: no drop brightness, no probe)
            every = str(gauge.probe.interval) if gauge.probe.mature else "-"
            print(f"{rate:6.1f} {fps_start:10.1f} {fps_g:11.1f} {fps_p:9.1f} {fps_m:9.1f} {fps_g / fps_m:6.2f} "
                  f"{every:>11} {(rejected + len(gauge.drops)) / len(frames):13.1f} "
                  f"{len(gauge.drops):8d}", flush=True)
            del frames

    # peak memory of the gauge alone on a fresh clip
    frames, _ = render_clip(profile, n_frames=min(args.frames, 60), rain_rate_mm_h=10.0, seed=8)
    tracemalloc.start()
    gauge = RainGauge(profile, window_s=60.0, step_s=10.0, velocity_model="gunn_kinzer")
    for fr in frames:
        gauge.process(fr)
    gauge.flush()
    _cur, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"peak memory: {peak / 2 ** 20:.1f} MiB allocated by the gauge (tracemalloc, frames excluded "
          f"{frames.nbytes / 2 ** 20:.0f} MiB), process max RSS {rss:.0f} MiB")
    print("target: steady gauge >= 60 frames/s at 1280x720 on one core")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
