"""Speed of rain detection and removal, per stage, beside MOG2 and the temporal median.

    python benchmarks/bench_derain_speed.py [--frames 40] [--sizes 640x480,1280x720]

One OpenCV thread (cv2.setNumThreads(1)); every figure is milliseconds per
frame measured in this run, on the same synthetic frames: a textured scene,
static or panning by (0.7, 0.2) px per frame, with rain streaks obeying
Eq. (18) of Garg & Nayar and sensor noise of 2 gray levels (the gauge
camera's).  Each stage is timed by the wall clock and by the CPU time of
this process (on a shared machine the latter is the steadier figure; the
whole Derainer and MOG2 take the best of three runs each), and
given as a multiple of one MOG2.apply on the same frames in the same run.  Targets at 1280x720 on one core:
detection + dynamics + removal >= 30 frames/s, and the part the gauge runs on
every frame (candidates, streaks, photometric test) no slower than one
MOG2 update.

The whole Derainer is timed as ``raingauge derain`` runs it (``near_px=0``:
its outputs are the derained frames and the removed pixels) and, beside it,
with the library default ``near_px=1``, which also runs the relaxed run test
that only widens ``DerainedFrame.detected`` (the mask the quality benchmark
scores).
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from raingauge.vision import (
    MOG2Detector, MotionTracker, RainDynamics, beta_max_for_exposure, candidates, detect_streaks, luminance,
    photometric_filter,
)
from raingauge.vision.baselines import median_frame
from raingauge.vision.motion import warp_to
from raingauge.vision.pipeline import Derainer, local_motion_mask
from raingauge.vision.removal import ArrayWindow, remove_window


def synthetic_clip(T, shape, *, density=0.01, noise=2.0, pan=(0.0, 0.0), seed=0):
    """Frames (T, M, N) uint8: textured scene, Eq. (18) streaks near vertical, Gaussian noise."""
    rng = np.random.default_rng(seed)
    M, N = shape
    pad = int(np.ceil(max(abs(pan[0]), abs(pan[1])) * T)) + 4
    tex = cv2.GaussianBlur(rng.uniform(0, 1, (M + 2 * pad, N + 2 * pad)).astype(np.float32), (0, 0), 2.0)
    tex = 30 + 170 * (tex - tex.min()) / (tex.max() - tex.min())
    n_streaks = int(density * M * N / (2 * 25))
    out = np.empty((T, M, N), np.uint8)
    for t in range(T):
        A = np.array([[1, 0, pad + pan[0] * t], [0, 1, pad + pan[1] * t]])
        bg = cv2.warpAffine(tex, A, (N, M), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
        mask = np.zeros((M, N), np.uint8)
        xs = rng.uniform(0, N, n_streaks)
        ys = rng.uniform(0, M, n_streaks)
        ls = rng.uniform(15, 35, n_streaks)
        th = np.radians(rng.uniform(95, 105, n_streaks))
        for x, y, L, a in zip(xs, ys, ls, th):
            dx, dy = 0.5 * L * np.cos(a), -0.5 * L * np.sin(a)
            cv2.line(mask, (int(x - dx), int(y - dy)), (int(x + dx), int(y + dy)), 1, 2)
        m = mask.astype(bool)
        img = bg.copy()
        img[m] += rng.uniform(20, 45) - 0.02 * bg[m]
        img += rng.normal(0, noise, (M, N)).astype(np.float32)
        out[t] = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return out


class Clock:
    """Wall-clock and process CPU time of a block [s].

    On a shared machine the wall clock also counts the time other processes
    held the core; the CPU time of this process does not.
    """

    def __enter__(self):
        self.w0, self.c0 = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self.w0
        self.cpu = time.process_time() - self.c0


def per_frame_ms(fn, items):
    """(wall, cpu) milliseconds per item of ``fn(item)``."""
    items = list(items)
    with Clock() as ck:
        for it in items:
            fn(it)
    n = max(len(items), 1)
    return 1000.0 * ck.wall / n, 1000.0 * ck.cpu / n


def full_run_ms(frames, repeat=3, **kw):
    """(wall, cpu) milliseconds per frame of the whole Derainer on ``frames``, a fresh
    Derainer each time, the best of ``repeat`` runs (by CPU time)."""
    best = None
    for _ in range(repeat):
        d = Derainer(None, **kw)
        with Clock() as ck:
            out = list(d.process(frames))
        assert len(out) == len(frames)
        ms = (1000.0 * ck.wall / len(frames), 1000.0 * ck.cpu / len(frames))
        best = ms if best is None or ms[1] < best[1] else best
    return best


def mog2_ms(frames, repeat=3):
    """(wall, cpu) milliseconds per frame of MOG2.apply, a fresh model each time, the best of
    ``repeat`` runs (as :func:`full_run_ms`)."""
    best = None
    for _ in range(repeat):
        ms = per_frame_ms(MOG2Detector().apply, frames)
        best = ms if best is None or ms[1] < best[1] else best
    return best


def bench(shape, T):
    frames = synthetic_clip(T, shape)
    pan = synthetic_clip(T, shape, pan=(0.7, 0.2), seed=1)
    lum = [luminance(f.astype(np.float32)) for f in frames]
    plum = [luminance(f.astype(np.float32)) for f in pan]
    bm = beta_max_for_exposure(0.004)
    triples = list(range(1, T - 1))
    res = {}
    res["linearise + luminance"] = per_frame_ms(lambda f: luminance(f.astype(np.float32)), frames)
    res["candidates (Eq. 19)"] = per_frame_ms(lambda n: candidates(lum[n - 1], lum[n], lum[n + 1], c=3.0), triples)
    cands = {n: candidates(lum[n - 1], lum[n], lum[n + 1], c=3.0) for n in triples}
    res["streaks + photometric (Eq. 18)"] = per_frame_ms(
        lambda n: photometric_filter(lum[n - 1], lum[n], lum[n + 1], cands[n], beta_max=bm, noise_sigma=2.0),
        triples)
    res["GAUGE PART: detect_streaks"] = per_frame_ms(
        lambda n: detect_streaks(lum[n - 1], lum[n], lum[n + 1], c=3.0, beta_max=bm, noise_sigma=2.0), triples)
    bs = {n: detect_streaks(lum[n - 1], lum[n], lum[n + 1], c=3.0, beta_max=bm, noise_sigma=2.0)[0] for n in triples}
    tr = MotionTracker()
    res["motion estimate, panning (phase corr. + GN)"] = per_frame_ms(tr.add, plum)
    Ms = {n: (tr.between(n - 1, n), tr.between(n + 1, n)) for n in triples}
    res["warp n-1, n+1 into n, panning"] = per_frame_ms(
        lambda n: (warp_to(plum[n - 1], Ms[n][0]), warp_to(plum[n + 1], Ms[n][1])), triples)
    res["local motion mask"] = per_frame_ms(
        lambda n: local_motion_mask(lum[n - 1], lum[n], lum[n + 1], c=6.0, tol=17.0), triples)
    dyn = RainDynamics(shape)
    res["dynamics update (R_b, lag-one)"] = per_frame_ms(lambda n: dyn.update(bs[n]), triples)
    every = Derainer(None).segment_every
    w, c = per_frame_ms(lambda _: dyn.field(), range(3))
    res[f"direction field + segmentation (/{every})"] = (w / every, c / every)
    region = dyn.field().region_mask(dilate_px=5)
    wins = [n for n in triples if 3 <= n < T - 3]
    res["removal (Sec. 5.2)"] = per_frame_ms(
        lambda n: remove_window(ArrayWindow(lum[n - 3:n + 4], lum[n - 3:n + 4]), bs[n], region, c=3.0,
                                beta_max=bm, noise_sigma=2.0), wins)
    # as `raingauge derain` runs it: its outputs are the derained frames and the removed
    # pixels, so the relaxed run test that only widens DerainedFrame.detected is off
    kw = dict(c=3.0, noise_sigma=2.0, beta_max=bm, motion="translation", near_px=0)
    res["FULL Derainer (static camera)"] = full_run_ms(frames, **kw)
    res["FULL Derainer (panning camera)"] = full_run_ms(pan, **kw)
    # the library default, with DerainedFrame.detected in full (near_px=1)
    kw["near_px"] = 1
    res["  ... with the full detected mask, static"] = full_run_ms(frames, **kw)
    res["  ... with the full detected mask, panning"] = full_run_ms(pan, **kw)
    res["baseline: MOG2.apply"] = mog2_ms(frames)
    res["baseline: temporal median (5 frames)"] = per_frame_ms(
        lambda n: median_frame(frames[max(0, n - 2):n + 3]), range(T))
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--sizes", default="640x480,1280x720")
    args = ap.parse_args(argv)
    cv2.setNumThreads(1)
    sizes = [tuple(int(v) for v in s.split("x"))[::-1] for s in args.sizes.split(",")]
    results = {s: bench(s, args.frames) for s in sizes}
    names = list(next(iter(results.values())))
    head = "stage".ljust(46) + "".join(f"{s[1]}x{s[0]}: wall / cpu [ms/frame], x MOG2".rjust(40) for s in sizes)
    print(head)
    print("-" * len(head))
    for name in names:
        cells = []
        for s in sizes:
            w, c = results[s][name]
            cells.append(f"{w:8.2f} / {c:8.2f}  ({c / results[s]['baseline: MOG2.apply'][1]:5.2f})".rjust(40))
        print(name.ljust(46) + "".join(cells))
    print("\n(x MOG2: CPU time of the stage over the CPU time of one MOG2.apply on the same frames, this run)\n")
    for s in sizes:
        r = results[s]
        mog = r["baseline: MOG2.apply"][1]
        gauge = r["GAUGE PART: detect_streaks"][1]
        st = r["FULL Derainer (static camera)"]
        pn = r["FULL Derainer (panning camera)"]
        sd = r["  ... with the full detected mask, static"]
        pd = r["  ... with the full detected mask, panning"]
        print(f"{s[1]}x{s[0]}: gauge part / one MOG2 update = {gauge / mog:.2f} (target <= 1); full Derainer "
              f"static {1000 / st[1]:.1f} frames/s CPU ({1000 / st[0]:.1f} wall), {st[1] / mog:.2f} x MOG2; "
              f"panning {1000 / pn[1]:.1f} frames/s CPU ({1000 / pn[0]:.1f} wall), {pn[1] / mog:.2f} x MOG2 "
              f"(target >= 30 frames/s at 1280x720); with the full detected mask static {1000 / sd[1]:.1f}, "
              f"panning {1000 / pd[1]:.1f} frames/s CPU; gauge part {1000 / gauge:.1f} frames/s CPU")


if __name__ == "__main__":
    main()
