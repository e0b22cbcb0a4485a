"""How much the rate moves with the drop brightness E_r, and through which part of the gauge.

The gauge estimates E_r from its streaks (:func:`raingauge.gauge.gauge.drop_brightness_dn`)
and uses it twice: to measure the photometric focus q' of its streaks (the defocus test and
the sizes) and to draw the completeness probe's artificial drops
(:class:`raingauge.gauge.completeness.CompletenessProbe`), which then sets the sample
volume.  This script runs one simulated clip through the gauge given E_r, at the
simulator's value and ``--offsets`` gray levels beside it, and, for each offset, once more
with the probe run wholly at the simulator's E_r (its drops drawn, measured and sized at
the true brightness) while the gauge measures its own streaks at the offset one.  It
prints measured/true for each, and the elasticity d ln(rate) / d ln(E_r) between the
lowest and highest offset: the share the probe's drops carry is the difference between the
two rows of an offset.  Last, per band of measured diameter, the rain the counted drops
carry (at the weights they were counted with) and that band's own elasticity: the sizes
whose sample volume the detection threshold sets move most.

    python benchmarks/diag_brightness_sensitivity.py --background textured_still --rate 30 --noise 1 --wind 3
    python benchmarks/diag_brightness_sensitivity.py --background textured_still --rate 30 --noise 1 --wind 0
    python benchmarks/diag_brightness_sensitivity.py --background dark_uniform --rate 10 --offsets -4,0,4
"""

from __future__ import annotations

import argparse
import bisect
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _clip_args import add_clip_arguments, dsd_keywords, frame_size  # noqa: E402
from bench_gauge_accuracy import BACKGROUNDS  # noqa: E402

#: Bands of measured diameter [mm].
BANDS_MM = (0.25, 1.0, 1.5, 2.0, 3.0, 8.0)


def _gauge_class():
    from raingauge.gauge import RainGauge

    class ProbeAtBrightness(RainGauge):
        """A gauge whose completeness probe runs at its own fixed drop brightness."""

        def __init__(self, *args, probe_brightness_dn: float, **kwargs):
            super().__init__(*args, **kwargs)
            self._probe_brightness_dn = float(probe_brightness_dn)

        def _run_probe(self, *args, **kwargs):
            own = self.fixed_drop_brightness_dn
            self.fixed_drop_brightness_dn = self._probe_brightness_dn
            try:
                return super()._run_probe(*args, **kwargs)
            finally:
                self.fixed_drop_brightness_dn = own

    return RainGauge, ProbeAtBrightness


