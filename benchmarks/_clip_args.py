"""The command-line arguments of one simulated clip, shared by the diagnostic scripts."""

from __future__ import annotations

from bench_gauge_accuracy import BACKGROUNDS


def add_clip_arguments(ap, *, rate: float, dsd: str, seconds: float, seed: int) -> None:
    """--background, --rate, --dsd, --noise, --seconds, --seed and --size, with these defaults."""
    ap.add_argument("--background", choices=sorted(BACKGROUNDS), default="bright_sky")
    ap.add_argument("--rate", type=float, default=rate, help="rain rate [mm/h]")
    ap.add_argument("--dsd", choices=("marshall_palmer", "gamma3"), default=dsd,
                    help="drop size distribution: Marshall-Palmer, or gamma with mu = 3")
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
