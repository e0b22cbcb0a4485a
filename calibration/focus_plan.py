"""Lens and focus plan (step 4 of ``raingauge calibrate``).

Sec. 8 [GargNayar2007]: the gauge observes "a small volume of rain" defined by
the F-number and the distance of the focal plane z0; the depth of field is
kept low so that streaks rarely overlap, and z0 is set so that the smallest
drops are visible, z0 <= 2 f a_min (Eq. (26): a drop of radius a at depth z
is w = 2 f a / z pixels wide, at least one pixel up to z_m = 2 f a).

The settings come from the advisor's gauge mode
(:func:`raingauge.advisor.advise_gauge`) applied to the calibrated camera with
the F-numbers the lens actually offers: z0 = min(2 f a_min, the lens's far
focus limit), the widest aperture, and a short exposure (suggested, not
written: the profile keeps the exposure the camera is set to).  This module
adds what the technician needs at the lens:

- the depth of field for a blur circle of ``coc_px`` pixels (thin lens,
  :func:`raingauge.physics.camera.depth_of_field_m`);
- the sample volume: the advisor's volume in which drops of radius a_min are
  measured (a pixel wide and blurred by at most their width), and the
  field of view between the near and far limits of the depth of field, a
  frustum V = (W H / f^2) (z_far^3 - z_near^3) / 3 for a W x H pixel image;
- the expected drop counts and counting uncertainty at 1, 10 and 50 mm/h.
"""

from __future__ import annotations

import dataclasses
import math

from raingauge.errors import InputError

__all__ = ["FocusPlan", "plan_focus", "frustum_volume_m3", "standard_f_numbers", "A_MIN_M"]

#: Radius of the smallest drop the gauge must resolve [m] (Sec. 8 [GargNayar2007]: a_min = 0.5 mm).
A_MIN_M = 0.5e-3

#: Full stops and the common third stops of lens F-number scales.
_STOPS = (1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.2, 2.5, 2.8, 3.2, 3.5, 4.0, 4.5, 5.0, 5.6, 6.3, 7.1, 8.0,
          9.0, 10.0, 11.0, 13.0, 14.0, 16.0, 18.0, 20.0, 22.0, 32.0)


def standard_f_numbers(lo: float, hi: float) -> list[float]:
    """The usual lens F-number marks between ``lo`` and ``hi`` (inclusive) [-]."""
    out = [n for n in _STOPS if lo * (1 - 1e-6) <= n <= hi * (1 + 1e-6)]
    if not out or abs(out[0] - lo) > 1e-6:
        out.insert(0, float(lo))
    return sorted(set(out))


def frustum_volume_m3(z_near_m: float, z_far_m: float, *, width_px: int, height_px: int,
                      focal_length_px: float) -> float:
    """Volume of the field of view between two depths [m^3].

    Parameters
    ----------
    z_near_m, z_far_m : float
        Depth limits [m] (``z_far_m`` may be inf).
    width_px, height_px : int
        Image size [px].
    focal_length_px : float
        Focal length [px].
    """
    if not (z_far_m > z_near_m >= 0):
        return 0.0
    return width_px * height_px / focal_length_px ** 2 * (z_far_m ** 3 - z_near_m ** 3) / 3.0


@dataclasses.dataclass
class FocusPlan:
    """The plan for the lens.

    Attributes
    ----------
    focus_distance_m : float
        Distance of the plane of focus z0 [m].
    f_number : float
        Aperture to set [-].
    exposure_s : float
        Exposure the advisor suggests [s].
    z_max_m : float
        2 f a_min, the farthest focus at which the smallest drop is a pixel wide [m].
    near_m, far_m : float
        Depth-of-field limits for a blur circle of ``coc_px`` [m] (far may be inf).
    dof_volume_m3 : float
        Field of view between near and far [m^3] (inf when far is).
    sample_volume_m3 : float
        Volume in which drops of radius a_min are measured (advisor) [m^3].
    a_min_m : float
        Radius of the smallest drop [m].
    focal_length_mm : float
        f in millimetres (f_px times the pitch) [mm].
    coc_px : float
        Blur circle counted as sharp [px].
    counting : list of dict
        Advisor's expected drops per minute and rate uncertainty per rain rate.
    notes : list of str
    """

    focus_distance_m: float
    f_number: float
    exposure_s: float
    z_max_m: float
    near_m: float
    far_m: float
    dof_volume_m3: float
    sample_volume_m3: float
    a_min_m: float
    focal_length_mm: float
    coc_px: float
    counting: list
    notes: list[str]

    def summary(self) -> str:
        far = "infinity" if math.isinf(self.far_m) else f"{self.far_m:.3f} m"
        dof_v = "unbounded" if math.isinf(self.dof_volume_m3) else f"{self.dof_volume_m3 * 1e3:.3f} litres"
        lines = [
            f"focus distance    z0 = {self.focus_distance_m:.4g} m (2 f a_min = {self.z_max_m:.4g} m for "
            f"a_min = {self.a_min_m * 1e3:.2f} mm)",
            f"aperture          F/{self.f_number:g} (focal length {self.focal_length_mm:.2f} mm)",
            f"depth of field    {self.near_m:.4g} m to {far} (blur circle {self.coc_px:g} px): {dof_v}",
            f"sample volume     {self.sample_volume_m3 * 1e3:.3f} litres for drops of "
            f"{2e3 * self.a_min_m:.2g} mm diameter",
            f"exposure          {self.exposure_s * 1e3:.3g} ms suggested",
        ]
        for c in self.counting:
            lines.append(f"{'at %g mm/h' % c['rain_rate_mm_h']:<18}{c['drops_per_minute']:.0f} drops/min, rate "
                         f"+-{100 * c['rate_rel_uncertainty']:.1f}% per {c['window_s']:g} s")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_provenance(self) -> dict:
        def fin(v, nd=6):
            return float(f"{v:.{nd}g}") if math.isfinite(v) else "inf"

        return {
            "calibrated": True,
            "focus_distance_m": fin(self.focus_distance_m),
            "f_number": self.f_number,
            "suggested_exposure_s": fin(self.exposure_s),
            "z_max_m": fin(self.z_max_m),
            "dof_near_m": fin(self.near_m),
            "dof_far_m": fin(self.far_m),
            "dof_volume_m3": fin(self.dof_volume_m3),
            "sample_volume_m3": fin(self.sample_volume_m3),
            "a_min_m": self.a_min_m,
            "coc_px": self.coc_px,
            "drops_per_minute": {f"{c['rain_rate_mm_h']:g}_mm_h": fin(c["drops_per_minute"], 4)
                                 for c in self.counting},
            "notes": list(self.notes),
        }


