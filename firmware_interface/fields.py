"""The one table of output fields [ModbusAP] [VaisalaWXT530] [NMEA0183].

Every quantity the instrument publishes is described once, in :data:`FIELDS`:
its name (the key of an instrument record, the SQLite column and the CSV
header), unit, description, the scaled 16/32-bit Modbus input register(s) and
their type, the float32 register, the position in the ``$PRGRR`` serial
sentence and the SQLite column type.  The Modbus register map
(:mod:`firmware_interface.modbus`), the serial sentences
(:mod:`firmware_interface.nmea`), the history database
(:mod:`raingauge.history`), the CSV export and the README's tables are all
derived from it, so they cannot drift apart.

Instrument records
------------------
An *instrument record* is a plain ``dict`` with the keys of :data:`FIELDS`
(vector fields such as the DSD hold a list); :func:`record_defaults` gives a
record with every key present and "invalid" values, and :func:`sql_row`
flattens a record into one database/CSV row.

Modbus conventions (weather-sensor style, [VaisalaWXT530])
----------------------------------------------------------
* Protocol addresses from 0 (``mbpoll -0``; add 1 for 1-based "register numbers").
* Scaled integers: ``register = round(value * scale)``.  "Invalid" is 65535
  (uint16), 32767 (int16) or 0xFFFFFFFF (uint32); out-of-range values saturate
  at the largest valid value.
* 32-bit values (uint32, float32) occupy two registers, **high word first**
  (big-endian words, big-endian bytes: ABCD); read both in one request.
* float32 registers hold NaN for "invalid".
"""

from __future__ import annotations

import dataclasses
import math
import struct
from typing import Any

__all__ = [
    "Field",
    "HoldingRegister",
    "FIELDS",
    "FIELD_BY_NAME",
    "HOLDING_REGISTERS",
    "STATUS_BITS",
    "N_DSD_CLASSES",
    "RESET_MAGIC",
    "FIRMWARE_VERSION_BYTE",
    "record_defaults",
    "sql_columns",
    "sql_row",
    "iso_utc",
    "csv_header",
    "encode_register",
    "decode_register",
    "encode_float32",
    "decode_float32",
    "input_register_image",
    "nmea_fields",
    "render_register_table",
    "render_nmea_table",
    "render_sql_table",
    "render_docs",
    "status_word",
    "intensity_code",
]

#: Number of Parsivel diameter classes carried by the DSD fields.
N_DSD_CLASSES = 32

#: Written to holding register 0 it resets the accumulation (Vaisala/Lufft convention).
RESET_MAGIC = 0x3247

#: Low byte of input register 0: firmware version, major in the high nibble,
#: minor in the low nibble (0.1 -> 0x01).
FIRMWARE_VERSION_BYTE = 0x01

#: Status register (input register 1) bits.
STATUS_BITS: dict[str, int] = {
    "camera_ok": 0,
    "rain_detected": 1,
    "low_confidence": 2,
    "calibrated": 3,
    "storage_fault": 4,
    "output_fault": 5,
}
_STATUS_TEXT = {
    "camera_ok": "frames arrive from the camera",
    "rain_detected": "the last record saw rain (intensity class above none)",
    "low_confidence": "the last record carries a quality flag (few drops, short window, missing data)",
    "calibrated": "the camera profile comes from `raingauge calibrate` (not a default)",
    "storage_fault": "the history database cannot be written (e.g. disk full); measurement goes on",
    "output_fault": "a serial or Modbus output failed (port vanished, queue overflow)",
}

_INVALID = {"uint16": 0xFFFF, "int16": 0x7FFF, "uint32": 0xFFFFFFFF}
_RANGE = {"uint16": (0, 0xFFFE), "int16": (-0x8000, 0x7FFE), "uint32": (0, 0xFFFFFFFE)}
_WIDTH = {"uint16": 1, "int16": 1, "uint32": 2, "float32": 2}

INTENSITY_NAMES = ("none", "light", "moderate", "heavy", "violent")


