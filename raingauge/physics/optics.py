"""Optics of a single raindrop: Eqs. (5)-(14) [GargNayar2007], Sec. 4.2.

Geometry (Fig. 5 [GargNayar2007]).  A local frame sits at the centre of the
drop with its z-axis along the camera's optical axis, pointing *away* from the
camera (camera frame convention: x right, y down, z forward).  A direction is
written as a polar angle theta from +z and an azimuth phi about z.  The camera
ray through an image point of the drop travels along ``v = (sin(alpha) cos(phi_n),
sin(alpha) sin(phi_n), cos(alpha))``; it meets the drop surface at the point whose
outward normal is ``n = (theta_n, phi_n)``.  Points the camera sees have
``theta_n`` in ``(pi/2, pi]`` (normals facing the camera); the centre of the drop's
image is ``theta_n = pi``.  The angles of the paper are planar and *signed*: a
direction ``(theta, phi)`` with theta outside ``[0, pi]`` is the same vector
``(sin theta cos phi, sin theta sin phi, cos theta)`` (see :func:`direction`).

Every scene direction returned here (``r``, ``s``, ``p``) is the direction *from the
drop towards the scene* that sends light to the camera.

All angles are in radians; the refractive index ``mu`` is relative to air.
"""

from __future__ import annotations

import numpy as np

#: refractive index of water at visible wavelengths [-]
MU_WATER = 1.333
#: refractive index of acrylic (PMMA), as used for the Fig. 6 experiment [-]
MU_ACRYLIC = 1.49

__all__ = [
    "MU_WATER", "MU_ACRYLIC", "fresnel_reflectance", "refraction_angle", "incidence_angle",
    "image_radius", "refraction_mapping", "specular_mapping", "internal_reflection_mapping",
    "transfer_refraction", "transfer_specular", "transfer_internal", "composite_radiance",
    "direction", "angles", "normal_theta_from_refraction", "drop_field_of_view",
    "mean_transfer", "refraction_share", "refraction_exit_point",
]


# --------------------------------------------------------------------------------------
# Fresnel and Snell
# --------------------------------------------------------------------------------------

