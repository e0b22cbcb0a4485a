"""Accuracy of the camera rain gauge on simulated rain with ground truth.

The matrix of the gauge's acceptance: rates {0.5, 2, 10, 30, 100} mm/h x
backgrounds {dark uniform, textured still, bright sky, moving objects} x noise
{1, 3} gray levels x wind {0, 3 m/s} x DSD {Marshall-Palmer, gamma mu = 3,
replayed Parsivel records}, each clip >= 60 s rendered by the simulator; plus
rain-free clips (moving objects, ripples, noise).  Prints measured/true per
clip and the summary against the targets:

* rates >= 2 mm/h: median |error| <= 5 %, every clip within 15 %
* rates < 2 mm/h: within 0.2 mm/h
* the 95 % interval covers the truth in >= 90 % of clips
* rain-free clips read < 0.05 mm/h
* Dm within 10 %

Then replays a heavy 30-minute stretch of the real Parsivel day
(../shared/data/parsivel) through the simulator and the gauge and prints the
gauge's per-minute rate beside the disdrometer's reported intensity.

The whole matrix (240 clips) at 1280x720 is hours of CPU; ``--quick`` runs one
clip per rate and background (noise, wind and DSD cycled), ``--rates``,
``--backgrounds``, ``--noises``, ``--winds`` and ``--dsds`` pick subsets,
``--size`` and ``--seconds`` shrink the clips, ``--jobs N`` runs the clips in N
processes (rows print in matrix order), ``--replay-minutes`` and
``--replay-size`` shorten and shrink the replay.  A clip's seed is its place in
the list of clips run; with ``--matrix-seeds`` its place in the full matrix, so
that a subset reruns the full matrix's own clips (two versions of the gauge
compared clip by clip on a subset, or a subset against a full run).  ``--probe-seed``
draws the completeness probe's drops from another seed: the same clips run with two
probe seeds and set side by side with ``--compare`` show how far a reading moves with
the probe's draws alone, the scatter any change to the gauge must beat.

    python benchmarks/bench_gauge_accuracy.py --quick --size 640x360 --seconds 60
    python benchmarks/bench_gauge_accuracy.py --jobs 8 --no-replay          # the full matrix
    python benchmarks/bench_gauge_accuracy.py --jobs 2 --no-replay --winds 3 --dsds gamma3 --matrix-seeds
    python benchmarks/bench_gauge_accuracy.py --no-matrix --replay-size 320x180
    python benchmarks/bench_gauge_accuracy.py --summarize full.txt winds3_rerun.txt
    python benchmarks/bench_gauge_accuracy.py --compare before.txt after.txt
"""

from __future__ import annotations

import argparse
import itertools
import math
import re
import sys
import time
from pathlib import Path

import numpy as np

RATES = (0.5, 2.0, 10.0, 30.0, 100.0)
BACKGROUNDS = {
    # name: (simulator background, motion, drop brightness E_r [gray levels])
    "dark_uniform": ("uniform:40", None, 200.0),
    "textured_still": ("skimage:brick", None, 200.0),
    "bright_sky": ("ramp:150:190", None, 250.0),
    "moving_objects": ("skimage:coffee", "objects:4:60", 200.0),
}
NOISES = (1.0, 3.0)
WINDS = (0.0, 3.0)
DSDS = ("marshall_palmer", "gamma3", "parsivel")
RAIN_FREE = {
    "objects": ("skimage:coffee", "objects:5:80"),
    "ripples": ("skimage:grass", "ripples:0.3"),
    "noise": ("uniform:60", None),
}


def shared_parsivel() -> Path | None:
    import os

    env = os.environ.get("RAINGAUGE_SHARED_DATA")
    base = Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "data"
    path = base / "parsivel" / "locarno_2018-10-29.dat.gz"
    return path if path.exists() else None


