"""Reading an OTT Parsivel optical disdrometer and turning its raw counts into rain.

The Parsivel [Loffler-Mang2000] counts every particle crossing a laser sheet
(180 mm x 30 mm) by diameter class and velocity class; one telegram per
interval (30 s) holds the 32 x 32 count matrix beside the instrument's own
products.  :func:`read_parsivel` reads the comma-separated telegram files of
the EPFL campaigns (format in ``shared/data/README.md``, plain or gzip);
:func:`record_density_m4`, :func:`counts_rain_rate_mm_h` and
:func:`record_moments` compute N(D), Eq. (28) and the DSD moments from the raw
counts, independently of the instrument's firmware.

The effective sampling area for a drop of diameter D is
A(D) = 180 mm x (30 mm - D/2): a drop is counted only when it lies wholly
inside the sheet.
"""

from __future__ import annotations

import csv
import gzip
import io
import math
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from raingauge.errors import InputError
from raingauge.physics.drops import (
    PARSIVEL_D_CENTRES_MM,
    PARSIVEL_D_WIDTHS_MM,
    PARSIVEL_V_CENTRES_M_S,
    BinnedDSD,
    dsd_moments,
)

#: sampling interval of one telegram [s]
PARSIVEL_INTERVAL_S = 30.0
#: laser sheet length and width [m]
SHEET_LENGTH_M = 0.180
SHEET_WIDTH_M = 0.030
#: time format of the telegram (column 3)
TIME_FORMAT = "%d-%m-%Y %H:%M:%S"
N_COLUMNS = 24


@dataclass(frozen=True)
class ParsivelRecord:
    """One Parsivel telegram.

    Attributes
    ----------
    time : datetime
        End of the interval, timezone-aware UTC.
    reported_rate_mm_h : float
        The instrument's rain intensity [mm/h] (column 6).
    counts : ndarray, shape (32, 32), int
        Raw counts [velocity class, diameter class] (field 93).
    reported_accumulation_mm : float
        The instrument's accumulated rain [mm] (column 7).
    reported_z_dbz : float
        The instrument's reflectivity [dBZ] (NaN when it reports -9.999).
    synop_4680 : int
        WMO 4680 present-weather code (column 8).
    particle_count : int
        Particles detected in the interval (column 13).
    sensor_status : int
        0 OK, 1 laser dirty but measuring, 2 no measurement, 3 laser damaged.
    reported_log10_n : ndarray, shape (32,)
        Field 90, log10 N(D) [m^-3 mm^-1]; NaN where the instrument reports -9.999.
    reported_v_m_s : ndarray, shape (32,)
        Field 91, mean fall velocity per diameter class [m/s].
    line_number : int
        1-based line in the file.
    """

    time: datetime
    reported_rate_mm_h: float
    counts: np.ndarray
    reported_accumulation_mm: float = math.nan
    reported_z_dbz: float = math.nan
    synop_4680: int = -1
    particle_count: int = -1
    sensor_status: int = -1
    reported_log10_n: np.ndarray = field(default_factory=lambda: np.full(32, np.nan))
    reported_v_m_s: np.ndarray = field(default_factory=lambda: np.full(32, np.nan))
    line_number: int = 0


@dataclass
class ParsivelFile:
    """The records of a telegram file and what could not be read.

    Attributes
    ----------
    path : Path
        The file.
    records : list of ParsivelRecord
        Records in file order.
    malformed_lines : int
        Non-empty lines that could not be read (wrong number of fields, bad
        time, bad numbers, count field not 1024 values).
    malformed_examples : list of (int, str)
        Up to 10 (line number, reason) pairs.
    interval_s : float
        Sampling interval [s].
    """

    path: Path
    records: list[ParsivelRecord]
    malformed_lines: int = 0
    malformed_examples: list[tuple[int, str]] = field(default_factory=list)
    interval_s: float = PARSIVEL_INTERVAL_S

    def __len__(self) -> int:
        return len(self.records)


def _float(text: str) -> float:
    return float(text.strip())


def _vector(text: str, n: int, name: str) -> np.ndarray:
    parts = text.strip().split(",")
    if parts and parts[-1].strip() == "":
        parts.pop()
    if len(parts) != n:
        raise ValueError(f"{name} has {len(parts)} values, expected {n}")
    try:
        return np.array(parts, dtype=float)
    except ValueError:
        raise ValueError(f"{name} holds a value that is not a number") from None


