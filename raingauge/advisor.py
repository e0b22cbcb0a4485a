"""Camera settings for rain: reduce it in a picture, or enhance it for the gauge (Secs. 6-8, Table 1).

Two goals [GargNayar2007]:

``reduce`` (Sec. 7)
    Choose exposure T, F-number N and focus z0 that minimise the rain's
    visibility sigma_r (Eq. 27) while the scene looks the same: scene motion
    blurs by at most one pixel (T <= 1 / motion), the scene's depth range
    stays inside the depth of field (circle of confusion one pixel), the
    exposure stays inside what the camera allows, and the gain follows
    Eq. (20) so that brightness k0 = k pi T / (4 N^2) does not change.
    The answer carries the settings, the predicted reduction factor
    sigma_r(new) / sigma_r(current) and the reasons, or "X" (infeasible) where
    nothing helps, as in Table 1 rows (e)-(f).

``gauge`` (Sec. 8)
    Settings that make the camera a rain gauge: focus z0 <= 2 f a_min so the
    smallest drops measured are at least a pixel wide in focus, the widest
    aperture (shallow depth of field: a thin, well-defined sample volume with
    few overlapping streaks), and a short exposure.  Reports the sample volume
    per size class, the drops expected per minute and the Poisson counting
    uncertainty of the rain rate at 1, 10 and 50 mm/h (Marshall-Palmer).

Scene description
-----------------
Either metric values (image motion [px/s], nearest scene distance [m], depth
range [m], ``inf`` for a scene reaching the horizon) or the coarse categories
of Table 1:

- motion: ``slow`` = 15 px/s (the paper: "less than 15 pixels/sec", no blur
  at 1/15 s), ``fast`` = 125 px/s (one pixel in the 8 ms of rows (g)-(h));
- near distance against the rain-visible limit z_v = R z_m = 2 R f a_ref
  (note 27: about 24 m for the Canon XL1; 24 m exactly with f = 8000 px,
  R = 3 and a_ref = 0.5 mm): ``close`` = z_v / 1.5, ``far`` = 1.5 z_v;
- depth range: ``small`` = half the near distance (the scene ends at 1.5x its
  near end), ``large`` = to the horizon.

With the XL1 profile these give back Table 1's F-numbers from the depth of
field alone (14, 4.4, 6, 2 against 13.4, 4.5, 6.0, 2.0).

Exposure policy
---------------
sigma_r falls as 1/sqrt(T), so the advisor uses the longest exposure the
scene's motion allows, capped by the camera's ``exposure_range_s``.
Exposures longer than the frame interval are a camcorder's slow shutter: each
exposure spans several frame intervals and the effective frame rate drops to
1/T.  Following Table 1 (1/15 s only in rows (a) and (c), the large depth
ranges) the slow shutter is used (``slow_shutter="auto"``) only when the
aperture cannot help: the scene reaches beyond the hyperfocal distance of the
widest aperture, so the lens must stay stopped down; or when the rain is heavy
(``rain_rate_mm_h`` >= :data:`HEAVY_RAIN_MM_H`, Fig. 16(IV), T = 120 ms).
``"always"`` and ``"never"`` override.

Infeasible ("X")
----------------
No setting keeps the scene sharp (too deep for the lens, too fast for the
shortest exposure); or the scene's motion forbids any exposure longer than the
current one while the scene's near end lies inside the rain-visible region
(rain in the scene's depth cannot be defocused without defocusing the scene):
Table 1 rows (e)-(f).

Notes
-----
- Predictions use Eq. (27) for a single drop size, a_ref = 0.5 mm
  (:data:`raingauge.physics.visibility.A_REF_M`): in a ratio of two settings
  the rain rate, drop contrast and scene brightness cancel, only z_m = 2 f a
  remains.  Integrated over a Marshall-Palmer DSD the aperture's effect is
  somewhat weaker (larger drops reach farther; see the tests).
- a_min = 0.5 mm is read as a *radius*, as printed in Sec. 8 ("the radius of
  the smallest raindrop"): this agrees with the paper's own Fig. 18 settings
  (f = 3300 px, z0 = 3 m <= 2 f a_min = 3.3 m; a 0.25 mm radius would demand
  z0 <= 1.65 m).  Physically smaller drops exist (drizzle); 0.5 mm is the
  smallest radius the gauge *sizes* (>= 1 px wide in focus).  Pass ``a_min_m``
  to change it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from raingauge.errors import ConfigError
from raingauge.physics import camera as cam
from raingauge.physics import visibility as vis

__all__ = [
    "GOALS",
    "MOTION_CATEGORIES_PX_S",
    "HEAVY_RAIN_MM_H",
    "SLOW_SHUTTER_MODES",
    "Scene",
    "Settings",
    "Advice",
    "rain_visible_limit_m",
    "make_scene",
    "sigma_r_for",
    "reduction_factor",
    "advise_reduce",
    "advise_gauge",
    "advise",
    "table1",
    "TABLE1_ROWS",
]

GOALS = ("reduce", "gauge")
#: Image motion of the Table 1 categories [px/s].
MOTION_CATEGORIES_PX_S = {"slow": 15.0, "fast": 125.0}
#: Near-distance categories as multiples of the rain-visible limit R z_m.
NEAR_CATEGORIES = {"close": 1.0 / 1.5, "far": 1.5}
#: Depth-range categories as multiples of the near distance.
DEPTH_CATEGORIES = {"small": 0.5, "large": math.inf}
#: Rain rate from which the slow shutter is used whatever the scene [mm/h]
#: (WMO heavy rain, 7.6 mm/h).
HEAVY_RAIN_MM_H = 7.6
SLOW_SHUTTER_MODES = ("auto", "always", "never")
#: Gain change [dB] beyond which the reason warns that gain alone cannot keep the brightness.
GAIN_RANGE_DB = 18.0
#: Table 1 rows: label -> (motion, near, depth, paper T [s] or None, paper N or None).
TABLE1_ROWS = {
    "a": ("slow", "close", "large", 0.066, 14.0),
    "b": ("slow", "close", "small", 0.033, 4.4),
    "c": ("slow", "far", "large", 0.066, 6.0),
    "d": ("slow", "far", "small", 0.033, 2.0),
    "e": ("fast", "close", "large", None, None),
    "f": ("fast", "close", "small", None, None),
    "g": ("fast", "far", "large", 0.008, 6.0),
    "h": ("fast", "far", "small", 0.008, 2.4),
}


@dataclasses.dataclass(frozen=True)
class Scene:
    """What the camera watches: image motion [px/s], nearest distance [m], depth range [m] (may be inf)."""

    motion_px_s: float
    near_m: float
    depth_m: float
    label: str = ""

    @property
    def far_m(self) -> float:
        """Far end of the scene [m]."""
        return self.near_m + self.depth_m


@dataclasses.dataclass(frozen=True)
class Settings:
    """Exposure T [s], F-number N [-], focus distance z0 [m]."""

    exposure_s: float
    f_number: float
    focus_distance_m: float


@dataclasses.dataclass
class Advice:
    """The advisor's answer; :meth:`to_dict` gives the JSON record."""

    goal: str
    feasible: bool
    settings: Settings | None
    reason: str
    predicted_reduction: float | None = None
    sigma_r: float | None = None
    sigma_r_current: float | None = None
    gain_change_db: float | None = None
    effective_frame_rate_hz: float | None = None
    scene: Scene | None = None
    details: dict[str, Any] = dataclasses.field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        s = self.settings
        out: dict[str, Any] = {
            "goal": self.goal,
            "feasible": self.feasible,
            "exposure_s": None if s is None else s.exposure_s,
            "f_number": None if s is None else s.f_number,
            "focus_distance_m": None if s is None else s.focus_distance_m,
            "reason": self.reason,
        }
        if self.goal == "reduce":
            out["predicted_reduction"] = self.predicted_reduction
            out["sigma_r"] = self.sigma_r
            out["sigma_r_current"] = self.sigma_r_current
            out["gain_change_db"] = self.gain_change_db
            out["effective_frame_rate_hz"] = self.effective_frame_rate_hz
            if self.scene is not None:
                out["scene"] = {"motion_px_s": self.scene.motion_px_s, "near_m": self.scene.near_m,
                                "depth_m": None if math.isinf(self.scene.depth_m) else self.scene.depth_m,
                                "label": self.scene.label}
        out.update(self.details)
        return out


