"""Calibrate a camera into a rain-gauge profile: geometry, response, noise, focus plan, dry run.

Steps (each may be skipped; a skipped step keeps the values of --base and is
marked "not calibrated" in the profile's [provenance]):

  1. geometry   checkerboard views (a folder of images, a video, or camera:N)
                -> focal length [px], principal point, distortion, RMS error
  2. response   an exposure bracket of a still scene -> response curve
                (OpenCV Debevec or Robertson) -> 256-entry linearisation table
  3. noise      frames of a still scene -> noise sigma against intensity
                -> the detection threshold c of Eq. (19)
  4. focus      focal length, pixel pitch and the lens's F-numbers -> focus
                distance z0 <= 2 f a_min, aperture, sample volume (Sec. 8)
  5. dry run    some seconds without rain -> false detections per minute,
                warning when the scene moves
  6. write      OUT.toml, plus OUT.response.txt beside it when the camera is
                not linear (referenced by a relative path)

Without step options, in a terminal, the wizard asks for each step
(defaults in brackets) and keeps its progress in OUT.toml.state.json so an
interrupted calibration resumes where it stopped.  With options it runs
without questions, e.g.

  raingauge calibrate --checkerboard views/ --pattern 9x6 --square-m 0.025 \\
      --bracket bracket/ --still still/ --dry dry.mkv --out camera.toml

Exposure bracket: the exposure time of each image is read from a sidecar
file exposures.txt in the bracket folder ("FILE SECONDS" per line, seconds as
0.004 or 1/250), or else from the file names: exp_0.004s.png, exp_1-250s.png
(= 1/250 s).  --demo renders synthetic captures with a known camera and
calibrates from them.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import sys
import tempfile
from pathlib import Path

STEPS = ("geometry", "response", "noise", "focus", "dry_run")
STEP_TITLES = {
    "geometry": "geometry (checkerboard)",
    "response": "radiometric response (exposure bracket)",
    "noise": "noise and detection threshold (still scene)",
    "focus": "lens and focus plan",
    "dry_run": "dry run (no rain)",
}
#: Camera-profile keys each step sets.
STEP_KEYS = {
    "geometry": ("focal_length_px", "principal_point_px", "distortion", "width_px", "height_px"),
    "response": ("response",),
    "noise": ("noise_sigma_dn", "detection_threshold_dn"),
    "focus": ("focus_distance_m", "f_number", "pixel_pitch_m"),
    "dry_run": (),
}
#: Most frames read for the noise step and the dry run (30 s at 30 frames/s).
MAX_STILL_FRAMES = 300
MAX_DRY_FRAMES = 900


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", metavar="PROFILE.toml", help="profile to write (asked for when interactive)")
    parser.add_argument("--base", metavar="PROFILE", default="gauge-default",
                        help="profile whose values the steps not run keep (file or shipped name; default gauge-default)")
    parser.add_argument("--name", help="name of the new profile (default: the output file's stem)")
    g = parser.add_argument_group("1. geometry")
    g.add_argument("--checkerboard", metavar="SRC", help="folder of checkerboard images, a video file, or camera:N")
    g.add_argument("--pattern", metavar="COLSxROWS", default="9x6",
                   help="inner corners per row and column (default 9x6, i.e. a board of 10x7 squares)")
    g.add_argument("--square-m", type=float, metavar="SIZE", help="side of one square [m], e.g. 0.025")
    g.add_argument("--distortion-model", default="k1k2p1p2",
                   choices=("k1k2p1p2", "k1k2k3p1p2", "rational", "none"), help="distortion coefficients to fit")
    g.add_argument("--views", type=int, default=10, help="views to collect from a live camera (default 10)")
    g.add_argument("--max-rms-px", type=float, default=1.0, help="largest accepted RMS reprojection error [px]")
    r = parser.add_argument_group("2. radiometric response")
    r.add_argument("--bracket", metavar="DIR", help="folder with the exposure bracket (see above for exposure times)")
    r.add_argument("--response-method", default="debevec", choices=("debevec", "robertson"),
                   help="OpenCV response estimator (default debevec)")
    n = parser.add_argument_group("3. noise")
    n.add_argument("--still", metavar="SRC", help="folder, video or camera:N of a still scene without rain")
    n.add_argument("--false-rate", type=float, default=1e-3,
                   help="false Eq. (19) candidates per pixel and frame the threshold c allows (default 1e-3)")
    f = parser.add_argument_group("4. focus plan")
    f.add_argument("--pixel-pitch-m", type=float, metavar="P", help="pixel pitch [m] (default: from --base)")
    f.add_argument("--f-numbers", metavar="LIST",
                   help="F-numbers the lens offers, comma separated (default: the stops in the base's f_number_range)")
    f.add_argument("--a-min-m", type=float, default=0.5e-3,
                   help="radius of the smallest drop to resolve [m] (default 0.5e-3, Sec. 8)")
    f.add_argument("--focus-m", type=float, help="focus distance actually set on the lens [m] (default: the plan's)")
    f.add_argument("--f-number", type=float, help="F-number actually set on the lens (default: the plan's)")
    f.add_argument("--no-focus-plan", action="store_true", help="keep focus distance and F-number of --base")
    d = parser.add_argument_group("5. dry run")
    d.add_argument("--dry", metavar="SRC", help="folder, video or camera:N of some seconds without rain")
    m = parser.add_argument_group("mode")
    m.add_argument("--interactive", action="store_true", help="ask for every step even when options are given")
    m.add_argument("--restart", action="store_true", help="ignore a saved interactive session and start again")
    m.add_argument("--demo", action="store_true",
                   help="render synthetic captures of a known camera and calibrate from them")
    m.add_argument("--demo-dir", metavar="DIR", help="keep the demo captures in DIR (default: a temporary folder)")


# ------------------------------------------------------------------- helpers
def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat().replace("+00:00", "Z")


def _jsonable(value):
    """Plain JSON/TOML values: tuples -> lists, numpy scalars -> float/int, no None/NaN."""
    import numpy as np

    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [_jsonable(v) for v in value.tolist()]
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else str(v)
    return value


class _GrayFrames:
    """Gray uint8 frames from a folder, a video or camera:N, read one at a time.

    Iterating checks, at the end, that no image was unreadable and that all
    frames share one size.  ``fps`` is the source's frame rate when it has one.
    """

    def __init__(self, src: str, *, limit: int, what: str):
        from raingauge.errors import SourceError
        from calibration.frames import camera_device, is_camera
        from raingauge.videoio import FrameReader

        self.src, self.limit, self.what = str(src), int(limit), what
        self.fps = None
        self.shape = None
        self._reader = None
        if is_camera(self.src):
            import cv2

            self._device = camera_device(self.src)
            cap = cv2.VideoCapture(self._device)
            ok = cap.isOpened()
            if ok:
                self.fps = float(cap.get(cv2.CAP_PROP_FPS)) or None
            cap.release()
            if not ok:
                raise SourceError(f"{what}: camera {self.src} cannot be opened. Fix: check the camera, or give a folder")
        else:
            self._reader = FrameReader(self.src, mode="gray")
            self.fps = self._reader.fps

    def _raw(self):
        if self._reader is not None:
            yield from self._reader
            return
        import cv2

        cap = cv2.VideoCapture(self._device)
        try:
            while True:
                ok, img = cap.read()
                if not ok:
                    break
                yield cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
        finally:
            cap.release()

    def __iter__(self):
        from raingauge.errors import InputError

        shape = None
        n = 0
        for frame in self._raw():
            if shape is None:
                shape = self.shape = frame.shape
            elif frame.shape != shape:
                raise InputError(f"{self.what} {self.src}: frames of different sizes. Fix: keep the camera mode fixed")
            yield frame
            n += 1
            if n >= self.limit:
                break
        if self._reader is not None and self._reader.corrupt_frames:
            raise InputError(f"{self.what} {self.src}: {self._reader.corrupt_frames} image(s) cannot be read. "
                             "Fix: delete or re-export the damaged files")
        if n == 0:
            raise InputError(f"{self.what} {self.src}: no frame could be read. Fix: check the files or the camera")


def _parse_f_numbers(text: str) -> list[float]:
    from raingauge.errors import InputError

    try:
        values = [float(v) for v in str(text).replace(";", ",").replace(" ", ",").split(",") if v.strip()]
    except ValueError:
        values = []
    if not values or any(not (v >= 0.5 and math.isfinite(v)) for v in values):
        raise InputError(f"F-numbers {text!r}: expected numbers >= 0.5 separated by commas. Fix: e.g. 1.4,2,2.8,4")
    return sorted(values)


# ------------------------------------------------------------------- session
class Session:
    """The state of one calibration: the base profile and the results of the steps run.

    ``results[step]`` holds ``camera`` (profile keys the step sets),
    ``provenance`` (what goes under [provenance.STEP]), ``summary`` (text) and,
    for the response step, ``table`` (256 floats, or absent for a linear camera).
    Everything is plain JSON so the interactive wizard can save and resume it.
    """

    def __init__(self, base: str = "gauge-default"):
        from raingauge.profile import load_profile

        self.base_name = str(base)
        self.base = load_profile(base)
        self.results: dict[str, dict] = {}
        self.answers: dict[str, object] = {}

    # -- state
    def to_json(self) -> dict:
        return {"base": self.base_name, "results": self.results, "answers": self.answers, "saved": _now()}

    @classmethod
    def from_json(cls, data: dict) -> "Session":
        s = cls(data.get("base", "gauge-default"))
        s.results = {k: v for k, v in data.get("results", {}).items() if k in STEPS}
        s.answers = dict(data.get("answers", {}))
        return s

    # -- current values
    def value(self, key: str):
        """A profile value as the steps so far leave it."""
        for step in STEPS:
            cam = self.results.get(step, {}).get("camera", {})
            if key in cam:
                return cam[key]
        v = getattr(self.base, key)
        return list(v) if isinstance(v, tuple) else v

    def table(self):
        """The linearisation table in force: the measured one, or the base's."""
        import numpy as np

        res = self.results.get("response")
        if res is not None:
            return np.asarray(res["table"]) if res.get("table") is not None else np.arange(256.0)
        return np.asarray(self.base.response_table, dtype=np.float64)

    def _size_warning(self, shape, what: str) -> str:
        """A summary line when frames do not have the profile's image size (empty otherwise)."""
        if shape is None:
            return ""
        w, h = int(self.value("width_px")), int(self.value("height_px"))
        if (shape[1], shape[0]) == (w, h):
            return ""
        return (f"\nwarning: the {what} are {shape[1]}x{shape[0]} but the profile's camera is {w}x{h}: "
                "record every step in the camera mode the gauge runs in")

    # -- steps
    def run_geometry(self, source: str, *, pattern: str, square_m: float | None, distortion_model="k1k2p1p2",
                     views: int = 10, max_rms_px: float = 1.0) -> dict:
        from calibration import geometry
        from calibration.frames import is_camera
        from raingauge.errors import InputError

        if square_m is None:
            raise InputError("geometry: the size of a checkerboard square is needed. Fix: measure one square "
                             "and give it in metres, e.g. --square-m 0.025")
        if is_camera(source):
            print(f"move the board through the view: {views} different positions and tilts are collected")

        def progress(count, total):
            print(f"  view {count}/{total}", flush=True)

        res = geometry.calibrate_geometry(source, pattern, square_m, n_live_views=views, on_view=progress,
                                          distortion_model=distortion_model, max_rms_px=max_rms_px)
        prov = res.to_provenance()
        prov.update(source=str(source), pattern=str(pattern), square_m=float(square_m))
        self.results["geometry"] = _jsonable({
            "camera": {
                "focal_length_px": res.focal_length_px,
                "principal_point_px": list(res.principal_point_px),
                "distortion": list(res.distortion),
                "width_px": res.image_size[0],
                "height_px": res.image_size[1],
            },
            "provenance": prov,
            "residual": {"geometry_rms_px": res.rms_px},
            "summary": res.summary(),
        })
        return self.results["geometry"]

    def run_response(self, folder: str, *, method: str = "debevec") -> dict:
        from calibration import radiometry

        images, times, _names = radiometry.read_bracket(folder)
        res = radiometry.calibrate_response(images, times, method=method)
        prov = res.to_provenance()
        prov["source"] = str(folder)
        linear = res.is_linear
        prov["written_as"] = "linear" if linear else "table"
        summary = res.summary()
        if linear:
            summary += "\nthe camera is linear within 2%: the profile says response = \"linear\""
        self.results["response"] = _jsonable({
            "camera": {"response": "linear" if linear else "table"},
            "table": None if linear else res.table,
            "provenance": prov,
            "residual": {"response_linearity_rms": res.linearity_rms},
            "summary": summary,
        })
        return self.results["response"]

    def run_noise(self, source: str, *, false_rate: float = 1e-3) -> dict:
        from calibration import noise

        frames = _GrayFrames(source, limit=MAX_STILL_FRAMES, what="still scene")
        res = noise.calibrate_noise(iter(frames), table=self.table(), false_rate=false_rate)
        prov = res.to_provenance()
        prov["source"] = str(source)
        summary = res.summary() + self._size_warning(frames.shape, "still frames")
        self.results["noise"] = _jsonable({
            "camera": {"noise_sigma_dn": res.noise_sigma_dn, "detection_threshold_dn": res.c_dn},
            "provenance": prov,
            "residual": {"noise_sigma_dn": res.noise_sigma_dn},
            "summary": summary,
        })
        return self.results["noise"]

    def current_profile(self):
        """The base profile with the camera values measured so far (the response table aside)."""
        changes = {}
        for step in STEPS:
            for key, value in self.results.get(step, {}).get("camera", {}).items():
                if key != "response":
                    changes[key] = value
        return self.base.replace(**changes) if changes else self.base

    def default_f_numbers(self) -> list[float]:
        from calibration import focus_plan

        rng = self.value("f_number_range")
        return focus_plan.standard_f_numbers(*rng) if rng else [float(self.value("f_number"))]

    def plan(self, *, pixel_pitch_m: float | None, f_numbers: list[float] | None, a_min_m: float):
        from calibration import focus_plan
        from raingauge.errors import InputError

        pitch = pixel_pitch_m if pixel_pitch_m is not None else self.value("pixel_pitch_m")
        if pitch is None:
            raise InputError("focus plan: the pixel pitch is unknown (not in the base profile). "
                             "Fix: give it from the sensor's data sheet, e.g. --pixel-pitch-m 3.45e-6")
        if f_numbers is None:
            f_numbers = self.default_f_numbers()
        plan = focus_plan.plan_focus(self.current_profile(), f_numbers=list(f_numbers),
                                     pixel_pitch_m=float(pitch), a_min_m=a_min_m)
        return plan, float(pitch), list(f_numbers)

    def run_focus(self, *, pixel_pitch_m=None, f_numbers=None, a_min_m=0.5e-3, focus_m=None, f_number=None) -> dict:
        from raingauge.errors import InputError

        plan, pitch, f_numbers = self.plan(pixel_pitch_m=pixel_pitch_m, f_numbers=f_numbers, a_min_m=a_min_m)
        z0 = plan.focus_distance_m if focus_m is None else float(focus_m)
        n = plan.f_number if f_number is None else float(f_number)
        for name, v in (("focus distance", z0), ("F-number", n)):
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"focus plan: {name} {v!r} must be positive")
        prov = plan.to_provenance()
        prov.update(f_numbers=f_numbers, pixel_pitch_m=pitch, set_focus_distance_m=z0, set_f_number=n)
        summary = plan.summary()
        if z0 > plan.z_max_m * (1 + 1e-9):
            summary += (f"\nwarning: the lens is focused at {z0:g} m, beyond 2 f a_min = {plan.z_max_m:.3f} m: "
                        "the smallest drops are under a pixel wide in focus")
            prov.setdefault("notes", []).append("focus set beyond 2 f a_min")
        if focus_m is not None or f_number is not None:
            summary += f"\nset on the lens: z0 = {z0:g} m, F/{n:g}"
        self.results["focus"] = _jsonable({
            "camera": {"focus_distance_m": z0, "f_number": n, "pixel_pitch_m": pitch},
            "provenance": prov,
            "residual": {"sample_volume_m3": plan.sample_volume_m3},
            "summary": summary,
        })
        return self.results["focus"]

    def run_dry(self, source: str) -> dict:
        from calibration import dryrun

        frames = _GrayFrames(source, limit=MAX_DRY_FRAMES, what="dry-run video")
        rate = frames.fps or float(self.value("frame_rate_hz"))
        res = dryrun.dry_run(iter(frames), frame_rate_hz=rate, exposure_s=float(self.value("exposure_s")),
                             c_dn=float(self.value("detection_threshold_dn")),
                             noise_sigma_dn=float(self.value("noise_sigma_dn")), table=self.table())
        prov = res.to_provenance()
        prov.update(source=str(source), frame_rate_hz=rate)
        summary = res.summary() + self._size_warning(frames.shape, "dry-run frames")
        self.results["dry_run"] = _jsonable({
            "camera": {},
            "provenance": prov,
            "residual": {"dry_run_false_per_min": res.false_per_minute},
            "summary": summary,
        })
        return self.results["dry_run"]

    # -- output
    def build(self, out: Path, name: str | None = None):
        """The new profile, its provenance, and the table to write (or None)."""
        import numpy as np

        from raingauge import __version__
        from raingauge.profile import profile_from_dict

        cam = self.base.to_dict()
        cam["name"] = name or out.stem
        table = None
        table_name = None
        for step in STEPS:
            res = self.results.get(step)
            if res is None:
                continue
            for key, value in res["camera"].items():
                cam[key] = value
        if "response" in self.results:
            if self.results["response"].get("table") is not None:
                table = np.asarray(self.results["response"]["table"], dtype=np.float64)
                table_name = out.stem + ".response.txt"
                cam["response"] = table_name
            else:
                cam["response"] = "linear"
        elif not self.base.is_linear:
            # Keep the base's table: copy it beside the new profile.
            table = np.asarray(self.base.response_table, dtype=np.float64)
            table_name = out.stem + ".response.txt"
            cam["response"] = table_name
        done = [s for s in STEPS if s in self.results]
        prov: dict = {
            "date": _now(),
            "tool": f"raingauge calibrate {__version__}",
            "base": self.base.name,
            "steps_done": done,
            "steps_not_calibrated": [s for s in STEPS if s not in self.results],
        }
        residuals = {}
        for step in STEPS:
            res = self.results.get(step)
            if res is None:
                keys = [k for k in STEP_KEYS[step]]
                prov[step] = {"calibrated": False, "kept_from": self.base.name, "keys": keys}
            else:
                prov[step] = res["provenance"]
                residuals.update(res.get("residual", {}))
        prov["residuals"] = residuals
        prov = _jsonable(prov)
        profile = profile_from_dict({"camera": cam, "provenance": prov}, source=str(out),
                                    response_table=table if table is not None else np.arange(256.0))
        return profile, prov, table, table_name

    def write(self, out: Path, name: str | None = None) -> list[Path]:
        """Write the profile (and its table) atomically; returns the files written."""
        from calibration.radiometry import write_table
        from raingauge.profile import load_profile, write_profile

        out = Path(out)
        _check_out_dir(out)
        profile, prov, table, table_name = self.build(out, name)
        written = []
        if table is not None:
            written.append(write_table(out.parent / table_name, table))
        written.append(write_profile(profile, out, provenance=prov))
        load_profile(out)  # the written file must load back
        return written


