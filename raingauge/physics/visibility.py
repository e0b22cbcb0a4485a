"""Visibility of rain and camera parameters: Eqs. (20)-(27) [GargNayar2007].

How exposure time T, F-number N and focus distance z0 change what rain does
to the intensity of a pixel watching a static scene (Sec. 6):

- Eq. (20): image intensity and the exposure factor k0 = k pi T / (4 N^2);
- Eqs. (21)-(22): intensity change of a focused drop near (z < z_m = 2 f a)
  and far (z > z_m) from the camera;
- Eqs. (23)-(24): the same change spread over a defocused streak;
- Eqs. (25)-(26), (31): variance added by a thin layer of rain;
- Eq. (27), (33): the standard deviation sigma_r produced by a volume of rain,
  integrated over depth up to the rain-visible limit z = R z_m, for a single
  drop size or over a drop size distribution.

The depth integral G(f, N, z0) of Eq. (33) is given both numerically
(:func:`visibility_g` with ``method="numerical"``, quadrature of Eq. (26) with
the camera's blur circle and streak width) and in closed form
(``method="closed_form"``, and the three cases of the paper in
:func:`visibility_g_cases`), derived afresh because Appendix 10.3(c) of the
source text is garbled.

Derivation of the closed form
-----------------------------
With the thin lens, the blur circle of a point at depth z when focused at z0
is b_c(z) = K |z - z0| / z pixels, K = H / z0 (z0 >> f_m) where
H = f_px^2 p / N is the hyperfocal distance for a one-pixel circle of
confusion (f_px focal length in pixels, p pixel pitch).  The exact thin lens
has K = f_px (f_m / N) / (z0 - f_m); K is taken from the blur-circle function
itself so both routes use the same optics.  With the focused width
w(z) = max(z_m / z, 1), z_m = 2 f a, the integrand of Eq. (33),
f / (z (w + |b_c|)), has a denominator linear in z on each piece::

    near (z < z_m), z < z0:  X(z)  = z_m + H (1 - z / z0)
    near (z < z_m), z > z0:  X'(z) = z_m - H (1 - z / z0)
    far  (z > z_m), z < z0:  Y(z)  = (1 - H / z0) z + H
    far  (z > z_m), z > z0:  Y'(z) = (1 + H / z0) z - H

and each piece integrates to a logarithm, f / alpha ln(D(z2) / D(z1)) for
D = alpha z + beta (or f (z2 - z1) / beta when alpha = 0, i.e. H = z0).
With z1 the nearest depth considered and R z_m the rain-visible limit:

Case 1, z0 > R z_m::

    G = f z0 / H ln(X(z1) / X(z_m)) + f / (1 - H/z0) ln(Y(R z_m) / Y(z_m))

Case 2, z_m < z0 < R z_m::

    G = f z0 / H ln(X(z1) / X(z_m)) + f / (1 - H/z0) ln(z0 / Y(z_m))
        + f / (1 + H/z0) ln(Y'(R z_m) / z0)

Case 3, z1 < z0 < z_m::

    G = f z0 / H ln(X(z1) / z_m) + f z0 / H ln(X'(z_m) / z_m)
        + f / (1 + H/z0) ln(Y'(R z_m) / Y'(z_m))

(Case 4, z0 < z1, is case 3 without its first term and with X'(z1) in place
of z_m in the second; it is covered by :func:`visibility_g`.)

Notes
-----
- Eq. (26) as printed has w(z) = max(f z / a, 1); the focused streak width is
  w(z) = max(2 f a / z, 1) pixels (the drop's image diameter, at least one
  pixel), which is what Eqs. (21)-(24) need.
- Substituting Eqs. (21)/(22), (24) and (31) into Eq. (25) gives the constant
  16 a^4, not the printed 4 a^4 of Eqs. (26) and (33): near the camera
  n w^d dI_d^2 = rho (z/f) v T (z_m/z)^2 / (w + b_c) (k0 2a/(vT) dL)^2
  = k0^2 dL^2 16 a^4 rho f / (v T z (w + b_c)), and the far region gives the
  same.  A constant factor only scales sigma_r; it cancels in every ratio
  (reduction factor) the advisor reports.
- Eq. (35) as printed carries a spurious square root and ln z0 / Y'(2fa) for
  ln Y'(2Rfa) / z0; Eq. (36) repeats a term; the H of Eq. (34) reads
  "f^2 p / F", i.e. H = f^2 p / N, the hyperfocal distance with a one-pixel
  circle of confusion.  The closed forms above are derived from Eq. (26) and
  agree with its numerical integral (see the tests).
- The rain-visible limit R z_m (Sec. 6.1, note 20) is taken with a constant R
  (the paper: "R depends on the brightness of the scene and camera
  sensitivity"), which is what makes sigma_r fall exactly as 1/sqrt(T)
  (Fig. 15(a)).  :data:`R_VISIBLE` = 3 with the reference radius
  :data:`A_REF_M` = 0.5 mm puts the limit at R z_m = 24 m for the Canon XL1 at
  f = 8000 px, the figure of the paper's note 27.
- sigma_r is returned in units of the drop contrast k0 (L_r - L_b) (pass
  ``contrast`` in gray levels for an absolute value).
"""