# ------------------------------------------------------------------ helpers
def _pitch(profile) -> float:
    if profile.pixel_pitch_m is None:
        raise ConfigError(
            f"camera profile {profile.name!r} has no pixel_pitch_m; the depth of field and blur circle "
            "need it. Fix: add pixel_pitch_m (sensor width / width_px, e.g. 5.0e-6) to the [camera] table")
    return float(profile.pixel_pitch_m)


def _ranges(profile):
    exp = profile.exposure_range_s or (min(profile.exposure_s, 1e-4), profile.frame_interval_s)
    fnum = profile.f_number_range or (profile.f_number, profile.f_number)
    focus = profile.focus_range_m or (max(2.0 * profile.focal_length_px * _pitch(profile), 0.05), 1e4)
    return exp, fnum, focus


def rain_visible_limit_m(profile, *, a_ref_m=vis.A_REF_M, r_visible=vis.R_VISIBLE) -> float:
    """R z_m = 2 R f a_ref for this camera [m] (note 27: ~24 m for the XL1)."""
    return float(vis.rain_visible_limit_m(a_ref_m, focal_length_px=profile.focal_length_px,
                                          r_visible=r_visible))


def _category_or_number(value, categories: dict, what: str) -> tuple[float, str]:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        x = float(value)
        label = ""
    else:
        text = str(value).strip().lower()
        if text in categories:
            return categories[text], text
        try:
            x = float(text)
        except ValueError:
            raise ConfigError(f"{what} {value!r} is neither a number nor one of: "
                              f"{', '.join(categories)}. Fix: use e.g. {next(iter(categories))} or 20") from None
        label = ""
    if not (x >= 0) or math.isnan(x):
        raise ConfigError(f"{what} must be >= 0, got {value!r}")
    return x, label