@dataclasses.dataclass(frozen=True)
class Field:
    """One published quantity.

    Attributes
    ----------
    name : record key, SQLite column and CSV header (vector fields expand to
        ``name_01 .. name_32`` in SQLite/CSV).
    unit : unit of the value in the record.
    description : one line for the README.
    sql_type : ``"REAL"``, ``"INTEGER"`` or ``"TEXT"``; ``None`` = not stored.
    register : first scaled input register (function 04), or ``None``.
    reg_type : ``"uint16"``, ``"int16"`` or ``"uint32"``.
    scale : register value = round(value * scale) (after ``transform``).
    transform : ``None`` or ``"log10"`` (register holds log10(value) * scale;
        0 maps to the most negative value -32768).
    float_register : first float32 input register, or ``None``.
    nmea : 1-based field position in ``$PRGRR``, or ``None``.
    nmea_decimals : decimals written in the sentence.
    count : 1, or ``N_DSD_CLASSES`` for the per-class DSD.
    """

    name: str
    unit: str
    description: str
    sql_type: str | None = "REAL"
    register: int | None = None
    reg_type: str | None = None
    scale: float = 1.0
    transform: str | None = None
    float_register: int | None = None
    nmea: int | None = None
    nmea_decimals: int = 0
    count: int = 1

    @property
    def register_count(self) -> int:
        """Registers taken in the scaled block."""
        return 0 if self.register is None else _WIDTH[self.reg_type] * self.count

    @property
    def float_register_count(self) -> int:
        return 0 if self.float_register is None else 2 * self.count

    @property
    def invalid(self) -> int | None:
        """Register value meaning "invalid"."""
        return None if self.reg_type is None else _INVALID[self.reg_type]

    @property
    def columns(self) -> list[str]:
        """SQLite/CSV columns of this field."""
        if self.sql_type is None:
            return []
        if self.count == 1:
            return [self.name]
        return [f"{self.name}_{k + 1:02d}" for k in range(self.count)]


@dataclasses.dataclass(frozen=True)
class HoldingRegister:
    """A writable setting (function 03/06/16)."""

    address: int
    name: str
    description: str
    minimum: int
    maximum: int
    special: tuple[int, ...] = ()


HOLDING_REGISTERS: tuple[HoldingRegister, ...] = (
    HoldingRegister(0, "reset", "write 0x3247 (12871) to reset accumulation and rain duration; "
                    "reads 0; any other value is refused (exception 03)", 0, 0, (RESET_MAGIC,)),
    HoldingRegister(1, "unit_id", "Modbus unit (slave) id, 1-247; takes effect after the reply "
                    "and is kept in the history database", 1, 247),
    HoldingRegister(2, "window_s", "averaging window of a record [s], 10-3600, a whole multiple "
                    "of the step", 10, 3600),
)

_D = N_DSD_CLASSES

