"""Physically based rain video with ground truth [GargNayar2007].

The rain
--------
Drops fill the space in front of the camera as a Poisson process of uniform
positions (Sec. 3) with a size distribution from :mod:`raingauge.physics.drops`
(or replayed from the class densities of Parsivel records), and fall at a
chosen velocity law (default ``"gunn_kinzer"``) plus an optional horizontal
wind.  A drop is created once and then moves exactly as its velocity says:
it crosses the view over as many consecutive frames as its speed implies.

Only drops that can change a pixel by at least ``render_threshold_dn``
(default 0.25 gray level) are drawn: for each diameter the simulator finds the
depth range [z_lo(D), z_hi(D)] of the rain-visible region (Sec. 6.1) where the
uniform-spreading intensity change of Eqs. (21)-(24) reaches the threshold for
the largest contrast the background allows, and generates drops in the camera's
viewing frustum (widened by the footprint of a drop) over that range.  Drops
outside it would change no pixel by that much; the truth records the ranges.

Each diameter class lives in its own convex region (a frustum slice with a
margin).  Drops present at t = 0 are uniform in it; later drops enter through
the faces the velocity points into, at the Poisson rate density x area x
inward normal speed, uniformly over the face and in time.  The number of drops
in any sub-volume is then Poisson at every instant, with the density of the
size distribution, and every drop follows one straight path.

The imaging (Eqs. 15-17, 21-24)
-------------------------------
A pinhole camera with the profile's focal length f [px] and principal point.
Over the exposure [t_k, t_k + T] a drop of radius a at depth z projects to a
disc of radius a_i = f a / z moving from the projection of its position at t_k
to that at t_k + T.  The exposure integral of Eq. (15) over all pixels is the
disc area times T: the drop contributes an "exposure area" pi a_i^2 (in pixel
units, as a fraction of the exposure).  Following Sec. 6.1 (Eqs. 23-24) this
is spread uniformly over the defocused streak, the capsule swept by a disc of
diameter w + b_c, with w = max(2 a_i, 1) (partial pixel coverage of small
drops, Eq. 22) and b_c the thin-lens blur circle (Eq. 23).  A pixel inside
the streak receives the fraction beta = tau / T = pi a_i^2 / A_streak of the
exposure from the drop, and its linear intensity becomes (Eq. 17)

    I = I_b + beta (E_r - I_b),

E_r the drop's own brightness (Sec. 4.2.3: brighter than the background and
nearly independent of it; ``drop_brightness_dn``).  Edge pixels get the
fraction of their area inside the streak (exact horizontally, two samples per
row vertically).  Contributions of several drops add (Eq. 25's layers).

Close-up drops (Sec. 9; option ``closeup``, off by default)
-----------------------------------------------------------
A drop whose focused image is wide enough for its internal pattern to matter
and sharp enough for the pattern to survive the defocus (2 a_i >= 6 px and
b_c <= 0.5 x 2 a_i, :func:`closeup_selection`) can be drawn, instead of the
uniform capsule, as the ray-traced streak of an oscillating drop
(:mod:`raingauge.render.closeup`): its (2, 0) and (2, 1) modes oscillate at
Rayleigh's frequency with amplitudes and phases fixed per drop from the seed
(:func:`closeup_oscillations`), so the streak's brightness repeats every fall
distance per oscillation period.  Streaks are traced at quantised sizes and
phases (cached), warped onto the drop's image segment, normalised to the
uniform model's exposure area pi a_i^2 and mean brightness E_r (so the
deposit of Eqs. 15-17 is unchanged), and blurred with the drop's blur circle
(:func:`render_closeup_drops`).  The lighting is the overcast sky (uniform
ambient) or the sky plus a light (``closeup_light``).

Then the sensor: the profile's radiometric response (``profile.delinearize``'s
inverse table), Gaussian noise of ``noise_sigma_dn`` gray levels, 8-bit
quantisation and optional JPEG compression.

The truth
---------
Computed from the drops actually generated, never from the nominal parameter:
at the middle of every exposure the drops inside a reference volume (a box
inside the viewing frustum, by default from 0.8 z0 to 1.25 z0 in depth, where
every diameter is generated whether visible or not) give Eq. (28) as
``rain_rate_from_drops``; windows average these snapshots (one window per
record when replaying a Parsivel file).  ``Simulation.population(times)``
gives every generated drop at any time, for independent checks.  The DSD of each window is given in the 32 Parsivel classes.
Per frame, the drops drawn (3-D position at the start of the exposure, radius,
velocity, image streak end points, depth, blur, beta) and, when asked, the
rain mask (pixels changed by at least 1 gray level) and the clean frame.

Notes
-----
- Sec. 6.1 writes tau ~ 2a/v for a pixel on the centre line of a streak; the
  mean over the streak width is (pi/4) of that, and uniform spreading (the
  paper's own Eq. 23 approximation) gives every streak pixel this mean.  The
  exposure area pi a_i^2 is exact; the paper's Eqs. (22) and (26) use the
  bounding square 4 a_i^2 instead, so rendered intensity changes are pi/4 of
  Eqs. (21)-(22) and rendered standard deviations pi/4 of Eq. (27) (about 0.9
  of that again, because real pixels integrate a 1-px streak that straddles two
  of them where Eq. (26) assumes it covers exactly w pixels).
- Drop counts in any volume are Poisson at every instant; the drops in one
  volume at two times are not independent (they are the same drops, moved).
- Sensor noise comes from OpenCV's generator (``cv2.randn``), reseeded for
  every frame from the simulation's own seed: the video is reproducible, and
  OpenCV's global random state is changed.
- The camera is level: gravity is +y (image down).  The wind direction
  ``wind_dir_deg`` is where the wind blows *to*, in the horizontal plane,
  measured from the image's +x axis (0 = to the right) towards the optical
  axis (90 = away from the camera).
"""

from __future__ import annotations

import dataclasses
import math
import threading
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from raingauge.errors import ConfigError, InputError, ProfileError
from raingauge.physics import drops as _drops

__all__ = [
    "simulate",
    "render_clip",
    "Simulation",
    "RainVolume",
    "DropTable",
    "streak_capsules",
    "render_streaks",
    "compose_rain",
    "visible_depth_range",
    "small_profile",
    "DEFAULT_DROP_BRIGHTNESS_DN",
    "DEFAULT_RENDER_THRESHOLD_DN",
    "DEFAULT_PIXEL_PITCH_M",
    "closeup_selection",
    "closeup_oscillations",
    "render_closeup_drops",
    "CLOSEUP_MIN_WIDTH_PX",
    "CLOSEUP_MAX_BLUR_RATIO",
    "CLOSEUP_LIGHT_TO_SKY",
]

#: E_r: linear brightness of a drop [gray levels] (overcast sky refracted by the drop, Sec. 4.2.3)
DEFAULT_DROP_BRIGHTNESS_DN = 200.0
#: drops that cannot change a pixel by this much [gray levels] are not generated outside the reference volume
DEFAULT_RENDER_THRESHOLD_DN = 0.25
#: pixel pitch assumed when the profile has none [m] (only the blur circle needs it)
DEFAULT_PIXEL_PITCH_M = 5.0e-6
#: nearest depth at which drops are generated [m]
DEFAULT_NEAR_LIMIT_M = 0.05
#: farthest depth considered [m]
FAR_LIMIT_M = 3000.0
#: length of the generation time steps [s]
_CHUNK_S = 0.5


# ============================================================================ profiles
def small_profile(width_px: int = 320, height_px: int = 240, *, base: str = "gauge-default",
                 **changes) -> "Any":
    """A scaled-down copy of a shipped profile for fast tests.

    The focal length is scaled with the width so the field of view is kept.

    Parameters
    ----------
    width_px, height_px : int
        Frame size [px].
    base : str
        Shipped profile name or path.
    **changes
        Further profile fields to replace (validated).
    """
    from raingauge.profile import load_profile

    prof = load_profile(base)
    scale = width_px / prof.width_px
    fields = {"width_px": int(width_px), "height_px": int(height_px),
              "focal_length_px": prof.focal_length_px * scale}
    if prof.pixel_pitch_m is not None:
        fields["pixel_pitch_m"] = prof.pixel_pitch_m / scale
    fields.update(changes)
    return prof.replace(**fields)


def _resolve_profile(profile):
    from raingauge.profile import CameraProfile, load_profile

    if isinstance(profile, CameraProfile):
        return profile
    if profile is None or isinstance(profile, (str, Path)):
        return load_profile(profile)
    if isinstance(profile, dict):
        from raingauge.profile import profile_from_dict

        data = profile if "camera" in profile else {"camera": profile}
        return profile_from_dict(data)
    raise ProfileError(f"expected a CameraProfile, a profile path or name, got {type(profile).__name__}")


# ============================================================================ image geometry
def streak_capsules(start_m, end_m, radius_m, *, focal_length_px: float, principal_point_px,
                    f_number: float, focus_distance_m: float, pixel_pitch_m: float) -> dict:
    """Image streaks of drops over an exposure: capsule end points, radius and exposure area.

    Pinhole projection of the positions at the start and end of the exposure;
    focused width w = max(2 f a / z, 1) (Eq. 26 as corrected; w = 1 carries
    the partial coverage of Eq. 22); thin-lens blur circle b_c (Eq. 23); the
    streak is the capsule of radius (w + b_c) / 2 around the segment.

    Parameters
    ----------
    start_m, end_m : array_like, shape (n, 3)
        Drop centres at the start and end of the exposure, camera frame [m].
    radius_m : array_like, shape (n,)
        Drop radii a [m].
    focal_length_px : float
        f [px].
    principal_point_px : (float, float)
        (c_x, c_y) [px].
    f_number : float
        N [-].
    focus_distance_m : float
        z0 [m].
    pixel_pitch_m : float
        Pixel pitch [m].

    Returns
    -------
    dict of ndarray
        ``p0``, ``p1`` (n, 2) end points (x, y) [px]; ``depth_m`` (n,) depth at
        mid-exposure; ``image_radius_px`` a_i; ``width_px`` w; ``blur_px`` b_c;
        ``radius_px`` capsule radius; ``area_px`` exposure area pi a_i^2 [px^2].
    """
    from raingauge.physics.camera import blur_circle_px

    s = np.asarray(start_m, dtype=np.float64).reshape(-1, 3)
    e = np.asarray(end_m, dtype=np.float64).reshape(-1, 3)
    a = np.asarray(radius_m, dtype=np.float64).reshape(-1)
    f = float(focal_length_px)
    cx, cy = principal_point_px
    p0 = np.stack([f * s[:, 0] / s[:, 2] + cx, f * s[:, 1] / s[:, 2] + cy], axis=1)
    p1 = np.stack([f * e[:, 0] / e[:, 2] + cx, f * e[:, 1] / e[:, 2] + cy], axis=1)
    z = 0.5 * (s[:, 2] + e[:, 2])
    a_i = f * a / z
    w = np.maximum(2.0 * a_i, 1.0)
    b = blur_circle_px(z, focal_length_px=f, f_number=f_number, focus_distance_m=focus_distance_m,
                       pixel_pitch_m=pixel_pitch_m)
    return {"p0": p0, "p1": p1, "depth_m": z, "image_radius_px": a_i, "width_px": w,
            "blur_px": b, "radius_px": 0.5 * (w + b), "area_px": math.pi * a_i ** 2}


def _capsule_spans(y, x0, y0, x1, y1, r):
    """Horizontal extent [xl, xr] of capsules on the lines y (vectorised; empty gives xl > xr)."""
    inf = np.inf
    # end discs
    d0 = r * r - (y - y0) ** 2
    d1 = r * r - (y - y1) ** 2
    h0 = np.sqrt(np.maximum(d0, 0.0))
    h1 = np.sqrt(np.maximum(d1, 0.0))
    lo = np.minimum(np.where(d0 >= 0, x0 - h0, inf), np.where(d1 >= 0, x1 - h1, inf))
    hi = np.maximum(np.where(d0 >= 0, x0 + h0, -inf), np.where(d1 >= 0, x1 + h1, -inf))
    # the band around the segment
    dx, dy = x1 - x0, y1 - y0
    length = np.hypot(dx, dy)
    ok = length > 1e-9
    ux = np.where(ok, dx / np.where(ok, length, 1.0), 1.0)
    uy = np.where(ok, dy / np.where(ok, length, 1.0), 0.0)
    yy = y - y0
    tiny = 1e-12
    uxs = np.where(np.abs(ux) < tiny, np.where(ux < 0, -tiny, tiny), ux)
    uys = np.where(np.abs(uy) < tiny, np.where(uy < 0, -tiny, tiny), uy)
    # 0 <= X ux + yy uy <= L
    a1 = (0.0 - yy * uy) / uxs
    b1 = (length - yy * uy) / uxs
    # -r <= -X uy + yy ux <= r   <=>  yy ux - r <= X uy <= yy ux + r
    a2 = (yy * ux - r) / uys
    b2 = (yy * ux + r) / uys
    blo = np.maximum(np.minimum(a1, b1), np.minimum(a2, b2))
    bhi = np.minimum(np.maximum(a1, b1), np.maximum(a2, b2))
    band = ok & (blo <= bhi)
    lo = np.minimum(lo, np.where(band, x0 + blo, inf))
    hi = np.maximum(hi, np.where(band, x0 + bhi, -inf))
    return lo, hi


