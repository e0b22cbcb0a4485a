"""Plot the instrument history: rain rate, accumulation and the DSD over time.

Three panels sharing the time axis: the rain rate [mm/h] with its 95% interval,
the accumulation since reset [mm], and N(D) [m^-3 mm^-1] of the 32 Parsivel
classes as a colour map (log scale).  Windows without camera data are shaded.
"""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--db", required=True, help="history database written by `raingauge run`")
    parser.add_argument("--png", required=True, metavar="OUT", help="PNG file to write")
    parser.add_argument("--from", dest="start", default=None, metavar="ISO", help="first time (inclusive)")
    parser.add_argument("--to", dest="end", default=None, metavar="ISO", help="last time (inclusive)")


def plot_history(rows: list[dict], png: str) -> None:
    """Draw the three panels of ``rows`` (history rows) into ``png``."""
    import datetime as dt

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from firmware_interface.fields import FIELD_BY_NAME

    def col(name):
        return np.array([np.nan if r[name] is None else r[name] for r in rows], dtype=float)

    t = [dt.datetime.fromtimestamp(r["time_unix"], tz=dt.timezone.utc) for r in rows]
    rate, acc = col("rain_rate_mm_h"), col("accumulation_mm")
    lo, hi = col("rain_rate_ci95_lo_mm_h"), col("rain_rate_ci95_hi_mm_h")
    nd_cols = FIELD_BY_NAME["dsd_n_m3_mm"].columns
    d_cols = FIELD_BY_NAME["dsd_d_mm"].columns
    nd = np.array([[np.nan if r[c] is None else r[c] for c in nd_cols] for r in rows], dtype=float)
    d = np.array([[np.nan if r[c] is None else r[c] for c in d_cols] for r in rows], dtype=float)
    d_centres = np.nanmedian(d, axis=0) if np.isfinite(d).any() else np.arange(1, 33, dtype=float)
    d_centres = np.where(np.isfinite(d_centres), d_centres, np.arange(1, 33))
    missing = np.array([bool(r["missing"]) for r in rows])

    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True, constrained_layout=True)
    ax = axes[0]
    ax.plot(t, rate, color="C0", lw=1.2, label="rain rate")
    if np.isfinite(lo).any():
        ax.fill_between(t, lo, hi, color="C0", alpha=0.25, lw=0, label="95% interval")
    ax.set_ylabel("rate [mm/h]")
    ax.legend(loc="upper left")
    axes[1].plot(t, acc, color="C2", lw=1.2)
    axes[1].set_ylabel("accumulation [mm]")
    for a in axes[:2]:
        for i in np.flatnonzero(missing):
            a.axvspan(t[max(i - 1, 0)], t[i], color="0.85", lw=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_nd = np.where(nd > 0, np.log10(nd), np.nan)
    if len(t) >= 2:
        mesh = axes[2].pcolormesh(t, d_centres, log_nd.T, shading="nearest", cmap="viridis")
        fig.colorbar(mesh, ax=axes[2], label="log10 N(D) [m^-3 mm^-1]")
    axes[2].set_ylabel("D [mm]")
    axes[2].set_ylim(0, min(8.0, float(np.nanmax(d_centres)) + 0.5))
    axes[2].set_xlabel("time (UTC)")
    fig.suptitle(f"raingauge history, {t[0]:%Y-%m-%d %H:%M} to {t[-1]:%Y-%m-%d %H:%M} UTC")
    try:
        fig.savefig(png, dpi=100, format="png")
    finally:
        plt.close(fig)


def run(args: argparse.Namespace) -> int:
    import sys

    from raingauge.errors import InputError
    from raingauge.history import History, parse_iso

    hist = History(args.db, readonly=True)
    try:
        rows = list(hist.rows(parse_iso(args.start, name="--from"), parse_iso(args.end, name="--to")))
    finally:
        hist.close()
    if not rows:
        raise InputError(f"{args.db}: no records in the chosen time range. Fix: widen --from/--to or run the gauge first")
    try:
        plot_history(rows, args.png)
    except OSError as exc:
        raise InputError(f"--png {args.png}: cannot write the plot ({exc.strerror or exc}). "
                         "Fix: give a writable file path such as rain.png") from None
    print(f"raingauge plot: {len(rows)} records -> {args.png}", file=sys.stderr)
    return 0
