"""Run the field instrument: camera -> gauge -> Modbus, NMEA serial, SQLite history.

With no configuration at all it runs the embedded default: the simulated
camera (simulate:10, rain at 10 mm/h, gauge-default profile), Modbus TCP on
127.0.0.1:5020, history in ./raingauge.sqlite, and prints one line per record.
A TOML file (--config, example in deploy/raingauge.toml) sets everything; the
options below override it.  SIGTERM or Ctrl-C flush the last partial window,
write what is queued and exit cleanly.

The simulated camera renders in its own process and diagnostics run in a
low-priority one, so the gauge keeps a core.  Paced sources (cameras, and
files or simulation without --fast) do not wait for a slow gauge: frames it
cannot take are dropped, counted in each record (dropped_frames) and flagged.
The summary at exit gives frames measured and dropped, frames/s and the gauge's
time per frame.

Sources: simulate:RATE | a camera index (0) | rtsp:// or http:// URL |
a video file | a folder of images.  Use "off" to switch an output off.
"""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default=None, metavar="FILE", help="instrument configuration (TOML)")
    parser.add_argument("--source", default=None, help="frame source (default simulate:10)")
    parser.add_argument("--camera", default=None, metavar="PROFILE", help="camera profile (file or shipped name)")
    parser.add_argument("--modbus-tcp", default=None, metavar="HOST:PORT", help="Modbus TCP address, or off")
    parser.add_argument("--modbus-rtu", default=None, metavar="PORT[:BAUD]", help="Modbus RTU serial port, or off")
    parser.add_argument("--serial", default=None, metavar="PORT[:BAUD]", help="NMEA serial output, or off")
    parser.add_argument("--db", default=None, metavar="PATH", help="history database (SQLite), or off")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="stop after S seconds of source time (default: run until stopped)")
    parser.add_argument("--fast", action="store_true",
                        help="play files and simulation as fast as the gauge goes (nothing dropped); "
                             "without it they run at the camera's frame rate and frames the gauge cannot "
                             "take are dropped, counted and flagged dropped_frames")
    parser.add_argument("--window", type=float, default=None, metavar="S", help="averaging window [s]")
    parser.add_argument("--step", type=float, default=None, metavar="S", help="record interval [s]")
    parser.add_argument("--sim-size", default=None, metavar="WxH", help="size of simulated frames, e.g. 320x240")
    parser.add_argument("--diagnostics", default=None, metavar="DIR", help="diagnostics folder, or off")
    parser.add_argument("--quiet", action="store_true", help="do not print records")


def _off(value):
    return "" if value is not None and value.strip().lower() in ("off", "none", "") else value


def format_record(rec: dict) -> str:
    """One human-readable line per record."""
    import math

    def f(v, fmt):
        return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)

    flags = ",".join(rec.get("quality") or []) or "-"
    dropped = f" (+{rec['dropped_frames']} dropped)" if rec.get("dropped_frames") else ""
    if rec.get("missing"):
        return f"{rec.get('time_utc') or ''} MISSING (no frames)  acc {f(rec.get('accumulation_mm'), '.2f')} mm  status 0x{rec['status']:02X}"
    return (f"{rec.get('time_utc') or ''} rate {f(rec.get('rain_rate_mm_h'), '7.2f')} mm/h  "
            f"acc {f(rec.get('accumulation_mm'), '7.2f')} mm  drops {f(rec.get('drops_counted'), 'd'):>5}  "
            f"Dm {f(rec.get('dm_mm'), '.2f')} mm  class {f(rec.get('intensity_class'), 'd')}  "
            f"frames {rec.get('frames')}{dropped}  status 0x{rec['status']:02X}  flags {flags}")