def parsivel_start_for_rate(pf, rate_mm_h: float, minutes: float = 1.0):
    """The record whose following minutes' mean reported intensity is closest to rate."""
    rates = np.array([r.reported_rate_mm_h for r in pf.records])
    n = max(int(round(minutes * 2)), 1)
    kernel = np.ones(n) / n
    mean = np.convolve(rates, kernel, mode="valid")
    i = int(np.argmin(np.abs(mean - rate_mm_h)))
    return pf.records[i].time


def heavy_stretch_start(pf, minutes: float = 30.0):
    rates = np.array([r.reported_rate_mm_h for r in pf.records])
    n = int(minutes * 2)
    mean = np.convolve(rates, np.ones(n) / n, mode="valid")
    i = int(np.argmax(mean))
    return pf.records[i].time, float(mean[i])


def true_dm_mm(truth) -> float:
    """Dm of the drops the clip rendered [mm]: each window's Dm of its drops' own diameters,
    weighted by its liquid water (the third moment); NaN without drops."""
    dm = np.array([w["dm_mm"] if w["dm_mm"] is not None else np.nan for w in truth["windows"]], dtype=float)
    m3 = np.array([w["lwc_g_m3"] for w in truth["windows"]], dtype=float)
    ok = np.isfinite(dm) & (m3 > 0)
    return float(np.sum(dm[ok] * m3[ok]) / np.sum(m3[ok])) if ok.any() else float("nan")


def parsivel_dm_mm(pf, truth) -> float:
    """Dm of the Parsivel records a clip replayed, as the simulator draws them [mm]: each
    record's N(D) constant across its diameter class (not at the class centre: the classes
    widen to 0.5 and 1 mm above 2.5 mm), over the diameters the velocity law covers, and
    the records pooled.  NaN without such records."""
    from raingauge.disdrometer import record_density_m4
    from raingauge.physics import drops as D

    rain = truth.get("rain") or {}
    if rain.get("source") != "parsivel":
        return float("nan")
    wanted = set(rain["records"])
    lo_mm, hi_mm = rain.get("diameter_range_mm", (0.0, math.inf))
    edges = np.clip(np.asarray(D.PARSIVEL_D_EDGES_MM, dtype=float), lo_mm, hi_mm)
    m3 = m4 = 0.0
    for r in pf.records:
        if r.time.isoformat() in wanted:
            n = np.nan_to_num(record_density_m4(r.counts))
            m3 += float(np.sum(n * (edges[1:] ** 4 - edges[:-1] ** 4) / 4.0))
            m4 += float(np.sum(n * (edges[1:] ** 5 - edges[:-1] ** 5) / 5.0))
    return m4 / m3 if m3 > 0 else float("nan")


def nominal_dm_mm(rate: float, dsd: str) -> float:
    """Dm of the distribution the simulator drew the drops from (MP, gamma); NaN for replays.

    The truth's reference box holds too few large drops in a minute to fix Dm, which the
    gauge samples over a far larger volume-time."""
    from raingauge.physics import drops as D

    if dsd == "marshall_palmer":
        return D.dsd_moments_continuous(D.MarshallPalmer(rate), velocity_model="gunn_kinzer")["dm_mm"]
    if dsd == "gamma3":
        return D.dsd_moments_continuous(D.gamma_for_rain_rate(rate, 3.0), velocity_model="gunn_kinzer")["dm_mm"]
    return float("nan")


