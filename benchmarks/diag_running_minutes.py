"""A running gauge minute after minute: each minute's measured/true rate on one long clip.

The accuracy benchmark (``bench_gauge_accuracy.py``) reads each clip's first minute, from
a gauge that starts cold (no drop brightness E_r, no probe correction yet).  A field
gauge runs on: this renders one clip of several minutes, feeds it to one gauge with a
record every minute, and prints each minute's rate against the truth of the same
minute, its flags, and the gauge's E_r at the end of it beside the simulator's.

    python benchmarks/diag_running_minutes.py --background moving_objects --noise 3 --rate 2 --seed 15
    python benchmarks/diag_running_minutes.py --background dark_uniform --noise 1 --rate 10 --minutes 5
    python benchmarks/diag_running_minutes.py --background moving_objects --noise 3 --given-brightness
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _clip_args import add_clip_arguments, dsd_keywords, frame_size  # noqa: E402
from bench_gauge_accuracy import BACKGROUNDS  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_clip_arguments(ap, rate=2.0, dsd="marshall_palmer", seconds=60.0, seed=15)
    ap.add_argument("--minutes", type=int, default=3, help="minutes of rain (one record each)")
    ap.add_argument("--wind", type=float, default=0.0, help="wind [m/s]")
    ap.add_argument("--given-brightness", action="store_true",
                    help="give the gauge the simulator's drop brightness E_r instead of its estimate")
    args = ap.parse_args(argv)
    if args.minutes < 1:
        ap.error(f"--minutes must be at least 1, got {args.minutes}")
    w, h = frame_size(ap, args.size)
    seconds = 60.0 * args.minutes
    from raingauge.gauge import RainGauge
    from raingauge.profile import default_profile
    from raingauge.render.simulator import simulate

    prof = default_profile().replace(width_px=w, height_px=h, noise_sigma_dn=float(args.noise))
    spec, motion, e_r = BACKGROUNDS[args.background]
    sim = simulate(prof, seconds=seconds, seed=args.seed, background=spec, motion=motion, wind_m_s=args.wind,
                   drop_brightness_dn=e_r, truth_drops=False, truth_window_s=60.0,
                   **dsd_keywords(ap, args.dsd, args.rate, seconds))
    g = RainGauge(prof, window_s=60.0, step_s=60.0, drop_brightness_dn=e_r if args.given_brightness else None)
    fps = prof.frame_rate_hz
    print(f"{args.background}, {args.rate:g} mm/h {args.dsd}, noise {args.noise:g}, wind {args.wind:g} m/s, "
          f"seed {args.seed}, {args.minutes} min, E_r {'given' if args.given_brightness else 'estimated'}")
    print(f"{'minute':>6} {'true':>8} {'meas':>8} {'ratio':>6} {'E_r':>6} {'Dm_t':>5} {'Dm_m':>5} flags")
    recs, marks = [], []
    for k, (frame, _ft) in enumerate(sim):
        new = g.process(frame, t_s=k / fps)
        recs += new
        marks += [g.drop_brightness_estimate_dn] * len(new)
    tail = g.flush()
    recs += tail
    marks += [g.drop_brightness_estimate_dn] * len(tail)
    windows = sim.truth["windows"]
    for i, (rec, truth, e_est) in enumerate(zip(recs, windows, marks)):
        true = truth["rain_rate_mm_h"]
        dm_m = rec["dm_mm"] if rec["dm_mm"] is not None else float("nan")
        dm_t = truth["dm_mm"] if truth["dm_mm"] is not None else float("nan")
        print(f"{i + 1:6d} {true:8.3f} {rec['rain_rate_mm_h']:8.3f} "
              f"{rec['rain_rate_mm_h'] / true if true > 0 else float('nan'):6.3f} {e_est:6.1f} "
              f"{dm_t:5.2f} {dm_m:5.2f} {','.join(rec['quality'])}")
    print(f"simulator's E_r {e_r:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
