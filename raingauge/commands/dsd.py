"""Read a Parsivel disdrometer file: the instrument's rain rate beside ours from its raw counts.

Writes one CSV row per telegram with the columns

  time, reported_rate_mm_h, rate_mm_h, reported_z_dbz, z_dbz, dm_mm, nw_mm1_m3,
  nt_m3, lwc_g_m3, ke_flux_j_m2_h, particle_count, sensor_status

(``rate_mm_h`` and the moments from the raw 32x32 counts with the effective
sampling area 180 mm x (30 mm - D/2); ``reported_*`` as the instrument sent
them).  A summary goes to stderr: records read, malformed lines skipped, the
rain per UTC day (ours and reported), records with a sensor warning and the
median per-record ratio ours/reported (records reported above 0.1 mm/h).

Examples::

  raingauge dsd locarno_2018-10-29.dat.gz --csv rain.csv
  raingauge dsd station.dat --csv - | head
"""

from __future__ import annotations

import argparse
import csv
import math
import sys

COLUMNS = ("time", "reported_rate_mm_h", "rate_mm_h", "reported_z_dbz", "z_dbz", "dm_mm",
           "nw_mm1_m3", "nt_m3", "lwc_g_m3", "ke_flux_j_m2_h", "particle_count", "sensor_status")

#: records with a reported rate below this [mm/h] are left out of the median ratio
RATIO_MIN_RATE_MM_H = 0.1


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="Parsivel telegram file (.dat or .dat.gz)")
    parser.add_argument("--csv", metavar="OUT", default=None,
                        help="write the per-record table to OUT ('-' for standard output)")
    parser.add_argument("--interval", type=float, default=30.0, metavar="SECONDS",
                        help="sampling interval of one telegram [s] (default 30)")


def _fmt(x: float, digits: int) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return ""
    return f"{x:.{digits}f}"


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from raingauge.disdrometer import daily_totals_mm, read_parsivel, record_moments
    from raingauge.errors import InputError

    if not (math.isfinite(args.interval) and args.interval > 0):
        raise InputError(f"--interval must be a number of seconds > 0, got {args.interval}. "
                         "Fix: give the telegram interval, e.g. --interval 30")
    pf = read_parsivel(args.file, interval_s=args.interval)
    if not pf.records:
        why = "".join(f"; line {n}: {reason}" for n, reason in pf.malformed_examples[:2])
        raise InputError(f"{pf.path} holds no Parsivel telegram ({pf.malformed_lines} malformed lines{why}). "
                         "Fix: give a Parsivel telegram file (.dat or .dat.gz, one 24-field line per record)")

    out = None
    close = False
    if args.csv == "-":
        out = sys.stdout
    elif args.csv:
        try:
            out = open(args.csv, "w", newline="")
        except OSError as exc:
            raise InputError(f"cannot write {args.csv}: {exc.strerror}; choose a writable path") from None
        close = True

    ratios = []
    try:
        writer = csv.writer(out, lineterminator="\n") if out is not None else None
        if writer is not None:
            writer.writerow(COLUMNS)
        for rec in pf.records:
            m = record_moments(rec.counts, args.interval)
            if rec.reported_rate_mm_h > RATIO_MIN_RATE_MM_H:
                ratios.append(m["rain_rate_mm_h"] / rec.reported_rate_mm_h)
            if writer is not None:
                writer.writerow([
                    rec.time.strftime("%Y-%m-%dT%H:%M:%SZ"),
                    _fmt(rec.reported_rate_mm_h, 3),
                    _fmt(m["rain_rate_mm_h"], 3),
                    _fmt(rec.reported_z_dbz, 2),
                    _fmt(m["z_dbz"], 2),
                    _fmt(m["dm_mm"], 3),
                    _fmt(m["nw_mm1_m3"], 1),
                    _fmt(m["nt_m3"], 2),
                    _fmt(m["lwc_g_m3"], 4),
                    _fmt(m["ke_flux_j_m2_h"], 2),
                    rec.particle_count,
                    rec.sensor_status,
                ])
    finally:
        if close:
            out.close()

    err = sys.stderr
    print(f"{pf.path}: {len(pf.records)} records, {pf.malformed_lines} malformed lines skipped",
          file=err)
    for number, reason in pf.malformed_examples[:3]:
        print(f"  line {number}: {reason}", file=err)
    if pf.records:
        print(f"  from {pf.records[0].time:%Y-%m-%d %H:%M:%S} to "
              f"{pf.records[-1].time:%Y-%m-%d %H:%M:%S} UTC", file=err)
    totals = daily_totals_mm(pf.records, args.interval)
    print("  rain per UTC day [mm]:      ours   reported", file=err)
    for day, (ours, reported) in totals.items():
        print(f"    {day}          {ours:9.2f}  {reported:9.2f}", file=err)
    ours_all = sum(v[0] for v in totals.values())
    rep_all = sum(v[1] for v in totals.values())
    print(f"    total               {ours_all:9.2f}  {rep_all:9.2f}", file=err)
    flagged = sum(1 for r in pf.records if r.sensor_status not in (0, -1))
    if flagged:
        print(f"  {flagged} records with sensor status != 0 (1 laser dirty, 2 no measurement, "
              f"3 laser damaged); kept in the table", file=err)
    if ratios:
        print(f"  median ours/reported over {len(ratios)} records with reported rate > "
              f"{RATIO_MIN_RATE_MM_H} mm/h: {float(np.median(ratios)):.3f}", file=err)
    return 0
