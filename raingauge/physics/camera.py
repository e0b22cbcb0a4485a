"""Camera geometry for rain: projection, image velocity, defocus, depth of field.

Camera frame: x right, y down, z forward along the optical axis [m]; image
coordinates (u, v) = (column, row) in pixels with the principal point at
(cx, cy).  The focal length ``f`` is in pixels, as in [GargNayar2007]; where a
physical aperture is needed the metric focal length is f_m = f * pixel_pitch.

Contents: :func:`project`, :func:`back_project`, :func:`image_velocity_px_s`,
:func:`blur_circle_px` (thin lens), :func:`depth_of_field_m`,
:func:`z_m` (= 2 f a), :func:`streak_width_px` (Eq. 26 as corrected),
:func:`streak_length_px`, :func:`rain_visible_distance_m` (the rain-visible
region R z_m of Sec. 6.1).
"""

from __future__ import annotations

import math

import numpy as np

from raingauge.physics._checks import positive as _positive


def _depth(z_m) -> np.ndarray:
    """Depths [m] as an array, NaN where z <= 0 (behind the camera)."""
    z = np.asarray(z_m, dtype=float)
    return np.where(z > 0, z, np.nan)


def _thin_lens(focal_length_px, f_number, focus_distance_m, pixel_pitch_m) -> tuple[float, float, float, float]:
    """Checked (f_m [m], N [-], z0 [m], p [m]) of a thin lens focused beyond its focal length."""
    f = _positive("focal_length_px", focal_length_px)
    n = _positive("f_number", f_number)
    z0 = _positive("focus_distance_m", focus_distance_m)
    p = _positive("pixel_pitch_m", pixel_pitch_m)
    fm = f * p
    if z0 <= fm:
        raise ValueError(f"focus_distance_m ({z0} m) must exceed the focal length ({fm} m)")
    return fm, n, z0, p


def project(points_m, *, focal_length_px: float, principal_point_px) -> np.ndarray:
    """Pinhole projection, u = cx + f x / z, v = cy + f y / z [px] (perspective projection of Appendix 10.2 [GargNayar2007]; [Horn1986]).

    Parameters
    ----------
    points_m : array_like, shape (..., 3)
        Points (x, y, z) in the camera frame [m].
    focal_length_px : float
        Focal length f [px].
    principal_point_px : array_like, shape (2,)
        (cx, cy) [px].

    Returns
    -------
    ndarray, shape (..., 2)
        (u, v) [px]; NaN for points with z <= 0 (behind the camera).
    """
    p = np.asarray(points_m, dtype=float)
    if p.shape[-1] != 3:
        raise ValueError(f"points_m must have shape (..., 3), got {p.shape}")
    f = _positive("focal_length_px", focal_length_px)
    c = np.asarray(principal_point_px, dtype=float)
    zz = _depth(p[..., 2])
    u = c[0] + f * p[..., 0] / zz
    v = c[1] + f * p[..., 1] / zz
    return np.stack([u, v], axis=-1)


def back_project(pixels_px, z_m, *, focal_length_px: float, principal_point_px) -> np.ndarray:
    """Inverse of :func:`project` at a known depth: x = (u - cx) z / f, y = (v - cy) z / f [m] ([Horn1986]).

    Parameters
    ----------
    pixels_px : array_like, shape (..., 2)
        (u, v) [px].
    z_m : array_like
        Depth z [m], broadcast against ``pixels_px[..., 0]``.
    focal_length_px : float
        Focal length f [px].
    principal_point_px : array_like, shape (2,)
        (cx, cy) [px].

    Returns
    -------
    ndarray, shape (..., 3)
        Points (x, y, z) [m].
    """
    q = np.asarray(pixels_px, dtype=float)
    f = _positive("focal_length_px", focal_length_px)
    c = np.asarray(principal_point_px, dtype=float)
    z = np.broadcast_to(np.asarray(z_m, dtype=float), q.shape[:-1])
    return np.stack([(q[..., 0] - c[0]) * z / f, (q[..., 1] - c[1]) * z / f, z], axis=-1)


