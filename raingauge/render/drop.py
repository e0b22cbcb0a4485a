"""The world in a drop: render a stationary drop from an environment map, and undo it (Fig. 7).

Sec. 4.2 [GargNayar2007].  The environment is an equirectangular image in the
camera frame (x right, y down, z forward): column ``0 .. W`` spans the longitude
``atan2(x, z)`` from -pi to pi (the image centre looks along the optical axis,
away from the camera) and row ``0 .. H`` the latitude ``asin(-y)`` from +pi/2 (up)
to -pi/2.

:func:`render_drop` draws the drop as the camera sees it along a viewing ray at
angle alpha from the optical axis, with Eq. (14) (model) or with the 3-D ray
tracer of :mod:`raingauge.render.raytrace`.  :func:`drop_to_perspective`
inverts Eq. (7): from an image of a drop it builds a near-perspective view of
the environment behind it (Sec. 4.2.2); :func:`find_drop` finds the drop's
circle when its centre and radius are not given.
"""

from __future__ import annotations

import numpy as np

from raingauge.errors import InputError
from raingauge.physics import optics

__all__ = ["equirect_directions", "sample_environment", "view_rotation", "render_drop",
           "find_drop", "drop_to_perspective", "perspective_view"]

RENDER_METHODS = ("model", "raytrace")


def equirect_directions(height: int, width: int) -> np.ndarray:
    """Unit directions (H, W, 3) of the pixel centres of an equirectangular map (camera frame)."""
    lon = ((np.arange(width) + 0.5) / width) * 2.0 * np.pi - np.pi
    lat = 0.5 * np.pi - ((np.arange(height) + 0.5) / height) * np.pi
    lon, lat = np.meshgrid(lon, lat)
    return np.stack([np.cos(lat) * np.sin(lon), -np.sin(lat), np.cos(lat) * np.cos(lon)], axis=-1)


def sample_environment(env, dirs):
    """Bilinear lookup of an equirectangular map.

    Parameters
    ----------
    env : ndarray (H, W) or (H, W, C)
        Environment radiance (any unit).
    dirs : ndarray (..., 3)
        Directions in the camera frame (need not be unit length).

    Returns
    -------
    ndarray (...) or (..., C), float
    """
    env = np.asarray(env)
    if env.ndim not in (2, 3):
        raise InputError(f"environment map must be (H, W) or (H, W, C), got shape {env.shape}")
    h, w = env.shape[:2]
    d = np.asarray(dirs, dtype=float)
    norm = np.linalg.norm(d, axis=-1)
    lon = np.arctan2(d[..., 0], d[..., 2])
    lat = np.arcsin(np.clip(-d[..., 1] / np.where(norm > 0, norm, 1.0), -1.0, 1.0))
    col = (lon + np.pi) / (2.0 * np.pi) * w - 0.5
    row = (0.5 * np.pi - lat) / np.pi * h - 0.5
    c0 = np.floor(col).astype(int)
    r0 = np.floor(row).astype(int)
    fc = col - c0
    fr = row - r0
    c1 = (c0 + 1) % w
    c0 = c0 % w
    r1 = np.clip(r0 + 1, 0, h - 1)
    r0 = np.clip(r0, 0, h - 1)
    e = env.astype(float, copy=False)
    if e.ndim == 3:
        fc = fc[..., None]
        fr = fr[..., None]
    top = e[r0, c0] * (1 - fc) + e[r0, c1] * fc
    bot = e[r1, c0] * (1 - fc) + e[r1, c1] * fc
    return top * (1 - fr) + bot * fr


def view_rotation(alpha_rad: float, azimuth_rad: float = 0.0) -> np.ndarray:
    """Rotation (3, 3) taking the drop's local frame (z along the viewing ray) to the camera frame.

    The viewing ray is ``v = (sin a cos psi, sin a sin psi, cos a)`` (Eq. 7's alpha,
    azimuth psi); the rotation is the smallest one taking +z onto v
    (footnote 4 [GargNayar2007]: align the local z-axis with the viewing ray).

    Parameters
    ----------
    alpha_rad : float
        Angle between the viewing ray and the optical axis [rad].
    azimuth_rad : float
        Azimuth of the viewing ray about the optical axis, from +x towards +y [rad].
    """
    v = np.array([np.sin(alpha_rad) * np.cos(azimuth_rad), np.sin(alpha_rad) * np.sin(azimuth_rad),
                  np.cos(alpha_rad)])
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, v)
    s = np.linalg.norm(axis)
    c = float(np.dot(z, v))
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * kx + (1 - c) * (kx @ kx)