#: The table.  Order = column order in SQLite and CSV.
FIELDS: tuple[Field, ...] = (
    Field("device_id_version", "-", "high byte: device id (profile `device_id`); low byte: firmware "
          "version (major << 4 | minor)", sql_type=None, register=0, reg_type="uint16"),
    Field("status", "bits", "status bits: " + "; ".join(f"bit {b} {n}" for n, b in STATUS_BITS.items()),
          sql_type="INTEGER", register=1, reg_type="uint16", nmea=7),
    Field("rain_rate_mm_h", "mm/h", "rain rate over the last window (Eq. 28)", register=2,
          reg_type="uint16", scale=100, float_register=200, nmea=2, nmea_decimals=2),
    Field("accumulation_mm", "mm", "rain accumulated since the last reset", register=3,
          reg_type="uint32", scale=100, float_register=202, nmea=3, nmea_decimals=2),
    Field("drops_counted", "count", "drops measured in the last window", sql_type="INTEGER",
          register=5, reg_type="uint16", float_register=204, nmea=4),
    Field("dm_mm", "mm", "mass-weighted mean diameter Dm", register=6, reg_type="uint16", scale=100,
          float_register=206, nmea=5, nmea_decimals=2),
    Field("z_dbz", "dBZ", "radar reflectivity factor Z", register=7, reg_type="int16", scale=10,
          float_register=208),
    Field("intensity_class", "0-4", "0 none, 1 light (< 2.5 mm/h), 2 moderate (< 10), 3 heavy "
          "(< 50), 4 violent (>= 50)", sql_type="INTEGER", register=8, reg_type="uint16",
          float_register=210, nmea=6),
    Field("synop_4680", "code", "present weather, WMO code table 4680 (precipitation part)",
          sql_type="INTEGER", register=9, reg_type="uint16", float_register=212),
    Field("time_unix", "s", "end of the window, seconds since 1970-01-01 UTC", register=10,
          reg_type="uint32", nmea=1),
    Field("time_utc", "ISO 8601", "end of the window as UTC text (from `time_unix`)", sql_type="TEXT"),
    Field("nt_m3", "m^-3", "total drop concentration Nt", float_register=214),
    Field("rain_rate_ci95_lo_mm_h", "mm/h", "lower end of the 95% interval of the rate",
          float_register=216),
    Field("rain_rate_ci95_hi_mm_h", "mm/h", "upper end of the 95% interval of the rate",
          float_register=218),
    Field("drops_rejected_defocus", "count", "streaks rejected as out of focus in the last window",
          sql_type="INTEGER", float_register=220),
    Field("window_s", "s", "length of the averaging window", float_register=222),
    Field("rain_duration_s", "s", "time with rain (steps whose intensity class is above none) since the last reset",
          float_register=224),
    Field("t_start_s", "s", "start of the window on the gauge clock (seconds since start)"),
    Field("t_end_s", "s", "end of the window on the gauge clock (seconds since start)"),
    Field("missing", "0/1", "1 when the camera delivered no frames for this window (no data, not zero rain)",
          sql_type="INTEGER"),
    Field("quality", "flags", "quality flags, comma separated", sql_type="TEXT"),
    Field("frames", "count", "frames processed in the last step", sql_type="INTEGER"),
    Field("corrupt_frames", "count", "corrupt frames skipped since start", sql_type="INTEGER"),
    Field("dropped_frames", "count", "frames of the last step the gauge could not take in real time "
          "(dropped by the camera side, not measured; the rate counts only measured frames)",
          sql_type="INTEGER"),
    Field("exposure_s", "s", "camera exposure time"),
    Field("f_number", "-", "lens F-number"),
    Field("focus_distance_m", "m", "focus distance"),
    Field("frame_rate_hz", "Hz", "camera frame rate"),
    Field("dsd_d_mm", "mm", "centre diameter of Parsivel class k", count=_D),
    Field("dsd_n_m3_mm", "m^-3 mm^-1", "N(D) in Parsivel class k; registers hold log10(N) x 1000 "
          "(-32768 for N = 0, 32767 invalid), the float block holds N itself",
          register=100, reg_type="int16", scale=1000, transform="log10", float_register=230,
          count=_D),
)

FIELD_BY_NAME: dict[str, Field] = {f.name: f for f in FIELDS}


def _check_table() -> None:
    """Registers and NMEA positions must not overlap (import-time guard)."""
    used: dict[int, str] = {}
    for f in FIELDS:
        for base, n in ((f.register, f.register_count), (f.float_register, f.float_register_count)):
            if base is None:
                continue
            for a in range(base, base + n):
                if a in used:
                    raise RuntimeError(f"input register {a} used by {used[a]} and {f.name}")
                used[a] = f.name
    pos = [f.nmea for f in FIELDS if f.nmea is not None]
    if sorted(pos) != list(range(1, len(pos) + 1)):
        raise RuntimeError(f"$PRGRR positions must be 1..n without gaps, got {sorted(pos)}")


_check_table()


