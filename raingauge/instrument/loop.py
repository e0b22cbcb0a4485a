"""The field instrument's loop: source -> gauge (linearisation inside) -> records -> outputs.

::

    [renderer process]  simulated camera only: frames rendered ahead into shared memory
          │
    Grabber thread ──(t, frame)──> measuring loop ──record──> Modbus server process
    (pacing, reconnect,            RainGauge.process          ├──> serial writer thread (NMEA)
     corrupt and dropped           (8-bit frames in)          ├──> history writer thread (SQLite)
     frames counted)               accumulation, status       └──> stdout (optional)
                                        └──frames──> diagnostics process, SCHED_IDLE (low rate:
                                                     derained frames, needle map, advisor)

The gauge gets the camera's 8-bit frames and linearises them itself (one
look-up); the loop adds no copy.  When the gauge is slower than a paced source
(a camera, or a file or the simulated camera played in real time), the grabber
drops frames explicitly (see :mod:`raingauge.instrument.sources`): every record
carries ``dropped_frames`` (frames of its step that were not measured) and the
quality flag ``dropped_frames``; the rate's sample time counts only the frames
measured.  Unpaced sources (``--fast``) wait for the gauge instead.

The measuring loop never waits for an output: every output has its own thread
and queue, and ``publish`` returns at once.  A camera that vanishes clears the
``camera_ok`` status bit; while it is gone a record marked ``missing`` (rate
invalid, not zero) is published at every step, and the gauge restarts when
frames come back.  A history database that cannot be written (disk full)
raises the ``storage_fault`` bit; records are kept in memory and written when
the disk has room again.  :meth:`Instrument.stop` (SIGTERM) flushes the gauge's
last partial window, drains the queues and closes everything.

Accumulation and rain duration since the last reset are the instrument's own
(they survive restarts through the history database); a Modbus write of
0x3247 to holding register 0 resets them.
"""

from __future__ import annotations

import collections
import datetime as dt
import json
import logging
import math
import os
import shutil
import threading
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from firmware_interface.fields import (
    N_DSD_CLASSES, STATUS_BITS, intensity_code, iso_utc, record_defaults, status_word,
)

__all__ = ["Instrument", "Accumulator", "HistoryWriter", "Diagnostics", "SnapshotWriter", "instrument_record",
           "make_gauge"]

log = logging.getLogger("raingauge.instrument")


def make_gauge(profile, *, window_s: float, step_s: float, velocity_model: str, clock_start_s: float,
               completeness_probe: bool = True):
    """The camera rain gauge of Sec. 8 (:class:`raingauge.gauge.RainGauge`)."""
    from raingauge.gauge import RainGauge

    return RainGauge(profile, window_s=window_s, step_s=step_s, velocity_model=velocity_model,
                     clock_start_s=clock_start_s, completeness_probe=completeness_probe)


# ---------------------------------------------------------------------- accumulation
class Accumulator:
    """Rain accumulated [mm] and rain duration [s] since the last reset (thread-safe)."""

    def __init__(self, accumulation_mm: float = 0.0, rain_duration_s: float = 0.0):
        self._lock = threading.Lock()
        self.accumulation_mm = float(accumulation_mm)
        self.rain_duration_s = float(rain_duration_s)
        self.resets = 0

    def add(self, depth_mm: float, rain_s: float) -> tuple[float, float]:
        with self._lock:
            if math.isfinite(depth_mm) and depth_mm > 0:
                self.accumulation_mm += depth_mm
            if math.isfinite(rain_s) and rain_s > 0:
                self.rain_duration_s += rain_s
            return self.accumulation_mm, self.rain_duration_s

    def reset(self) -> None:
        with self._lock:
            self.accumulation_mm = 0.0
            self.rain_duration_s = 0.0
            self.resets += 1

    def state(self) -> dict[str, float]:
        with self._lock:
            return {"accumulation_mm": self.accumulation_mm, "rain_duration_s": self.rain_duration_s}


def _finite(v) -> bool:
    try:
        return v is not None and math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def _raining(rec: dict[str, Any]) -> bool:
    """Rain seen in a record: intensity class above "none" (else a positive rate)."""
    if rec.get("missing"):
        return False
    code = rec.get("intensity_class")
    if _finite(code):
        return int(code) > 0
    return _finite(rec.get("rain_rate_mm_h")) and rec["rain_rate_mm_h"] > 0


