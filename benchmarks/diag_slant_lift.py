"""How much the detection's largest over the wind's slants lifts faint streaks and noise.

In a cross wind :func:`raingauge.gauge.streaks.detect_streaks` smooths the change along
each slant of :func:`raingauge.gauge.streaks.wind_slopes` and thresholds the largest; the
model of the sample volume (:func:`raingauge.gauge.volume.pass_probability`) takes the
change smoothed along one direction, the streak's own.  This script draws the spike image
of pure noise frames, min(I_n - I_{n-1}, I_n - I_{n+1}), adds faint streaks of a given
contrast two pixels wide at the slowest and fastest drops' slants, and prints the share of
noise pixels and of streak pixels at or above the detection threshold c, smoothed along the
streak's own slant alone and taking the largest over all the slants.

    python benchmarks/diag_slant_lift.py
    python benchmarks/diag_slant_lift.py --noise 1 --wind 5
"""

from __future__ import annotations

import argparse

import numpy as np


def streak_image(shape, slope: float, contrast: float, *, rows=(100, 140), every_px: int = 40) -> np.ndarray:
    """Streaks two pixels wide along dx/dy = ``slope`` [px/px], ``contrast`` [gray levels]
    high, one every ``every_px`` columns across the frame."""
    m, n = shape
    img = np.zeros((m, n), np.float32)
    y = np.arange(*rows)
    mid = 0.5 * (rows[0] + rows[1])
    for x0 in range(50, n - 80, every_px):
        x = x0 + slope * (y - mid)
        xi = np.floor(x).astype(int)
        frac = (x - xi).astype(np.float32)
        np.add.at(img, (y, xi), contrast * (1 - frac))
        np.add.at(img, (y, xi + 1), contrast * frac)
    return img + np.roll(img, 1, axis=1)


def main(argv=None) -> int:
    import cv2

    from raingauge.gauge.streaks import fall_kernel, wind_slopes
    from raingauge.profile import default_profile

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, default=3.0, help="sensor noise [gray levels]")
    ap.add_argument("--wind", type=float, default=3.0, help="drift of the drops [m/s]")
    ap.add_argument("--contrasts", default="3,4,5,6", help="streak contrasts [gray levels]")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    if not (args.noise > 0 and args.wind != 0):
        ap.error("--noise must be > 0 and --wind not 0 (without wind the detection smooths along one direction)")
    cv2.setNumThreads(1)
    prof = default_profile()
    c = prof.detection_threshold_dn
    slopes = wind_slopes(args.wind)
    rng = np.random.default_rng(args.seed)
    shape = (prof.height_px, prof.width_px)
    f = [rng.normal(100.0, args.noise, shape).astype(np.float32) for _ in range(3)]
    noise_spike = f[1] - np.maximum(f[0], f[2])

    def smooth(img, s):
        return cv2.filter2D(img, -1, fall_kernel(5, s), borderType=cv2.BORDER_REFLECT)

    def largest(img):
        out = smooth(img, slopes[0])
        for s in slopes[1:]:
            cv2.max(out, smooth(img, s), dst=out)
        return out

    print(f"# noise {args.noise:g} gray levels, wind {args.wind:g} m/s: {len(slopes)} slants "
          f"{', '.join(f'{s:.2f}' for s in slopes)}; threshold c = {c:g}")
    one = np.mean(smooth(noise_spike, slopes[len(slopes) // 2]) >= c)
    print(f"noise pixels at or above c: one slant {one:.2e}, the largest over the slants "
          f"{np.mean(largest(noise_spike) >= c):.2e}")
    print(f"{'contrast':>8} {'slant':>6} {'own slant':>10} {'largest':>8} {'ratio':>6}")
    for dc in (float(v) for v in args.contrasts.split(",")):
        for s_true in (slopes[0], slopes[-1]):
            img = streak_image(shape, s_true, dc)
            spike = noise_spike + img
            on = img > 0.5 * dc
            own = float(np.mean(smooth(spike, s_true)[on] >= c))
            big = float(np.mean(largest(spike)[on] >= c))
            print(f"{dc:8.1f} {s_true:6.2f} {own:10.3f} {big:8.3f} {big / own if own > 0 else float('nan'):6.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
