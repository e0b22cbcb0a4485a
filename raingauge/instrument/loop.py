"""The field instrument's loop: source -> linearisation -> gauge -> records -> outputs.

::

    Grabber thread ──(t, frame)──> measuring loop ──record──> Modbus server thread (asyncio)
    (reconnect, corrupt frames)    profile.linearize          ├──> serial writer thread (NMEA)
                                   RainGauge.process          ├──> history writer thread (SQLite)
                                   accumulation, status       └──> stdout (optional)
                                        └──frames──> diagnostics thread (low rate: derained frames,
                                                     needle map, advisor recommendation)

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
import queue
import shutil
import threading
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from firmware_interface.fields import (
    N_DSD_CLASSES, STATUS_BITS, intensity_code, iso_utc, record_defaults, status_word,
)

__all__ = ["Instrument", "Accumulator", "HistoryWriter", "Diagnostics", "instrument_record", "make_gauge"]

log = logging.getLogger("raingauge.instrument")


def make_gauge(profile, *, window_s: float, step_s: float, velocity_model: str, clock_start_s: float):
    """The camera rain gauge of Sec. 8 (:class:`raingauge.gauge.RainGauge`)."""
    from raingauge.gauge import RainGauge

    return RainGauge(profile, window_s=window_s, step_s=step_s, velocity_model=velocity_model,
                     clock_start_s=clock_start_s)


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


# ---------------------------------------------------------------------- diagnostics thread
class Diagnostics:
    """Low-rate diagnostics beside the gauge, on their own thread.

    Each snapshot (a short stack of recent frames) gives, in
    ``folder/YYYYmmddTHHMMSSZ/``: ``frame.png`` (the middle frame),
    ``derained.png`` (rain removed, Sec. 5.2), ``needles.png`` (the needle map
    of the rain dynamics, Fig. 11) and ``advice.json`` (the advisor's gauge
    settings and the counting uncertainty at the current rate, Secs. 6-8).
    Each part is guarded: a failure is logged and the others go on; nothing
    here can stall or stop the gauge.  Only the newest ``keep`` snapshots are
    kept.
    """

    def __init__(self, folder: str | Path, profile, *, keep: int = 24):
        self.folder = Path(folder)
        self.profile = profile
        self.keep = keep
        self.snapshots = 0
        self.failures: collections.Counter = collections.Counter()
        self.busy = False
        self._queue: queue.Queue = queue.Queue(maxsize=1)
        self._thread = threading.Thread(target=self._run, name="diagnostics", daemon=True)
        self._thread.start()

    def submit(self, frames: list[np.ndarray], *, time_unix: float, rain_rate_mm_h: float, window_s: float) -> bool:
        """Hand over a snapshot; dropped (False) when the previous one is still being worked on."""
        try:
            self._queue.put_nowait((list(frames), time_unix, rain_rate_mm_h, window_s))
            return True
        except queue.Full:
            return False

    def close(self) -> None:
        try:
            self._queue.put_nowait(None)
        except queue.Full:
            pass
        self._thread.join(timeout=2.0)

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

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            self.busy = True
            try:
                self.snapshot(*item)
            finally:
                self.busy = False

    def snapshot(self, frames: list[np.ndarray], time_unix: float, rain_rate_mm_h: float, window_s: float) -> Path | None:
        """Write one snapshot; return its folder (None when the folder cannot be made)."""
        import cv2

        stamp = dt.datetime.fromtimestamp(time_unix, tz=dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
        out = self.folder / stamp

        def mkdir():
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

            results = list(Derainer(self.profile).process(frames))
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
        self.snapshots += 1
        self._guard("prune old snapshots", self._prune)
        return out

    def _prune(self) -> None:
        dirs = sorted(p for p in self.folder.iterdir() if p.is_dir())
        for old in dirs[: max(0, len(dirs) - self.keep)]:
            shutil.rmtree(old, ignore_errors=True)


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
    wall_t0 : [s since epoch] wall-clock time of the instrument clock's zero
    accumulator : :class:`Accumulator` to continue (restored from the history database)
    modbus : the Modbus output among ``outputs`` (for status updates between records), optional
    settings_extra : more settings stored with every record (e.g. the Modbus unit id)
    """

    def __init__(self, profile, grabber, *, window_s: float = 60.0, step_s: float = 10.0,
                 velocity_model: str = "paper", outputs: list | None = None, history=None,
                 diagnostics: Diagnostics | None = None, diagnostics_interval_s: float = 600.0,
                 diagnostics_frames: int = 32, stall_timeout_s: float = 5.0,
                 on_record: Callable[[dict], None] | None = None,
                 gauge_factory: Callable[..., Any] = make_gauge, wall_t0: float | None = None,
                 accumulator: Accumulator | None = None, modbus=None, settings_extra: dict | None = None):
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
        self.wall_t0 = time.time() if wall_t0 is None else float(wall_t0)
        self.accumulator = accumulator or Accumulator()
        self.modbus = modbus
        self.settings_extra = dict(settings_extra or {})
        self.calibrated = bool(getattr(profile, "provenance", None))
        self.records = 0
        self.missing_records = 0
        self.frames = 0
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
                                         velocity_model=self.velocity_model, clock_start_s=t_s)
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
        rec["frames"] = self._frames_in_step
        rec["corrupt_frames"] = self.grabber.corrupt_frames + self.grabber.source_corrupt_frames
        self._frames_in_step = 0
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
        g.start()
        lost = False
        last_frame_wall = time.monotonic()
        try:
            while not self._stop.is_set():
                if time.monotonic() >= self._next_status_check:
                    self._next_status_check = time.monotonic() + 0.25
                    self._refresh_status()
                item = g.get(timeout=0.25)
                if item is None:
                    if g.finished.is_set() and g.queue.empty():
                        if g.error is not None and self._gauge is None:
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
                lin = self.profile.linearize(frame)
                try:
                    records = self._gauge.process(lin, t_s=t_s)
                except Exception:  # noqa: BLE001 - one bad frame must not end months of measuring
                    self.gauge_errors += 1
                    if self.gauge_errors == 1 or self.gauge_errors % 1000 == 0:
                        log.exception("gauge failed on a frame at t = %.2f s (%d so far); frame skipped",
                                      t_s, self.gauge_errors)
                    records = []
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
            "corrupt_frames": self.grabber.corrupt_frames + self.grabber.source_corrupt_frames,
            "reconnects": self.grabber.reconnects,
            "gauge_errors": self.gauge_errors,
            "history_written": None if self.history_writer is None else self.history_writer.written,
            "history_pending": None if self.history_writer is None else self.history_writer.pending(),
            "accumulation_mm": self.accumulator.state()["accumulation_mm"],
            "diagnostics_snapshots": None if self.diagnostics is None else self.diagnostics.snapshots,
        }
