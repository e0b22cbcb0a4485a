"""How much the detection's largest over the wind's slants lifts faint streaks and noise.

In a cross wind :func:`raingauge.gauge.streaks.detect_streaks` smooths the change along
each slant of :func:`raingauge.gauge.streaks.wind_slopes` and thresholds the largest.
This script draws the spike image of pure noise frames, min(I_n - I_{n-1}, I_n - I_{n+1}),
adds faint streaks of a given contrast, bands two pixels wide across the rows at the
slowest, a middle and the fastest drops' slants, and prints the share of noise pixels
and of the streaks' best pixels (nearest their centre lines: where a streak is found
first) at or above the detection threshold c, smoothed along the streak's own slant alone
and taking the largest over all the slants, beside what the model of the sample volume
gives for each (:func:`raingauge.gauge.slants.slant_margin`).

    python benchmarks/diag_slant_lift.py
    python benchmarks/diag_slant_lift.py --noise 1 --wind 5
"""

from __future__ import annotations

import argparse

import numpy as np


def streak_image(shape, slope: float, contrast: float, *, rows=(100, 140), every_px: int = 40):
    """Bands two pixels wide across the rows along dx/dy = ``slope`` [px/px], each pixel
    changed by ``contrast`` [gray levels] times the part of it the band covers, one every
    ``every_px`` columns; and each band's pixels nearest its centre line, (rows, columns)."""
    m, n = shape
    img = np.zeros((m, n), np.float32)
    y = np.arange(*rows)
    mid = 0.5 * (rows[0] + rows[1])
    cols = np.arange(n)
    reach = int(abs(slope) * (rows[1] - rows[0])) + 4
    ys, xs = [], []
    for x0 in range(reach, n - reach, every_px):
        centre = x0 + slope * (y - mid)
        lo = np.maximum(cols[None, :] - 0.5, centre[:, None] - 1.0)
        hi = np.minimum(cols[None, :] + 0.5, centre[:, None] + 1.0)
        img[y] += contrast * np.clip(hi - lo, 0.0, 1.0).astype(np.float32)
        ys.append(y)
        xs.append(np.rint(centre).astype(int))
    return img, (np.concatenate(ys), np.concatenate(xs))


def main(argv=None) -> int:
    import cv2

    from scipy.special import ndtr

    from raingauge.gauge.slants import slant_margin
    from raingauge.gauge.streaks import smoothed_spike, wind_slopes
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
        return smoothed_spike(img, smooth_px=5, slope=s)

    def largest(img):
        return smoothed_spike(img, smooth_px=5, slope=slopes[0], slopes=slopes[1:])

    print(f"# noise {args.noise:g} gray levels, wind {args.wind:g} m/s: {len(slopes)} slants "
          f"{', '.join(f'{s:.2f}' for s in slopes)}; threshold c = {c:g}")
    one = np.mean(smooth(noise_spike, slopes[len(slopes) // 2]) >= c)
    print(f"noise pixels at or above c: one slant {one:.2e}, the largest over the slants "
          f"{np.mean(largest(noise_spike) >= c):.2e}")
    print("streaks' best pixels at or above c: measured | model")
    print(f"{'contrast':>8} {'slant':>6} {'own':>7} {'largest':>8} {'ratio':>6} | {'own':>7} {'largest':>8} {'ratio':>6}")
    for dc in (float(v) for v in args.contrasts.split(",")):
        for s_true in (slopes[0], slopes[len(slopes) // 2], slopes[-1]):
            img, best = streak_image(shape, s_true, dc, rows=(100, 300))
            spike = noise_spike + img
            own = float(np.mean(smooth(spike, s_true)[best] >= c))
            big = float(np.mean(largest(spike)[best] >= c))
            w_across = 2.0 / np.sqrt(1.0 + s_true * s_true)
            kw = dict(threshold_dn=c, noise_sigma_dn=args.noise, streak_slope=s_true)
            m_own = float(ndtr(slant_margin(dc, w_across, slopes=[s_true], **kw)))
            m_big = float(ndtr(slant_margin(dc, w_across, slopes=slopes, **kw)))
            print(f"{dc:8.1f} {s_true:6.2f} {own:7.3f} {big:8.3f} {big / own if own > 0 else float('nan'):6.2f} | "
                  f"{m_own:7.3f} {m_big:8.3f} {m_big / m_own if m_own > 0 else float('nan'):6.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