def image_velocity_px_s(points_m, velocity_m_s, *, focal_length_px: float) -> np.ndarray:
    """Image-plane velocity of a moving point, d(u, v)/dt [px/s].

    du/dt = f (vx z - x vz) / z^2, dv/dt = f (vy z - y vz) / z^2.  For a drop
    falling straight down (velocity (0, v, 0)) this is f v / z, the v_i of
    Appendix 10.2 [GargNayar2007].

    Parameters
    ----------
    points_m : array_like, shape (..., 3)
        Positions [m] (z > 0).
    velocity_m_s : array_like, shape (..., 3)
        Velocities [m/s] in the camera frame (y down: a falling drop has vy > 0).
    focal_length_px : float
        Focal length f [px].

    Returns
    -------
    ndarray, shape (..., 2)
        (du/dt, dv/dt) [px/s]; NaN where z <= 0.
    """
    p = np.asarray(points_m, dtype=float)
    w = np.asarray(velocity_m_s, dtype=float)
    f = _positive("focal_length_px", focal_length_px)
    p, w = np.broadcast_arrays(p, w)
    z = _depth(p[..., 2])
    du = f * (w[..., 0] * z - p[..., 0] * w[..., 2]) / z ** 2
    dv = f * (w[..., 1] * z - p[..., 1] * w[..., 2]) / z ** 2
    return np.stack([du, dv], axis=-1)


def blur_circle_px(z_m, *, focal_length_px: float, f_number: float, focus_distance_m: float,
                   pixel_pitch_m: float) -> np.ndarray:
    """Diameter of the defocus blur circle of a point at depth z, thin lens [Horn1986].

    b_c = (f_m / N) * f_m |z - z0| / (z (z0 - f_m)) / p    [px],

    with f_m = f p the metric focal length, N the F-number (aperture
    diameter f_m / N) and z0 the focus distance.  This is the b_c of
    Eqs. (23)-(26) [GargNayar2007].

    Parameters
    ----------
    z_m : array_like
        Depth of the point [m] (> 0).
    focal_length_px : float
        Focal length f [px].
    f_number : float
        F-number N [-].
    focus_distance_m : float
        Focus distance z0 [m] (> f_m).
    pixel_pitch_m : float
        Pixel pitch p [m].

    Returns
    -------
    ndarray
        Blur-circle diameter [px]; 0 at z = z0; NaN for z <= 0.
    """
    fm, n, z0, p = _thin_lens(focal_length_px, f_number, focus_distance_m, pixel_pitch_m)
    zz = _depth(z_m)
    return (fm / n) * fm * np.abs(zz - z0) / (zz * (z0 - fm)) / p


def depth_of_field_m(*, focal_length_px: float, f_number: float, focus_distance_m: float,
                     pixel_pitch_m: float, coc_px: float = 1.0) -> tuple[float, float]:
    """Near and far limits of the depth of field, thin lens [Horn1986]: where the blur circle equals ``coc_px`` [m].

    With K = f_m^2 / (N p (z0 - f_m)) [px] (so that b_c = K |z - z0| / z):
    near = K z0 / (K + c), far = K z0 / (K - c) (infinite when K <= c, i.e.
    focused beyond the hyperfocal distance).

    Parameters
    ----------
    focal_length_px : float
        Focal length f [px].
    f_number : float
        F-number N [-].
    focus_distance_m : float
        Focus distance z0 [m].
    pixel_pitch_m : float
        Pixel pitch p [m].
    coc_px : float
        Acceptable blur-circle diameter c [px] (default one pixel).

    Returns
    -------
    (near, far) : tuple of float
        Depths [m]; ``far`` may be ``inf``.
    """
    fm, n, z0, p = _thin_lens(focal_length_px, f_number, focus_distance_m, pixel_pitch_m)
    c = _positive("coc_px", coc_px)
    k = fm * fm / (n * p * (z0 - fm))
    near = k * z0 / (k + c)
    far = k * z0 / (k - c) if k > c else math.inf
    return float(near), float(far)