# ------------------------------------------------------------------ records
def record_defaults() -> dict[str, Any]:
    """A record with every field present and marked invalid (NaN / None / empty)."""
    out: dict[str, Any] = {}
    for f in FIELDS:
        if f.count > 1:
            out[f.name] = [math.nan] * f.count
        elif f.sql_type == "TEXT":
            out[f.name] = ""
        elif f.sql_type == "INTEGER" or f.name == "device_id_version":
            out[f.name] = None
        else:
            out[f.name] = math.nan
    out["quality"] = []
    out["status"] = 0
    out["missing"] = 0
    return out


def _finite(value) -> bool:
    try:
        return value is not None and math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def iso_utc(t_unix: float) -> str:
    """``2026-11-22T09:30:00Z`` from seconds since the epoch [s]."""
    import datetime as dt

    stamp = dt.datetime.fromtimestamp(float(t_unix), tz=dt.timezone.utc)
    text = stamp.isoformat(timespec="milliseconds" if stamp.microsecond else "seconds")
    return text.replace("+00:00", "Z")


def sql_columns() -> dict[str, type]:
    """Column name -> Python type for the history table (float, int, str), in table order."""
    types = {"REAL": float, "INTEGER": int, "TEXT": str}
    cols: dict[str, type] = {}
    for f in FIELDS:
        for c in f.columns:
            cols[c] = types[f.sql_type]
    return cols


def csv_header() -> list[str]:
    """The CSV header: the SQLite columns in table order."""
    return list(sql_columns())


def sql_row(record: dict[str, Any]) -> dict[str, Any]:
    """Flatten an instrument record into one row with every column (None = NULL).

    NaN becomes NULL, the quality list becomes ``"flag1,flag2"``, vector
    fields expand to ``name_01 .. name_32``.
    """
    row: dict[str, Any] = {}
    for f in FIELDS:
        if f.sql_type is None:
            continue
        value = record.get(f.name)
        if f.name == "time_utc" and not value and _finite(record.get("time_unix")):
            value = iso_utc(float(record["time_unix"]))
        if f.count > 1:
            values = list(value) if value is not None else []
            values = values + [None] * (f.count - len(values))
            for c, v in zip(f.columns, values[: f.count]):
                row[c] = float(v) if _finite(v) else None
            continue
        if f.sql_type == "TEXT":
            if isinstance(value, (list, tuple)):
                value = ",".join(str(v) for v in value)
            row[f.name] = "" if value is None else str(value)
        elif f.sql_type == "INTEGER":
            row[f.name] = int(value) if _finite(value) else None
        else:
            row[f.name] = float(value) if _finite(value) else None
    return row


# ------------------------------------------------------------------ registers
def encode_register(field: Field, value) -> list[int]:
    """Scaled register word(s) of one value of ``field`` (a scalar)."""
    t = field.reg_type
    if not _finite(value):
        inv = _INVALID[t]
        return [inv >> 16, inv & 0xFFFF] if t == "uint32" else [inv]
    v = float(value)
    if field.transform == "log10":
        if v <= 0:
            return [0x8000]  # -32768: nothing in this class
        v = math.log10(v)
    lo, hi = _RANGE[t]
    n = int(min(max(round(v * field.scale), lo), hi))
    if t == "uint32":
        return [n >> 16, n & 0xFFFF]
    return [n & 0xFFFF]


def decode_register(field: Field, words: list[int]) -> float:
    """Inverse of :func:`encode_register` (NaN for invalid; 0 for a log10 field's -32768)."""
    t = field.reg_type
    if t == "uint32":
        n = (words[0] << 16) | words[1]
    else:
        n = words[0]
    if n == _INVALID[t]:
        return math.nan
    if t == "int16":
        n = n - 0x10000 if n >= 0x8000 else n
        if field.transform == "log10" and n == -0x8000:
            return 0.0
    v = n / field.scale
    return 10.0 ** v if field.transform == "log10" else v


