"""NMEA 0183 style serial sentences for a record.

Two sentences per step:

``$PRGRR`` (proprietary: ``P`` + maker code ``RGR``), fields in the order of
:func:`firmware_interface.fields.nmea_fields` (time hhmmss UTC, rain rate
[mm/h], accumulation since reset [mm], drops counted, Dm [mm], intensity class
0-4, status bits as two hex digits).  An empty field means "invalid", as NMEA
does for null fields.

``$WIXDR`` (the standard transducer sentence) with the rain group as Vaisala
weather transmitters send it [VaisalaWXT530]: ``V`` accumulation [mm], ``Z``
rain duration [s], ``R`` intensity [mm/h], units ``M``, ``s``, ``M`` and
transducer id 0.

Both carry the NMEA checksum (XOR of the bytes between ``$`` and ``*``, two
upper-case hex digits) and are at most 82 characters including CR LF
[NMEA0183].
"""

from __future__ import annotations

import datetime as _dt
import math
from typing import Any

from firmware_interface.fields import intensity_code, nmea_fields

__all__ = ["checksum", "sentence", "prgrr", "wixdr", "sentences_for", "parse", "MAX_LEN", "TALKER_PRGRR"]

#: Longest sentence NMEA 0183 allows, CR LF included.
MAX_LEN = 82
TALKER_PRGRR = "PRGRR"


def checksum(body: str) -> int:
    """XOR of the bytes of ``body`` (the text between ``$`` and ``*``)."""
    value = 0
    for b in body.encode("ascii"):
        value ^= b
    return value


def sentence(body: str) -> str:
    """``$body*hh\\r\\n``; raises ValueError when longer than 82 characters or not printable ASCII."""
    if any(ch in body for ch in "$*!\r\n") or not body.isascii():
        raise ValueError(f"NMEA body must be printable ASCII without $ * ! CR LF: {body!r}")
    line = f"${body}*{checksum(body):02X}\r\n"
    if len(line) > MAX_LEN:
        raise ValueError(f"NMEA sentence of {len(line)} characters exceeds {MAX_LEN}: {line!r}")
    return line


def _num(value, decimals: int, *, lo: float = 0.0, hi: float = 1e7) -> str:
    if value is None:
        return ""
    try:
        v = float(value)
    except (TypeError, ValueError):
        return ""
    if not math.isfinite(v):
        return ""
    v = min(max(v, lo), hi)
    return f"{v:.{decimals}f}" if decimals else str(int(round(v)))


def _hhmmss(t) -> str:
    if t is None or not math.isfinite(float(t)):
        return ""
    return _dt.datetime.fromtimestamp(float(t), tz=_dt.timezone.utc).strftime("%H%M%S")


def prgrr(record: dict[str, Any]) -> str:
    """The proprietary ``$PRGRR`` sentence of an instrument record."""
    parts = [TALKER_PRGRR]
    for f in nmea_fields():
        value = record.get(f.name)
        if f.name == "time_unix":
            parts.append(_hhmmss(value))
        elif f.name == "status":
            parts.append("" if value is None else f"{int(value) & 0xFF:02X}")
        elif f.name == "intensity_class":
            code = intensity_code(value)
            parts.append("" if code is None else str(code))
        else:
            parts.append(_num(value, f.nmea_decimals))
    return sentence(",".join(parts))


def wixdr(record: dict[str, Any]) -> str:
    """``$WIXDR`` rain group: V accumulation [mm], Z duration [s], R intensity [mm/h]."""
    acc = _num(record.get("accumulation_mm"), 2)
    dur = _num(record.get("rain_duration_s"), 0)
    rate = _num(record.get("rain_rate_mm_h"), 1)
    return sentence(f"WIXDR,V,{acc},M,0,Z,{dur},s,0,R,{rate},M,0")


def sentences_for(record: dict[str, Any]) -> list[str]:
    """Both sentences of one record, in sending order."""
    return [prgrr(record), wixdr(record)]


def parse(line: str) -> list[str]:
    """Check a sentence's framing and checksum and return its fields (talker first).

    Raises ValueError on a missing ``$``/``*`` or a wrong checksum.
    """
    line = line.strip()
    if not line.startswith("$") or "*" not in line:
        raise ValueError(f"not an NMEA sentence: {line!r}")
    body, _, hh = line[1:].rpartition("*")
    if len(hh) != 2 or int(hh, 16) != checksum(body):
        raise ValueError(f"bad checksum in {line!r} (computed {checksum(body):02X})")
    return body.split(",")