from __future__ import annotations

import math

import numpy as np

from raingauge.physics import camera as _camera
from raingauge.physics._checks import positive

__all__ = [
    "A_REF_M",
    "R_VISIBLE",
    "Z_NEAR_M",
    "G_METHODS",
    "image_intensity",
    "exposure_factor",
    "gain_for_brightness",
    "residence_time_s",
    "delta_i_near",
    "delta_i_far",
    "delta_i_focused",
    "delta_i_defocused",
    "mean_drops_per_pixel",
    "layer_variance_density",
    "rain_visible_limit_m",
    "visibility_g",
    "visibility_g_cases",
    "sigma_r",
]

#: Reference drop radius [m] for single-size predictions: the smallest drop
#: that matters, a_min of Sec. 8.
A_REF_M = 0.5e-3
#: Rain-visible region 0 < z < R z_m (Sec. 6.1, note 20).
R_VISIBLE = 3.0
#: Nearest depth [m] of the depth integral (drops closer than this, e.g.
#: inside a lens hood, are ignored; they add < 1e-3 of G).
Z_NEAR_M = 0.1
#: Ways to evaluate G(f, N, z0).
G_METHODS = ("closed_form", "numerical")


# --------------------------------------------------------------------- Eq. 20
def exposure_factor(*, exposure_s, f_number, gain=1.0):
    """The exposure constant k0 = k pi T / (4 N^2) of Eq. (20) [GargNayar2007].

    Parameters
    ----------
    exposure_s : float or array [s]
        Exposure time T.
    f_number : float or array [-]
        Lens F-number N.
    gain : float or array [gray levels per unit radiance and second]
        Camera gain k.

    Returns
    -------
    k0 : float or ndarray [gray levels per unit radiance]
    """
    return np.asarray(gain) * math.pi / 4.0 * np.asarray(exposure_s) / np.asarray(f_number) ** 2


def image_intensity(radiance, *, exposure_s, f_number, gain=1.0):
    """Pixel intensity I = k pi/4 T/N^2 L = k0 L, Eq. (20) [GargNayar2007] [Horn1986].

    Parameters
    ----------
    radiance : float or array [radiance units]
    exposure_s : float [s]
    f_number : float [-]
    gain : float [gray levels per unit radiance and second]

    Returns
    -------
    intensity : float or ndarray [gray levels] (linear camera)
    """
    return exposure_factor(exposure_s=exposure_s, f_number=f_number, gain=gain) * np.asarray(radiance)


def gain_for_brightness(k0, *, exposure_s, f_number):
    """Gain k = 4 N^2 k0 / (pi T) that keeps the image brightness k0 L fixed (Eq. 20).

    Parameters
    ----------
    k0 : float [gray levels per unit radiance]
        The brightness constant to keep.
    exposure_s : float or array [s]
    f_number : float or array [-]

    Returns
    -------
    gain : float or ndarray [gray levels per unit radiance and second]
    """
    return 4.0 * np.asarray(f_number) ** 2 * np.asarray(k0) / (math.pi * np.asarray(exposure_s))