def make_scene(profile, *, motion="slow", near="far", depth="small", a_ref_m=vis.A_REF_M,
               r_visible=vis.R_VISIBLE) -> Scene:
    """A :class:`Scene` from Table 1 categories or numbers.

    Parameters
    ----------
    profile : CameraProfile
    motion : "slow" | "fast" | float [px/s]
    near : "close" | "far" | float [m]
        Categories are relative to the rain-visible limit R z_m of this camera.
    depth : "small" | "large" | float [m] (``inf`` allowed)
        Categories are relative to the near distance.
    """
    m, m_label = _category_or_number(motion, MOTION_CATEGORIES_PX_S, "scene motion")
    z_v = rain_visible_limit_m(profile, a_ref_m=a_ref_m, r_visible=r_visible)
    n_rel, n_label = _category_or_number(near, NEAR_CATEGORIES, "near distance")
    near_m = n_rel * z_v if n_label else n_rel
    if not (0 < near_m < math.inf):
        raise ConfigError(f"near distance must be a finite number of metres > 0, got {near!r}. "
                          "Fix: use close, far or a distance such as 20")
    d_rel, d_label = _category_or_number(depth, DEPTH_CATEGORIES, "depth range")
    depth_m = d_rel * near_m if d_label else d_rel
    label = " ".join(x for x in (m_label, n_label, d_label) if x)
    return Scene(motion_px_s=m, near_m=near_m, depth_m=depth_m, label=label)


def sigma_r_for(profile, settings: Settings, *, radius_m=vis.A_REF_M, r_visible=vis.R_VISIBLE,
                dsd=None, velocity_model="paper") -> float:
    """sigma_r (Eq. 27, units of the drop contrast) for ``settings`` on this camera."""
    return vis.sigma_r(exposure_s=settings.exposure_s, f_number=settings.f_number,
                       focus_distance_m=settings.focus_distance_m,
                       focal_length_px=profile.focal_length_px, pixel_pitch_m=_pitch(profile),
                       radius_m=radius_m, dsd=dsd, velocity_model=velocity_model, r_visible=r_visible)


def reduction_factor(profile, current: Settings, new: Settings, **kw) -> float:
    """sigma_r(new) / sigma_r(current), Eq. (27) [GargNayar2007] (Fig. 16's predicted factors)."""
    return sigma_r_for(profile, new, **kw) / sigma_r_for(profile, current, **kw)


def _current(profile) -> Settings:
    return Settings(profile.exposure_s, profile.f_number, profile.focus_distance_m)


def _dof(profile, n, z0):
    return cam.depth_of_field_m(focal_length_px=profile.focal_length_px, f_number=n,
                                focus_distance_m=z0, pixel_pitch_m=_pitch(profile))