def build_instrument(config, *, print_records=True, gauge_factory=None):
    """Wire source, gauge and outputs from a validated configuration into an Instrument."""
    import logging
    import sys

    from raingauge.errors import ConfigError
    from raingauge.history import History
    from raingauge.instrument.loop import Accumulator, Diagnostics, Instrument
    from raingauge.instrument.sources import Grabber, open_source, scaled_profile
    from raingauge.profile import load_profile

    log = logging.getLogger("raingauge.run")
    profile = load_profile(config.camera["profile"])
    src = config.source
    if src["size"] is not None and str(src["uri"]).startswith("simulate"):
        profile = scaled_profile(profile, *src["size"])
    source = open_source(src["uri"], profile=profile, realtime=src["realtime"], seed=int(src["seed"]))
    grabber = Grabber(source, shape=profile.shape, backoff_s=(0.5, float(src["reconnect_max_s"])))

    window_s = float(config.gauge["window_s"])
    step_s = float(config.gauge["step_s"])
    unit_id = int(config.modbus["unit_id"])
    history = None
    acc = Accumulator()
    if config.history["path"]:
        retention = float(config.history["retention_days"]) or None
        history = History(config.history["path"], retention_days=retention)
        saved = history.settings()
        acc = Accumulator(saved.get("accumulation_mm", 0.0), saved.get("rain_duration_s", 0.0))
        if "unit_id" in saved and saved["unit_id"] != unit_id:
            log.info("Modbus unit id %s from the database (set over Modbus) overrides %s", saved["unit_id"], unit_id)
            unit_id = int(saved["unit_id"])
        if "window_s" in saved and float(saved["window_s"]) != window_s:
            w = float(saved["window_s"])
            if w >= step_s and abs(w / step_s - round(w / step_s)) < 1e-9:
                log.info("window %g s from the database (set over Modbus) overrides %g s", w, window_s)
                window_s = w

    outputs = []
    modbus = None
    holder = {}
    settings_extra = {"unit_id": unit_id}

    def on_reset():
        holder["instrument"].reset_accumulation()

    def on_setting(name, value):
        inst = holder["instrument"]
        if name == "window_s":
            inst.request_window(float(value))
        elif name == "unit_id":
            inst.settings_extra["unit_id"] = int(value)
        if inst.history_writer is not None:
            inst.history_writer.put_settings({name: value})

    m = config.modbus
    if m["tcp"] or m["rtu"]:
        from firmware_interface.modbus import ModbusProcess, parse_host_port
        from firmware_interface.serial_out import parse_port_spec

        rtu = None
        if m["rtu"]:
            port, baud = parse_port_spec(m["rtu"], default_baud=19200)
            rtu = {"port": port, "baudrate": baud, "parity": m["rtu_parity"]}
        # In its own process: a flood of Modbus requests cannot slow the gauge.
        modbus = ModbusProcess(tcp=parse_host_port(m["tcp"]) if m["tcp"] else None, rtu=rtu, unit_id=unit_id,
                              device_id=profile.device_id, window_s=window_s, step_s=step_s,
                              on_reset=on_reset, on_setting=on_setting, model=profile.name)
        modbus.start()
        outputs.append(modbus)
        if m["tcp"]:
            print(f"raingauge: Modbus TCP on {modbus.tcp[0]}:{modbus.tcp_port}", file=sys.stderr)
    if config.serial["port"]:
        from firmware_interface.serial_out import SerialWriter, parse_port_spec

        port, baud = parse_port_spec(config.serial["port"], default_baud=9600)
        outputs.append(SerialWriter(port, baud))
    diagnostics = None
    d = config.diagnostics
    if d["enabled"] and d["folder"]:
        diagnostics = Diagnostics(d["folder"], profile)

    def on_record(rec):
        if print_records:
            print(format_record(rec), flush=True)

    if not profile.provenance:
        log.info("camera profile %s is not calibrated (run `raingauge calibrate`)", profile.name)
    try:
        velocity_model = config.gauge["velocity_model"]
        inst = Instrument(profile, grabber, window_s=window_s, step_s=step_s, velocity_model=velocity_model,
                          outputs=outputs, history=history, diagnostics=diagnostics,
                          diagnostics_interval_s=float(d["interval_s"]), diagnostics_frames=int(d["frames"]),
                          stall_timeout_s=float(src["stall_timeout_s"]), on_record=on_record,
                          accumulator=acc, modbus=modbus, settings_extra=settings_extra,
                          gauge_options=({} if config.gauge["completeness_probe"]
                                         else {"completeness_probe": False}),
                          **({"gauge_factory": gauge_factory} if gauge_factory is not None else {}))
    except ConfigError:
        for out in outputs:
            (getattr(out, "close", None) or out.stop)()
        raise
    holder["instrument"] = inst
    return inst


def run(args: argparse.Namespace) -> int:
    import logging
    import math
    import signal
    import sys

    from raingauge.errors import ConfigError
    from raingauge.instrument.config import apply_overrides, load_config

    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        raise ConfigError(f"--duration {args.duration:g}: must be a positive number of seconds. "
                          "Fix: e.g. --duration 60, or leave it out to run until stopped")
    config = load_config(args.config)
    size = None
    if args.sim_size:
        try:
            w, h = (int(v) for v in args.sim_size.lower().split("x"))
            size = [w, h]
        except ValueError:
            raise ConfigError(f"--sim-size {args.sim_size!r}: expected WIDTHxHEIGHT, e.g. 320x240") from None
    config = apply_overrides(
        config,
        source__uri=args.source, camera__profile=args.camera,
        modbus__tcp=_off(args.modbus_tcp), modbus__rtu=_off(args.modbus_rtu), serial__port=_off(args.serial),
        history__path=_off(args.db), gauge__window_s=args.window, gauge__step_s=args.step,
        source__realtime=False if args.fast else None, source__size=size,
        diagnostics__folder=_off(args.diagnostics),
        diagnostics__enabled=False if args.diagnostics is not None and not _off(args.diagnostics) else None,
    )
    logging.basicConfig(level=getattr(logging, config.log["level"].upper()), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    inst = build_instrument(config, print_records=config.log["print_records"] and not args.quiet)

    p = inst.profile
    print(f"raingauge: measuring from {inst.grabber.source.name}, camera {p.name} {p.width_px}x{p.height_px} "
          f"at {p.frame_rate_hz:g} Hz; a record every {inst.step_s:g} s over {inst.window_s:g} s",
          file=sys.stderr, flush=True)

    signalled = []

    def on_signal(signum, frame):
        signalled.append(signum)
        inst.stop()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        summary = inst.run(duration_s=args.duration)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    print("raingauge run: " + ", ".join(f"{k} {v}" for k, v in summary.items()), file=sys.stderr)
    src = inst.grabber.source
    if not src.live and not signalled and int(summary.get("frames") or 0) < 3:
        from raingauge.errors import InputError

        bad = int(summary.get("corrupt_frames") or 0)
        raise InputError(
            f"source {src.name} gave {int(summary.get('frames') or 0)} usable frame(s) ({bad} unreadable or not "
            f"{p.width_px}x{p.height_px}); the gauge needs at least 3 consecutive frames, so nothing was measured. "
            f"Fix: give a video or image folder of at least 3 frames at {p.width_px}x{p.height_px}, or a camera "
            "profile (--camera) of the source's size")
    return 0