# -------------------------------------------------------------- Eqs. 21-22
def residence_time_s(radius_m, velocity_m_s):
    """Time tau = 2 a / v a drop near the camera covers a pixel (Sec. 6.1) [GargNayar2007].

    Parameters
    ----------
    radius_m : float or array [m]
    velocity_m_s : float or array [m/s]

    Returns
    -------
    tau : float or ndarray [s]
    """
    return 2.0 * np.asarray(radius_m, dtype=float) / np.asarray(velocity_m_s, dtype=float)


def delta_i_near(radius_m, *, velocity_m_s, exposure_s, contrast=1.0):
    """Intensity change of a focused drop with z < z_m, Eq. (21) [GargNayar2007].

    dI = k0 (tau / T) (L_r - L_b), tau = 2 a / v; independent of depth.

    Parameters
    ----------
    radius_m : float or array [m]
    velocity_m_s : float or array [m/s]
    exposure_s : float [s]
    contrast : float [gray levels]
        k0 (L_r - L_b): the intensity change of a drop covering the pixel for
        the whole exposure.

    Returns
    -------
    dI : float or ndarray [same unit as ``contrast``]
    """
    return contrast * residence_time_s(radius_m, velocity_m_s) / exposure_s


def delta_i_far(radius_m, z_m, *, velocity_m_s, exposure_s, focal_length_px, contrast=1.0):
    """Intensity change of a focused drop with z > z_m, Eq. (22) [GargNayar2007].

    dI = k0 4 f a^2 / (z v T) (L_r - L_b): the drop's image, taken as its
    bounding square (2 f a / z)^2 as in the paper, covers that fraction of the
    pixel for tau = z / (f v) (Appendix 10.3(a)); equals Eq. (21) at
    z = z_m = 2 f a.

    Parameters
    ----------
    radius_m : float or array [m]
    z_m : float or array [m]
        Depth of the drop.
    velocity_m_s : float or array [m/s]
    exposure_s : float [s]
    focal_length_px : float [px]
    contrast : float [gray levels]

    Returns
    -------
    dI : float or ndarray

    Notes
    -----
    The image of a far drop is a disc of area pi (f a / z)^2, pi/4 of the
    square the paper's 4 f a^2 stands for; a renderer that draws discs (the
    simulator) shows pi/4 of this change (tests/test_visibility.py).
    """
    a = np.asarray(radius_m, dtype=float)
    return contrast * 4.0 * focal_length_px * a**2 / (np.asarray(z_m) * velocity_m_s * exposure_s)


def delta_i_focused(radius_m, z_m, *, velocity_m_s, exposure_s, focal_length_px, contrast=1.0):
    """Eq. (21) for z <= z_m = 2 f a and Eq. (22) beyond [GargNayar2007].

    Parameters
    ----------
    radius_m : float or array [m]
    z_m : float or array [m]
        Depth of the drop.
    velocity_m_s : float or array [m/s]
    exposure_s : float [s]
    focal_length_px : float [px]
    contrast : float [gray levels]

    Returns
    -------
    dI : float or ndarray [same unit as ``contrast``]
    """
    a = np.asarray(radius_m, dtype=float)
    z = np.asarray(z_m, dtype=float)
    near = delta_i_near(a, velocity_m_s=velocity_m_s, exposure_s=exposure_s, contrast=contrast)
    far = delta_i_far(a, z, velocity_m_s=velocity_m_s, exposure_s=exposure_s,
                      focal_length_px=focal_length_px, contrast=contrast)
    return np.where(z <= 2.0 * focal_length_px * a, near, far)


# -------------------------------------------------------------- Eqs. 23-24
def delta_i_defocused(delta_i, *, width_px, blur_px, streak_length_px=None):
    """Intensity change of a defocused streak, Eqs. (23)-(24) [GargNayar2007].

    Defocus spreads the focused change uniformly over the defocused streak:
    Eq. (23) dI_d = w l / ((w + b_c)(l + b_c)) dI with the streak length
    l = v_i T; when ``streak_length_px`` is None, l >> b_c and Eq. (24)
    dI_d = w / (w + b_c) dI.

    Parameters
    ----------
    delta_i : float or array [gray levels]
        Change of the focused streak (Eqs. 21-22).
    width_px : float or array [px]
        Focused streak width w (>= 1; for far drops w = 1 since Eq. (22)
        already accounts for partial coverage, note 22).
    blur_px : float or array [px]
        Blur-circle diameter b_c.
    streak_length_px : float or array [px], optional
        v_i T, the length of the motion-blurred streak.

    Returns
    -------
    dI_d : float or ndarray
    """
    w = np.asarray(width_px, dtype=float)
    b = np.abs(np.asarray(blur_px, dtype=float))
    out = np.asarray(delta_i) * w / (w + b)
    if streak_length_px is not None:
        length = np.asarray(streak_length_px, dtype=float)
        out = out * length / (length + b)
    return out