def parse_telegram(fields: list[str], line_number: int = 0) -> ParsivelRecord:
    """Parse one telegram already split into its 24 comma-separated fields.

    Parameters
    ----------
    fields : list of str
        The columns of one line (quoted fields unquoted).
    line_number : int
        For error messages.

    Raises
    ------
    ValueError
        Naming the first field that cannot be read.
    """
    if len(fields) != N_COLUMNS:
        raise ValueError(f"{len(fields)} fields, expected {N_COLUMNS}")
    try:
        time = datetime.strptime(fields[3].strip(), TIME_FORMAT).replace(tzinfo=timezone.utc)
    except ValueError:
        raise ValueError(f"time {fields[3]!r} is not {TIME_FORMAT}") from None
    try:
        rate = _float(fields[6])
    except ValueError:
        raise ValueError(f"rain intensity {fields[6]!r} is not a number") from None
    if not (math.isfinite(rate) and rate >= 0):
        raise ValueError(f"rain intensity {fields[6]!r} is negative or not finite")
    counts_f = _vector(fields[22], 1024, "raw count field 93")
    if np.any(counts_f < 0) or np.any(counts_f != np.round(counts_f)):
        raise ValueError("raw count field 93 holds negative or fractional counts")
    counts = counts_f.astype(np.int64).reshape(32, 32)

    def optional_float(text: str) -> float:
        try:
            x = _float(text)
        except ValueError:
            return math.nan
        return math.nan if x == -9.999 else x

    def optional_int(text: str) -> int:
        try:
            return int(text.strip())
        except ValueError:
            return -1

    try:
        log10_n = _vector(fields[20], 32, "field 90")
        log10_n[log10_n == -9.999] = np.nan
    except ValueError:
        log10_n = np.full(32, np.nan)
    try:
        vmean = _vector(fields[21], 32, "field 91")
    except ValueError:
        vmean = np.full(32, np.nan)
    return ParsivelRecord(
        time=time,
        reported_rate_mm_h=rate,
        counts=counts,
        reported_accumulation_mm=optional_float(fields[7]),
        reported_z_dbz=optional_float(fields[10]),
        synop_4680=optional_int(fields[8]),
        particle_count=optional_int(fields[13]),
        sensor_status=optional_int(fields[17]),
        reported_log10_n=log10_n,
        reported_v_m_s=vmean,
        line_number=line_number,
    )


def _open_text(path: Path):
    with open(path, "rb") as fh:
        magic = fh.read(2)
    if magic == b"\x1f\x8b":
        return io.TextIOWrapper(gzip.open(path, "rb"), encoding="ascii", errors="replace", newline="")
    return open(path, encoding="ascii", errors="replace", newline="")