_SCRATCH = threading.local()


def _span_entries(rows, xl, xr, weight, n, width):
    """Flat indices and values of the second-difference form of row spans [xl, xr].

    Summing the values along a row gives, at each pixel, ``weight`` times the
    part of the pixel's width inside [xl, xr] (pixel centres at integers).
    """
    a = np.asarray(xl, np.float64) + 0.5
    b = np.asarray(xr, np.float64) + 0.5
    ia = np.floor(a)
    ib = np.floor(b)
    fa = a - ia
    fb = b - ib
    ia = np.clip(ia, -1, n).astype(np.int64)
    ib = np.clip(ib, -1, n).astype(np.int64)
    base = np.asarray(rows, np.int64) * width
    w = np.asarray(weight, np.float64)
    flat = np.concatenate([base + np.maximum(ia, 0), base + ia + 1, base + np.maximum(ib, 0), base + ib + 1])
    vals = np.concatenate([w * (1.0 - fa), w * fa, -w * (1.0 - fb), -w * fb])
    return flat, vals


def _scratch(m: int, width: int, *, pooled: bool = False):
    """Reusable accumulation buffers for one image size (one set per thread).  With
    ``pooled`` they are views of one growing set shared by all sizes, for a caller whose
    result does not stay a view into them (images of a new size each call, such as the
    completeness probe's canvases, then allocate nothing)."""
    if pooled:
        pool = getattr(_SCRATCH, "pool", None)
        need = ((m + 1) * (width + 1), m * width)
        if pool is None or pool[0].size < need[0]:
            size = int(need[0] * 1.25) + 1024
            pool = _SCRATCH.pool = (np.empty(size, np.float64), np.empty(size, np.float64),
                                    np.empty(size, np.float64))
        return (pool[0][:need[1]], pool[1][:need[1]].reshape(m, width),
                pool[2][:need[0]].reshape(m + 1, width + 1))
    cache = getattr(_SCRATCH, "buffers", None)
    if cache is None:
        cache = _SCRATCH.buffers = {}
    key = (m, width)
    if key not in cache:
        if len(cache) > 8:
            cache.clear()
        cache[key] = (np.zeros(m * width, np.float64), np.zeros((m, width), np.float64),
                         np.zeros((m + 1, width + 1), np.float64))
    return cache[key]


def render_streaks(shape, p0, p1, radius_px, area_px, *, n_sub: int = 2,
                   max_rows_factor: float = 4.0, _view: bool = False):
    """Exposure fractions of motion-blurred, defocused streaks, Eqs. (15)-(17), (23).

    Each streak is a capsule (radius ``radius_px`` around the segment p0-p1)
    over which the exposure area ``area_px`` (= pi a_i^2, in pixel-exposures)
    is spread uniformly, so a pixel inside it is covered for the fraction
    beta = area / A_capsule of the exposure.  Pixels on the edge get the
    part of their area inside the capsule: exact across each row, ``n_sub``
    samples per row vertically.

    Parameters
    ----------
    shape : (int, int)
        Image shape (M, N).
    p0, p1 : array_like, shape (n, 2)
        Streak end points (x, y) [px] (pixel centres at integers).
    radius_px : array_like, shape (n,)
        Capsule radius [px] (>= 0.5).
    area_px : array_like, shape (n,)
        Exposure area of each drop [px^2].
    n_sub : int
        Vertical samples per pixel row.
    max_rows_factor : float
        Capsules taller than this many image heights are normalised by their
        analytic area and rasterised on the image rows only.
    _view : bool
        Return a view into scratch memory, valid until the next call (internal).

    Returns
    -------
    beta : ndarray, shape (M, N), float32 (float64 view with ``_view``)
        Sum over streaks of the exposure fraction tau / T at each pixel.
    beta_inside : ndarray, shape (n,)
        Exposure fraction of a pixel fully inside each streak (its beta, Eq. 18).
    """
    import cv2

    m, n = int(shape[0]), int(shape[1])
    p0 = np.asarray(p0, dtype=np.float64).reshape(-1, 2)
    p1 = np.asarray(p1, dtype=np.float64).reshape(-1, 2)
    r = np.asarray(radius_px, dtype=np.float64).reshape(-1)
    area = np.asarray(area_px, dtype=np.float64).reshape(-1)
    count = r.size
    beta_inside = np.zeros(count)
    if count == 0:
        return np.zeros((m, n), np.float32), beta_inside
    x0, y0, x1, y1 = p0[:, 0], p0[:, 1], p1[:, 0], p1[:, 1]
    # vertical samples per row: n_sub for thin streaks, one for wide (blurred) ones
    ns = np.where(r < 3.0, int(n_sub), 1).astype(np.int64)
    ymin = np.minimum(y0, y1) - r
    ymax = np.maximum(y0, y1) + r
    # sub-row j of a streak with ns samples per row lies at y = (j + 0.5) / ns - 0.5
    j_lo = np.ceil((ymin + 0.5) * ns - 0.5).astype(np.int64)
    j_hi = np.floor((ymax + 0.5) * ns - 0.5).astype(np.int64)
    huge = (j_hi - j_lo + 1) > max_rows_factor * m * ns
    j_lo = np.where(huge, np.maximum(j_lo, 0), j_lo)
    j_hi = np.where(huge, np.minimum(j_hi, m * ns - 1), j_hi)
    # a vertical streak is a rectangle [x0 - r, x0 + r] on the rows its segment spans
    # entirely; those rows are added as one rectangle, the others row by row
    vertical = (np.abs(x1 - x0) < 1e-9) & ~huge
    r_a = np.ceil(np.minimum(y0, y1) + 0.5).astype(np.int64)
    r_b = np.floor(np.maximum(y0, y1) - 0.5).astype(np.int64)
    rect = vertical & (r_b >= r_a)
    j_a = np.where(rect, r_a * ns, 0)
    n_rect_j = np.where(rect, (r_b - r_a + 1) * ns, 0)
    counts = np.maximum(j_hi - j_lo + 1, 0) - n_rect_j
    total = int(counts.sum())
    idx = np.repeat(np.arange(count), counts)
    starts = np.cumsum(counts) - counts
    nsp = ns[idx]
    k = np.arange(total) - np.repeat(starts, counts)
    j = j_lo[idx] + k
    j = j + np.where(j >= j_a[idx], n_rect_j[idx], 0)
    ys = ((j + 0.5) / nsp - 0.5).astype(np.float32)
    f32 = np.float32
    xl, xr = _capsule_spans(ys, x0.astype(f32)[idx], y0.astype(f32)[idx], x1.astype(f32)[idx],
                            y1.astype(f32)[idx], r.astype(f32)[idx])
    seg = np.maximum(xr - xl, f32(0.0)) / nsp
    cover = np.bincount(idx, weights=seg, minlength=count)
    cover = cover + np.where(rect, (r_b - r_a + 1) * 2.0 * r, 0.0)
    length = np.hypot(x1 - x0, y1 - y0)
    analytic = 2.0 * r * length + math.pi * r * r
    cover = np.where(huge | (cover <= 0), analytic, cover)
    beta_inside = area / cover
    width = n + 2
    # spans on image rows that reach into the image
    row = np.floor(ys + f32(0.5)).astype(np.int64)
    keep = (seg > 0) & (row >= 0) & (row < m) & (xr > -0.5) & (xl < n - 0.5)
    flat, vals = _span_entries(row[keep], xl[keep], xr[keep], beta_inside[idx[keep]] / nsp[keep], n, width)
    # rectangles: their entries go to the first row (+) and the row after the last (-)
    ri = np.nonzero(rect & (r_b >= 0) & (r_a < m) & (x0 + r > -0.5) & (x0 - r < n - 0.5))[0]
    ra = np.maximum(r_a[ri], 0)
    rb = np.minimum(r_b[ri], m - 1)
    f_top, v_top = _span_entries(ra, x0[ri] - r[ri], x0[ri] + r[ri], beta_inside[ri], n, width)
    below = rb + 1 < m
    f_bot, v_bot = _span_entries(rb[below] + 1, x0[ri][below] - r[ri][below], x0[ri][below] + r[ri][below],
                                 -beta_inside[ri][below], n, width)
    acc, diff, integral = _scratch(m, width, pooled=not _view)
    acc.fill(0.0)
    np.add.at(acc, flat, vals)
    acc2 = acc.reshape(m, width)
    # row sums by OpenCV's integral image of the rows' differences: the integral of
    # A[y] - A[y-1] over y' <= y, x' <= x is the sum of A[y, x'] over x' <= x
    diff[0] = acc2[0]
    np.subtract(acc2[1:], acc2[:-1], out=diff[1:])
    if ri.size:
        dflat = diff.reshape(-1)
        np.add.at(dflat, np.concatenate([f_top, f_bot]), np.concatenate([v_top, v_bot]))
    cv2.integral(diff, integral, sdepth=cv2.CV_64F)
    out = integral[1:, 1:n + 1]
    if not _view:
        out = out.astype(np.float32)
    return out, beta_inside


def compose_rain(background, beta, *, drop_brightness_dn: float = DEFAULT_DROP_BRIGHTNESS_DN, out=None):
    """Rainy linear frame from the background and the streaks' exposure fractions, Eq. (17).

    I = I_b + beta (E_r - I_b), beta clipped to [0, 1].

    Parameters
    ----------
    background : ndarray, shape (M, N)
        Linear background I_b [gray levels].
    beta : ndarray, shape (M, N)
        Exposure fraction covered by drops (:func:`render_streaks`).
    drop_brightness_dn : float
        E_r, linear brightness of a drop [gray levels].
    out : ndarray, shape (M, N), float32, optional
        Where to write the result.

    Returns
    -------
    ndarray, shape (M, N), float32
    """
    bg = np.asarray(background, dtype=np.float32)
    out = np.subtract(np.float32(drop_brightness_dn), bg, out=out, dtype=np.float32)
    if beta.size and float(beta.max()) > 1.0:
        beta = np.minimum(beta, 1.0)
    np.multiply(out, beta, out=out, casting="same_kind")
    out += bg
    return out


# ============================================================================ close-up drops (Sec. 9)
#: close-up drawing: smallest focused streak width 2 a_i for the oscillation pattern to show [px]
CLOSEUP_MIN_WIDTH_PX = 6.0
#: close-up drawing: largest blur circle b_c, as a fraction of the focused width 2 a_i [-]
CLOSEUP_MAX_BLUR_RATIO = 0.5
#: peak radiance of the close-up light relative to the sky (``closeup_light``) [-]
CLOSEUP_LIGHT_TO_SKY = 100.0
#: close-up streaks are traced at most this wide and then scaled to the drop's width [px]
_CLOSEUP_MAX_RENDER_WIDTH_PX = 12
#: ... and with at most this many pixels of width x length (longer streaks are traced smaller)
_CLOSEUP_MAX_RENDER_AREA_PX = 8 * 300
#: quantisation of the close-up streaks (so that the streak cache hits)
_CLOSEUP_RADIUS_STEP = 0.04          # relative step of the radius grid (log) [-]
_CLOSEUP_FALL_STEP_PX = 2.0          # fall length at the traced scale [px]
_CLOSEUP_VIEW_STEP_RAD = 0.1         # elevation of the line of sight [rad]
_CLOSEUP_PHASES = 8                  # phase of the (2, 0) mode at the start of the exposure
_CLOSEUP_REL_PHASES = 4              # phase of the (2, 1) mode relative to the (2, 0) mode
_CLOSEUP_AZIMUTHS = 4                # azimuth of the (2, 1) mode over [0, pi)
#: oscillation amplitudes drawn per drop (peak fractional radius change; a few per cent in rain,
#: [TokayBeard1996]) [-]
CLOSEUP_AMPLITUDES_AXISYMMETRIC = (0.03, 0.06, 0.09)
CLOSEUP_AMPLITUDES_TRANSVERSE = (0.0, 0.03, 0.06)