# ----------------------------------------------------------------- non-interactive
def _steps_requested(args) -> bool:
    return any(getattr(args, k) for k in ("checkerboard", "bracket", "still", "dry"))


def run_batch(args, out: Path) -> Session:
    session = Session(args.base)
    f_numbers = _parse_f_numbers(args.f_numbers) if args.f_numbers else None
    if args.checkerboard:
        _report("geometry", session.run_geometry(
            args.checkerboard, pattern=args.pattern, square_m=args.square_m,
            distortion_model=args.distortion_model, views=args.views, max_rms_px=args.max_rms_px))
    if args.bracket:
        _report("response", session.run_response(args.bracket, method=args.response_method))
    if args.still:
        _report("noise", session.run_noise(args.still, false_rate=args.false_rate))
    focus_asked = any(v is not None for v in (args.pixel_pitch_m, args.f_numbers, args.focus_m, args.f_number))
    if not args.no_focus_plan and (args.checkerboard or focus_asked):
        if not focus_asked and session.value("pixel_pitch_m") is None:
            print("== focus plan skipped: the pixel pitch is unknown (give --pixel-pitch-m)")
        else:
            _report("focus", session.run_focus(pixel_pitch_m=args.pixel_pitch_m, f_numbers=f_numbers,
                                               a_min_m=args.a_min_m, focus_m=args.focus_m, f_number=args.f_number))
    if args.dry:
        _report("dry_run", session.run_dry(args.dry))
    return session