# -------------------------------------------------------------- Eqs. 25-26, 31
def mean_drops_per_pixel(density_m3, z_m, dz_m, *, velocity_m_s, exposure_s, focal_length_px):
    """Mean number of drops of a layer crossing a pixel in one exposure, Eq. (31) [GargNayar2007].

    n = rho (z / f) v T dz (the pixel's footprint z/f by the fall v T by dz).

    Parameters
    ----------
    density_m3 : float or array [m^-3]
    z_m : float or array [m]
    dz_m : float or array [m]
        Layer thickness.
    velocity_m_s : float or array [m/s]
    exposure_s : float [s]
    focal_length_px : float [px]

    Returns
    -------
    n : float or ndarray [-]
    """
    return np.asarray(density_m3) * np.asarray(z_m) / focal_length_px * velocity_m_s * exposure_s * np.asarray(dz_m)


def _blur_k(*, focal_length_px, f_number, focus_distance_m, pixel_pitch_m):
    """K in b_c(z) = K |z - z0| / z, read off the camera's blur-circle function [px]."""
    z0 = float(focus_distance_m)
    b = _camera.blur_circle_px(2.0 * z0, focal_length_px=focal_length_px, f_number=f_number,
                               focus_distance_m=z0, pixel_pitch_m=pixel_pitch_m)
    return 2.0 * float(b)


def layer_variance_density(z_m, *, radius_m, density_m3, velocity_m_s, exposure_s,
                           focal_length_px, f_number, focus_distance_m, pixel_pitch_m,
                           contrast=1.0):
    """Variance per metre of depth from a layer of rain at z, Eqs. (25)-(26) [GargNayar2007].

    sigma^2(z) = n(z) w^d(z) dI_d(z)^2 / dz with n from Eq. (31),
    w^d = w + |b_c| and dI_d from Eqs. (21)/(22) and (24); equals
    contrast^2 16 a^4 rho f / (v T z (w + |b_c|)).  Computed here from its
    parts, not from the assembled formula.

    Parameters
    ----------
    z_m : float or array [m]
        Depth of the layer.
    radius_m : float [m]
    density_m3 : float [m^-3]
        Number of drops of this size per cubic metre.
    velocity_m_s : float [m/s]
    exposure_s : float [s]
    focal_length_px : float [px]
    f_number : float [-]
    focus_distance_m : float [m]
    pixel_pitch_m : float [m]
    contrast : float [gray levels]

    Returns
    -------
    dsigma2_dz : float or ndarray [contrast^2 / m]

    Notes
    -----
    The width is w(z) = max(2 f a / z, 1) (the printed max(f z / a, 1) is a
    slip); for z > z_m Eq. (22) is used with w = 1 (note 22).
    """
    z = np.asarray(z_m, dtype=float)
    f = focal_length_px
    w = _camera.streak_width_px(radius_m, z, focal_length_px=f)
    b = np.abs(_camera.blur_circle_px(z, focal_length_px=f, f_number=f_number,
                                      focus_distance_m=focus_distance_m, pixel_pitch_m=pixel_pitch_m))
    d_i = delta_i_focused(radius_m, z, velocity_m_s=velocity_m_s, exposure_s=exposure_s,
                          focal_length_px=f, contrast=contrast)
    d_i_d = delta_i_defocused(d_i, width_px=w, blur_px=b)
    n_per_m = mean_drops_per_pixel(density_m3, z, 1.0, velocity_m_s=velocity_m_s,
                                   exposure_s=exposure_s, focal_length_px=f)
    return n_per_m * (w + b) * d_i_d**2