def closeup_selection(width_px, blur_px, *, min_width_px: float = CLOSEUP_MIN_WIDTH_PX,
                      max_blur_ratio: float = CLOSEUP_MAX_BLUR_RATIO) -> np.ndarray:
    """Which drops are drawn as close-up streaks of an oscillating drop (Sec. 9 [GargNayar2007]).

    A drop qualifies when its focused image is wide enough for the pattern its
    oscillations make inside the streak to be resolved, 2 a_i >= ``min_width_px``,
    and its thin-lens blur circle (Eq. 23) does not wash that pattern out,
    b_c <= ``max_blur_ratio`` x 2 a_i.  The glints and dark bands of the pattern
    are about a quarter to half of the drop's width across; a blur of half the
    width keeps them as visible modulations of the streak.

    Parameters
    ----------
    width_px : array_like, shape (n,)
        Focused drop image diameter 2 a_i = 2 f a / z [px] (not clipped at 1 px).
    blur_px : array_like, shape (n,)
        Blur circle diameter b_c [px].
    min_width_px : float
        Smallest focused width [px].
    max_blur_ratio : float
        Largest b_c / (2 a_i) [-].

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    w = np.asarray(width_px, dtype=np.float64)
    b = np.asarray(blur_px, dtype=np.float64)
    return (w >= float(min_width_px)) & (b <= float(max_blur_ratio) * w)


def _pillbox_kernel(diameter_px: float) -> np.ndarray:
    """Normalised disc of diameter ``diameter_px`` (thin-lens blur, Eq. 23), anti-aliased (8 x 8 samples)."""
    r = 0.5 * float(diameter_px)
    half = int(math.ceil(r + 0.5))
    s = (np.arange(8) + 0.5) / 8 - 0.5
    c = np.arange(-half, half + 1)
    yy = (c[:, None, None, None] + s[None, None, :, None])
    xx = (c[None, :, None, None] + s[None, None, None, :])
    k = ((xx ** 2 + yy ** 2) <= r * r).mean(axis=(2, 3))
    if k.sum() <= 0:
        k[half, half] = 1.0
    return (k / k.sum()).astype(np.float32)


def closeup_oscillations(ids, seed_sequence) -> dict:
    """Oscillation amplitudes and phases of drops, fixed per drop id (Sec. 9 [GargNayar2007]).

    Each drop keeps its oscillation from frame to frame: the values come from a
    generator seeded by the simulation's seed and the drop's id, so they do not
    depend on which other drops exist or on the order of drawing.

    Parameters
    ----------
    ids : array_like of int, shape (n,)
        Drop ids.
    seed_sequence : numpy.random.SeedSequence
        The simulation's seed sequence for oscillations.

    Returns
    -------
    dict of ndarray (n,)
        ``amp_axisymmetric``, ``amp_transverse`` [-] (from
        :data:`CLOSEUP_AMPLITUDES_AXISYMMETRIC`, :data:`CLOSEUP_AMPLITUDES_TRANSVERSE`),
        ``phase_axisymmetric``, ``phase_transverse`` [rad] (uniform in [0, 2 pi)),
        ``transverse_azimuth`` [rad] (uniform in [0, pi)).
    """
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    out = {k: np.empty(ids.size) for k in ("amp_axisymmetric", "amp_transverse", "phase_axisymmetric",
                                            "phase_transverse", "transverse_azimuth")}
    ss = seed_sequence
    for i, drop_id in enumerate(ids):
        rng = np.random.default_rng(np.random.SeedSequence(ss.entropy, spawn_key=(*ss.spawn_key, int(drop_id))))
        u = rng.uniform(size=5)
        out["amp_axisymmetric"][i] = CLOSEUP_AMPLITUDES_AXISYMMETRIC[int(u[0] * len(CLOSEUP_AMPLITUDES_AXISYMMETRIC))]
        out["amp_transverse"][i] = CLOSEUP_AMPLITUDES_TRANSVERSE[int(u[1] * len(CLOSEUP_AMPLITUDES_TRANSVERSE))]
        out["phase_axisymmetric"][i] = 2.0 * math.pi * u[2]
        out["phase_transverse"][i] = 2.0 * math.pi * u[3]
        out["transverse_azimuth"][i] = math.pi * u[4]
    return out


def _closeup_render_size(width_px: float, fall_px: float):
    """Traced width and fall [px] of a close-up streak, quantised, and the scale factor to the image."""
    w_r = int(min(max(round(width_px), 2), _CLOSEUP_MAX_RENDER_WIDTH_PX))
    while True:
        s = w_r / width_px
        fall_r = _CLOSEUP_FALL_STEP_PX * round(fall_px * s / _CLOSEUP_FALL_STEP_PX)
        if w_r * (fall_r + w_r) <= _CLOSEUP_MAX_RENDER_AREA_PX or w_r <= 4:
            return w_r, float(fall_r)
        w_r -= 1


def render_closeup_drops(shape, p0, p1, radius_m, image_radius_px, blur_px, *, exposure_s: float,
                         drop_brightness_dn: float, oscillation: dict, start_time_s=0.0,
                         view_theta_rad=0.0, light=None, cache: dict | None = None):
    """Close-up streaks of oscillating drops, defocused, as exposure layers (Sec. 9, Eqs. 15-17, 23).

    Each drop's streak is traced by :func:`raingauge.render.closeup.cached_closeup_streak`
    (its oscillating shape ray-traced at instants over the exposure while it
    falls) at a quantised size, mapped onto the image segment p0-p1 by an
    affine warp (the traced drop width to 2 a_i across, the traced fall to
    |p1 - p0| along), normalised (below), and convolved with the drop's blur
    circle b_c (a disc, Eq. 23).  Compose a linear frame as

        I = I_b (1 - coverage) + radiance

    (on top of the uniform streaks: ``I += radiance - coverage I_b``).

    Normalisation.  Every streak's coverage sums to the uniform model's
    exposure area pi a_i^2 [px^2] (Eqs. 15-17: the exposure integral of a
    drop over all pixels), and its radiance to E_r pi a_i^2: the drop's mean
    brightness is the simulator's E_r (Sec. 4.2.3), which the close-up
    renderer's lighting distributes within the drop.  On a uniform background
    a close-up streak therefore deposits exactly pi a_i^2 (E_r - I_b) gray-level
    pixels, as the uniform capsule does; only the distribution differs.  The
    traced coverage before normalisation is reported (``raw_area_ratio``, traced
    coverage sum / pi (w_r / 2)^2): it is below 1 by the side-view area of the
    oblate equilibrium shape, gamma^(1/3) for axis ratio gamma (0.93-1 for
    D <= 4 mm), and by the pixel sampling (a few per cent).

    Parameters
    ----------
    shape : (int, int)
        Image shape (M, N).
    p0, p1 : array_like, shape (n, 2)
        Drop centre at the start and end of the exposure (x, y) [px].
    radius_m : array_like, shape (n,)
        Drop radius a [m].
    image_radius_px : array_like, shape (n,)
        a_i = f a / z [px].
    blur_px : array_like, shape (n,)
        Blur circle diameter b_c [px].
    exposure_s : float
        Exposure time T [s].
    drop_brightness_dn : float
        E_r, the drop's mean linear brightness [gray levels].
    oscillation : dict of array_like (n,)
        As returned by :func:`closeup_oscillations` (amplitudes [-], phases at t = 0 [rad]).
    start_time_s : float or array_like (n,)
        Time at the start of the exposure [s] (the oscillation's phase).
    view_theta_rad : float or array_like (n,)
        Elevation of the line of sight below the horizontal [rad].
    light : (float, float) or None
        (theta, phi) of a light [rad] in :mod:`raingauge.render.closeup`'s convention,
        :data:`CLOSEUP_LIGHT_TO_SKY` times as bright as the sky; None: the sky only.
    cache : dict, optional
        Traced streaks by quantised key, kept across calls.

    Returns
    -------
    coverage, radiance : ndarray, shape (M, N), float32
        Exposure fraction covered by the drops [-]; radiance they contribute [gray levels].
    info : dict of ndarray (n,)
        ``period_px`` (fall per oscillation period in the image [px]), ``frequency_hz``,
        ``render_width_px``, ``render_fall_px``, ``raw_area_ratio``, ``phase_index``.
    """
    import cv2

    from raingauge.render.closeup import cached_closeup_streak
    from raingauge.render.oscillation import rayleigh_frequency_hz

    m, n = int(shape[0]), int(shape[1])
    p0 = np.asarray(p0, dtype=np.float64).reshape(-1, 2)
    p1 = np.asarray(p1, dtype=np.float64).reshape(-1, 2)
    count = p0.shape[0]
    a = np.asarray(radius_m, dtype=np.float64).reshape(-1)
    a_i = np.asarray(image_radius_px, dtype=np.float64).reshape(-1)
    blur = np.asarray(blur_px, dtype=np.float64).reshape(-1)
    t_start = np.broadcast_to(np.asarray(start_time_s, dtype=np.float64), (count,))
    view = np.broadcast_to(np.asarray(view_theta_rad, dtype=np.float64), (count,))
    osc = {k: np.broadcast_to(np.asarray(v, dtype=np.float64), (count,)) for k, v in oscillation.items()}
    e_r = float(drop_brightness_dn)
    coverage = np.zeros((m, n), np.float32)
    radiance = np.zeros((m, n), np.float32)
    info = {k: np.zeros(count) for k in ("period_px", "frequency_hz", "render_width_px", "render_fall_px",
                                         "raw_area_ratio", "phase_index")}
    light_key = None if light is None else tuple(float(v) for v in light)
    lighting = ({"ambient": 1.0} if light_key is None
                else {"ambient": 1.0, "light_radiance": CLOSEUP_LIGHT_TO_SKY})
    step = math.log1p(_CLOSEUP_RADIUS_STEP)
    two_pi = 2.0 * math.pi
    for i in range(count):
        a_q = float(math.exp(round(math.log(a[i]) / step) * step))
        freq = float(rayleigh_frequency_hz(a_q))
        width = 2.0 * a_i[i]
        seg = p1[i] - p0[i]
        length = float(np.hypot(*seg))
        w_r, fall_r = _closeup_render_size(width, length)
        # phases: the (2, 0) mode's phase at the start of the exposure, the (2, 1) mode relative to it
        phi = (osc["phase_axisymmetric"][i] + two_pi * freq * t_start[i]) % two_pi
        q = int(round(phi / two_pi * _CLOSEUP_PHASES)) % _CLOSEUP_PHASES
        rel = (osc["phase_transverse"][i] - osc["phase_axisymmetric"][i]) % two_pi
        qr = int(round(rel / two_pi * _CLOSEUP_REL_PHASES)) % _CLOSEUP_REL_PHASES
        qa = int(round(osc["transverse_azimuth"][i] % math.pi / math.pi * _CLOSEUP_AZIMUTHS)) % _CLOSEUP_AZIMUTHS
        psi20 = two_pi * q / _CLOSEUP_PHASES
        psi21 = psi20 + two_pi * qr / _CLOSEUP_REL_PHASES
        vt = _CLOSEUP_VIEW_STEP_RAD * round(float(view[i]) / _CLOSEUP_VIEW_STEP_RAD)
        amp20 = round(float(osc["amp_axisymmetric"][i]), 4)
        amp21 = round(float(osc["amp_transverse"][i]), 4)
        key = (a_q, w_r, fall_r, vt, amp20, amp21, q, qr, qa, light_key, float(exposure_s))
        streak = None if cache is None else cache.get(key)
        if streak is None:
            streak = cached_closeup_streak(
                a_q, length_px=fall_r + w_r, width_px=float(w_r), light_dir=light_key, view_theta=vt,
                exposure_s=float(exposure_s), amp_axisymmetric=amp20, amp_transverse=amp21,
                phase_axisymmetric=psi20, phase_transverse=psi21,
                transverse_azimuth=math.pi * qa / _CLOSEUP_AZIMUTHS, supersample=2,
                time_samples_per_px=1.0, **lighting)
            if cache is not None:
                if len(cache) >= 1024:
                    cache.clear()
                cache[key] = streak
        # affine map from the traced patch (col, row) to the image (x, y)
        scale_c = width / w_r
        scale_a = length / streak.fall_px if streak.fall_px > 0 and length > 1e-6 else scale_c
        u = seg / length if length > 1e-6 else np.array([0.0, 1.0])
        nrm = np.array([u[1], -u[0]])
        cs = np.asarray(streak.centre_start_px, dtype=np.float64)
        anchor = p0[i]
        if streak.fall_px <= 0:          # a fall shorter than the trace's quantum: the still drop, mid-way
            anchor = 0.5 * (p0[i] + p1[i])
        lin = np.stack([nrm * scale_c, u * scale_a], axis=1)            # columns: patch x, patch y
        h_p, w_p = streak.coverage.shape
        corners = np.array([[-0.5, -0.5], [w_p - 0.5, -0.5], [-0.5, h_p - 0.5], [w_p - 0.5, h_p - 0.5]])
        img_corners = (corners - cs) @ lin.T + anchor
        kernel = _pillbox_kernel(blur[i]) if blur[i] >= 1.0 else None
        margin = 2 + (kernel.shape[0] // 2 if kernel is not None else 0)
        x0 = int(math.floor(img_corners[:, 0].min())) - margin
        y0 = int(math.floor(img_corners[:, 1].min())) - margin
        x1 = int(math.ceil(img_corners[:, 0].max())) + margin
        y1 = int(math.ceil(img_corners[:, 1].max())) + margin
        if x1 < 0 or y1 < 0 or x0 >= n or y0 >= m:
            continue
        mat = np.concatenate([lin, (anchor - lin @ cs - np.array([x0, y0]))[:, None]], axis=1)
        size = (x1 - x0 + 1, y1 - y0 + 1)
        cov = cv2.warpAffine(np.ascontiguousarray(streak.coverage, np.float32), mat, size,
                             flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        rad = cv2.warpAffine(np.ascontiguousarray(streak.radiance, np.float32), mat, size,
                             flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        area = math.pi * a_i[i] ** 2
        c_sum = float(cov.sum(dtype=np.float64))
        r_sum = float(rad.sum(dtype=np.float64))
        if c_sum <= 0:
            continue
        cov *= np.float32(area / c_sum)
        if r_sum > 0:
            rad *= np.float32(e_r * area / r_sum)
        if kernel is not None:
            cov = cv2.filter2D(cov, -1, kernel, borderType=cv2.BORDER_CONSTANT)
            rad = cv2.filter2D(rad, -1, kernel, borderType=cv2.BORDER_CONSTANT)
        ya, yb, xa, xb = max(y0, 0), min(y1, m - 1), max(x0, 0), min(x1, n - 1)
        if ya <= yb and xa <= xb:
            coverage[ya:yb + 1, xa:xb + 1] += cov[ya - y0:yb - y0 + 1, xa - x0:xb - x0 + 1]
            radiance[ya:yb + 1, xa:xb + 1] += rad[ya - y0:yb - y0 + 1, xa - x0:xb - x0 + 1]
        info["period_px"][i] = length / (float(exposure_s) * freq)
        info["frequency_hz"][i] = freq
        info["render_width_px"][i] = w_r
        info["render_fall_px"][i] = streak.fall_px
        info["raw_area_ratio"][i] = float(streak.coverage.sum(dtype=np.float64)) / (math.pi * (w_r / 2.0) ** 2)
        info["phase_index"][i] = q
    return coverage, radiance, info


# ============================================================================ visibility
def _peak_delta_dn(d_m, z_m, v_m_s, *, f, exposure_s, blur, contrast):
    """Intensity change inside the uniformly spread, defocused streak [gray levels]."""
    a_i = f * (0.5 * d_m) / z_m
    w = np.maximum(2.0 * a_i, 1.0)
    r = 0.5 * (w + blur)
    length = f * v_m_s * exposure_s / z_m
    return contrast * math.pi * a_i ** 2 / (2.0 * r * length + math.pi * r * r)


def visible_depth_range(diameter_m, velocity_m_s, *, focal_length_px, exposure_s, f_number,
                        focus_distance_m, pixel_pitch_m, contrast_dn,
                        threshold_dn=DEFAULT_RENDER_THRESHOLD_DN, near_m=DEFAULT_NEAR_LIMIT_M,
                        far_m=FAR_LIMIT_M, n_grid=700):
    """Depths where a drop can change a pixel by ``threshold_dn``: the rain-visible region (Sec. 6.1).

    The change is that of a pixel inside the defocused streak (Eqs. 21-24 with
    uniform spreading over the capsule, see the module Notes) at the largest
    contrast |E_r - I_b| the background allows.

    Parameters
    ----------
    diameter_m, velocity_m_s : array_like, shape (K,)
        Drop diameters [m] and fall speeds [m/s].
    focal_length_px, exposure_s, f_number, focus_distance_m, pixel_pitch_m : float
        Camera [px, s, -, m, m].
    contrast_dn : float
        Largest |E_r - I_b| [gray levels].
    threshold_dn : float
        Smallest change worth drawing [gray levels].
    near_m, far_m : float
        Depth limits considered [m].
    n_grid : int
        Log-spaced depth samples.

    Returns
    -------
    z_lo, z_hi : ndarray, shape (K,)
        Depth range [m]; NaN where the drop is nowhere visible.
    """
    from raingauge.physics.camera import blur_circle_px

    d = np.atleast_1d(np.asarray(diameter_m, dtype=np.float64))
    v = np.atleast_1d(np.asarray(velocity_m_s, dtype=np.float64))
    z = np.geomspace(near_m, far_m, int(n_grid))
    b = blur_circle_px(z, focal_length_px=focal_length_px, f_number=f_number,
                       focus_distance_m=focus_distance_m, pixel_pitch_m=pixel_pitch_m)
    dz = d[:, None]
    delta = _peak_delta_dn(dz, z[None, :], v[:, None], f=float(focal_length_px), exposure_s=exposure_s,
                           blur=b[None, :], contrast=float(contrast_dn))
    vis = delta >= threshold_dn
    any_vis = vis.any(axis=1)
    first = np.argmax(vis, axis=1)
    last = z.size - 1 - np.argmax(vis[:, ::-1], axis=1)
    # one grid step of safety on each side
    lo = z[np.maximum(first - 1, 0)]
    hi = z[np.minimum(last + 1, z.size - 1)]
    lo = np.where(first == 0, near_m, lo)
    return np.where(any_vis, lo, np.nan), np.where(any_vis, hi, np.nan)


# ============================================================================ the rain volume
class _Regions:
    """Convex generation regions, one per diameter bin (arrays over bins).

    Region b: z in [z0, z1], x in [sx0 z + ox0, sx1 z + ox1], y in [sy0 z + oy0, sy1 z + oy1]
    (a slice of the viewing frustum widened by a margin, or a box when the slopes are 0).
    """

    def __init__(self, z0, z1, sx0, ox0, sx1, ox1, sy0, oy0, sy1, oy1):
        arr = lambda v: np.asarray(v, dtype=np.float64) * np.ones(np.shape(z0))  # noqa: E731
        self.z0, self.z1 = arr(z0), arr(z1)
        self.sx0, self.ox0, self.sx1, self.ox1 = arr(sx0), arr(ox0), arr(sx1), arr(ox1)
        self.sy0, self.oy0, self.sy1, self.oy1 = arr(sy0), arr(oy0), arr(sy1), arr(oy1)
        k = self.z0.size
        one, zero = np.ones(k), np.zeros(k)
        # half-spaces n . p <= c: near, far, left, right, top, bottom
        self.normals = np.stack([
            np.stack([zero, zero, -one], 1), np.stack([zero, zero, one], 1),
            np.stack([-one, zero, self.sx0], 1), np.stack([one, zero, -self.sx1], 1),
            np.stack([zero, -one, self.sy0], 1), np.stack([zero, one, -self.sy1], 1)], axis=1)   # (K, 6, 3)
        self.offsets = np.stack([-self.z0, self.z1, -self.ox0, self.ox1, -self.oy0, self.oy1], axis=1)
        self.dxs, self.dxo = self.sx1 - self.sx0, self.ox1 - self.ox0
        self.dys, self.dyo = self.sy1 - self.sy0, self.oy1 - self.oy0
        za, zb = self.z0, self.z1
        p2, p1, p0 = self.dxs * self.dys, self.dxs * self.dyo + self.dys * self.dxo, self.dxo * self.dyo
        self.volume = p2 / 3 * (zb ** 3 - za ** 3) + p1 / 2 * (zb ** 2 - za ** 2) + p0 * (zb - za)
        zlen = zb - za
        int_dy = self.dys / 2 * (zb ** 2 - za ** 2) + self.dyo * zlen
        int_dx = self.dxs / 2 * (zb ** 2 - za ** 2) + self.dxo * zlen
        near = (self.dxs * za + self.dxo) * (self.dys * za + self.dyo)
        far = (self.dxs * zb + self.dxo) * (self.dys * zb + self.dyo)
        #: per face F with inflow rate = density x F x max(0, -v . n)  (|n| cancels the slant)
        self.face_measure = np.stack([near, far, int_dy, int_dy, int_dx, int_dx], axis=1)   # (K, 6)

    @staticmethod
    def _linear_z(z0, z1, alpha, beta, u):
        """Depths with density proportional to alpha z + beta on [z0, z1] (arrays), from uniforms u."""
        total = alpha / 2 * (z1 ** 2 - z0 ** 2) + beta * (z1 - z0)
        c = alpha / 2 * z0 ** 2 + beta * z0 + u * total
        flat = np.abs(alpha) * (z1 - z0) < 1e-9 * np.maximum(np.abs(beta), 1e-300)
        safe = np.where(flat, 1.0, alpha)
        z = (-beta + np.sqrt(np.maximum(beta * beta + 2 * alpha * c, 0.0))) / safe
        return np.clip(np.where(flat, z0 + u * (z1 - z0), z), z0, z1)

    def sample_inside(self, bins, rng):
        """Uniform points inside the regions of ``bins`` (one per entry)."""
        out = np.empty((bins.size, 3))
        pending = np.arange(bins.size)
        while pending.size:
            b = bins[pending]
            z = rng.uniform(self.z0[b], self.z1[b])
            amax = (self.dxs[b] * self.z1[b] + self.dxo[b]) * (self.dys[b] * self.z1[b] + self.dyo[b])
            area = (self.dxs[b] * z + self.dxo[b]) * (self.dys[b] * z + self.dyo[b])
            acc = rng.uniform(size=b.size) * amax < area
            b, z, idx = b[acc], z[acc], pending[acc]
            x = self.sx0[b] * z + self.ox0[b] + rng.uniform(size=b.size) * (self.dxs[b] * z + self.dxo[b])
            y = self.sy0[b] * z + self.oy0[b] + rng.uniform(size=b.size) * (self.dys[b] * z + self.dyo[b])
            out[idx] = np.stack([x, y, z], axis=1)
            pending = pending[~acc]
        return out

    def sample_face(self, bins, faces, rng):
        """Uniform points on face ``faces`` of the regions of ``bins``."""
        u1, u2 = rng.uniform(size=bins.size), rng.uniform(size=bins.size)
        b = bins
        z0, z1 = self.z0[b], self.z1[b]
        side_x = (faces == 2) | (faces == 3)
        side_y = (faces == 4) | (faces == 5)
        zx = self._linear_z(z0, z1, self.dys[b], self.dyo[b], u1)     # side faces: density ~ height
        zy = self._linear_z(z0, z1, self.dxs[b], self.dxo[b], u1)     # top/bottom: density ~ width
        z = np.where(faces == 0, z0, np.where(faces == 1, z1, np.where(side_x, zx, zy)))
        xlo, dx = self.sx0[b] * z + self.ox0[b], self.dxs[b] * z + self.dxo[b]
        ylo, dy = self.sy0[b] * z + self.oy0[b], self.dys[b] * z + self.dyo[b]
        x = np.where(side_x, np.where(faces == 2, xlo, xlo + dx), xlo + np.where(side_y, u2, u1) * dx)
        y = np.where(side_y, np.where(faces == 4, ylo, ylo + dy), ylo + u2 * dy)
        return np.stack([x, y, z], axis=1)

    def exit_after(self, bins, points, vel):
        """Time until each point of ``bins``' regions, moving at ``vel``, leaves it [s]."""
        n = self.normals[bins]                               # (m, 6, 3)
        nv = np.einsum("mfk,mk->mf", n, vel)
        gap = self.offsets[bins] - np.einsum("mfk,mk->mf", n, points)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(nv > 1e-15, gap / nv, np.inf)
        return np.maximum(s.min(axis=1), 0.0)


@dataclasses.dataclass
class _Segment:
    """Rain with a constant DSD over [t0, t1)."""
    t0: float
    t1: float
    n_bin_m3: np.ndarray         # (K,) drops per m^3 in each fine bin
    sub_cdf: np.ndarray          # (K, S) cumulative weights of sub-intervals (normalised)
    nominal_rate_mm_h: float | None
    label: str


def _fine_bins(d_lo: float, d_hi: float) -> np.ndarray:
    """Diameter bin edges [m]: the Parsivel classes split in four, clipped to [d_lo, d_hi]."""
    e = _drops.PARSIVEL_D_EDGES_MM * 1e-3
    fine = np.concatenate([np.linspace(e[i], e[i + 1], 5)[:-1] for i in range(e.size - 1)] + [[e[-1]]])
    fine = fine[(fine > d_lo) & (fine < d_hi)]
    return np.concatenate([[d_lo], fine, [d_hi]])


def _segment_from_dsd(dsd, edges, t0, t1, nominal, label, n_sub=8):
    lo, hi = edges[:-1], edges[1:]
    t = (np.arange(n_sub) + 0.5) / n_sub
    mids = lo[:, None] + (hi - lo)[:, None] * t[None, :]
    dens = np.asarray(dsd.number_density(mids), dtype=np.float64)
    dens = np.where(np.isfinite(dens) & (dens > 0), dens, 0.0)
    w = dens * ((hi - lo) / n_sub)[:, None]
    n_bin = w.sum(axis=1)
    cdf = np.cumsum(w, axis=1)
    cdf = np.where(n_bin[:, None] > 0, cdf / np.where(n_bin > 0, n_bin, 1.0)[:, None],
                   (np.arange(1, n_sub + 1) / n_sub)[None, :])
    return _Segment(float(t0), float(t1), n_bin, cdf, nominal, label)


class RainVolume:
    """Drops in front of a camera: Poisson in space, persistent, moving with their velocity.

    Parameters
    ----------
    segments : list of _Segment
        Piecewise-constant DSD in time (fine diameter bins ``edges``).
    edges : ndarray
        Diameter bin edges [m].
    regions : _Regions
        Generation region of each bin.
    velocity_model : str
        Fall-velocity law (:func:`raingauge.physics.drops.fall_velocity`).
    wind_m_s : (float, float)
        Horizontal wind (v_x, v_z) in the camera frame [m/s].
    rng : numpy.random.Generator
    """

    def __init__(self, segments, edges, regions, *, velocity_model, wind_m_s, rng):
        self.segments = segments
        self.edges = edges
        self.regions = regions
        self.velocity_model = velocity_model
        self.wind = (float(wind_m_s[0]), float(wind_m_s[1]))
        self.rng = rng
        self.k = edges.size - 1
        v_edges = _drops.fall_velocity(edges, velocity_model)
        self.v_max_bin = np.fmax(v_edges[:-1], v_edges[1:])
        self._next_id = 0
        self._pool = {"id": np.zeros(0, np.int64), "d": np.zeros(0), "pe": np.zeros((0, 3)),
                      "vel": np.zeros((0, 3)), "te": np.zeros(0), "tx": np.zeros(0),
                      "bin": np.zeros(0, np.int32)}
        self.generated_until = 0.0
        self.n_generated = 0
        self._fill_initial()

    def _segment_at(self, t):
        for seg in self.segments:
            if seg.t0 <= t < seg.t1:
                return seg
        return self.segments[-1]

    def _sample_d(self, seg, bins):
        sub = seg.sub_cdf[bins]                       # (n, S)
        u = self.rng.uniform(size=bins.size)
        j = (u[:, None] > sub).sum(axis=1)
        j = np.minimum(j, sub.shape[1] - 1)
        frac = (j + self.rng.uniform(size=bins.size)) / sub.shape[1]
        lo, hi = self.edges[bins], self.edges[bins + 1]
        return lo + frac * (hi - lo)

    def _velocities(self, d):
        v = _drops.fall_velocity(d, self.velocity_model)
        return np.stack([np.full(d.size, self.wind[0]), v, np.full(d.size, self.wind[1])], axis=1)

    def _add(self, d, pe, vel, te, bins):
        tx = te + self.regions.exit_after(bins, pe, vel)
        ids = np.arange(self._next_id, self._next_id + d.size, dtype=np.int64)
        self._next_id += d.size
        self.n_generated += d.size
        new = {"id": ids, "d": d, "pe": pe, "vel": vel, "te": te, "tx": tx, "bin": bins.astype(np.int32)}
        for key in self._pool:
            self._pool[key] = np.concatenate([self._pool[key], new[key]])

    def _fill_initial(self):
        seg = self._segment_at(0.0)
        lam = seg.n_bin_m3 * self.regions.volume
        counts = self.rng.poisson(np.where(lam > 0, lam, 0.0))
        bins = np.repeat(np.arange(self.k), counts)
        if bins.size == 0:
            return
        pe = self.regions.sample_inside(bins, self.rng)
        d = self._sample_d(seg, bins)
        self._add(d, pe, self._velocities(d), np.zeros(d.size), bins)

    def _inflow(self, t0, t1):
        seg = self._segment_at(t0)
        wx, wz = self.wind
        n = self.regions.normals                                  # (K, 6, 3)
        # bound of max(0, -v . n) over each bin: v_y in [0, v_max]
        phi_max = np.maximum(0.0, -(wx * n[:, :, 0] + wz * n[:, :, 2])
                             - np.minimum(0.0, self.v_max_bin[:, None] * n[:, :, 1]))
        lam = seg.n_bin_m3[:, None] * self.regions.face_measure * phi_max * (t1 - t0)
        counts = self.rng.poisson(np.where(np.isfinite(lam) & (lam > 0), lam, 0.0)).ravel()
        cand = np.repeat(np.arange(counts.size), counts)
        if cand.size == 0:
            return
        bins, faces = cand // 6, cand % 6
        d = self._sample_d(seg, bins)
        vel = self._velocities(d)
        phi = np.maximum(0.0, -np.einsum("mk,mk->m", vel, n[bins, faces]))
        keep = self.rng.uniform(size=cand.size) * phi_max[bins, faces] < phi
        bins, faces, d, vel = bins[keep], faces[keep], d[keep], vel[keep]
        if bins.size == 0:
            return
        pe = self.regions.sample_face(bins, faces, self.rng)
        te = self.rng.uniform(t0, t1, size=bins.size)
        self._add(d, pe, vel, te, bins)

    def advance_to(self, t):
        """Generate the drops entering before time ``t`` [s]."""
        while self.generated_until < t:
            t0 = self.generated_until
            t1 = t0 + _CHUNK_S
            for seg in self.segments:          # do not straddle a change of DSD
                if t0 < seg.t1 < t1:
                    t1 = seg.t1
            self._inflow(t0, t1)
            self.generated_until = t1

    def forget_before(self, t):
        """Drop the drops that left the volume before ``t`` [s]."""
        keep = self._pool["tx"] >= t
        if not np.all(keep):
            for key in self._pool:
                self._pool[key] = self._pool[key][keep]

    def alive(self, t0, t1):
        """Indices (into :meth:`columns`) of drops inside their region at some time in [t0, t1]."""
        self.advance_to(t1)
        p = self._pool
        return np.nonzero((p["te"] <= t1) & (p["tx"] >= t0))[0]

    def positions(self, idx, t):
        p = self._pool
        return p["pe"][idx] + p["vel"][idx] * (t - p["te"][idx])[:, None]

    @property
    def columns(self):
        return self._pool


# ============================================================================ per-frame truth
class DropTable:
    """Per-frame drop list in columns; also iterable as one dict per drop.

    ``table["radius_m"]`` gives a column (ndarray), ``table[i]`` or iteration a
    dict per drop with the keys of :attr:`COLUMNS`.
    """

    COLUMNS = ("id", "position_m", "radius_m", "diameter_m", "velocity_m_s", "streak_px",
               "depth_m", "width_px", "blur_px", "beta", "tau_s")

    def __init__(self, columns: dict):
        self._c = columns

    def __len__(self):
        return int(self._c["id"].size)

    def __getitem__(self, key):
        if isinstance(key, str):
            return self._c[key]
        return {k: (self._c[k][key].tolist() if np.ndim(self._c[k][key]) else self._c[k][key].item())
                for k in self.COLUMNS}

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def keys(self):
        return self.COLUMNS

    def to_json(self) -> dict:
        return {k: np.round(self._c[k], 9).tolist() for k in self.COLUMNS}


# ============================================================================ the simulation
class _Sensor:
    """Radiometric response, noise, 8-bit quantisation, optional JPEG."""

    def __init__(self, profile, *, noise_sigma_dn, jpeg_quality, rng):
        self.linear = profile.is_linear
        self.table = np.asarray(profile.response_table, dtype=np.float64)
        self.sigma = float(noise_sigma_dn)
        self.jpeg = jpeg_quality
        self.rng = rng
        self._noise = None

    def codes_float(self, linear):
        if self.linear:
            return np.asarray(linear, dtype=np.float32)
        return np.interp(linear, self.table, np.arange(256.0)).astype(np.float32)

    def __call__(self, linear, *, owned=False):
        """8-bit frame from linear intensity (``owned``: ``linear`` may be overwritten)."""
        import cv2

        x = self.codes_float(linear)
        if x is linear and not owned:
            x = x.copy()
        if self.sigma > 0:
            if self._noise is None or self._noise.shape != x.shape:
                self._noise = np.empty(x.shape, np.float32)
            cv2.setRNGSeed(int(self.rng.integers(0, 2 ** 31 - 1)))
            cv2.randn(self._noise, 0.0, self.sigma)
            x += self._noise
        np.maximum(x, 0.0, out=x)
        out = cv2.convertScaleAbs(x)   # rounds to nearest, saturates at 255
        if self.jpeg is not None:
            ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(self.jpeg)])
            out = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
        return out