def run_case(job) -> dict:
    """One clip through a gauge given E_r = ``e_gauge``, its probe at ``e_probe`` (None: the same)."""
    (background, noise, wind, seconds, seed, size, dsd_kw, e_gauge, e_probe) = job
    from raingauge.profile import default_profile
    from raingauge.render.simulator import simulate

    RainGauge, ProbeAtBrightness = _gauge_class()
    w, h = size
    prof = default_profile().replace(width_px=w, height_px=h, noise_sigma_dn=float(noise))
    spec, motion, e_r = BACKGROUNDS[background]
    sim = simulate(prof, seconds=seconds, seed=seed, background=spec, motion=motion, wind_m_s=wind,
                   drop_brightness_dn=e_r, truth_drops=False, **dsd_kw)
    if e_probe is None:
        g = RainGauge(prof, window_s=seconds, step_s=seconds, drop_brightness_dn=e_gauge, keep_drops=True)
    else:
        g = ProbeAtBrightness(prof, window_s=seconds, step_s=seconds, drop_brightness_dn=e_gauge,
                              keep_drops=True, probe_brightness_dn=e_probe)
    recs = []
    for k, (frame, _ft) in enumerate(sim):
        recs += g.process(frame, t_s=k / prof.frame_rate_hz)
    recs += g.flush()
    true = float(sim.truth["rain_rate_mm_h"])
    rec = recs[-1]
    bands = [0.0] * (len(BANDS_MM) - 1)
    for d in g.drops:
        k = bisect.bisect_right(BANDS_MM, 1e3 * d["diameter_m"]) - 1
        if 0 <= k < len(bands):
            bands[k] += 3.6e6 * math.pi / 6.0 * d["diameter_m"] ** 3 * d["velocity_m_s"] * d["weight_s_m3"] / seconds
    return {"e_gauge": e_gauge, "e_probe": e_probe, "true": true, "meas": float(rec["rain_rate_mm_h"]),
            "n": int(rec["drops_counted"]), "bands": bands}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_clip_arguments(ap, rate=30.0, dsd="marshall_palmer", seconds=30.0, seed=77)
    ap.add_argument("--wind", type=float, default=3.0, help="cross wind [m/s]")
    ap.add_argument("--offsets", default="-2,0,2", help="E_r given, gray levels beside the simulator's")
    ap.add_argument("--jobs", type=int, default=2, help="clips run at once")
    args = ap.parse_args(argv)
    size = frame_size(ap, args.size)
    try:
        offsets = sorted({float(s) for s in args.offsets.split(",") if s.strip()})
    except ValueError:
        ap.error(f"--offsets must be numbers separated by commas, e.g. -2,0,2, got {args.offsets!r}")
    if len(offsets) < 2:
        ap.error("--offsets needs at least two values (the elasticity is taken between the outer ones)")
    e_r = BACKGROUNDS[args.background][2]
    if any(not e_r + o > 0 for o in offsets):
        ap.error(f"every E_r given must be positive: the simulator's is {e_r:g}")
    dsd_kw = dsd_keywords(ap, args.dsd, args.rate, args.seconds)
    base = (args.background, args.noise, args.wind, args.seconds, args.seed, size, dsd_kw)
    jobs = [base + (e_r + o, None) for o in offsets]
    jobs += [base + (e_r + o, e_r) for o in offsets if o != 0]
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        rows = list(pool.map(run_case, jobs))
    print(f"{args.background}, {args.rate:g} mm/h {args.dsd}, noise {args.noise:g}, wind {args.wind:g} m/s, "
          f"{args.seconds:g} s, seed {args.seed}; simulator's E_r {e_r:g}")
    print(f"{'E_r gauge':>10} {'E_r probe':>10} | {'true':>8} {'meas':>8} {'ratio':>6} {'drops':>6}")
    for r in rows:
        probe = "same" if r["e_probe"] is None else f"{r['e_probe']:g}"
        print(f"{r['e_gauge']:10g} {probe:>10} | {r['true']:8.3f} {r['meas']:8.3f} "
              f"{r['meas'] / r['true']:6.3f} {r['n']:6d}")
    same = {r["e_gauge"]: r["meas"] for r in rows if r["e_probe"] is None}
    held = {r["e_gauge"]: r["meas"] for r in rows if r["e_probe"] is not None}
    lo, hi = e_r + offsets[0], e_r + offsets[-1]
    span = math.log(hi / lo)
    if same[lo] > 0 and same[hi] > 0:
        print(f"elasticity d ln(rate) / d ln(E_r): {math.log(same[hi] / same[lo]) / span:+.1f} "
              f"(E_r {lo:g} to {hi:g})")
        lo_h = held.get(lo, same.get(lo))
        hi_h = held.get(hi, same.get(hi))
        if lo_h and hi_h and lo_h > 0 and hi_h > 0:
            print(f"  with the probe at the simulator's E_r: {math.log(hi_h / lo_h) / span:+.1f}")
    else:
        print("no rain measured at an outer offset: no elasticity")
    by_e = {r["e_gauge"]: r["bands"] for r in rows if r["e_probe"] is None}
    print("counted rain per band of measured diameter [mm/h] (probe at the gauge's E_r)")
    print(f"{'D [mm]':>10} | " + " ".join(f"{'E_r ' + format(e, 'g'):>10}" for e in sorted(by_e)) + " | elasticity")
    for k, (b_lo, b_hi) in enumerate(zip(BANDS_MM[:-1], BANDS_MM[1:])):
        vals = [by_e[e][k] for e in sorted(by_e)]
        el = (f"{math.log(by_e[hi][k] / by_e[lo][k]) / span:+10.1f}" if by_e[lo][k] > 0 and by_e[hi][k] > 0
              else f"{'-':>10}")
        print(f"{b_lo:4.2f}-{b_hi:<5.2f} | " + " ".join(f"{v:10.3f}" for v in vals) + f" | {el}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