def rain_visible_limit_m(radius_m, *, focal_length_px, r_visible=R_VISIBLE):
    """Far end R z_m = 2 R f a of the rain-visible region (Sec. 6.1, Fig. 13) [GargNayar2007].

    Parameters
    ----------
    radius_m : float or array [m]
    focal_length_px : float [px]
    r_visible : float [-]
        R; see the module Notes for the default.

    Returns
    -------
    z : float or ndarray [m]
    """
    return r_visible * _camera.z_m(radius_m, focal_length_px=focal_length_px)


# -------------------------------------------------------------------- G(f,N,z0)
def _int_inv_linear(alpha, beta, lo, hi):
    """Integral of dz / (alpha z + beta) over [lo, hi] (0 where hi <= lo), stable as alpha -> 0."""
    alpha, beta, lo, hi = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (alpha, beta, lo, hi)))
    length = np.maximum(hi - lo, 0.0)
    d_lo = alpha * lo + beta
    with np.errstate(divide="ignore", invalid="ignore"):
        u = alpha * length / d_lo
        ratio = np.where(np.abs(u) < 1e-9, 1.0 - u / 2.0, np.log1p(u) / np.where(u == 0, 1.0, u))
        out = np.where(length > 0, length / d_lo * ratio, 0.0)
    return out


def _check_g_inputs(radius_m, focal_length_px, f_number, focus_distance_m, pixel_pitch_m,
                    r_visible, z_near_m):
    a = np.asarray(radius_m, dtype=float)
    if np.any(~np.isfinite(a)) or np.any(a <= 0):
        raise ValueError(f"radius_m must be positive and finite [m], got {radius_m!r}")
    for name, value in (("focal_length_px", focal_length_px), ("f_number", f_number),
                        ("focus_distance_m", focus_distance_m), ("pixel_pitch_m", pixel_pitch_m),
                        ("r_visible", r_visible)):
        positive(name, value)
    if not (np.isfinite(z_near_m) and z_near_m >= 0):
        raise ValueError(f"z_near_m must be >= 0 [m], got {z_near_m!r}")
    if focus_distance_m <= focal_length_px * pixel_pitch_m:
        raise ValueError(
            f"focus_distance_m {focus_distance_m} m is inside the focal length "
            f"{focal_length_px * pixel_pitch_m:.4g} m; focus farther away")
    return a


def visibility_g(radius_m=A_REF_M, *, focal_length_px, f_number, focus_distance_m, pixel_pitch_m,
                 r_visible=R_VISIBLE, z_near_m=Z_NEAR_M, method="closed_form"):
    """G(f, N, z0) = integral of f dz / (z (w(z) + |b_c(z)|)), Eq. (33) [GargNayar2007].

    Integrated from ``z_near_m`` to the rain-visible limit R z_m.

    Parameters
    ----------
    radius_m : float or array [m]
        Drop radius a (sets z_m = 2 f a and the limit R z_m).
    focal_length_px : float [px]
    f_number : float [-]
    focus_distance_m : float [m]
    pixel_pitch_m : float [m]
    r_visible : float [-]
        R of the rain-visible region.
    z_near_m : float [m]
        Nearest depth included.
    method : {"closed_form", "numerical"} [-]
        ``closed_form``: the piecewise-logarithmic form (module docstring);
        ``numerical``: adaptive quadrature of the integrand built from the
        camera's blur circle and streak width (scalar radius only).

    Returns
    -------
    G : float or ndarray [-] (same shape as ``radius_m``)

    Notes
    -----
    The printed Eqs. (34)-(36) are garbled; see the module docstring.
    """
    if method not in G_METHODS:
        raise ValueError(f"unknown method {method!r}; valid: {', '.join(G_METHODS)}")
    a = _check_g_inputs(radius_m, focal_length_px, f_number, focus_distance_m, pixel_pitch_m,
                        r_visible, z_near_m)
    f = float(focal_length_px)
    z0 = float(focus_distance_m)
    zm = 2.0 * f * a
    z_far = r_visible * zm
    if method == "numerical":
        from scipy.integrate import quad

        def one(ai, zmi, zfi):
            def integrand(z):
                w = float(_camera.streak_width_px(ai, z, focal_length_px=f))
                b = abs(float(_camera.blur_circle_px(z, focal_length_px=f, f_number=f_number,
                                                     focus_distance_m=z0, pixel_pitch_m=pixel_pitch_m)))
                return f / (z * (w + b))
            lo = max(z_near_m, 1e-6)
            if zfi <= lo:
                return 0.0
            pts = sorted(p for p in (zmi, z0) if lo < p < zfi)
            edges = [lo, *pts, zfi]
            return sum(quad(integrand, e0, e1, limit=200, epsabs=0.0, epsrel=1e-10)[0]
                       for e0, e1 in zip(edges[:-1], edges[1:]))

        flat = [one(ai, zmi, zfi) for ai, zmi, zfi in zip(a.ravel(), np.ravel(zm), np.ravel(z_far))]
        out = np.asarray(flat).reshape(a.shape)
        return float(out) if out.ndim == 0 else out

    k = _blur_k(focal_length_px=f, f_number=f_number, focus_distance_m=z0, pixel_pitch_m=pixel_pitch_m)
    h = k * z0
    zn = float(z_near_m)
    # near, z < z0:  z_m + K (z0 - z)
    g = _int_inv_linear(-k, zm + h, zn, np.minimum(zm, z0))
    # near, z > z0:  z_m + K (z - z0)
    g = g + _int_inv_linear(k, zm - h, np.maximum(zn, z0), zm)
    # far, z < z0:   (1 - K) z + K z0
    g = g + _int_inv_linear(1.0 - k, h, np.maximum(zn, zm), np.minimum(z0, z_far))
    # far, z > z0:   (1 + K) z - K z0
    g = g + _int_inv_linear(1.0 + k, -h, np.maximum(np.maximum(zn, zm), z0), z_far)
    out = f * g
    return float(out) if out.ndim == 0 else out


