"""Radiometric response from an exposure bracket (step 2 of ``raingauge calibrate``).

The paper's photometry (Eqs. (15)-(19) [GargNayar2007]) assumes image
intensity proportional to scene radiance times exposure time: I = k L T
(Horn 1986, [Horn1986]).  Most cameras apply a non-linear response; the
paper's own camera "was calibrated to make its radiometric response linear"
(Sec. 4.4, note 23).  This step recovers the response curve from several
images of one still scene at different exposure times with OpenCV's
``CalibrateDebevec`` [Debevec1997] or ``CalibrateRobertson`` [Robertson2003],
and turns it into the profile's 256-entry linearisation table.

Exposure times of the bracket
-----------------------------
Either a sidecar file ``exposures.txt`` in the bracket folder, one line per
image: ``FILE SECONDS`` where SECONDS is a decimal (``0.004``) or a fraction
(``1/250``); lines starting with ``#`` are comments.  Or, when there is no
sidecar, the exposure time in each file name: ``<anything>_<seconds>s.<ext>``
with a decimal number of seconds (``exp_0.004s.png``, ``scene_2.5e-4s.tif``)
or a fraction written with a dash (``exp_1-250s.png`` = 1/250 s).  The
sidecar wins when both are present.

The table
---------
``table[code]`` is the linear intensity for 8-bit code ``code`` in gray-level
units, scaled so that ``table[255] = 255``, ``table[0] = 0``, monotonically
non-decreasing.  For a linear camera it is the identity.
"""

from __future__ import annotations

import dataclasses
import math
import re
from fractions import Fraction
from pathlib import Path

import numpy as np

from raingauge.errors import InputError

__all__ = [
    "RESPONSE_METHODS",
    "ResponseResult",
    "parse_exposure_name",
    "read_bracket",
    "response_curve",
    "response_table",
    "linearity",
    "calibrate_response",
    "write_table",
    "EXPOSURE_SIDECAR",
]

#: OpenCV response-curve estimators by name.
RESPONSE_METHODS = ("debevec", "robertson")
EXPOSURE_SIDECAR = "exposures.txt"
#: Codes used for the linearity figure: away from the noisy toe and the clipped shoulder.
LINEARITY_CODES = (24, 240)

_NAME_RE = re.compile(r"_(?P<num>\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)(?:-(?P<den>\d+(?:\.\d*)?))?s$")


class BracketError(InputError):
    """An exposure bracket that cannot be used for the response curve."""


@dataclasses.dataclass
class ResponseResult:
    """Outcome of the radiometric step.

    Attributes
    ----------
    table : (256,) float64
        Linearisation table [gray levels], table[0] = 0, table[255] = 255.
    method : str
        ``"debevec"`` or ``"robertson"``.
    exposures_s : list of float
        Exposure times of the bracket [s].
    linearity_rms : float
        RMS relative deviation from proportionality after correction, over
        codes in :data:`LINEARITY_CODES` [-].
    linearity_max : float
        95th percentile of the absolute relative deviation after correction [-].
    raw_linearity_rms : float
        The same RMS deviation for the uncorrected codes [-] (for comparison).
    gamma : float
        Exponent of the best power-law fit code ~ linear^(1/gamma) (1 for a
        linear camera) [-].
    n_images : int
    """

    table: np.ndarray
    method: str
    exposures_s: list[float]
    linearity_rms: float
    linearity_max: float
    raw_linearity_rms: float
    gamma: float
    n_images: int

    @property
    def is_linear(self) -> bool:
        """True when the camera is already linear (the table is within 2% of the identity)."""
        codes = np.arange(LINEARITY_CODES[0], LINEARITY_CODES[1] + 1)
        return bool(np.max(np.abs(self.table[codes] / codes - 1)) < 0.02)

    def summary(self) -> str:
        times = ", ".join(_fmt_time(t) for t in self.exposures_s)
        return "\n".join([
            f"response method   {self.method} over {self.n_images} images ({times})",
            f"response shape    code ~ linear^(1/{self.gamma:.2f})",
            f"linearity         {self.linearity_rms:.2%} RMS (95% within {self.linearity_max:.2%}) after correction; "
            f"{self.raw_linearity_rms:.1%} RMS before",
        ])

    def to_provenance(self) -> dict:
        return {
            "calibrated": True,
            "method": self.method,
            "exposures_s": [float(t) for t in self.exposures_s],
            "linearity_rms": round(self.linearity_rms, 5),
            "linearity_p95": round(self.linearity_max, 5),
            "raw_linearity_rms": round(self.raw_linearity_rms, 5),
            "gamma": round(self.gamma, 4),
        }


