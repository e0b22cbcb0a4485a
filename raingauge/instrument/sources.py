"""Frame sources for the instrument: cameras, streams, files, image folders, simulated rain.

A source yields gray uint8 frames (M, N) of the camera profile's size.  Live
sources (a camera by OpenCV device index, an RTSP/HTTP stream) raise
:class:`raingauge.errors.SourceError` when the device vanishes; recorded ones
(a video file, a folder of images) end; the simulated camera
(``simulate:RATE``) plays :func:`raingauge.render.simulator.simulate` output
for ever, chunk after chunk.

:class:`Grabber` runs a source on its own thread, reconnects with exponential
backoff when it is lost, skips and counts corrupt frames (empty, wrong size or
type), and hands ``(t_s, frame)`` pairs to the measuring loop through a small
queue.

When the measuring loop falls behind, what happens depends on the source's clock:

* *paced* sources - live cameras and streams, and recorded or simulated sources
  played in real time (``realtime=True``) - go on at their frame rate as a
  camera does: when the queue is full, the backlog is dropped **explicitly** and
  the gauge resumes with the newest frame.  :attr:`Grabber.dropped_frames`
  counts them, the frames kept carry their true times (so the gauge sees the
  gaps, flags its records ``dropped_frames`` and takes as sample time only the
  frames it measured), and the instrument reports the count in every record.
  The lag between camera and gauge stays below the queue (``queue_size``
  frames).  Dropping the whole backlog at once, rather than the oldest frame
  each time, leaves the gauge runs of consecutive frames with a few gaps
  between them instead of a gap at every frame: the gauge's three-frame test
  (Eq. 19) and its de-duplication of a drop seen in neighbouring frames work
  on consecutive frames, and evenly thinned frames (every third one kept) read
  the rate about a third high in a 320x240 simulation at 30 mm/h, while runs
  with gaps read it within the counting noise
  (``benchmarks/bench_run_rate.py --gaps``).
* unpaced sources (files or simulation with ``realtime=False``) wait for the
  loop: nothing is dropped, and source time runs slower than the wall clock.

Specifications accepted by :func:`open_source`::

    simulate:10          simulated rain at 10 mm/h (real time, or as fast as possible)
    0, 1, ...            OpenCV device index
    /dev/video0          a camera device node (or a udev symlink to one)
    rtsp://..., http://..., https://...   network stream
    /path/clip.mkv       video file
    /path/frames/        folder of images, in name order
"""

from __future__ import annotations

import logging
import os
import queue
import stat
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np

from raingauge.errors import InputError, SourceError

__all__ = [
    "FrameSource",
    "CameraSource",
    "FileSource",
    "SimulatedSource",
    "Grabber",
    "open_source",
    "scaled_profile",
    "to_gray",
]

log = logging.getLogger("raingauge.source")

_STREAM_PREFIXES = ("rtsp://", "rtsps://", "http://", "https://", "rtmp://", "udp://", "tcp://")


def to_gray(frame: np.ndarray) -> np.ndarray:
    """A uint8 (M, N) frame from (M, N), (M, N, 3) BGR or (M, N, 4) BGRA."""
    frame = np.asarray(frame)
    if frame.ndim == 3 and frame.shape[2] in (3, 4):
        import cv2

        code = cv2.COLOR_BGR2GRAY if frame.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        frame = cv2.cvtColor(frame, code)
    if frame.dtype == np.uint16:
        frame = (frame >> 8).astype(np.uint8)
    return frame


class FrameSource:
    """Base class: ``open()``, ``read() -> frame | None``, ``close()``.

    Attributes
    ----------
    name : what the source is (for logs)
    live : True for cameras and streams (reconnect on loss), False for files and simulation
    frame_rate_hz : frames per second [Hz]
    realtime : recorded sources are paced at ``frame_rate_hz`` when True
    """

    name = "source"
    live = False
    frame_rate_hz: float = 30.0
    realtime = False

    def open(self) -> None:
        """Connect; raises SourceError (live) or InputError (files) when impossible."""

    def read(self) -> np.ndarray | None:
        """Next frame (uint8, gray or BGR); None at the end; raises SourceError when lost."""
        raise NotImplementedError

    def close(self) -> None:
        """Release the device or file."""