def visibility_g_cases(radius_m=A_REF_M, *, focal_length_px, f_number, focus_distance_m,
                       pixel_pitch_m, r_visible=R_VISIBLE, z_near_m=Z_NEAR_M):
    """G(f, N, z0) by the three cases of Appendix 10.3(c), Eqs. (34)-(36) as corrected.

    Scalar radius.  Case 1: z0 > R z_m; case 2: z_m < z0 <= R z_m;
    case 3: z1 < z0 <= z_m (z1 = ``z_near_m``).  Requires z1 < z_m; raises
    ValueError for z0 <= z1 (not a case of the paper).  H = K z0 with K from
    the camera's blur circle.

    Parameters
    ----------
    radius_m : float [m]
    focal_length_px : float [px]
    f_number : float [-]
    focus_distance_m : float [m]
    pixel_pitch_m : float [m]
    r_visible : float [-]
    z_near_m : float [m]

    Returns
    -------
    G : float [-]
    """
    a = float(_check_g_inputs(radius_m, focal_length_px, f_number, focus_distance_m, pixel_pitch_m,
                              r_visible, z_near_m))
    f = float(focal_length_px)
    z0 = float(focus_distance_m)
    z1 = float(z_near_m)
    zm = 2.0 * f * a
    zr = r_visible * zm
    if not (z1 < zm and z1 < z0):
        raise ValueError(f"the paper's cases need z_near_m < z_m = {zm:g} m and < z0 = {z0:g} m")
    h = _blur_k(focal_length_px=f, f_number=f_number, focus_distance_m=z0,
                pixel_pitch_m=pixel_pitch_m) * z0

    def x(z):
        return zm + h * (1.0 - z / z0)

    def x_prime(z):
        return zm - h * (1.0 - z / z0)

    def y(z):
        return (1.0 - h / z0) * z + h

    def y_prime(z):
        return (1.0 + h / z0) * z - h

    def far_before(z_lo, z_hi):
        # f / (1 - H/z0) ln(Y(z_hi) / Y(z_lo)); f (z_hi - z_lo) / H when H = z0
        alpha = 1.0 - h / z0
        if abs(alpha) < 1e-12:
            return f * (z_hi - z_lo) / h
        return f / alpha * math.log(y(z_hi) / y(z_lo))

    if z0 > zr:  # case 1
        return f * z0 / h * math.log(x(z1) / x(zm)) + far_before(zm, zr)
    if z0 > zm:  # case 2
        return (f * z0 / h * math.log(x(z1) / x(zm)) + far_before(zm, z0)
                + f / (1.0 + h / z0) * math.log(y_prime(zr) / z0))
    # case 3
    return (f * z0 / h * math.log(x(z1) / zm) + f * z0 / h * math.log(x_prime(zm) / zm)
            + f / (1.0 + h / z0) * math.log(y_prime(zr) / y_prime(zm)))