def _focus_interval(profile, n, scene: Scene, focus_range):
    """[z0_lo, z0_hi] of focus distances whose depth of field (1 px) holds the scene at F-number n."""
    from scipy.optimize import brentq

    fm = profile.focal_length_px * _pitch(profile)
    lo_lim = max(focus_range[0], fm * 1.0001)
    hi_lim = focus_range[1]
    if lo_lim >= hi_lim:
        return None
    d1, d2 = scene.near_m, scene.far_m
    # near limit of the DoF grows with z0: largest z0 with near <= d1
    def g_near(z0):
        return _dof(profile, n, z0)[0] - d1
    if g_near(lo_lim) > 0:
        return None
    z_hi = hi_lim if g_near(hi_lim) <= 0 else brentq(g_near, lo_lim, hi_lim, xtol=1e-9, rtol=1e-10)
    # far limit grows with z0: smallest z0 with far >= d2
    def g_far(z0):
        # 1/d2 - 1/far: >= 0 when the far limit reaches the scene's far end (1/inf = 0)
        far = _dof(profile, n, z0)[1]
        return (0.0 if math.isinf(d2) else 1.0 / d2) - (0.0 if math.isinf(far) else 1.0 / far)
    if g_far(lo_lim) >= 0:
        z_lo = lo_lim
    elif g_far(z_hi) < 0:
        return None
    else:
        z_lo = brentq(g_far, lo_lim, z_hi, xtol=1e-12, rtol=1e-12)
        if g_far(z_lo) < 0:
            z_lo = min(z_lo * (1.0 + 1e-9), z_hi)
    if z_lo > z_hi:
        return None
    return z_lo, z_hi


def _best_aperture_focus(profile, scene, fnum_range, focus_range, *, r_visible, a_ref_m, n_grid=96):
    """(G, N, z0) minimising G(f, N, z0) with the scene inside the depth of field, or None."""
    pitch = _pitch(profile)

    def g_of(n, z0):
        return vis.visibility_g(a_ref_m, focal_length_px=profile.focal_length_px, f_number=n,
                                focus_distance_m=z0, pixel_pitch_m=pitch, r_visible=r_visible)

    grid = np.geomspace(fnum_range[0], fnum_range[1], n_grid) if fnum_range[1] > fnum_range[0] \
        else np.array([fnum_range[0]])
    feasible = [(n, _focus_interval(profile, n, scene, focus_range)) for n in grid]
    first = next((i for i, (_, iv) in enumerate(feasible) if iv is not None), None)
    if first is None:
        return None
    candidates = [(n, iv) for n, iv in feasible[first:] if iv is not None]
    if first > 0:
        # the smallest feasible F-number, where the focus interval shrinks to a point
        def width(n):
            iv = _focus_interval(profile, n, scene, focus_range)
            return -1.0 if iv is None else 1.0
        n_lo, n_hi = grid[first - 1], grid[first]
        for _ in range(40):
            mid = math.sqrt(n_lo * n_hi)
            if width(mid) > 0:
                n_hi = mid
            else:
                n_lo = mid
        iv = _focus_interval(profile, n_hi, scene, focus_range)
        if iv is not None:
            candidates.insert(0, (n_hi, iv))
    best = None
    for n, (z_lo, z_hi) in candidates:
        zs = np.unique(np.geomspace(z_lo, z_hi, 7)) if z_hi > z_lo else np.array([z_lo])
        for z0 in zs:
            g = g_of(n, float(z0))
            if best is None or g < best[0] * (1 - 1e-12):
                best = (g, float(n), float(z0))
    return best


def _gain_db(current: Settings, new: Settings) -> float:
    """Gain change keeping k0 = k pi T / (4 N^2) fixed, Eq. (20) [dB, 20 log10]."""
    k_cur = vis.gain_for_brightness(1.0, exposure_s=current.exposure_s, f_number=current.f_number)
    k_new = vis.gain_for_brightness(1.0, exposure_s=new.exposure_s, f_number=new.f_number)
    return float(20.0 * math.log10(k_new / k_cur))


def _scene_sharp(profile, s: Settings, scene: Scene) -> list[str]:
    problems = []
    if scene.motion_px_s * s.exposure_s > 1.0 + 1e-9:
        problems.append(f"motion blur {scene.motion_px_s * s.exposure_s:.2g} px")
    near, far = _dof(profile, s.f_number, s.focus_distance_m)
    if near > scene.near_m * (1 + 1e-9) or far < scene.far_m * (1 - 1e-9):
        problems.append(f"depth of field {near:.3g}-{far:.3g} m misses the scene "
                        f"{scene.near_m:.3g}-{scene.far_m:.3g} m")
    return problems