def _fmt_time(t: float) -> str:
    if t < 1 and abs(1 / t - round(1 / t)) < 1e-4 * (1 / t):
        return f"1/{round(1 / t)} s"
    return f"{t:g} s"


# ------------------------------------------------------------------------ input
def _parse_seconds(text: str) -> float | None:
    text = text.strip()
    try:
        value = float(Fraction(text)) if "/" in text else float(text)
    except (ValueError, ZeroDivisionError):
        return None
    return value if math.isfinite(value) and value > 0 else None


def parse_exposure_name(name: str) -> float | None:
    """Exposure time [s] from a file name ``..._<seconds>s.<ext>`` or ``..._<a>-<b>s.<ext>`` (a/b s).

    Returns None when the name carries no exposure time.
    """
    stem = Path(name).stem
    m = _NAME_RE.search(stem)
    if not m:
        return None
    num = float(m.group("num"))
    den = float(m.group("den")) if m.group("den") else 1.0
    if den == 0:
        return None
    value = num / den
    return value if math.isfinite(value) and value > 0 else None


def _read_sidecar(folder: Path) -> dict[str, float]:
    path = folder / EXPOSURE_SIDECAR
    out: dict[str, float] = {}
    for i, line in enumerate(path.read_text().splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").replace("\t", " ").split()
        if len(parts) != 2 or _parse_seconds(parts[1]) is None:
            raise BracketError(
                f"{path}, line {i}: expected 'FILE SECONDS' (e.g. 'img1.png 1/250'), got {line!r}. "
                "Fix: one image and its exposure time per line"
            )
        out[parts[0]] = _parse_seconds(parts[1])
    return out


def read_bracket(folder: str | Path) -> tuple[list[np.ndarray], np.ndarray, list[str]]:
    """Read an exposure bracket: images, exposure times [s] and file names.

    Exposure times come from ``exposures.txt`` in the folder or from the file
    names (see the module docstring).  Images are returned as (M, N, 3) BGR
    uint8 (gray images are replicated), sorted by exposure time.

    Raises
    ------
    BracketError
        Missing folder, unreadable image, missing exposure time, images of
        different sizes, fewer than 3 distinct exposures or a span under 2 stops.
    """
    import cv2

    from raingauge.videoio import IMAGE_SUFFIXES

    folder = Path(folder)
    if not folder.is_dir():
        raise BracketError(f"exposure bracket {folder}: not a folder. Fix: give the folder holding the bracket images")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith("."))
    if not files:
        raise BracketError(f"exposure bracket {folder}: no images ({', '.join(IMAGE_SUFFIXES)}). "
                           "Fix: put the images of the still scene at several exposure times there")
    sidecar = _read_sidecar(folder) if (folder / EXPOSURE_SIDECAR).is_file() else None
    images, times, names = [], [], []
    for p in files:
        if sidecar is not None:
            if p.name not in sidecar:
                raise BracketError(f"exposure bracket {folder}: {p.name} is not listed in {EXPOSURE_SIDECAR}. "
                                   f"Fix: add a line '{p.name} SECONDS' or remove the image")
            t = sidecar[p.name]
        else:
            t = parse_exposure_name(p.name)
            if t is None:
                raise BracketError(
                    f"exposure bracket {folder}: no exposure time in the file name {p.name}. Fix: name the images "
                    f"like exp_0.004s.png or exp_1-250s.png (1/250 s), or list them in {EXPOSURE_SIDECAR} "
                    "as 'FILE SECONDS' lines"
                )
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if img is None or img.size == 0:
            raise BracketError(f"exposure bracket image {p}: cannot be read. Fix: re-export it as PNG")
        if img.dtype != np.uint8:
            raise BracketError(f"exposure bracket image {p}: {img.dtype} samples; the linearisation table maps "
                               "8-bit codes. Fix: save the bracket as 8-bit images as the camera delivers them")
        if img.ndim == 2:
            img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        elif img.shape[2] == 4:
            img = img[:, :, :3]
        images.append(np.ascontiguousarray(img))
        times.append(t)
        names.append(p.name)
    if len({im.shape for im in images}) > 1:
        raise BracketError(f"exposure bracket {folder}: images of different sizes. Fix: keep the camera mode fixed")
    distinct = sorted(set(times))
    if len(distinct) < 3:
        which = ", ".join(_fmt_time(t) for t in distinct)
        raise BracketError(
            f"exposure bracket {folder}: {len(images)} image(s) at {len(distinct)} exposure time(s) ({which}); "
            "the response curve needs at least 3 different exposures. Fix: photograph the same still scene "
            "at 5 or more exposure times one stop apart (e.g. 1/1000 to 1/60 s), camera on a tripod"
        )
    if distinct[-1] / distinct[0] < 4.0:
        raise BracketError(
            f"exposure bracket {folder}: exposures span only {distinct[-1] / distinct[0]:.2f}x "
            f"({_fmt_time(distinct[0])} to {_fmt_time(distinct[-1])}); at least 4x (2 stops) is needed. "
            "Fix: widen the bracket, e.g. 1/1000 to 1/60 s"
        )
    order = np.argsort(times, kind="stable")
    return [images[i] for i in order], np.array([times[i] for i in order]), [names[i] for i in order]


