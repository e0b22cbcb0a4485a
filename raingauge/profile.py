"""Camera profiles: the TOML description of a camera that the gauge runs on.

A profile is a TOML file with a ``[camera]`` table.  These keys are a contract
shared with other tools (the calibration wizard writes them, the simulator and
the gauge read them)::

    [camera]
    name = "gauge-default"
    width_px = 1280
    height_px = 720
    frame_rate_hz = 30.0
    focal_length_px = 7000.0
    f_number = 2.0
    focus_distance_m = 2.5
    exposure_s = 0.004
    pixel_pitch_m = 5.0e-6      # optional
    noise_sigma_dn = 2.0        # sensor noise, gray levels
    response = "linear"         # or a path to a 256-entry linearisation table

Optional keys (defaults in :data:`OPTIONAL_KEYS`):

``principal_point_px``  [cx, cy]; default the image centre.
``distortion``          OpenCV distortion coefficients (k1, k2, p1, p2[, k3]).
``exposure_range_s``    [min, max] exposure the camera allows.
``f_number_range``      [min, max] F-number the lens allows.
``focus_range_m``       [min, max] focus distance the lens allows.
``gain``                gray levels per unit linear irradiance (informational).
``detection_threshold_dn``  the Eq. (19) threshold c for this camera.
``device_id``           instrument identifier (0-255) reported over Modbus.

A ``[provenance]`` table (free-form, written by ``raingauge calibrate``) is
kept verbatim in :attr:`CameraProfile.provenance`.

The linearisation table, when ``response`` is a path (relative to the profile
file), holds 256 numbers, one per 8-bit code value, giving the linear
intensity in gray-level units (0 maps to 0, 255 to about 255).  It may be a
text file with one number per line (or comma separated) or a ``.npy`` file.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from raingauge.errors import ProfileError

__all__ = [
    "CameraProfile",
    "load_profile",
    "default_profile",
    "profile_from_dict",
    "profile_to_toml",
    "write_profile",
    "PROFILE_DIR_PACKAGE",
]

PROFILE_DIR_PACKAGE = "calibration.profiles"

REQUIRED_KEYS: dict[str, type | tuple[type, ...]] = {
    "name": str,
    "width_px": int,
    "height_px": int,
    "frame_rate_hz": (int, float),
    "focal_length_px": (int, float),
    "f_number": (int, float),
    "focus_distance_m": (int, float),
    "exposure_s": (int, float),
    "noise_sigma_dn": (int, float),
    "response": str,
}

OPTIONAL_KEYS: dict[str, Any] = {
    "pixel_pitch_m": None,
    "principal_point_px": None,
    "distortion": None,
    "exposure_range_s": None,
    "f_number_range": None,
    "focus_range_m": None,
    "gain": None,
    "detection_threshold_dn": 3.0,
    "device_id": 1,
}

_HINTS = {
    "name": 'a short identifier, e.g. name = "gauge-default"',
    "width_px": "image width in pixels, e.g. width_px = 1280",
    "height_px": "image height in pixels, e.g. height_px = 720",
    "frame_rate_hz": "frames per second, e.g. frame_rate_hz = 30.0",
    "focal_length_px": "focal length in pixels (f_mm / pixel pitch), e.g. focal_length_px = 7000.0",
    "f_number": "the lens F-number N, e.g. f_number = 2.0",
    "focus_distance_m": "distance of the plane of focus in metres, e.g. focus_distance_m = 2.5",
    "exposure_s": "exposure time in seconds, e.g. exposure_s = 0.004",
    "noise_sigma_dn": "sensor noise standard deviation in gray levels, e.g. noise_sigma_dn = 2.0",
    "response": 'response = "linear", or a path to a 256-entry linearisation table',
}


@dataclasses.dataclass(frozen=True)
class CameraProfile:
    """A validated, immutable camera description (SI units).

    Attributes mirror the TOML keys.  ``response_table`` is the 256-entry
    linearisation table (identity for a linear camera); ``source`` is the file
    the profile came from (or ``None``).
    """

    name: str
    width_px: int
    height_px: int
    frame_rate_hz: float
    focal_length_px: float
    f_number: float
    focus_distance_m: float
    exposure_s: float
    noise_sigma_dn: float
    response: str = "linear"
    pixel_pitch_m: float | None = None
    principal_point_px: tuple[float, float] | None = None
    distortion: tuple[float, ...] | None = None
    exposure_range_s: tuple[float, float] | None = None
    f_number_range: tuple[float, float] | None = None
    focus_range_m: tuple[float, float] | None = None
    gain: float | None = None
    detection_threshold_dn: float = 3.0
    device_id: int = 1
    provenance: dict = dataclasses.field(default_factory=dict, compare=False)
    response_table: np.ndarray = dataclasses.field(default=None, compare=False, repr=False)
    source: str | None = dataclasses.field(default=None, compare=False)

    # ------------------------------------------------------------------ derived
    @property
    def frame_interval_s(self) -> float:
        """Time between frames [s]."""
        return 1.0 / self.frame_rate_hz

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape (rows, columns)."""
        return (self.height_px, self.width_px)

    @property
    def principal_point(self) -> tuple[float, float]:
        """Principal point (cx, cy) [px]; the image centre when not calibrated."""
        if self.principal_point_px is not None:
            return self.principal_point_px
        return ((self.width_px - 1) / 2.0, (self.height_px - 1) / 2.0)

    @property
    def is_linear(self) -> bool:
        return self.response == "linear"

    def linearize(self, frame: np.ndarray) -> np.ndarray:
        """Map 8-bit code values to linear intensity [gray levels], float32.

        Parameters
        ----------
        frame : (M, N) or (M, N, C) uint8 array
        """
        frame = np.asarray(frame)
        if self.is_linear:
            return frame.astype(np.float32)
        if frame.dtype != np.uint8:
            raise ProfileError(
                f"profile {self.name!r} has a non-linear response table, which maps 8-bit "
                f"frames; got dtype {frame.dtype}. Convert frames to uint8 first."
            )
        return self.response_table.astype(np.float32)[frame]

    def delinearize(self, linear: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`linearize`: linear intensity -> 8-bit code values (uint8)."""
        linear = np.asarray(linear, dtype=np.float64)
        if self.is_linear:
            return np.clip(np.rint(linear), 0, 255).astype(np.uint8)
        table = np.asarray(self.response_table, dtype=np.float64)
        # The table is monotonic; invert by interpolation onto code values.
        codes = np.interp(linear, table, np.arange(256.0))
        return np.clip(np.rint(codes), 0, 255).astype(np.uint8)

    def replace(self, **changes: Any) -> "CameraProfile":
        """A copy with some fields changed, validated again."""
        data = self.to_dict()
        data.update(changes)
        return profile_from_dict(
            {"camera": data, "provenance": dict(self.provenance)},
            source=self.source,
            response_table=self.response_table if "response" not in changes else None,
        )

    def to_dict(self) -> dict[str, Any]:
        """The ``[camera]`` table as plain TOML-able values (optional keys left out when unset)."""
        out: dict[str, Any] = {}
        for key in list(REQUIRED_KEYS) + ["pixel_pitch_m"] + [
            k for k in OPTIONAL_KEYS if k != "pixel_pitch_m"
        ]:
            value = getattr(self, key)
            if value is None:
                continue
            if isinstance(value, tuple):
                value = list(value)
            out[key] = value
        return out


# ---------------------------------------------------------------------- loading
def _err(source: str | None, key: str | None, problem: str, fix: str | None = None) -> ProfileError:
    where = f"camera profile {source}" if source else "camera profile"
    if key:
        where += f", key [camera].{key}"
    msg = f"{where}: {problem}"
    if fix:
        msg += f". Fix: {fix}"
    return ProfileError(msg)


def _check_type(source, key, value, types):
    if isinstance(value, bool) or not isinstance(value, types):
        want = types.__name__ if isinstance(types, type) else " or ".join(t.__name__ for t in types)
        raise _err(source, key, f"expected {want}, got {type(value).__name__} {value!r}", _HINTS.get(key))


def _positive(source, key, value):
    if not (math.isfinite(float(value)) and float(value) > 0):
        raise _err(source, key, f"must be a positive finite number, got {value!r}", _HINTS.get(key))


def _pair(source, key, value) -> tuple[float, float]:
    if (
        not isinstance(value, (list, tuple))
        or len(value) != 2
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    ):
        raise _err(source, key, f"expected a list of two numbers [min, max], got {value!r}")
    lo, hi = float(value[0]), float(value[1])
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
        raise _err(source, key, f"needs 0 < min <= max, got {value!r}")
    return (lo, hi)


def load_response_table(path: Path, *, source: str | None = None) -> np.ndarray:
    """Read a 256-entry linearisation table (text or .npy)."""
    try:
        if path.suffix == ".npy":
            table = np.load(path)
        else:
            text = path.read_text().replace(",", " ")
            table = np.array([float(t) for t in text.split()], dtype=np.float64)
    except FileNotFoundError:
        raise _err(source, "response", f"linearisation table {path} does not exist",
                   'give a path relative to the profile file, or response = "linear"') from None
    except (OSError, ValueError) as exc:
        raise _err(source, "response", f"cannot read linearisation table {path}: {exc}",
                   "write 256 numbers, one per line") from None
    table = np.asarray(table, dtype=np.float64).ravel()
    if table.size != 256 or not np.all(np.isfinite(table)):
        raise _err(source, "response", f"linearisation table {path} has {table.size} finite entries, needs 256",
                   "one linear value per 8-bit code 0..255")
    if np.any(np.diff(table) < 0):
        raise _err(source, "response", f"linearisation table {path} is not monotonically increasing",
                   "re-run the radiometric step of `raingauge calibrate`")
    return table


def profile_from_dict(
    data: dict, *, source: str | None = None, base_dir: Path | None = None,
    response_table: np.ndarray | None = None,
) -> CameraProfile:
    """Validate a parsed TOML document (with a ``camera`` table) into a :class:`CameraProfile`."""
    if not isinstance(data, dict) or "camera" not in data or not isinstance(data["camera"], dict):
        raise _err(source, None, "no [camera] table", "start the file with a [camera] table (see calibration/profiles/gauge-default.toml)")
    cam = data["camera"]
    unknown = set(cam) - set(REQUIRED_KEYS) - set(OPTIONAL_KEYS)
    if unknown:
        raise _err(source, sorted(unknown)[0], "unknown key",
                   f"remove it or use one of: {', '.join(list(REQUIRED_KEYS) + list(OPTIONAL_KEYS))}")
    for key, types in REQUIRED_KEYS.items():
        if key not in cam:
            raise _err(source, key, "missing", _HINTS[key])
        _check_type(source, key, cam[key], types)
    kw: dict[str, Any] = {k: cam[k] for k in REQUIRED_KEYS}
    for key in ("width_px", "height_px"):
        if kw[key] < 3 or kw[key] > 20000:
            raise _err(source, key, f"must be between 3 and 20000 pixels, got {kw[key]}", _HINTS[key])
    for key in ("frame_rate_hz", "focal_length_px", "f_number", "focus_distance_m", "exposure_s"):
        _positive(source, key, kw[key])
        kw[key] = float(kw[key])
    noise = float(kw["noise_sigma_dn"])
    if not (math.isfinite(noise) and noise >= 0):
        raise _err(source, "noise_sigma_dn", f"must be >= 0, got {noise}", _HINTS["noise_sigma_dn"])
    kw["noise_sigma_dn"] = noise
    if kw["exposure_s"] > 1.0 / kw["frame_rate_hz"] * (1 + 1e-9):
        raise _err(
            source, "exposure_s",
            f"exposure {kw['exposure_s']} s is longer than the frame interval 1/{kw['frame_rate_hz']:g} s",
            f"use exposure_s <= {1.0 / kw['frame_rate_hz']:.6g} or a lower frame_rate_hz",
        )
    if kw["f_number"] < 0.5:
        raise _err(source, "f_number", f"F-number {kw['f_number']} is not physical (< 0.5)", _HINTS["f_number"])

    for key, default in OPTIONAL_KEYS.items():
        kw[key] = cam.get(key, default)
    if kw["pixel_pitch_m"] is not None:
        _check_type(source, "pixel_pitch_m", kw["pixel_pitch_m"], (int, float))
        _positive(source, "pixel_pitch_m", kw["pixel_pitch_m"])
        kw["pixel_pitch_m"] = float(kw["pixel_pitch_m"])
    if kw["principal_point_px"] is not None:
        pp = kw["principal_point_px"]
        if not (isinstance(pp, (list, tuple)) and len(pp) == 2 and all(isinstance(v, (int, float)) for v in pp)):
            raise _err(source, "principal_point_px", f"expected [cx, cy], got {pp!r}")
        kw["principal_point_px"] = (float(pp[0]), float(pp[1]))
    if kw["distortion"] is not None:
        d = kw["distortion"]
        if not (isinstance(d, (list, tuple)) and len(d) in (4, 5, 8, 12, 14) and all(isinstance(v, (int, float)) for v in d)):
            raise _err(source, "distortion", f"expected 4, 5, 8, 12 or 14 OpenCV coefficients, got {d!r}")
        kw["distortion"] = tuple(float(v) for v in d)
    for key in ("exposure_range_s", "f_number_range", "focus_range_m"):
        if kw[key] is not None:
            kw[key] = _pair(source, key, kw[key])
    if kw["gain"] is not None:
        _check_type(source, "gain", kw["gain"], (int, float))
        _positive(source, "gain", kw["gain"])
    _check_type(source, "detection_threshold_dn", kw["detection_threshold_dn"], (int, float))
    _positive(source, "detection_threshold_dn", kw["detection_threshold_dn"])
    kw["detection_threshold_dn"] = float(kw["detection_threshold_dn"])
    _check_type(source, "device_id", kw["device_id"], int)
    if not 0 <= kw["device_id"] <= 255:
        raise _err(source, "device_id", f"must be 0..255, got {kw['device_id']}")

    if response_table is None:
        if kw["response"] == "linear":
            response_table = np.arange(256, dtype=np.float64)
        else:
            path = Path(kw["response"])
            if not path.is_absolute() and base_dir is not None:
                path = base_dir / path
            response_table = load_response_table(path, source=source)
    provenance = data.get("provenance", {})
    if not isinstance(provenance, dict):
        raise _err(source, None, "[provenance] must be a table")
    return CameraProfile(**kw, provenance=dict(provenance), response_table=response_table, source=source)


def load_profile(path: str | Path | None = None) -> CameraProfile:
    """Load and validate a camera profile.

    Parameters
    ----------
    path : str or Path, optional
        A TOML file, or the name of a profile shipped in
        ``calibration/profiles`` (e.g. ``"canon_xl1"``).  ``None`` gives the
        embedded default (``gauge-default``).
    """
    if path is None:
        return default_profile()
    p = Path(path)
    if not p.exists() and p.suffix == "" and "/" not in str(path):
        shipped = resources.files(PROFILE_DIR_PACKAGE) / f"{path}.toml"
        if shipped.is_file():
            with resources.as_file(shipped) as real:
                return load_profile(real)
    if not p.exists():
        raise ProfileError(
            f"camera profile {p}: file does not exist. Fix: give the path of a TOML profile, "
            f"or a shipped name ({', '.join(shipped_profiles())})"
        )
    try:
        data = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"camera profile {p}: not valid TOML ({exc}). Fix: correct the syntax") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ProfileError(f"camera profile {p}: cannot be read ({exc})") from None
    return profile_from_dict(data, source=str(p), base_dir=p.parent)


def shipped_profiles() -> list[str]:
    """Names of the profiles shipped in ``calibration/profiles``."""
    return sorted(
        entry.name[:-5]
        for entry in resources.files(PROFILE_DIR_PACKAGE).iterdir()
        if entry.name.endswith(".toml")
    )


def default_profile() -> CameraProfile:
    """The embedded default profile, ``gauge-default``."""
    return load_profile("gauge-default")


def profile_to_toml(profile: CameraProfile, *, provenance: dict | None = None,
                    response_path: str | None = None) -> str:
    """Serialise a profile to TOML text (the keys of the profile contract)."""
    import tomli_w

    cam = profile.to_dict()
    if response_path is not None:
        cam["response"] = response_path
    doc: dict[str, Any] = {"camera": cam}
    prov = provenance if provenance is not None else profile.provenance
    if prov:
        doc["provenance"] = prov
    return tomli_w.dumps(doc)


def write_profile(profile: CameraProfile, path: str | Path, *, provenance: dict | None = None,
                  response_path: str | None = None) -> Path:
    """Write a profile atomically (temporary file + rename) and return its path."""
    path = Path(path)
    text = profile_to_toml(profile, provenance=provenance, response_path=response_path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return path
