"""Close-up rain streaks: an oscillating drop ray-traced and integrated over the exposure.

Sec. 9 [GargNayar2007] and [GargNayar2006].  A drop near the camera images to a
streak wide enough to show the brightness pattern made by its oscillations:
speckles, smeared highlights, curved contours that repeat every oscillation
period along the streak.  Here the drop (:class:`raingauge.render.oscillation.OscillatingDrop`)
is ray-traced (:mod:`raingauge.render.raytrace`) at many instants of the
exposure while it falls, and the instants are averaged.

Geometry.  World axes X (right), Y (up), Z (horizontal, away from the camera);
the drop falls along -Y.  The camera looks at the drop with an orthographic
projection (a drop is millimetres across, the camera at least decimetres away)
along ``forward = (0, -sin(view_theta), cos(view_theta))``: ``view_theta`` is the
elevation of the line of sight below the horizontal (positive: the camera looks
down on the drop).  Image axes: x right (= X), y down.  The light (a distant
source of small angular size) lies in the direction
``cos(theta_l) * (towards camera) + sin(theta_l) * (cos(phi_l) * right + sin(phi_l) * up)``:
``theta_l = 0`` is frontal lighting from behind the camera, ``theta_l = pi``
back-lighting, ``phi_l`` is measured in the image plane from image-right towards image-up.

Patch layout.  ``width_px`` is the image diameter of the volume-equivalent
sphere (2 a) and sets the scale; the drop's centre moves down by
``length_px - width_px`` pixels during the exposure, from ``pad + width_px / 2``
below the top edge (``CloseupStreak.centre_start_px`` / ``centre_end_px``).  The
patch is ``(ceil(length_px) + 2 pad, ceil(width_px * r_max / a) + 2)`` with
``pad = 1 + ceil((r_max / a - 1) width_px / 2)``, r_max the drop's largest radius.
Compose a streak on a background E_b as ``E = E_b (1 - coverage) + radiance``.

Use in the rain simulator.  Radiance comes out in the unit of the lighting:
with ``light_dir=None, ambient=E_sky`` (overcast) or an environment map in
gray levels (bright sky above, the scene's brightness below and behind), the
streak is in gray levels and composes directly onto the linear frame.  A
streak takes seconds to trace; :func:`cached_closeup_streak` memoises streaks
for repeated (quantised) sizes and directions.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from raingauge.physics import optics
from raingauge.render.oscillation import OscillatingDrop
from raingauge.render.raytrace import trace

__all__ = ["CloseupStreak", "viewing_frame", "light_direction", "light_scene",
           "render_closeup_drop", "closeup_streak", "render_closeup_streak", "cached_closeup_streak"]


def viewing_frame(view_theta: float):
    """(forward, right, down) unit vectors of the camera for elevation ``view_theta`` [rad]."""
    forward = np.array([0.0, -math.sin(view_theta), math.cos(view_theta)])
    right = np.array([1.0, 0.0, 0.0])
    down = np.cross(right, forward)
    return forward, right, down


def light_direction(light_theta: float, light_phi: float, view_theta: float) -> np.ndarray:
    """Unit vector from the drop towards the light (world frame), see module notes [rad]."""
    forward, right, down = viewing_frame(view_theta)
    return (math.cos(light_theta) * (-forward)
            + math.sin(light_theta) * (math.cos(light_phi) * right - math.sin(light_phi) * down))


def light_scene(light_dir, *, light_radiance: float = 1.0, ambient: float = 0.05,
                light_size_rad: float = math.radians(3.0), environment=None, view_theta: float = 0.0):
    """Scene radiance for rays leaving the drop: ambient + a small light (+ an environment map).

    Parameters
    ----------
    light_dir : (3,) or None
        Direction towards the light (world frame); None for no light.
    light_radiance : float
        Peak radiance of the light [radiance unit].
    ambient : float
        Uniform sky radiance [radiance unit].
    light_size_rad : float
        Angular radius (Gaussian sigma) of the light [rad].
    environment : ndarray (H, W), optional
        Equirectangular map in the camera frame (x right, y down, z forward),
        added to the ambient term.
    view_theta : float
        Camera elevation, to turn world directions into camera directions [rad].
    """
    if not light_size_rad > 0:
        raise ValueError(f"light_size_rad must be > 0, got {light_size_rad}")
    ldir = None if light_dir is None else np.asarray(light_dir, float) / np.linalg.norm(light_dir)
    forward, right, down = viewing_frame(view_theta)
    cam = np.stack([right, down, forward])

    def scene(o, d):
        out = np.full(d.shape[0], float(ambient))
        if ldir is not None:
            cosang = np.clip(d @ ldir, -1.0, 1.0)
            ang = np.arccos(cosang)
            out += light_radiance * np.exp(-0.5 * (ang / light_size_rad) ** 2)
        if environment is not None:
            from raingauge.render.drop import sample_environment
            out += sample_environment(environment, d @ cam.T)
        return out

    scene.max_radiance = float(ambient) + (light_radiance if ldir is not None else 0.0) + (
        float(np.max(environment)) if environment is not None else 0.0)
    return scene


def _trace_drop_samples(drop: OscillatingDrop, x_m, y_m, t_s, *, view_theta, scene, mu,
                        chunk: int = 120_000):
    """Trace orthographic rays through image offsets (x_m, y_m) from the drop centre at times t_s.

    Returns (radiance of the drop where hit, else 0; hit mask), both (n,).
    """
    forward, right, down = viewing_frame(view_theta)
    surf = drop.surface()
    back = 4.0 * drop.max_radius_m
    n = x_m.size
    rad = np.zeros(n)
    hit = np.zeros(n, dtype=bool)
    # rays that cannot reach the bounding sphere are skipped
    near = np.hypot(x_m, y_m) < drop.max_radius_m * 1.0001
    idx = np.nonzero(near)[0]
    for start in range(0, idx.size, chunk):
        sel = idx[start:start + chunk]
        origins = (x_m[sel, None] * right + y_m[sel, None] * down - back * forward)
        dirs = np.broadcast_to(forward, origins.shape)
        res = trace(surf, origins, dirs, scene, mu=mu, max_internal=4, min_weight=1e-4,
                    ray_time=t_s[sel])
        hit[sel] = res.hit
        rad[sel] = np.where(res.hit, res.radiance, 0.0)
    return rad, hit


def _subpixel_offsets(supersample: int):
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be >= 1, got {supersample}")
    return (np.arange(s) + 0.5) / s - 0.5


def render_closeup_drop(drop: OscillatingDrop, *, t_s: float = 0.0, width_px: float,
                        shape=None, center_px=None, view_theta: float = 0.0, scene,
                        mu: float = optics.MU_WATER, supersample: int = 3):
    """Image of the drop at one instant (no motion blur), same geometry as the streaks.

    Parameters
    ----------
    drop : OscillatingDrop
    t_s : float
        Time [s] (oscillation phase).
    width_px : float
        Image diameter of the volume-equivalent sphere, 2a [px].
    shape : (M, N), optional
        Output size [px]; a square just holding the drop by default.
    center_px : (x, y), optional
        Column, row of the drop's centre [px]; the image centre by default.
    view_theta : float
        Camera elevation [rad].
    scene : callable
        ``scene(origins, dirs)`` radiance of rays leaving the drop (:func:`light_scene`).
    mu : float
        Refractive index [-].
    supersample : int
        s x s rays per pixel.

    Returns
    -------
    (radiance, coverage) : float32 (M, N) each; radiance is zero where the drop is absent.
    """
    scale = width_px / (2.0 * drop.radius_m)
    if shape is None:
        side = int(math.ceil(2 * drop.max_radius_m * scale)) + 2
        shape = (side, side)
    m, n = shape
    cx, cy = ((n - 1) / 2.0, (m - 1) / 2.0) if center_px is None else center_px
    sub = _subpixel_offsets(supersample)
    rows, cols, sy, sx = np.meshgrid(np.arange(m), np.arange(n), sub, sub, indexing="ij")
    x_m = ((cols + sx) - cx).ravel() / scale
    y_m = ((rows + sy) - cy).ravel() / scale
    rad, hit = _trace_drop_samples(drop, x_m, y_m, np.full(x_m.size, float(t_s)),
                                   view_theta=view_theta, scene=scene, mu=mu)
    k = int(supersample) ** 2
    return (rad.reshape(m, n, k).mean(-1).astype(np.float32),
            hit.reshape(m, n, k).mean(-1).astype(np.float32))


@dataclass
class CloseupStreak:
    """A rendered close-up streak.

    radiance : float32 (H, W)  time-averaged radiance contributed by the drop.
    coverage : float32 (H, W)  fraction of the exposure the drop covers each pixel.
    fall_px : float            distance the drop's centre moves during the exposure [px]
                               (the requested length rounded to the time lattice).
    centre_start_px, centre_end_px : (col, row) of the drop's centre in the patch at the
                               start and the end of the exposure [px].
    period_px : float          fall distance per oscillation period [px].
    frequency_hz : float       oscillation frequency [Hz].
    fall_speed_m_s : float     fall speed [m/s].
    exposure_s : float         exposure time [s].
    max_scene_radiance : float brightest radiance in the scene (light + ambient + map).
    """

    radiance: np.ndarray
    coverage: np.ndarray
    fall_px: float
    period_px: float
    centre_start_px: tuple
    centre_end_px: tuple
    frequency_hz: float
    fall_speed_m_s: float
    exposure_s: float
    max_scene_radiance: float

    def composite(self, background) -> np.ndarray:
        """E = E_b (1 - coverage) + radiance on a background patch of the same shape (or a scalar)."""
        return (np.asarray(background, np.float32) * (1.0 - self.coverage) + self.radiance)


def _terminal_speed(radius_m: float) -> float:
    """Terminal speed [m/s]: the Gunn-Kinzer table, or the paper's v = 200 sqrt(a) beyond its 5.8 mm end."""
    from raingauge.physics.drops import fall_velocity

    v = float(fall_velocity(2.0 * radius_m, model="gunn_kinzer"))
    if np.isfinite(v) and v > 0:
        return v
    return 200.0 * math.sqrt(radius_m)