def run_clip(profile, *, seconds, rate, background, motion, e_r, noise, wind, dsd, pf, seed,
             gauge_law, window_s=None, drop_every=0, probe_seed=None):
    """One simulated clip through the gauge; with ``drop_every`` = K every K-th frame is
    missing from the stream (the others carry their times)."""
    from raingauge.gauge import RainGauge
    from raingauge.render.simulator import simulate

    prof = profile.replace(noise_sigma_dn=float(noise))
    kw = dict(seconds=seconds, seed=seed, background=background, motion=motion, wind_m_s=wind,
              drop_brightness_dn=e_r, truth_drops=False)
    if dsd == "parsivel":
        kw.update(parsivel=pf, start=parsivel_start_for_rate(pf, rate, seconds / 60.0))
    elif dsd == "gamma3":
        kw.update(rain_rate_mm_h=rate, dsd="gamma", dsd_params={"mu": 3.0})
    else:
        kw.update(rain_rate_mm_h=rate)
    sim = simulate(prof, **kw)
    window = window_s or seconds
    g = RainGauge(prof, window_s=window, step_s=window, velocity_model=gauge_law, probe_seed=probe_seed)
    recs = []
    t0 = time.perf_counter()
    for k, (frame, _ft) in enumerate(sim):
        if drop_every and k % drop_every == drop_every - 1:
            continue
        recs += g.process(frame, t_s=k / prof.frame_rate_hz)
    recs += g.flush()
    elapsed = time.perf_counter() - t0
    return recs, sim.truth, elapsed, g.drop_brightness_estimate_dn


def _clip_row(job):
    """One clip of the matrix (run in a worker process): its printed row and summary entry."""
    (k, rate, bg, noise, wind, dsd, size, seconds, seed, gauge_law, drop_every, probe_seed) = job
    from raingauge.profile import default_profile

    w, h = size
    profile = default_profile().replace(width_px=w, height_px=h)
    pf = None
    if dsd == "parsivel":
        from raingauge.disdrometer import read_parsivel

        pf = read_parsivel(shared_parsivel())
    spec, motion, e_r = BACKGROUNDS[bg]
    recs, truth, elapsed, e_est = run_clip(profile, seconds=seconds, rate=rate, background=spec, motion=motion,
                                           e_r=e_r, noise=noise, wind=wind, dsd=dsd, pf=pf, seed=seed + k,
                                    gauge_law=gauge_law, drop_every=drop_every, probe_seed=probe_seed)
    rec = recs[-1]
    true = float(truth["rain_rate_mm_h"])
    meas = rec["rain_rate_mm_h"]
    lo, hi = rec["rain_rate_ci95_mm_h"]
    # a null upper end means "no upper limit" (no drop size visible against this background)
    lo = 0.0 if lo is None else lo
    hi = float("inf") if hi is None else hi
    cov = lo <= true <= hi
    dm_t = nominal_dm_mm(rate, dsd) if dsd != "parsivel" else parsivel_dm_mm(pf, truth)
    if not np.isfinite(dm_t):
        dm_t = true_dm_mm(truth)
    dm_m = rec["dm_mm"] if rec["dm_mm"] is not None else float("nan")
    n_frames = int(round(seconds * profile.frame_rate_hz))
    # the rate's statistical standard uncertainty: its counting and the probe's sampling
    stat = math.hypot(*(rec[k] or 0.0 for k in ("rain_rate_counting_rsd", "rain_rate_probe_rsd")))
    row = dict(rate=rate, bg=bg, noise=noise, wind=wind, dsd=dsd, true=true, meas=meas, lo=lo, hi=hi, cov=cov,
               n=int(rec["drops_counted"]), stat=stat, dm_t=dm_t, dm_m=dm_m, fps=n_frames / elapsed,
               d_er=e_est - e_r, comp=rec["completed_share"] if rec["completed_share"] is not None else float("nan"),
               flags=",".join(rec["quality"]))
    return format_row(row), row


def format_row(r: dict) -> str:
    """A clip's printed row (``parse_output`` reads it back): ``dEr`` is the drop brightness
    the gauge estimated less the simulator's [gray levels], ``comp%`` the share of the rate
    completed below the smallest counted size (``completed_share``) [%]."""
    ratio = r["meas"] / r["true"] if r["true"] > 0 else float("nan")
    return (f"{r['rate']:6.1f} {r['bg']:>15} {r['noise']:5.1f} {r['wind']:4.1f} {r['dsd']:>15} | {r['true']:8.3f} "
            f"{r['meas']:8.3f} {ratio:6.3f} [{r['lo']:7.3f},{r['hi']:8.3f}] {'y' if r['cov'] else 'n':>3} "
            f"{r['n']:5d} {100 * r['stat']:5.1f} {r['dm_t']:5.2f} {r['dm_m']:5.2f} {r['fps']:5.1f} "
            f"{r.get('d_er', float('nan')):5.1f} {100 * r.get('comp', float('nan')):5.1f} {r['flags']}")


