"""Export the instrument history (SQLite) as CSV.

Writes the header (the columns of the output field table, see
docs/modbus_registers.md) and one line per record whose window ends between
--from and --to (ISO 8601; a date alone means midnight UTC, a time without a
zone means UTC).  Example::

    raingauge export --db /var/lib/raingauge/raingauge.sqlite --from 2026-11-01 --to 2026-11-02 --csv day.csv
"""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--db", required=True, help="history database written by `raingauge run`")
    parser.add_argument("--from", dest="start", default=None, metavar="ISO", help="first time (inclusive)")
    parser.add_argument("--to", dest="end", default=None, metavar="ISO", help="last time (inclusive)")
    parser.add_argument("--csv", default="-", metavar="OUT|-", help="output file, - for standard output (default)")


def run(args: argparse.Namespace) -> int:
    import sys

    from raingauge.errors import InputError
    from raingauge.history import History, parse_iso

    start = parse_iso(args.start, name="--from")
    end = parse_iso(args.end, name="--to")
    if start is not None and end is not None and end < start:
        raise InputError(f"--to {args.end} is before --from {args.start}. Fix: swap them")
    hist = History(args.db, readonly=True)
    try:
        if args.csv == "-":
            n = hist.export_csv(sys.stdout, start=start, end=end)
        else:
            try:
                fh = open(args.csv, "w", newline="")
            except OSError as exc:
                raise InputError(f"--csv {args.csv}: cannot write ({exc.strerror or exc}). "
                                 "Fix: give a writable file path, or - for standard output") from None
            with fh:
                n = hist.export_csv(fh, start=start, end=end)
    finally:
        hist.close()
    print(f"raingauge export: {n} records", file=sys.stderr)
    return 0