def fresnel_reflectance(incidence_rad, mu):
    """Fresnel reflectance k(i, mu) for unpolarised light (note 5 [GargNayar2007]; [BornWolf1999]).

    Parameters
    ----------
    incidence_rad : array_like
        Angle of incidence i measured from the surface normal [rad], in [0, pi/2].
    mu : float or array_like
        Refractive index of the far side relative to the near side [-]
        (mu = 1.333 for air -> water, 1/1.333 for water -> air).

    Returns
    -------
    ndarray
        Reflected fraction of the incident radiance [-]; 1 under total internal
        reflection.

    Notes
    -----
    Note 5 of [GargNayar2007] writes k = sqrt(k_perp^2 + k_par^2).  For
    unpolarised light the reflectance is the *mean* of the s- and p-polarised
    reflectances, k = (k_s + k_p) / 2, which is what is computed here.  The
    reciprocity k(q, 1/mu) = k(i, mu) used to derive Eq. (9) holds for this form.
    """
    i = np.asarray(incidence_rad, dtype=float)
    mu = np.asarray(mu, dtype=float)
    cos_i = np.cos(i)
    sin_t = np.sin(i) / mu
    tir = sin_t >= 1.0
    cos_t = np.sqrt(np.clip(1.0 - sin_t ** 2, 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = ((cos_i - mu * cos_t) / (cos_i + mu * cos_t)) ** 2
        rp = ((mu * cos_i - cos_t) / (mu * cos_i + cos_t)) ** 2
    k = 0.5 * (rs + rp)
    return np.where(tir, 1.0, np.nan_to_num(k, nan=1.0))


def refraction_angle(incidence_rad, mu):
    """Snell's law: the angle of refraction q = asin(sin(i) / mu) [rad] (the q of Eqs. (7)-(13) [GargNayar2007]; [BornWolf1999]).

    Parameters
    ----------
    incidence_rad : array_like
        Angle of incidence [rad].
    mu : float
        Relative refractive index [-].
    """
    return np.arcsin(np.clip(np.sin(np.asarray(incidence_rad, dtype=float)) / mu, -1.0, 1.0))


def incidence_angle(theta_n, alpha=0.0):
    """Angle of incidence of the camera ray, i = pi - theta_n + alpha (Eqs. 8, 12) [rad].

    Parameters
    ----------
    theta_n : array_like
        Polar angle of the surface normal [rad] (pi at the centre of the drop's image).
    alpha : float or array_like
        Angle between the camera ray and the optical axis, signed in the plane of
        the normal [rad].
    """
    return np.pi - np.asarray(theta_n, dtype=float) + alpha


def image_radius(theta_n, *, radius_m, z_m, focal_length_px):
    """Eq. (6) [GargNayar2007]: image distance rho = (f / z) a sin(theta_n) [px].

    Parameters
    ----------
    theta_n : array_like
        Polar angle of the surface normal [rad].
    radius_m : float
        Drop radius a [m].
    z_m : float
        Distance of the drop from the camera [m].
    focal_length_px : float
        Effective focal length f [px].

    Notes
    -----
    The text prints "rho = (f/z), a sin theta_n"; the comma is a typesetting
    slip for the product (f / z) a sin(theta_n).
    """
    return focal_length_px / z_m * radius_m * np.sin(np.asarray(theta_n, dtype=float))


# --------------------------------------------------------------------------------------
# Geometric mappings (Eqs. 7, 10, 12)
# --------------------------------------------------------------------------------------

def refraction_mapping(theta_n, phi_n, *, alpha=0.0, mu=MU_WATER):
    """Eq. (7) [GargNayar2007]: scene direction r of the ray refracted through the drop.

    theta_r = 2 (pi - theta_n) + alpha - 2 asin(sin(theta_n - alpha) / mu),
    phi_r = pi + phi_n.

    Parameters
    ----------
    theta_n, phi_n : array_like
        Surface normal at the image point [rad].
    alpha : float or array_like
        Angle of the camera ray from the optical axis [rad] (0: orthographic).
    mu : float
        Refractive index of the drop [-].

    Returns
    -------
    (theta_r, phi_r) : tuple of ndarray
        Signed planar polar angle and azimuth of r [rad] (see module notes).
    """
    theta_n = np.asarray(theta_n, dtype=float)
    theta_r = (2.0 * (np.pi - theta_n) + alpha
               - 2.0 * np.arcsin(np.clip(np.sin(theta_n - alpha) / mu, -1.0, 1.0)))
    return theta_r, np.pi + np.asarray(phi_n, dtype=float)


def refraction_exit_point(theta_n, phi_n, *, alpha=0.0, mu=MU_WATER):
    """Where the refracted ray of Eq. (7) leaves the drop, on the unit sphere (..., 3).

    In triangle OAB of Fig. 20(a) [GargNayar2007] the chord inside the drop
    subtends the central angle pi - 2q, so the exit point lies at the signed
    polar angle theta_n - pi + 2q in the plane of incidence (azimuth phi_n),
    with i = pi - theta_n + alpha and q = asin(sin(i) / mu).

    Parameters
    ----------
    theta_n, phi_n : array_like
        Surface normal at the entry point [rad].
    alpha : float or array_like
        Angle of the camera ray from the optical axis [rad].
    mu : float
        Refractive index of the drop [-].

    Returns
    -------
    ndarray (..., 3)
        Exit point divided by the drop radius [-].

    Notes
    -----
    Eq. (7) gives only the direction of the scene ray; the paper treats the
    scene as distant, so the ray is taken to leave from the drop's centre.  For a
    scene a few drop radii away (Fig. 6: an acrylic ball of radius 0.875 in,
    6 in in front of a checkerboard) this assumption alone moves the predicted
    corners by about 2-4 % of the ball's image diameter; starting the ray of
    Eq. (7) at this exit point (and giving each camera ray its own alpha) removes
    the error.
    """
    i = incidence_angle(theta_n, alpha)
    q = refraction_angle(i, mu)
    return direction(np.asarray(theta_n, dtype=float) - np.pi + 2.0 * q, phi_n)


def specular_mapping(theta_n, phi_n, *, alpha=0.0):
    """Eq. (10) [GargNayar2007]: direction s of the specularly reflected scene ray.

    theta_s = 2 theta_n - pi - alpha, phi_s = phi_n.

    Parameters
    ----------
    theta_n, phi_n : array_like
        Surface normal [rad].
    alpha : float or array_like
        Angle of the camera ray from the optical axis [rad].
    """
    return 2.0 * np.asarray(theta_n, dtype=float) - np.pi - alpha, np.asarray(phi_n, dtype=float)


def internal_reflection_mapping(theta_n, phi_n, *, n_reflections, alpha=0.0, mu=MU_WATER):
    """Eq. (12) [GargNayar2007]: direction p of a scene ray reflected N times inside the drop.

    theta_p = 2 (i - q) + N (pi - 2 q) - alpha, phi_p = pi + phi_n,
    with i = pi - theta_n + alpha and q = asin(sin(i) / mu).

    Parameters
    ----------
    theta_n, phi_n : array_like
        Surface normal [rad].
    n_reflections : int
        Number N >= 1 of internal reflections [-].
    alpha : float or array_like
        Angle of the camera ray from the optical axis [rad].
    mu : float
        Refractive index of the drop [-].

    Notes
    -----
    The text prints phi_p = pi - phi_n.  Every refraction and internal reflection
    turns the ray the same way within the plane of incidence (Appendix 10.1(b)),
    so the exit ray lies on the far side of the axis, phi_p = pi + phi_n, as for
    Eq. (7); a 3-D ray trace confirms this (tests/test_optics.py).  The two forms
    agree only for phi_n = 0 or pi.
    """
    if int(n_reflections) < 1:
        raise ValueError(f"n_reflections must be >= 1, got {n_reflections}")
    i = incidence_angle(theta_n, alpha)
    q = refraction_angle(i, mu)
    theta_p = 2.0 * (i - q) + int(n_reflections) * (np.pi - 2.0 * q) - alpha
    return theta_p, np.pi + np.asarray(phi_n, dtype=float)


# --------------------------------------------------------------------------------------
# Radiance transfer functions (Eqs. 9, 11, 13) and composite radiance (Eq. 14)
# --------------------------------------------------------------------------------------

def transfer_refraction(incidence_rad, mu=MU_WATER):
    """Eq. (9) [GargNayar2007]: R = (1 - k(i, mu))^2.

    Parameters
    ----------
    incidence_rad : array_like
        Angle of incidence i of the camera ray [rad].
    mu : float
        Refractive index of the drop [-].

    Notes
    -----
    The factors mu^2 at entry (Eq. 8) and 1/mu^2 at exit cancel (radiance
    invariance L / n^2, Appendix 10.1(c)).
    """
    return (1.0 - fresnel_reflectance(incidence_rad, mu)) ** 2


def transfer_specular(incidence_rad, mu=MU_WATER):
    """Eq. (11) [GargNayar2007]: S = k(i, mu).

    Parameters
    ----------
    incidence_rad : array_like
        Angle of incidence i [rad].
    mu : float
        Refractive index of the drop [-].
    """
    return fresnel_reflectance(incidence_rad, mu)


def transfer_internal(incidence_rad, mu=MU_WATER, *, n_reflections=1):
    """Eq. (13) [GargNayar2007]: P = k(i, mu)^N (1 - k(i, mu))^2.

    Parameters
    ----------
    incidence_rad : array_like
        Angle of incidence i [rad].
    mu : float
        Refractive index of the drop [-].
    n_reflections : int
        Number N >= 1 of internal reflections [-].

    Notes
    -----
    The text writes L_p = R^N S L_e(p) before giving the correct product
    k^N (1 - k)^2: N internal reflections (k each) and two refractions.
    """
    k = fresnel_reflectance(incidence_rad, mu)
    return k ** int(n_reflections) * (1.0 - k) ** 2


def direction(theta, phi):
    """Unit vector (sin theta cos phi, sin theta sin phi, cos theta) of the (signed, planar) angles of Fig. 5 [GargNayar2007] [-] -> (..., 3).

    Parameters
    ----------
    theta : array_like
        Polar angle from +z [rad]; any real value (the paper's angles are signed).
    phi : array_like
        Azimuth about z from +x towards +y [rad].
    """
    theta, phi = np.broadcast_arrays(np.asarray(theta, dtype=float), np.asarray(phi, dtype=float))
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


def angles(vec):
    """Inverse of :func:`direction`: theta = acos(z), phi = atan2(y, x) of unit vectors (Fig. 5 [GargNayar2007]) [rad].

    Parameters
    ----------
    vec : array_like, shape (..., 3)
        Unit vectors [-].

    Returns
    -------
    (theta, phi) : tuple of ndarray
        theta in [0, pi], phi in (-pi, pi] [rad].
    """
    v = np.asarray(vec, dtype=float)
    theta = np.arccos(np.clip(v[..., 2], -1.0, 1.0))
    phi = np.arctan2(v[..., 1], v[..., 0])
    return theta, phi


def composite_radiance(theta_n, phi_n, environment, *, alpha=0.0, mu=MU_WATER, n_internal=2,
                       components=("refraction", "specular", "internal")):
    """Eq. (14) [GargNayar2007]: radiance of the drop at the point with normal n.

    L(n) = R L_e(r) + S L_e(s) + sum_{N=1}^{2} P_N L_e(p_N)   (Eq. 5 with Eqs. 9, 11, 13).

    Parameters
    ----------
    theta_n, phi_n : array_like
        Surface normal [rad].
    environment : callable
        ``environment(dirs)`` -> radiance (...) or (..., C) for unit scene directions
        ``dirs`` of shape (..., 3) in the drop frame; any radiance unit (the result
        has the same unit).
    alpha : float or array_like
        Angle of the camera ray from the optical axis [rad].
    mu : float
        Refractive index of the drop [-].
    n_internal : int
        Highest number of internal reflections kept (the paper keeps 2) [-].
    components : sequence of str
        Any of "refraction", "specular", "internal".

    Returns
    -------
    ndarray
        Radiance L(n), same unit as the environment.
    """
    valid = {"refraction", "specular", "internal"}
    unknown = set(components) - valid
    if unknown:
        raise ValueError(f"unknown components {sorted(unknown)}; valid: {sorted(valid)}")
    i = incidence_angle(theta_n, alpha)

    def term(transfer, angles_):
        radiance = np.asarray(environment(direction(*angles_)), dtype=float)
        t = np.asarray(transfer, dtype=float)
        return t.reshape(t.shape + (1,) * (radiance.ndim - t.ndim)) * radiance

    total = 0.0
    if "refraction" in components:
        total = total + term(transfer_refraction(i, mu),
                             refraction_mapping(theta_n, phi_n, alpha=alpha, mu=mu))
    if "specular" in components:
        total = total + term(transfer_specular(i, mu), specular_mapping(theta_n, phi_n, alpha=alpha))
    if "internal" in components:
        for n in range(1, int(n_internal) + 1):
            total = total + term(transfer_internal(i, mu, n_reflections=n),
                                 internal_reflection_mapping(theta_n, phi_n, n_reflections=n,
                                                             alpha=alpha, mu=mu))
    return np.asarray(total, dtype=float)


# --------------------------------------------------------------------------------------
# Field of view, inversion, average brightness (Sec. 4.2.2-4.2.3)
# --------------------------------------------------------------------------------------

def normal_theta_from_refraction(theta_r, mu=MU_WATER):
    """Invert Eq. (7) with alpha = 0: the normal angle theta_n that sees scene angle theta_r.

    theta_r = 2 (i - q) rises monotonically with the incidence angle i on
    [0, pi/2] (d theta_r / d i = 2 (1 - cos i / (mu cos q)) > 0), so the inverse is
    unique; it is found by bisection.

    Parameters
    ----------
    theta_r : array_like
        Polar angle of the scene ray [rad], in [0, FOV/2].
    mu : float
        Refractive index of the drop [-].

    Returns
    -------
    ndarray
        theta_n in [pi/2, pi] [rad]; NaN where theta_r lies outside the drop's field of view.
    """
    t_in = np.asarray(theta_r, dtype=float)
    half_fov = 0.5 * drop_field_of_view(mu)
    t = np.clip(t_in, 0.0, half_fov)
    lo = np.zeros_like(t)
    hi = np.full_like(t, 0.5 * np.pi)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        f = 2.0 * (mid - refraction_angle(mid, mu))
        below = f < t
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    i = 0.5 * (lo + hi)
    bad = (t_in < -1e-12) | (t_in > half_fov + 1e-12) | ~np.isfinite(t_in)
    return np.where(bad, np.nan, np.pi - i)


def drop_field_of_view(mu=MU_WATER):
    """Full field of view of a drop seen by refraction (Sec. 4.2.2 [GargNayar2007]) [rad].

    The largest theta_r of Eq. (7) (alpha = 0) occurs at grazing incidence
    i = pi/2: theta_r,max = pi - 2 asin(1/mu); the field of view is twice that
    (about 165 degrees for water, mu = 1.333).

    Parameters
    ----------
    mu : float
        Refractive index of the drop [-].

    Notes
    -----
    The text takes the maximum "over all possible angles 0 <= theta_n <= 90 deg";
    with its own frame (z away from the camera, i = pi - theta_n) the visible
    normals are pi/2 <= theta_n <= pi, i.e. incidence angles 0 to 90 deg, which is
    what is meant.  For mu > sqrt(2) the field exceeds 180 deg (acrylic,
    mu = 1.49: 191 deg): such a ball sees slightly behind itself.
    """
    return 2.0 * (np.pi - 2.0 * np.arcsin(1.0 / mu))


def mean_transfer(mu=MU_WATER, *, component="refraction", n_samples=20001):
    """Average of a transfer function over the drop's image, uniform environment (L_e = 1).

    With Eq. (6) the image disc is rho = sin(i) (normalised), so the area element is
    sin(i) cos(i) di dphi and the disc average of T(i) is 2 int_0^{pi/2} T sin i cos i di.
    For refraction (Eq. 9) this is the fraction of the incident radiance a drop
    transmits to the camera: 0.94 for water ("transmits 94%", Sec. 4.2.1
    [GargNayar2007]).

    Parameters
    ----------
    mu : float
        Refractive index [-].
    component : str
        "refraction" (R), "specular" (S), "internal1", "internal2" (P with N = 1, 2),
        "total" (R + S + P1 + P2, Eq. 14), or "interface" (1 - k: the light that
        crosses one air-water surface, Eq. 8 without the mu^2 factor) [-].
    n_samples : int
        Quadrature points [-].

    Notes
    -----
    Sec. 4.2.1 says a drop "transmits 94% of the incident radiance" and Sec. 4.2.3
    that refracted light "is only attenuated by 6%".  The disc average of the
    single-surface transmission 1 - k is 0.934 for water, which matches those
    figures; the disc average of R = (1 - k)^2 (both surfaces, Eq. 9) is 0.881.
    """
    funcs = {
        "refraction": lambda i: transfer_refraction(i, mu),
        "specular": lambda i: transfer_specular(i, mu),
        "internal1": lambda i: transfer_internal(i, mu, n_reflections=1),
        "internal2": lambda i: transfer_internal(i, mu, n_reflections=2),
    }
    parts = dict(funcs)
    funcs["total"] = lambda i: sum(f(i) for f in parts.values())
    funcs["interface"] = lambda i: 1.0 - fresnel_reflectance(i, mu)
    if component not in funcs:
        raise ValueError(f"unknown component {component!r}; valid: {sorted(funcs)}")
    i = np.linspace(0.0, 0.5 * np.pi, int(n_samples))
    w = np.sin(i) * np.cos(i)
    return float(2.0 * np.trapezoid(funcs[component](i) * w, i))


def refraction_share(mu=MU_WATER):
    """Share of a drop's radiance due to refraction, uniform environment, Eq. (14) [-].

    Ratio of the disc averages of R and of R + S + P1 + P2 (see :func:`mean_transfer`).
    Sec. 4.2.1 [GargNayar2007]: "the radiance of the drop is mainly due to the refraction".

    Parameters
    ----------
    mu : float
        Refractive index [-].
    """
    return mean_transfer(mu, component="refraction") / mean_transfer(mu, component="total")