# ----------------------------------------------------------------- estimation
def response_curve(images: list[np.ndarray], exposures_s: np.ndarray, *, method: str = "debevec",
                   samples: int = 200, smoothness: float = 10.0) -> np.ndarray:
    """Camera response, linear exposure per code, from OpenCV [Debevec1997] / [Robertson2003].

    Parameters
    ----------
    images : list of (M, N, 3) uint8
        The bracket (same still scene).
    exposures_s : (K,) float
        Exposure times [s].
    method : {"debevec", "robertson"}
    samples : int
        Debevec: number of pixel locations sampled.
    smoothness : float
        Debevec: weight of the smoothness term (lambda).

    Returns
    -------
    (256,) float64 relative exposure per code (arbitrary scale, NaN where a
    code never occurs for Robertson).
    """
    import cv2

    if method not in RESPONSE_METHODS:
        raise ValueError(f"unknown response method {method!r}; valid: {', '.join(RESPONSE_METHODS)}")
    times = np.asarray(exposures_s, dtype=np.float32).copy()
    if method == "debevec":
        cal = cv2.createCalibrateDebevec(samples=int(samples), lambda_=float(smoothness), random=False)
    else:
        cal = cv2.createCalibrateRobertson(max_iter=60, threshold=1e-4)
    resp = cal.process([np.ascontiguousarray(im) for im in images], times)
    resp = np.asarray(resp, dtype=np.float64).reshape(256, -1)
    # Gray bracket: the channels are the same; colour: the gray response is their mean.
    import warnings

    with warnings.catch_warnings(), np.errstate(invalid="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(np.where(resp > 0, resp, np.nan), axis=1)


def response_table(curve: np.ndarray) -> np.ndarray:
    """Turn a relative response curve into the profile's linearisation table.

    Missing codes are interpolated (extrapolated towards 0 at the dark end),
    the curve is made monotonic, scaled to table[255] = 255 and pinned at
    table[0] = 0.

    Parameters
    ----------
    curve : (256,) float
        Relative linear exposure per code (NaN allowed).

    Returns
    -------
    (256,) float64 [gray levels]
    """
    curve = np.asarray(curve, dtype=np.float64).copy()
    codes = np.arange(256.0)
    ok = np.isfinite(curve) & (curve > 0)
    if ok.sum() < 16:
        raise BracketError("the response curve is defined for fewer than 16 codes. Fix: use a scene with a wide "
                           "range of brightness and a bracket spanning at least 4 stops")
    first = int(np.argmax(ok))
    curve = np.interp(codes, codes[ok], curve[ok])
    if first > 0:
        # Extrapolate the dark end linearly towards zero at code 0.
        curve[:first] = curve[first] * codes[:first] / first
    curve = np.maximum.accumulate(curve)
    table = curve / curve[255] * 255.0
    table[0] = 0.0
    return np.maximum.accumulate(table)


def linearity(images: list[np.ndarray], exposures_s: np.ndarray, table: np.ndarray,
              *, codes: tuple[int, int] = LINEARITY_CODES) -> tuple[float, float]:
    """How proportional to exposure time the linearised bracket is.

    For every pixel the radiance is estimated as the median of
    ``table[code] / t`` over its well-exposed images; the deviation of each
    well-exposed sample from ``radiance * t`` is relative.

    Parameters
    ----------
    images : list of (M, N) or (M, N, 3) uint8
    exposures_s : (K,) float [s]
    table : (256,) float [gray levels]
    codes : (lo, hi)
        Codes counted as well exposed.

    Returns
    -------
    (rms, p95) : RMS and 95th percentile of the absolute relative deviation [-].
    """
    table = np.asarray(table, dtype=np.float64)
    stack = np.stack([im[..., 1] if im.ndim == 3 else im for im in images]).astype(np.intp)
    stack = stack.reshape(len(images), -1)
    t = np.asarray(exposures_s, dtype=np.float64)[:, None]
    good = (stack >= codes[0]) & (stack <= codes[1])
    use = good.sum(axis=0) >= 2
    if not np.any(use):
        raise BracketError("no pixel is well exposed in two images of the bracket. Fix: use a bracket with "
                           "exposures one stop apart over a scene of moderate contrast")
    lin = table[stack[:, use]] / t
    g = good[:, use]
    radiance = np.nanmedian(np.where(g, lin, np.nan), axis=0)
    dev = (lin / radiance - 1.0)[g]
    return float(np.sqrt(np.mean(dev ** 2))), float(np.percentile(np.abs(dev), 95))


def _gamma_fit(table: np.ndarray) -> float:
    codes = np.arange(LINEARITY_CODES[0], LINEARITY_CODES[1] + 1, dtype=np.float64)
    x = np.log(table[codes.astype(int)] / 255.0)
    y = np.log(codes / 255.0)
    slope = float(np.sum(x * y) / np.sum(x * x))  # log code = slope * log linear
    return 1.0 / slope if slope > 0 else float("nan")


def calibrate_response(images: list[np.ndarray], exposures_s, *, method: str = "debevec") -> ResponseResult:
    """Response curve -> linearisation table -> linearity report.

    Parameters
    ----------
    images : list of (M, N, 3) uint8
    exposures_s : (K,) float [s]
    method : {"debevec", "robertson"}
    """
    exposures_s = np.asarray(exposures_s, dtype=np.float64)
    curve = response_curve(images, exposures_s, method=method)
    table = response_table(curve)
    rms, p95 = linearity(images, exposures_s, table)
    raw_rms, _ = linearity(images, exposures_s, np.arange(256.0))
    return ResponseResult(
        table=table,
        method=method,
        exposures_s=[float(t) for t in exposures_s],
        linearity_rms=rms,
        linearity_max=p95,
        raw_linearity_rms=raw_rms,
        gamma=_gamma_fit(table),
        n_images=len(images),
    )


def write_table(path: str | Path, table: np.ndarray) -> Path:
    """Write a linearisation table as text, one value per line (code 0 first), as the profile reads it."""
    path = Path(path)
    table = np.asarray(table, dtype=np.float64).ravel()
    if table.size != 256:
        raise ValueError(f"a linearisation table has 256 entries, got {table.size}")
    lines = [f"{v:.6f}" for v in table]
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(path)
    return path