class CameraSource(FrameSource):
    """An OpenCV camera (device index) or network stream (URL)."""

    live = True

    def __init__(self, target: int | str, *, frame_rate_hz: float = 30.0, failures_to_lose: int = 10):
        self.target = target
        self.name = f"camera {target}" if isinstance(target, int) else f"stream {target}"
        self.frame_rate_hz = frame_rate_hz
        self.failures_to_lose = failures_to_lose
        self._cap = None
        self._failures = 0
        self.failed_reads = 0

    def open(self) -> None:
        import cv2

        cap = cv2.VideoCapture(self.target)
        if not cap.isOpened():
            cap.release()
            raise SourceError(f"{self.name}: cannot be opened. Fix: check the cable/URL, that no other program "
                              "holds the camera, and the device permissions (group video)")
        fps = cap.get(cv2.CAP_PROP_FPS)
        if fps and 0 < fps < 1000:
            self.frame_rate_hz = float(fps)
        self._cap = cap
        self._failures = 0

    def read(self) -> np.ndarray | None:
        if self._cap is None:
            raise SourceError(f"{self.name}: not open")
        ok, frame = self._cap.read()
        if not ok or frame is None:
            self._failures += 1
            self.failed_reads += 1
            if self._failures >= self.failures_to_lose:
                raise SourceError(f"{self.name}: {self._failures} reads in a row failed (camera gone?)")
            return np.empty((0, 0), np.uint8)  # counted as corrupt by the grabber
        self._failures = 0
        return frame

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


class FileSource(FrameSource):
    """A video file or a folder of images, via :class:`raingauge.videoio.FrameReader`."""

    def __init__(self, path: str | Path, *, frame_rate_hz: float = 30.0, realtime: bool = False):
        self.path = Path(path)
        self.name = f"file {self.path}"
        self.frame_rate_hz = frame_rate_hz
        self.realtime = realtime
        self._iter: Iterator[np.ndarray] | None = None
        self._reader = None

    @property
    def corrupt_frames(self) -> int:
        return 0 if self._reader is None else self._reader.corrupt_frames

    def open(self) -> None:
        from raingauge.videoio import FrameReader

        self._reader = FrameReader(self.path, mode="gray")
        if self._reader.fps:
            self.frame_rate_hz = float(self._reader.fps)
        self._iter = iter(self._reader)

    def read(self) -> np.ndarray | None:
        if self._iter is None:
            raise SourceError(f"{self.name}: not open")
        return next(self._iter, None)

    def close(self) -> None:
        self._iter = None