def read_parsivel(path, *, interval_s: float = PARSIVEL_INTERVAL_S) -> ParsivelFile:
    """Read a Parsivel telegram file (plain text or gzip).

    Every non-empty line is one telegram; lines that cannot be read are
    counted in ``malformed_lines`` (with up to 10 examples) and skipped,
    never fatal.

    Parameters
    ----------
    path : str or Path
        The telegram file.
    interval_s : float
        Sampling interval of one telegram [s] (30 s for the EPFL campaigns).

    Returns
    -------
    ParsivelFile

    Raises
    ------
    InputError
        If the file does not exist or cannot be decompressed.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"Parsivel file {path} is a folder; give the path of a telegram file "
                         f"(.dat or .dat.gz) inside it")
    if not path.is_file():
        raise InputError(f"Parsivel file {path} not found; give the path of a telegram file "
                         f"(.dat or .dat.gz)")
    records: list[ParsivelRecord] = []
    malformed = 0
    examples: list[tuple[int, str]] = []
    try:
        with _open_text(path) as fh:
            for number, line in enumerate(fh, start=1):
                if not line.strip():
                    continue
                try:
                    fields = next(csv.reader([line]))
                    records.append(parse_telegram(fields, number))
                except (ValueError, csv.Error) as exc:
                    malformed += 1
                    if len(examples) < 10:
                        examples.append((number, str(exc)))
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise InputError(f"cannot read Parsivel file {path}: {exc}; check that it is a complete "
                         f"telegram file (plain text or gzip)") from None
    return ParsivelFile(path=path, records=records, malformed_lines=malformed,
                        malformed_examples=examples, interval_s=interval_s)


def effective_area_m2(diameter_m) -> np.ndarray:
    """Effective sampling area of the Parsivel sheet, A(D) = L (W - D/2) [m^2].

    Parameters
    ----------
    diameter_m : array_like
        Drop diameter D [m].
    """
    d = np.asarray(diameter_m, dtype=float)
    return SHEET_LENGTH_M * (SHEET_WIDTH_M - d / 2.0)


_D_M = PARSIVEL_D_CENTRES_MM * 1e-3
_DW_M = PARSIVEL_D_WIDTHS_MM * 1e-3
_AREA_M2 = effective_area_m2(_D_M)


def _counts_array(counts) -> np.ndarray:
    c = np.asarray(counts, dtype=float)
    if c.shape != (32, 32):
        raise ValueError(f"counts must have shape (32, 32) [velocity, diameter], got {c.shape}")
    return c


def record_density_m4(counts, interval_s: float = PARSIVEL_INTERVAL_S) -> np.ndarray:
    """Number density per diameter class from raw counts [m^-4].

    N(D_j) = sum_i c_ij / (A(D_j) dt v_i dD_j), with v_i the velocity class
    centres: a drop falling at v through area A during dt samples a column of
    air of volume A v dt.

    Parameters
    ----------
    counts : array_like, shape (32, 32)
        Raw counts [velocity class, diameter class].
    interval_s : float
        Sampling interval dt [s].

    Returns
    -------
    ndarray, shape (32,)
        N(D) [m^-4] at :data:`~raingauge.physics.drops.PARSIVEL_D_CENTRES_MM`.
    """
    c = _counts_array(counts)
    per_volume = (c / PARSIVEL_V_CENTRES_M_S[:, None]).sum(axis=0) / (_AREA_M2 * interval_s)
    return per_volume / _DW_M


def counts_rain_rate_mm_h(counts, interval_s: float = PARSIVEL_INTERVAL_S) -> float:
    """Rain rate from raw counts, R = 3.6e6 sum_ij c_ij (pi/6) D_j^3 / (A(D_j) dt) [mm/h].

    The counts are a flux (drops per area per time), so no velocity enters:
    this is Eq. (28) [GargNayar2007] with rho(a) v(a) replaced by the
    measured flux.

    Parameters
    ----------
    counts : array_like, shape (32, 32)
        Raw counts [velocity class, diameter class].
    interval_s : float
        Sampling interval dt [s].
    """
    c = _counts_array(counts)
    per_class = c.sum(axis=0)
    return float(3.6e6 * np.sum(per_class * math.pi / 6.0 * _D_M ** 3 / _AREA_M2) / interval_s)


def class_velocity_m_s(counts) -> np.ndarray:
    """Flux-consistent velocity of each diameter class [m/s].

    v_j = sum_i c_ij / sum_i (c_ij / v_i), the harmonic count-weighted mean,
    so that N(D_j) v_j dD_j A dt reproduces the counted flux and
    :func:`~raingauge.physics.drops.dsd_moments` returns the rate of
    :func:`counts_rain_rate_mm_h`.  NaN for empty classes.

    Parameters
    ----------
    counts : array_like, shape (32, 32)
        Raw counts [velocity class, diameter class].
    """
    c = _counts_array(counts)
    n = c.sum(axis=0)
    inv = (c / PARSIVEL_V_CENTRES_M_S[:, None]).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, n / np.where(inv > 0, inv, 1.0), np.nan)


def record_moments(counts, interval_s: float = PARSIVEL_INTERVAL_S) -> dict[str, float]:
    """DSD moments of one record (rain rate, LWC, Z, dBZ, Dm, Nw, Nt, KE flux).

    Parameters
    ----------
    counts : array_like, shape (32, 32)
        Raw counts [velocity class, diameter class].
    interval_s : float
        Sampling interval [s].

    Returns
    -------
    dict
        As :func:`~raingauge.physics.drops.dsd_moments`.
    """
    n = record_density_m4(counts, interval_s)
    v = class_velocity_m_s(counts)
    return dsd_moments(_D_M, _DW_M, n, np.nan_to_num(v, nan=0.0))


def record_dsd(counts, interval_s: float = PARSIVEL_INTERVAL_S) -> BinnedDSD:
    """The record's spectrum as a :class:`~raingauge.physics.drops.BinnedDSD` (Parsivel classes)."""
    return BinnedDSD.from_centres(_D_M, _DW_M, record_density_m4(counts, interval_s))


def daily_totals_mm(records, interval_s: float = PARSIVEL_INTERVAL_S) -> dict[str, tuple[float, float]]:
    """Rain per UTC day: {"YYYY-MM-DD": (ours_mm, reported_mm)}.

    Each record contributes rate x interval; ours from the raw counts, the
    other from the instrument's reported intensity.

    Parameters
    ----------
    records : iterable of ParsivelRecord
    interval_s : float
        Sampling interval [s].
    """
    out: dict[str, list[float]] = {}
    for r in records:
        key = r.time.strftime("%Y-%m-%d")
        acc = out.setdefault(key, [0.0, 0.0])
        acc[0] += counts_rain_rate_mm_h(r.counts, interval_s) * interval_s / 3600.0
        acc[1] += r.reported_rate_mm_h * interval_s / 3600.0
    return {k: (v[0], v[1]) for k, v in sorted(out.items())}