def closeup_streak(radius_m: float, *, length_px: float, width_px: float,
                   light_dir=(math.radians(60.0), math.radians(90.0)), view_theta: float = 0.0,
                   exposure_s: float | None = None, fall_speed_m_s: float | None = None,
                   amp_axisymmetric: float = 0.05, amp_transverse: float = 0.03,
                   phase_axisymmetric: float = 0.0, phase_transverse: float = math.pi / 2,
                   transverse_azimuth: float = 0.0, frequency_hz: float | None = None,
                   shape: str = "beard_chuang", environment=None, light_radiance: float = 1.0,
                   ambient: float = 0.05, light_size_rad: float = math.radians(3.0),
                   mu: float = optics.MU_WATER, supersample: int = 2,
                   time_samples_per_px: float | None = None,
                   start_time_s: float = 0.0) -> CloseupStreak:
    """Render a close-up rain streak of an oscillating drop (Sec. 9 [GargNayar2007], [GargNayar2006]).

    Parameters
    ----------
    radius_m : float
        Radius a of the volume-equivalent sphere [m].
    length_px, width_px : float
        Streak length and drop image diameter 2a [px] (see module notes).
    light_dir : (theta, phi), (3,) or None
        Direction of the light: angles [rad] (module notes) or a world-frame vector
        towards the light; None: ambient / map only.
    view_theta : float
        Elevation of the line of sight below the horizontal [rad].
    exposure_s, fall_speed_m_s : float, optional
        Give at most one.  The fall speed defaults to the drop's terminal speed
        (Gunn-Kinzer); the exposure then follows from ``length_px``.  Given an
        exposure, the speed follows from it.
    amp_axisymmetric, amp_transverse : float
        Peak fractional radius change of the (2, 0) and (2, 1) modes [-].
    phase_axisymmetric, phase_transverse, transverse_azimuth : float
        Mode phases and the azimuth of the transverse mode [rad].
    frequency_hz : float, optional
        Oscillation frequency; Rayleigh's by default [Hz].
    shape : str
        Equilibrium shape ("beard_chuang", "spheroid", "sphere").
    environment : ndarray (H, W), optional
        Equirectangular environment (camera frame) added to the ambient sky.
    light_radiance, ambient, light_size_rad : float
        Light peak radiance, sky radiance [radiance unit], light angular size [rad].
    mu : float
        Refractive index [-].
    supersample : int
        Rays per pixel across the streak, per instant [-].
    time_samples_per_px : float, optional
        Instants per pixel of fall (default 2 x supersample); the motion itself
        samples each pixel along the streak [-].
    start_time_s : float
        Time at the start of the exposure (oscillation phase) [s].

    Returns
    -------
    CloseupStreak
    """
    if not radius_m > 0:
        raise ValueError(f"radius_m must be > 0, got {radius_m}")
    if not width_px > 0:
        raise ValueError(f"width_px must be > 0, got {width_px}")
    if not length_px >= width_px:
        raise ValueError(f"length_px ({length_px}) must be at least width_px ({width_px})")
    if exposure_s is not None and fall_speed_m_s is not None:
        raise ValueError("give exposure_s or fall_speed_m_s, not both (length_px fixes the other)")
    drop = OscillatingDrop(radius_m, amp_axisymmetric=amp_axisymmetric,
                           amp_transverse=amp_transverse, phase_axisymmetric=phase_axisymmetric,
                           phase_transverse=phase_transverse, transverse_azimuth=transverse_azimuth,
                           frequency_hz=frequency_hz, shape=shape)
    scale = width_px / (2.0 * radius_m)                    # px per metre
    fall_px = float(length_px - width_px)
    foreshortening = math.cos(view_theta)
    if fall_px > 0:
        if exposure_s is not None:
            if not exposure_s > 0:
                raise ValueError(f"exposure_s must be > 0, got {exposure_s}")
            speed = fall_px / (scale * foreshortening * exposure_s)
        else:
            speed = float(fall_speed_m_s) if fall_speed_m_s is not None else _terminal_speed(radius_m)
            if not speed > 0:
                raise ValueError(f"fall_speed_m_s must be > 0, got {speed}")
            exposure_s = fall_px / (scale * foreshortening * speed)
    else:
        speed = float(fall_speed_m_s) if fall_speed_m_s is not None else _terminal_speed(radius_m)
        exposure_s = float(exposure_s) if exposure_s is not None else 0.0
    period_px = speed * foreshortening * scale / drop.frequency_hz

    if light_dir is None:
        ldir = None
    else:
        ld = np.asarray(light_dir, dtype=float).ravel()
        if ld.size == 2:
            ldir = light_direction(ld[0], ld[1], view_theta)
        elif ld.size == 3 and np.linalg.norm(ld) > 0:
            ldir = ld / np.linalg.norm(ld)
        else:
            raise ValueError("light_dir must be (theta, phi) [rad] or a non-zero world vector (3,)")
    scene = light_scene(ldir, light_radiance=light_radiance, ambient=ambient,
                        light_size_rad=light_size_rad, environment=environment,
                        view_theta=view_theta)

    # margins hold the drop's largest extent (oblate, oscillating) beyond its radius a
    pad = 1 + int(math.ceil(max(0.0, drop.max_radius_m / radius_m - 1.0) * width_px / 2.0))
    h = int(math.ceil(length_px)) + 2 * pad
    w = int(math.ceil(width_px * drop.max_radius_m / radius_m)) + 2
    cx = (w - 1) / 2.0
    y_start = pad + width_px / 2.0 - 0.5                   # centre row at t = 0
    # instants on a lattice of exactly 1/rate px of fall: every row then sees the drop
    # at the same sub-pixel phases, so the time average has no beat along the streak
    rate = float(time_samples_per_px) if time_samples_per_px else 2.0 * int(supersample)
    if not rate > 0:
        raise ValueError(f"time_samples_per_px must be > 0, got {time_samples_per_px}")
    n_t = max(1, int(round(fall_px * rate)))
    centres = y_start + (np.arange(n_t) + 0.5) / rate if fall_px > 0 else np.full(1, y_start)
    v_img = scale * foreshortening * speed                 # px/s
    times = start_time_s + (centres - y_start) * (0.0 if fall_px <= 0 else 1.0 / v_img)
    if fall_px > 0:
        fall_px = n_t / rate
        exposure_s = fall_px / v_img
    r_px = drop.max_radius_m * scale
    sub = _subpixel_offsets(supersample)
    k = sub.size                                           # sub-columns; rows via the motion
    radiance = np.zeros(h * w)
    coverage = np.zeros(h * w)
    cols = np.arange(w)
    # group instants so each trace call holds a few ten thousand rays
    per_batch = max(1, int(60_000 // max(1, k * w * (2 * r_px + 3))))
    for b0 in range(0, n_t, per_batch):
        xs, ys, ts, pix = [], [], [], []
        for j in range(b0, min(n_t, b0 + per_batch)):
            r0 = max(0, int(math.floor(centres[j] - r_px - 1)))
            r1 = min(h, int(math.ceil(centres[j] + r_px + 2)))
            rr, cc, sx = np.meshgrid(np.arange(r0, r1), cols, sub, indexing="ij")
            xs.append(((cc + sx) - cx).ravel() / scale)
            ys.append((rr - centres[j]).ravel() / scale)
            ts.append(np.full(rr.size, times[j]))
            pix.append((rr * w + cc).ravel())
        x_m, y_m, t_s, p = (np.concatenate(v) for v in (xs, ys, ts, pix))
        rad, hit = _trace_drop_samples(drop, x_m, y_m, t_s, view_theta=view_theta,
                                       scene=scene, mu=mu)
        radiance += np.bincount(p, weights=rad, minlength=h * w)
        coverage += np.bincount(p, weights=hit.astype(float), minlength=h * w)
    norm = 1.0 / (k * n_t)
    return CloseupStreak(radiance=(radiance * norm).reshape(h, w).astype(np.float32),
                         coverage=(coverage * norm).reshape(h, w).astype(np.float32),
                         fall_px=fall_px, period_px=float(period_px),
                         centre_start_px=(cx, y_start), centre_end_px=(cx, y_start + fall_px),
                         frequency_hz=float(drop.frequency_hz), fall_speed_m_s=float(speed),
                         exposure_s=float(exposure_s), max_scene_radiance=scene.max_radiance)


def render_closeup_streak(radius_m: float, *, length_px: float, width_px: float,
                          light_dir=(math.radians(60.0), math.radians(90.0)),
                          view_theta: float = 0.0, **kw) -> np.ndarray:
    """Time-averaged radiance patch (H, W) float32 of a close-up streak; see :func:`closeup_streak`.

    For the rain simulator's drops near the camera: add it to the background
    weighted by ``1 - coverage`` (use :func:`closeup_streak` to get the coverage).
    """
    return closeup_streak(radius_m, length_px=length_px, width_px=width_px, light_dir=light_dir,
                          view_theta=view_theta, **kw).radiance


@functools.lru_cache(maxsize=64)
def _cached_streak(radius_m, length_px, width_px, light_dir, view_theta, options):
    streak = closeup_streak(radius_m, length_px=length_px, width_px=width_px, light_dir=light_dir,
                            view_theta=view_theta, **dict(options))
    streak.radiance.flags.writeable = False
    streak.coverage.flags.writeable = False
    return streak


def cached_closeup_streak(radius_m: float, *, length_px: float, width_px: float,
                          light_dir=(math.radians(60.0), math.radians(90.0)),
                          view_theta: float = 0.0, **kw) -> CloseupStreak:
    """:func:`closeup_streak`, memoised (64 streaks) on its arguments; the arrays are read-only.

    All arguments must be hashable (no environment map); quantise sizes and
    angles before calling to reuse streaks between drops.
    """
    if "environment" in kw:
        raise ValueError("cached_closeup_streak cannot take an environment map; call closeup_streak")
    ld = None if light_dir is None else tuple(float(v) for v in np.ravel(light_dir))
    return _cached_streak(float(radius_m), float(length_px), float(width_px), ld, float(view_theta),
                          tuple(sorted(kw.items())))