def _ignore_interrupts() -> None:
    """Worker processes leave Ctrl-C and SIGTERM (sent to the whole service) to the instrument,
    which flushes and then stops them in order."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def get_or_orphaned(q, parent_pid: int, poll_s: float = 1.0):
    """``q.get()`` in a worker process; None as soon as the parent process is gone (kill -9)."""
    while True:
        try:
            return q.get(timeout=poll_s)
        except queue.Empty:
            if os.getppid() != parent_pid:
                return None


def _render_worker(profile, rain_rate_mm_h: float, seed: int, chunk_s: float, buf, n_slots: int,
                   free_slots, ready, parent_pid: int) -> None:
    """Renderer process of :class:`SimulatedSource`: render frames into a shared ring of slots.

    Takes a free slot index from ``free_slots`` (None: stop), renders the next
    frame into it and puts the slot index on ``ready``; an exception is sent as
    ``("error", text)``.
    """
    import traceback

    _ignore_interrupts()
    ready.cancel_join_thread()
    try:
        from raingauge.render.simulator import simulate

        ring = np.frombuffer(buf, dtype=np.uint8).reshape((n_slots,) + tuple(profile.shape))
        k = 0
        while True:
            sim = simulate(profile, seconds=chunk_s, rain_rate_mm_h=rain_rate_mm_h, seed=seed + k,
                           truth_drops=False)
            for item in sim:
                frame = item[0] if isinstance(item, tuple) else item
                slot = get_or_orphaned(free_slots, parent_pid)
                if slot is None:
                    return
                ring[slot] = frame
                ready.put(slot)
            k += 1
    except Exception:  # noqa: BLE001 - reported to the instrument, which ends the source
        ready.put(("error", traceback.format_exc()))


class SimulatedSource(FrameSource):
    """The built-in simulated camera: :func:`raingauge.render.simulator.simulate` at a fixed rate.

    The frames are rendered ahead in a separate process (``process=True``)
    into a ring of ``prefetch`` shared-memory slots, so that rendering runs on
    another core than the gauge; :meth:`read` copies the next frame out and
    frees its slot.  The rain is continuous over ``chunk_s`` seconds; each
    following chunk starts new rain with the next seed.  The process is
    started with ``spawn`` (the instrument has threads), so a script that
    opens this source at import time needs the usual
    ``if __name__ == "__main__":`` guard, or ``process=False``.  It ends with
    the instrument: at :meth:`close`, and by itself when the instrument is
    killed.

    Parameters
    ----------
    rain_rate_mm_h : [mm/h] rain rate of the simulated rain
    profile : the camera profile rendered (its size may be reduced by ``size``)
    realtime : paced at the profile's frame rate like a camera (True: frames the
        gauge cannot take in time are dropped and counted, see :class:`Grabber`)
        or as fast as possible, nothing dropped (False)
    chunk_s : [s] seconds of continuous rain per call of the simulator
    seed : random seed of the first chunk (the next chunks use seed + 1, ...)
    limit_frames : stop after this many frames (None: for ever)
    process : render in a separate process (True) or on the calling thread
    prefetch : frames rendered ahead (slots of the shared ring)
    start_timeout_s : [s] longest wait for the renderer's first frame
    """

    def __init__(self, rain_rate_mm_h: float, profile, *, realtime: bool = True, chunk_s: float = 3600.0,
                 seed: int = 0, limit_frames: int | None = None, process: bool = True, prefetch: int = 6,
                 start_timeout_s: float = 120.0):
        if not (rain_rate_mm_h >= 0 and np.isfinite(rain_rate_mm_h)):
            raise InputError(f"simulate:{rain_rate_mm_h}: the rain rate must be a finite number >= 0 mm/h. "
                             "Fix: e.g. simulate:10")
        if int(prefetch) < 1:
            raise InputError(f"prefetch = {prefetch}: at least one frame must be rendered ahead. Fix: prefetch=6")
        self.rain_rate_mm_h = float(rain_rate_mm_h)
        self.profile = profile
        self.name = f"simulated camera at {rain_rate_mm_h:g} mm/h"
        self.frame_rate_hz = profile.frame_rate_hz
        self.realtime = realtime
        self.chunk_s = chunk_s
        self.seed = seed
        self.limit_frames = limit_frames
        self.process = bool(process)
        self.prefetch = int(prefetch)
        self.start_timeout_s = float(start_timeout_s)
        self._gen: Iterator | None = None
        self._count = 0
        self._proc = None
        self._ring = None
        self._free = None
        self._ready = None
        self._first: np.ndarray | None = None

    # ------------------------------------------------------------------ in-process rendering
    def _frames(self) -> Iterator[np.ndarray]:
        from raingauge.render.simulator import simulate

        k = 0
        while True:
            sim = simulate(self.profile, seconds=self.chunk_s, rain_rate_mm_h=self.rain_rate_mm_h,
                           seed=self.seed + k, truth_drops=False)
            for item in sim:
                frame = item[0] if isinstance(item, tuple) else item
                yield frame
            k += 1

    # ------------------------------------------------------------------ renderer process
    def _start_process(self) -> None:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")          # the instrument has threads: never fork it
        shape = tuple(self.profile.shape)
        buf = ctx.RawArray("B", self.prefetch * shape[0] * shape[1])
        self._ring = np.frombuffer(buf, dtype=np.uint8).reshape((self.prefetch,) + shape)
        self._free = ctx.Queue()
        self._ready = ctx.Queue()
        for slot in range(self.prefetch):
            self._free.put(slot)
        self._proc = ctx.Process(target=_render_worker, name="raingauge-simulated-camera", daemon=True,
                                 args=(self.profile, self.rain_rate_mm_h, self.seed, self.chunk_s, buf,
                                       self.prefetch, self._free, self._ready, os.getpid()))
        self._proc.start()

    def _next_from_process(self, timeout_s: float) -> np.ndarray | None:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                item = self._ready.get(timeout=0.5)
                break
            except queue.Empty:
                if not self._proc.is_alive():
                    raise SourceError(f"{self.name}: the renderer process ended (exit code "
                                      f"{self._proc.exitcode})") from None
                if time.monotonic() > deadline:
                    raise SourceError(f"{self.name}: no frame from the renderer in {timeout_s:.0f} s") from None
        if isinstance(item, tuple):
            raise RuntimeError(f"{self.name}: the simulator failed:\n{item[1]}")
        frame = self._ring[item].copy()
        self._free.put(item)
        return frame

    def open(self) -> None:
        self._count = 0
        if not self.process:
            self._gen = self._frames()
            return
        self.close()
        self._start_process()
        try:
            # the first frame (imports, first chunk) before the source counts as started
            self._first = self._next_from_process(self.start_timeout_s)
        except Exception:
            self.close()
            raise

    def read(self) -> np.ndarray | None:
        if self.limit_frames is not None and self._count >= self.limit_frames:
            return None
        if not self.process:
            if self._gen is None:
                raise SourceError(f"{self.name}: not open")
            self._count += 1
            return next(self._gen)
        if self._proc is None:
            raise SourceError(f"{self.name}: not open")
        if self._first is not None:
            frame, self._first = self._first, None
        else:
            try:
                frame = self._next_from_process(30.0)
            except RuntimeError as exc:
                log.error("%s", exc)
                return None                    # the simulation cannot go on: the source ends
        self._count += 1
        return frame

    def close(self) -> None:
        self._gen = None
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            self._free.put(None)
        except (OSError, ValueError):
            pass
        proc.join(timeout=2.0)
        if proc.is_alive():
            proc.kill()
            proc.join(timeout=2.0)
        for q in (self._free, self._ready):
            q.close()
            q.cancel_join_thread()
        self._free = self._ready = None
        self._ring = None
        self._first = None


def scaled_profile(profile, width_px: int, height_px: int):
    """The profile of the same camera at another resolution (field of view kept).

    The focal length [px] scales with the width and the pixel pitch [m]
    inversely, so the optics in metres stay the same; used for small
    simulated frames (``[source] size``).
    """
    scale = width_px / profile.width_px
    changes = {"width_px": int(width_px), "height_px": int(height_px),
               "focal_length_px": profile.focal_length_px * scale, "principal_point_px": None}
    if profile.pixel_pitch_m is not None:
        changes["pixel_pitch_m"] = profile.pixel_pitch_m / scale
    return profile.replace(**changes)


def open_source(spec: str, *, profile, realtime: bool = True, seed: int = 0) -> FrameSource:
    """A :class:`FrameSource` for a specification (see the module docstring)."""
    spec = str(spec).strip()
    if spec.startswith("simulate:") or spec == "simulate":
        text = spec.partition(":")[2] or "10"
        try:
            rate = float(text)
        except ValueError:
            raise InputError(f"source {spec!r}: the rain rate {text!r} is not a number. Fix: e.g. simulate:10") from None
        return SimulatedSource(rate, profile, realtime=realtime, seed=seed)
    if spec.isdigit():
        return CameraSource(int(spec), frame_rate_hz=profile.frame_rate_hz)
    if spec.lower().startswith(_STREAM_PREFIXES):
        return CameraSource(spec, frame_rate_hz=profile.frame_rate_hz)
    path = Path(spec).expanduser()
    if path.exists() and stat.S_ISCHR(path.stat().st_mode):
        return CameraSource(str(path), frame_rate_hz=profile.frame_rate_hz)   # /dev/video0, udev symlink
    if path.exists():
        return FileSource(path, frame_rate_hz=profile.frame_rate_hz, realtime=realtime)
    raise InputError(
        f"source {spec!r}: no such file or folder, and not a camera index or URL. Fix: use simulate:RATE, "
        "a device index such as 0, an rtsp:// or http:// URL, a video file or a folder of images"
    )


class Grabber:
    """Read a source on its own thread; reconnect, skip corrupt frames, time-stamp.

    Frames come out of :meth:`get` as ``(t_s, frame)`` with ``t_s`` [s] since
    :meth:`start`: the frame index over the frame rate for recorded and
    simulated sources, the monotonic clock for live ones.

    Attributes
    ----------
    connected : the source is delivering
    corrupt_frames : frames skipped as unreadable or of the wrong size
    reconnects : successful reconnections after a loss
    dropped_frames : frames of a paced source dropped because the loop was behind
    clock_slip_s : [s] how far a paced recorded source fell behind the wall clock
    finished : a recorded source reached its end
    """

    def __init__(self, source: FrameSource, *, shape: tuple[int, int] | None = None,
                 backoff_s: tuple[float, float] = (0.5, 60.0), queue_size: int = 16):
        if int(queue_size) < 1:
            raise InputError(f"queue_size = {queue_size}: the frame queue needs at least one place. Fix: 8")
        self.source = source
        self.shape = shape
        self.backoff_s = backoff_s
        self.queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self.connected = False
        self.corrupt_frames = 0
        self.reconnects = 0
        self.dropped_frames = 0
        self.finished = threading.Event()
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="grabber", daemon=True)
        self._t0 = 0.0
        self._go = threading.Event()
        self._pace_t0: float | None = None
        self.clock_slip_s = 0.0
        self._warned_shape = False
        self._warned_drop = False
        self._warned_slow = False

    def start(self, *, hold: bool = False) -> "Grabber":
        """Start the thread: it connects at once; with ``hold`` it reads no frame before :meth:`release`.

        Holding lets the consumer finish its own start-up (the gauge's sample
        volume takes seconds) while the source starts, without a paced
        source dropping frames meanwhile.
        """
        self._t0 = time.monotonic()
        if not hold:
            self._go.set()
        self._thread.start()
        return self

    def release(self) -> None:
        """Start delivering frames (after ``start(hold=True)``); the clock starts now."""
        if not self._go.is_set():
            self._t0 = time.monotonic()
            self._go.set()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        try:
            self.source.close()
        except Exception:  # noqa: BLE001
            log.exception("closing %s", self.source.name)

    def get(self, timeout: float) -> tuple[float, np.ndarray] | None:
        """Next ``(t_s, frame)``, or None when none came within ``timeout`` [s]."""
        try:
            return self.queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def now_s(self) -> float:
        """Seconds since start on the grabber's clock."""
        return time.monotonic() - self._t0

    def _check(self, frame) -> np.ndarray | None:
        if frame is None or not isinstance(frame, np.ndarray) or frame.size == 0:
            return None
        frame = to_gray(frame)
        if frame.ndim != 2 or frame.dtype != np.uint8:
            return None
        if self.shape is not None and frame.shape != tuple(self.shape):
            if not self._warned_shape:
                log.error("%s delivers %dx%d frames but the camera profile says %dx%d; frames skipped. "
                          "Fix: set width_px/height_px of the profile to the camera's resolution",
                          self.source.name, frame.shape[1], frame.shape[0], self.shape[1], self.shape[0])
                self._warned_shape = True
            return None
        return frame

    def _put(self, item) -> None:
        if self.paced:
            while True:
                try:
                    self.queue.put_nowait(item)
                    return
                except queue.Full:
                    while True:                      # drop the backlog, keep the newest frame
                        try:
                            self.queue.get_nowait()
                        except queue.Empty:
                            break
                        self.dropped_frames += 1
                    if not self._warned_drop:
                        self._warned_drop = True
                        log.warning("%s: the gauge is slower than the camera's %g frames/s; frames it cannot "
                                    "take are dropped, counted and flagged (dropped_frames)",
                                    self.source.name, self.source.frame_rate_hz)
        while not self._stop.is_set():
            try:
                self.queue.put(item, timeout=0.2)
                return
            except queue.Full:
                continue

    def _pace(self, t: float) -> None:
        """Hold a recorded frame until its time ``t`` [s] on the wall clock.

        The clock starts with the first frame (start-up is not counted).  A
        source that cannot produce frames in real time (a renderer slower than
        the frame rate) slips: its clock is moved on rather than bursting to
        catch up, and this is logged once.
        """
        now = time.monotonic()
        if self._pace_t0 is None:
            self._pace_t0 = now - t
        wait = self._pace_t0 + t - now
        if wait > 0:
            self._stop.wait(wait)
        elif wait < -0.5:
            self._pace_t0 -= wait
            self.clock_slip_s -= wait
            if not self._warned_slow:
                self._warned_slow = True
                log.warning("%s delivers frames slower than %g frames/s: its clock slips behind the wall "
                            "clock (nothing is dropped for it)", self.source.name, self.source.frame_rate_hz)

    def _run(self) -> None:
        src = self.source
        delay = self.backoff_s[0]
        index = 0
        ever_connected = False
        while not self._stop.is_set():
            if not self.connected:
                try:
                    src.open()
                except (SourceError, InputError, OSError) as exc:
                    if not src.live:
                        self.error = exc
                        self.finished.set()
                        return
                    log.warning("%s: %s; retrying in %.1f s", src.name, exc, delay)
                    self._stop.wait(delay)
                    delay = min(delay * 2, self.backoff_s[1])
                    continue
                except Exception as exc:  # noqa: BLE001 - e.g. the simulator failing
                    self.error = exc
                    log.exception("%s cannot start", src.name)
                    self.finished.set()
                    return
                if ever_connected:
                    self.reconnects += 1
                    log.info("%s reconnected", src.name)
                ever_connected = True
                self.connected = True
                delay = self.backoff_s[0]
            while not self._go.is_set() and not self._stop.is_set():
                self._go.wait(0.1)
            if self._stop.is_set():
                break
            try:
                frame = src.read()
            except SourceError as exc:
                log.warning("%s lost: %s", src.name, exc)
                self.connected = False
                try:
                    src.close()
                except Exception:  # noqa: BLE001
                    pass
                continue
            except Exception as exc:  # noqa: BLE001 - a decoder error on one frame
                self.corrupt_frames += 1
                log.debug("%s: corrupt frame (%s)", src.name, exc)
                continue
            if frame is None:
                if src.live:
                    self.connected = False
                    continue
                self.connected = False
                self.finished.set()
                return
            # A recorded frame holds its time slot even when it is corrupt.
            t = self.now_s() if src.live else (index + self.source_corrupt_frames) / src.frame_rate_hz
            index += 1
            checked = self._check(frame)
            if checked is None:
                self.corrupt_frames += 1
                continue
            if not src.live and src.realtime:
                self._pace(t)
            self._put((t, checked))
        self.connected = False

    @property
    def paced(self) -> bool:
        """The source runs on its own clock (camera, stream, or played in real time)."""
        return bool(self.source.live or self.source.realtime)

    @property
    def source_corrupt_frames(self) -> int:
        """Corrupt frames the source itself skipped (unreadable images in a folder)."""
        return int(getattr(self.source, "corrupt_frames", 0) or 0)
