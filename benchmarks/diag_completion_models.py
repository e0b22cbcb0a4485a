"""How much rain each model of the hidden small drops puts below the smallest counted size.

Where the scene hides the small drops (a bright sky, texture, noise), the gauge completes
the spectrum below the smallest counted diameter D_cut by continuing the counted tail
(:meth:`raingauge.gauge.RainGauge._completion`): an exponential whose slope is the maximum
likelihood estimate of the truncated tail (1 / Lambda = the mean of D - D_cut).  This
script takes the true spectra the accuracy benchmark renders (Marshall-Palmer and gamma
mu = 3 at 2 and 10 mm/h, and the minutes of the real Parsivel day nearest 0.5, 2, 10 and
30 mm/h when ``../shared/data`` is there), cuts each at D_cut, and prints the share of the
rain below the cut beside what three continuations of the tail above it put there:

* the gauge's exponential;
* a constrained gamma, N ~ D^mu exp(-Lambda D) with mu = -0.016 Lambda^2 + 1.213 Lambda
  - 1.957 (Lambda in 1/mm; [Zhang2001], from disdrometer spectra), Lambda chosen so
  that the truncated tail has the measured mean of D - D_cut;
* a gamma, N ~ D^mu exp(-Lambda D) with both fitted to the tail by maximum likelihood
  (:func:`truncated_gamma_fit`, here without its prior: the tail is the whole spectrum,
  not a window's drops).  On the gauge's own counted drops the shape is far less sure
  than here (README, Known limits), and the gauge continues the exponential.

Shares are of the completed rain (the tail's own rain plus what the model adds); the
diameters start at 0.3 mm (the camera sizes nothing smaller).

    python benchmarks/diag_completion_models.py
    python benchmarks/diag_completion_models.py --cuts 0.7,0.9,1.1
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_gauge_accuracy import parsivel_start_for_rate, shared_parsivel  # noqa: E402

#: Diameter grid [mm].
GRID_MM = np.linspace(0.3, 8.0, 4000)


#: Prior of :func:`truncated_gamma_fit`'s shape mu: normal about the exponential (mu = 0)
#: with this standard deviation [-]; the range of mu searched [-]; the largest diameter of
#: the fitted spectrum [m].
MU_PRIOR_SD = 10.0
MU_RANGE = (-2.0, 20.0)
D_MAX_M = 8e-3


def truncated_gamma_fit(diameter_m, weight, d_fit_m: float, *, prior_sd: float | None = None):
    """The gamma spectrum N(D) ~ D^mu exp(-Lambda D) of drops counted above ``d_fit_m``.

    The maximum a posteriori estimate of (mu, Lambda) of a gamma density truncated to
    [D_f, :data:`D_MAX_M`], from the drops' diameters weighted by their number
    densities (the log-likelihood is the effective number of drops, (sum w)^2 / sum w^2,
    times the weighted mean log-density), with a normal prior of standard deviation
    ``prior_sd`` on mu about 0 (the exponential; None: :data:`MU_PRIOR_SD`; inf: no
    prior).  For each mu on a grid, Lambda is the root of the likelihood equation
    E[D] = the weighted mean diameter; mu is the grid's best, refined by a parabola
    through its neighbours.

    Parameters
    ----------
    diameter_m : (n,) array_like
        Diameters [m], all >= ``d_fit_m``.
    weight : (n,) array_like
        Positive weights (number densities) [any unit].
    d_fit_m : float
        The truncation [m].
    prior_sd : float, optional

    Returns
    -------
    None when the drops do not fix a spectrum (fewer than two distinct sizes), else
    (mu [-], Lambda [1/m], log Z): the density over D >= D_f is
    exp(mu ln(D / D_f) - Lambda (D - D_f) - log Z) [1/m].
    """
    d = np.asarray(diameter_m, dtype=float).ravel()
    w = np.asarray(weight, dtype=float).ravel()
    ok = np.isfinite(d) & np.isfinite(w) & (w > 0) & (d >= d_fit_m)
    d, w = d[ok], w[ok]
    if d.size < 2 or not np.ptp(d) > 0 or not d_fit_m > 0:
        return None
    n_eff = float(w.sum() ** 2 / np.sum(w * w))
    w = w / w.sum()
    m1 = float(np.sum(w * (d - d_fit_m)))                     # mean excess [m]
    ml = float(np.sum(w * np.log(d / d_fit_m)))               # mean log [-]
    x = np.linspace(0.0, D_MAX_M - d_fit_m, 600)   # excess grid [m]
    dx = np.full(x.size, x[1] - x[0])                         # trapezoid weights [m]
    dx[[0, -1]] *= 0.5
    lx = np.log1p(x / d_fit_m)
    mus = np.arange(MU_RANGE[0], MU_RANGE[1] + 1e-9, 0.1)

    def moments(mu, lam):
        logf = mu[:, None] * lx[None, :] - lam[:, None] * x[None, :]
        top = logf.max(axis=1, keepdims=True)
        f = np.exp(logf - top) * dx
        z = f.sum(axis=1)
        return (f * x).sum(axis=1) / z, np.log(z) + top[:, 0]

    def fit_lambda(mu):
        """(Lambda, log Z) at each shape of ``mu``: bisection in log Lambda, as the mean
        excess E[D - D_f] falls while Lambda grows."""
        lo = np.full(mu.size, math.log(1e-3 / m1))
        hi = np.full(mu.size, math.log(1e3 / m1 + 1e4))
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            high = moments(mu, np.exp(mid))[0] > m1
            lo = np.where(high, mid, lo)
            hi = np.where(high, hi, mid)
        lam = np.exp(0.5 * (lo + hi))
        return lam, moments(mu, lam)[1]

    lam, log_z = fit_lambda(mus)
    ll = n_eff * (mus * ml - lam * m1 - log_z)
    sd = MU_PRIOR_SD if prior_sd is None else float(prior_sd)
    if not sd > 0:
        raise ValueError(f"prior_sd must be > 0 (inf: no prior), got {prior_sd!r}")
    if np.isfinite(sd):
        ll = ll - 0.5 * (mus / sd) ** 2
    ll = np.where(np.isfinite(ll), ll, -np.inf)
    k = int(np.argmax(ll))
    if not np.isfinite(ll[k]):
        return None
    mu = float(mus[k])
    if 0 < k < mus.size - 1:
        # the parabola through the grid's best and its neighbours
        den = ll[k - 1] - 2.0 * ll[k] + ll[k + 1]
        if den < 0:
            mu += 0.1 * float(np.clip(0.5 * (ll[k - 1] - ll[k + 1]) / den, -0.5, 0.5))
    # Lambda and the normalisation at the refined mu
    lam1, lz = fit_lambda(np.array([mu]))
    return mu, float(lam1[0]), float(lz[0])


def constrained_mu(lam_per_mm):
    """The shape mu of the constrained gamma at slope Lambda [1/mm] ([Zhang2001])."""
    lam = np.asarray(lam_per_mm, dtype=float)
    return -0.016 * lam ** 2 + 1.213 * lam - 1.957


def shares(n, cut_mm: float, velocity) -> tuple[float, float, float, float]:
    """(true share of the rain below ``cut_mm``, the exponential's, the constrained gamma's,
    the fitted gamma's) for the number density ``n`` on :data:`GRID_MM` (any units) and
    fall speeds ``velocity``."""
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
    fit = truncated_gamma_fit(g[hi] * 1e-3, tail_n, cut_mm * 1e-3, prior_sd=math.inf)
    fitted = float("nan") if fit is None else completed(np.exp(fit[0] * np.log(g / cut_mm)
                                                               - fit[1] * 1e-3 * (g - cut_mm)))

    def mismatch(lam_g):
        mu = constrained_mu(lam_g)
        s = g[hi] ** mu * np.exp(-lam_g * (g[hi] - cut_mm))
        return float(np.sum(s * (g[hi] - cut_mm)) / np.sum(s)) - excess

    try:
        lam_g = brentq(mismatch, 0.3, 40.0)
    except ValueError:
        return true, expo, float("nan"), fitted
    mu = float(constrained_mu(lam_g))
    cg = completed(g ** mu * np.exp(-lam_g * (g - cut_mm)))
    return true, expo, cg, fitted


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
    print(f"{'spectrum':40s} {'D_cut':>6}  {'true':>6}  {'expon.':>6}  {'C-G':>6}  {'gamma':>6}"
          "   share of the rain below D_cut")
    for name, n in spectra((2.0, 10.0), (0.5, 2.0, 10.0, 30.0)):
        for cut in cuts:
            true, expo, cg, fitted = shares(n, cut, velocity)
            print(f"{name:40s} {cut:6.2f}  {true:6.3f}  {expo:6.3f}  {cg:6.3f}  {fitted:6.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