# ------------------------------------------------------------------- reduce
def advise_reduce(profile, scene: Scene, *, current: Settings | None = None,
                  rain_rate_mm_h: float | None = None, slow_shutter: str = "auto",
                  a_ref_m: float = vis.A_REF_M, r_visible: float = vis.R_VISIBLE) -> Advice:
    """Settings that minimise sigma_r (Eq. 27) with the scene unchanged (Sec. 7, Table 1).

    Parameters
    ----------
    profile : CameraProfile
        Focal length [px], pixel pitch [m], frame rate, allowed ranges, and the
        current settings (``exposure_s``, ``f_number``, ``focus_distance_m``).
    scene : Scene
    current : Settings, optional
        Settings to compare against (default: the profile's).
    rain_rate_mm_h : float, optional
        Known rain rate; heavy rain allows the slow shutter (Fig. 16(IV)).
    slow_shutter : {"auto", "always", "never"}
        Exposures longer than the frame interval (see the module docstring).
    a_ref_m : float [m]
        Drop radius of the single-size prediction.
    r_visible : float [-]
        R of the rain-visible region.
    """
    if slow_shutter not in SLOW_SHUTTER_MODES:
        raise ConfigError(f"unknown slow_shutter {slow_shutter!r}; valid: {', '.join(SLOW_SHUTTER_MODES)}")
    current = current or _current(profile)
    exp_range, fnum_range, focus_range = _ranges(profile)
    frame_t = profile.frame_interval_s
    z_v = rain_visible_limit_m(profile, a_ref_m=a_ref_m, r_visible=r_visible)
    why: list[str] = []
    t_motion = math.inf if scene.motion_px_s <= 0 else 1.0 / scene.motion_px_s
    pitch = _pitch(profile)
    fm = profile.focal_length_px * pitch
    hyperfocal_open = fm * fm / (fnum_range[0] * pitch) + fm
    pinned = scene.far_m >= hyperfocal_open
    heavy = rain_rate_mm_h is not None and rain_rate_mm_h >= HEAVY_RAIN_MM_H
    allow_slow = slow_shutter == "always" or (slow_shutter == "auto" and (pinned or heavy))
    t_cap = min(exp_range[1], t_motion, math.inf if allow_slow else max(frame_t, exp_range[0]))
    if t_cap < exp_range[0] * (1 - 1e-9):
        return Advice("reduce", False, None, scene=scene,
                      reason=(f"X: scene motion {scene.motion_px_s:g} px/s needs an exposure <= "
                              f"{t_motion * 1e3:.3g} ms to stay within one pixel of blur, below the "
                              f"camera's shortest {exp_range[0] * 1e3:.3g} ms"))
    t_best = t_cap
    found = _best_aperture_focus(profile, scene, fnum_range, focus_range, r_visible=r_visible, a_ref_m=a_ref_m)
    if found is None:
        return Advice("reduce", False, None, scene=scene,
                      reason=(f"X: no F-number in {fnum_range[0]:g}-{fnum_range[1]:g} and focus in "
                              f"{focus_range[0]:g}-{focus_range[1]:g} m holds the scene "
                              f"{scene.near_m:.3g}-{scene.far_m:.3g} m inside the depth of field"))
    _, n_best, z_best = found
    if t_best <= current.exposure_s * (1 + 1e-9) and scene.near_m < z_v:
        return Advice("reduce", False, None, scene=scene,
                      reason=(f"X: the scene's motion ({scene.motion_px_s:g} px/s) allows no exposure longer "
                              f"than the current {current.exposure_s * 1e3:.3g} ms (at most "
                              f"{t_best * 1e3:.3g} ms), and the scene starts at {scene.near_m:.3g} m, inside "
                              f"the rain-visible region (< R z_m = {z_v:.3g} m): rain at the scene's depth "
                              "cannot be defocused without defocusing the scene (Table 1 rows e-f)"))
    new = Settings(float(t_best), n_best, z_best)
    kw = dict(radius_m=a_ref_m, r_visible=r_visible)
    s_new = sigma_r_for(profile, new, **kw)
    s_cur = sigma_r_for(profile, current, **kw)
    factor = s_new / s_cur
    # why
    if t_best == t_motion:
        why.append(f"exposure {t_best * 1e3:.3g} ms: the longest that keeps {scene.motion_px_s:g} px/s of "
                   "motion within one pixel of blur (sigma_r ~ 1/sqrt(T), Eq. 27)")
    elif t_best == exp_range[1]:
        why.append(f"exposure {t_best * 1e3:.3g} ms: the camera's longest (sigma_r ~ 1/sqrt(T), Eq. 27)")
    else:
        why.append(f"exposure {t_best * 1e3:.3g} ms: the frame interval, keeping the full "
                   f"{profile.frame_rate_hz:g} frames/s (sigma_r ~ 1/sqrt(T), Eq. 27)")
    if t_best > frame_t * (1 + 1e-9):
        cause = ("the scene reaches past the hyperfocal distance of the widest aperture "
                 f"({hyperfocal_open:.3g} m), so the aperture cannot defocus the rain") if pinned else \
            ("the rain is heavy" if heavy else "the slow shutter was requested")
        why.append(f"slow shutter beyond the {frame_t * 1e3:.3g} ms frame interval (effective "
                   f"{1.0 / t_best:.3g} frames/s) because {cause}")
    elif t_motion > frame_t * (1 + 1e-9) and exp_range[1] > frame_t * (1 + 1e-9) and not allow_slow:
        why.append("no slow shutter: the aperture can defocus the rain instead, keeping the frame rate")
    near, far = _dof(profile, n_best, z_best)
    why.append(f"F/{n_best:.3g} focused at {z_best:.3g} m: the setting with the least rain whose depth of "
               f"field ({near:.3g}-{'inf' if math.isinf(far) else f'{far:.3g}'} m, 1 px) holds the scene "
               f"{scene.near_m:.3g}-{'inf' if math.isinf(scene.far_m) else f'{scene.far_m:.3g}'} m "
               "(wider apertures blur nearby drops, Fig. 15(b))")
    gain = _gain_db(current, new)
    why.append(f"gain {gain:+.1f} dB keeps the brightness (Eq. 20)"
               + (f" (more than a camcorder's usual {GAIN_RANGE_DB:g} dB of gain control: use a neutral-density "
                  "filter or accept the brightness change)" if abs(gain) > GAIN_RANGE_DB else ""))
    cur_problems = _scene_sharp(profile, current, scene)
    if cur_problems:
        why.append("the current settings do not keep this scene sharp (" + "; ".join(cur_problems) + ")")
    why.append(f"predicted sigma_r x{factor:.3g} of the current T={current.exposure_s * 1e3:.3g} ms, "
               f"N={current.f_number:g}, z0={current.focus_distance_m:g} m")
    return Advice("reduce", True, new, reason="; ".join(why), predicted_reduction=factor, sigma_r=s_new,
                  sigma_r_current=s_cur, gain_change_db=gain,
                  effective_frame_rate_hz=min(profile.frame_rate_hz, 1.0 / new.exposure_s), scene=scene,
                  details={"rain_visible_limit_m": z_v})