def z_m(radius_m, *, focal_length_px: float) -> np.ndarray:
    """Distance below which a drop images wider than one pixel, z_m = 2 f a [GargNayar2007, Sec. 6.1].

    Parameters
    ----------
    radius_m : array_like
        Drop radius a [m].
    focal_length_px : float
        Focal length f [px].

    Returns
    -------
    ndarray
        z_m [m].
    """
    f = _positive("focal_length_px", focal_length_px)
    return 2.0 * f * np.asarray(radius_m, dtype=float)


def streak_width_px(radius_m, z_m, *, focal_length_px: float) -> np.ndarray:
    """Width of a focused streak, w(z) = max(2 f a / z, 1) [px] (Eq. 26 [GargNayar2007]).

    Parameters
    ----------
    radius_m : array_like
        Drop radius a [m].
    z_m : array_like
        Depth z [m] (> 0).
    focal_length_px : float
        Focal length f [px].

    Returns
    -------
    ndarray
        Width [px] (>= 1); NaN for z <= 0.

    Notes
    -----
    The text of Eq. (26) prints w(z) = max(f z / a, 1); the image diameter of
    a drop of radius a at depth z is 2 f a / z, which reaches one pixel at
    z = z_m = 2 f a, consistent with Sec. 6.1.
    """
    f = _positive("focal_length_px", focal_length_px)
    zz = _depth(z_m)
    return np.maximum(2.0 * f * np.asarray(radius_m, dtype=float) / zz, 1.0)


def streak_length_px(speed_m_s, z_m, exposure_s: float, *, focal_length_px: float,
                     radius_m=0.0) -> np.ndarray:
    """Length of a vertical streak, l = f v T / z + 2 f a / z [px] (v_i T of Appendix 10.2 and Eq. (23) [GargNayar2007], plus the drop's image).

    Parameters
    ----------
    speed_m_s : array_like
        Speed of the drop across the line of sight [m/s].
    z_m : array_like
        Depth [m] (> 0).
    exposure_s : float
        Exposure time T [s].
    focal_length_px : float
        Focal length f [px].
    radius_m : array_like
        Drop radius a [m] (0 gives the motion length alone).
    """
    f = _positive("focal_length_px", focal_length_px)
    zz = _depth(z_m)
    return f * (np.asarray(speed_m_s, dtype=float) * exposure_s
                + 2.0 * np.asarray(radius_m, dtype=float)) / zz


def rain_visible_distance_m(radius_m, velocity_m_s, *, focal_length_px: float, exposure_s: float,
                            contrast_dn: float, threshold_dn: float) -> np.ndarray:
    """Far edge of the rain-visible region, R z_m [GargNayar2007, Sec. 6.1, Fig. 13].

    A drop nearer than z_m = 2 f a changes a pixel by
    dI = (tau / T) dL with tau = 2 a / v (Eq. 21); beyond z_m the change falls
    as dI (z_m / z) (Eq. 22).  It is detectable while dI >= ``threshold_dn``,
    i.e. out to R z_m with R = (2 a / (v T)) dL / threshold.

    Parameters
    ----------
    radius_m : array_like
        Drop radius a [m].
    velocity_m_s : array_like
        Fall speed v [m/s].
    focal_length_px : float
        Focal length f [px].
    exposure_s : float
        Exposure time T [s].
    contrast_dn : float
        k0 (L_r - L_b), the change a drop would cause if it covered the pixel
        for the whole exposure [gray levels].
    threshold_dn : float
        Smallest detectable change [gray levels] (e.g. 3 sigma of sensor noise).

    Returns
    -------
    ndarray
        R z_m [m]; 0 where even drops nearer than z_m are not detectable (R < 1).

    Notes
    -----
    tau / T is capped at 1 (a drop cannot cover a pixel for longer than the
    exposure).  The paper leaves R as "a constant that depends on the scene
    brightness and camera sensitivity"; this function makes it explicit.
    """
    f = _positive("focal_length_px", focal_length_px)
    t = _positive("exposure_s", exposure_s)
    thr = _positive("threshold_dn", threshold_dn)
    a = np.asarray(radius_m, dtype=float)
    v = np.asarray(velocity_m_s, dtype=float)
    frac = np.minimum(2.0 * a / (v * t), 1.0)
    r = frac * abs(float(contrast_dn)) / thr
    return np.where(r >= 1.0, r * 2.0 * f * a, 0.0)
