"""Detect and remove rain in a video (Sec. 5 of Garg & Nayar).

IN is a video file OpenCV reads or a folder of images (taken in name order);
OUT is written as the same kind: a video (lossless FFV1 in .mkv; .avi, .mp4)
or a folder of PNG images, with one output frame for every input frame.
Frames that repeat their predecessor are recognised and get the same output.

The rain pixels removed can be written as a mask video/folder (--mask, white =
rain), and the needle map of the rain (direction and strength of the
spatio-temporal correlation, Fig. 11(e)) over the output as another
(--needles).  Without --camera, a linear camera with a 1/30 s exposure is
assumed and the noise is estimated from the video.
"""

from __future__ import annotations

import argparse
import math
import sys
import time


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", metavar="IN", help="video file or folder of images")
    parser.add_argument("output", metavar="OUT", help="output video (.mkv/.avi/.mp4) or folder, same kind as IN")
    parser.add_argument("--camera", metavar="PROFILE", default=None,
                        help="camera profile (TOML path or shipped name): linearisation, exposure, noise")
    parser.add_argument("--mask", metavar="MASK_OUT", default=None, help="write the removed rain pixels here")
    parser.add_argument("--needles", metavar="NEEDLES_OUT", default=None,
                        help="write the needle-map overlay (rain direction and strength) here")
    parser.add_argument("--c", type=float, default=None,
                        help="Eq. (19) threshold in gray levels (default: the profile's, 3)")
    parser.add_argument("--l", type=int, default=11, help="correlation neighbourhood in pixels (odd, default 11)")
    parser.add_argument("--f", type=int, default=30, help="frames of the correlation window (default 30)")
    parser.add_argument("--motion", default="translation", choices=("none", "translation", "euclidean"),
                        help="global camera-motion compensation (default translation)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


class _Progress:
    """A one-line progress bar on stderr, for inputs long enough to need one."""

    def __init__(self, total: int | None, enabled: bool):
        self.total = total
        self.enabled = enabled and (total is None or total >= 60)
        self.t0 = time.monotonic()
        self.last = 0.0
        self.count = 0

    def update(self, n: int = 1) -> None:
        self.count += n
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self.last < 0.25 and (self.total is None or self.count < self.total):
            return
        self.last = now
        rate = self.count / max(now - self.t0, 1e-9)
        if self.total:
            frac = min(self.count / self.total, 1.0)
            bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
            eta = (self.total - self.count) / rate if rate > 0 else float("nan")
            msg = f"\rderain [{bar}] {self.count}/{self.total} frames, {rate:.1f} frames/s, {eta:.0f} s left "
        else:
            msg = f"\rderain {self.count} frames, {rate:.1f} frames/s "
        sys.stderr.write(msg)
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")
            sys.stderr.flush()


def _check_kind(inp, out, what: str) -> None:
    from pathlib import Path

    from raingauge.errors import InputError
    from raingauge.videoio import VIDEO_FOURCC

    in_video = Path(inp).is_file()
    out_video = Path(out).suffix.lower() in VIDEO_FOURCC
    if in_video and not out_video:
        raise InputError(f"{what} {out}: IN is a video, so {what} must be a video too. "
                         f"Fix: give a name ending in {', '.join(VIDEO_FOURCC)} (lossless: .mkv)")
    if not in_video and out_video:
        raise InputError(f"{what} {out}: IN is a folder of images, so {what} must be a folder too. "
                         "Fix: give a folder name without a video suffix")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from raingauge.errors import InputError
    from raingauge.profile import load_profile
    from raingauge.videoio import FrameReader, FrameWriter
    from raingauge.vision import Derainer, dominant_direction_deg, needle_map

    if args.l < 3 or args.l % 2 == 0:
        raise InputError(f"--l {args.l}: the neighbourhood must be an odd number of pixels >= 3. Fix: e.g. --l 11")
    if args.f < 2:
        raise InputError(f"--f {args.f}: the correlation needs at least 2 frames. Fix: e.g. --f 30")
    if args.c is not None and not (math.isfinite(args.c) and args.c > 0):
        raise InputError(f"--c {args.c}: the threshold must be a positive number of gray levels. Fix: e.g. --c 3")
    for what, path in (("OUT", args.output), ("MASK_OUT", args.mask), ("NEEDLES_OUT", args.needles)):
        if path is not None:
            _check_kind(args.input, path, what)

    profile = load_profile(args.camera) if args.camera is not None else None
    reader = FrameReader(args.input)
    total = reader.n_frames
    if total is not None and total < 3:
        raise InputError(f"{args.input}: {total} frame(s); rain detection compares each frame with the one "
                         "before and after it. Fix: give at least 3 frames")
    it = iter(reader)
    head = []
    for frame in it:
        head.append(frame)
        if len(head) == 3:
            break
    if len(head) < 3:
        raise InputError(f"{args.input}: only {len(head)} readable frame(s); rain detection compares each frame "
                         "with the one before and after it. Fix: give at least 3 frames (or check the file)")
    shape = head[0].shape
    fps = reader.fps or (profile.frame_rate_hz if profile is not None else 30.0)

    # the mask written is of the removed pixels (DerainedFrame.rain): the relaxed run test,
    # which only widens DerainedFrame.detected, is not run (near_px=0)
    derainer = Derainer(profile, c=args.c, l=args.l, f=args.f, motion=args.motion, near_px=0)
    progress = _Progress(total, enabled=not args.quiet)
    writers = [FrameWriter(args.output, fps=fps)]
    mask_w = FrameWriter(args.mask, fps=fps) if args.mask else None
    needle_w = FrameWriter(args.needles, fps=fps) if args.needles else None
    n_out = 0
    rain_frac = []
    last_field = None

    def emit(results):
        nonlocal n_out, last_field
        for r in results:
            writers[0].write(r.frame)
            if mask_w is not None:
                mask_w.write(r.rain.astype(np.uint8) * 255)
            if needle_w is not None:
                needle_w.write(needle_map(r.frame, r.field) if r.field is not None else
                               (r.frame if r.frame.ndim == 3 else np.dstack([r.frame] * 3)))
            rain_frac.append(float(r.rain.mean()))
            last_field = r.field if r.field is not None else last_field
            n_out += 1
            progress.update()

    n_in = 0
    try:
        for frame in _chain(head, it):
            if frame.shape != shape:
                raise InputError(f"{args.input}: frame {n_in} has size {frame.shape}, the first has {shape}. "
                                 "Fix: give frames of one size")
            n_in += 1
            emit(derainer.push(frame))
        emit(derainer.flush())
    finally:
        progress.close()
        for w in writers + [mask_w, needle_w]:
            if w is not None:
                w.close()
    if n_out != n_in:  # pragma: no cover - guarded by the Derainer contract
        raise RuntimeError(f"internal error: {n_in} frames in, {n_out} out")
    direction = dominant_direction_deg(last_field) if last_field is not None else float("nan")
    msg = (f"derain: {n_in} frames -> {args.output}; rain pixels removed: {100 * np.mean(rain_frac):.3f} % "
           f"per frame on average")
    if math.isfinite(direction):
        msg += f"; rain direction {direction:.0f} deg (90 = vertical)"
    if reader.corrupt_frames:
        msg += f"; {reader.corrupt_frames} unreadable image(s) skipped"
    print(msg)
    return 0


def _chain(head, it):
    yield from head
    yield from it