# --------------------------------------------------------------------- Eq. 27
def _velocity(radius_m, velocity_model):
    a = np.asarray(radius_m, dtype=float)
    if callable(velocity_model):
        return np.asarray(velocity_model(a), dtype=float)
    from raingauge.physics import drops

    return np.asarray(drops.fall_velocity(2.0 * a, model=velocity_model), dtype=float)


def sigma_r(*, exposure_s, f_number, focus_distance_m, focal_length_px, pixel_pitch_m,
            radius_m=A_REF_M, density_m3=1.0, dsd=None, velocity_model="paper",
            contrast=1.0, r_visible=R_VISIBLE, z_near_m=Z_NEAR_M, n_sizes=160):
    """Standard deviation of a pixel's intensity from a volume of rain, Eq. (27) [GargNayar2007].

    Single size: sigma_r = contrast sqrt(16 a^4 rho G(f, N, z0) / (v(a) T)).
    Over a drop size distribution N(D) [m^-4]: the layers of each size add,
    sigma_r^2 = contrast^2 integral N(D) 16 a^4 G(a) / (v(a) T) dD, a = D/2,
    each size with its own z_m and rain-visible limit R z_m.

    Parameters
    ----------
    exposure_s : float [s]
    f_number : float [-]
    focus_distance_m : float [m]
    focal_length_px : float [px]
    pixel_pitch_m : float [m]
    radius_m : float [m]
        Drop radius for the single-size form (ignored when ``dsd`` is given).
    density_m3 : float [m^-3]
        Number density rho of that size.
    dsd : object, optional
        A drop size distribution (N(D) [m^-4], D [m]) with ``number_density(diameter_m) -> m^-4``,
        ``d_min_m`` and ``d_max_m`` (raingauge.physics.drops classes).
    velocity_model : str or callable
        A name of raingauge.physics.drops.FALL_VELOCITY_MODELS, or a function
        radius [m] -> velocity [m/s].  The paper's v = 200 sqrt(a) by default.
    contrast : float [gray levels]
        k0 (L_r - L_b); 1 gives sigma_r in units of the drop contrast.
    r_visible : float [-]
    z_near_m : float [m]
    n_sizes : int [-]
        Diameter nodes of the (composite Simpson) size integral.

    Returns
    -------
    sigma_r : float [contrast units]

    Notes
    -----
    The constant is 16 a^4 (the printed 4 a^4 is a slip; see the module Notes).
    """
    positive("exposure_s", exposure_s)
    geo = dict(focal_length_px=focal_length_px, f_number=f_number, focus_distance_m=focus_distance_m,
               pixel_pitch_m=pixel_pitch_m, r_visible=r_visible, z_near_m=z_near_m)
    if dsd is None:
        g = visibility_g(radius_m, **geo)
        v = float(_velocity(radius_m, velocity_model))
        var = 16.0 * radius_m**4 * density_m3 * g / (v * exposure_s)
        return float(contrast * math.sqrt(var))
    from scipy.integrate import simpson

    d_lo = max(float(dsd.d_min_m), 1e-5)
    d_hi = float(dsd.d_max_m)
    n = int(n_sizes) | 1
    diam = np.linspace(d_lo, d_hi, n)
    a = diam / 2.0
    v = _velocity(a, velocity_model)
    good = np.isfinite(v) & (v > 0)
    nd = np.where(good, np.asarray(dsd.number_density(diam), dtype=float), 0.0)
    g = visibility_g(a, **geo)
    integrand = np.where(good, nd * 16.0 * a**4 * g / np.where(good, v, 1.0), 0.0)
    var = simpson(integrand, x=diam) / exposure_s
    return float(contrast * math.sqrt(max(var, 0.0)))