# -------------------------------------------------------------------- gauge
def _velocity(diam_m, velocity_model):
    from raingauge.physics import drops

    return np.asarray(drops.fall_velocity(diam_m, model=velocity_model), dtype=float)


def gauge_sample_volumes(profile, settings: Settings, diameters_m, *, acceptance=1.0,
                         z_near_m=vis.Z_NEAR_M):
    """Sample volume [m^3] and its horizontal cross-section [m^2] per drop diameter.

    A drop of radius a at depth z is measured when it is at least a pixel wide
    (z <= z_m = 2 f a) and its blur circle is at most ``acceptance`` times its
    focused width (b_c <= acceptance * 2 f a / z, i.e.
    |z - z0| <= acceptance z_m / K with b_c = K |z - z0| / z).  The volume is
    the part of the view pyramid between those depths:
    V = W H (z_hi^3 - z_lo^3) / (3 f^2), and the horizontal cross-section that
    falling drops cross is A = W (z_hi^2 - z_lo^2) / (2 f) (W, H image size
    [px], f [px]).

    Returns
    -------
    (volume_m3, area_m2, z_lo_m, z_hi_m) : ndarrays shaped like ``diameters_m``
    """
    f = profile.focal_length_px
    d = np.asarray(diameters_m, dtype=float)
    zm = f * d
    k = vis._blur_k(focal_length_px=f, f_number=settings.f_number,
                    focus_distance_m=settings.focus_distance_m, pixel_pitch_m=_pitch(profile))
    half = acceptance * zm / k
    z0 = settings.focus_distance_m
    z_lo = np.maximum(z0 - half, z_near_m)
    z_hi = np.minimum(z0 + half, zm)
    ok = z_hi > z_lo
    vol = np.where(ok, profile.width_px * profile.height_px * (z_hi**3 - z_lo**3) / (3.0 * f * f), 0.0)
    area = np.where(ok, profile.width_px * (z_hi**2 - z_lo**2) / (2.0 * f), 0.0)
    return vol, area, np.where(ok, z_lo, np.nan), np.where(ok, z_hi, np.nan)


