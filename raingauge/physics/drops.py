"""Raindrops: size distributions, fall velocity, shape, Eq. (28) and DSD moments.

Units are SI throughout: diameters ``D`` and radii ``a`` in metres, number
densities ``N(D)`` in m^-4 (drops per m^3 of air per metre of diameter),
velocities in m/s.  Millimetres and mm/h appear only in names that say so
(``rain_rate_mm_h``, ``dm_mm``, ``PARSIVEL_D_CENTRES_MM``).

Contents
--------
* Fall-velocity laws behind one registry, :func:`fall_velocity`
  (``"paper"``, ``"gunn_kinzer"``, ``"atlas1973"``, ``"beard1976"``).
* Drop size distributions with one interface (:class:`DSD`):
  :class:`MarshallPalmer`, :class:`GammaDSD`, :class:`NormalizedGammaDSD`,
  :class:`BinnedDSD`; the registry :func:`make_dsd`; :func:`gamma_for_rain_rate`.
* Spatial statistics of rain [GargNayar2007, Sec. 3]: Poisson counts and
  uniform positions (:func:`poisson_count`, :func:`uniform_positions`,
  :func:`sample_drops_in_box`).
* Eq. (28) [GargNayar2007]: :func:`rain_rate_mm_h` (continuous DSD) and
  :func:`rain_rate_from_drops` (a drop population in a volume); the moments a
  disdrometer reports, :func:`dsd_moments` (binned spectrum) and
  :func:`dsd_moments_continuous`.  Moments from raw Parsivel counts live in
  :mod:`raingauge.disdrometer`.
* Drop shape, Eq. (1) [GargNayar2007] with the [BeardChuang1987] model's
  coefficients as tabulated in [ChuangBeard1990]: :func:`shape_coefficients`,
  :func:`drop_shape_radius`, :func:`axis_ratio`.
* The Parsivel size and velocity classes [Loffler-Mang2000].
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Callable

import numpy as np
from scipy import special, stats
from scipy.interpolate import PchipInterpolator
from scipy.optimize import brentq

# ---------------------------------------------------------------------------
# Constants
# ---------------------------------------------------------------------------

#: density of liquid water [kg m^-3]
RHO_WATER = 1000.0
#: standard gravity [m s^-2]
GRAVITY = 9.80665
#: specific gas constant of dry air [J kg^-1 K^-1]
R_DRY_AIR = 287.05
#: reference surface pressure [Pa] and temperature [K] (Gunn & Kinzer's laboratory: 1013 hPa, 20 C)
P_REF_PA = 101325.0
T_REF_K = 293.15

#: default drop-diameter range of the continuous DSDs [m].  Drops below 0.1 mm
#: carry no measurable water; 5.8 mm is the largest drop of the Gunn-Kinzer table
#: (larger drops break up in free fall), so every velocity law covers this range.
DEFAULT_D_MIN_M = 0.1e-3
DEFAULT_D_MAX_M = 5.8e-3

#: Eq. (28) conversion: m s^-1 of water depth -> mm h^-1
_M_S_TO_MM_H = 3.6e6

# ---------------------------------------------------------------------------
# Parsivel classes
# ---------------------------------------------------------------------------

#: Parsivel (OTT, first generation) diameter class centres [mm], 32 classes
PARSIVEL_D_CENTRES_MM = np.array([
    0.062, 0.187, 0.312, 0.437, 0.562, 0.687, 0.812, 0.937, 1.062, 1.187,
    1.375, 1.625, 1.875, 2.125, 2.375, 2.75, 3.25, 3.75, 4.25, 4.75,
    5.5, 6.5, 7.5, 8.5, 9.5, 11.0, 13.0, 15.0, 17.0, 19.0, 21.5, 24.5])
#: Parsivel diameter class widths [mm]
PARSIVEL_D_WIDTHS_MM = np.array(
    [0.125] * 10 + [0.25] * 5 + [0.5] * 5 + [1.0] * 5 + [2.0] * 5 + [3.0] * 2)
#: Parsivel velocity class centres [m/s], 32 classes
PARSIVEL_V_CENTRES_M_S = np.array([
    0.05, 0.15, 0.25, 0.35, 0.45, 0.55, 0.65, 0.75, 0.85, 0.95,
    1.1, 1.3, 1.5, 1.7, 1.9, 2.2, 2.6, 3.0, 3.4, 3.8,
    4.4, 5.2, 6.0, 6.8, 7.6, 8.8, 10.4, 12.0, 13.6, 15.2, 17.6, 20.8])
#: Parsivel velocity class widths [m/s]
PARSIVEL_V_WIDTHS_M_S = np.array(
    [0.1] * 10 + [0.2] * 5 + [0.4] * 5 + [0.8] * 5 + [1.6] * 5 + [3.2] * 2)
#: Parsivel diameter class edges [mm] (33 values, 0 to 26 mm); the centres
#: above are the instrument's nominal values (0.062 for 0-0.125 mm, etc.)
PARSIVEL_D_EDGES_MM = np.concatenate([[0.0], np.cumsum(PARSIVEL_D_WIDTHS_MM)])


# ---------------------------------------------------------------------------
# Fall velocity
# ---------------------------------------------------------------------------

#: Gunn & Kinzer (1949), Table 2: diameter [mm] -> terminal velocity [m/s]
#: at 1013 hPa, 20 C, 50 % relative humidity.
GUNN_KINZER_D_MM = np.array([
    0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0,
    2.2, 2.4, 2.6, 2.8, 3.0, 3.2, 3.4, 3.6, 3.8, 4.0, 4.2, 4.4, 4.6, 4.8, 5.0,
    5.2, 5.4, 5.6, 5.8])
GUNN_KINZER_V_M_S = np.array([
    0.27, 0.72, 1.17, 1.62, 2.06, 2.47, 2.87, 3.27, 3.67, 4.03, 4.64, 5.17,
    5.65, 6.09, 6.49, 6.90, 7.27, 7.57, 7.82, 8.06, 8.26, 8.44, 8.60, 8.72,
    8.83, 8.92, 8.98, 9.03, 9.07, 9.09, 9.12, 9.14, 9.16, 9.17])
_GK_INTERP = PchipInterpolator(GUNN_KINZER_D_MM * 1e-3, GUNN_KINZER_V_M_S, extrapolate=False)

#: Atlas et al. (1973) fit crosses zero at this diameter [m]
_ATLAS_D0_M = math.log(10.3 / 9.65) / 600.0

#: valid diameter range [m] of each fall-velocity model (NaN outside)
FALL_VELOCITY_RANGES_M: dict[str, tuple[float, float]] = {
    "paper": (0.0, 7.0e-3),
    "gunn_kinzer": (0.1e-3, 5.8e-3),
    "atlas1973": (0.1e-3, 7.0e-3),
    "beard1976": (0.5e-6, 7.0e-3),
}
FALL_VELOCITY_MODELS: tuple[str, ...] = tuple(FALL_VELOCITY_RANGES_M)


def _check_model(model: str, registry) -> None:
    if model not in registry:
        raise ValueError(f"unknown model {model!r}; valid models: {', '.join(registry)}")


def velocity_paper(diameter_m):
    """Terminal velocity of the paper, v = 200 sqrt(a) [GargNayar2007, Sec. 3].

    Parameters
    ----------
    diameter_m : array_like
        Drop diameter D [m]; a = D/2.

    Returns
    -------
    ndarray
        Velocity [m/s]; NaN outside 0 <= D <= 7 mm (a <= 3.5 mm, the paper's
        largest drop).

    Notes
    -----
    This is a large-drop law (fits the Gunn-Kinzer data for a > 0.6 mm to
    within ~15 %).  Against that table it is 1.5-2.8x too fast for
    D <= 0.5 mm (1.2x at 0.8 mm) and 10-17 % too fast above 5 mm.  It is kept because Eq. (29) and the paper's bounds
    (tau < 1.18 ms, beta < 0.039) are derived with it.
    """
    d = np.asarray(diameter_m, dtype=float)
    lo, hi = FALL_VELOCITY_RANGES_M["paper"]
    with np.errstate(invalid="ignore"):
        v = 200.0 * np.sqrt(np.where(d >= 0, d, np.nan) / 2.0)
    return np.where((d >= lo) & (d <= hi), v, np.nan)


def velocity_gunn_kinzer(diameter_m):
    """Terminal velocity tabulated by [GunnKinzer1949], monotone cubic interpolation.

    Parameters
    ----------
    diameter_m : array_like
        Drop diameter D [m].

    Returns
    -------
    ndarray
        Velocity [m/s] at 1013 hPa and 20 C; NaN outside the table,
        0.1 mm <= D <= 5.8 mm.  Exact at the tabulated diameters.
    """
    d = np.asarray(diameter_m, dtype=float)
    lo, hi = FALL_VELOCITY_RANGES_M["gunn_kinzer"]
    inside = (d >= lo) & (d <= hi)
    v = _GK_INTERP(np.where(inside, d, lo))
    return np.where(inside, v, np.nan)


def velocity_atlas1973(diameter_m):
    """Terminal velocity v = 9.65 - 10.3 exp(-600 D) [Atlas1973].

    Parameters
    ----------
    diameter_m : array_like
        Drop diameter D [m].

    Returns
    -------
    ndarray
        Velocity [m/s] at sea level; NaN outside 0.1 mm <= D <= 7 mm.

    Notes
    -----
    The fit crosses zero at D = ln(10.3/9.65)/600 = 0.109 mm; between
    0.1 mm and that diameter the velocity is returned as 0 (those drops
    carry ~1e-9 of the water of any rain).  The fit is within ~5 % of
    Gunn-Kinzer for 0.6 mm < D < 5.8 mm and too slow below.
    """
    d = np.asarray(diameter_m, dtype=float)
    lo, hi = FALL_VELOCITY_RANGES_M["atlas1973"]
    with np.errstate(over="ignore", invalid="ignore"):
        v = np.maximum(9.65 - 10.3 * np.exp(-600.0 * d), 0.0)
    return np.where((d >= lo) & (d <= hi), v, np.nan)


def air_density(pressure_pa: float = P_REF_PA, temperature_k: float = T_REF_K) -> float:
    """Density of dry air, ideal-gas law rho_a = p / (R_d T) [kg m^-3] (air density of [Beard1976]).

    Parameters
    ----------
    pressure_pa : float
        Air pressure [Pa].
    temperature_k : float
        Air temperature [K].
    """
    return pressure_pa / (R_DRY_AIR * temperature_k)


def air_viscosity(temperature_k: float = T_REF_K) -> float:
    """Dynamic viscosity of air, Sutherland's law eta = 1.458e-6 T^1.5 / (T + 110.4) [kg m^-1 s^-1] ([Beard1976]).

    Parameters
    ----------
    temperature_k : float
        Air temperature [K].
    """
    return 1.458e-6 * temperature_k ** 1.5 / (temperature_k + 110.4)


def water_surface_tension(temperature_k: float = T_REF_K) -> float:
    """Surface tension of water against air, sigma = 0.07564 - 1.4e-4 (T - 273.15) [N m^-1] ([Beard1976] regime 3).

    Parameters
    ----------
    temperature_k : float
        Temperature [K]; 0.0756 N/m at 0 C, 0.0728 N/m at 20 C.
    """
    return 0.07564 - 1.4e-4 * (temperature_k - 273.15)


def velocity_beard1976(diameter_m, pressure_pa: float = P_REF_PA,
                       temperature_k: float = T_REF_K):
    """Terminal velocity of [Beard1976] with air density from pressure and temperature.

    Three regimes, each a fit of the drag in dimensionless numbers:

    1. 0.5 um <= D < 19 um: Stokes flow with slip correction,
       v = C1 Csc D^2, C1 = (rho_w - rho_a) g / (18 eta), Csc = 1 + 2.51 lambda/D.
    2. 19 um <= D < 1.07 mm: X = ln(C2 D^3), C2 = 4 rho_a (rho_w - rho_a) g / (3 eta^2),
       Re = Csc exp(sum b_n X^n), v = eta Re / (rho_a D).
    3. 1.07 mm <= D <= 7 mm: Bond number Bo = C3 D^2, C3 = 4 (rho_w - rho_a) g / (3 sigma),
       physical property number Np = sigma^3 rho_a^2 / (eta^4 (rho_w - rho_a) g),
       X = ln(Bo Np^(1/6)), Re = Np^(1/6) exp(sum b_n X^n), v = eta Re / (rho_a D).

    Parameters
    ----------
    diameter_m : array_like
        Drop diameter D [m].
    pressure_pa : float
        Air pressure [Pa] (default 101325).
    temperature_k : float
        Air temperature [K] (default 293.15).

    Returns
    -------
    ndarray
        Velocity [m/s]; NaN outside 0.5 um <= D <= 7 mm.

    Notes
    -----
    Air: ideal-gas density, Sutherland viscosity, mean free path
    lambda = 6.62e-8 m (eta/1.818e-5)(101325/p)(T/293.15)^0.5.  At sea level
    and 20 C the law reproduces the Gunn-Kinzer table to within ~3 %; aloft
    (lower density) drops fall faster, roughly as (rho_0/rho_a)^0.4-0.5.
    """
    d = np.asarray(diameter_m, dtype=float)
    if not (pressure_pa > 0 and temperature_k > 0):
        raise ValueError(f"beard1976 needs pressure_pa > 0 and temperature_k > 0, "
                         f"got {pressure_pa!r} Pa, {temperature_k!r} K")
    lo, hi = FALL_VELOCITY_RANGES_M["beard1976"]
    inside = (d >= lo) & (d <= hi)
    dd = np.where(inside, d, 1e-3)
    rho_a = air_density(pressure_pa, temperature_k)
    eta = air_viscosity(temperature_k)
    sigma = water_surface_tension(temperature_k)
    drho = RHO_WATER - rho_a
    lam = 6.62e-8 * (eta / 1.818e-5) * (P_REF_PA / pressure_pa) * math.sqrt(temperature_k / T_REF_K)
    csc = 1.0 + 2.51 * lam / dd

    # regime 1
    v1 = drho * GRAVITY / (18.0 * eta) * csc * dd ** 2
    # regime 2
    b2 = (-0.318657e1, 0.992696, -0.153193e-2, -0.987059e-3, -0.578878e-3,
          0.855176e-4, -0.327815e-5)
    c2 = 4.0 * rho_a * drho * GRAVITY / (3.0 * eta ** 2)
    x2 = np.log(c2 * dd ** 3)
    y2 = np.polynomial.polynomial.polyval(x2, b2)
    v2 = eta * csc * np.exp(y2) / (rho_a * dd)
    # regime 3
    b3 = (-0.500015e1, 0.523778e1, -0.204914e1, 0.475294, -0.542819e-1, 0.238449e-2)
    c3 = 4.0 * drho * GRAVITY / (3.0 * sigma)
    np6 = (sigma ** 3 * rho_a ** 2 / (eta ** 4 * drho * GRAVITY)) ** (1.0 / 6.0)
    x3 = np.log(c3 * dd ** 2 * np6)
    y3 = np.polynomial.polynomial.polyval(x3, b3)
    v3 = eta * np6 * np.exp(y3) / (rho_a * dd)

    v = np.where(dd < 19e-6, v1, np.where(dd < 1.07e-3, v2, v3))
    return np.where(inside, v, np.nan)


_VELOCITY_FUNCS: dict[str, Callable] = {
    "paper": velocity_paper,
    "gunn_kinzer": velocity_gunn_kinzer,
    "atlas1973": velocity_atlas1973,
    "beard1976": velocity_beard1976,
}


def fall_velocity(diameter_m, model: str = "gunn_kinzer", **kw) -> np.ndarray:
    """Terminal fall velocity of a raindrop, from a registry of laws.

    Parameters
    ----------
    diameter_m : array_like
        Volume-equivalent drop diameter D [m].
    model : str
        One of :data:`FALL_VELOCITY_MODELS` [-]:

        ``"paper"``        v = 200 sqrt(a) [GargNayar2007]; 0 <= D <= 7 mm.
        ``"gunn_kinzer"``  the 1949 table, interpolated [GunnKinzer1949]; 0.1-5.8 mm.
        ``"atlas1973"``    9.65 - 10.3 exp(-600 D) [Atlas1973]; 0.1-7 mm.
        ``"beard1976"``    [Beard1976] with air density; 0.5 um - 7 mm;
                           keywords ``pressure_pa`` [Pa], ``temperature_k`` [K].
    **kw
        Model-specific keywords (only ``beard1976`` takes any).

    Returns
    -------
    ndarray
        Velocity [m/s], same shape as ``diameter_m`` (0-d for a scalar);
        NaN outside the model's range (see :data:`FALL_VELOCITY_RANGES_M`) and
        for NaN input.

    Raises
    ------
    ValueError
        Unknown model (the message lists the valid ones) or keywords the model
        does not take.
    """
    _check_model(model, _VELOCITY_FUNCS)
    if kw and model != "beard1976":
        raise ValueError(f"fall-velocity model {model!r} takes no keywords, got {sorted(kw)}")
    allowed = {"pressure_pa", "temperature_k"}
    if set(kw) - allowed:
        raise ValueError(f"unknown keywords {sorted(set(kw) - allowed)} for beard1976; "
                         f"valid: {sorted(allowed)}")
    return np.asarray(_VELOCITY_FUNCS[model](diameter_m, **kw), dtype=float)


# ---------------------------------------------------------------------------
# Drop size distributions
# ---------------------------------------------------------------------------

_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)


def _gauss_nodes(edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """8-point Gauss-Legendre nodes and weights on each interval of ``edges``."""
    a, b = edges[:-1, None], edges[1:, None]
    half = (b - a) / 2.0
    x = (a + b) / 2.0 + half * _GL_X[None, :]
    w = half * _GL_W[None, :]
    return x.ravel(), w.ravel()


class DSD(ABC):
    """Common interface of drop size distributions.

    Subclasses define :meth:`number_density` ``N(D)`` [m^-4] on
    [``d_min_m``, ``d_max_m``] (zero outside) and may override the sampling.
    """

    d_min_m: float
    d_max_m: float

    @abstractmethod
    def number_density(self, diameter_m) -> np.ndarray:
        """N(D) [m^-4] at diameters ``diameter_m`` [m]; zero outside [d_min_m, d_max_m]."""

    def number_density_radius(self, radius_m) -> np.ndarray:
        """Density per unit radius, rho(a) = 2 N(2a) [m^-4] (the rho(a) of Eq. 28).

        Parameters
        ----------
        radius_m : array_like
            Drop radius a [m].
        """
        return 2.0 * self.number_density(2.0 * np.asarray(radius_m, dtype=float))

    def quadrature(self) -> tuple[np.ndarray, np.ndarray]:
        """Nodes [m] and weights [m] integrating smooth f(D) N(D) over the DSD's range."""
        edges = np.linspace(self.d_min_m, self.d_max_m, 129)
        return _gauss_nodes(edges)

    def moment(self, k: float) -> float:
        """k-th moment, M_k = integral of D^k N(D) dD over [d_min, d_max] [m^(k-3)].

        Parameters
        ----------
        k : float
            Order of the moment (0 gives N_t [m^-3]).
        """
        x, w = self.quadrature()
        return float(np.sum(w * x ** k * self.number_density(x)))

    def concentration_m3(self) -> float:
        """Total number concentration N_t over [d_min, d_max] [m^-3]."""
        return self.moment(0)

    def _cdf_grid(self) -> tuple[np.ndarray, np.ndarray]:
        """Diameters [m] and the unnormalised cumulative count [m^-3] at them."""
        edges = np.linspace(self.d_min_m, self.d_max_m, 1025)
        x, w = _gauss_nodes(edges)
        per_interval = (w * self.number_density(x)).reshape(edges.size - 1, -1).sum(axis=1)
        return edges, np.concatenate([[0.0], np.cumsum(per_interval)])

    def cdf(self, diameter_m) -> np.ndarray:
        """Fraction of drops with diameter below ``diameter_m`` [m] (0 below d_min, 1 above d_max).

        Exact at 1024 equal steps of [d_min, d_max] (Gauss-Legendre), linear between.
        """
        grid, c = self._cdf_grid()
        d = np.asarray(diameter_m, dtype=float)
        if c[-1] <= 0:
            return np.zeros_like(d)
        return np.interp(d, grid, c / c[-1], left=0.0, right=1.0)

    def sample_diameters(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Draw ``n`` independent diameters [m] from N(D) normalised on [d_min, d_max].

        Inverse-CDF sampling on the grid of :meth:`cdf`.

        Parameters
        ----------
        n : int
            Number of drops.
        rng : numpy.random.Generator
            Random source.
        """
        grid, c = self._cdf_grid()
        if c[-1] <= 0:
            raise ValueError(f"{type(self).__name__}.sample_diameters: the distribution holds no drops")
        u = rng.uniform(0.0, 1.0, size=int(n))
        return np.interp(u, c / c[-1], grid)

    def sample_radii(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Draw ``n`` drop radii [m] (half the sampled diameters)."""
        return 0.5 * self.sample_diameters(n, rng)


def _check_range(d_min_m: float, d_max_m: float) -> None:
    if not (0.0 <= d_min_m < d_max_m and math.isfinite(d_max_m)):
        raise ValueError(f"need 0 <= d_min_m < d_max_m < inf, got {d_min_m!r}, {d_max_m!r}")


class GammaDSD(DSD):
    """Gamma DSD, N(D) = N0 D^mu exp(-Lambda D) [m^-4], truncated to [d_min, d_max].

    Parameters
    ----------
    n0 : float
        Intercept N0 [m^(-4-mu)].
    mu : float
        Shape parameter [-] (> -1); mu = 0 is exponential.
    lam : float
        Slope Lambda [m^-1] (> 0).
    d_min_m, d_max_m : float
        Diameter range [m] (default 0.1 mm to 5.8 mm).
    """

    def __init__(self, n0: float, mu: float, lam: float, *,
                 d_min_m: float = DEFAULT_D_MIN_M, d_max_m: float = DEFAULT_D_MAX_M):
        if not (n0 >= 0 and math.isfinite(n0)):
            raise ValueError(f"GammaDSD: n0 must be finite and >= 0, got {n0!r}")
        if not mu > -1:
            raise ValueError(f"GammaDSD: mu must be > -1, got {mu!r}")
        if not (lam > 0 and math.isfinite(lam)):
            raise ValueError(f"GammaDSD: lam must be finite and > 0 [1/m], got {lam!r}")
        _check_range(d_min_m, d_max_m)
        self.n0 = float(n0)
        self.mu = float(mu)
        self.lam = float(lam)
        self.d_min_m = float(d_min_m)
        self.d_max_m = float(d_max_m)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(n0={self.n0:.4g}, mu={self.mu:g}, lam={self.lam:.4g}, "
                f"d_min_m={self.d_min_m:g}, d_max_m={self.d_max_m:g})")

    def number_density(self, diameter_m) -> np.ndarray:
        """N(D) [m^-4]; zero outside [d_min, d_max].

        Parameters
        ----------
        diameter_m : array_like
            Diameter D [m].
        """
        d = np.asarray(diameter_m, dtype=float)
        inside = (d >= self.d_min_m) & (d <= self.d_max_m)
        dd = np.where(inside, d, self.d_min_m)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            n = self.n0 * dd ** self.mu * np.exp(-self.lam * dd)
        return np.where(inside, n, 0.0)

    def moment(self, k: float) -> float:
        """M_k = N0 Lambda^-(mu+k+1) [Gamma(mu+k+1, Lambda D) between the limits] [m^(k-3)].

        Closed form with the regularised incomplete gamma function.
        """
        s = self.mu + k + 1.0
        if s <= 0:
            return super().moment(k)
        part = (special.gammainc(s, self.lam * self.d_max_m)
                - special.gammainc(s, self.lam * self.d_min_m))
        return float(self.n0 * math.exp(special.gammaln(s) - s * math.log(self.lam)) * part)

    def cdf(self, diameter_m) -> np.ndarray:
        """Exact truncated-gamma CDF (regularised incomplete gamma function)."""
        d = np.clip(np.asarray(diameter_m, dtype=float), self.d_min_m, self.d_max_m)
        s = self.mu + 1.0
        lo = special.gammainc(s, self.lam * self.d_min_m)
        hi = special.gammainc(s, self.lam * self.d_max_m)
        if hi - lo <= 0:
            return super().cdf(diameter_m)
        return (special.gammainc(s, self.lam * d) - lo) / (hi - lo)

    def with_range(self, d_min_m: float, d_max_m: float) -> "GammaDSD":
        """The same N(D) truncated to another diameter range [m]."""
        return GammaDSD(self.n0, self.mu, self.lam, d_min_m=d_min_m, d_max_m=d_max_m)

    def sample_diameters(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Exact inverse-CDF sampling of the truncated gamma distribution [m]."""
        if self.n0 == 0:
            raise ValueError(f"{type(self).__name__}.sample_diameters: the distribution holds no drops")
        dist = stats.gamma(a=self.mu + 1.0, scale=1.0 / self.lam)
        lo, hi = dist.cdf(self.d_min_m), dist.cdf(self.d_max_m)
        if hi - lo < 1e-12:
            return super().sample_diameters(n, rng)
        u = rng.uniform(lo, hi, size=int(n))
        return np.clip(dist.ppf(u), self.d_min_m, self.d_max_m)


class MarshallPalmer(GammaDSD):
    """Marshall-Palmer DSD, N(D) = 8e6 exp(-4100 h^-0.21 D) [m^-4] [MarshallPalmer1948].

    Parameters
    ----------
    rain_rate_mm_h : float
        Rain rate h [mm/h] (>= 0).
    d_min_m, d_max_m : float
        Diameter range [m] (default 0.1 mm to 5.8 mm).

    Notes
    -----
    [GargNayar2007, Sec. 3] writes N(a) = 8e6 exp(-8200 h^-0.21 a) per unit
    *radius*.  N0 = 8e6 m^-4 (= 8000 m^-3 mm^-1) is per unit *diameter*; per
    unit radius the density is rho(a) = 2 N(2a) = 1.6e7 exp(-8200 h^-0.21 a)
    (:meth:`number_density_radius`).  With the seed's form, Eq. (28) returns
    only about 0.6 h (see :func:`marshall_palmer_paper_density_radius`).

    Even done right, Marshall-Palmer is an empirical fit and does not close
    exactly: Eq. (28) on it returns h to within ~10-20 % depending on the
    velocity law and the rate (the tests measure and bound this).  Use
    :func:`gamma_for_rain_rate` when the rate must close exactly.
    """

    N0_M4 = 8.0e6
    LAMBDA_COEFF_M = 4100.0

    def __init__(self, rain_rate_mm_h: float, *, d_min_m: float = DEFAULT_D_MIN_M,
                 d_max_m: float = DEFAULT_D_MAX_M):
        h = float(rain_rate_mm_h)
        if not (h >= 0 and math.isfinite(h)):
            raise ValueError(f"MarshallPalmer: rain_rate_mm_h must be finite and >= 0, got {rain_rate_mm_h!r}")
        self.rain_rate_mm_h = h
        if h == 0:
            super().__init__(0.0, 0.0, self.LAMBDA_COEFF_M, d_min_m=d_min_m, d_max_m=d_max_m)
        else:
            super().__init__(self.N0_M4, 0.0, self.LAMBDA_COEFF_M * h ** -0.21,
                             d_min_m=d_min_m, d_max_m=d_max_m)

    def __repr__(self) -> str:
        return f"MarshallPalmer({self.rain_rate_mm_h:g}, d_min_m={self.d_min_m:g}, d_max_m={self.d_max_m:g})"


def marshall_palmer_paper_density_radius(radius_m, rain_rate_mm_h: float) -> np.ndarray:
    """The Marshall-Palmer density exactly as printed in [GargNayar2007, Sec. 3] [m^-4].

    N(a) = 8e6 exp(-8200 h^-0.21 a), per unit radius.

    Parameters
    ----------
    radius_m : array_like
        Drop radius a [m].
    rain_rate_mm_h : float
        Rain rate h [mm/h].

    Notes
    -----
    Kept to document the slip: the intercept should be 1.6e7 per unit radius
    (8e6 is per unit diameter), so this density holds half the drops and
    Eq. (28) returns ~0.6 h.  Use :class:`MarshallPalmer` instead.
    """
    a = np.asarray(radius_m, dtype=float)
    return 8.0e6 * np.exp(-8200.0 * rain_rate_mm_h ** -0.21 * a)


class NormalizedGammaDSD(GammaDSD):
    """Normalised gamma DSD [Testud2001].

    N(D) = Nw f(mu) (D/Dm)^mu exp(-(4 + mu) D/Dm),
    f(mu) = 6 (4 + mu)^(mu+4) / (4^4 Gamma(mu + 4)).

    Parameters
    ----------
    nw : float
        Normalised intercept Nw [m^-4] (8e6 m^-4 = 8000 m^-3 mm^-1 is Marshall-Palmer's).
    dm_m : float
        Mass-weighted mean diameter Dm = M4/M3 [m].
    mu : float
        Shape [-] (> -1; mu = 0 is exponential with N0 = Nw).
    d_min_m, d_max_m : float
        Diameter range [m].

    Notes
    -----
    Nw and Dm are the untruncated-distribution values; the truncated moments
    of a spectrum with Dm well inside [d_min, d_max] agree to < 1 %.
    """

    def __init__(self, nw: float, dm_m: float, mu: float, *, d_min_m: float = DEFAULT_D_MIN_M,
                 d_max_m: float = DEFAULT_D_MAX_M):
        if not (dm_m > 0 and math.isfinite(dm_m)):
            raise ValueError(f"NormalizedGammaDSD: dm_m must be > 0 [m], got {dm_m!r}")
        if not mu > -1:
            raise ValueError(f"NormalizedGammaDSD: mu must be > -1, got {mu!r}")
        self.nw = float(nw)
        self.dm_m = float(dm_m)
        f_mu = 6.0 / 4.0 ** 4 * math.exp((mu + 4.0) * math.log(4.0 + mu) - special.gammaln(mu + 4.0))
        n0 = nw * f_mu * dm_m ** (-mu)
        super().__init__(n0, mu, (4.0 + mu) / dm_m, d_min_m=d_min_m, d_max_m=d_max_m)


class BinnedDSD(DSD):
    """A measured spectrum: constant density within each diameter class.

    Parameters
    ----------
    edges_m : array_like, shape (K+1,)
        Increasing class edges [m].
    n_m4 : array_like, shape (K,)
        Number density in each class [m^-4] (>= 0).
    """

    def __init__(self, edges_m, n_m4):
        edges = np.asarray(edges_m, dtype=float)
        n = np.asarray(n_m4, dtype=float)
        if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0) or edges[0] < 0:
            raise ValueError("BinnedDSD: edges_m must be a 1-d increasing array of >= 2 "
                             "non-negative diameters [m]")
        if n.shape != (edges.size - 1,):
            raise ValueError(f"BinnedDSD: n_m4 must have {edges.size - 1} values (one per class), "
                             f"got shape {n.shape}")
        if np.any(~np.isfinite(n)) or np.any(n < 0):
            raise ValueError("BinnedDSD: n_m4 must be finite and >= 0")
        self.edges_m = edges
        self.n_m4 = n
        self.d_min_m = float(edges[0])
        self.d_max_m = float(edges[-1])

    @classmethod
    def from_centres(cls, centres_m, widths_m, n_m4) -> "BinnedDSD":
        """Build from class centres and widths [m] of contiguous classes.

        The edges are the lowest lower edge (clipped at 0) followed by the
        cumulative widths, so rounded nominal centres (Parsivel's 0.062 mm
        for the 0-0.125 mm class) still give contiguous classes.
        """
        c = np.asarray(centres_m, dtype=float)
        w = np.asarray(widths_m, dtype=float)
        start = max(float(c[0] - w[0] / 2), 0.0)
        edges = start + np.concatenate([[0.0], np.cumsum(w)])
        return cls(edges, n_m4)

    @property
    def centres_m(self) -> np.ndarray:
        return 0.5 * (self.edges_m[1:] + self.edges_m[:-1])

    @property
    def widths_m(self) -> np.ndarray:
        return np.diff(self.edges_m)

    def number_density(self, diameter_m) -> np.ndarray:
        """Class density N(D) [m^-4] of the class holding D; zero outside the edges."""
        d = np.asarray(diameter_m, dtype=float)
        idx = np.searchsorted(self.edges_m, d, side="right") - 1
        inside = (d >= self.d_min_m) & (d <= self.d_max_m)
        idx = np.clip(idx, 0, self.n_m4.size - 1)
        return np.where(inside, self.n_m4[idx], 0.0)

    def quadrature(self) -> tuple[np.ndarray, np.ndarray]:
        return _gauss_nodes(self.edges_m)

    def concentration_m3(self) -> float:
        return float(np.sum(self.n_m4 * self.widths_m))

    def _cdf_grid(self) -> tuple[np.ndarray, np.ndarray]:
        return self.edges_m, np.concatenate([[0.0], np.cumsum(self.n_m4 * self.widths_m)])

    def __repr__(self) -> str:
        return (f"BinnedDSD({self.n_m4.size} classes, {self.d_min_m * 1e3:g}-{self.d_max_m * 1e3:g} mm, "
                f"N_t={self.concentration_m3():.4g} m^-3)")

    def with_range(self, d_min_m: float, d_max_m: float) -> "BinnedDSD":
        """The spectrum restricted to [d_min_m, d_max_m] [m]; classes cut by a limit are clipped.

        Useful before pairing a measured spectrum (Parsivel classes reach
        26 mm) with a velocity law of narrower range.
        """
        _check_range(d_min_m, d_max_m)
        lo = np.maximum(self.edges_m[:-1], d_min_m)
        hi = np.minimum(self.edges_m[1:], d_max_m)
        keep = hi > lo
        if not np.any(keep):
            raise ValueError(f"no class of the spectrum overlaps {d_min_m * 1e3:g}-{d_max_m * 1e3:g} mm")
        lo, hi, n = lo[keep], hi[keep], self.n_m4[keep]
        return BinnedDSD(np.concatenate([lo[:1], hi]), n)

    def sample_diameters(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Pick a class with probability N_k dD_k / N_t, then a uniform diameter in it [m]."""
        p = self.n_m4 * self.widths_m
        total = p.sum()
        if total <= 0:
            raise ValueError("BinnedDSD.sample_diameters: the spectrum holds no drops")
        k = rng.choice(p.size, size=int(n), p=p / total)
        return rng.uniform(self.edges_m[k], self.edges_m[k + 1])


_DSD_REGISTRY: dict[str, Callable[..., DSD]] = {
    "marshall_palmer": MarshallPalmer,
    "gamma": GammaDSD,
    "normalized_gamma": NormalizedGammaDSD,
}
DSD_MODELS: tuple[str, ...] = tuple(_DSD_REGISTRY)


def make_dsd(name: str, **params) -> DSD:
    """Build a DSD by name: N(D) [m^-4] of [MarshallPalmer1948], a gamma law, or [Testud2001].

    Parameters
    ----------
    name : str
        ``"marshall_palmer"`` (``rain_rate_mm_h``), ``"gamma"`` (``n0``, ``mu``, ``lam``, SI)
        or ``"normalized_gamma"`` (``nw`` [m^-4], ``dm_m`` [m], ``mu``); all take
        ``d_min_m``/``d_max_m`` [m].
    **params
        Constructor parameters.

    Raises
    ------
    ValueError
        Unknown name (lists the valid ones) or bad parameters.
    """
    _check_model(name, _DSD_REGISTRY)
    try:
        return _DSD_REGISTRY[name](**params)
    except TypeError as exc:
        raise ValueError(f"bad parameters for DSD {name!r}: {exc}") from None


# ---------------------------------------------------------------------------
# Eq. (28) and moments
# ---------------------------------------------------------------------------

def rain_rate_mm_h(dsd: DSD, velocity_model: str = "gunn_kinzer", **velocity_kw) -> float:
    """Rain rate of a DSD, Eq. (28) [GargNayar2007] ([WangClifford1975]).

    h = 3.6e6 (4 pi / 3) integral a^3 rho(a) v(a) da
      = 3.6e6 (pi / 6) integral D^3 N(D) v(D) dD     [mm/h].

    Parameters
    ----------
    dsd : DSD
        Drop size distribution (N(D) in m^-4, D in m).
    velocity_model : str
        A :func:`fall_velocity` model [-].
    **velocity_kw
        Keywords of the velocity model (``beard1976``: pressure_pa, temperature_k).

    Returns
    -------
    float
        Rain rate [mm/h].

    Raises
    ------
    ValueError
        If the velocity law is undefined (NaN) over part of the DSD's range
        holding more than 0.1 % of its water; narrow the DSD range or choose a
        law that covers it.

    Notes
    -----
    Eq. (28) in terms of radius with rho(a) = 2 N(2a) is identical to the
    diameter form used here.
    """
    x, w = dsd.quadrature()
    n = dsd.number_density(x)
    v = fall_velocity(x, velocity_model, **velocity_kw)
    water = w * x ** 3 * n
    missing = ~np.isfinite(v)
    if np.any(missing):
        total = water.sum()
        lost = water[missing].sum()
        if total > 0 and lost / total > 1e-3:
            lo, hi = FALL_VELOCITY_RANGES_M[velocity_model]
            raise ValueError(
                f"velocity model {velocity_model!r} covers {lo * 1e3:g}-{hi * 1e3:g} mm only, but "
                f"{100 * lost / total:.2g} % of the DSD's water lies outside it; "
                f"truncate the DSD (d_min_m/d_max_m) or use another model")
    return float(_M_S_TO_MM_H * math.pi / 6.0 * np.sum(np.where(missing, 0.0, water * v)))


def rain_rate_from_drops(diameters_m, velocities_m_s, volume_m3: float) -> float:
    """Eq. (28) over an actual population of drops in a volume [GargNayar2007].

    h = 3.6e6 sum_i (pi/6) D_i^3 v_i / V   [mm/h]

    Parameters
    ----------
    diameters_m : array_like
        Diameters of the drops present in the volume [m].
    velocities_m_s : array_like
        Their fall speeds [m/s] (same shape).
    volume_m3 : float
        The volume they occupy [m^3] (> 0).

    Returns
    -------
    float
        Rain rate [mm/h]; 0 for an empty population.
    """
    d = np.asarray(diameters_m, dtype=float)
    v = np.asarray(velocities_m_s, dtype=float)
    if d.shape != v.shape:
        raise ValueError(f"diameters and velocities differ in shape: {d.shape} vs {v.shape}")
    if not volume_m3 > 0:
        raise ValueError(f"volume_m3 must be > 0, got {volume_m3!r}")
    return float(_M_S_TO_MM_H * np.sum(math.pi / 6.0 * d ** 3 * v) / volume_m3)


def dsd_moments(d_centres_m, d_widths_m, n_m4, velocities_m_s) -> dict[str, float]:
    """The integral quantities a disdrometer reports, from a binned spectrum.

    With n_k = N(D_k) dD_k [m^-3] in class k:

    * ``nt_m3``        N_t = sum n_k                                     [m^-3]
    * ``lwc_g_m3``     W = 1e3 rho_w (pi/6) sum D^3 n_k                 [g m^-3]
    * ``rain_rate_mm_h`` Eq. (28): 3.6e6 (pi/6) sum D^3 v n_k           [mm/h]
    * ``z_mm6_m3``     Z = sum D_mm^6 n_k                                [mm^6 m^-3]
    * ``z_dbz``        10 log10 Z (NaN when Z = 0)                       [dBZ]
    * ``dm_mm``        Dm = sum D^4 n_k / sum D^3 n_k                    [mm]
    * ``nw_mm1_m3``    Nw = 4^4 W / (pi rho_w Dm^4) [Testud2001]         [m^-3 mm^-1]
    * ``ke_flux_j_m2_h`` kinetic energy flux, 3600 rho_w (pi/12) sum D^3 v^3 n_k [J m^-2 h^-1]

    Parameters
    ----------
    d_centres_m : array_like, shape (K,)
        Class centre diameters [m].
    d_widths_m : array_like, shape (K,)
        Class widths [m].
    n_m4 : array_like, shape (K,)
        Number density N(D) per class [m^-4].
    velocities_m_s : array_like, shape (K,) or scalar
        Fall velocity of each class [m/s]; classes with NaN velocity but no
        drops are ignored.

    Returns
    -------
    dict
        The keys above; Dm and Nw are NaN for an empty spectrum.
    """
    d = np.asarray(d_centres_m, dtype=float)
    dw = np.asarray(d_widths_m, dtype=float)
    n = np.asarray(n_m4, dtype=float)
    v = np.broadcast_to(np.asarray(velocities_m_s, dtype=float), d.shape)
    nk = n * dw
    v = np.where(nk > 0, v, 0.0)
    nt = float(nk.sum())
    m3 = float(np.sum(d ** 3 * nk))
    m4 = float(np.sum(d ** 4 * nk))
    lwc_kg = RHO_WATER * math.pi / 6.0 * m3
    rate = _M_S_TO_MM_H * math.pi / 6.0 * float(np.sum(d ** 3 * v * nk))
    z = float(np.sum((d * 1e3) ** 6 * nk))
    dm = m4 / m3 if m3 > 0 else float("nan")
    nw = 4.0 ** 4 * lwc_kg / (math.pi * RHO_WATER * dm ** 4) if m3 > 0 else float("nan")
    ke = 3600.0 * RHO_WATER * math.pi / 12.0 * float(np.sum(d ** 3 * v ** 3 * nk))
    return {
        "rain_rate_mm_h": rate,
        "lwc_g_m3": lwc_kg * 1e3,
        "z_mm6_m3": z,
        "z_dbz": 10.0 * math.log10(z) if z > 0 else float("nan"),
        "dm_mm": dm * 1e3,
        "nw_mm1_m3": nw * 1e-3,
        "nt_m3": nt,
        "ke_flux_j_m2_h": ke,
    }


def dsd_moments_continuous(dsd: DSD, velocity_model: str = "gunn_kinzer",
                           **velocity_kw) -> dict[str, float]:
    """:func:`dsd_moments` of a continuous DSD, by quadrature over its range (Eq. (28) [GargNayar2007] and moments).

    Parameters
    ----------
    dsd : DSD
        The distribution, N(D) [m^-4].
    velocity_model : str
        A :func:`fall_velocity` model [-] (NaN velocities count as 0).
    **velocity_kw
        Keywords of the velocity model (``beard1976``: pressure_pa [Pa], temperature_k [K]).
    """
    x, w = dsd.quadrature()
    v = np.nan_to_num(fall_velocity(x, velocity_model, **velocity_kw), nan=0.0)
    return dsd_moments(x, w, dsd.number_density(x), v)


_eq28_rate = rain_rate_mm_h


def gamma_for_rain_rate(rain_rate_mm_h: float, mu: float, velocity_model: str = "gunn_kinzer",
                        *, nw: float = MarshallPalmer.N0_M4, d_min_m: float = DEFAULT_D_MIN_M,
                        d_max_m: float = DEFAULT_D_MAX_M, **velocity_kw) -> GammaDSD:
    """A gamma DSD whose Eq. (28) rain rate equals the target exactly.

    The normalised intercept is held at ``nw`` (default Marshall-Palmer's
    8e6 m^-4) and Dm is solved for (Brent) so that :func:`rain_rate_mm_h`
    with ``velocity_model`` returns ``rain_rate_mm_h``.  With mu = 0 this is
    Marshall-Palmer re-tuned to close.

    Parameters
    ----------
    rain_rate_mm_h : float
        Target rain rate [mm/h] (> 0).
    mu : float
        Shape parameter [-] (> -1).
    velocity_model : str
        Velocity law used in Eq. (28) [-].
    nw : float
        Normalised intercept [m^-4].
    d_min_m, d_max_m : float
        Diameter range [m].
    **velocity_kw
        Keywords of the velocity model (``beard1976``: pressure_pa [Pa], temperature_k [K]).

    Returns
    -------
    GammaDSD
        A :class:`NormalizedGammaDSD` (a GammaDSD subclass).
    """
    if not (rain_rate_mm_h > 0 and math.isfinite(rain_rate_mm_h)):
        raise ValueError(f"gamma_for_rain_rate: rain_rate_mm_h must be > 0, got {rain_rate_mm_h!r}")
    _check_model(velocity_model, _VELOCITY_FUNCS)

    def mismatch(log_dm: float) -> float:
        dsd = NormalizedGammaDSD(nw, math.exp(log_dm), mu, d_min_m=d_min_m, d_max_m=d_max_m)
        rate = _eq28_rate(dsd, velocity_model, **velocity_kw)
        return math.log(max(rate, 1e-300)) - math.log(rain_rate_mm_h)

    lo, hi = math.log(0.05e-3), math.log(20e-3)
    f_lo, f_hi = mismatch(lo), mismatch(hi)
    if not (f_lo < 0 < f_hi):
        raise ValueError(f"no gamma DSD with mu={mu}, Nw={nw:g} m^-4 in {d_min_m * 1e3:g}-"
                         f"{d_max_m * 1e3:g} mm reaches {rain_rate_mm_h} mm/h; raise nw or d_max_m")
    log_dm = brentq(mismatch, lo, hi, xtol=1e-10, rtol=1e-12)
    return NormalizedGammaDSD(nw, math.exp(log_dm), mu, d_min_m=d_min_m, d_max_m=d_max_m)



# ---------------------------------------------------------------------------
# Spatial statistics [GargNayar2007, Sec. 3]
# ---------------------------------------------------------------------------

def _box_array(box_m) -> np.ndarray:
    box = np.asarray(box_m, dtype=float)
    if box.shape != (3, 2) or np.any(box[:, 1] <= box[:, 0]) or not np.all(np.isfinite(box)):
        raise ValueError("box_m must be ((x0, x1), (y0, y1), (z0, z1)) [m] with x0 < x1 etc.")
    return box


def box_volume_m3(box_m) -> float:
    """Volume V = (x1 - x0)(y1 - y0)(z1 - z0) of an axis-aligned box [m^3] (the V of Sec. 3 [GargNayar2007]).

    Parameters
    ----------
    box_m : array_like, shape (3, 2)
        ((x0, x1), (y0, y1), (z0, z1)) [m].
    """
    box = _box_array(box_m)
    return float(np.prod(box[:, 1] - box[:, 0]))


def poisson_count(density_m3: float, volume_m3: float, rng: np.random.Generator) -> int:
    """Number of drops in a volume, P(k) = exp(-n) n^k / k!, n = rho V [GargNayar2007, Sec. 3].

    Parameters
    ----------
    density_m3 : float
        Mean drop density rho [m^-3].
    volume_m3 : float
        Volume V [m^3].
    rng : numpy.random.Generator
        Random source.
    """
    if density_m3 < 0 or volume_m3 < 0:
        raise ValueError("density_m3 and volume_m3 must be >= 0")
    return int(rng.poisson(density_m3 * volume_m3))


def uniform_positions(n: int, box_m, rng: np.random.Generator) -> np.ndarray:
    """``n`` positions uniform in a box, p(r) = 1/V [GargNayar2007, Sec. 3] -> (n, 3) [m].

    Parameters
    ----------
    n : int
        Number of positions [-].
    box_m : array_like, shape (3, 2)
        ((x0, x1), (y0, y1), (z0, z1)) [m].
    rng : numpy.random.Generator
        Random source.
    """
    box = _box_array(box_m)
    return rng.uniform(box[:, 0], box[:, 1], size=(int(n), 3))


def sample_drops_in_box(dsd: DSD, box_m, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random snapshot of rain in a box: Poisson count, uniform positions, DSD diameters [GargNayar2007, Sec. 3].

    Parameters
    ----------
    dsd : DSD
        Drop size distribution (sets N_t and the diameters).
    box_m : array_like, shape (3, 2)
        ((x0, x1), (y0, y1), (z0, z1)) [m].
    rng : numpy.random.Generator
        Random source.

    Returns
    -------
    positions_m : ndarray, shape (n, 3)
        Drop centres [m].
    diameters_m : ndarray, shape (n,)
        Drop diameters [m].
    """
    volume = box_volume_m3(box_m)
    n = poisson_count(dsd.concentration_m3(), volume, rng)
    if n == 0:
        return np.zeros((0, 3)), np.zeros(0)
    return uniform_positions(n, box_m, rng), dsd.sample_diameters(n, rng)


# ---------------------------------------------------------------------------
# Drop shape, Eq. (1)
# ---------------------------------------------------------------------------

#: Diameters [mm] of the equilibrium-shape table of Eq. (1).
SHAPE_TABLE_D_MM = np.array([1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 5.5, 6.0, 6.5, 7.0, 8.0, 9.0])
#: Cosine-series shape coefficients c_0..c_10 (x 1e-4) of uncharged drops in
#: equilibrium fall, [ChuangBeard1990] Table 1 (the [BeardChuang1987] model),
#: converted to the paper's convention theta = 0 pointing in the direction
#: of fall (down): c_n(paper) = (-1)^n c_n(table).  Rows: SHAPE_TABLE_D_MM.
_SHAPE_TABLE_E4 = np.array([
    # c0    c1     c2    c3    c4   c5    c6   c7   c8   c9  c10
    [-28,   -30,   -83,  -22,   -3,   2,    1,   0,   0,   0,   0],
    [-72,   -70,  -210,  -57,   -6,   7,    3,   0,  -1,   0,   1],
    [-134, -118,  -385, -100,   -5,  17,    6,  -1,  -3,   1,   1],
    [-211, -180,  -592, -147,    4,  32,   10,  -3,  -5,   1,   2],
    [-297, -247,  -816, -188,   24,  52,   13,  -8,  -8,   1,   4],
    [-388, -309, -1042, -221,   53,  75,   15, -15, -12,   0,   7],
    [-481, -359, -1263, -244,   91,  99,   15, -25, -16,  -2,  10],
    [-573, -401, -1474, -255,  137, 121,   11, -36, -19,  -6,  13],
    [-665, -435, -1674, -258,  187, 141,    4, -48, -21, -11,  17],
    [-755, -465, -1863, -251,  242, 157,   -7, -61, -21, -17,  21],
    [-843, -472, -2040, -240,  299, 168,  -21, -73, -20, -25,  24],
    [-930, -487, -2207, -222,  358, 175,  -37, -84, -16, -34,  27],
    [-1014, -492, -2364, -199, 419, 178,  -56, -93, -12, -43,  30],
    [-1187, -482, -2650, -148, 543, 171, -100, -107,  2, -64,  32],
    [-1328, -403, -2899, -106, 662, 153, -146, -111, 18, -81,  31],
], dtype=float)
SHAPE_COEFFICIENTS = _SHAPE_TABLE_E4 * 1e-4
#: largest diameter of the shape table [m]
SHAPE_D_MAX_M = 9.0e-3


def shape_coefficients(diameter_m) -> np.ndarray:
    """Cosine-series coefficients c_0..c_10 of the equilibrium drop shape of Eq. (1) [GargNayar2007] [-].

    Parameters
    ----------
    diameter_m : array_like
        Volume-equivalent diameter D [m].

    Returns
    -------
    ndarray, shape (..., 11)
        c_0..c_10 (paper convention, theta = 0 downward), linearly interpolated
        in the table for 1 mm <= D <= 9 mm and scaled as (D / 1 mm)^2 below
        1 mm (distortion grows with the Bond number, ~D^2); NaN for D < 0 or
        D > 9 mm.
    """
    d = np.asarray(diameter_m, dtype=float)
    dmm = d * 1e3
    table_d = SHAPE_TABLE_D_MM
    cols = [np.interp(np.clip(dmm, table_d[0], table_d[-1]), table_d, SHAPE_COEFFICIENTS[:, k])
            for k in range(11)]
    c = np.stack(cols, axis=-1)
    small = np.clip(dmm / table_d[0], 0.0, 1.0) ** 2
    c = np.where((dmm < table_d[0])[..., None], SHAPE_COEFFICIENTS[0] * small[..., None], c)
    bad = ~((d >= 0) & (d <= SHAPE_D_MAX_M))
    return np.where(bad[..., None], np.nan, c)


def drop_shape_radius(theta_rad, radius_m) -> np.ndarray:
    """Eq. (1) [GargNayar2007]: r(theta) = a (1 + sum_{n=0}^{10} c_n cos(n theta)) [m].

    Parameters
    ----------
    theta_rad : array_like
        Polar angle theta [rad]; theta = 0 points in the direction of fall (down).
    radius_m : array_like
        Radius a of the volume-equivalent sphere [m] (broadcast against theta).

    Returns
    -------
    ndarray
        Distance from the drop's centre to its surface [m].

    Notes
    -----
    Eq. (1) in the text sums n = 1..10 and omits the coefficients; they are
    taken from [ChuangBeard1990] Table 1 ([BeardChuang1987] model).  The
    n = 0 term c_0 (negative) is included: it keeps the drop's volume equal
    to that of the sphere of radius a.  The table's polar angle is measured
    from the top of the drop; here c_n carries the factor (-1)^n so that
    theta = 0 is the flattened base facing the direction of fall, as in the
    paper's Fig. 2(a).
    """
    theta = np.asarray(theta_rad, dtype=float)
    a = np.asarray(radius_m, dtype=float)
    theta, a = np.broadcast_arrays(theta, a)
    c = shape_coefficients(2.0 * a)
    n = np.arange(11)
    series = np.sum(c * np.cos(n * theta[..., None]), axis=-1)
    return a * (1.0 + series)


def _shape_axis_ratio(diameter_m) -> np.ndarray:
    d = np.atleast_1d(np.asarray(diameter_m, dtype=float))
    theta = np.linspace(0.0, math.pi, 721)
    r = drop_shape_radius(theta[None, :], d[:, None] / 2.0)
    vertical = r[:, 0] + r[:, -1]
    horizontal = 2.0 * np.max(r * np.sin(theta)[None, :], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = vertical / horizontal
    out = np.where(d == 0, 1.0, out)
    return out.reshape(np.shape(diameter_m))


def axis_ratio(diameter_m, model: str = "beard_chuang") -> np.ndarray:
    """Equilibrium axis ratio b/a (vertical over horizontal) of a falling drop.

    Parameters
    ----------
    diameter_m : array_like
        Volume-equivalent diameter D [m].
    model : str
        ``"beard_chuang"``: polynomial fit [Brandes2002] to [BeardChuang1987],
        1.0048 + 5.7e-4 D - 2.628e-2 D^2 + 3.682e-3 D^3 - 1.677e-4 D^4 (D in mm),
        valid 0 < D <= 7 mm (1 below 0.5 mm within 0.5 %).
        ``"cosine_shape"``: height over width of the Eq. (1) shape
        (:func:`drop_shape_radius`), valid 0 <= D <= 9 mm.
        ``"pruppacher_beard"``: 1.03 - 0.062 D (D in mm) [PruppacherBeard1970], clipped to <= 1.
        ``"sphere"``: 1.

    Returns
    -------
    ndarray
        Axis ratio [-]; NaN outside 0 <= D <= 7 mm.
    """
    models = ("beard_chuang", "cosine_shape", "pruppacher_beard", "sphere")
    _check_model(model, models)
    d = np.asarray(diameter_m, dtype=float)
    dmm = d * 1e3
    inside = (d >= 0) & (d <= 7e-3)
    if model == "cosine_shape":
        return _shape_axis_ratio(d)
    if model == "beard_chuang":
        r = 1.0048 + 5.7e-4 * dmm - 2.628e-2 * dmm ** 2 + 3.682e-3 * dmm ** 3 - 1.677e-4 * dmm ** 4
        r = np.minimum(r, 1.0)
    elif model == "pruppacher_beard":
        r = np.minimum(1.03 - 0.062 * dmm, 1.0)
    else:
        r = np.ones_like(dmm)
    return np.where(inside, r, np.nan)
