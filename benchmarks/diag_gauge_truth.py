"""Where a clip's rain goes: the gauge's counted drops matched to the simulator's drops.

The accuracy benchmark (``bench_gauge_accuracy.py``) says how far a clip's rate is
off; this says where.  One clip is rendered with its drops (``truth_drops``) and run
through the gauge with ``keep_drops``; each counted drop is matched to the drop of
the same frame whose streak holds its centre (across the streak's direction within its
radius and 3 px, along it within a quarter of its length and 3 px; the closest in those
units), and
the script prints

* per band of true diameter: the rain the truth has there, the rain the gauge makes
  of the drops it matched there (measured size, speed and weight), their ratio, and
  the median measured / true diameter;
* per band of measured diameter (the record's spectrum is binned so): the rain the
  gauge puts there beside the truth's, the median true / measured diameter of its
  matched drops, and the share of its rain from drops measured a quarter or more under
  their size (each weighs 1 / kappa at the size it was measured at);
* per radius class of the completeness probe: the drops the gauge counted against
  the count the model of the sample volume expects of the clip's drops
  (sum of p(a, z) over the whole streaks in the depth span of the sizes whose sample
  volume is above the gauge's floor, at the frame's contrast weights and the noise the
  gauge estimated), beside the same ratio for the probe's injected drops
  (:meth:`raingauge.gauge.completeness.CompletenessProbe.class_counts`).  Where the
  two differ, the probe does not see what loses the real drops, and its correction
  misses it.  The last columns take the probe's ratio bin by bin (4 bins of radius
  within the class, 4 of place within the depth span) weighted as the clip's own drops
  fall in them: where the difference stays, it is not the mix of sizes and depths
  within the class;
* the rain of counted drops no drop of the clip explains (false detections);
* the counted rain of the matched drops nearer than, within and beyond the depth span
  the model of the sample volume gives their true size (the probe places its drops
  only within it).

The count ratios carry the matching's own losses (a drop whose streak is cut by the
frame edge or merged with another is not counted however good the gauge): compare
them between clips and with the probe's, not with 1.

    python benchmarks/diag_gauge_truth.py --rate 10 --background bright_sky --noise 3
    python benchmarks/diag_gauge_truth.py --rate 30 --wind 3 --seconds 60
    python benchmarks/diag_gauge_truth.py --rate 10 --dsd gamma3
    python benchmarks/diag_gauge_truth.py --rate 30 --background dark_uniform --noise 1 --dsd parsivel
    python benchmarks/diag_gauge_truth.py --rate 100 --background dark_uniform --noise 1 --given-brightness

The first line gives the drop brightness E_r the gauge estimated beside the simulator's;
``--given-brightness`` runs the gauge on the simulator's instead.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _clip_args import add_clip_arguments, dsd_keywords, frame_size  # noqa: E402
from bench_gauge_accuracy import BACKGROUNDS  # noqa: E402

#: Bands of true diameter [mm].
BANDS_MM = (0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0)
#: Margin a streak keeps from the frame edge to count as whole [px].
WHOLE_MARGIN_PX = 12
#: Drops smaller than this are left out of the truth kept per frame (none is counted) [m].
MIN_RADIUS_M = 0.1e-3


def _frame_truth(drops, shape):
    """The drops of one frame as arrays: radius, depth, streak centre, radius and length [px],
    and whether the streak is whole in the frame."""
    p = np.asarray(drops["streak_px"], dtype=float)
    r = 0.5 * (np.asarray(drops["width_px"], dtype=float) + np.asarray(drops["blur_px"], dtype=float))
    m, n = shape
    x0 = np.minimum(p[:, 0, 0], p[:, 1, 0]) - r
    x1 = np.maximum(p[:, 0, 0], p[:, 1, 0]) + r
    y0 = np.minimum(p[:, 0, 1], p[:, 1, 1]) - r
    y1 = np.maximum(p[:, 0, 1], p[:, 1, 1]) + r
    g = WHOLE_MARGIN_PX
    a = np.asarray(drops["radius_m"], dtype=float)
    keep = a >= MIN_RADIUS_M
    dx, dy = p[:, 1, 0] - p[:, 0, 0], p[:, 1, 1] - p[:, 0, 1]
    length = np.hypot(dx, dy)
    # the streak's direction (straight down for a drop that did not move)
    ux = np.where(length > 0, dx / np.maximum(length, 1e-12), 0.0)
    uy = np.where(length > 0, dy / np.maximum(length, 1e-12), 1.0)
    out = {"a": a, "z": np.asarray(drops["depth_m"], dtype=float),
           "xc": 0.5 * (p[:, 0, 0] + p[:, 1, 0]), "yc": 0.5 * (p[:, 0, 1] + p[:, 1, 1]), "r": r,
           "length": length, "ux": ux, "uy": uy,
           "whole": (x0 > g) & (y0 > g) & (x1 < n - g) & (y1 < m - g)}
    return {key: val[keep] for key, val in out.items()}


def match(truth, x, y):
    """Index of the drop of ``truth`` (:func:`_frame_truth`) whose streak holds (x, y), or -1."""
    if truth["a"].size == 0:
        return -1
    # offsets along the streak and across it (a slanted streak measured in part has its
    # centre off the true one along the slant)
    ex, ey = x - truth["xc"], y - truth["yc"]
    along = np.abs(ex * truth["ux"] + ey * truth["uy"]) / (0.25 * truth["length"] + 3.0)
    across = np.abs(-ex * truth["uy"] + ey * truth["ux"]) / (truth["r"] + 3.0)
    u = np.maximum(along, across)
    j = int(np.argmin(u))
    return j if u[j] <= 1.0 else -1


def run(rate, background, noise, wind, seconds, seed, size, *, given_brightness=False, dsd_kw=None):
    from raingauge.gauge import RainGauge
    from raingauge.gauge.completeness import CLASS_EDGES_M
    from raingauge.gauge.gauge import KAPPA_FLOOR_REL
    from raingauge.gauge.volume import background_histogram
    from raingauge.physics import drops as D
    from raingauge.profile import default_profile
    from raingauge.render.simulator import simulate

    w, h = size
    prof = default_profile().replace(width_px=w, height_px=h, noise_sigma_dn=float(noise))
    spec, motion, e_r = BACKGROUNDS[background]
    # the drop size distribution, as the accuracy benchmark draws it (default Marshall-Palmer)
    dsd_kw = {"rain_rate_mm_h": rate} if dsd_kw is None else dsd_kw
    sim = simulate(prof, seconds=seconds, seed=seed, background=spec, motion=motion, wind_m_s=wind,
                   drop_brightness_dn=e_r, truth_drops=True, **dsd_kw)
    # given the simulator's drop brightness, the gauge does not estimate it from its streaks
    g = RainGauge(prof, window_s=seconds, step_s=seconds, keep_drops=True,
                  drop_brightness_dn=e_r if given_brightness else None)
    if g.probe is not None:
        g.probe.outcomes = []
    fps = prof.frame_rate_hz
    truth = {}
    recs = []
    last = None
    for k, (frame, ft) in enumerate(sim):
        truth[k] = _frame_truth(ft["drops"], prof.shape)
        recs += g.process(frame, t_s=k / fps)
        last = frame
    recs += g.flush()
    rec, tr = recs[-1], sim.truth
    true_rate = float(tr["rain_rate_mm_h"])
    print(f"{rate} mm/h {background} noise {noise} wind {wind}: gauge {rec['rain_rate_mm_h']:.3f} "
          f"truth {true_rate:.3f} ratio {rec['rain_rate_mm_h'] / true_rate:.3f}  "
          f"Dm {rec['dm_mm']} / {tr['windows'][-1]['dm_mm']:.3f}  "
          f"E_r {g.drop_brightness_estimate_dn:.1f} / {e_r:.1f}{' (given)' if given_brightness else ''}")

    # ---- counted drops against the drops they are
    found = set()
    rows = []            # (true radius, measured radius, rain [mm/h]); true radius NaN: unmatched
    depths = []          # the matched drop's true depth [m] (NaN: unmatched)
    for d in g.drops:
        k = int(round(d["t"] * fps))
        contrib = 3.6e6 * math.pi / 6.0 * d["diameter_m"] ** 3 * d["velocity_m_s"] * d["weight_s_m3"] / seconds
        j = match(truth[k], d["x"], d["y"]) if k in truth else -1
        if j >= 0:
            found.add((k, j))
        rows.append((truth[k]["a"][j] if j >= 0 else math.nan, 0.5 * d["diameter_m"], contrib))
        depths.append(truth[k]["z"][j] if j >= 0 else math.nan)
    rows = np.array(rows, dtype=float).reshape(-1, 3)
    depths = np.array(depths, dtype=float)
    dmm = np.asarray(D.PARSIVEL_D_CENTRES_MM)
    nd = np.nan_to_num(np.asarray(tr["windows"][-1]["dsd_n_m3_mm"], dtype=float))
    v = np.nan_to_num(np.asarray(D.fall_velocity(dmm * 1e-3), dtype=float))
    true_band = 3.6e6 * math.pi / 6.0 * (dmm * 1e-3) ** 3 * v * nd * np.asarray(D.PARSIVEL_D_WIDTHS_MM)
    print("\n true D [mm]   truth [mm/h]  gauge [mm/h]  ratio   drops  median D_m/D")
    for lo, hi in zip(BANDS_MM[:-1], BANDS_MM[1:]):
        sel = (2e3 * rows[:, 0] >= lo) & (2e3 * rows[:, 0] < hi)
        t = float(true_band[(dmm >= lo) & (dmm < hi)].sum())
        got = float(rows[sel, 2].sum())
        med = float(np.median(rows[sel, 1] / rows[sel, 0])) if sel.any() else math.nan
        print(f" {lo:4.2f}-{hi:4.2f}   {t:12.3f}  {got:12.3f}  {got / t if t > 0 else math.nan:5.2f}  "
              f"{int(sel.sum()):6d}  {med:6.3f}")
    lost = ~np.isfinite(rows[:, 0])
    print(f" unmatched counted drops: {int(lost.sum())}, {rows[lost, 2].sum():.3f} mm/h "
          f"({rows[lost, 2].sum() / true_rate:.1%} of the truth)")
    # where the matched drops lay against the depth span the model of the sample volume
    # gives their true size (the probe places its drops only within it)
    span_vol = g.sample_volume(rec["quality"])
    ok = ~lost
    near, far = (np.asarray(x, dtype=float) for x in span_vol.depth_span(rows[ok, 0]))
    z = depths[ok]
    print(" counted rain by the true drop's depth against its size's depth span:")
    for name, sel in (("nearer", z < near), ("within", (z >= near) & (z <= far)), ("beyond", z > far)):
        print(f"   {name:7s} {int(sel.sum()):6d} drops  {rows[ok][sel, 2].sum():8.3f} mm/h "
              f"({rows[ok][sel, 2].sum() / true_rate:.1%} of the truth)")
    # the spectrum the record gives is binned by the measured size: what lands in each band
    # of it, and how much of that is drops measured a quarter or more under their size
    print("\n meas. D [mm]  truth [mm/h]  gauge [mm/h]  ratio   drops  median D/D_m  from >= 1.25 D_m")
    for lo, hi in zip(BANDS_MM[:-1], BANDS_MM[1:]):
        sel = (2e3 * rows[:, 1] >= lo) & (2e3 * rows[:, 1] < hi)
        t = float(true_band[(dmm >= lo) & (dmm < hi)].sum())
        got = float(rows[sel, 2].sum())
        m = sel & np.isfinite(rows[:, 0])
        med = float(np.median(rows[m, 0] / rows[m, 1])) if m.any() else math.nan
        under = float(rows[m & (rows[:, 0] >= 1.25 * rows[:, 1]), 2].sum())
        print(f" {lo:4.2f}-{hi:4.2f}   {t:12.3f}  {got:12.3f}  {got / t if t > 0 else math.nan:5.2f}  "
              f"{int(sel.sum()):6d}  {med:12.3f}  {under / got if got > 0 else math.nan:16.2f}")

    # ---- counts against the model, beside the probe's
    # the volume of the window's frames (with or without the low-contrast hysteresis)
    vol = g.sample_volume(rec["quality"])
    e_est = g.drop_brightness_estimate_dn
    weights = vol.histogram_weights(background_histogram(last), e_est) if np.isfinite(e_est) else None
    # the noise the gauge's sample volume is taken at (the sensor's and the faint rain's)
    noise_dn = g.noise_estimate_dn
    # sizes whose sample volume is under the gauge's floor are not counted at all (their
    # rain is not measured): left out of the expectation, as the probe leaves them out
    grid = np.geomspace(0.05e-3, 5e-3, 120)
    floor = KAPPA_FLOOR_REL * float(np.nanmax(vol.kappa(grid, weights=weights, noise_dn=noise_dn, wind_m_s=wind))) \
        if weights is not None else math.inf
    n_cls = CLASS_EDGES_M.size - 1
    counted = np.zeros(n_cls)
    expected = np.zeros(n_cls)
    real = []            # per live drop: class, radius, place in its depth span, p, counted
    for k, t in truth.items():
        near, far = vol.depth_span(t["a"])
        live = t["whole"] & (t["a"] >= CLASS_EDGES_M[0]) & (t["z"] >= near) & (t["z"] <= far)
        live &= vol.kappa(t["a"], weights=weights, noise_dn=noise_dn, wind_m_s=wind) >= floor
        for j in np.flatnonzero(live):
            c = min(int(np.searchsorted(CLASS_EDGES_M, t["a"][j], side="right")) - 1, n_cls - 1)
            p = vol.pass_probability_over(t["a"][j], t["z"][j], weights, noise_dn, wind_m_s=wind) \
                if weights is not None else 0.0
            expected[c] += p
            counted[c] += (k, j) in found
            real.append((c, t["a"][j], (t["z"][j] - near[j]) / max(far[j] - near[j], 1e-12), p,
                         (k, j) in found))
    if g.probe is not None:
        _, p_counted, p_expected = g.probe.class_counts()
    else:
        p_counted = p_expected = np.zeros(n_cls)
    mixed = _probe_at_real_mix(g, vol, np.array(real, dtype=float).reshape(-1, 5), n_cls)
    print("\n class  a [mm]      real counted/expected         probe counted/expected       real/probe"
          "   probe at the real drops' mix   real/that")
    for c in range(n_cls):
        # (a ratio on less than one expected drop says nothing)
        r_c = counted[c] / expected[c] if expected[c] >= 1.0 else math.nan
        prb = p_counted[c] / p_expected[c] if p_expected[c] >= 1.0 else math.nan
        print(f"   {c}   {CLASS_EDGES_M[c] * 1e3:4.2f}-{CLASS_EDGES_M[c + 1] * 1e3:4.2f}  "
              f"{int(counted[c]):6d} / {expected[c]:8.1f} = {r_c:5.2f}     "
              f"{int(p_counted[c]):5d} / {p_expected[c]:7.1f} = {prb:5.2f}        {r_c / prb:5.2f}"
              f"   {mixed[c]:28.2f}   {r_c / mixed[c]:9.2f}")


#: Sub-bins of a probe class (in log a) and of the depth span, for :func:`_probe_at_real_mix`.
MIX_BINS = (4, 4)


def _probe_at_real_mix(g, vol, real, n_cls):
    """Per radius class, the probe's counted / expected taken bin by bin (radius within the
    class, place within the depth span) and averaged with the real drops' expected counts
    as weights: what the probe would say of drops mixed as the clip's are.  Equal to the
    real drops' ratio when the departure from the model depends only on (a, z)."""
    from raingauge.gauge.completeness import CLASS_EDGES_M

    out = np.full(n_cls, np.nan)
    if g.probe is None or not g.probe.outcomes or real.size == 0:
        return out
    pr = np.array(g.probe.outcomes, dtype=float)
    a_p, z_p, hit_p, p_p = pr[:, 0], pr[:, 1], pr[:, 2], pr[:, 3]
    near, far = (np.asarray(x, dtype=float) for x in vol.depth_span(a_p))
    u_p = (z_p - near) / np.maximum(far - near, 1e-12)
    cls_p = np.clip(np.searchsorted(CLASS_EDGES_M, a_p, side="right") - 1, 0, n_cls - 1)
    na, nu = MIX_BINS
    for c in range(n_cls):
        lo, hi = np.log(CLASS_EDGES_M[c]), np.log(CLASS_EDGES_M[c + 1])

        def bins(a, u):
            ia = np.clip(((np.log(a) - lo) / (hi - lo) * na).astype(int), 0, na - 1)
            iu = np.clip((u * nu).astype(int), 0, nu - 1)
            return ia * nu + iu

        rs = real[real[:, 0] == c]
        ps = cls_p == c
        if rs.size == 0 or not ps.any() or rs[:, 3].sum() < 1.0:
            continue
        b_r = bins(rs[:, 1], rs[:, 2])
        b_p = bins(a_p[ps], u_p[ps])
        w = np.bincount(b_r, rs[:, 3], minlength=na * nu)
        cnt = np.bincount(b_p, hit_p[ps], minlength=na * nu)
        exp_ = np.bincount(b_p, p_p[ps], minlength=na * nu)
        ok = exp_ > 0
        if not np.any(w[ok] > 0):
            continue
        out[c] = float(np.sum(w[ok] * cnt[ok] / exp_[ok]) / np.sum(w[ok]))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_clip_arguments(ap, rate=10.0, dsd="marshall_palmer", seconds=60.0, seed=7)
    ap.add_argument("--wind", type=float, default=0.0, help="wind [m/s]")
    ap.add_argument("--given-brightness", action="store_true",
                    help="give the gauge the simulator's drop brightness E_r instead of its estimate")
    args = ap.parse_args(argv)
    w, h = frame_size(ap, args.size)
    run(args.rate, args.background, args.noise, args.wind, args.seconds, args.seed, (w, h),
        given_brightness=args.given_brightness, dsd_kw=dsd_keywords(ap, args.dsd, args.rate, args.seconds))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