def _report(step: str, result: dict) -> None:
    print(f"== {STEP_TITLES[step]}")
    print(result["summary"])
    sys.stdout.flush()


# ------------------------------------------------------------------- interactive
class _Prompter:
    """Questions on stdout, answers from stdin (a terminal, or a script driving one)."""

    def ask(self, question: str, default=None) -> str:
        suffix = f" [{default}]" if default not in (None, "") else ""
        sys.stdout.write(f"{question}{suffix}: ")
        sys.stdout.flush()
        line = sys.stdin.readline()
        if not line:
            raise EOFError
        answer = line.strip()
        return answer if answer else ("" if default is None else str(default))

    def yes(self, question: str, default: bool = True) -> bool:
        while True:
            a = self.ask(question + (" [Y/n]" if default else " [y/N]"), None).lower()
            if a == "":
                return default
            if a in ("y", "yes"):
                return True
            if a in ("n", "no"):
                return False
            print("please answer y or n")

    def number(self, question: str, default) -> float:
        while True:
            a = self.ask(question, default)
            try:
                v = float(a)
            except ValueError:
                print(f"{a!r} is not a number")
                continue
            if math.isfinite(v) and v > 0:
                return v
            print("a positive number, please")


def _save_state(path: Path, session: Session) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(session.to_json(), indent=1))
    tmp.replace(path)


