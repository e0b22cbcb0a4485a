"""How much of the drop brightness E_r is left to chance by the samples it rests on.

The gauge estimates E_r (:func:`raingauge.gauge.gauge.drop_brightness_dn`) from the
brightness samples of its latest law-abiding streaks, divided by a reference focus q_ref
that the completeness probe's drops give (their measured focus, their E_r being the one
they were drawn with).  This script runs one simulated clip through the gauge and, at its
end, resamples each of the two sets of samples with replacement (a bootstrap) to give the
standard deviation of E_r that each leaves, beside the estimate's error against the
simulator's E_r.  It also prints the reference the gauge used and the one that, with the
same streak samples, would have given the simulator's E_r: the part of the error that is
the reference's and not the samples'.

One gray level of E_r moves the rate 2-5 % over the brick wall
(``diag_brightness_sensitivity.py``), so a bootstrap spread of half a gray level is a
few per cent of a minute's reading, before the probe's own correction.  The spread is
that of one set of samples; E_r is updated as they turn over, and the frames of a minute
see a few such sets.

    python benchmarks/diag_brightness_sampling.py --background textured_still --rate 100 --noise 1 --wind 3 --seed 208
    python benchmarks/diag_brightness_sampling.py --background dark_uniform --rate 10 --noise 1 --wind 3 --dsd gamma3
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _clip_args import add_clip_arguments, dsd_keywords, frame_size  # noqa: E402
from bench_gauge_accuracy import BACKGROUNDS  # noqa: E402


def reference_for(samples, backgrounds, q_min: float, percentile: float, target_dn: float) -> float:
    """The constant reference q_ref with which :func:`drop_brightness_dn` of these samples
    is ``target_dn`` (bisection; E_r falls as q_ref rises) [-]."""
    from raingauge.gauge.gauge import drop_brightness_dn

    lo, hi = 0.2, 5.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if drop_brightness_dn(samples, backgrounds, q_min=q_min, q_ref=mid, percentile=percentile) > target_dn:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def bootstrap(g, *, draws: int, seed: int) -> dict:
    """E_r of the gauge's samples now, and its bootstrap spread over each set of samples."""
    from raingauge.gauge.gauge import BRIGHTNESS_PERCENTILE, drop_brightness_dn, focus_percentile

    q_min = g.volume.q_min
    backgrounds, samples = (a.copy() for a in g._brightness.arrays())
    q_ref, key = g._brightness_q_of_contrast()
    from_probe = key[0] == "probe"
    e_now = drop_brightness_dn(samples, backgrounds, q_min=q_min, q_ref=q_ref, percentile=BRIGHTNESS_PERCENTILE)
    rng = np.random.default_rng(seed)
    out = {"e_now": e_now, "n_streaks": samples.size, "from_probe": from_probe,
           "q_used": float(q_ref(e_now - float(np.median(backgrounds)))), "q_min": q_min}
    e_streaks = []
    for _ in range(draws):
        i = rng.integers(0, samples.size, samples.size)
        e_streaks.append(drop_brightness_dn(samples[i], backgrounds[i], q_min=q_min, q_ref=q_ref,
                                            percentile=BRIGHTNESS_PERCENTILE))
    out["sd_streaks"] = float(np.std(e_streaks))
    q, w = (a.copy() for a in g._probe_focus.arrays())
    out["n_probe"] = q.size
    if from_probe:
        q_emp = focus_percentile(q, w, q_min=q_min, percentile=BRIGHTNESS_PERCENTILE)
        e_probe = []
        for _ in range(draws):
            i = rng.integers(0, q.size, q.size)
            scale = focus_percentile(q[i], w[i], q_min=q_min, percentile=BRIGHTNESS_PERCENTILE) / q_emp
            e_probe.append(drop_brightness_dn(samples, backgrounds, q_min=q_min,
                                              q_ref=lambda c, s=scale: s * q_ref(c),
                                              percentile=BRIGHTNESS_PERCENTILE))
        out["sd_probe"] = float(np.std(e_probe))
    else:
        out["sd_probe"] = float("nan")
    out["samples"] = (samples, backgrounds)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_clip_arguments(ap, rate=30.0, dsd="marshall_palmer", seconds=60.0, seed=77)
    ap.add_argument("--wind", type=float, default=3.0, help="cross wind [m/s]")
    ap.add_argument("--draws", type=int, default=100, help="bootstrap draws")
    args = ap.parse_args(argv)
    if args.draws < 2:
        ap.error(f"--draws must be at least 2, got {args.draws}")
    w, h = frame_size(ap, args.size)
    from raingauge.gauge import RainGauge
    from raingauge.gauge.gauge import BRIGHTNESS_PERCENTILE
    from raingauge.profile import default_profile
    from raingauge.render.simulator import simulate

    spec, motion, e_r = BACKGROUNDS[args.background]
    prof = default_profile().replace(width_px=w, height_px=h, noise_sigma_dn=float(args.noise))
    sim = simulate(prof, seconds=args.seconds, seed=args.seed, background=spec, motion=motion,
                   wind_m_s=args.wind, drop_brightness_dn=e_r, truth_drops=False,
                   **dsd_keywords(ap, args.dsd, args.rate, args.seconds))
    g = RainGauge(prof, window_s=args.seconds, step_s=args.seconds)
    recs = []
    for k, (frame, _ft) in enumerate(sim):
        recs += g.process(frame, t_s=k / prof.frame_rate_hz)
    recs += g.flush()
    true = float(sim.truth["rain_rate_mm_h"])
    b = bootstrap(g, draws=args.draws, seed=args.seed)
    samples, backgrounds = b["samples"]
    q_need = reference_for(samples, backgrounds, b["q_min"], BRIGHTNESS_PERCENTILE, e_r)
    print(f"{args.background}, {args.rate:g} mm/h {args.dsd}, noise {args.noise:g}, wind {args.wind:g} m/s, "
          f"{args.seconds:g} s, seed {args.seed}")
    print(f"rate: true {true:.3f} mm/h, measured {recs[-1]['rain_rate_mm_h']:.3f} "
          f"({recs[-1]['rain_rate_mm_h'] / true:.3f})")
    print(f"E_r: simulator {e_r:g}, gauge at the end {b['e_now']:.2f} ({b['e_now'] - e_r:+.2f} gray levels; "
          f"contrast over the median background {b['e_now'] - float(np.median(backgrounds)):.1f})")
    src = "the probe's drops" if b["from_probe"] else "the model (the probe had too few focus samples)"
    print(f"reference q_ref: used {b['q_used']:.4f} (from {src}); the simulator's E_r needs {q_need:.4f}")
    print(f"bootstrap sd of E_r over {args.draws} draws: the streaks' {b['n_streaks']} samples "
          f"{b['sd_streaks']:.2f} gray levels; the probe's {b['n_probe']} focus samples "
          + ("-" if not np.isfinite(b["sd_probe"]) else f"{b['sd_probe']:.2f} gray levels"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
