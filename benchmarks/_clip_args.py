"""The command-line arguments of one simulated clip, shared by the diagnostic scripts."""

from __future__ import annotations

from bench_gauge_accuracy import BACKGROUNDS, parsivel_start_for_rate, shared_parsivel


def add_clip_arguments(ap, *, rate: float, dsd: str, seconds: float, seed: int,
                       dsds=("marshall_palmer", "gamma3", "parsivel")) -> None:
    """--background, --rate, --dsd (one of ``dsds``), --noise, --seconds, --seed and --size,
    with these defaults."""
    ap.add_argument("--background", choices=sorted(BACKGROUNDS), default="bright_sky")
    ap.add_argument("--rate", type=float, default=rate, help="rain rate [mm/h]")
    ap.add_argument("--dsd", choices=dsds, default=dsd,
                    help="drop size distribution: Marshall-Palmer, gamma with mu = 3, or the minute of the "
                         "real Parsivel day (../shared/data) nearest the rate, as the accuracy benchmark "
                         "replays it")
    ap.add_argument("--noise", type=float, default=3.0, help="sensor noise [gray levels]")
    ap.add_argument("--seconds", type=float, default=seconds)
    ap.add_argument("--seed", type=int, default=seed)
    ap.add_argument("--size", default="1280x720", help="frame size WxH [px]")


def frame_size(ap, text: str) -> tuple[int, int]:
    """(width, height) of a WxH argument; a malformed one ends the script with the fix."""
    try:
        w, h = (int(s) for s in text.lower().split("x"))
    except ValueError:
        ap.error(f"--size must be WxH, e.g. 1280x720, got {text!r}")
    return w, h


def dsd_keywords(ap, dsd: str, rate: float, seconds: float) -> dict:
    """The simulator's keywords for the clip's drop size distribution, as the accuracy
    benchmark draws it; without ../shared/data a Parsivel clip ends the script with the fix."""
    if dsd == "parsivel":
        path = shared_parsivel()
        if path is None:
            ap.error("--dsd parsivel needs ../shared/data/parsivel (or RAINGAUGE_SHARED_DATA pointing at "
                     "the data directory)")
        from raingauge.disdrometer import read_parsivel

        pf = read_parsivel(path)
        return {"parsivel": pf, "start": parsivel_start_for_rate(pf, rate, seconds / 60.0)}
    if dsd == "gamma3":
        return {"rain_rate_mm_h": rate, "dsd": "gamma", "dsd_params": {"mu": 3.0}}
    return {"rain_rate_mm_h": rate}