def run_interactive(args, out: Path | None) -> int:
    from raingauge.errors import RaingaugeError

    p = _Prompter()
    print("raingauge calibrate: turn this camera into a rain gauge. Press Enter to accept [defaults]; "
          "leave a source empty to skip a step.")
    if out is None:
        out = Path(p.ask("Profile to write", "camera.toml"))
    _check_out_dir(out)
    state_path = out.with_name(out.name + ".state.json")
    session = None
    if state_path.exists() and not args.restart:
        try:
            data = json.loads(state_path.read_text())
            saved = Session.from_json(data)
        except (ValueError, OSError, RaingaugeError) as exc:
            print(f"the saved session {state_path} cannot be used ({exc}); starting again")
        else:
            done = ", ".join(saved.results) or "none"
            if p.yes(f"Resume the calibration saved in {state_path.name} (steps done: {done})?", True):
                session = saved
    if session is None:
        while True:
            base = p.ask("Base profile (values for the steps you skip)", args.base)
            try:
                session = Session(base)
                break
            except RaingaugeError as exc:
                print(f"error: {exc}")
    a = session.answers
    shown: set[str] = set()

    def remember(key, value):
        a[key] = value
        return value

    def step(name: str, number: int, body) -> None:
        print(f"\n-- step {number}/6: {STEP_TITLES[name]}")
        if name in session.results:
            first = session.results[name]["summary"].splitlines()[0]
            if not p.yes(f"already done ({first.strip()}). Redo it?", False):
                return
        while True:
            try:
                result = body()
            except RaingaugeError as exc:
                print(f"error: {exc}")
                if p.yes("Try this step again?", True):
                    continue
                print(f"{name}: skipped, keeping the values of {session.base.name}")
                return
            if result is None:
                if name in session.results:
                    print(f"{name}: keeping the earlier result")
                else:
                    print(f"{name}: skipped, keeping the values of {session.base.name}")
                return
            summary = result["summary"]
            if name in shown:
                # The plan was shown before the questions: only what changed since.
                summary = "\n".join(line for line in summary.splitlines()
                                     if line.startswith(("set on the lens", "warning")))
            if summary:
                print(summary)
            if p.yes("Accept this result?", True):
                _save_state(state_path, session)
                return
            session.results.pop(name, None)
            if not p.yes("Try this step again?", True):
                return

    def geometry():
        src = p.ask("Checkerboard views: folder of images, video file or camera:N (empty: skip)",
                    a.get("checkerboard", args.checkerboard or ""))
        if not src:
            return None
        remember("checkerboard", src)
        pattern = remember("pattern", p.ask("Inner corners COLSxROWS", a.get("pattern", args.pattern)))
        square = remember("square_m", p.number("Square size [m]", a.get("square_m", args.square_m or 0.025)))
        return session.run_geometry(src, pattern=pattern, square_m=square,
                                    distortion_model=args.distortion_model, views=args.views,
                                    max_rms_px=args.max_rms_px)

    def response():
        src = p.ask("Exposure bracket folder (exposure in the file names or exposures.txt; empty: skip)",
                    a.get("bracket", args.bracket or ""))
        if not src:
            return None
        remember("bracket", src)
        method = remember("response_method", p.ask("Method, debevec or robertson",
                                                   a.get("response_method", args.response_method)))
        if method not in ("debevec", "robertson"):
            from raingauge.errors import InputError

            raise InputError(f"unknown method {method!r}; choose debevec or robertson")
        return session.run_response(src, method=method)

    def noise():
        src = p.ask("Still scene: folder, video or camera:N without rain (empty: skip)",
                    a.get("still", args.still or ""))
        if not src:
            return None
        remember("still", src)
        return session.run_noise(src, false_rate=args.false_rate)

    def focus():
        if not p.yes("Plan the focus distance and aperture?", not args.no_focus_plan):
            return None
        default_pitch = args.pixel_pitch_m or session.value("pixel_pitch_m") or 5e-6
        pitch = remember("pixel_pitch_m", p.number("Pixel pitch [m]", a.get("pixel_pitch_m", default_pitch)))
        default_fn = args.f_numbers or ",".join(f"{v:g}" for v in session.default_f_numbers())
        fns = _parse_f_numbers(remember("f_numbers", p.ask("F-numbers of the lens", a.get("f_numbers", default_fn))))
        a_min = remember("a_min_m", p.number("Radius of the smallest drop [m]", a.get("a_min_m", args.a_min_m)))
        plan, _pitch, _fns = session.plan(pixel_pitch_m=pitch, f_numbers=fns, a_min_m=a_min)
        print(plan.summary())
        shown.add("focus")
        z0 = p.number("Focus distance you set on the lens [m]", f"{plan.focus_distance_m:.4g}")
        n = p.number("F-number you set on the lens", f"{plan.f_number:g}")
        return session.run_focus(pixel_pitch_m=pitch, f_numbers=fns, a_min_m=a_min,
                                 focus_m=z0 if abs(z0 - plan.focus_distance_m) > 5e-4 * plan.focus_distance_m else None,
                                 f_number=n if n != plan.f_number else None)

    def dry():
        src = p.ask("Dry run: folder, video or camera:N of some seconds without rain (empty: skip)",
                    a.get("dry", args.dry or ""))
        if not src:
            return None
        remember("dry", src)
        return session.run_dry(src)

    try:
        for i, (name, body) in enumerate(zip(STEPS, (geometry, response, noise, focus, dry)), 1):
            step(name, i, body)
        print("\n-- step 6/6: write the profile")
        done = [s for s in STEPS if s in session.results]
        skipped = [s for s in STEPS if s not in session.results]
        print(f"calibrated: {', '.join(done) or 'nothing'}; kept from {session.base.name}: {', '.join(skipped) or 'nothing'}")
        name = p.ask("Profile name", a.get("name", args.name or out.stem))
        if not p.yes(f"Write {out}?", True):
            print(f"not written; the session stays in {state_path}")
            return 1
        written = session.write(out, name)
    except EOFError:
        print(f"\ninput ended; the session is saved in {state_path} (run again to resume)")
        return 1
    for w in written:
        print(f"wrote {w}")
    if state_path.exists():
        state_path.unlink()
    return 0