def _parse_time(start):
    if start is None:
        return None
    if isinstance(start, datetime):
        return start if start.tzinfo else start.replace(tzinfo=timezone.utc)
    text = str(start).strip().replace("Z", "+00:00")
    for fmt in (None, "%d-%m-%Y %H:%M:%S", "%Y-%m-%d %H:%M"):
        try:
            t = datetime.fromisoformat(text) if fmt is None else datetime.strptime(text, fmt)
        except ValueError:
            continue
        return t if t.tzinfo else t.replace(tzinfo=timezone.utc)
    raise ConfigError(f"start time {start!r} not understood. Fix: use ISO format, e.g. 2018-10-29T06:00:00")


class Simulation:
    """A rain clip being rendered: iterate for ``(frame_uint8, frame_truth)``.

    Built by :func:`simulate`; see there for the parameters.  ``truth`` is the
    clip's ground truth (dict, JSON-ready); reading it before iterating runs
    the rain volume (without drawing) to compute it.
    """

    def __init__(self, profile, *, n_frames, segments, edges, velocity_model, wind, scene,
                 seed, truth_masks, truth_clean, truth_drops, truth_linear, drop_brightness_dn, render_threshold_dn,
                 depth_range_m, reference_depth_m, truth_window_s, jpeg_quality, noise, pixel_pitch_m,
                 assumptions, rain_description, window_edges=None, closeup=False, closeup_light=None,
                 closeup_min_width_px=CLOSEUP_MIN_WIDTH_PX, closeup_max_blur_ratio=CLOSEUP_MAX_BLUR_RATIO):
        self.profile = profile
        self.n_frames = int(n_frames)
        self.segments = segments
        self.edges = edges
        self.velocity_model = velocity_model
        self.wind = wind
        self.scene = scene
        self.seed = seed
        self.truth_masks = truth_masks
        self.truth_clean = truth_clean
        self.truth_drops = truth_drops
        self.truth_linear = truth_linear
        self.e_r = float(drop_brightness_dn)
        self.threshold = float(render_threshold_dn)
        self.pitch = float(pixel_pitch_m)
        self.jpeg = jpeg_quality
        self.noise = noise
        self.assumptions = assumptions
        self.rain_description = rain_description
        self.fps = profile.frame_rate_hz
        self.T = profile.exposure_s
        self.seconds = self.n_frames / self.fps
        f = profile.focal_length_px
        cx, cy = profile.principal_point
        self.f, self.cx, self.cy = f, cx, cy
        m, n = profile.shape
        self.sx0, self.sx1 = (-0.5 - cx) / f, (n - 0.5 - cx) / f
        self.sy0, self.sy1 = (-0.5 - cy) / f, (m - 0.5 - cy) / f
        z0 = profile.focus_distance_m
        # reference volume: the frustum's cross-section at its near end, extruded in depth
        if reference_depth_m is None:
            reference_depth_m = (0.8 * z0, 1.25 * z0)
        zr0, zr1 = (float(v) for v in reference_depth_m)
        if not (0 < zr0 < zr1):
            raise ConfigError(f"reference_depth_m must be (near, far) with 0 < near < far, got {reference_depth_m!r}")
        self.ref_box = np.array([[self.sx0 * zr0, self.sx1 * zr0], [self.sy0 * zr0, self.sy1 * zr0], [zr0, zr1]])
        self.ref_volume = float(np.prod(self.ref_box[:, 1] - self.ref_box[:, 0]))
        # rain-visible ranges per bin
        d_hi_bin = edges[1:]
        v_hi = _drops.fall_velocity(d_hi_bin, velocity_model)
        v_lo = _drops.fall_velocity(edges[:-1], velocity_model)
        lo_bg, hi_bg = scene.bounds()
        self.contrast = max(abs(self.e_r - lo_bg), abs(self.e_r - hi_bg), 1e-6)
        self.depth_override = depth_range_m is not None
        if depth_range_m is not None:
            zl, zh = (float(v) for v in depth_range_m)
            if not (0 < zl < zh):
                raise ConfigError(f"depth_range_m must be (near, far) with 0 < near < far, got {depth_range_m!r}")
            self.z_lo = np.full(edges.size - 1, zl)
            self.z_hi = np.full(edges.size - 1, zh)
        else:
            self.z_lo, self.z_hi = visible_depth_range(
                d_hi_bin, np.fmin(v_hi, v_lo), focal_length_px=f, exposure_s=self.T,
                f_number=profile.f_number, focus_distance_m=z0, pixel_pitch_m=self.pitch,
                contrast_dn=self.contrast, threshold_dn=self.threshold)
        # generation regions: visible range plus the reference volume
        from raingauge.physics.camera import blur_circle_px

        k = edges.size - 1
        self.margins = np.zeros(k)
        g0, g1 = np.full(k, zr0), np.full(k, zr1)
        for b in range(k):
            zl, zh = self.z_lo[b], self.z_hi[b]
            if np.isfinite(zl):
                zg = np.geomspace(zl, zh, 200)
                a_i = f * 0.5 * d_hi_bin[b] / zg
                bl = blur_circle_px(zg, focal_length_px=f, f_number=profile.f_number,
                                    focus_distance_m=z0, pixel_pitch_m=self.pitch)
                r_eff = 0.5 * (np.maximum(2 * a_i, 1.0) + bl) + 2.0
                self.margins[b] = float(np.max(r_eff * zg / f))
                g0[b], g1[b] = min(zl, zr0), max(zh, zr1)
        mg = self.margins
        self.regions = _Regions(g0, g1, self.sx0, -mg, self.sx1, mg, self.sy0, -mg, self.sy1, mg)
        # truth windows
        if window_edges is None:
            w = float(truth_window_s)
            if not w > 0:
                raise ConfigError(f"truth_window_s must be > 0, got {truth_window_s!r}")
            k = max(1, int(math.ceil(self.seconds / w - 1e-9)))
            window_edges = [min(i * w, self.seconds) for i in range(k + 1)]
        self.window_edges = np.asarray(window_edges, dtype=float)
        self._truth = None
        self._children = np.random.SeedSequence(seed).spawn(3)
        self.closeup = bool(closeup)
        self.closeup_light = None if closeup_light is None else tuple(float(v) for v in closeup_light)
        self.closeup_min_width = float(closeup_min_width_px)
        self.closeup_max_blur = float(closeup_max_blur_ratio)
        self._closeup_cache = {}

    @property
    def reference_box_m(self) -> np.ndarray:
        """The truth's reference volume, [[x0, x1], [y0, y1], [z0, z1]] in the camera frame [m]."""
        return self.ref_box.copy()

    @property
    def reference_volume_m3(self) -> float:
        """Volume of the reference box [m^3]."""
        return self.ref_volume

    # ---------------------------------------------------------------- internals
    def _rngs(self):
        rain, noise, _ = (np.random.default_rng(s) for s in self._children)
        return rain, noise

    def _new_volume(self, rng):
        return RainVolume(self.segments, self.edges, self.regions, velocity_model=self.velocity_model,
                          wind_m_s=self.wind, rng=rng)

    def _frame_drops(self, vol, k):
        """Drops drawn in frame k and their streaks."""
        t0 = k / self.fps
        idx = vol.alive(t0, t0 + self.T)
        cols = vol.columns
        pa = vol.positions(idx, t0)
        pb = pa + cols["vel"][idx] * self.T
        zm = 0.5 * (pa[:, 2] + pb[:, 2])
        b = cols["bin"][idx]
        vis = (zm >= self.z_lo[b]) & (zm <= self.z_hi[b]) & (pa[:, 2] > 1e-3) & (pb[:, 2] > 1e-3)
        idx, pa, pb = idx[vis], pa[vis], pb[vis]
        caps = streak_capsules(pa, pb, 0.5 * cols["d"][idx], focal_length_px=self.f,
                               principal_point_px=(self.cx, self.cy), f_number=self.profile.f_number,
                               focus_distance_m=self.profile.focus_distance_m, pixel_pitch_m=self.pitch)
        m, n = self.profile.shape
        r = caps["radius_px"]
        xs = np.stack([caps["p0"][:, 0], caps["p1"][:, 0]])
        ys = np.stack([caps["p0"][:, 1], caps["p1"][:, 1]])
        on = ((xs.max(0) + r > -0.5) & (xs.min(0) - r < n - 0.5)
              & (ys.max(0) + r > -0.5) & (ys.min(0) - r < m - 0.5))
        caps = {key: val[on] for key, val in caps.items()}
        return idx[on], pa[on], caps

    def _snapshot(self, vol, t):
        """Diameters and fall speeds of the drops inside the reference volume at time t."""
        p = vol.columns
        live = np.nonzero((p["te"] <= t) & (p["tx"] >= t))[0]
        pos = vol.positions(live, t)
        box = self.ref_box
        inside = np.all((pos >= box[:, 0]) & (pos < box[:, 1]), axis=1)
        sel = live[inside]
        return p["d"][sel], p["vel"][sel, 1]

    # ---------------------------------------------------------------- truth
    def _truth_accumulator(self):
        nw = self.window_edges.size - 1
        return {"rate_sum": np.zeros(nw), "snaps": np.zeros(nw, np.int64),
                "counts": np.zeros((nw, 32)), "drops": np.zeros(nw, np.int64),
                "moments": np.zeros((nw, 4))}

    def _accumulate(self, acc, vol, k):
        t = k / self.fps + 0.5 * self.T
        d, v = self._snapshot(vol, t)
        w = int(np.clip(np.searchsorted(self.window_edges, k / self.fps, side="right") - 1,
                        0, self.window_edges.size - 2))
        acc["rate_sum"][w] += _drops.rain_rate_from_drops(d, v, self.ref_volume)
        acc["snaps"][w] += 1
        acc["drops"][w] += d.size
        dmm = d * 1e3
        acc["moments"][w] += [np.sum(dmm ** 3), np.sum(dmm ** 4), np.sum(dmm ** 6), 0.0]
        cls = np.searchsorted(_drops.PARSIVEL_D_EDGES_MM * 1e-3, d, side="right") - 1
        ok = (cls >= 0) & (cls < 32)
        acc["counts"][w] += np.bincount(cls[ok], minlength=32)[:32]
        return d.size

    def _finish_truth(self, acc, n_generated):
        widths = _drops.PARSIVEL_D_WIDTHS_MM
        windows = []
        total_rate = 0.0
        total_snaps = 0
        for i in range(self.window_edges.size - 1):
            s = int(acc["snaps"][i])
            if s == 0:
                continue
            rate = acc["rate_sum"][i] / s
            total_rate += acc["rate_sum"][i]
            total_snaps += s
            n_m3_mm = acc["counts"][i] / s / self.ref_volume / widths
            t0, t1 = float(self.window_edges[i]), float(self.window_edges[i + 1])
            nominal = self._nominal_rate(t0, t1)
            m3, m4, m6, _ = acc["moments"][i] / s / self.ref_volume       # mm^k m^-3
            z = float(m6)
            windows.append({
                "t_start_s": t0, "t_end_s": t1, "rain_rate_mm_h": float(rate),
                "dsd_d_mm": _drops.PARSIVEL_D_CENTRES_MM.tolist(),
                "dsd_n_m3_mm": [float(x) for x in n_m3_mm],
                "nt_m3": float(acc["drops"][i] / s / self.ref_volume),
                "lwc_g_m3": float(math.pi / 6.0 * m3 * 1e-9 * _drops.RHO_WATER * 1e3),
                "z_mm6_m3": z, "z_dbz": (10.0 * math.log10(z) if z > 0 else None),
                "dm_mm": (float(m4 / m3) if m3 > 0 else None),
                "snapshots": s, "mean_drops_in_reference": float(acc["drops"][i] / s),
                "nominal_rain_rate_mm_h": nominal,
                "ratio_to_nominal": (float(rate / nominal) if nominal else None),
            })
        rate = total_rate / total_snaps if total_snaps else 0.0
        nominal = self._nominal_rate(0.0, self.seconds)
        prof = self.profile.to_dict()
        if self.profile.pixel_pitch_m is None:
            prof["pixel_pitch_m_assumed"] = self.pitch
        truth = {
            "camera": prof,
            "n_frames": self.n_frames,
            "frame_rate_hz": self.fps,
            "seconds": self.seconds,
            "seed": self.seed,
            "rain": self.rain_description,
            "velocity_model": self.velocity_model,
            "wind_m_s": [self.wind[0], 0.0, self.wind[1]],
            "scene": self.scene.describe(),
            "drop_brightness_dn": self.e_r,
            "rain_rate_mm_h": float(rate),
            "accumulation_mm": float(rate * self.seconds / 3600.0),
            "nominal_rain_rate_mm_h": nominal,
            "ratio_to_nominal": (float(rate / nominal) if nominal else None),
            "rate_method": "Eq. (28) on the drops inside the reference volume at mid-exposure of every "
                           "frame (raingauge.physics.drops.rain_rate_from_drops), averaged",
            "reference_volume": {"box_m": self.ref_box.tolist(), "volume_m3": self.ref_volume},
            "windows": windows,
            "drops_generated": int(n_generated),
            "rendering": {
                "render_threshold_dn": self.threshold,
                "depth_range_override_m": ([float(self.z_lo[0]), float(self.z_hi[0])]
                                           if self.depth_override else None),
                "contrast_dn": self.contrast,
                "note": ("drops are generated in the reference volume for every diameter and elsewhere "
                         "only where they can change a pixel by at least render_threshold_dn "
                         "(visible_depth_m per diameter bin)"),
                "bin_edges_mm": (self.edges * 1e3).round(6).tolist(),
                "visible_depth_m": [[None if not np.isfinite(a) else float(a),
                                     None if not np.isfinite(b) else float(b)]
                                    for a, b in zip(self.z_lo, self.z_hi)],
            },
            "assumptions": self.assumptions,
        }
        if self.closeup:
            self._closeup_truth(truth)
        return truth

    def _closeup_truth(self, truth):
        truth["rendering"]["closeup"] = {
            "rule": "drops with focused width 2 f a / z >= min_width_px and blur circle <= max_blur_ratio x "
                    "that width are drawn as ray-traced streaks of oscillating drops (Sec. 9), normalised to "
                    "the uniform model's exposure area pi a_i^2 and mean brightness E_r",
            "min_width_px": self.closeup_min_width, "max_blur_ratio": self.closeup_max_blur,
            "light_theta_phi_rad": None if self.closeup_light is None else list(self.closeup_light),
            "light_to_sky": None if self.closeup_light is None else CLOSEUP_LIGHT_TO_SKY,
        }

    def _nominal_rate(self, t0, t1):
        vals, wts = [], []
        for seg in self.segments:
            o = min(t1, seg.t1) - max(t0, seg.t0)
            if o > 0 and seg.nominal_rate_mm_h is not None:
                vals.append(seg.nominal_rate_mm_h)
                wts.append(o)
        if not wts:
            return None
        return float(np.average(vals, weights=wts))

    @property
    def truth(self) -> dict:
        """The clip's ground truth (computed by a drawing-free pass if not yet iterated)."""
        if self._truth is None:
            rain_rng, _ = self._rngs()
            vol = self._new_volume(rain_rng)
            acc = self._truth_accumulator()
            for k in range(self.n_frames):
                vol.advance_to(k / self.fps + self.T)
                self._accumulate(acc, vol, k)
                if k % 32 == 31:
                    vol.forget_before(k / self.fps)
            self._truth = self._finish_truth(acc, vol.n_generated)
        return self._truth

    def population(self, times_s) -> Iterator[dict]:
        """The generated drops alive at each time (ascending), whether drawn or not.

        Yields, per time, a dict of ``id``, ``diameter_m`` (n,), ``position_m``
        (n, 3) and ``velocity_m_s`` (n, 3): the same drops the frames show (same
        seed), including those generated only for the reference volume.
        """
        rain_rng, _ = self._rngs()
        vol = self._new_volume(rain_rng)
        last = -np.inf
        for t in times_s:
            t = float(t)
            if t < last:
                raise ValueError("population(): times must be ascending")
            last = t
            vol.advance_to(t)
            p = vol.columns
            live = np.nonzero((p["te"] <= t) & (p["tx"] >= t))[0]
            yield {"id": p["id"][live], "diameter_m": p["d"][live], "position_m": vol.positions(live, t),
                   "velocity_m_s": p["vel"][live]}
            vol.forget_before(t)

    # ---------------------------------------------------------------- frames
    def _draw_closeup(self, lin, bg, vol, k, ids_idx, pa, caps):
        """Add the close-up streaks of drops ``ids_idx`` to the linear frame ``lin`` (in place)."""
        cols = vol.columns
        ids = cols["id"][ids_idx]
        osc = closeup_oscillations(ids, self._children[2])
        mid = pa + 0.5 * self.T * cols["vel"][ids_idx]
        view = np.arctan2(mid[:, 1], np.hypot(mid[:, 0], mid[:, 2]))
        cov, rad, info = render_closeup_drops(
            self.profile.shape, caps["p0"], caps["p1"], 0.5 * cols["d"][ids_idx], caps["image_radius_px"],
            caps["blur_px"], exposure_s=self.T, drop_brightness_dn=self.e_r, oscillation=osc,
            start_time_s=k / self.fps, view_theta_rad=view, light=self.closeup_light,
            cache=self._closeup_cache)
        # I = I_b (1 - coverage) + radiance on top of the uniform streaks
        np.multiply(cov, bg, out=cov)
        np.subtract(rad, cov, out=rad)
        lin += rad
        np.maximum(lin, 0.0, out=lin)
        info["id"] = ids
        info["amp_axisymmetric"] = osc["amp_axisymmetric"]
        info["amp_transverse"] = osc["amp_transverse"]
        return info

    def __len__(self):
        return self.n_frames

    def __iter__(self) -> Iterator[tuple[np.ndarray, dict]]:
        rain_rng, noise_rng = self._rngs()
        vol = self._new_volume(rain_rng)
        sensor = _Sensor(self.profile, noise_sigma_dn=self.profile.noise_sigma_dn if self.noise else 0.0,
                         jpeg_quality=self.jpeg, rng=noise_rng)
        clean_sensor = _Sensor(self.profile, noise_sigma_dn=0.0, jpeg_quality=None, rng=noise_rng)
        acc = self._truth_accumulator()
        shape = self.profile.shape
        lin_buf = np.empty(shape, np.float32)
        for k in range(self.n_frames):
            idx, pa, caps = self._frame_drops(vol, k)
            near = None
            if self.closeup and idx.size:
                near = closeup_selection(2.0 * caps["image_radius_px"], caps["blur_px"],
                                         min_width_px=self.closeup_min_width,
                                         max_blur_ratio=self.closeup_max_blur)
                if not near.any():
                    near = None
            if near is None:
                beta, beta_in = render_streaks(shape, caps["p0"], caps["p1"], caps["radius_px"],
                                               caps["area_px"], _view=True)
            else:
                far = ~near
                beta, beta_far = render_streaks(shape, caps["p0"][far], caps["p1"][far], caps["radius_px"][far],
                                                caps["area_px"][far], _view=True)
                beta_in = np.empty(idx.size)
                beta_in[far] = beta_far
                # beta of the equivalent uniform capsule (Eq. 18) for the close-up drops
                r_c = caps["radius_px"][near]
                len_c = np.hypot(*(caps["p1"][near] - caps["p0"][near]).T)
                beta_in[near] = caps["area_px"][near] / (2.0 * r_c * len_c + math.pi * r_c ** 2)
            bg = self.scene.frame(k)
            lin = compose_rain(bg, beta, drop_brightness_dn=self.e_r, out=lin_buf)
            closeup_info = None
            if near is not None:
                closeup_info = self._draw_closeup(lin, bg, vol, k, idx[near], pa[near],
                                                  {key: val[near] for key, val in caps.items()})
            frame = sensor(lin, owned=not (self.truth_masks or self.truth_linear))
            self._accumulate(acc, vol, k)
            ft: dict[str, Any] = {"index": k, "t_s": k / self.fps}
            if self.truth_drops:
                cols = vol.columns
                d = cols["d"][idx]
                ft["drops"] = DropTable({
                    "id": cols["id"][idx], "position_m": pa, "radius_m": 0.5 * d, "diameter_m": d,
                    "velocity_m_s": cols["vel"][idx],
                    "streak_px": np.stack([caps["p0"], caps["p1"]], axis=1),
                    "depth_m": caps["depth_m"], "width_px": caps["width_px"], "blur_px": caps["blur_px"],
                    "beta": beta_in, "tau_s": beta_in * self.T})
            if self.closeup:
                ft["closeup"] = closeup_info if closeup_info is not None else {
                    key: np.zeros(0) for key in ("id", "period_px", "frequency_hz", "render_width_px",
                                                 "render_fall_px", "raw_area_ratio", "phase_index",
                                                 "amp_axisymmetric", "amp_transverse")}
            if self.truth_linear:
                ft["linear"] = lin.copy()
                ft["linear_clean"] = bg
            if self.truth_masks or self.truth_clean:
                if self.truth_masks:
                    diff = sensor.codes_float(lin) - sensor.codes_float(bg)
                    ft["rain_mask"] = np.abs(diff) >= 1.0
                if self.truth_clean:
                    ft["clean"] = clean_sensor(bg)
            if k % 32 == 31:
                vol.forget_before(k / self.fps)
            yield frame, ft
        self._truth = self._finish_truth(acc, vol.n_generated)