def _disc_samples(size_px: int, supersample: int):
    """Sub-pixel sample positions (x, y) normalised by the drop radius, shape (S, M, N)."""
    s = int(supersample)
    sub = (np.arange(s) + 0.5) / s - 0.5
    half = size_px / 2.0
    grid = np.arange(size_px) + 0.5 - half
    xs, ys = [], []
    for sy in sub:
        for sx in sub:
            y, x = np.meshgrid(grid + sy, grid + sx, indexing="ij")
            xs.append(x / half)
            ys.append(y / half)
    return np.stack(xs), np.stack(ys)


def render_drop(env, *, size_px: int, alpha_rad: float = 0.0, azimuth_rad: float = 0.0,
                mu: float = optics.MU_WATER, supersample: int = 2,
                components=("refraction", "specular", "internal"), method: str = "model",
                background=0.0):
    """Appearance of a stationary spherical drop, Eq. (14) [GargNayar2007].

    Parameters
    ----------
    env : ndarray (H, W) or (H, W, C)
        Equirectangular environment radiance (camera frame, see module notes).
    size_px : int
        Side of the output image; the drop's circular image fills it (diameter) [px].
    alpha_rad, azimuth_rad : float
        Viewing ray's angle from the optical axis and its azimuth [rad].
    mu : float
        Refractive index [-].
    supersample : int
        s x s samples per pixel [-].
    components : sequence of str
        Terms of Eq. (14) to include ("refraction", "specular", "internal").
    method : str
        "model" (Eqs. 7-14) or "raytrace" (3-D vector ray tracer).
    background : float or array
        Radiance outside the drop's disc.

    Returns
    -------
    (image, coverage) : float32 (M, N[, C]) radiance and float32 (M, N) fraction of each
        pixel covered by the drop.

    Notes
    -----
    The image is drawn on the plane perpendicular to the viewing ray, rows along
    the rotated camera y axis (:func:`view_rotation`), so the drop is a circle; on
    the camera's image plane an off-axis drop is that circle seen obliquely, an
    ellipse related to it by a projective mapping (footnote 4 [GargNayar2007]).
    """
    if method not in RENDER_METHODS:
        raise ValueError(f"unknown method {method!r}; valid: {list(RENDER_METHODS)}")
    size_px = int(size_px)
    if size_px < 2:
        raise InputError(f"size_px must be >= 2, got {size_px}")
    env = np.asarray(env)
    rot = view_rotation(alpha_rad, azimuth_rad)

    def env_fn(dirs):
        return sample_environment(env, dirs @ rot.T)

    xs, ys = _disc_samples(size_px, supersample)
    rho = np.hypot(xs, ys)
    inside = rho < 1.0
    extra = env.shape[2:]
    out = np.zeros(xs.shape + extra)
    if method == "model":
        theta_n = np.pi - np.arcsin(np.clip(rho[inside], 0.0, 1.0))
        phi_n = np.arctan2(ys[inside], xs[inside])
        out[inside] = optics.composite_radiance(theta_n, phi_n, env_fn, mu=mu,
                                                components=tuple(components))
    else:
        from raingauge.render.raytrace import Sphere, trace
        n = int(inside.sum())
        origins = np.stack([xs[inside], ys[inside], np.full(n, -3.0)], axis=-1)
        dirs = np.tile([0.0, 0.0, 1.0], (n, 1))
        res = trace(Sphere(1.0), origins, dirs, lambda o, d: env_fn(d), mu=mu,
                    max_internal=2 if "internal" in components else 0,
                    specular="specular" in components)
        acc = np.zeros((n,) + extra)
        if "refraction" in components and 0 in res.components:
            acc += res.components[0]
        if "specular" in components and -1 in res.components:
            acc += res.components[-1]
        if "internal" in components:
            for key in (1, 2):
                if key in res.components:
                    acc += res.components[key]
        out[inside] = acc
    bg = np.asarray(background, dtype=float)
    out[~inside] = bg
    image = out.mean(axis=0).astype(np.float32)
    coverage = inside.mean(axis=0).astype(np.float32)
    return image, coverage


# --------------------------------------------------------------------------------------
# the inverse: from an image of a drop to a perspective view (Fig. 7)
# --------------------------------------------------------------------------------------

