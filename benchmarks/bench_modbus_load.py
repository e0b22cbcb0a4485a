"""Modbus TCP load while the gauge measures: no failed request, frame rate kept.

50 Modbus TCP clients (a separate process, raw sockets, nothing shared with
the server's library) each read input registers 0-11 at 10 Hz, 60 s in all,
while the instrument runs the real gauge on the simulated camera as fast as
it can, with the Modbus server in its own process as ``raingauge run`` starts
it.  The gauge's frame rate with clients is compared with its rate without
them in the same run: the clients poll in 10 s slices that alternate with
quiet 10 s slices (ABBA order), so a machine shared with other work loads
both sides alike.  Printed: requests sent and failed, latency percentiles,
frames/s in quiet and loaded slices (median and per slice) and the drop.
Targets (issue 6): no failed request; frame-rate drop <= 10 %.

    python benchmarks/bench_modbus_load.py [--seconds 60] [--slice 10] [--clients 50] [--hz 10] [--size 1280x720]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import statistics
import struct
import sys
import threading
import time


# ---------------------------------------------------------------------- clients (child process)
async def _client(port: int, hz: float, windows: list[tuple[float, float]], stats: dict, tid0: int) -> None:
    """Poll input registers 0-11 at ``hz`` inside each (start, end) wall-clock window; stay connected between."""
    try:
        reader, writer = await asyncio.wait_for(asyncio.open_connection("127.0.0.1", port), 5)
    except Exception:  # noqa: BLE001
        stats["connect_failed"] += 1
        return
    period = 1.0 / hz
    tid = tid0
    for start, end in windows:
        await asyncio.sleep(max(0.0, start - time.time()) + (tid0 % 97) / 97 * period)
        next_t = time.monotonic()
        while time.time() < end:
            tid = (tid + 1) & 0xFFFF
            request = struct.pack(">HHHBBHH", tid, 0, 6, 1, 4, 0, 12)
            t0 = time.monotonic()
            stats["sent"] += 1
            try:
                writer.write(request)
                header = await asyncio.wait_for(reader.readexactly(9), 1.0)
                rtid, _, _length, _, fc, nbytes = struct.unpack(">HHHBBB", header)
                body = await asyncio.wait_for(reader.readexactly(nbytes), 1.0)
                if rtid != tid or fc != 4 or nbytes != 24 or len(body) != 24:
                    stats["failed"] += 1
                else:
                    stats["lat"].append(time.monotonic() - t0)
            except Exception:  # noqa: BLE001
                stats["failed"] += 1
                try:
                    writer.close()
                    reader, writer = await asyncio.wait_for(asyncio.open_connection("127.0.0.1", port), 5)
                except Exception:  # noqa: BLE001
                    stats["connect_failed"] += 1
                    return
            next_t += period
            await asyncio.sleep(max(0.0, next_t - time.monotonic()))
    writer.close()


def client_process(port: int, clients: int, hz: float, windows: list[tuple[float, float]], out) -> None:
    stats = {"sent": 0, "failed": 0, "connect_failed": 0, "lat": []}

    async def main():
        await asyncio.gather(*(_client(port, hz, windows, stats, 1000 * i) for i in range(clients)))

    asyncio.run(main())
    lat = sorted(stats["lat"])

    def pct(p):
        return lat[min(len(lat) - 1, int(p * len(lat)))] * 1e3 if lat else float("nan")

    out.put({"sent": stats["sent"], "failed": stats["failed"], "connect_failed": stats["connect_failed"],
             "p50_ms": pct(0.5), "p99_ms": pct(0.99), "max_ms": lat[-1] * 1e3 if lat else float("nan")})


# ---------------------------------------------------------------------- the gauge
def _cpu_s(pid) -> float:
    """User + system CPU seconds of a process (Linux /proc)."""
    import os

    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="total polling time [s]")
    ap.add_argument("--slice", type=float, default=10.0, help="length of a loaded or quiet slice [s]")
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--hz", type=float, default=10.0)
    ap.add_argument("--size", default="1280x720", help="simulated frame size WxH (default: the gauge-default camera; a tiny size such as 160x120 makes the per-request cost look larger against a very cheap frame)")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))

    from firmware_interface.modbus import ModbusProcess
    from raingauge.instrument.loop import Instrument
    from raingauge.instrument.sources import Grabber, SimulatedSource, scaled_profile
    from raingauge.profile import load_profile

    n_loaded = max(1, round(args.seconds / args.slice))
    # ABBA: quiet, loaded, loaded, quiet, quiet, loaded, ... (2 n slices)
    pattern = [(k % 4) in (1, 2) for k in range(2 * n_loaded)]
    warm = 8.0
    profile = scaled_profile(load_profile("gauge-default"), *size)
    source = SimulatedSource(10.0, profile, realtime=False)
    modbus = ModbusProcess(tcp=("127.0.0.1", 0), window_s=10, step_s=2).start()   # as `raingauge run` does
    inst = Instrument(profile, Grabber(source, shape=profile.shape), window_s=10.0, step_s=2.0,
                      outputs=[modbus], modbus=modbus)
    t_start = time.time() + warm
    bounds = [t_start + k * args.slice for k in range(len(pattern) + 1)]
    windows = [(bounds[k], bounds[k + 1]) for k, loaded in enumerate(pattern) if loaded]
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    proc = ctx.Process(target=client_process, args=(modbus.tcp_port, args.clients, args.hz, windows, q))
    proc.start()
    counts: list[tuple[float, int]] = []
    cpu: list[tuple[float, float, float]] = []   # CPU seconds: gauge process, server process, clients

    def sampler():
        for b in bounds:
            time.sleep(max(0.0, b - time.time()))
            counts.append((time.monotonic(), inst.frames))
            cpu.append((_cpu_s("self"), _cpu_s(modbus._proc.pid), _cpu_s(proc.pid)))
        proc.join(60)
        inst.stop()

    print(f"gauge on simulate:10 at {size[0]}x{size[1]}; {args.clients} clients at {args.hz:g} Hz in "
          f"{n_loaded} slices of {args.slice:g} s between {n_loaded} quiet ones", flush=True)
    threading.Thread(target=sampler, daemon=True).start()
    inst.run()
    stats = q.get(timeout=60)
    fps = [(counts[k + 1][1] - counts[k][1]) / (counts[k + 1][0] - counts[k][0]) for k in range(len(pattern))]
    quiet = [f for f, loaded in zip(fps, pattern) if not loaded]
    loaded = [f for f, loaded in zip(fps, pattern) if loaded]
    drop = 1.0 - statistics.median(loaded) / statistics.median(quiet)
    print("frames/s per slice: " + " ".join(f"{'L' if l else 'q'}{f:.1f}" for f, l in zip(fps, pattern)))
    spans = [counts[k + 1][0] - counts[k][0] for k in range(len(pattern))]
    use = [[(cpu[k + 1][j] - cpu[k][j]) / spans[k] for j in range(3)] for k in range(len(pattern))]
    for label, want in (("quiet", False), ("loaded", True)):
        rows = [u for u, l in zip(use, pattern) if l == want]
        g, srv, cl = (statistics.median(r[j] for r in rows) for j in range(3))
        print(f"CPU in {label} slices [cores]: gauge process {g:.2f}, Modbus server process {srv:.3f}, "
              f"client process {cl:.3f}")
    print(f"without clients : {statistics.median(quiet):.2f} frames/s (median of {len(quiet)} slices)")
    print(f"with {args.clients} clients at {args.hz:g} Hz: {statistics.median(loaded):.2f} frames/s "
          f"(drop {100 * drop:+.1f} %, target <= 10 %)")
    expected = args.clients * args.hz * args.slice * n_loaded
    print(f"requests: {stats['sent']} sent ({stats['sent'] / expected:.2f} of {expected:.0f} planned), "
          f"{stats['failed']} failed, {stats['connect_failed']} connections refused (target 0); "
          f"latency p50 {stats['p50_ms']:.1f} ms, p99 {stats['p99_ms']:.1f} ms, max {stats['max_ms']:.1f} ms")
    ok = stats["failed"] == 0 and stats["connect_failed"] == 0 and drop <= 0.10
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
