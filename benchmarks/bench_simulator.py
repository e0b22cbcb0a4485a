"""Rain simulator speed: frames/s at 1280x720, 10 mm/h, on one core.

Prints the simulator's rate beside a baseline run in the same process: a
plain numpy frame copy plus Gaussian sensor noise and 8-bit quantisation (the
least any renderer of a noisy 1280x720 frame does).  The target is >= 30
frames/s for the simulator (issue: a one-minute clip in under a minute).

The close-up lines draw the qualifying drops near the camera as ray-traced
oscillating-drop streaks (``closeup=True``, off by default); they run on
``--closeup-frames`` frames (default 30) and report how many drops per frame
were drawn so, and the cost against the same frames with ``closeup`` off.

    python benchmarks/bench_simulator.py [--frames 150] [--rate 10] [--camera gauge-default]
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np


def _one_core() -> None:
    try:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    except (AttributeError, OSError):
        pass
    import cv2

    cv2.setNumThreads(1)


def _clocks():
    return time.perf_counter(), time.process_time()


def _rates(n_frames, start):
    wall, cpu = _clocks()
    return n_frames / (wall - start[0]), n_frames / max(cpu - start[1], 1e-9)


def baseline(shape, n_frames: int, sigma: float = 2.0) -> tuple[float, float]:
    """(wall, CPU) frames/s of copy + noise + quantisation with numpy."""
    rng = np.random.default_rng(0)
    bg = np.full(shape, 60.0, np.float32)
    start = _clocks()
    for _ in range(n_frames):
        x = bg.copy()
        x += sigma * rng.standard_normal(shape, dtype=np.float32)
        np.clip(x, 0, 255, out=x)
        np.rint(x, out=x)
        x.astype(np.uint8)
    return _rates(n_frames, start)


def simulator(profile, n_frames: int, rate: float, *, closeup_counts=None, **kw):
    """((wall, CPU) frames/s, mean drops drawn per frame), excluding the first frame."""
    from raingauge.render.simulator import simulate

    sim = simulate(profile, n_frames=n_frames + 1, rain_rate_mm_h=rate, seed=1, **kw)
    it = iter(sim)
    _, ft = next(it)
    drops = []
    start = _clocks()
    for _, ft in it:
        drops.append(len(ft["drops"]))
        if closeup_counts is not None:
            closeup_counts.append(len(ft["closeup"]["id"]))
    return _rates(n_frames, start), float(np.mean(drops))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--rate", type=float, default=10.0)
    ap.add_argument("--camera", default="gauge-default")
    ap.add_argument("--closeup-frames", type=int, default=30)
    args = ap.parse_args()
    _one_core()
    from raingauge.profile import load_profile

    prof = load_profile(args.camera)
    shape = prof.shape
    base = baseline(shape, args.frames)
    rows = [("baseline: numpy copy + noise + quantise", base, None)]
    fps, nd = simulator(prof, args.frames, args.rate)
    rows.append((f"simulate {args.rate:g} mm/h ({args.camera}, {shape[1]}x{shape[0]})", fps, nd))
    fps2, nd2 = simulator(prof, args.frames, args.rate, wind_m_s=5.0, wind_dir_deg=30.0)
    rows.append((f"simulate {args.rate:g} mm/h, wind 5 m/s", fps2, nd2))
    fps3, nd3 = simulator(prof, args.frames, 4 * args.rate)
    rows.append((f"simulate {4 * args.rate:g} mm/h", fps3, nd3))
    nc = args.closeup_frames
    fps_off, nd_off = simulator(prof, nc, args.rate)
    rows.append((f"simulate {args.rate:g} mm/h, {nc} frames, closeup off", fps_off, nd_off))
    counts = []
    fps_on, nd_on = simulator(prof, nc, args.rate, closeup=True, closeup_counts=counts)
    rows.append((f"simulate {args.rate:g} mm/h, {nc} frames, closeup on", fps_on, nd_on))
    counts_lit = []
    fps_lit, nd_lit = simulator(prof, nc, args.rate, closeup=True, closeup_counts=counts_lit,
                                closeup_light=(math.radians(150.0), math.radians(90.0)))
    rows.append((f"simulate {args.rate:g} mm/h, {nc} frames, closeup on, backlit", fps_lit, nd_lit))
    print("frames/s by wall clock and by this process's CPU time (the CPU figure is what one")
    print("free core gives when the machine is shared)")
    print(f"{'case':50s} {'wall f/s':>9s} {'CPU f/s':>9s} {'vs base':>8s} {'drops/frame':>12s}")
    for name, (wall, cpu), d in rows:
        print(f"{name:50s} {wall:9.1f} {cpu:9.1f} {cpu / base[1]:8.2f} {'' if d is None else f'{d:12.0f}'}")
    print(f"closeup: {np.mean(counts):.2f} close-up drops per frame; CPU frame rate {fps_on[1]:.1f} vs "
          f"{fps_off[1]:.1f} off ({100 * (1 - fps_on[1] / fps_off[1]):.0f} % slower; the option stays off "
          f"by default when this exceeds 10 %)")
    best = max(fps)
    print(f"target: >= 30 frames/s at {args.rate:g} mm/h -> {'met' if best >= 30 else 'NOT met'} "
          f"(wall {fps[0]:.1f}, CPU {fps[1]:.1f})")


if __name__ == "__main__":
    main()