# ------------------------------------------------------------------------ demo
def _demo(args, out: Path) -> int:
    from calibration import synthetic

    keep = args.demo_dir
    folder = Path(keep) if keep else Path(tempfile.mkdtemp(prefix="raingauge-demo-"))
    try:
        print(f"rendering synthetic captures into {folder}")
        truth = synthetic.write_demo_captures(folder)
        args.checkerboard = str(folder / "checkerboard")
        args.pattern = truth["geometry"]["pattern"]
        args.square_m = truth["geometry"]["square_m"]
        args.bracket = str(folder / "bracket")
        args.still = str(folder / "still")
        args.dry = str(folder / "dry")
        if args.pixel_pitch_m is None:
            args.pixel_pitch_m = 5e-6
        session = run_batch(args, out)
        written = session.write(out, args.name)
        g = session.results["geometry"]["camera"]
        print("== demo: recovered against truth")
        print(f"focal length  {g['focal_length_px']:.2f} px (true {truth['geometry']['focal_length_px']:.2f})")
        pp = g["principal_point_px"]
        tp = truth["geometry"]["principal_point_px"]
        print(f"principal pt  ({pp[0]:.1f}, {pp[1]:.1f}) px (true ({tp[0]:.1f}, {tp[1]:.1f}))")
        print(f"response      gamma {session.results['response']['provenance']['gamma']:.2f} "
              f"(true: {truth['bracket']['response']})")
        print(f"noise sigma   {session.results['noise']['camera']['noise_sigma_dn']:.3f} gray levels, linear "
              f"(true {truth['still']['sigma_dn']:.3f})")
        for w in written:
            print(f"wrote {w}")
    finally:
        if not keep:
            import shutil

            shutil.rmtree(folder, ignore_errors=True)
    return 0


