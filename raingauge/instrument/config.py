"""The instrument's configuration: one TOML file, validated with errors naming key and fix.

Every key is optional; a file may hold only what differs from the embedded
default (which runs the simulated camera, see :data:`DEFAULTS`).  Sections and
keys (see ``deploy/raingauge.toml`` for a commented example)::

    [camera]      profile            shipped profile name or path of a profile TOML
    [source]      uri                "simulate:RATE", a device index "0", rtsp:// or http(s):// URL,
                                     a video file or a folder of images
                  realtime           play files / simulation at the camera's frame rate (true: like
                                     a camera, frames the gauge cannot take are dropped, counted and
                                     flagged) or as fast as possible (false: nothing dropped)
                  size               [width, height] of simulated frames (simulation only)
                  reconnect_max_s    longest wait between reconnection attempts [s]
                  stall_timeout_s    no frame for this long counts as a lost camera [s]
    [gauge]       window_s, step_s   averaging window and record interval [s]
                  velocity_model     fall-velocity law used to size drops
                  completeness_probe artificial drops measure how the scene hides rain (bool)
    [modbus]      tcp                "HOST:PORT" or "" (off); rtu "PORT[:BAUD]" or "" (off)
                  rtu_parity         "N", "E" or "O"; unit_id 1-247
    [serial]      port               "PORT[:BAUD]" or "" (off) for the NMEA sentences
    [history]     path               SQLite database; retention_days (0 = keep all)
    [diagnostics] enabled, folder, interval_s, frames
    [log]         level              "debug", "info", "warning", "error"; print_records (bool)

Settings written over Modbus (unit id, window) are kept in the history
database and override the file on the next start.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Any

from raingauge.errors import ConfigError

__all__ = ["DEFAULTS", "InstrumentConfig", "load_config", "config_from_dict", "apply_overrides", "EMBEDDED_SOURCE"]

EMBEDDED_SOURCE = "simulate:10"

#: section -> key -> default
DEFAULTS: dict[str, dict[str, Any]] = {
    "camera": {"profile": "gauge-default"},
    "source": {"uri": EMBEDDED_SOURCE, "realtime": True, "size": None, "reconnect_max_s": 60.0,
               "stall_timeout_s": 5.0, "seed": 0},
    "gauge": {"window_s": 60.0, "step_s": 10.0, "velocity_model": "gunn_kinzer", "completeness_probe": True},
    "modbus": {"tcp": "127.0.0.1:5020", "rtu": "", "rtu_parity": "N", "unit_id": 1},
    "serial": {"port": ""},
    "history": {"path": "raingauge.sqlite", "retention_days": 0.0},
    "diagnostics": {"enabled": True, "folder": "diagnostics", "interval_s": 600.0, "frames": 32},
    "log": {"level": "info", "print_records": True},
}

_HINT: dict[tuple[str, str], str] = {
    ("camera", "profile"): 'profile = "gauge-default" or a path such as "/etc/raingauge/camera.toml"',
    ("source", "uri"): 'uri = "simulate:10", "0" (first camera), "rtsp://host/stream", a video file or an image folder',
    ("source", "realtime"): "realtime = true (pace at the frame rate) or false (as fast as possible)",
    ("source", "size"): "size = [640, 360] (width, height of simulated frames)",
    ("source", "reconnect_max_s"): "reconnect_max_s = 60.0",
    ("source", "stall_timeout_s"): "stall_timeout_s = 5.0",
    ("source", "seed"): "seed = 0 (random seed of the simulated rain)",
    ("gauge", "window_s"): "window_s = 60.0 (a whole multiple of step_s)",
    ("gauge", "step_s"): "step_s = 10.0",
    ("gauge", "velocity_model"): 'velocity_model = "gunn_kinzer" (or "paper", "atlas1973", "beard1976")',
    ("gauge", "completeness_probe"): "completeness_probe = true (or false to save its CPU)",
    ("modbus", "tcp"): 'tcp = "0.0.0.0:502" or "" to switch Modbus TCP off',
    ("modbus", "rtu"): 'rtu = "/dev/ttyUSB0:19200" or "" to switch Modbus RTU off',
    ("modbus", "rtu_parity"): 'rtu_parity = "N" (or "E", "O")',
    ("modbus", "unit_id"): "unit_id = 1 (1-247)",
    ("serial", "port"): 'port = "/dev/ttyUSB1:4800" or "" to switch the NMEA output off',
    ("history", "path"): 'path = "/var/lib/raingauge/raingauge.sqlite"',
    ("history", "retention_days"): "retention_days = 365 (0 keeps everything)",
    ("diagnostics", "enabled"): "enabled = true",
    ("diagnostics", "folder"): 'folder = "/var/lib/raingauge/diagnostics"',
    ("diagnostics", "interval_s"): "interval_s = 600.0",
    ("diagnostics", "frames"): "frames = 32 (frames kept for a diagnostic snapshot, >= 3)",
    ("log", "level"): 'level = "info"',
    ("log", "print_records"): "print_records = true",
}


def _err(source: str | None, section: str, key: str | None, problem: str) -> ConfigError:
    where = f"configuration {source}" if source else "configuration"
    name = f"[{section}]" + (f".{key}" if key else "")
    hint = _HINT.get((section, key or ""), None)
    msg = f"{where}, key {name}: {problem}"
    if hint:
        msg += f". Fix: {hint}"
    return ConfigError(msg)


def _number(src, sec, key, v, *, positive=True, allow_zero=False, integer=False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not isinstance(v, int)):
        raise _err(src, sec, key, f"expected {'an integer' if integer else 'a number'}, got {v!r}")
    if not math.isfinite(v):
        raise _err(src, sec, key, f"expected a finite number, got {v!r}")
    if positive and not (v > 0 or (allow_zero and v == 0)):
        raise _err(src, sec, key, f"must be {'>= 0' if allow_zero else '> 0'}, got {v!r}")
    return v


def _string(src, sec, key, v) -> str:
    if not isinstance(v, str):
        raise _err(src, sec, key, f"expected a string, got {v!r}")
    return v


def _bool(src, sec, key, v) -> bool:
    if not isinstance(v, bool):
        raise _err(src, sec, key, f"expected true or false, got {v!r}")
    return v


@dataclasses.dataclass(frozen=True)
class InstrumentConfig:
    """A validated configuration (the sections of :data:`DEFAULTS` as dicts)."""

    camera: dict
    source: dict
    gauge: dict
    modbus: dict
    serial: dict
    history: dict
    diagnostics: dict
    log: dict
    origin: str | None = None

    def as_dict(self) -> dict[str, dict]:
        return {s: dict(getattr(self, s)) for s in DEFAULTS}


def _validate(data: dict, source: str | None) -> dict[str, dict]:
    if not isinstance(data, dict):
        raise ConfigError(f"configuration {source}: expected tables such as [source], [modbus]")
    out = copy.deepcopy(DEFAULTS)
    for section, table in data.items():
        if section not in DEFAULTS:
            raise ConfigError(f"configuration {source or ''}: unknown section [{section}]. Fix: remove it or use one "
                              f"of {', '.join('[' + s + ']' for s in DEFAULTS)}")
        if not isinstance(table, dict):
            raise _err(source, section, None, "must be a table")
        for key, value in table.items():
            if key not in DEFAULTS[section]:
                raise _err(source, section, key, f"unknown key; valid keys of [{section}]: {', '.join(DEFAULTS[section])}")
            out[section][key] = value
    S = source
    c = out["camera"]
    _string(S, "camera", "profile", c["profile"])
    s = out["source"]
    s["uri"] = str(s["uri"]) if isinstance(s["uri"], int) and not isinstance(s["uri"], bool) else s["uri"]
    if not _string(S, "source", "uri", s["uri"]).strip():
        raise _err(S, "source", "uri", "is empty")
    _bool(S, "source", "realtime", s["realtime"])
    if s["size"] is not None:
        size = s["size"]
        if not (isinstance(size, list) and len(size) == 2 and all(isinstance(v, int) and not isinstance(v, bool) and 16 <= v <= 20000 for v in size)):
            raise _err(S, "source", "size", f"expected [width, height] in pixels (16-20000), got {size!r}")
    _number(S, "source", "reconnect_max_s", s["reconnect_max_s"])
    _number(S, "source", "stall_timeout_s", s["stall_timeout_s"])
    _number(S, "source", "seed", s["seed"], positive=False, integer=True)
    g = out["gauge"]
    w = _number(S, "gauge", "window_s", g["window_s"])
    st = _number(S, "gauge", "step_s", g["step_s"])
    if w < st:
        raise _err(S, "gauge", "window_s", f"window {w} s is shorter than the step {st} s")
    if abs(w / st - round(w / st)) > 1e-9:
        raise _err(S, "gauge", "window_s", f"window {w} s is not a whole multiple of step_s = {st} s")
    if w > 3600:
        raise _err(S, "gauge", "window_s", f"window {w} s is longer than an hour")
    _string(S, "gauge", "velocity_model", g["velocity_model"])
    _bool(S, "gauge", "completeness_probe", g["completeness_probe"])
    m = out["modbus"]
    for key in ("tcp", "rtu"):
        _string(S, "modbus", key, m[key])
    if m["tcp"]:
        from firmware_interface.modbus import parse_host_port

        try:
            parse_host_port(m["tcp"])
        except ConfigError as exc:
            raise _err(S, "modbus", "tcp", str(exc).split(". Fix:")[0]) from None
    if m["rtu_parity"] not in ("N", "E", "O"):
        raise _err(S, "modbus", "rtu_parity", f"must be N, E or O, got {m['rtu_parity']!r}")
    u = _number(S, "modbus", "unit_id", m["unit_id"], integer=True)
    if not 1 <= u <= 247:
        raise _err(S, "modbus", "unit_id", f"must be 1-247, got {u}")
    _string(S, "serial", "port", out["serial"]["port"])
    h = out["history"]
    _string(S, "history", "path", h["path"])
    _number(S, "history", "retention_days", h["retention_days"], allow_zero=True)
    d = out["diagnostics"]
    _bool(S, "diagnostics", "enabled", d["enabled"])
    _string(S, "diagnostics", "folder", d["folder"])
    _number(S, "diagnostics", "interval_s", d["interval_s"])
    n = _number(S, "diagnostics", "frames", d["frames"], integer=True)
    if n < 3:
        raise _err(S, "diagnostics", "frames", f"needs at least 3 frames, got {n}")
    lg = out["log"]
    if lg["level"] not in ("debug", "info", "warning", "error"):
        raise _err(S, "log", "level", f"unknown level {lg['level']!r}")
    _bool(S, "log", "print_records", lg["print_records"])
    return out


def config_from_dict(data: dict, *, source: str | None = None) -> InstrumentConfig:
    """Validate a parsed TOML document."""
    return InstrumentConfig(**_validate(data, source), origin=source)


def load_config(path: str | Path | None) -> InstrumentConfig:
    """Read and validate a configuration file; ``None`` gives the embedded default."""
    if path is None:
        return config_from_dict({})
    p = Path(path)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise ConfigError(f"configuration {p}: file does not exist. Fix: give the path of a TOML file "
                          "(see deploy/raingauge.toml), or leave --config out for the embedded default") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"configuration {p}: cannot be read ({exc})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"configuration {p}: not valid TOML ({exc}). Fix: correct the syntax") from None
    return config_from_dict(data, source=str(p))


def apply_overrides(config: InstrumentConfig, **overrides: Any) -> InstrumentConfig:
    """Return a config with command-line overrides applied and validated again.

    Keys are ``section__key`` (``source__uri="0"``); ``None`` values are ignored.
    """
    data = config.as_dict()
    for name, value in overrides.items():
        if value is None:
            continue
        section, _, key = name.partition("__")
        data[section][key] = value
    return config_from_dict(data, source=(config.origin or "defaults") + " + command line")

