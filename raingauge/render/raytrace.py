"""A small vectorised ray tracer for a single drop: Snell refraction with Fresnel weights in 3-D.

It is the independent check of the drop optics of Sec. 4.2 [GargNayar2007]
(Fig. 6) and the renderer of oscillating drops for close-up streaks (Sec. 9,
[GargNayar2006]).  Nothing here uses the closed-form mappings of
:mod:`raingauge.physics.optics`: rays are intersected with the surface,
reflected and refracted with vector Snell's law, and every branch carries its
unpolarised Fresnel weight, so the radiance of a pixel is the weighted sum of
the scene radiance over all paths (reflection, refraction, 1, 2, ... internal
reflections), each path kept apart by the number of internal reflections.

Surfaces are star-shaped about a centre: :class:`Sphere` (analytic) and
:class:`StarSurface` (any radius function r(u) of the direction u, e.g. an
oscillating raindrop), intersected by marching and bisection.  A scene is a
callable ``scene(origins, dirs) -> radiance`` for rays leaving the drop.

Lengths are in any one unit (metres in the package, inches in the Fig. 6 check).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from raingauge.physics.optics import fresnel_reflectance

Scene = Callable[[np.ndarray, np.ndarray], np.ndarray]

#: label of rays that never met the drop
BACKGROUND = -2
#: label of rays reflected at the first (outer) surface hit
SPECULAR = -1


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def reflect(d, n):
    """Mirror direction of unit rays d (..., 3) about unit normals n (..., 3)."""
    return d - 2.0 * np.sum(d * n, axis=-1, keepdims=True) * n


def refract(d, n, eta):
    """Vector Snell's law.

    Parameters
    ----------
    d : ndarray (..., 3)
        Unit direction of the incident ray.
    n : ndarray (..., 3)
        Unit normal on the incident side (n . d < 0).
    eta : float or ndarray (...)
        Ratio n_incident / n_transmitted [-].

    Returns
    -------
    (t, tir) : transmitted unit direction (NaN under total internal reflection)
        and the boolean total-internal-reflection mask.
    """
    eta = np.asarray(eta, dtype=float)[..., None] if np.ndim(eta) else float(eta)
    cos_i = -np.sum(d * n, axis=-1, keepdims=True)
    k = 1.0 - eta ** 2 * (1.0 - cos_i ** 2)
    tir = k[..., 0] < 0.0
    t = eta * d + (eta * cos_i - np.sqrt(np.clip(k, 0.0, None))) * n
    t[tir] = np.nan
    return t, tir


class Sphere:
    """A sphere of radius ``radius`` about ``center`` (analytic intersections)."""

    def __init__(self, radius: float, center=(0.0, 0.0, 0.0)):
        if not radius > 0:
            raise ValueError(f"sphere radius must be > 0, got {radius}")
        self.radius = float(radius)
        self.center = np.asarray(center, dtype=float)
        self.bounding_radius = self.radius

    def intersect(self, o, d, *, inside: bool, time=None):
        """Distance along unit rays (o, d) to the surface (NaN: no hit); ``time`` is ignored."""
        oc = o - self.center
        b = np.sum(oc * d, axis=-1)
        c = np.sum(oc * oc, axis=-1) - self.radius ** 2
        disc = b * b - c
        ok = disc >= 0.0
        s = np.sqrt(np.where(ok, disc, 0.0))
        eps = 1e-9 * self.radius
        if inside:
            t = -b + s
            good = ok & (t > eps)
        else:
            t = -b - s
            good = ok & (t > eps)
        return np.where(good, t, np.nan)

    def normal(self, p, time=None):
        """Outward unit normal at surface points p (..., 3)."""
        return _unit(p - self.center)


class StarSurface:
    """A closed surface r = radius_fn(u) around ``center``; u a unit direction (..., 3).

    ``max_radius`` must bound radius_fn from above.  Intersections march
    ``n_march`` steps through the bounding sphere and refine the first crossing
    by regula falsi; ``n_march=0`` assumes a convex surface and brackets the
    crossing without marching.  Normals are the normalised gradient of
    F(p) = |p - c| - r(u).
    With ``time_dependent=True`` the radius function is ``radius_fn(u, t)`` and every
    ray carries its own time t (a drop that changes shape during the exposure).
    """

    def __init__(self, radius_fn: Callable[..., np.ndarray], max_radius: float,
                 center=(0.0, 0.0, 0.0), *, n_march: int = 24, n_bisect: int = 40,
                 time_dependent: bool = False):
        self.time_dependent = bool(time_dependent)
        if not max_radius > 0:
            raise ValueError(f"max_radius must be > 0, got {max_radius}")
        self.radius_fn = radius_fn
        self.center = np.asarray(center, dtype=float)
        self.bounding_radius = float(max_radius) * 1.0001
        self.n_march = int(n_march)
        self.n_bisect = int(n_bisect)

    def implicit(self, p, time=None):
        """F(p) = |p - c| - r(u): negative inside, positive outside [length].

        ``time`` (m,) goes with the leading axis of p (m, ...) for a time-dependent surface.
        """
        v = p - self.center
        r = np.sqrt(np.einsum("...k,...k->...", v, v))
        u = v / np.where(r > 0, r, 1.0)[..., None]
        if not self.time_dependent:
            return r - self.radius_fn(u)
        t = np.zeros(p.shape[0]) if time is None else np.asarray(time, dtype=float)
        t = t.reshape(t.shape + (1,) * (r.ndim - t.ndim))
        return r - self.radius_fn(u, t)

    def intersect(self, o, d, *, inside: bool, time=None):
        """Distance along unit rays (o, d) to the first crossing of the surface (NaN: none)."""
        oc = o - self.center
        b = np.sum(oc * d, axis=-1)
        c = np.sum(oc * oc, axis=-1) - self.bounding_radius ** 2
        disc = b * b - c
        ok = disc > 0.0
        s = np.sqrt(np.where(ok, disc, 0.0))
        t_far = -b + s
        eps = 1e-7 * self.bounding_radius
        if inside:
            t_near = np.full_like(b, eps)
        else:
            t_near = np.maximum(-b - s, eps)
        ok &= t_far > t_near
        m = o.shape[0]
        out = np.full(m, np.nan)
        idx = np.nonzero(ok)[0]
        if idx.size == 0:
            return out
        o2, d2, t0, t1 = o[idx], d[idx], t_near[idx], t_far[idx]
        tm = None if time is None else np.asarray(time, dtype=float)[idx]
        rows = np.arange(idx.size)
        if self.n_march > 0:
            frac = np.linspace(0.0, 1.0, self.n_march + 1)
            ts = t0[:, None] + (t1 - t0)[:, None] * frac[None, :]
            pts = o2[:, None, :] + ts[..., None] * d2[:, None, :]
            f = self.implicit(pts, tm)
            crossed = (f < 0.0) if not inside else (f > 0.0)
            if inside:
                crossed[:, 0] = False
            first = np.argmax(crossed, axis=1)
            hit = crossed[rows, first]
            first = np.maximum(first, 1)
            lo = ts[rows, first - 1]
            hi = ts[rows, first]
            f_lo = f[rows, first - 1]
            f_hi = f[rows, first]
        else:
            # convex shape: one crossing between the bounding-sphere entry and the
            # ray's closest approach to the centre (outside rays), or between the
            # start and the bounding-sphere exit (inside rays)
            if inside:
                # the closest approach to the centre is well inside: a clean bracket
                # even when the ray starts a rounding error outside the surface
                lo, hi = np.maximum(-b[idx], t0), t1
            else:
                lo = t0
                hi = np.clip(-b[idx], t0, t1)
            f_lo = self.implicit(o2 + lo[:, None] * d2, tm)
            f_hi = self.implicit(o2 + hi[:, None] * d2, tm)
            hit = np.sign(f_lo) != np.sign(f_hi)
            hit &= (f_lo < 0) if inside else (f_lo > 0)
        # Illinois regula falsi on the bracket [lo, hi] (F changes sign in it),
        # iterating only on the rays not yet converged
        tol = 1e-9 * self.bounding_radius
        t = 0.5 * (lo + hi)
        active = np.nonzero(hit)[0]
        side = np.zeros(idx.size, dtype=int)
        for _ in range(self.n_bisect):
            if active.size == 0:
                break
            a_lo, a_hi, fa_lo, fa_hi = lo[active], hi[active], f_lo[active], f_hi[active]
            denom = fa_hi - fa_lo
            mid = np.where(denom != 0, a_lo - fa_lo * (a_hi - a_lo) / np.where(denom != 0, denom, 1.0),
                           0.5 * (a_lo + a_hi))
            mid = np.clip(mid, np.minimum(a_lo, a_hi), np.maximum(a_lo, a_hi))
            fm = self.implicit(o2[active] + mid[:, None] * d2[active],
                               None if tm is None else tm[active])
            t[active] = mid
            same = np.sign(fm) == np.sign(fa_lo)
            prev = side[active]
            # replace the endpoint on fm's side; halve the kept one if it was kept last time too
            lo[active] = np.where(same, mid, a_lo)
            f_lo[active] = np.where(same, fm, np.where(prev == -1, 0.5 * fa_lo, fa_lo))
            hi[active] = np.where(same, a_hi, mid)
            f_hi[active] = np.where(same, np.where(prev == 1, 0.5 * fa_hi, fa_hi), fm)
            side[active] = np.where(same, 1, -1)
            done = (np.abs(fm) < tol) | (np.abs(hi[active] - lo[active]) < tol)
            active = active[~done]
        out[idx[hit]] = t[hit]
        return out

    def normal(self, p, time=None):
        """Outward unit normal at surface points p (..., 3) (central differences of F)."""
        h = 1e-5 * self.bounding_radius
        g = np.empty(p.shape, dtype=float)
        for k in range(3):
            e = np.zeros(3)
            e[k] = h
            g[..., k] = self.implicit(p + e, time) - self.implicit(p - e, time)
        return _unit(g)


@dataclass
class TraceResult:
    """Radiance gathered for each primary ray, split by path.

    ``components[label]`` holds the radiance carried by paths with that label:
    ``SPECULAR`` (-1), ``0`` (refraction, Eq. 9), ``N`` (N internal reflections,
    Eq. 13); ``hit`` marks primary rays that met the drop; ``radiance`` is the
    total (background for rays that missed the drop).
    """

    radiance: np.ndarray
    hit: np.ndarray
    components: dict = field(default_factory=dict)


def trace(surface, origins, dirs, scene: Scene, *, mu: float, max_internal: int = 8,
          min_weight: float = 1e-5, specular: bool = True, ray_time=None) -> TraceResult:
    """Trace rays (origins, dirs) through one drop into a scene.

    Parameters
    ----------
    surface : Sphere or StarSurface
        The drop.
    origins, dirs : ndarray (n, 3)
        Primary rays (dirs need not be normalised) [length unit of the surface].
    scene : callable
        ``scene(origins, dirs) -> radiance`` (n,) or (n, C) for rays that leave the drop.
    mu : float
        Refractive index of the drop relative to the surrounding air [-].
    max_internal : int
        Highest number of internal reflections followed [-].
    min_weight : float
        Branches whose Fresnel weight falls below this are dropped [-].
    specular : bool
        Follow the reflection at the first outer hit.
    ray_time : ndarray (n,), optional
        Time of each primary ray [s], for a time-dependent surface.

    Returns
    -------
    TraceResult
    """
    o = np.asarray(origins, dtype=float).reshape(-1, 3)
    d = _unit(np.asarray(dirs, dtype=float).reshape(-1, 3))
    n_rays = o.shape[0]
    probe = np.asarray(scene(o[:1], d[:1]))
    extra = probe.shape[1:]
    radiance = np.zeros((n_rays,) + extra)
    comps: dict[int, np.ndarray] = {}
    hit_any = np.zeros(n_rays, dtype=bool)
    eps = 1e-6 * surface.bounding_radius

    # ray state
    w = np.ones(n_rays)
    pix = np.arange(n_rays)
    inside = np.zeros(n_rays, dtype=bool)
    label = np.full(n_rays, BACKGROUND)
    n_int = np.zeros(n_rays, dtype=int)
    times = np.zeros(n_rays) if ray_time is None else np.asarray(ray_time, float).reshape(-1)

    def scatter_add(target, index, values):
        flat_t = target.reshape(n_rays, -1)
        flat_v = values.reshape(values.shape[0], -1)
        for ch in range(flat_t.shape[1]):
            flat_t[:, ch] += np.bincount(index, weights=flat_v[:, ch], minlength=n_rays)

    def emit(sel_o, sel_d, sel_w, sel_pix, sel_label):
        if sel_pix.size == 0:
            return
        val = np.asarray(scene(sel_o, sel_d), dtype=float)
        contrib = val * sel_w.reshape((-1,) + (1,) * len(extra))
        scatter_add(radiance, sel_pix, contrib)
        for lab in np.unique(sel_label):
            if lab == BACKGROUND:
                continue
            m = sel_label == lab
            arr = comps.setdefault(int(lab), np.zeros((n_rays,) + extra))
            scatter_add(arr, sel_pix[m], contrib[m])

    for _ in range(4 * (max_internal + 4)):
        if o.shape[0] == 0:
            break
        t = np.full(o.shape[0], np.nan)
        tm = times[pix]
        if np.any(~inside):
            t[~inside] = surface.intersect(o[~inside], d[~inside], inside=False, time=tm[~inside])
        if np.any(inside):
            t[inside] = surface.intersect(o[inside], d[inside], inside=True, time=tm[inside])
        miss = np.isnan(t)
        # rays leaving the drop (or never meeting it) see the scene; an inside ray
        # that finds no exit is a numerical failure of a grazing path and is dropped
        out_sel = miss & ~inside
        emit(o[out_sel], d[out_sel], w[out_sel], pix[out_sel], label[out_sel])
        keep = ~miss
        if not np.any(keep):
            break
        o, d, w, pix, inside, label, n_int, t = (o[keep], d[keep], w[keep], pix[keep],
                                                 inside[keep], label[keep], n_int[keep], t[keep])
        primary = label == BACKGROUND
        hit_any[pix[primary]] = True
        p = o + t[:, None] * d
        n_out = surface.normal(p, times[pix])
        n_face = np.where(inside[:, None], -n_out, n_out)
        cos_i = np.clip(-np.sum(d * n_face, axis=-1), 0.0, 1.0)
        mu_rel = np.where(inside, 1.0 / mu, mu)
        k = fresnel_reflectance(np.arccos(cos_i), mu_rel)
        d_refl = reflect(d, n_face)
        d_refr, tir = refract(d, n_face, 1.0 / mu_rel)
        k = np.where(tir, 1.0, k)

        new_o, new_d, new_w, new_pix, new_in, new_lab, new_n = [], [], [], [], [], [], []
        # reflected branch
        if specular:
            refl_ok = np.ones(o.shape[0], dtype=bool)
        else:
            refl_ok = inside.copy()
        refl_ok &= (w * k > min_weight)
        refl_ok &= ~inside | (n_int + 1 <= max_internal)
        lab_refl = np.where(inside, label, np.where(primary, SPECULAR, label))
        new_o.append(p[refl_ok] + eps * n_face[refl_ok])
        new_d.append(d_refl[refl_ok])
        new_w.append((w * k)[refl_ok])
        new_pix.append(pix[refl_ok])
        new_in.append(inside[refl_ok])
        new_lab.append(lab_refl[refl_ok])
        new_n.append((n_int + inside.astype(int))[refl_ok])
        # transmitted branch
        tr_ok = ~tir & (w * (1.0 - k) > min_weight)
        lab_tr = np.where(inside, n_int, label)
        new_o.append(p[tr_ok] - eps * n_face[tr_ok])
        new_d.append(d_refr[tr_ok])
        new_w.append((w * (1.0 - k))[tr_ok])
        new_pix.append(pix[tr_ok])
        new_in.append(~inside[tr_ok])
        new_lab.append(np.where(inside[tr_ok], lab_tr[tr_ok], 0))
        new_n.append(n_int[tr_ok])
        o = np.concatenate(new_o)
        d = _unit(np.concatenate(new_d))
        w = np.concatenate(new_w)
        pix = np.concatenate(new_pix)
        inside = np.concatenate(new_in)
        label = np.concatenate(new_lab)
        n_int = np.concatenate(new_n)
    return TraceResult(radiance=radiance, hit=hit_any, components=comps)


# --------------------------------------------------------------------------------------
# cameras and simple scenes
# --------------------------------------------------------------------------------------

def pinhole_rays(shape, *, position, forward, right, focal_length_px, principal_point=None,
                 supersample: int = 1):
    """Rays of a pinhole camera, camera frame x right, y down, z forward.

    Parameters
    ----------
    shape : (M, N)
        Image size in rows, columns [px].
    position : (3,)
        Centre of projection [length].
    forward, right : (3,)
        Optical axis and image +x direction (orthogonalised here).
    focal_length_px : float
        Focal length [px].
    principal_point : (cx, cy), optional
        Principal point [px]; the image centre by default.
    supersample : int
        s x s rays per pixel on a regular sub-grid.

    Returns
    -------
    origins, dirs : ndarray (M, N, s*s, 3)
    """
    m, n = shape
    f = _unit(forward)
    r = _unit(np.asarray(right, float) - np.dot(right, f) * f)
    down = np.cross(f, r)
    cx, cy = ((n - 1) / 2.0, (m - 1) / 2.0) if principal_point is None else principal_point
    s = int(supersample)
    sub = (np.arange(s) + 0.5) / s - 0.5
    ys = np.arange(m)[:, None] + sub[None, :]
    xs = np.arange(n)[:, None] + sub[None, :]
    yy = ys[:, None, :, None] * np.ones((1, n, 1, s))
    xx = xs[None, :, None, :] * np.ones((m, 1, s, 1))
    x = (xx - cx) / focal_length_px
    y = (yy - cy) / focal_length_px
    dirs = (x[..., None] * r + y[..., None] * down + f).reshape(m, n, s * s, 3)
    origins = np.broadcast_to(np.asarray(position, float), dirs.shape).copy()
    return origins, _unit(dirs)


def plane_scene(*, point, normal, texture: Callable[[np.ndarray], np.ndarray],
                background: float | Callable = 0.0) -> Scene:
    """A textured plane: rays that meet it (forward) see ``texture(hit_points)``.

    Parameters
    ----------
    point, normal : (3,)
        A point of the plane and its normal [length].
    texture : callable
        ``texture(points (n, 3)) -> radiance (n,)``.
    background : float or callable
        Radiance of rays that miss the plane, or ``background(dirs) -> radiance``.
    """
    p0 = np.asarray(point, float)
    nrm = _unit(normal)

    def scene(o, d):
        denom = d @ nrm
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((p0 - o) @ nrm) / denom
        ok = np.isfinite(t) & (t > 0)
        out = (np.zeros(o.shape[0]) + background) if not callable(background) else \
            np.asarray(background(d), float).copy()
        if np.any(ok):
            out[ok] = texture(o[ok] + t[ok, None] * d[ok])
        return out

    return scene