def encode_float32(value) -> list[int]:
    """IEEE-754 float32, high word first (NaN for invalid)."""
    v = float(value) if _finite(value) else math.nan
    hi, lo = struct.unpack(">HH", struct.pack(">f", v))
    return [hi, lo]


def decode_float32(words: list[int]) -> float:
    return struct.unpack(">f", struct.pack(">HH", words[0], words[1]))[0]


def status_word(**bits: bool) -> int:
    """Status register value from named bits (see :data:`STATUS_BITS`)."""
    unknown = set(bits) - set(STATUS_BITS)
    if unknown:
        raise ValueError(f"unknown status bits {sorted(unknown)}; valid: {list(STATUS_BITS)}")
    return sum(1 << STATUS_BITS[k] for k, v in bits.items() if v)


def intensity_code(value) -> int | None:
    """Intensity class as 0-4 from an int or a name ("none" ... "violent")."""
    if value is None:
        return None
    if isinstance(value, str):
        key = value.strip().lower()
        if key in INTENSITY_NAMES:
            return INTENSITY_NAMES.index(key)
        raise ValueError(f"unknown intensity class {value!r}; valid: {INTENSITY_NAMES}")
    if not _finite(value):
        return None
    return int(value)


def input_register_image(record: dict[str, Any], *, device_id: int) -> dict[int, list[int]]:
    """All input registers for a record: ``{first_address: [words...]}`` per field.

    ``device_id`` [0-255] goes into the high byte of register 0.
    """
    out: dict[int, list[int]] = {}
    for f in FIELDS:
        if f.name == "device_id_version":
            out[0] = [((int(device_id) & 0xFF) << 8) | FIRMWARE_VERSION_BYTE]
            continue
        value = record.get(f.name)
        if f.name == "intensity_class":
            value = intensity_code(value)
        values = list(value) if f.count > 1 else [value]
        if f.count > 1:
            values = (values + [None] * f.count)[: f.count]
        if f.register is not None:
            words: list[int] = []
            for v in values:
                words.extend(encode_register(f, v))
            out[f.register] = words
        if f.float_register is not None:
            words = []
            for v in values:
                words.extend(encode_float32(v))
            out[f.float_register] = words
    return out


def nmea_fields() -> list[Field]:
    """Fields of ``$PRGRR`` in sentence order."""
    return sorted((f for f in FIELDS if f.nmea is not None), key=lambda f: f.nmea)


# ------------------------------------------------------------------ docs
def _md_escape(text: str) -> str:
    return text.replace("|", "\\|")


