"""How much rain each model of the hidden small drops puts below the smallest counted size.

Where the scene hides the small drops (a bright sky, texture, noise), the gauge completes
the spectrum below the smallest counted diameter D_cut by continuing the counted tail
(:meth:`raingauge.gauge.RainGauge._completion`): an exponential whose slope is the maximum
likelihood estimate of the truncated tail (1 / Lambda = the mean of D - D_cut).  This
script takes the true spectra the accuracy benchmark renders (Marshall-Palmer and gamma
mu = 3 at 2 and 10 mm/h, and the minutes of the real Parsivel day nearest 0.5, 2, 10 and
30 mm/h when ``../shared/data`` is there), cuts each at D_cut, and prints the share of the
rain below the cut beside what two continuations of the tail above it put there:

* the gauge's exponential;
* a constrained gamma, N ~ D^mu exp(-Lambda D) with mu = -0.016 Lambda^2 + 1.213 Lambda
  - 1.957 (Lambda in 1/mm; [Zhang2001], from disdrometer spectra), Lambda chosen so
  that the truncated tail has the measured mean of D - D_cut.

Shares are of the completed rain (the tail's own rain plus what the model adds); the
diameters start at 0.3 mm (the camera sizes nothing smaller).

    python benchmarks/diag_completion_models.py
    python benchmarks/diag_completion_models.py --cuts 0.7,0.9,1.1
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_gauge_accuracy import parsivel_start_for_rate, shared_parsivel  # noqa: E402

#: Diameter grid [mm].
GRID_MM = np.linspace(0.3, 8.0, 4000)


def constrained_mu(lam_per_mm):
    """The shape mu of the constrained gamma at slope Lambda [1/mm] ([Zhang2001])."""
    lam = np.asarray(lam_per_mm, dtype=float)
    return -0.016 * lam ** 2 + 1.213 * lam - 1.957


def shares(n, cut_mm: float, velocity) -> tuple[float, float, float]:
    """(true share of the rain below ``cut_mm``, the exponential's, the constrained gamma's)
    for the number density ``n`` on :data:`GRID_MM` (any units) and fall speeds ``velocity``."""
    from scipy.optimize import brentq

    g = GRID_MM
    dg = g[1] - g[0]
    rain = n * g ** 3 * velocity
    lo = g < cut_mm
    hi = ~lo
    total_tail = float(rain[hi].sum())
    true = float(rain[lo].sum() / rain.sum())
    tail_n = n[hi]
    excess = float(np.sum(tail_n * (g[hi] - cut_mm)) / np.sum(tail_n))
    n_tail = float(np.sum(tail_n) * dg)

    def completed(shape):
        s = shape * n_tail / (np.sum(shape[hi]) * dg)
        added = float(np.sum(s[lo] * g[lo] ** 3 * velocity[lo]))
        return added / (total_tail + added)

    lam = 1.0 / excess
    expo = completed(np.exp(-lam * (g - cut_mm)))

    def mismatch(lam_g):
        mu = constrained_mu(lam_g)
        s = g[hi] ** mu * np.exp(-lam_g * (g[hi] - cut_mm))
        return float(np.sum(s * (g[hi] - cut_mm)) / np.sum(s)) - excess

    try:
        lam_g = brentq(mismatch, 0.3, 40.0)
    except ValueError:
        return true, expo, float("nan")
    mu = float(constrained_mu(lam_g))
    cg = completed(g ** mu * np.exp(-lam_g * (g - cut_mm)))
    return true, expo, cg


def spectra(rates_model, rates_parsivel):
    """(name, number density on GRID_MM) of each true spectrum."""
    from raingauge.physics import drops as D

    d_m = GRID_MM * 1e-3
    for r in rates_model:
        yield f"Marshall-Palmer {r:g} mm/h", np.asarray(D.MarshallPalmer(r).number_density(d_m), dtype=float)
        yield f"gamma mu=3 {r:g} mm/h", np.asarray(D.gamma_for_rain_rate(r, 3.0).number_density(d_m), dtype=float)
    path = shared_parsivel()
    if path is None:
        print("note: ../shared/data/parsivel not found: no Parsivel spectra", file=sys.stderr)
        return
    from raingauge.disdrometer import read_parsivel, record_density_m4

    pf = read_parsivel(path)
    edges = np.asarray(D.PARSIVEL_D_EDGES_MM)
    idx = np.clip(np.searchsorted(edges, GRID_MM, side="right") - 1, 0, 31)
    times = [x.time for x in pf.records]
    for r in rates_parsivel:
        i = times.index(parsivel_start_for_rate(pf, r, 1.0))
        recs = pf.records[i:i + 2]
        n = sum(np.nan_to_num(record_density_m4(x.counts)) for x in recs) / len(recs)
        yield f"Parsivel {recs[0].time:%Y-%m-%d %H:%M} ({np.mean([x.reported_rate_mm_h for x in recs]):.2f} mm/h)", n[idx]


def main(argv=None) -> int:
    from raingauge.physics import drops as D

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cuts", default="0.8,1.0", help="smallest counted diameters D_cut [mm], comma-separated")
    args = ap.parse_args(argv)
    try:
        cuts = [float(c) for c in args.cuts.split(",")]
    except ValueError:
        ap.error(f"--cuts must be diameters in mm, e.g. 0.8,1.0, got {args.cuts!r}")
    if any(not (GRID_MM[0] < c < GRID_MM[-1]) for c in cuts):
        ap.error(f"--cuts must lie between {GRID_MM[0]:g} and {GRID_MM[-1]:g} mm")
    velocity = np.nan_to_num(np.asarray(D.fall_velocity(GRID_MM * 1e-3), dtype=float))
    print(f"{'spectrum':40s} {'D_cut':>6}  {'true':>6}  {'expon.':>6}  {'C-G':>6}   share of the rain below D_cut")
    for name, n in spectra((2.0, 10.0), (0.5, 2.0, 10.0, 30.0)):
        for cut in cuts:
            true, expo, cg = shares(n, cut, velocity)
            print(f"{name:40s} {cut:6.2f}  {true:6.3f}  {expo:6.3f}  {cg:6.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