def _check_out_dir(out: Path) -> None:
    from raingauge.errors import InputError

    if not out.parent.is_dir():
        raise InputError(f"output folder {out.parent} does not exist. Fix: create it or choose another --out")


def _check_options(args) -> None:
    """Refuse impossible numbers before any step runs (a later step must not fail on an option)."""
    from calibration.geometry import MIN_VIEWS
    from raingauge.errors import InputError

    def positive(option: str, value, example: str, *, optional: bool = True) -> None:
        if value is None and optional:
            return
        if not (value is not None and math.isfinite(value) and value > 0):
            raise InputError(f"{option} {value} is not a positive number. Fix: e.g. {option} {example}")

    positive("--square-m", args.square_m, "0.025")
    positive("--max-rms-px", args.max_rms_px, "1.0", optional=False)
    positive("--pixel-pitch-m", args.pixel_pitch_m, "3.45e-6")
    positive("--a-min-m", args.a_min_m, "0.5e-3", optional=False)
    positive("--focus-m", args.focus_m, "3.0")
    positive("--f-number", args.f_number, "2.0")
    if args.views < MIN_VIEWS:
        raise InputError(f"--views {args.views} is too few; the calibration needs at least {MIN_VIEWS}. "
                         f"Fix: e.g. --views 10")
    if not (math.isfinite(args.false_rate) and 0 < args.false_rate < 0.25):
        raise InputError(f"--false-rate {args.false_rate} must lie between 0 and 0.25 (false candidates per "
                         "pixel and frame). Fix: e.g. --false-rate 1e-3")
    if args.f_numbers:
        _parse_f_numbers(args.f_numbers)


def run(args: argparse.Namespace) -> int:
    from raingauge.errors import InputError

    out = Path(args.out) if args.out else None
    if out is not None:
        _check_out_dir(out)
    _check_options(args)
    if args.demo:
        if out is None:
            raise InputError("--demo needs --out PROFILE.toml")
        return _demo(args, out)
    if args.interactive or not _steps_requested(args):
        if not args.interactive and not sys.stdin.isatty():
            raise InputError(
                "nothing to calibrate: give --checkerboard, --bracket, --still or --dry (with --out), "
                "or run the command in a terminal for the interactive wizard"
            )
        return run_interactive(args, out)
    if out is None:
        raise InputError("--out PROFILE.toml is needed: the profile to write")
    session = run_batch(args, out)
    written = session.write(out, args.name)
    for w in written:
        print(f"wrote {w}")
    skipped = [s for s in STEPS if s not in session.results]
    if skipped:
        print(f"not calibrated (values kept from {session.base.name}): {', '.join(skipped)}")
    return 0