def gauge_counting(profile, settings: Settings, rain_rate_mm_h: float, *, window_s=60.0,
                   velocity_model="gunn_kinzer", acceptance=1.0):
    """Expected drops per minute and the Poisson counting uncertainty of the rate.

    The gauge's rate over a window t is h = 3.6e6 sum_i (pi/6) D_i^3 / (A(D_i) t)
    (the water that crossed unit horizontal area, Eq. 28 as a flux); the count
    in each Parsivel diameter class is Poisson with mean
    N(D) dD v(D) A(D) t (Marshall-Palmer N(D)), so
    var h = (3.6e6)^2 sum_j lambda_j ((pi/6) D_j^3 / (A_j t))^2.

    Returns
    -------
    dict with drops_per_minute, rate_measured_mm_h (drops the gauge sizes; below
    the true rate by the unseen small drops), rate_rel_uncertainty (1 sigma),
    drops_per_frame.
    """
    from raingauge.physics import drops

    dsd = drops.MarshallPalmer(rain_rate_mm_h)
    centres = drops.PARSIVEL_D_CENTRES_MM * 1e-3
    widths = drops.PARSIVEL_D_WIDTHS_MM * 1e-3
    keep = (centres >= dsd.d_min_m) & (centres <= dsd.d_max_m)
    centres, widths = centres[keep], widths[keep]
    vol, area, _, _ = gauge_sample_volumes(profile, settings, centres, acceptance=acceptance)
    v = _velocity(centres, velocity_model)
    v = np.where(np.isfinite(v), v, 0.0)
    conc = dsd.number_density(centres) * widths  # m^-3 per class
    lam = conc * v * area * window_s
    water = math.pi / 6.0 * centres**3
    with np.errstate(divide="ignore", invalid="ignore"):
        per_drop = np.where(area > 0, 3.6e6 * water / (area * window_s), 0.0)
    rate = float(np.sum(lam * per_drop))
    sd = float(math.sqrt(np.sum(lam * per_drop**2)))
    true_rate = float(drops.rain_rate_mm_h(dsd, velocity_model=velocity_model))
    return {
        "rain_rate_mm_h": rain_rate_mm_h,
        "drops_per_minute": float(np.sum(conc * v * area) * 60.0),
        "drops_per_frame": float(np.sum(conc * vol)),
        "rate_measured_mm_h": rate,
        "rate_dsd_mm_h": true_rate,
        "rate_rel_uncertainty": sd / rate if rate > 0 else math.inf,
        "window_s": window_s,
    }


