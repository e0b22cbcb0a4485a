"""Does the completeness probe count its drops as the gauge counts the same drops in the video?

The probe (:class:`raingauge.gauge.completeness.CompletenessProbe`) corrects the sample
volume by what the gauge makes of artificial drops added to copies of its frames.  Its
correction is only as good as its drops are like the real ones.  This script renders,
into a simulated rain clip, extra drops of one radius a at one depth z, and
pins the probe to the same a and z (:func:`raingauge.gauge.fidelity.probe_fidelity`),
and prints, per (a, z):

* the share of the extra drops the gauge counted (a counted drop within the streak's
  radius + 3 px across and a quarter of its length + 3 px along its centre),
* the share of the probe's drops it counted, and
* the rain the gauge credits each with on average, (2 a_m)^3 v_m / kappa(a_m) at its
  measured size and speed (0 when not counted), the quantity the probe's ratio sums,
  with its standard error, relative to the probe's (extra / probe), and
* the model's pass probability p(a, z) averaged over the probe's drops, and
* the photometric focus q' of the gauge's brightness samples (mostly the extra drops'
  streaks, against the simulator's E_r) and of the probe's drops (against theirs): the
  fixed point of the percentile the drop brightness E_r is estimated at, the median and
  the count.

The two agree where the probe is faithful.  By default the gauge is given the
simulator's drop brightness E_r: its own estimate leans on the focus of the streaks it
sees, and many sharp drops of one size move it.  ``--rejections`` prints under each point
how many streaks of the video each of the gauge's tests turned away (``no_volume``: a drop
measured at a size whose modelled sample volume lies under the floor, left to the
spectrum's completion).

    python benchmarks/diag_probe_fidelity.py --background bright_sky --points 0.45:2.48,0.5:2.5
    python benchmarks/diag_probe_fidelity.py --background dark_uniform --points 0.2:2.5 --seconds 20
    python benchmarks/diag_probe_fidelity.py --background bright_sky --noise 1 --rate 0.5 --wind 3 --points 0.4:2.5 --seconds 20
    python benchmarks/diag_probe_fidelity.py --background dark_uniform --rate 0.3 --wind 3 --points 0.35:2.5 --rejections
    python benchmarks/diag_probe_fidelity.py --background textured_still --noise 1 --rate 0.3 --wind 3 \
        --points 1.0:2.5,0.5:2.5,2.0:2.42 --seconds 20 --seed 5
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _clip_args import add_clip_arguments, frame_size  # noqa: E402
from bench_gauge_accuracy import BACKGROUNDS  # noqa: E402

from raingauge.gauge.fidelity import probe_fidelity  # noqa: E402

def _ratio(a, b) -> str:
    """'r +- se' of two (mean, standard error) pairs, the errors in quadrature."""
    (ma, sa), (mb, sb) = a, b
    if not (mb > 0 and ma >= 0):
        return f"{'n/a':>28s}"
    r = ma / mb
    se = r * ((sa / ma) ** 2 + (sb / mb) ** 2) ** 0.5 if ma > 0 else float("nan")
    return f"{r:20.3f} +- {se:5.3f}"


def _focus(summary) -> str:
    """'P (median, n)' of a focus summary."""
    p, med, n = summary
    return f"{p:5.3f} ({med:5.3f}, {n:4d})" if n else f"{'-':>20s}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_clip_arguments(ap, rate=2.0, dsd="gamma3", seconds=30.0, seed=12, dsds=("marshall_palmer", "gamma3"))
    ap.add_argument("--points", default="0.45:2.48,0.5:2.5,0.55:2.53",
                    help="drops as RADIUS_MM:DEPTH_M, comma-separated")
    ap.add_argument("--wind", type=float, default=0.0, help="cross wind [m/s]: the drops slant with it")
    ap.add_argument("--rejections", action="store_true",
                    help="also print, per point, how many streaks of the video each of the gauge's tests "
                         "turned away")
    ap.add_argument("--estimate-brightness", action="store_true",
                    help="let the gauge estimate E_r (the extra drops move the estimate)")
    args = ap.parse_args(argv)
    from raingauge.profile import default_profile

    w, h = frame_size(ap, args.size)
    try:
        points = [tuple(float(x) for x in p.split(":")) for p in args.points.split(",")]
        if any(len(p) != 2 for p in points):
            raise ValueError
    except ValueError:
        ap.error(f"--points must be RADIUS_MM:DEPTH_M,..., e.g. --points 0.5:2.5, got {args.points!r}")
    prof = default_profile().replace(width_px=w, height_px=h, noise_sigma_dn=float(args.noise))
    print(f"{args.background}, {args.rate:g} mm/h {args.dsd}, noise {args.noise:g}, wind {args.wind:g} m/s, "
          f"{args.seconds:g} s, "
          f"E_r {'estimated' if args.estimate_brightness else 'given'}")
    print("  a [mm]  z [m]  r [px]  L [px]     extra counted        probe counted        "
          "rain per drop, extra / probe   model p   E_r   q' streaks (median, n)   q' probe (median, n)")
    for a_mm, z in points:
        spec, motion, e_r = BACKGROUNDS[args.background]
        res = probe_fidelity(prof, radius_m=1e-3 * a_mm, depth_m=z, background=spec, motion=motion,
                             drop_brightness_dn=e_r, rain_rate_mm_h=args.rate,
                             dsd="gamma" if args.dsd == "gamma3" else None, seconds=args.seconds,
                             seed=args.seed, wind_m_s=args.wind, given_brightness=not args.estimate_brightness)
        (rh, rt), (ph, pt) = res["real"], res["probe"]
        print(f"  {a_mm:6.3f}  {z:5.3f}  {res['radius_px']:6.2f}  {res['length_px']:6.1f}   "
              f"{rh:6d}/{rt:6d} = {rh / max(rt, 1):5.3f}   {ph:5d}/{pt:5d} = {ph / max(pt, 1):5.3f}   "
              f"{_ratio(res['real_share'], res['probe_share'])}   {res['model_p']:7.3f}  "
              f"{res['drop_brightness_dn']:5.1f}   {_focus(res['focus_streaks'])}   {_focus(res['focus_probe'])}")
        if args.rejections:
            print("          turned away: " + ", ".join(f"{k} {v}" for k, v in sorted(res["rejections"].items())
                                                       if v))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
