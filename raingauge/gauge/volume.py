"""The gauge's sample volume, per drop size, from the camera profile (Sec. 8).

A drop of radius a at depth z, measured at the focus distance z0 (Sec. 8
[GargNayar2007]), shows an apparent width w' = sqrt(w^2 + b^2) with
w = 2 f a / z (Eq. 26 as corrected) and b the thin-lens blur circle
(``raingauge.physics.camera.blur_circle_px``; a pillbox of diameter b has
the variance b^2/16 across the streak, the same as a disc's chord of diameter
b), and an apparent speed v' = V(a) z0 / z.  The defocus test of
:mod:`raingauge.gauge.rejection` accepts it with probability

    P(a, z) = Phi((tol - r) / s) - Phi((-tol - r) / s),  r = ln(v' / V(a')),

s being the measurement's standard error of r.  Each depth slab dz holds, per
pixel of the image, (z / f)^2 dz of space, so the gauge samples

    kappa(a) = int P(a, z) (z / f)^2 dz        [m^3 per px^2 of image]

and the volume imaged by the whole frame is kappa(a) times the frame's area
in pixels, less the border in which a streak is cut by the edge (edge
clipping: a streak w + |dx| wide and w + |dy| tall is whole only when it
starts inside a (N - w - |dx|) x (M - w - |dy|) rectangle).

Counting each drop once over consecutive frames (flux counting), a drop whose
streak moves (u_x, u_y) px/s is counted if it is whole in at least one frame;
the expected count per second per unit of image density is
:func:`effective_area_rate_px2_s`, from the identity
int min(d, chord) = |R| - |R intersect (R + d)| for a convex region R.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from raingauge.gauge.rejection import (
    DEFAULT_BLUR_FLOOR_PX,
    DEFAULT_BLUR_RELATIVE,
    DEFAULT_BLUR_SIGMA_PX,
    DEFAULT_K_SIGMA,
    DEFAULT_Q_MIN,
    DEFAULT_MOTION_SIGMA_PX,
    DEFAULT_TOLERANCE_FLOOR,
    DEFAULT_WIDTH_SIGMA_PX,
    law_tolerance,
    max_blur_px,
    q_sigma,
    ratio_sigma,
    velocity_log_ratio,
)

__all__ = [
    "SampleVolume",
    "pass_probability",
    "effective_area_rate_px2_s",
    "whole_streak_area_px2",
    "EDGE_MARGIN_PX",
    "DEFOCUS_MODELS",
]

#: How defocus widens a streak (see :func:`pass_probability`).
DEFOCUS_MODELS = ("uniform", "pillbox")

#: Streaks closer than this to the frame edge count as clipped [px].
EDGE_MARGIN_PX = 2.0


def _pitch(profile) -> float:
    return profile.pixel_pitch_m if profile.pixel_pitch_m else 5e-6


def pass_probability(radius_m: float, z_m, profile, *, velocity_model: str = "paper",
                     rain_velocity_model: str | None = None, floor: float = DEFAULT_TOLERANCE_FLOOR,
                     k_sigma: float = DEFAULT_K_SIGMA, width_sigma_px: float = DEFAULT_WIDTH_SIGMA_PX,
                     motion_sigma_px: float = DEFAULT_MOTION_SIGMA_PX, blur_variance_factor: float = 1.0,
                     blur_floor_px: float = DEFAULT_BLUR_FLOOR_PX, blur_relative: float = DEFAULT_BLUR_RELATIVE,
                     blur_sigma_px: float = DEFAULT_BLUR_SIGMA_PX, defocus_model: str = "uniform",
                     q_min: float = DEFAULT_Q_MIN) -> dict:
    """Probability that a drop of radius a at depth z passes the defocus test.

    Parameters
    ----------
    radius_m : float
        True drop radius a [m].
    z_m : array_like
        Depths [m].
    profile : CameraProfile
    velocity_model : str
        The law the gauge tests against.
    rain_velocity_model : str, optional
        The law the drops follow (default: the same).
    floor, k_sigma, width_sigma_px, motion_sigma_px :
        The velocity test's tolerance (see :mod:`raingauge.gauge.rejection`).
    blur_floor_px, blur_relative, blur_sigma_px :
        The blur test: b <= max(floor, relative w), fitted with this standard error
        (``"pillbox"`` only).
    defocus_model : str
        ``"uniform"``: the paper's Eqs. (23)-(24), the drop's change spread
        evenly over a streak w + b wide (w' = w + b; edges stay sharp): the
        velocity law and the photometric focus q = (w / w')^2 >= ``q_min``
        reject defocus (:func:`raingauge.gauge.rejection.photometric_focus`).  ``"pillbox"``: convolution with
        the blur circle (w'^2 = w^2 + factor b^2, soft edges, the blur test applies).
    blur_variance_factor : float
        w'^2 = w^2 + factor b^2 (1 for a pillbox blur) [-].

    Returns
    -------
    dict of arrays over ``z_m``: ``p`` (probability), ``apparent_radius_m``,
    ``apparent_velocity_m_s``, ``width_px``, ``blur_px``, ``motion_px``.
    """
    from raingauge.physics.camera import blur_circle_px
    from raingauge.physics.drops import fall_velocity
    from scipy.special import ndtr

    z = np.asarray(z_m, dtype=float)
    f = profile.focal_length_px
    z0 = profile.focus_distance_m
    if defocus_model not in DEFOCUS_MODELS:
        raise ValueError(f"unknown defocus model {defocus_model!r}; valid: {list(DEFOCUS_MODELS)}")
    w = np.maximum(2.0 * f * radius_m / z, 1.0)
    b = blur_circle_px(z, focal_length_px=f, f_number=profile.f_number, focus_distance_m=z0,
                       pixel_pitch_m=_pitch(profile))
    if defocus_model == "uniform":
        w_app = w + b
    else:
        w_app = np.sqrt(w * w + blur_variance_factor * b * b)
    a_app = w_app * z0 / (2.0 * f)
    v_true = float(fall_velocity(2.0 * radius_m, model=rain_velocity_model or velocity_model))
    v_app = v_true * z0 / z
    motion = f * v_true * profile.exposure_s / z
    r = velocity_log_ratio(a_app, v_app, model=velocity_model)
    tol = law_tolerance(a_app, w_app, motion, floor=floor, k_sigma=k_sigma, model=velocity_model)
    sig = ratio_sigma(a_app, w_app, motion, width_sigma_px=width_sigma_px,
                      motion_sigma_px=motion_sigma_px, model=velocity_model)
    sig = np.maximum(sig, 1e-6)
    p = np.where(np.isfinite(r), ndtr((tol - r) / sig) - ndtr((-tol - r) / sig), 0.0)
    if defocus_model == "pillbox":
        bmax = max_blur_px(w, floor_px=blur_floor_px, relative=blur_relative)
        p = p * ndtr((bmax - np.sqrt(blur_variance_factor) * b) / blur_sigma_px)
    else:
        q = (2.0 * f * radius_m / z / w_app) ** 2
        p = p * ndtr((q - q_min) / q_sigma(q, w_app))
    if not np.isfinite(v_true):
        p = np.zeros_like(z)
    return {"p": p, "apparent_radius_m": a_app, "apparent_velocity_m_s": v_app, "width_px": w,
            "blur_px": b, "motion_px": motion}


def whole_streak_area_px2(motion_px, width_px, shape, *, margin_px: float = EDGE_MARGIN_PX) -> np.ndarray:
    """Area of the start positions from which a streak lies whole in the frame [px^2].

    (N - w - |dx| - 2 m)+ (M - w - |dy| - 2 m)+ for a frame of shape (M, N).

    Parameters
    ----------
    motion_px : (..., 2) array_like
        Streak motion (dx, dy) during the exposure [px].
    width_px : array_like
        Streak width w [px].
    shape : (M, N)
        Frame shape [px].
    margin_px : float
        Border within which a streak counts as clipped [px].
    """
    mot = np.asarray(motion_px, dtype=float)
    w = np.asarray(width_px, dtype=float)
    M, N = shape
    wr = np.clip(N - w - np.abs(mot[..., 0]) - 2 * margin_px, 0, None)
    hr = np.clip(M - w - np.abs(mot[..., 1]) - 2 * margin_px, 0, None)
    return wr * hr


def effective_area_rate_px2_s(motion_px, width_px, shape, *, exposure_s: float, frame_interval_s: float,
                              margin_px: float = EDGE_MARGIN_PX) -> np.ndarray:
    """Rate at which distinct drops are counted per unit image density [px^2/s].

    A drop moving (dx, dy) px per exposure T moves d = (dx, dy) Delta/T between
    frames; it is counted once if its streak is whole in at least one frame.
    With R the W_R x H_R rectangle of whole-streak start positions
    (:func:`whole_streak_area_px2`), the expected count per second is
    density x [W_R H_R - (W_R - |d_x|)+ (H_R - |d_y|)+] / Delta: every drop
    crossing R when the frames are close enough, W_R H_R / Delta (the
    snapshot rate) when a drop jumps past R between frames.

    Parameters
    ----------
    motion_px : (..., 2) array_like
        Streak motion (dx, dy) during the exposure [px].
    width_px : array_like
        Streak width [px].
    shape : (M, N)
        Frame shape [px].
    exposure_s : float
        Exposure T [s].
    frame_interval_s : float
        Frame interval Delta [s].

    Returns
    -------
    ndarray [px^2/s]
    """
    mot = np.asarray(motion_px, dtype=float)
    w = np.asarray(width_px, dtype=float)
    M, N = shape
    wr = np.clip(N - w - np.abs(mot[..., 0]) - 2 * margin_px, 0, None)
    hr = np.clip(M - w - np.abs(mot[..., 1]) - 2 * margin_px, 0, None)
    scale = frame_interval_s / exposure_s
    dx = np.abs(mot[..., 0]) * scale
    dy = np.abs(mot[..., 1]) * scale
    overlap = np.clip(wr - dx, 0, None) * np.clip(hr - dy, 0, None)
    return (wr * hr - overlap) / frame_interval_s


@dataclass
class SampleVolume:
    """Sample volume of a camera profile per drop radius (tabulated).

    Parameters
    ----------
    profile : CameraProfile
    velocity_model : str
        The law of the defocus test (and of the drops).
    rain_velocity_model : str, optional
        The law the drops follow when it differs (for studies of a mismatch).
    floor, k_sigma : float
        Tolerance of the test (see :mod:`raingauge.gauge.rejection`).
    blur_variance_factor, defocus_model :
        See :func:`pass_probability`.
    radii_m : array, optional
        Radius grid [m] (default 0.1-4 mm, 80 log-spaced points).

    Attributes
    ----------
    kappa_m3_px2 : ndarray
        kappa(a) [m^3/px^2] on ``radii_m``.
    mean_depth_m : ndarray
        Mean depth of the accepted drops, weighted by the sampled space [m].
    apparent_radius_factor : ndarray
        (E[(a'/a)^3 | accepted])^(1/3): how much larger the accepted drops of
        radius a look at z0, the blur included [-].
    """

    profile: object
    velocity_model: str = "paper"
    rain_velocity_model: str | None = None
    floor: float = DEFAULT_TOLERANCE_FLOOR
    k_sigma: float = DEFAULT_K_SIGMA
    blur_variance_factor: float = 1.0
    defocus_model: str = "uniform"
    q_min: float = DEFAULT_Q_MIN
    radii_m: np.ndarray = field(default_factory=lambda: np.geomspace(0.1e-3, 4.0e-3, 80))
    min_width_px: float = 1.0

    def __post_init__(self):
        prof = self.profile
        z0 = prof.focus_distance_m
        f = prof.focal_length_px
        z = np.linspace(0.4 * z0, 2.5 * z0, 1600)
        dz = z[1] - z[0]
        kap, zbar, fac = [], [], []
        for a in self.radii_m:
            res = pass_probability(a, z, prof, velocity_model=self.velocity_model,
                                   rain_velocity_model=self.rain_velocity_model, floor=self.floor,
                                   k_sigma=self.k_sigma, blur_variance_factor=self.blur_variance_factor,
                                   defocus_model=self.defocus_model, q_min=self.q_min)
            wt = res["p"] * (z / f) ** 2 * dz
            k = float(wt.sum())
            kap.append(k)
            if k > 0:
                zbar.append(float((wt * z).sum() / k))
                fac.append(float(((wt * (res["apparent_radius_m"] / a) ** 3).sum() / k) ** (1 / 3)))
            else:
                zbar.append(z0)
                fac.append(1.0)
        self.kappa_m3_px2 = np.array(kap)
        self.mean_depth_m = np.array(zbar)
        self.apparent_radius_factor = np.array(fac)
        # below one pixel of focused width the size cannot be measured
        self.min_radius_m = self.min_width_px * z0 / (2.0 * f)

    # -- per radius
    def kappa(self, radius_m) -> np.ndarray:
        """kappa(a) [m^3 per px^2 of image], 0 below the measurable size."""
        a = np.asarray(radius_m, dtype=float)
        k = np.interp(np.log(np.clip(a, 1e-9, None)), np.log(self.radii_m), self.kappa_m3_px2,
                      left=0.0, right=self.kappa_m3_px2[-1])
        return np.where(a >= self.min_radius_m, k, 0.0)

    def depth_m(self, radius_m) -> np.ndarray:
        """Mean depth of accepted drops of radius a [m]."""
        a = np.asarray(radius_m, dtype=float)
        return np.interp(np.log(np.clip(a, 1e-9, None)), np.log(self.radii_m), self.mean_depth_m)

    def true_radius_m(self, apparent_radius_m) -> np.ndarray:
        """Invert a' = a F(a): the drop radius behind an apparent radius at z0 [m]."""
        app = self.radii_m * self.apparent_radius_factor
        order = np.argsort(app)
        a = np.asarray(apparent_radius_m, dtype=float)
        return np.interp(a, app[order], self.radii_m[order])

    def depth_range_m(self, radius_m: float, *, p_min: float = 0.5) -> tuple[float, float]:
        """Depths [m] between which a drop of radius a passes with probability >= p_min."""
        z0 = self.profile.focus_distance_m
        z = np.linspace(0.4 * z0, 2.5 * z0, 4000)
        p = pass_probability(radius_m, z, self.profile, velocity_model=self.velocity_model,
                             rain_velocity_model=self.rain_velocity_model, floor=self.floor,
                             k_sigma=self.k_sigma, blur_variance_factor=self.blur_variance_factor,
                                   defocus_model=self.defocus_model, q_min=self.q_min)["p"]
        ok = np.nonzero(p >= p_min)[0]
        if ok.size == 0:
            return (z0, z0)
        return float(z[ok[0]]), float(z[ok[-1]])

    def volume_m3(self, radius_m, *, motion_px=None) -> np.ndarray:
        """Snapshot sample volume of one frame [m^3], corrected for edge clipping.

        kappa(a) times the area of whole-streak start positions; the streak
        motion defaults to that of a drop of radius a falling at the law's
        speed at z0.
        """
        from raingauge.physics.drops import fall_velocity

        prof = self.profile
        a = np.asarray(radius_m, dtype=float)
        f = prof.focal_length_px
        z0 = prof.focus_distance_m
        w = 2 * f * a / z0
        if motion_px is None:
            v = fall_velocity(2 * a, model=self.rain_velocity_model or self.velocity_model)
            motion_px = np.stack([np.zeros_like(a), f * v * prof.exposure_s / z0], axis=-1)
        area = whole_streak_area_px2(motion_px, w, prof.shape)
        return self.kappa(a) * area