def advise_gauge(profile, *, a_min_m: float = 0.5e-3, window_s: float = 60.0,
                 rain_rates_mm_h=(1.0, 10.0, 50.0), velocity_model: str = "gunn_kinzer",
                 acceptance: float = 1.0) -> Advice:
    """Settings that enhance rain for the camera rain gauge (Sec. 8) and what they sample.

    z0 = 2 f a_min (the largest focus distance at which drops of radius a_min
    are a pixel wide, z0 <= 2 f a_min), the widest aperture, and the shortest
    exposure that still gives a measurable streak (>= 3 px for a_min drops)
    and keeps the photometric constraint usable (T >= 2 tau_max, Eq. 29).

    Parameters
    ----------
    profile : CameraProfile
    a_min_m : float [m]
        Radius of the smallest drop to size (the paper's a_min = 0.5 mm).
    window_s : float [s]
        Averaging window of the counting uncertainty.
    rain_rates_mm_h : sequence of float [mm/h]
    velocity_model : str
        Fall-velocity law of the rain (raingauge.physics.drops registry).
    acceptance : float [-]
        Largest blur circle accepted, as a multiple of the focused width.
    """
    from raingauge.physics import streaks

    if not (a_min_m > 0):
        raise ConfigError(f"a_min_m must be > 0 m, got {a_min_m!r}")
    exp_range, fnum_range, focus_range = _ranges(profile)
    f = profile.focal_length_px
    z_limit = 2.0 * f * a_min_m
    if z_limit < focus_range[0]:
        return Advice("gauge", False, None,
                      reason=(f"X: z0 <= 2 f a_min = {z_limit:.3g} m, nearer than the lens focuses "
                              f"({focus_range[0]:g} m). Fix: a longer focal length or a close-up lens"))
    z0 = min(z_limit, focus_range[1])
    n = fnum_range[0]
    v_min = float(_velocity(2.0 * a_min_m, velocity_model))
    t_streak = 3.0 * z0 / (f * v_min)
    t_photo = 2.0 * streaks.tau_max_s()
    t = min(max(exp_range[0], t_streak, t_photo), exp_range[1], profile.frame_interval_s
            if exp_range[1] > profile.frame_interval_s else exp_range[1])
    settings = Settings(float(t), float(n), float(z0))
    from raingauge.physics import drops

    centres = drops.PARSIVEL_D_CENTRES_MM * 1e-3
    keep = centres <= drops.DEFAULT_D_MAX_M
    vol, area, z_lo, z_hi = gauge_sample_volumes(profile, settings, centres[keep], acceptance=acceptance)
    per_class = [
        {"d_mm": float(d * 1e3), "volume_m3": float(vv), "area_m2": float(aa),
         "z_lo_m": None if np.isnan(lo) else float(lo), "z_hi_m": None if np.isnan(hi) else float(hi)}
        for d, vv, aa, lo, hi in zip(centres[keep], vol, area, z_lo, z_hi)
    ]
    v_ref, _, _, _ = gauge_sample_volumes(profile, settings, [2.0 * a_min_m], acceptance=acceptance)
    counting = [gauge_counting(profile, settings, h, window_s=window_s, velocity_model=velocity_model,
                               acceptance=acceptance) for h in rain_rates_mm_h]
    v_fast = float(_velocity(5.5e-3, velocity_model))
    streak_fast = f * v_fast * t / z0
    why = [
        f"focus z0 = {z0:.3g} m <= 2 f a_min = {z_limit:.3g} m: drops of radius >= {a_min_m * 1e3:g} mm are "
        "at least a pixel wide in focus (Sec. 8)",
        f"F/{n:g}, the widest aperture: the shallowest depth of field, a thin sample volume and few "
        "overlapping streaks, and defocused drops fail the size-velocity test",
        f"exposure {t * 1e3:.3g} ms: short, so streaks stay bright (beta = tau/T), yet >= 3 px long for "
        f"the smallest drops and >= 2 tau_max; the fastest drops streak {streak_fast:.0f} px",
    ]
    lines = ", ".join(f"{c['rain_rate_mm_h']:g} mm/h: {c['drops_per_minute']:.0f} drops/min, "
                      f"+-{100 * c['rate_rel_uncertainty']:.1f}% per {window_s:g} s" for c in counting)
    why.append(lines)
    return Advice("gauge", True, settings, reason="; ".join(why), details={
        "sample_volume_m3": float(v_ref[0]),
        "sample_volume_for_d_mm": 2e3 * a_min_m,
        "a_min_m": a_min_m,
        "per_class": per_class,
        "counting": counting,
        "velocity_model": velocity_model,
    })


def advise(profile, goal: str, scene: Scene | None = None, **kw) -> Advice:
    """Dispatch on ``goal`` ("reduce" needs a scene)."""
    if goal not in GOALS:
        raise ConfigError(f"unknown goal {goal!r}; valid: {', '.join(GOALS)}")
    if goal == "reduce":
        if scene is None:
            raise ConfigError("goal 'reduce' needs a scene (motion, near distance, depth range)")
        return advise_reduce(profile, scene, **kw)
    return advise_gauge(profile, **kw)


def table1(profile, **kw) -> dict[str, Advice]:
    """Table 1 of [GargNayar2007] for this camera: row label -> :class:`Advice`."""
    out = {}
    for label, (motion, near, depth, _t, _n) in TABLE1_ROWS.items():
        scene = make_scene(profile, motion=motion, near=near, depth=depth)
        out[label] = advise_reduce(profile, scene, **kw)
    return out