_ROW = re.compile(
    r"^\s*(?P<rate>[\d.]+)\s+(?P<bg>\S+)\s+(?P<noise>[\d.]+)\s+(?P<wind>[\d.]+)\s+(?P<dsd>\S+)\s+\|"
    r"\s+(?P<true>\S+)\s+(?P<meas>\S+)\s+\S+\s+\[\s*(?P<lo>\S+),\s*(?P<hi>\S+)\]\s+(?P<cov>[yn])"
    r"\s+(?P<n>\d+)\s+(?P<sd>\S+)\s+(?P<dm_t>\S+)\s+(?P<dm_m>\S+)\s+(?P<fps>\S+)"
    # (runs saved before the drop brightness and completion columns lack them)
    r"(?:\s+(?P<d_er>-?[\d.]+|nan)\s+(?P<comp>[\d.]+|nan))?\s*(?P<flags>\S*)\s*$")
_FREE = re.compile(r"^\s*(?P<name>\w+): (?P<rate>\S+) mm/h\s+drops")


def parse_output(text: str) -> tuple[list[dict], list[float]]:
    """The clips' rows and the rain-free rates of a printed run (``--summarize`` reads saved runs).

    The printed figures carry 3 decimals (the rate) and 1 (the statistical sd), so a
    summary of a saved run agrees with the run's own to that rounding.
    """
    rows, free = [], []
    for line in text.splitlines():
        m = _ROW.match(line)
        if m:
            g = m.groupdict()
            rows.append(dict(rate=float(g["rate"]), bg=g["bg"], noise=float(g["noise"]), wind=float(g["wind"]),
                             dsd=g["dsd"], true=float(g["true"]), meas=float(g["meas"]), lo=float(g["lo"]),
                             hi=float(g["hi"]), cov=g["cov"] == "y", n=int(g["n"]), stat=float(g["sd"]) / 100,
                             dm_t=float(g["dm_t"]), dm_m=float(g["dm_m"]), fps=float(g["fps"]), flags=g["flags"],
                             d_er=float(g["d_er"] or "nan"), comp=float(g["comp"] or "nan") / 100))
            continue
        m = _FREE.match(line)
        if m and m["name"] in RAIN_FREE:
            free.append(float(m["rate"]))
    return rows, free


def within_target(r: dict) -> bool:
    """The clip's rate within its target: 15 % from 2 mm/h on, 0.2 mm/h below."""
    if r["true"] >= 2.0:
        return abs(r["meas"] / r["true"] - 1) <= 0.15
    return abs(r["meas"] - r["true"]) <= 0.2