def instrument_record(gauge_record: dict[str, Any], *, wall_t0: float, profile, window_s: float) -> dict[str, Any]:
    """Map a gauge record (keys of the :class:`raingauge.gauge.RainGauge` contract) to an instrument record.

    Accumulation, rain duration, status, frame counts are filled in by the loop.
    """
    rec = record_defaults()
    g = gauge_record
    for key in ("t_start_s", "t_end_s", "rain_rate_mm_h", "drops_counted", "drops_rejected_defocus",
                "nt_m3", "dm_mm", "z_dbz", "synop_4680"):
        if key in g and g[key] is not None:
            rec[key] = g[key]
    ci = g.get("rain_rate_ci95_mm_h")
    if ci is not None and len(ci) == 2:
        rec["rain_rate_ci95_lo_mm_h"], rec["rain_rate_ci95_hi_mm_h"] = ci[0], ci[1]
    try:
        rec["intensity_class"] = intensity_code(g.get("intensity_class"))
    except ValueError:
        rec["intensity_class"] = None
    for key in ("dsd_d_mm", "dsd_n_m3_mm"):
        values = g.get(key)
        if values is not None:
            values = [float(v) for v in np.asarray(values, dtype=float).ravel()[:N_DSD_CLASSES]]
            rec[key] = values + [math.nan] * (N_DSD_CLASSES - len(values))
    rec["quality"] = list(g.get("quality") or [])
    rec["time_unix"] = wall_t0 + float(g.get("t_end_s", 0.0))
    rec["window_s"] = float(window_s)
    rec["exposure_s"] = profile.exposure_s
    rec["f_number"] = profile.f_number
    rec["focus_distance_m"] = profile.focus_distance_m
    rec["frame_rate_hz"] = profile.frame_rate_hz
    rec["missing"] = 0
    return rec


# ---------------------------------------------------------------------- history thread
class HistoryWriter:
    """Write records to :class:`raingauge.history.History` on its own thread.

    When the database cannot be written (:class:`raingauge.history.StorageFull`)
    :attr:`fault` is raised, the record stays at the head of the backlog and the
    write is retried every ``retry_s``; up to ``max_backlog`` records are held.
    """

    def __init__(self, history, *, retry_s: float = 5.0, max_backlog: int = 100_000):
        self.history = history
        self.retry_s = retry_s
        self.fault = False
        self.written = 0
        self.lost = 0
        self.last_error: str | None = None
        self._backlog: collections.deque = collections.deque()
        self._max_backlog = max_backlog
        self._cv = threading.Condition()
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="history", daemon=True)
        self._thread.start()

    def put(self, record: dict[str, Any], settings: dict[str, Any] | None = None) -> None:
        with self._cv:
            if len(self._backlog) >= self._max_backlog:
                self._backlog.popleft()
                self.lost += 1
            self._backlog.append((record, settings))
            self._cv.notify()

    def put_settings(self, settings: dict[str, Any]) -> None:
        """Store settings in order with the records queued before them."""
        self.put(None, settings)

    def pending(self) -> int:
        with self._cv:
            return len(self._backlog)

    def _run(self) -> None:
        from raingauge.history import StorageFull

        while True:
            with self._cv:
                while not self._backlog and not self._stop:
                    self._cv.wait()
                if not self._backlog and self._stop:
                    return
                record, settings = self._backlog[0]
            try:
                if record is None:
                    self.history.set_settings(**settings)
                else:
                    self.history.append(record, settings=settings)
            except StorageFull as exc:
                if not self.fault:
                    log.error("history: %s; records are kept in memory and written when there is room", exc)
                self.fault = True
                self.last_error = str(exc)
                with self._cv:
                    if self._stop:
                        return
                    self._cv.wait(self.retry_s)
                continue
            except Exception:  # noqa: BLE001 - never let the writer die
                log.exception("history: unexpected error; record kept for a retry")
                self.fault = True
                with self._cv:
                    if self._stop:
                        return
                    self._cv.wait(self.retry_s)
                continue
            with self._cv:
                self._backlog.popleft()
            if record is not None:
                self.written += 1
            if self.fault:
                log.info("history: writing again")
            self.fault = False

    def close(self, timeout_s: float = 10.0) -> None:
        """Write what is queued (up to ``timeout_s``) and stop."""
        deadline = time.monotonic() + timeout_s
        while self.pending() and not self.fault and time.monotonic() < deadline:
            time.sleep(0.01)
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        self._thread.join(timeout=max(0.1, deadline - time.monotonic()))
        if self.pending():
            log.error("history: %d records could not be written before exit", self.pending())


