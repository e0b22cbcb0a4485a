"""The detection's pass in a cross wind beside OpenCV's filters, on the same frames.

In a cross wind :func:`raingauge.gauge.streaks.detect_streaks` sums the spike image of
Eq. (19) along each slant the wind gives the drop sizes (:func:`wind_slopes`) and
thresholds the largest, in one compiled pass (:func:`raingauge.gauge._kernels.slant_masks`).
The baseline is the same smoothing by OpenCV (:func:`raingauge.gauge.streaks.smoothed_spike`:
one ``cv2.filter2D`` per slant, their largest, the conversion to float32) and
``cv2.compare``.  Both take each frame's spike in turn (one core, CPU time), at the
detection threshold and its hysteresis's, over the wind's slants and over the direction
search's 13; the masks' disagreement is printed beside (only where a sum equals a
threshold: tests/test_gauge_streaks.py).

    python benchmarks/bench_slant_detection.py
    python benchmarks/bench_slant_detection.py --frames 60 --backgrounds uniform:40 --wind 5
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=40, help="frames per clip")
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--rate", type=float, default=30.0, help="rain rate [mm/h]")
    ap.add_argument("--wind", type=float, default=3.0, help="cross wind [m/s]")
    ap.add_argument("--backgrounds", default="uniform:40,skimage:brick")
    ap.add_argument("--c", type=float, default=3.0, help="detection threshold [gray levels]")
    ap.add_argument("--grow", type=float, default=0.6, help="hysteresis, a share of c")
    args = ap.parse_args(argv)
    if args.frames < 3:
        ap.error(f"--frames must be at least 3, got {args.frames}")

    import cv2
    import numpy as np

    cv2.setNumThreads(1)
    from raingauge.gauge import _kernels
    from raingauge.gauge.gauge import DIRECTION_SEARCH_SLOPES
    from raingauge.gauge.streaks import smoothed_spike, spike_image, wind_slopes
    from raingauge.profile import default_profile
    from raingauge.render.simulator import render_clip

    if not _kernels.AVAILABLE:
        print("numba is not installed: the detection uses OpenCV's filters, nothing to compare")
        return 1
    w, h = (int(v) for v in args.size.lower().split("x"))
    profile = default_profile().replace(width_px=w, height_px=h)
    c, low = args.c, args.c * args.grow
    # compile (or load) the pass before timing it
    _kernels.slant_masks(np.zeros((16, 16), np.int16), 5, (0.3, 0.6), c, low)
    print(f"# detection in a {args.wind:g} m/s cross wind at {w}x{h}, {args.rate:g} mm/h, one core, CPU time "
          f"per frame; OpenCV: filter2D per slant + max + compare; compiled: one pass")
    print(f"{'background':>16} {'slants':>7} {'OpenCV ms':>10} {'compiled ms':>12} {'ratio':>6} "
          f"{'set px':>8} {'differ':>7}")
    clock = time.process_time
    for background in args.backgrounds.split(","):
        frames, _ = render_clip(profile, n_frames=args.frames, rain_rate_mm_h=args.rate, seed=3,
                                background=background, wind_m_s=args.wind)
        frames = [np.asarray(f, np.uint8) for f in frames]
        wind = wind_slopes(args.wind)
        for name, slopes in (("wind", wind), ("search", list(DIRECTION_SEARCH_SLOPES))):
            main_slope = wind[len(wind) // 2] if name == "wind" else 0.0
            extra = [v for v in slopes if abs(v - main_slope) >= 0.05]
            t_cv = t_pass = 0.0
            n_set = n_diff = 0
            for k in range(1, len(frames) - 1):
                spike = spike_image(frames[k - 1], frames[k], frames[k + 1])
                t0 = clock()
                s = smoothed_spike(spike, smooth_px=5, slope=main_slope, slopes=extra)
                m_cv = cv2.compare(s, c, cv2.CMP_GE)
                l_cv = cv2.compare(s, low, cv2.CMP_GE)
                t1 = clock()
                m, lo = _kernels.slant_masks(spike, 5, [main_slope, *extra], c, low)
                t2 = clock()
                t_cv += t1 - t0
                t_pass += t2 - t1
                n_set += int(np.count_nonzero(m_cv))
                n_diff += int(np.count_nonzero(m != m_cv)) + int(np.count_nonzero(lo != l_cv))
            n = len(frames) - 2
            label = f"{name} {len(extra) + 1}"
            print(f"{background:>16} {label:>7} {1e3 * t_cv / n:10.2f} {1e3 * t_pass / n:12.2f} "
                  f"{t_cv / t_pass:6.2f} {n_set // n:8d} {n_diff / n:7.1f}", flush=True)
        del frames
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
