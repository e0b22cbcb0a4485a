"""Shape of an oscillating raindrop (Sec. 9 [GargNayar2007]; [GargNayar2006], [TokayBeard1996]).

A falling drop's shape is its equilibrium shape (Eq. (1), [BeardChuang1987])
deformed by the two modes that dominate in rain [TokayBeard1996]: the
axisymmetric oblate-prolate mode (n = 2, m = 0) and the transverse mode
(n = 2, m = 1), both oscillating at Rayleigh's frequency of the n = 2 mode
[Rayleigh1879]:

    r(theta, phi, t) = r_eq(theta) [1 + A_20 P_2(cos theta) sin(w t + psi_20)
                                      + A_21 sin(2 theta) cos(phi - phi_21) sin(w t + psi_21)]

with w = 2 pi f_2 and theta the polar angle from the direction of fall (down).
The mode functions are scaled to a peak of 1, so A_20 and A_21 are the largest
fractional changes of the radius each mode causes.

Drop frame: world axes X (horizontal, image right), Y (up), Z (horizontal); the
drop falls along -Y.  Directions are unit vectors (..., 3) in that frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: surface tension of water at 20 C [N/m]
SURFACE_TENSION_N_M = 0.0728
#: density of water [kg/m^3]
WATER_DENSITY_KG_M3 = 1000.0

EQUILIBRIUM_SHAPES = ("beard_chuang", "spheroid", "sphere")


def rayleigh_frequency_hz(radius_m, *, n: int = 2, surface_tension_n_m: float = SURFACE_TENSION_N_M,
                          density_kg_m3: float = WATER_DENSITY_KG_M3):
    """Rayleigh's frequency of mode n of a free drop [Rayleigh1879] [Hz].

    f_n = (1 / 2 pi) sqrt(n (n - 1) (n + 2) sigma / (rho a^3)); every m of a given n
    shares it (a sphere is degenerate in m).

    Parameters
    ----------
    radius_m : array_like
        Drop radius a [m].
    n : int
        Mode order, >= 2 [-].
    surface_tension_n_m : float
        Surface tension sigma [N/m].
    density_kg_m3 : float
        Density of water rho [kg/m^3].

    Notes
    -----
    For a = 1 mm, f_2 = 121 Hz.  Drops of rain oscillate a few per cent slower
    than this (oblateness, flow around the drop); the closed form is the model
    named in Sec. 9 and [GargNayar2006].
    """
    if int(n) < 2:
        raise ValueError(f"mode order n must be >= 2, got {n}")
    a = np.asarray(radius_m, dtype=float)
    n = int(n)
    return np.sqrt(n * (n - 1) * (n + 2) * surface_tension_n_m / (density_kg_m3 * a ** 3)) / (2 * np.pi)


def _spheroid_axis_ratio(diameter_m):
    """Beard-Chuang polynomial axis ratio b/a (vertical / horizontal), D in mm."""
    dmm = np.asarray(diameter_m, dtype=float) * 1e3
    r = 1.0048 + 5.7e-4 * dmm - 2.628e-2 * dmm ** 2 + 3.682e-3 * dmm ** 3 - 1.677e-4 * dmm ** 4
    return np.clip(r, 0.3, 1.0)


def equilibrium_radius(theta_rad, radius_m, *, shape: str = "beard_chuang"):
    """Equilibrium surface radius r_eq(theta) [m]; theta from the direction of fall (down).

    Parameters
    ----------
    theta_rad : array_like
        Polar angle from the direction of fall [rad].
    radius_m : float
        Radius of the volume-equivalent sphere [m].
    shape : str
        "beard_chuang" (Eq. (1) with the [BeardChuang1987] coefficients, from
        :func:`raingauge.physics.drops.drop_shape_radius`), "spheroid" (oblate
        spheroid of equal volume with the Beard-Chuang axis ratio), "sphere".
    """
    if shape not in EQUILIBRIUM_SHAPES:
        raise ValueError(f"unknown equilibrium shape {shape!r}; valid: {list(EQUILIBRIUM_SHAPES)}")
    theta = np.asarray(theta_rad, dtype=float)
    a = float(radius_m)
    if shape == "sphere":
        return np.full(theta.shape, a)
    if shape == "beard_chuang":
        try:
            from raingauge.physics.drops import drop_shape_radius
        except ImportError:  # pragma: no cover - the physics module ships with the package
            drop_shape_radius = None
        if drop_shape_radius is not None and 2 * a <= 9e-3:
            return np.asarray(drop_shape_radius(theta, a), dtype=float)
    gamma = float(_spheroid_axis_ratio(2 * a))
    horiz = a * gamma ** (-1.0 / 3.0)
    vert = a * gamma ** (2.0 / 3.0)
    return 1.0 / np.sqrt((np.sin(theta) / horiz) ** 2 + (np.cos(theta) / vert) ** 2)


@dataclass
class OscillatingDrop:
    """A drop of radius ``radius_m`` oscillating in the (2, 0) and (2, 1) modes.

    Parameters
    ----------
    radius_m : float
        Radius of the volume-equivalent sphere [m].
    amp_axisymmetric, amp_transverse : float
        Peak fractional radius change of the (2, 0) and (2, 1) modes [-].
    phase_axisymmetric, phase_transverse : float
        Phases psi_20, psi_21 [rad].
    transverse_azimuth : float
        Azimuth phi_21 of the plane of the transverse mode, from +X towards +Z [rad].
    frequency_hz : float, optional
        Oscillation frequency; Rayleigh's f_2 for the radius by default [Hz].
    shape : str
        Equilibrium shape, see :func:`equilibrium_radius`.
    """

    radius_m: float
    amp_axisymmetric: float = 0.0
    amp_transverse: float = 0.0
    phase_axisymmetric: float = 0.0
    phase_transverse: float = 0.0
    transverse_azimuth: float = 0.0
    frequency_hz: float | None = None
    shape: str = "beard_chuang"

    def __post_init__(self):
        if not self.radius_m > 0:
            raise ValueError(f"drop radius must be > 0 m, got {self.radius_m}")
        if abs(self.amp_axisymmetric) + abs(self.amp_transverse) >= 0.5:
            raise ValueError("oscillation amplitudes must sum to less than 0.5 (fraction of the radius)")
        if self.frequency_hz is None:
            self.frequency_hz = float(rayleigh_frequency_hz(self.radius_m))
        # equilibrium radius as a Chebyshev series in cos(theta): Eq. (1)'s cos(n theta)
        # terms are exactly T_n(cos theta), so degree 12 reproduces it
        theta = np.linspace(0.0, np.pi, 721)
        r_eq = equilibrium_radius(theta, self.radius_m, shape=self.shape)
        self._cheb = np.polynomial.chebyshev.chebfit(np.cos(theta), r_eq, 12)
        self._r_eq_max = float(r_eq.max())

    @property
    def period_s(self) -> float:
        """Oscillation period 1 / f [s]."""
        return 1.0 / self.frequency_hz

    @property
    def max_radius_m(self) -> float:
        """Upper bound of the surface radius over all times [m]."""
        return self._r_eq_max * (1.0 + abs(self.amp_axisymmetric) + abs(self.amp_transverse)) * 1.001

    def radius(self, u, t_s=0.0):
        """Surface radius r(u, t) [m] along unit directions u (..., 3) at time t [s] (broadcast)."""
        u = np.asarray(u, dtype=float)
        cos_t = np.clip(-u[..., 1], -1.0, 1.0)          # theta from the direction of fall (-Y)
        r_eq = np.polynomial.chebyshev.chebval(cos_t, self._cheb)
        if self.amp_axisymmetric == 0.0 and self.amp_transverse == 0.0:
            return r_eq
        w = 2.0 * np.pi * self.frequency_hz
        t = np.asarray(t_s, dtype=float)
        p2 = 1.5 * cos_t ** 2 - 0.5
        # sin(2 theta) cos(phi - phi_21) = 2 cos(theta) (u_x cos phi_21 + u_z sin phi_21)
        transverse = 2.0 * cos_t * (u[..., 0] * np.cos(self.transverse_azimuth)
                                    + u[..., 2] * np.sin(self.transverse_azimuth))
        dev = (self.amp_axisymmetric * p2 * np.sin(w * t + self.phase_axisymmetric)
               + self.amp_transverse * transverse * np.sin(w * t + self.phase_transverse))
        return r_eq * (1.0 + dev)

    def surface(self, *, n_march: int = 0, n_bisect: int = 40):
        """A time-dependent :class:`raingauge.render.raytrace.StarSurface` of this drop (centre 0).

        ``n_march=0`` treats the drop as convex (true of the equilibrium shapes up to
        D ~ 4 mm and small oscillations); give n_march > 0 for dimpled large drops.
        """
        from raingauge.render.raytrace import StarSurface

        return StarSurface(self.radius, self.max_radius_m, n_march=n_march, n_bisect=n_bisect,
                           time_dependent=True)