def render_register_table() -> str:
    """The Modbus register map as Markdown (input registers, float block, holding registers)."""
    lines = [
        "### Input registers (function 04), scaled integers",
        "",
        "| Address | Words | Name | Type | Scale | Unit | Invalid | Description |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for f in sorted((f for f in FIELDS if f.register is not None), key=lambda f: f.register):
        last = f.register + f.register_count - 1
        addr = f"{f.register}" if last == f.register else f"{f.register}-{last}"
        scale = f"x {f.scale:g}" if f.transform is None else f"log10 x {f.scale:g}"
        typ = f.reg_type + (" (high word first)" if f.reg_type == "uint32" else "")
        if f.count > 1:
            typ += f" x {f.count}"
        invalid = "-" if f.name == "device_id_version" else str(f.invalid)
        lines.append(f"| {addr} | {f.register_count} | `{f.name}` | {typ} | {scale} | "
                     f"{_md_escape(f.unit)} | {invalid} | {_md_escape(f.description)} |")
    lines += [
        "",
        "### Input registers (function 04), float32 block",
        "",
        "IEEE-754 float32, two registers each, high word first; NaN = invalid.",
        "",
        "| Address | Words | Name | Unit | Description |",
        "|---|---|---|---|---|",
    ]
    for f in sorted((f for f in FIELDS if f.float_register is not None), key=lambda f: f.float_register):
        last = f.float_register + f.float_register_count - 1
        desc = f.description if f.transform is None else "N(D) in Parsivel class k (linear, not log10)"
        lines.append(f"| {f.float_register}-{last} | {f.float_register_count} | `{f.name}` | "
                     f"{_md_escape(f.unit)} | {_md_escape(desc)} |")
    lines += [
        "",
        "### Holding registers (functions 03, 06, 16)",
        "",
        "| Address | Name | Range | Description |",
        "|---|---|---|---|",
    ]
    for h in HOLDING_REGISTERS:
        rng = ", ".join(f"0x{s:04X}" for s in h.special) if h.special else f"{h.minimum}-{h.maximum}"
        lines.append(f"| {h.address} | `{h.name}` | {rng} | {_md_escape(h.description)} |")
    lines += [
        "",
        "Any other address, count or value answers exception 02 (illegal data address) or",
        "03 (illegal data value) and changes nothing. Device identification (function 43/14)",
        "answers VendorName, ProductCode, MajorMinorRevision, ProductName and ModelName.",
        "",
        "### Status bits (input register 1)",
        "",
        "| Bit | Name | Set when |",
        "|---|---|---|",
    ]
    for name, bit in STATUS_BITS.items():
        lines.append(f"| {bit} | `{name}` | {_STATUS_TEXT[name]} |")
    return "\n".join(lines) + "\n"


def render_nmea_table() -> str:
    """The ``$PRGRR`` field list as Markdown."""
    lines = [
        "### `$PRGRR` (proprietary, every step)",
        "",
        "`$PRGRR,f1,f2,...*hh<CR><LF>`; empty field = invalid; checksum = XOR of the bytes "
        "between `$` and `*`.",
        "",
        "| Field | Name | Unit | Format | Description |",
        "|---|---|---|---|---|",
    ]
    for f in nmea_fields():
        if f.name == "time_unix":
            fmt, unit = "hhmmss (UTC)", "UTC"
        elif f.name == "status":
            fmt, unit = "2 hex digits", "bits"
        else:
            fmt, unit = (f"%.{f.nmea_decimals}f" if f.nmea_decimals else "integer"), f.unit
        lines.append(f"| {f.nmea} | `{f.name}` | {_md_escape(unit)} | {fmt} | {_md_escape(f.description)} |")
    lines += [
        "",
        "### `$WIXDR` (standard transducer sentence, as Vaisala weather transmitters send it)",
        "",
        "`$WIXDR,V,<accumulation>,M,0,Z,<rain duration>,s,0,R,<rate>,M,0*hh`: V = accumulation "
        "[mm] since reset, Z = rain duration [s] since reset, R = rain intensity [mm/h]; "
        "transducer id 0.",
    ]
    return "\n".join(lines) + "\n"


def render_sql_table() -> str:
    """History database / CSV columns as Markdown."""
    lines = [
        "### History table `records` and CSV columns",
        "",
        "| Column | SQLite type | Unit | Description |",
        "|---|---|---|---|",
    ]
    for f in FIELDS:
        if f.sql_type is None:
            continue
        col = f.name if f.count == 1 else f"{f.columns[0]} .. {f.columns[-1]}"
        lines.append(f"| `{col}` | {f.sql_type} | {_md_escape(f.unit)} | {_md_escape(f.description)} |")
    return "\n".join(lines) + "\n"


def render_docs() -> str:
    """The whole ``docs/modbus_registers.md`` file."""
    return (
        "# Output fields: Modbus registers and serial sentences\n\n"
        "Generated from `firmware_interface/fields.py` "
        "(`python -m firmware_interface.fields > docs/modbus_registers.md`); "
        "do not edit by hand.\n\n"
        "Protocol addresses from 0 (mbpoll: `-0`). 32-bit values are two registers, high word "
        "first; read them in one request.\n\n"
        + render_register_table() + "\n## Serial sentences\n\n" + render_nmea_table()
        + "\n## History database and CSV\n\n" + render_sql_table()
    )


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.stdout.write(render_docs())