def plan_focus(
    profile,
    *,
    f_numbers: list[float],
    pixel_pitch_m: float | None = None,
    a_min_m: float = A_MIN_M,
    coc_px: float = 1.0,
) -> FocusPlan:
    """Focus distance, aperture and sample volume for the gauge (Sec. 8 [GargNayar2007]).

    Parameters
    ----------
    profile : CameraProfile
        The camera as calibrated so far (focal length, image size, focus range).
    f_numbers : list of float
        F-numbers the lens offers [-].
    pixel_pitch_m : float, optional
        Pixel pitch [m]; default the profile's.
    a_min_m : float
        Radius of the smallest drop to size [m].
    coc_px : float
        Blur circle accepted as in focus for the depth of field [px].

    Raises
    ------
    InputError
        No F-numbers, unknown pixel pitch, or a lens that cannot focus near
        enough for 2 f a_min.
    """
    from raingauge import advisor
    from raingauge.physics import camera

    pitch = pixel_pitch_m if pixel_pitch_m is not None else profile.pixel_pitch_m
    for name, value in (("pixel_pitch_m", pitch), ("a_min_m", a_min_m), ("coc_px", coc_px)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError(f"focus plan: {name} must be a positive number, got {value!r}. "
                             "Fix: e.g. --pixel-pitch-m 3.45e-6 from the sensor's data sheet")
    if not f_numbers or any(not (n >= 0.5) for n in f_numbers):
        raise InputError(f"focus plan: the lens's F-numbers are needed (all >= 0.5), got {f_numbers!r}. "
                         "Fix: e.g. --f-numbers 1.4,2,2.8,4,5.6,8")
    cam = profile.replace(pixel_pitch_m=float(pitch),
                          f_number_range=[float(min(f_numbers)), float(max(f_numbers))])
    advice = advisor.advise_gauge(cam, a_min_m=a_min_m)
    if not advice.feasible:
        raise InputError(f"focus plan: {advice.reason}")
    s = advice.settings
    z0, n = float(s.focus_distance_m), float(s.f_number)
    near, far = camera.depth_of_field_m(focal_length_px=cam.focal_length_px, f_number=n, focus_distance_m=z0,
                                        pixel_pitch_m=float(pitch), coc_px=coc_px)
    z_max = float(camera.z_m(a_min_m, focal_length_px=cam.focal_length_px))
    notes: list[str] = []
    if z0 < z_max * (1 - 1e-9):
        notes.append(f"the lens focuses no farther than {z0:g} m; z0 set there")
    dof_volume = frustum_volume_m3(near, far, width_px=cam.width_px, height_px=cam.height_px,
                                   focal_length_px=cam.focal_length_px) if math.isfinite(far) else math.inf
    if not math.isfinite(far):
        notes.append("the depth of field reaches infinity: streaks will overlap in heavy rain; "
                     "a longer focal length or a wider aperture bounds the volume")
    return FocusPlan(
        focus_distance_m=z0,
        f_number=n,
        exposure_s=float(s.exposure_s),
        z_max_m=z_max,
        near_m=float(near),
        far_m=float(far),
        dof_volume_m3=float(dof_volume),
        sample_volume_m3=float(advice.details["sample_volume_m3"]),
        a_min_m=float(a_min_m),
        focal_length_mm=cam.focal_length_px * float(pitch) * 1e3,
        coc_px=float(coc_px),
        counting=list(advice.details.get("counting", [])),
        notes=notes,
    )
