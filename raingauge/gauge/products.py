"""From counted drops to the products a disdrometer reports (Sec. 8, Eq. (28)).

Each counted drop i carries its diameter D_i [m], fall speed v_i [m/s] and a
weight g_i = 1 / (kappa(a_i) A_i) [s m^-3], the inverse of the space-time its
kind of drop is sampled in (:mod:`raingauge.gauge.volume`).  Over a window of
duration t the drop adds rho_i = g_i / t to the number density, and

    h = 3.6e6 (pi / 6) sum_i D_i^3 v_i rho_i          [mm/h]

is Eq. (28) [GargNayar2007] (h = 3.6e6 (4 pi / 3) int a^3 rho(a) v(a) da)
summed over the drops actually seen [WangClifford1975].  The moments follow
the usual disdrometer definitions ([Testud2001] for Nw).

The 95 % interval of the rate is that of a compound Poisson sum: with
c_i the rate contributions, n_eff = (sum c)^2 / sum c^2 drops of equal
contribution give the same variance, and the exact (Garwood) Poisson interval
on n_eff, scaled, brackets the rate.  The sum is skewed (a few large drops
carry much of it), so the upper limit uses the variance with two more drops
like the largest seen, which restores the coverage of windows that missed
the rare large drops (tests/test_gauge_products.py); a relative systematic
term (the sample volume's calibration) is added in quadrature.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "INTENSITY_CLASSES",
    "intensity_class",
    "intensity_code",
    "synop_4680",
    "poisson_interval",
    "rate_interval",
    "window_products",
    "NONE_BELOW_MM_H",
]

#: Intensity classes and their upper bounds [mm/h].
INTENSITY_CLASSES: tuple[tuple[str, float], ...] = (
    ("none", 0.0), ("light", 2.5), ("moderate", 10.0), ("heavy", 50.0), ("violent", math.inf))
#: Rates below this read as no rain [mm/h].
NONE_BELOW_MM_H = 0.05


def intensity_class(rate_mm_h: float) -> str:
    """Intensity class of a rain rate: none, light (< 2.5), moderate (< 10), heavy (< 50), violent.

    Parameters
    ----------
    rate_mm_h : float
        Rain rate [mm/h]; below :data:`NONE_BELOW_MM_H` (or NaN) is "none".
    """
    if not (rate_mm_h >= NONE_BELOW_MM_H):
        return "none"
    for name, upper in INTENSITY_CLASSES[1:]:
        if rate_mm_h < upper:
            return name
    return "violent"


def intensity_code(name: str) -> int:
    """0 none, 1 light, 2 moderate, 3 heavy, 4 violent."""
    names = [n for n, _ in INTENSITY_CLASSES]
    if name not in names:
        raise ValueError(f"unknown intensity class {name!r}; valid: {names}")
    return names.index(name)


def synop_4680(rate_mm_h: float, dm_mm: float | None = None) -> int:
    """Present weather from an automatic station, WMO code table 4680 [WMO306].

    0 no significant weather; rain (not freezing) 61 slight, 62 moderate,
    63 heavy; drizzle 51 slight (< 0.2 mm/h), 52 moderate (< 0.5 mm/h),
    53 heavy when the drops are drizzle-sized (Dm < 0.5 mm).

    Parameters
    ----------
    rate_mm_h : float
        Rain rate [mm/h].
    dm_mm : float, optional
        Mass-weighted mean diameter [mm].

    Notes
    -----
    Table 4680 names the intensities without fixing thresholds; the rain
    codes follow this instrument's intensity classes (61 below 2.5 mm/h,
    62 below 10 mm/h, 63 above, violent included) and the drizzle ones the
    thresholds common to optical disdrometers.
    """
    cls = intensity_class(rate_mm_h)
    if cls == "none":
        return 0
    if dm_mm is not None and np.isfinite(dm_mm) and dm_mm < 0.5:
        return 51 if rate_mm_h < 0.2 else (52 if rate_mm_h < 0.5 else 53)
    return {"light": 61, "moderate": 62, "heavy": 63, "violent": 63}[cls]


def poisson_interval(n: float, *, level: float = 0.95) -> tuple[float, float]:
    """Exact (Garwood) interval of a Poisson mean from n counts (n may be fractional).

    Parameters
    ----------
    n : float
        Observed count (>= 0).
    level : float
        Confidence level.
    """
    from scipy.stats import chi2

    alpha = 1.0 - level
    lo = 0.0 if n <= 0 else float(chi2.ppf(alpha / 2, 2 * n) / 2)
    hi = float(chi2.ppf(1 - alpha / 2, 2 * n + 2) / 2)
    return lo, hi


def rate_interval(contributions, *, empty_scale: float = 0.0, systematic_rel: float = 0.03,
                  level: float = 0.95) -> tuple[float, float]:
    """Interval of a rate that is a sum of independent Poisson-counted contributions.

    Parameters
    ----------
    contributions : array_like
        Rate each counted drop adds [mm/h].
    empty_scale : float
        Rate one typical drop would add, for the upper bound when nothing was counted [mm/h].
    systematic_rel : float
        Relative standard uncertainty of the calibration (sample volume) [-].
    level : float
        Confidence level.

    Returns
    -------
    (lo, hi) [mm/h]
    """
    c = np.asarray(contributions, dtype=float)
    c = c[np.isfinite(c) & (c > 0)]
    z = float(np.sqrt(2) * __import__("scipy.special", fromlist=["erfinv"]).erfinv(level))
    if c.size == 0:
        return 0.0, float(poisson_interval(0.0, level=level)[1] * empty_scale)
    total = float(c.sum())
    s2 = float(np.sum(c ** 2))
    n_eff = total ** 2 / s2
    lo = poisson_interval(n_eff, level=level)[0] * total / n_eff
    # the sum is skewed by rare large drops: a window that happened to miss them reads low,
    # so the upper side uses the variance with two more drops like the largest one seen
    n_up = total ** 2 / (s2 + 2.0 * float(c.max()) ** 2)
    hi = poisson_interval(n_up, level=level)[1] * total / n_up
    # add the systematic part in quadrature on each side
    dlo = math.hypot(total - lo, z * systematic_rel * total)
    dhi = math.hypot(hi - total, z * systematic_rel * total)
    return max(total - dlo, 0.0), total + dhi


def window_products(diameter_m, velocity_m_s, weight_s_m3, duration_s: float, *,
                    empty_scale_mm_h: float = 0.0, systematic_rel: float = 0.03) -> dict:
    """Rain rate and DSD products of one window of counted drops.

    Parameters
    ----------
    diameter_m : (K,) array
        Diameters of the counted drops [m].
    velocity_m_s : (K,) array
        Their fall speeds [m/s].
    weight_s_m3 : (K,) array
        1 / (sampled space-time) of each [s m^-3] (rho_i = weight / duration).
    duration_s : float
        Window duration [s] (> 0).
    empty_scale_mm_h : float
        Rate one typical drop would add, for the upper bound of an empty window [mm/h].

    Returns
    -------
    dict with ``rain_rate_mm_h, rain_rate_ci95_mm_h, dsd_d_mm, dsd_n_m3_mm, nt_m3, dm_mm,
    nw_mm1_m3, z_mm6_m3, z_dbz, lwc_g_m3, ke_flux_j_m2_h, drops_counted``.
    """
    from raingauge.physics.drops import PARSIVEL_D_CENTRES_MM, PARSIVEL_D_EDGES_MM, PARSIVEL_D_WIDTHS_MM

    if not duration_s > 0:
        raise ValueError(f"window duration must be > 0 s, got {duration_s!r}")
    d = np.asarray(diameter_m, dtype=float)
    v = np.asarray(velocity_m_s, dtype=float)
    g = np.asarray(weight_s_m3, dtype=float)
    ok = np.isfinite(d) & np.isfinite(v) & np.isfinite(g) & (g > 0) & (d > 0)
    d, v, g = d[ok], v[ok], g[ok]
    rho = g / duration_s                      # m^-3 per drop
    contrib = 3.6e6 * math.pi / 6.0 * d ** 3 * v * rho
    rate = float(contrib.sum())
    lo, hi = rate_interval(contrib, empty_scale=empty_scale_mm_h, systematic_rel=systematic_rel)
    d_mm = d * 1e3
    k = np.searchsorted(PARSIVEL_D_EDGES_MM, d_mm, side="right") - 1
    inside = (k >= 0) & (k < PARSIVEL_D_CENTRES_MM.size)
    n_class = np.bincount(k[inside], weights=rho[inside], minlength=PARSIVEL_D_CENTRES_MM.size)
    nd = n_class / PARSIVEL_D_WIDTHS_MM
    nt = float(rho.sum())
    m3 = float(np.sum(d_mm ** 3 * rho))
    m4 = float(np.sum(d_mm ** 4 * rho))
    z = float(np.sum(d_mm ** 6 * rho))
    lwc = 1e6 * math.pi / 6.0 * float(np.sum(d ** 3 * rho))          # g m^-3
    dm = m4 / m3 if m3 > 0 else float("nan")
    nw = 4.0 ** 4 / math.pi * lwc / (1e-3 * dm ** 4) if m3 > 0 else float("nan")
    ke = 3600.0 * 1000.0 * math.pi / 12.0 * float(np.sum(d ** 3 * v ** 3 * rho))
    return {
        "rain_rate_mm_h": rate,
        "rain_rate_ci95_mm_h": [lo, hi],
        "dsd_d_mm": PARSIVEL_D_CENTRES_MM.tolist(),
        "dsd_n_m3_mm": nd.tolist(),
        "nt_m3": nt,
        "dm_mm": dm,
        "nw_mm1_m3": nw,
        "z_mm6_m3": z,
        "z_dbz": 10.0 * math.log10(z) if z > 0 else float("nan"),
        "lwc_g_m3": lwc,
        "ke_flux_j_m2_h": ke,
        "drops_counted": int(d.size),
        "rate_contributions_mm_h": contrib,
    }