def summary_lines(rows: list[dict], free: list[float]) -> list[str]:
    """The summary against the targets (target in brackets)."""
    out = ["# summary (target in brackets)"]
    big = [r for r in rows if r["true"] >= 2.0]
    small = [r for r in rows if r["true"] < 2.0]
    if big:
        err = np.array([abs(r["meas"] / r["true"] - 1) for r in big])
        out.append(f"rates >= 2 mm/h: {len(big)} clips, median |error| {100 * np.median(err):.1f} % [<= 5 %], "
                   f"max {100 * err.max():.1f} % [<= 15 %], within 15 %: {np.mean(err <= 0.15) * 100:.0f} %")
        # each miss against the rate's own statistical uncertainty (counting and probe):
        # beyond about 2.5 of it the miss is a bias, not the luck of the draw
        for r, e in zip(big, err):
            if e > 0.15:
                z = (r["meas"] / r["true"] - 1) / r["stat"] if r["stat"] > 0 else float("nan")
                out.append(f"  beyond 15 %: {r['rate']:g} mm/h {r['bg']} noise {r['noise']:g} wind {r['wind']:g} "
                           f"{r['dsd']}: {r['meas'] / r['true']:.3f}, statistical sd {100 * r['stat']:.1f} %, "
                           f"{z:+.1f} sd")
    if small:
        err = np.array([abs(r["meas"] - r["true"]) for r in small])
        out.append(f"rates < 2 mm/h: {len(small)} clips, max |error| {err.max():.3f} mm/h [<= 0.2], "
                   f"within 0.2: {np.mean(err <= 0.2) * 100:.0f} %")
    for wind in sorted({r["wind"] for r in rows}):
        sel = [r["meas"] / r["true"] for r in rows if r["wind"] == wind and r["true"] >= 2.0
               and r["bg"] == "dark_uniform"]
        if sel:
            out.append(f"dark background, rates >= 2 mm/h, wind {wind:g} m/s: median measured/true "
                       f"{np.median(sel):.3f} over {len(sel)} clips")
    if rows:
        out.append(f"95 % interval covers the truth: {np.mean([r['cov'] for r in rows]) * 100:.0f} % [>= 90 %]")
        dm = np.array([abs(r["dm_m"] / r["dm_t"] - 1) for r in rows if np.isfinite(r["dm_m"])])
        if dm.size:
            out.append(f"Dm: median |error| {100 * np.median(dm):.1f} %, within 10 %: "
                       f"{np.mean(dm <= 0.1) * 100:.0f} % [all]")
    if free:
        out.append(f"rain-free: max {max(free):.4f} mm/h [< 0.05]")
    return out


def table_lines(rows: list[dict]) -> list[str]:
    """Per background and noise (rows) and rate (columns): clips within target of those run, and the
    range of measured/true; markdown, as the README's table."""
    rates = sorted({r["rate"] for r in rows})
    keys = sorted({(r["bg"], r["noise"]) for r in rows},
                  key=lambda k: (list(BACKGROUNDS).index(k[0]) if k[0] in BACKGROUNDS else len(BACKGROUNDS), k[1]))
    out = ["| background, noise | " + " | ".join(f"{r:g} mm/h" for r in rates) + " |",
           "|---|" + "---|" * len(rates)]
    for bg, noise in keys:
        cells = []
        for rate in rates:
            sel = [r for r in rows if r["bg"] == bg and r["noise"] == noise and r["rate"] == rate]
            if not sel:
                cells.append("")
                continue
            ratios = [r["meas"] / r["true"] for r in sel if r["true"] > 0]
            ok = sum(within_target(r) for r in sel)
            rng = f" ({min(ratios):.2f}-{max(ratios):.2f})" if ratios else ""
            cells.append(f"{ok}/{len(sel)}{rng}")
        out.append(f"| {bg.replace('_', ' ')}, {noise:g} | " + " | ".join(cells) + " |")
    return out


def _free_row(job):
    """One rain-free clip (run in a worker process)."""
    (k, name, size, seconds, gauge_law) = job
    from raingauge.profile import default_profile

    spec, motion = RAIN_FREE[name]
    profile = default_profile().replace(width_px=size[0], height_px=size[1])
    recs, truth, elapsed, e_est = run_clip(profile, seconds=seconds, rate=0.0, background=spec, motion=motion,
                                    e_r=200.0, noise=3.0, wind=0.0, dsd="marshall_palmer", pf=None, seed=100 + k,
                                    gauge_law=gauge_law)
    rec = recs[-1]
    return (f"{name:>10}: {rec['rain_rate_mm_h']:.4f} mm/h  drops {rec['drops_counted']}  "
            f"flags {','.join(rec['quality'])}"), rec["rain_rate_mm_h"]