# ============================================================================ entry points
def _rain_segments(*, rain_rate_mm_h, dsd, dsd_params, parsivel, start, seconds, velocity_model):
    """Time segments of the DSD, the diameter bins and a description for the truth."""
    lo_v, hi_v = _drops.FALL_VELOCITY_RANGES_M[velocity_model]
    lo_v = max(lo_v, 0.05e-3)
    if parsivel is not None:
        if rain_rate_mm_h is not None or dsd is not None:
            raise ConfigError("give either a Parsivel file or a rain rate / DSD, not both")
        try:
            from raingauge import disdrometer
        except ImportError as exc:  # pragma: no cover - the reader ships with raingauge
            raise ConfigError(f"Parsivel replay needs raingauge.disdrometer ({exc})") from None
        pf = parsivel if hasattr(parsivel, "records") else disdrometer.read_parsivel(parsivel)
        recs = sorted(pf.records, key=lambda r: r.time)
        if not recs:
            raise InputError(f"Parsivel file {parsivel}: no valid record. Fix: check the file")
        t_start = _parse_time(start)
        if t_start is None:
            i0 = 0
        else:
            i0 = next((i for i, r in enumerate(recs) if r.time >= t_start), None)
            if i0 is None:
                raise ConfigError(f"no Parsivel record at or after {t_start.isoformat()} "
                                  f"(file spans {recs[0].time.isoformat()} to {recs[-1].time.isoformat()})")
        interval = 30.0
        need = max(1, int(math.ceil(seconds / interval - 1e-9)))
        chosen = recs[i0:i0 + need]
        if len(chosen) < need:
            raise ConfigError(f"the Parsivel file holds {len(chosen)} record(s) from "
                              f"{recs[i0].time.isoformat()}, {seconds:g} s needs {need}. "
                              f"Fix: shorten --seconds or choose an earlier --start")
        edges_cls = _drops.PARSIVEL_D_EDGES_MM * 1e-3
        d_lo, d_hi = max(lo_v, edges_cls[0]), min(hi_v, edges_cls[-1])
        edges = _fine_bins(d_lo, d_hi)
        segs = []
        for i, rec in enumerate(chosen):
            n_m4 = np.asarray(disdrometer.record_density_m4(rec.counts, interval_s=interval), dtype=float)
            bd = _drops.BinnedDSD(edges_cls, np.where(np.isfinite(n_m4), n_m4, 0.0))
            segs.append(_segment_from_dsd(bd, edges, i * interval, (i + 1) * interval,
                                          float(rec.reported_rate_mm_h), rec.time.isoformat()))
        segs[-1].t1 = max(segs[-1].t1, seconds)
        desc = {"source": "parsivel", "file": str(getattr(pf, "path", parsivel)),
                "records": [r.time.isoformat() for r in chosen], "record_interval_s": interval,
                "nominal": "the Parsivel's reported intensity of each record",
                "diameter_range_mm": [d_lo * 1e3, d_hi * 1e3]}
        return segs, edges, desc, [s.t0 for s in segs] + [max(seconds, segs[-1].t0)]
    if dsd is None or isinstance(dsd, str):
        name = dsd or "marshall_palmer"
        params = dict(dsd_params or {})
        if rain_rate_mm_h is None and name in ("marshall_palmer",) and "rain_rate_mm_h" not in params:
            raise ConfigError("give a rain rate (rain_rate_mm_h / --rate) or a Parsivel file")
        if rain_rate_mm_h is not None:
            r = float(rain_rate_mm_h)
            if not (math.isfinite(r) and r >= 0):
                raise ConfigError(f"rain rate must be a finite number >= 0 mm/h, got {rain_rate_mm_h!r}")
        try:
            if name == "marshall_palmer":
                obj = _drops.MarshallPalmer(float(params.pop("rain_rate_mm_h", rain_rate_mm_h)), **params)
            elif name == "gamma" and rain_rate_mm_h is not None and "n0" not in params:
                mu = float(params.pop("mu", 3.0))
                obj = (_drops.gamma_for_rain_rate(float(rain_rate_mm_h), mu, velocity_model, **params)
                       if rain_rate_mm_h > 0 else _drops.MarshallPalmer(0.0))
            elif name == "normalized_gamma" and rain_rate_mm_h is not None and "dm_m" not in params:
                mu = float(params.pop("mu", 3.0))
                obj = (_drops.gamma_for_rain_rate(float(rain_rate_mm_h), mu, velocity_model, **params)
                       if rain_rate_mm_h > 0 else _drops.MarshallPalmer(0.0))
            else:
                obj = _drops.make_dsd(name, **params)
        except ValueError as exc:
            raise ConfigError(f"DSD {name!r}: {exc}") from None
        dsd_obj = obj
    else:
        dsd_obj = dsd
        if not hasattr(dsd_obj, "number_density"):
            raise ConfigError(f"dsd must be a DSD name or object with number_density(), got {dsd!r}")
    d_lo = max(float(dsd_obj.d_min_m), lo_v)
    d_hi = min(float(dsd_obj.d_max_m), hi_v)
    if not d_lo < d_hi:
        raise ConfigError(f"the DSD's diameter range {dsd_obj.d_min_m * 1e3:g}-{dsd_obj.d_max_m * 1e3:g} mm "
                          f"lies outside the range of velocity model {velocity_model!r}")
    edges = _fine_bins(d_lo, d_hi)
    nominal = float(rain_rate_mm_h) if rain_rate_mm_h is not None else None
    try:
        dsd_rate = _drops.rain_rate_mm_h(dsd_obj, velocity_model)
    except ValueError:
        dsd_rate = None
    seg = _segment_from_dsd(dsd_obj, edges, 0.0, max(seconds, 1e-9), nominal if nominal is not None else dsd_rate,
                            repr(dsd_obj))
    desc = {"source": "dsd", "dsd": repr(dsd_obj), "nominal_rain_rate_mm_h": nominal,
            "dsd_eq28_rain_rate_mm_h": dsd_rate, "diameter_range_mm": [d_lo * 1e3, d_hi * 1e3]}
    return [seg], edges, desc, None