# ---------------------------------------------------------------------- diagnostics process
def _lower_priority() -> str:
    """Run the calling process only on CPU time nobody else wants (SCHED_IDLE, else nice 19)."""
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        return "SCHED_IDLE"
    except (AttributeError, OSError):
        try:
            os.nice(19)
            return "nice 19"
        except OSError:
            return "normal"


def _diagnostics_worker(folder, profile, keep, buf, shape, jobs, idle, count, log_level, priority,
                        parent_pid) -> None:
    """The diagnostics process: one snapshot per job, frames read from the shared buffer."""
    from raingauge.instrument.sources import _ignore_interrupts, get_or_orphaned

    _ignore_interrupts()
    logging.basicConfig(level=log_level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:                                              # imports at start-up, at normal priority
        import cv2  # noqa: F401

        import raingauge.advisor  # noqa: F401
        import raingauge.vision  # noqa: F401
    except Exception:  # noqa: BLE001 - each snapshot part reports its own failure
        pass
    if priority == "idle":
        _lower_priority()
    writer = SnapshotWriter(folder, profile, keep=keep)
    ring = np.frombuffer(buf, dtype=np.uint8).reshape(shape)
    while True:
        job = get_or_orphaned(jobs, parent_pid)
        if job is None:
            return
        n, time_unix, rate, window_s = job
        try:
            if writer.snapshot([ring[i] for i in range(n)], time_unix, rate, window_s) is not None:
                with count.get_lock():
                    count.value += 1
        except Exception:  # noqa: BLE001 - never let the diagnostics process die
            log.exception("diagnostics: snapshot failed")
        finally:
            idle.set()


#: how the diagnostics process is scheduled: "idle" (only CPU time nobody else wants) or "normal"
DIAGNOSTICS_PRIORITIES = ("idle", "normal")


class SnapshotWriter:
    """Write diagnostic snapshots (see :class:`Diagnostics`) on the calling thread."""

    def __init__(self, folder: str | Path, profile, *, keep: int = 24):
        self.folder = Path(folder)
        self.profile = profile
        self.keep = keep
        self.snapshots = 0
        self.failures: collections.Counter = collections.Counter()

    def _guard(self, what: str, fn: Callable[[], Any]):
        try:
            return fn()
        except Exception as exc:  # noqa: BLE001 - diagnostics must never stop the gauge
            self.failures[what] += 1
            if self.failures[what] == 1:
                log.warning("diagnostics: %s failed (%s: %s); the gauge is not affected", what,
                            type(exc).__name__, exc)
            else:
                log.debug("diagnostics: %s failed again: %s", what, exc)
            return None

    def snapshot(self, frames: list[np.ndarray], time_unix: float, rain_rate_mm_h: float, window_s: float) -> Path | None:
        """Write one snapshot; return its folder (None when the folder cannot be made).

        The snapshot is written into ``STAMP.part`` and renamed when complete, so
        a folder without the suffix is never half written.
        """
        import cv2

        stamp = dt.datetime.fromtimestamp(time_unix, tz=dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
        final = self.folder / stamp
        out = self.folder / (stamp + ".part")

        def mkdir():
            if out.exists():
                shutil.rmtree(out)
            out.mkdir(parents=True, exist_ok=True)
            return out

        if self._guard("create folder", mkdir) is None:
            return None
        mid = frames[len(frames) // 2]

        def write(name, img):
            if not cv2.imwrite(str(out / name), img):
                raise OSError(f"cannot write {out / name} (disk full?)")

        self._guard("frame.png", lambda: write("frame.png", mid))

        def derain():
            from raingauge.vision import Derainer, needle_map

            # (frames and the needle map only: no relaxed run test for DerainedFrame.detected)
            results = list(Derainer(self.profile, near_px=0).process(frames))
            write("derained.png", results[len(results) // 2].frame)
            fields = [r.field for r in results if r.field is not None]
            if not fields:
                raise RuntimeError("no correlation field (too few frames for the needle map)")
            write("needles.png", needle_map(results[len(results) // 2].frame, fields[-1]))

        self._guard("derain + needle map", derain)

        def advice():
            from raingauge.advisor import advise_gauge

            rates = (1.0, 10.0, 50.0) + ((float(rain_rate_mm_h),) if _finite(rain_rate_mm_h) and rain_rate_mm_h > 0 else ())
            a = advise_gauge(self.profile, window_s=window_s, rain_rates_mm_h=rates)
            doc = {"time_unix": time_unix, "rain_rate_mm_h": rain_rate_mm_h if _finite(rain_rate_mm_h) else None,
                   "current": {"exposure_s": self.profile.exposure_s, "f_number": self.profile.f_number,
                               "focus_distance_m": self.profile.focus_distance_m},
                   "advice": a.to_dict()}
            (out / "advice.json").write_text(json.dumps(doc, indent=2, default=_json_default))

        self._guard("advisor", advice)

        def publish():
            if final.exists():
                shutil.rmtree(final)
            out.rename(final)
            return final

        if self._guard("complete snapshot", publish) is None:
            return None
        self.snapshots += 1
        self._guard("prune old snapshots", self._prune)
        return final

    def _prune(self) -> None:
        dirs = sorted(p for p in self.folder.iterdir() if p.is_dir() and not p.name.endswith(".part"))
        for old in dirs[: max(0, len(dirs) - self.keep)]:
            shutil.rmtree(old, ignore_errors=True)
        for part in self.folder.glob("*.part"):      # left by an interrupted snapshot
            shutil.rmtree(part, ignore_errors=True)


class Diagnostics:
    """Low-rate diagnostics beside the gauge, in a separate low-priority process.

    Each snapshot (a short stack of recent frames) gives, in
    ``folder/YYYYmmddTHHMMSSZ/``: ``frame.png`` (the middle frame),
    ``derained.png`` (rain removed, Sec. 5.2), ``needles.png`` (the needle map
    of the rain dynamics, Fig. 11) and ``advice.json`` (the advisor's gauge
    settings and the counting uncertainty at the current rate, Secs. 6-8).
    Each part is guarded: a failure is logged and the others go on.  Only the
    newest ``keep`` snapshots are kept.

    The work runs in its own process (started at the first :meth:`submit`)
    scheduled ``SCHED_IDLE`` (else ``nice 19``): it gets only CPU time the
    gauge and the camera leave, so it cannot slow the gauge, and with the GIL
    of another interpreter it cannot hold the gauge's thread either.  The
    frames travel through a shared-memory buffer (one copy, a few ms, once per
    snapshot); a snapshot is handed over only when the previous one is done.
    :meth:`snapshot` writes one on the calling thread (tools, tests).
    """

    def __init__(self, folder: str | Path, profile, *, keep: int = 24, close_timeout_s: float = 2.0,
                 priority: str = "idle"):
        if priority not in DIAGNOSTICS_PRIORITIES:
            raise ValueError(f"unknown diagnostics priority {priority!r}; valid: {list(DIAGNOSTICS_PRIORITIES)}")
        self.priority = priority
        self.folder = Path(folder)
        self.profile = profile
        self.keep = keep
        self.close_timeout_s = float(close_timeout_s)
        self._writer = SnapshotWriter(folder, profile, keep=keep)
        self._proc = None
        self._ring = None
        self._jobs = None
        self._idle = None
        self._count = None
        self.submitted = 0
        self.skipped = 0

    @property
    def failures(self) -> collections.Counter:
        """Failures of the snapshots written by :meth:`snapshot` (the process logs its own)."""
        return self._writer.failures

    @property
    def snapshots(self) -> int:
        """Snapshots completed (in the process and by :meth:`snapshot`)."""
        done = 0 if self._count is None else int(self._count.value)
        return done + self._writer.snapshots

    @property
    def busy(self) -> bool:
        return self._idle is not None and not self._idle.is_set()

    @property
    def pid(self) -> int | None:
        """Process id of the diagnostics process (None before :meth:`start`)."""
        return None if self._proc is None else self._proc.pid

    def start(self, shape: tuple[int, ...]) -> "Diagnostics":
        """Start the process for snapshots of up to ``shape`` = (T, M, N) uint8 frames.

        Called by the instrument at start-up (the process's imports then do not
        compete with measurement); :meth:`submit` starts it when needed.
        """
        self._start(tuple(int(v) for v in shape))
        return self

    def _start(self, shape: tuple[int, ...]) -> None:
        import multiprocessing as mp

        self.close()
        ctx = mp.get_context("spawn")          # never fork a process with threads
        buf = ctx.RawArray("B", int(np.prod(shape)))
        self._ring = np.frombuffer(buf, dtype=np.uint8).reshape(shape)
        self._jobs = ctx.Queue()
        self._idle = ctx.Event()
        self._idle.set()
        self._count = ctx.Value("i", 0)
        self._proc = ctx.Process(target=_diagnostics_worker, name="raingauge-diagnostics", daemon=True,
                                 args=(self.folder, self.profile, self.keep, buf, shape, self._jobs, self._idle,
                                       self._count, logging.getLogger().getEffectiveLevel(), self.priority,
                                       os.getpid()))
        self._proc.start()

    def submit(self, frames: list[np.ndarray], *, time_unix: float, rain_rate_mm_h: float, window_s: float) -> bool:
        """Hand over a snapshot; dropped (False) when the previous one is still being worked on."""
        frames = [np.asarray(f) for f in frames]
        if not frames or frames[0].dtype != np.uint8 or any(f.shape != frames[0].shape for f in frames):
            self.skipped += 1
            return False
        shape = (len(frames),) + frames[0].shape
        if self._proc is None or self._ring.shape[1:] != shape[1:] or self._ring.shape[0] < shape[0]:
            self._start(shape)
        if not self._proc.is_alive():
            log.error("diagnostics process ended (exit code %s); starting it again", self._proc.exitcode)
            self._start(shape)
        if not self._idle.is_set():
            self.skipped += 1
            return False
        self._idle.clear()
        for i, f in enumerate(frames):
            self._ring[i] = f
        self._jobs.put((len(frames), float(time_unix), float(rain_rate_mm_h), float(window_s)))
        self.submitted += 1
        return True

    def snapshot(self, frames: list[np.ndarray], time_unix: float, rain_rate_mm_h: float, window_s: float) -> Path | None:
        """Write one snapshot on the calling thread; return its folder (see :class:`SnapshotWriter`)."""
        return self._writer.snapshot(frames, time_unix, rain_rate_mm_h, window_s)

    def close(self) -> None:
        """Let a snapshot in progress finish (up to ``close_timeout_s``), then stop the process."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            self._jobs.put(None)
        except (OSError, ValueError):
            pass
        proc.join(timeout=self.close_timeout_s)
        if proc.is_alive():
            log.info("diagnostics: a snapshot was still in progress at exit; stopped")
            proc.kill()
            proc.join(timeout=2.0)
            for part in self.folder.glob("*.part"):       # the unfinished snapshot
                shutil.rmtree(part, ignore_errors=True)
        self._jobs.close()
        self._jobs.cancel_join_thread()


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return str(o)


# ---------------------------------------------------------------------- the instrument
class Instrument:
    """The measuring loop and its outputs.

    Parameters
    ----------
    profile : CameraProfile
    grabber : :class:`raingauge.instrument.sources.Grabber` (not started)
    window_s, step_s : [s]
    velocity_model : fall-velocity law of the gauge
    outputs : objects with ``publish(record)`` (Modbus, serial) - must not block
    history : :class:`raingauge.history.History` or None
    diagnostics : :class:`Diagnostics` or None
    diagnostics_interval_s : [s] between snapshots (instrument clock)
    diagnostics_frames : frames per snapshot
    stall_timeout_s : [s] a live source silent this long is "lost"
    on_record : called with every record (printing); exceptions are logged
    gauge_factory : builds the gauge (default :func:`make_gauge`)
    gauge_options : more keyword arguments of ``gauge_factory`` (e.g. ``completeness_probe``)
    wall_t0 : [s since epoch] wall-clock time of the instrument clock's zero
    accumulator : :class:`Accumulator` to continue (restored from the history database)
    modbus : the Modbus output among ``outputs`` (for status updates between records), optional
    settings_extra : more settings stored with every record (e.g. the Modbus unit id)
    """

    def __init__(self, profile, grabber, *, window_s: float = 60.0, step_s: float = 10.0,
                 velocity_model: str = "gunn_kinzer", outputs: list | None = None, history=None,
                 diagnostics: Diagnostics | None = None, diagnostics_interval_s: float = 600.0,
                 diagnostics_frames: int = 32, stall_timeout_s: float = 5.0,
                 on_record: Callable[[dict], None] | None = None,
                 gauge_factory: Callable[..., Any] = make_gauge, wall_t0: float | None = None,
                 accumulator: Accumulator | None = None, modbus=None, settings_extra: dict | None = None,
                 gauge_options: dict | None = None):
        self.profile = profile
        self.grabber = grabber
        self.window_s = float(window_s)
        self.step_s = float(step_s)
        self.velocity_model = velocity_model
        self.outputs = list(outputs or [])
        self.history_writer = HistoryWriter(history) if history is not None else None
        self.diagnostics = diagnostics
        self.diagnostics_interval_s = diagnostics_interval_s
        self.stall_timeout_s = stall_timeout_s
        self.on_record = on_record
        self.gauge_factory = gauge_factory
        self.gauge_options = dict(gauge_options or {})
        self.wall_t0 = time.time() if wall_t0 is None else float(wall_t0)
        self.accumulator = accumulator or Accumulator()
        self.modbus = modbus
        self.settings_extra = dict(settings_extra or {})
        self.calibrated = bool(getattr(profile, "provenance", None))
        self.records = 0
        self.missing_records = 0
        self.frames = 0
        self.gauge_time_s = 0.0
        self.wall_time_s = 0.0
        self.measuring_fps: float | None = None
        self._first_frame_wall: float | None = None
        self._dropped_seen = 0
        self._dropped_in_step = 0
        self.output_errors = 0
        self.gauge_errors = 0
        self._stop = threading.Event()
        self._pending_window: float | None = None
        self._ring: collections.deque = collections.deque(maxlen=max(3, int(diagnostics_frames)))
        self._frames_in_step = 0
        self._gauge = None
        self._gauge_acc_prev: float | None = None
        self._last_end_s = 0.0
        self._camera_ok = False
        self._next_diag_s = min(30.0, diagnostics_interval_s)
        self._last_rate_mm_h = math.nan
        self._last_status = 0
        self._published_status = -1
        self._next_status_check = 0.0

    # ------------------------------------------------------------------ control (any thread)
    def stop(self) -> None:
        """Ask the loop to finish (flush, drain, close); safe from a signal handler."""
        self._stop.set()

    def request_window(self, window_s: float) -> None:
        """Change the averaging window from the next record on (Modbus holding register 2)."""
        self._pending_window = float(window_s)

    def reset_accumulation(self) -> None:
        """Reset accumulation and rain duration (Modbus 0x3247)."""
        self.accumulator.reset()
        log.info("accumulation reset")
        if self.history_writer is not None:
            self.history_writer.put_settings(self.accumulator.state())

    # ------------------------------------------------------------------ status
    def status(self, record: dict | None = None) -> int:
        storage_fault = bool(self.history_writer and self.history_writer.fault)
        output_fault = self.output_errors > 0 or any(bool(getattr(o, "fault", False)) for o in self.outputs)
        rain = bool(record and _raining(record))
        low = bool(record and (record.get("quality") or record.get("missing")))
        return status_word(camera_ok=self._camera_ok, rain_detected=rain, low_confidence=low,
                           calibrated=self.calibrated, storage_fault=storage_fault, output_fault=output_fault)

    # ------------------------------------------------------------------ records
    def _new_gauge(self, t_s: float) -> None:
        self._gauge = self.gauge_factory(self.profile, window_s=self.window_s, step_s=self.step_s,
                                         velocity_model=self.velocity_model, clock_start_s=t_s,
                                         **self.gauge_options)
        self._gauge_acc_prev = None

    def _emit(self, rec: dict[str, Any]) -> None:
        if not rec.get("missing"):
            g_acc = rec.pop("_gauge_accumulation_mm", None)
            step = self.step_s
            if _finite(g_acc):
                depth = float(g_acc) - (self._gauge_acc_prev or 0.0)
                self._gauge_acc_prev = float(g_acc)
            elif _finite(rec.get("rain_rate_mm_h")):
                depth = float(rec["rain_rate_mm_h"]) * step / 3600.0
            else:
                depth = 0.0
            raining = _raining(rec)
            acc, dur = self.accumulator.add(depth, step if raining else 0.0)
        else:
            rec.pop("_gauge_accumulation_mm", None)
            state = self.accumulator.state()
            acc, dur = state["accumulation_mm"], state["rain_duration_s"]
        rec["accumulation_mm"] = acc
        rec["rain_duration_s"] = dur
        self._count_dropped()
        rec["frames"] = self._frames_in_step
        rec["dropped_frames"] = self._dropped_in_step
        if self._dropped_in_step and not rec.get("missing"):
            quality = list(rec.get("quality") or [])
            if "dropped_frames" not in quality:
                quality.append("dropped_frames")
            rec["quality"] = quality
        rec["corrupt_frames"] = self.grabber.corrupt_frames + self.grabber.source_corrupt_frames
        self._frames_in_step = 0
        self._dropped_in_step = 0
        rec["status"] = self.status(rec)
        self._last_status = self._published_status = rec["status"]
        if _finite(rec.get("time_unix")):
            rec["time_utc"] = iso_utc(float(rec["time_unix"]))
        rate = rec.get("rain_rate_mm_h")
        self._last_rate_mm_h = float(rate) if _finite(rate) else math.nan
        self.records += 1
        self._last_end_s = float(rec.get("t_end_s", self._last_end_s))
        for out in self.outputs:
            try:
                out.publish(rec)
            except Exception:  # noqa: BLE001 - an output must never stop the gauge
                self.output_errors += 1
                log.exception("output %s failed", type(out).__name__)
        if self.history_writer is not None:
            settings = dict(self.accumulator.state(), window_s=self.window_s, **self.settings_extra)
            self.history_writer.put(rec, settings)
        if self.on_record is not None:
            try:
                self.on_record(rec)
            except Exception:  # noqa: BLE001
                log.exception("record callback failed")

    def _count_dropped(self) -> None:
        """Move the grabber's newly dropped frames into the current step's count."""
        d = int(getattr(self.grabber, "dropped_frames", 0) or 0)
        self._dropped_in_step += max(0, d - self._dropped_seen)
        self._dropped_seen = d

    def _emit_gauge_records(self, records: list[dict]) -> None:
        for g in records:
            rec = instrument_record(g, wall_t0=self.wall_t0, profile=self.profile, window_s=self.window_s)
            rec["_gauge_accumulation_mm"] = g.get("accumulation_mm")
            self._emit(rec)
        pending = self._pending_window
        if records and pending is not None:
            self._pending_window = None
            if pending != self.window_s:
                log.info("window %.0f s -> %.0f s", self.window_s, pending)
                self.window_s = pending
                self._new_gauge(self._last_end_s)

    def _emit_missing(self, now_s: float) -> None:
        """While the camera is gone: one 'missing' record per step boundary passed."""
        while self._last_end_s + self.step_s <= now_s:
            end = self._last_end_s + self.step_s
            rec = record_defaults()
            rec.update(t_start_s=end - self.window_s, t_end_s=end, time_unix=self.wall_t0 + end,
                       window_s=self.window_s, missing=1, quality=["camera_lost"], drops_counted=None,
                       exposure_s=self.profile.exposure_s, f_number=self.profile.f_number,
                       focus_distance_m=self.profile.focus_distance_m, frame_rate_hz=self.profile.frame_rate_hz)
            self.missing_records += 1
            self._emit(rec)

    def _set_camera(self, ok: bool) -> None:
        if ok != self._camera_ok:
            self._camera_ok = ok
            self._refresh_status()

    def _refresh_status(self) -> None:
        """Publish status changes between records (camera lost, storage fault) to Modbus."""
        if self.modbus is None:
            return
        base = self.status()
        # keep the record-dependent bits (rain, low confidence) of the last record
        keep = (1 << STATUS_BITS["rain_detected"]) | (1 << STATUS_BITS["low_confidence"])
        word = (base & ~keep) | (self._last_status & keep)
        if word != self._published_status:
            self._published_status = word
            try:
                self.modbus.set_status(word)
            except Exception:  # noqa: BLE001
                log.exception("Modbus status update failed")

    # ------------------------------------------------------------------ the loop
    def run(self, duration_s: float | None = None) -> dict[str, Any]:
        """Measure until :meth:`stop`, the end of a recorded source, or ``duration_s`` [s] of source time.

        Returns a summary (records, frames, missing records, corrupt frames, ...).
        """
        g = self.grabber
        wall0 = time.monotonic()
        if self.diagnostics is not None and self.diagnostics.pid is None:
            try:
                self.diagnostics.start((self._ring.maxlen,) + tuple(self.profile.shape))
            except Exception:  # noqa: BLE001 - the gauge runs without diagnostics
                log.exception("diagnostics cannot start; measuring without them")
        # The source starts (the simulated camera's renderer imports and renders ahead) while
        # the gauge is built (its sample volume takes seconds); frames flow when both are ready.
        g.start(hold=True)
        lost = False
        try:
            try:
                if self._gauge is None:
                    self._new_gauge(0.0)
            finally:
                g.release()
            last_frame_wall = time.monotonic()
            while not self._stop.is_set():
                if time.monotonic() >= self._next_status_check:
                    self._next_status_check = time.monotonic() + 0.25
                    self._refresh_status()
                item = g.get(timeout=0.25)
                if item is None:
                    if g.finished.is_set() and g.queue.empty():
                        if g.error is not None and self.frames == 0:
                            raise g.error
                        break
                    if g.source.live:
                        now_s = g.now_s()
                        if not lost and time.monotonic() - last_frame_wall > self.stall_timeout_s:
                            lost = True
                            log.warning("no frames for %.0f s: camera lost; records are marked missing",
                                        self.stall_timeout_s)
                            self._set_camera(False)
                            self._gauge = None  # a window across the gap would be wrong
                            self._frames_in_step = 0
                        if lost:
                            self._emit_missing(now_s)
                        if duration_s is not None and now_s >= duration_s:
                            break
                    continue
                t_s, frame = item
                if duration_s is not None and t_s > duration_s:
                    break
                last_frame_wall = time.monotonic()
                if lost or self._gauge is None:
                    if lost:
                        self._emit_missing(t_s)
                    lost = False
                    self._new_gauge(t_s if self.frames else 0.0)
                self._set_camera(True)
                self._count_dropped()
                t_gauge = time.perf_counter()
                try:
                    records = self._gauge.process(frame, t_s=t_s)
                except Exception:  # noqa: BLE001 - one bad frame must not end months of measuring
                    self.gauge_errors += 1
                    if self.gauge_errors == 1 or self.gauge_errors % 1000 == 0:
                        log.exception("gauge failed on a frame at t = %.2f s (%d so far); frame skipped",
                                      t_s, self.gauge_errors)
                    records = []
                self.gauge_time_s += time.perf_counter() - t_gauge
                if self._first_frame_wall is None:
                    self._first_frame_wall = time.monotonic()
                self.frames += 1
                self._frames_in_step += 1
                self._ring.append(frame)
                if records:
                    self._emit_gauge_records(records)
                if self.diagnostics is not None and t_s >= self._next_diag_s and len(self._ring) >= 3:
                    self._next_diag_s = t_s + self.diagnostics_interval_s
                    self.diagnostics.submit(list(self._ring), time_unix=self.wall_t0 + t_s,
                                            rain_rate_mm_h=self._last_rate(), window_s=self.window_s)
        finally:
            t_end = time.monotonic()
            self.wall_time_s = t_end - wall0
            if self._first_frame_wall is not None and self.frames > 1:
                self.measuring_fps = (self.frames - 1) / max(t_end - self._first_frame_wall, 1e-9)
            self._finish()
        return self.summary()

    def _last_rate(self) -> float:
        """Rain rate of the last record [mm/h] (NaN before the first or while missing)."""
        return self._last_rate_mm_h

    def _finish(self) -> None:
        if self._gauge is not None:
            try:
                tail = self._gauge.flush()
            except Exception:  # noqa: BLE001
                log.exception("gauge flush failed")
                tail = []
            if tail:
                self._emit_gauge_records(tail)
        self.grabber.stop()
        if self.diagnostics is not None:
            self.diagnostics.close()
        for out in self.outputs:
            close = getattr(out, "close", None) or getattr(out, "stop", None)
            if close is not None:
                try:
                    close()
                except Exception:  # noqa: BLE001
                    log.exception("closing %s", type(out).__name__)
        if self.history_writer is not None:
            self.history_writer.close()

    def summary(self) -> dict[str, Any]:
        return {
            "records": self.records,
            "missing_records": self.missing_records,
            "frames": self.frames,
            "dropped_frames": int(getattr(self.grabber, "dropped_frames", 0) or 0),
            "wall_s": round(self.wall_time_s, 1),
            "frames_per_s": None if self.measuring_fps is None else round(self.measuring_fps, 1),
            "gauge_ms_per_frame": round(1e3 * self.gauge_time_s / self.frames, 1) if self.frames else None,
            "corrupt_frames": self.grabber.corrupt_frames + self.grabber.source_corrupt_frames,
            "reconnects": self.grabber.reconnects,
            "gauge_errors": self.gauge_errors,
            "history_written": None if self.history_writer is None else self.history_writer.written,
            "history_pending": None if self.history_writer is None else self.history_writer.pending(),
            "accumulation_mm": self.accumulator.state()["accumulation_mm"],
            "diagnostics_snapshots": None if self.diagnostics is None else self.diagnostics.snapshots,
        }
