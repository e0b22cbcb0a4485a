"""How well the gauge finds the drop brightness E_r, and why not: clips side by side.

Against a bright or textured background a streak changes a pixel by a few gray levels,
and the rate moves several times as much as the contrast E_r - E_b the gauge estimated
(``diag_gauge_truth.py --given-brightness`` shows how much of a clip's error is that).
The gauge takes E_r from its law-abiding streaks (:func:`raingauge.gauge.gauge.drop_brightness_dn`):
the E at which their focus d / (E - E_b), each against the background behind it (d = q' (E_r - E_b)
its contrast), has the percentile fixed point of a reference q_ref, the same fixed point of the
measured focus q' of a population of drops.  That reference is the
completeness probe's drops' own (drawn at a known E_r into the frames), carried from the
probe's sizes (uniform in log a) to Marshall-Palmer rain by the sample volume's factor
(:meth:`raingauge.gauge.volume.SampleVolume.brightness_q_population_factor`).

Per clip the script prints the rate's measured/true, E_r estimated against the simulator's,
and the pieces of the estimate: the streaks' fixed point of q' taken with the true E_r
(d / (E_r - E_b) per streak: the reference the estimate needed), the reference the gauge
used at the true contrast, the probe's own fixed point and the model's factor.  Where the
first two differ, E_r is off by their ratio in contrast.

    python benchmarks/diag_drop_brightness.py --background bright_sky --noise 3 --rate 2 --winds 0,3 --seeds 101,102,103

``--percentiles 50,75,90`` adds, per clip, the needed and the probe's fixed points at those
percentiles, and the quantiles of the streaks' q' (at the true E_r) and of the probe's.

Clips of 30 s at 1280x720 take about a minute each on one core.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _clip_args import add_clip_arguments, dsd_keywords, frame_size  # noqa: E402
from bench_gauge_accuracy import BACKGROUNDS  # noqa: E402


def run(background: str, noise: float, wind: float, seconds: float, seed: int, size, dsd_kw: dict) -> dict:
    """One clip through the gauge: its rate's measured/true and the parts of its E_r."""
    from raingauge.gauge import RainGauge
    from raingauge.gauge import gauge as G
    from raingauge.profile import default_profile
    from raingauge.render.simulator import simulate

    w, h = size
    prof = default_profile().replace(width_px=w, height_px=h, noise_sigma_dn=float(noise))
    spec, motion, e_r = BACKGROUNDS[background]
    sim = simulate(prof, seconds=seconds, seed=seed, background=spec, motion=motion, wind_m_s=wind,
                   drop_brightness_dn=e_r, **dsd_kw)
    g = RainGauge(prof, window_s=seconds, step_s=seconds)
    fps = prof.frame_rate_hz
    recs = []
    for k, (frame, _truth) in enumerate(sim):
        recs += g.process(frame, t_s=k / fps)
    recs += g.flush()
    rec = recs[-1]
    q_min = g.volume.q_min
    # (the gauge's own samples and reference: private, read for this diagnosis only)
    backgrounds, samples = g._brightness.arrays()
    contrast_true = e_r - float(np.median(backgrounds)) if backgrounds.size else np.nan
    q_true = (samples - backgrounds) / (e_r - backgrounds)
    needed = G.focus_percentile(q_true, q_min=q_min, percentile=G.BRIGHTNESS_PERCENTILE)
    q_ref, _key = g._brightness_q_of_contrast()
    pq, pw = g._probe_focus.arrays()
    probe_own = G.focus_percentile(pq, pw, q_min=q_min, percentile=G.BRIGHTNESS_PERCENTILE) if pq.size else np.nan
    used = float(q_ref(contrast_true))
    return {"ratio": rec["rain_rate_mm_h"] / float(sim.truth["rain_rate_mm_h"]),
            "e_r": g.drop_brightness_estimate_dn, "e_r_true": e_r, "n": int(samples.size),
            "needed": needed, "used": used, "probe": probe_own,
            "factor": used / probe_own if probe_own > 0 else np.nan,
            "q_true": q_true, "probe_q": pq, "probe_w": pw, "q_min": q_min}


