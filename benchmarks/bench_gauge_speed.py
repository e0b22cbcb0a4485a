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
core, OpenCV and BLAS held to one thread), so other work on the machine slows
both columns alike; the ratio gauge/MOG2 is the figure to compare between runs.

    python benchmarks/bench_gauge_speed.py --frames 120 --rates 0,10,50
    python benchmarks/bench_gauge_speed.py --frames 40 --backgrounds uniform:40
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
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--rates", default="0,10,50", help="rain rates of the test clips [mm/h]")
    ap.add_argument("--backgrounds", default="skimage:brick,uniform:40",
                    help="simulator backgrounds of the test clips, comma-separated (one table each)")
    args = ap.parse_args(argv)

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
    print(f"# gauge speed at {w}x{h}, one core (cv2 threads {cv2.getNumThreads()}), {args.frames} frames per clip, "
          f"CPU time")
    for background in args.backgrounds.split(","):
        print(f"## background {background}")
        print(f"{'rate':>6} {'gauge fps':>10} {'no probe':>9} {'MOG2 fps':>9} {'ratio':>6} {'streaks/frame':>13} "
              f"{'counted':>8}")
        for rate in (float(r) for r in args.rates.split(",")):
            frames, _truth = render_clip(profile, n_frames=args.frames, rain_rate_mm_h=rate, seed=7,
                                         background=background)
            gauge = RainGauge(profile, window_s=60.0, step_s=10.0, velocity_model="gunn_kinzer", keep_drops=True)
            t0 = time.process_time()
            for fr in frames:
                gauge.process(fr)
            recs = gauge.flush()
            t_gauge = time.process_time() - t0
            # the same without the completeness probe (its share of the time)
            plain = RainGauge(profile, window_s=60.0, step_s=10.0, velocity_model="gunn_kinzer",
                              completeness_probe=False)
            t0 = time.process_time()
            for fr in frames:
                plain.process(fr)
            plain.flush()
            t_plain = time.process_time() - t0
            mog = cv2.createBackgroundSubtractorMOG2(history=500, varThreshold=16, detectShadows=False)
            t0 = time.process_time()
            for fr in frames:
                mog.apply(fr)
            t_mog = time.process_time() - t0
            fps_g = len(frames) / t_gauge
            fps_m = len(frames) / t_mog
            rejected = sum(r["drops_rejected_defocus"] for r in recs)
            print(f"{rate:6.1f} {fps_g:10.1f} {len(frames) / t_plain:9.1f} {fps_m:9.1f} {fps_g / fps_m:6.2f} "
                  f"{(rejected + len(gauge.drops)) / len(frames):13.1f} {len(gauge.drops):8d}", flush=True)
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
    print("target: gauge >= 60 frames/s at 1280x720 on one core")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