def _gray_u8(image):
    img = np.asarray(image)
    if img.ndim == 3:
        img = img.astype(float).mean(axis=2)
    img = img.astype(float)
    lo, hi = np.nanmin(img), np.nanmax(img)
    if not hi > lo:
        raise InputError("the image is uniform: there is no drop to find; give --center and --radius")
    return np.clip((img - lo) / (hi - lo) * 255.0, 0, 255).astype(np.uint8)


def find_drop(image, *, min_radius_px: int | None = None, max_radius_px: int | None = None):
    """Find the circular image of a drop (Hough transform on gradients).

    Parameters
    ----------
    image : ndarray (M, N) or (M, N, C)
        Image containing one dominant drop.
    min_radius_px, max_radius_px : int, optional
        Search range of the radius [px]; by default 1/20 to 1/2 of the smaller side.

    Returns
    -------
    (cx, cy, radius) : floats [px], column/row of the centre and the radius.

    Raises
    ------
    InputError
        When no circle is found.
    """
    import cv2

    gray = _gray_u8(image)
    m, n = gray.shape
    side = min(m, n)
    rmin = int(min_radius_px) if min_radius_px else max(3, side // 20)
    rmax = int(max_radius_px) if max_radius_px else side // 2
    blur = cv2.GaussianBlur(gray, (0, 0), max(1.0, side / 300.0))
    circles = None
    for threshold in (0.9, 0.8, 0.7, 0.6):
        circles = cv2.HoughCircles(blur, cv2.HOUGH_GRADIENT_ALT, dp=1.0, minDist=side / 4.0,
                                   param1=120, param2=threshold, minRadius=rmin, maxRadius=rmax)
        if circles is not None and len(circles[0]):
            break
    if circles is None or not len(circles[0]):
        raise InputError("no drop (circle) found in the image; give its centre and radius "
                         "explicitly (--center X Y --radius R)")
    cx, cy, r = (float(v) for v in circles[0][0])
    return _refine_circle(blur, cx, cy, r)


def _refine_circle(gray, cx, cy, r):
    """Refine a Hough circle: the outermost strong edge along 180 rays, least-squares circle.

    The silhouette of a drop is its outermost edge; inside it the refracted scene
    has edges of its own, which the Hough estimate may have locked onto.
    """
    import cv2

    g = gray.astype(np.float32)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)
    angles = np.linspace(0, 2 * np.pi, 180, endpoint=False)
    radii = np.linspace(0.8 * r, 1.3 * r, int(max(20, 1.0 * r)))
    ca, sa = np.cos(angles)[:, None], np.sin(angles)[:, None]
    px = (cx + radii[None, :] * ca).astype(np.float32)
    py = (cy + radii[None, :] * sa).astype(np.float32)
    ok = (px >= 0) & (px < g.shape[1] - 1) & (py >= 0) & (py < g.shape[0] - 1)
    # gradient component along the ray: the silhouette is a radial edge
    radial = np.abs(cv2.remap(gx, px, py, cv2.INTER_LINEAR) * ca
                    + cv2.remap(gy, px, py, cv2.INTER_LINEAR) * sa)
    radial = np.where(ok, radial, 0.0)
    peak = radial.max()
    if not peak > 0:
        return cx, cy, r
    strong = radial > 0.3 * peak
    has = strong.any(axis=1)
    if has.sum() < 12:
        return cx, cy, r
    n_r = radial.shape[1]
    last = n_r - 1 - np.argmax(strong[:, ::-1], axis=1)
    rows = np.nonzero(has)[0]
    edge_r = np.empty(rows.size)
    for j, row in enumerate(rows):
        # peak of the outermost run of strong samples, to sub-sample precision
        k = last[row]
        start = k
        while start > 0 and strong[row, start - 1]:
            start -= 1
        k = start + int(np.argmax(radial[row, start:last[row] + 1]))
        if 0 < k < n_r - 1:
            y0, y1, y2 = radial[row, k - 1], radial[row, k], radial[row, k + 1]
            den = y0 - 2 * y1 + y2
            off = 0.5 * (y0 - y2) / den if den < 0 else 0.0
        else:
            off = 0.0
        edge_r[j] = np.interp(k + np.clip(off, -0.5, 0.5), np.arange(n_r), radii)
    x = cx + edge_r * np.cos(angles[rows])
    y = cy + edge_r * np.sin(angles[rows])
    keep = np.ones(x.size, dtype=bool)
    for _ in range(3):
        a = np.stack([x[keep], y[keep], np.ones(keep.sum())], axis=1)
        sol, *_ = np.linalg.lstsq(a, x[keep] ** 2 + y[keep] ** 2, rcond=None)
        ncx, ncy = sol[0] / 2.0, sol[1] / 2.0
        nr = np.sqrt(max(sol[2] + ncx ** 2 + ncy ** 2, 0.0))
        resid = np.abs(np.hypot(x - ncx, y - ncy) - nr)
        keep = resid < max(1.5, 3.0 * np.median(resid[keep]))
        if keep.sum() < 12:
            return cx, cy, r
    return float(ncx), float(ncy), float(nr)