def percentile_rows(r: dict, percentiles) -> list[str]:
    """Lines of the streaks' fixed point of q' at the true E_r (needed) beside the probe's
    own, at each percentile of ``percentiles`` [%]; then the 10/25/50/75/90 % quantiles of
    either's q' (the probe's weighted as the gauge weights them)."""
    from raingauge.gauge import gauge as G

    lines = []
    for p in percentiles:
        need = G.focus_percentile(r["q_true"], q_min=r["q_min"], percentile=p)
        own = (G.focus_percentile(r["probe_q"], r["probe_w"], q_min=r["q_min"], percentile=p)
               if r["probe_q"].size else np.nan)
        lines.append(f"      P{p:g}: needed {need:6.3f}  probe's {own:6.3f}  needed/probe's {need / own:6.3f}")
    qs = np.array([0.1, 0.25, 0.5, 0.75, 0.9])
    real = np.quantile(r["q_true"], qs) if r["q_true"].size else np.full(qs.size, np.nan)
    if r["probe_q"].size:
        order = np.argsort(r["probe_q"])
        cw = np.cumsum(r["probe_w"][order])
        own = np.interp(qs, (cw - 0.5 * r["probe_w"][order]) / cw[-1], r["probe_q"][order])
    else:
        own = np.full(qs.size, np.nan)
    lines.append("      q' at 10/25/50/75/90 %: streaks " + " ".join(f"{x:.3f}" for x in real)
                 + ", probe's " + " ".join(f"{x:.3f}" for x in own))
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_clip_arguments(ap, rate=2.0, dsd="marshall_palmer", seconds=30.0, seed=101)
    ap.add_argument("--winds", default="0,3", help="winds [m/s], comma-separated")
    ap.add_argument("--seeds", default=None, help="seeds, comma-separated (default --seed)")
    ap.add_argument("--percentiles", default=None,
                    help="also print the needed and the probe's fixed point of q' at these percentiles [%%], "
                         "comma-separated, and the quantiles of either's q'")
    args = ap.parse_args(argv)
    size = frame_size(ap, args.size)
    try:
        winds = [float(x) for x in args.winds.split(",")]
        seeds = [int(x) for x in (args.seeds or str(args.seed)).split(",")]
        percentiles = [float(x) for x in args.percentiles.split(",")] if args.percentiles else []
    except ValueError:
        ap.error(f"--winds, --seeds and --percentiles are comma-separated numbers, got {args.winds!r}, "
                 f"{args.seeds!r} and {args.percentiles!r}")
    if any(not 0.0 < p < 100.0 for p in percentiles):
        ap.error(f"--percentiles lie between 0 and 100, got {args.percentiles!r}")
    dsd_kw = dsd_keywords(ap, args.dsd, args.rate, args.seconds)
    print(f"# {args.rate} mm/h {args.dsd} over {args.background}, noise {args.noise}, {args.seconds:g} s at "
          f"{size[0]}x{size[1]}")
    print(" wind  seed | meas/true |   E_r  true | samples | q' needed  q_ref used | probe's  factor")
    for wind in winds:
        for seed in seeds:
            r = run(args.background, args.noise, wind, args.seconds, seed, size, dsd_kw)
            print(f" {wind:4.1f} {seed:5d} | {r['ratio']:9.3f} | {r['e_r']:5.1f} {r['e_r_true']:5.1f} | "
                  f"{r['n']:7d} | {r['needed']:9.3f} {r['used']:11.3f} | {r['probe']:7.3f} {r['factor']:7.3f}",
                  flush=True)
            if percentiles:
                print("\n".join(percentile_rows(r, percentiles)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