def simulate(profile, *, seconds=None, n_frames=None, rain_rate_mm_h=None, dsd=None, dsd_params=None,
             parsivel=None, start=None, velocity_model="gunn_kinzer", wind_m_s=0.0, wind_dir_deg=0.0,
             background="uniform:60", motion=None, seed=0, truth_masks=False, truth_clean=False,
             truth_drops=True, truth_linear=False, drop_brightness_dn=DEFAULT_DROP_BRIGHTNESS_DN,
             render_threshold_dn=DEFAULT_RENDER_THRESHOLD_DN, depth_range_m=None, reference_depth_m=None,
             truth_window_s=10.0, jpeg_quality=None, noise=True, closeup=False, closeup_light=None,
             closeup_min_width_px=CLOSEUP_MIN_WIDTH_PX,
             closeup_max_blur_ratio=CLOSEUP_MAX_BLUR_RATIO) -> Simulation:
    """Simulate rain in front of a camera (Secs. 3, 4.3, 6 [GargNayar2007]).

    Parameters
    ----------
    profile : CameraProfile, str or Path
        The camera (a profile, a TOML path or a shipped name).
    seconds : float
        Clip length [s] (or give ``n_frames``).
    n_frames : int, optional
        Clip length in frames.
    rain_rate_mm_h : float, optional
        Nominal rain rate [mm/h] (>= 0) for the DSD.
    dsd : str or DSD, optional
        ``"marshall_palmer"`` (default), ``"gamma"`` / ``"normalized_gamma"``
        (with ``rain_rate_mm_h``: :func:`gamma_for_rain_rate`, ``dsd_params={"mu": 3}``),
        or any DSD object of :mod:`raingauge.physics.drops`.
    dsd_params : dict, optional
        Parameters of a named DSD (SI).
    parsivel : str, Path or ParsivelFile, optional
        Replay measured rain: each record's raw counts become class densities
        for its 30 s.
    start : datetime or str, optional
        First Parsivel record to replay (the first at or after this time, UTC).
    velocity_model : str
        Fall-velocity law of the drops (``raingauge.physics.drops.FALL_VELOCITY_MODELS``).
    wind_m_s : float
        Horizontal wind speed [m/s] (drops drift with it).
    wind_dir_deg : float
        Direction the wind blows to [deg]: 0 = image right, 90 = away from the camera.
    background : str or ndarray
        See :mod:`raingauge.render.scenes`.
    motion : str or list of str, optional
        Scripted scene motion (:mod:`raingauge.render.scenes`).
    seed : int
        Random seed; the same seed gives the same video.
    truth_masks : bool
        Add ``rain_mask`` (pixels changed by >= 1 gray level) to each frame's truth.
    truth_clean : bool
        Add ``clean`` (the rain-free frame after the sensor, without noise).
    truth_drops : bool
        Add ``drops`` (a :class:`DropTable`) to each frame's truth.
    truth_linear : bool
        Add ``linear`` and ``linear_clean``: the rainy and rain-free frames in
        linear intensity before the sensor (float32, gray levels).
    drop_brightness_dn : float
        E_r, the linear brightness of a drop [gray levels] (Sec. 4.2.3).
    render_threshold_dn : float
        Drops are generated (outside the reference volume) only where they can
        change a pixel by this much [gray levels].
    depth_range_m : (float, float), optional
        Generate and draw drops of every size over exactly this depth range [m]
        instead of the rain-visible region.
    reference_depth_m : (float, float), optional
        Depth range of the truth's reference volume [m] (default 0.8-1.25 z0).
    truth_window_s : float
        Length of the truth windows [s] (Parsivel replay: one window per record).
    jpeg_quality : int, optional
        Compress every frame as JPEG with this quality (1-100).
    noise : bool
        Add the profile's sensor noise.
    closeup : bool
        Draw drops near the camera whose focused image is large and sharp
        enough (:func:`closeup_selection`: 2 a_i >= ``closeup_min_width_px``,
        b_c <= ``closeup_max_blur_ratio`` x 2 a_i) as ray-traced streaks of
        oscillating drops (Sec. 9, :func:`render_closeup_drops`) instead of
        uniform capsules; each deposits the same exposure as its capsule.
        Off by default: tracing costs about 0.2 s of CPU per drawn close-up
        streak (cached for repeated quantised sizes and phases, but most
        close-up drops are new), so with the gauge-default profile at 10 mm/h
        (about one such drop per frame) the frame rate falls from ~48 to ~5
        frames/s of CPU, far more than the 10 % the default may cost
        (``benchmarks/bench_simulator.py``).
        Each frame's truth then has ``closeup`` (ids of the drops so drawn,
        their oscillation amplitudes, the fall per oscillation period
        ``period_px``, ...) and the truth's ``rendering`` the rule used.
    closeup_light : (float, float), optional
        (theta, phi) [rad] of a light :data:`CLOSEUP_LIGHT_TO_SKY` times as
        bright as the sky, in :mod:`raingauge.render.closeup`'s convention
        (theta = 0: from behind the camera, pi: behind the drop; phi from image
        right towards image up); None (default): sky only, a uniform ambient
        (the pattern is then that of the drop's oscillating outline only).
    closeup_min_width_px, closeup_max_blur_ratio : float
        The selection rule's thresholds [px], [-].

    Returns
    -------
    Simulation

    Raises
    ------
    ConfigError, InputError, ProfileError
        Impossible requests (negative rate, unreadable background, invalid profile, ...).
    """
    from raingauge.render.scenes import Scene

    profile = _resolve_profile(profile)
    fps = profile.frame_rate_hz
    if n_frames is None:
        if seconds is None:
            raise ConfigError("give the clip length: seconds or n_frames")
        seconds = float(seconds)
        if not (math.isfinite(seconds) and seconds > 0):
            raise ConfigError(f"seconds must be > 0, got {seconds!r}")
        n_frames = max(1, int(round(seconds * fps)))
    n_frames = int(n_frames)
    if n_frames < 1:
        raise ConfigError(f"n_frames must be >= 1, got {n_frames}")
    seconds = n_frames / fps
    if velocity_model not in _drops.FALL_VELOCITY_MODELS:
        raise ConfigError(f"unknown velocity model {velocity_model!r}; valid: "
                          f"{', '.join(_drops.FALL_VELOCITY_MODELS)}")
    if not (math.isfinite(float(wind_m_s)) and float(wind_m_s) >= 0):
        raise ConfigError(f"wind speed must be >= 0 m/s (give the direction with wind_dir_deg), got {wind_m_s!r}")
    if not (math.isfinite(float(drop_brightness_dn)) and drop_brightness_dn >= 0):
        raise ConfigError(f"drop_brightness_dn must be >= 0, got {drop_brightness_dn!r}")
    if not (render_threshold_dn >= 0):
        raise ConfigError(f"render_threshold_dn must be >= 0, got {render_threshold_dn!r}")
    if render_threshold_dn == 0 and depth_range_m is None:
        raise ConfigError("render_threshold_dn = 0 makes the rain volume infinite; give depth_range_m too")
    if closeup_light is not None:
        try:
            light = tuple(float(v) for v in closeup_light)
        except (TypeError, ValueError):
            light = ()
        if len(light) != 2 or not all(math.isfinite(v) for v in light):
            raise ConfigError(f"closeup_light must be (theta, phi) in radians or None, got {closeup_light!r}")
    if not (float(closeup_min_width_px) > 0 and float(closeup_max_blur_ratio) >= 0):
        raise ConfigError(f"closeup_min_width_px must be > 0 and closeup_max_blur_ratio >= 0, got "
                          f"{closeup_min_width_px!r}, {closeup_max_blur_ratio!r}")
    if jpeg_quality is not None and not (1 <= int(jpeg_quality) <= 100):
        raise ConfigError(f"jpeg_quality must be 1..100, got {jpeg_quality!r}")
    if rain_rate_mm_h is not None:
        try:
            r = float(rain_rate_mm_h)
        except (TypeError, ValueError):
            raise ConfigError(f"rain rate must be a number [mm/h], got {rain_rate_mm_h!r}") from None
        if not (math.isfinite(r) and r >= 0):
            raise ConfigError(f"rain rate must be a finite number >= 0 mm/h, got {rain_rate_mm_h!r}. "
                              "Fix: give --rate 0 or more")
    assumptions = []
    pitch = profile.pixel_pitch_m
    if pitch is None:
        pitch = DEFAULT_PIXEL_PITCH_M
        assumptions.append(f"profile has no pixel_pitch_m; {pitch:g} m assumed for the blur circle")
    if profile.focus_distance_m <= profile.focal_length_px * pitch:
        raise ProfileError(f"camera profile {profile.name}: focus_distance_m {profile.focus_distance_m} m is "
                           f"inside the focal length. Fix: focus farther away")
    segments, edges, desc, window_edges = _rain_segments(
        rain_rate_mm_h=rain_rate_mm_h, dsd=dsd, dsd_params=dsd_params, parsivel=parsivel, start=start,
        seconds=seconds, velocity_model=velocity_model)
    ss = np.random.SeedSequence(seed)
    scene_seed = int(ss.generate_state(1)[0])
    scene = Scene(profile, background=background, motion=motion, seed=scene_seed)
    theta = math.radians(float(wind_dir_deg))
    wind = (float(wind_m_s) * math.cos(theta), float(wind_m_s) * math.sin(theta))
    if window_edges is not None:
        window_edges = [min(t, seconds) for t in window_edges if t < seconds] + [seconds]
    return Simulation(profile, n_frames=n_frames, segments=segments, edges=edges,
                      velocity_model=velocity_model, wind=wind, scene=scene, seed=seed,
                      truth_masks=truth_masks, truth_clean=truth_clean, truth_drops=truth_drops,
                      truth_linear=truth_linear,
                      drop_brightness_dn=drop_brightness_dn, render_threshold_dn=render_threshold_dn,
                      depth_range_m=depth_range_m, reference_depth_m=reference_depth_m,
                      truth_window_s=truth_window_s, jpeg_quality=jpeg_quality, noise=noise,
                      pixel_pitch_m=pitch, assumptions=assumptions, rain_description=desc,
                      window_edges=window_edges, closeup=closeup, closeup_light=closeup_light,
                      closeup_min_width_px=closeup_min_width_px, closeup_max_blur_ratio=closeup_max_blur_ratio)