def perspective_view(env, *, fov_deg: float, size_px: int):
    """A pinhole view (size, size[, C]) of an equirectangular environment along +z (for comparisons)."""
    f = (size_px / 2.0) / np.tan(np.radians(fov_deg) / 2.0)
    c = (size_px - 1) / 2.0
    y, x = np.mgrid[0:size_px, 0:size_px].astype(float)
    dirs = np.stack([(x - c) / f, (y - c) / f, np.ones_like(x)], axis=-1)
    return sample_environment(env, dirs).astype(np.float32)


def drop_to_perspective(image, *, center_xy, radius_px: float, fov_deg: float = 90.0,
                        size_px: int | None = None, mu: float = optics.MU_WATER,
                        flatten: bool = True):
    """Near-perspective view of the scene behind a drop, by inverting Eq. (7) (Fig. 7).

    A pinhole camera at the drop looking along the optical axis (away from the
    camera) has, for each output pixel, a scene direction (theta_r, phi_r).  Eq. (7)
    with alpha = 0, inverted (:func:`raingauge.physics.optics.normal_theta_from_refraction`),
    gives the normal theta_n and hence the drop image point rho = R sin(theta_n)
    (Eq. 6) at azimuth phi_r - pi (the drop inverts the scene).

    Parameters
    ----------
    image : ndarray (M, N) or (M, N, C)
        Image containing the drop.
    center_xy : (float, float)
        Column and row of the drop's centre [px].
    radius_px : float
        Radius of the drop's image [px].
    fov_deg : float
        Field of view of the output view [deg]; below the drop's own (~165 deg).
    size_px : int, optional
        Side of the square output [px]; by default the drop's diameter.
    mu : float
        Refractive index of the drop [-].
    flatten : bool
        Divide by the refraction transfer R = (1 - k)^2 (Eq. 9) to undo the
        darkening towards the rim.

    Returns
    -------
    ndarray (size, size[, C]) float32; pixels outside the drop's view are 0.
    """
    import cv2

    img = np.asarray(image)
    if img.ndim not in (2, 3):
        raise InputError(f"drop image must be (M, N) or (M, N, C), got shape {img.shape}")
    if not radius_px > 1:
        raise InputError(f"drop radius must be > 1 px, got {radius_px}")
    max_fov = np.degrees(optics.drop_field_of_view(mu))
    if not 0 < fov_deg < min(max_fov, 179.0):
        raise InputError(f"field of view must be between 0 and {min(max_fov, 179.0):.1f} degrees "
                         f"(the drop's own field of view), got {fov_deg}")
    size = int(size_px) if size_px else max(8, int(round(2 * radius_px)))
    f = (size / 2.0) / np.tan(np.radians(fov_deg) / 2.0)
    c = (size - 1) / 2.0
    y, x = np.mgrid[0:size, 0:size].astype(float)
    theta_r = np.arctan(np.hypot(x - c, y - c) / f)
    phi_r = np.arctan2(y - c, x - c)
    theta_n = optics.normal_theta_from_refraction(theta_r, mu)
    rho = radius_px * np.sin(theta_n)
    outside = ~np.isfinite(rho)              # beyond the drop's own field of view
    rho = np.where(outside, 0.0, rho)
    map_x = (center_xy[0] + rho * np.cos(phi_r - np.pi)).astype(np.float32)
    map_y = (center_xy[1] + rho * np.sin(phi_r - np.pi)).astype(np.float32)
    map_x[outside] = -1e6
    map_y[outside] = -1e6
    src = img.astype(np.float32)
    out = cv2.remap(src, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=0)
    if flatten:
        # R falls to 0 at grazing incidence: cap the gain at 10 (R >= 0.1)
        theta_n = np.where(outside, np.pi, theta_n)
        gain = 1.0 / np.maximum(optics.transfer_refraction(np.pi - theta_n, mu), 0.1)
        out = out * (gain[..., None] if out.ndim == 3 else gain)
    return out.astype(np.float32)