def _ordered(fn, jobs, n_proc):
    """fn over jobs, in order, in n_proc processes (1: in this one)."""
    if n_proc <= 1:
        for j in jobs:
            yield fn(j)
        return
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=n_proc) as ex:
        yield from ex.map(fn, jobs)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="1280x720", help="frame size WxH (focal length kept: same streaks)")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--quick", action="store_true", help="one clip per rate x background")
    ap.add_argument("--rates", default=",".join(str(r) for r in RATES))
    ap.add_argument("--backgrounds", default=",".join(BACKGROUNDS))
    ap.add_argument("--noises", default=",".join(f"{n:g}" for n in NOISES), help="noise levels [gray levels]")
    ap.add_argument("--winds", default=",".join(f"{v:g}" for v in WINDS), help="wind speeds [m/s]")
    ap.add_argument("--dsds", default=",".join(DSDS), help="DSDs: " + ", ".join(DSDS))
    ap.add_argument("--jobs", type=int, default=1, help="run the clips in N processes")
    ap.add_argument("--drop-every", type=int, default=0,
                    help="leave every K-th frame out of the stream (frames carry their times)")
    ap.add_argument("--replay-size", default=None, help="frame size of the replay WxH (default --size)")
    ap.add_argument("--gauge-law", default="gunn_kinzer",
                    help="velocity law of the gauge's defocus test (the simulator's rain falls at gunn_kinzer)")
    ap.add_argument("--replay-minutes", type=float, default=30.0)
    ap.add_argument("--no-replay", action="store_true")
    ap.add_argument("--no-matrix", action="store_true")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--probe-seed", type=int, default=None,
                    help="seed of the completeness probe's draws (default the gauge's): two runs of the same "
                         "clips with different probe seeds, set side by side with --compare, show how much a "
                         "reading moves with the probe's draws alone")
    ap.add_argument("--matrix-seeds", action="store_true",
                    help="seed each clip as in the full matrix (a subset reruns the same clips)")
    ap.add_argument("--summarize", nargs="+", metavar="FILE",
                    help="run nothing: the summary and table of saved runs' printed output (a clip run again "
                         "in a later file replaces the earlier)")
    ap.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"),
                    help="run nothing: two versions' saved runs clip by clip (the clips both ran, --matrix-seeds "
                         "runs of the same clips), and each one's summary over them; a file may be several "
                         "comma-separated, merged as --summarize merges them")
    args = ap.parse_args(argv)
    if args.summarize:
        return summarize(args.summarize)
    if args.compare:
        return compare(*args.compare)

    from raingauge.profile import default_profile

    w, h = (int(v) for v in args.size.lower().split("x"))
    profile = default_profile().replace(width_px=w, height_px=h)
    path = shared_parsivel()
    pf = None
    if path is not None:
        from raingauge.disdrometer import read_parsivel

        pf = read_parsivel(path)
    rates = [float(r) for r in args.rates.split(",")]
    backgrounds = args.backgrounds.split(",")
    noises = [float(v) for v in args.noises.split(",")]
    winds = [float(v) for v in args.winds.split(",")]
    dsds = args.dsds.split(",")
    for name, values, valid in (("--backgrounds", backgrounds, BACKGROUNDS), ("--dsds", dsds, DSDS)):
        bad = [v for v in values if v not in valid]
        if bad:
            ap.error(f"{name}: unknown {bad}; valid: {list(valid)}")
    if pf is None:
        dsds = [d for d in dsds if d != "parsivel"]
        print("note: ../shared/data/parsivel not found: no Parsivel DSD clips, no replay", file=sys.stderr)
    if args.seconds < 60:
        print(f"note: {args.seconds:g}-s clips; the acceptance matrix asks for >= 60 s", file=sys.stderr)

    if args.quick:
        combos = []
        for i, (rate, bg) in enumerate(itertools.product(rates, backgrounds)):
            combos.append((rate, bg, noises[i % len(noises)], winds[(i // 2) % len(winds)], dsds[i % len(dsds)]))
    else:
        combos = list(itertools.product(rates, backgrounds, noises, winds, dsds))

    rows = []
    if not args.no_matrix:
        print(f"# gauge accuracy: {len(combos)} clips of {args.seconds:g} s at {w}x{h}, "
              f"gauge law {args.gauge_law}"
              + (f", every {args.drop_every}th frame dropped" if args.drop_every else "")
              + (f", probe seed {args.probe_seed}" if args.probe_seed is not None else ""))
        print(f"{'rate':>6} {'background':>15} {'noise':>5} {'wind':>4} {'dsd':>15} | {'true':>8} {'meas':>8} "
              f"{'ratio':>6} {'ci95':>17} {'cov':>3} {'n':>5} {'sd%':>5} {'Dm_t':>5} {'Dm_m':>5} {'fps':>5} "
              f"{'dEr':>5} {'comp%':>5} flags")
        # a clip's seed is its place in the list; with --matrix-seeds its place in the full
        # matrix, so that a subset reruns the full matrix's own clips
        full = list(itertools.product(RATES, BACKGROUNDS, NOISES, WINDS, DSDS))
        places = [full.index(c) if args.matrix_seeds and c in full else k for k, c in enumerate(combos)]
        jobs = [(k, rate, bg, noise, wind, dsd, (w, h), args.seconds, args.seed, args.gauge_law, args.drop_every,
                 args.probe_seed) for k, (rate, bg, noise, wind, dsd) in zip(places, combos)]
        for line, row in _ordered(_clip_row, jobs, args.jobs):
            rows.append(row)
            print(line, flush=True)
        # rain-free clips
        print("# rain-free clips")
        free = []
        jobs = [(k, name, (w, h), args.seconds, args.gauge_law) for k, name in enumerate(RAIN_FREE)]
        for line, rate in _ordered(_free_row, jobs, args.jobs):
            free.append(rate)
            print(line, flush=True)
        for line in summary_lines(rows, free) + ["# within target of the clips run (range of measured/true)"] \
                + table_lines(rows):
            print(line)

    if not args.no_replay and pf is not None:
        if args.replay_size:
            rw, rh = (int(v) for v in args.replay_size.lower().split("x"))
            profile = profile.replace(width_px=rw, height_px=rh)
        replay(profile, pf, minutes=args.replay_minutes, gauge_law=args.gauge_law, seed=args.seed)
    return 0


def _clip_key(r: dict) -> tuple:
    return (r["rate"], r["bg"], r["noise"], r["wind"], r["dsd"])


def read_runs(paths) -> tuple[dict, list[float]]:
    """The clips (by rate, background, noise, wind and spectrum; a clip run again in a later file
    replaces the earlier) and the rain-free rates of saved runs; ValueError naming the file
    that cannot be read or holds no run."""
    clips, free = {}, []
    for path in paths:
        try:
            text = Path(path).read_text()
        except OSError as exc:
            raise ValueError(f"cannot read {path}: {exc.strerror}; pass the file a run's stdout was saved to")
        rows, f = parse_output(text)
        if not rows and not f:
            raise ValueError(f"{path} holds no clip rows of bench_gauge_accuracy.py; pass a run's saved stdout")
        clips.update({_clip_key(r): r for r in rows})
        free = f or free
    return clips, free


def compare(before: str, after: str) -> int:
    """Print two versions' saved runs clip by clip over the clips both ran (measured/true, a
    star where the clip misses its target), then each one's summary over those clips."""
    try:
        runs = [read_runs(x.split(",")) for x in (before, after)]
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    (a, _), (b, _) = runs
    keys = [k for k in a if k in b]
    if not keys:
        print(f"error: {before} and {after} share no clip; compare runs of the same clips (--matrix-seeds)",
              file=sys.stderr)
        return 2
    print(f"# {len(keys)} clips run by both ({len(a)} before, {len(b)} after)")
    print(f"{'rate':>6} {'background':>15} {'noise':>5} {'wind':>4} {'dsd':>15} | {'before':>7} {'after':>7} "
          f"{'dEr':>5} {'dEr':>5}")
    for k in keys:
        x, y = a[k], b[k]
        cells = [f"{r['meas'] / r['true']:6.3f}{' ' if within_target(r) else '*'}" for r in (x, y)]
        print(f"{k[0]:6.1f} {k[1]:>15} {k[2]:5.1f} {k[3]:4.1f} {k[4]:>15} | {cells[0]} {cells[1]} "
              f"{x['d_er']:5.1f} {y['d_er']:5.1f}")
    for name, run in (("before", a), ("after", b)):
        rows = [run[k] for k in keys]
        print(f"# {name}: {sum(within_target(r) for r in rows)} of {len(rows)} within target")
        for line in summary_lines(rows, [])[1:]:
            if not line.startswith("  beyond"):
                print(f"  {line}")
    return 0


def summarize(paths) -> int:
    """Print the summary and the table of saved runs (each clip once: the last file that ran it)."""
    try:
        clips, free = read_runs(paths)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rows = list(clips.values())
    print(f"# {len(rows)} clips from {len(paths)} file(s)")
    for line in summary_lines(rows, free) + ["# within target of the clips run (range of measured/true)"] \
            + table_lines(rows):
        print(line)
    return 0


def replay(profile, pf, *, minutes: float, gauge_law: str, seed: int) -> None:
    """A heavy stretch of the real Parsivel day through the simulator and the gauge, per minute."""
    from raingauge.gauge import RainGauge
    from raingauge.render.simulator import simulate

    start, mean = heavy_stretch_start(pf, 30.0)
    print(f"# Parsivel replay: {minutes:g} min from {start:%Y-%m-%d %H:%M:%S} UTC "
          f"(heaviest 30 min of the file, mean {mean:.1f} mm/h), {profile.width_px}x{profile.height_px}")
    sim = simulate(profile, seconds=minutes * 60.0, parsivel=pf, start=start, seed=seed,
                   background="uniform:40", truth_drops=False, truth_window_s=60.0)
    g = RainGauge(profile, window_s=60.0, step_s=60.0, velocity_model=gauge_law)
    recs = []
    for frame, _ft in sim:
        recs += g.process(frame)
    recs += g.flush()
    truth = sim.truth
    by_time = {r.time: r.reported_rate_mm_h for r in pf.records}
    times = sorted(t for t in by_time if t >= start)
    print(f"{'minute':>6} {'parsivel':>9} {'sim truth':>9} {'gauge':>8} {'ci95':>17}")
    gauge_all, pars_all = [], []
    for k, rec in enumerate(recs):
        t0 = start.timestamp() + rec["t_start_s"]
        pars = [by_time[t] for t in times if t0 <= t.timestamp() < t0 + 60.0]
        p = float(np.mean(pars)) if pars else float("nan")
        wins = [w for w in truth["windows"] if w["t_start_s"] >= rec["t_start_s"] - 1e-6
                and w["t_end_s"] <= rec["t_end_s"] + 1e-6]
        st = float(np.mean([w["rain_rate_mm_h"] for w in wins])) if wins else float("nan")
        lo, hi = (float("nan") if v is None else v for v in rec["rain_rate_ci95_mm_h"])
        print(f"{k + 1:6d} {p:9.2f} {st:9.2f} {rec['rain_rate_mm_h']:8.2f} [{lo:7.2f},{hi:8.2f}]", flush=True)
        gauge_all.append(rec["rain_rate_mm_h"])
        pars_all.append(p)
    g_acc = np.nansum(gauge_all) / 60.0
    p_acc = np.nansum(pars_all) / 60.0
    print(f"accumulation over the replay: gauge {g_acc:.2f} mm, Parsivel {p_acc:.2f} mm "
          f"(ratio {g_acc / p_acc if p_acc > 0 else float('nan'):.3f})")


if __name__ == "__main__":
    raise SystemExit(main())