def render_clip(profile, *, seconds=None, n_frames=None, rain_rate_mm_h=None, seed=0,
                return_clean=False, return_masks=False, return_drops=False, **kw):
    """Render a whole clip into memory: the fast path for tests.

    Parameters
    ----------
    profile : CameraProfile, str or Path
    seconds, n_frames : float, int
        Clip length (one of them).
    rain_rate_mm_h : float, optional
        Nominal rain rate [mm/h].
    seed : int
    return_clean, return_masks, return_drops : bool
        Also put ``clean`` (T, M, N) uint8, ``rain_masks`` (T, M, N) bool and
        ``frames`` (list of per-frame dicts with ``drops``) into the truth dict.
    **kw
        Any other :func:`simulate` parameter, e.g. ``closeup=True`` (off by
        default, see :func:`simulate`) and ``closeup_light``.

    Returns
    -------
    frames : ndarray, shape (T, M, N), uint8
    truth : dict
        :attr:`Simulation.truth`, plus the arrays asked for.
    """
    sim = simulate(profile, seconds=seconds, n_frames=n_frames, rain_rate_mm_h=rain_rate_mm_h, seed=seed,
                   truth_masks=return_masks, truth_clean=return_clean, truth_drops=return_drops, **kw)
    m, n = sim.profile.shape
    frames = np.empty((sim.n_frames, m, n), np.uint8)
    clean = np.empty_like(frames) if return_clean else None
    masks = np.empty((sim.n_frames, m, n), bool) if return_masks else None
    per_frame = []
    for k, (frame, ft) in enumerate(sim):
        frames[k] = frame
        if return_clean:
            clean[k] = ft["clean"]
        if return_masks:
            masks[k] = ft["rain_mask"]
        if return_drops:
            per_frame.append({"index": k, "t_s": ft["t_s"], "drops": ft["drops"]})
    truth = dict(sim.truth)
    if return_clean:
        truth["clean"] = clean
    if return_masks:
        truth["rain_masks"] = masks
    if return_drops:
        truth["frames"] = per_frame
    return frames, truth
