"""Serial output of the NMEA sentences, off the measuring loop.

:class:`SerialWriter` owns a thread and a bounded queue.  :meth:`publish`
never blocks: when the queue is full (a stuck port) the oldest record is
dropped and counted.  The thread opens the port lazily, writes with a write
timeout, and on any error closes the port, raises :attr:`fault` and retries
with exponential backoff, so unplugging a USB adapter and plugging it back in
recovers without a restart.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any, Callable

from firmware_interface.nmea import sentences_for

__all__ = ["SerialWriter", "parse_port_spec"]

log = logging.getLogger("raingauge.serial")


#: Baud rates a serial adapter accepts in practice [bit/s].
MIN_BAUD, MAX_BAUD = 50, 4_000_000


def parse_port_spec(spec: str, *, default_baud: int = 9600) -> tuple[str, int]:
    """``PORT[:BAUD]`` -> (port, baud).

    ``/dev/ttyUSB0:4800``, ``COM3``, ``COM3:19200``.  A pyserial URL
    (``socket://host:7000``, ``rfc2217://host:2217``, ``loop://``) is taken
    whole: its colons belong to the URL; give its baud as ``URL@BAUD``.
    Device paths that contain colons themselves
    (``/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0``) are kept whole
    when the last part is not a number.

    Raises
    ------
    ConfigError
        when the part after the last colon looks like a baud rate but is
        not a whole number in [50, 4000000] (``/dev/ttyUSB0:96OO``), or the
        port is empty.
    """
    from raingauge.errors import ConfigError

    spec = str(spec).strip()
    fix = "Fix: write PORT or PORT:BAUD, e.g. /dev/ttyUSB0:9600 (a pyserial URL as socket://host:7000@9600)"
    if not spec:
        raise ConfigError(f"serial port is empty. {fix}")
    if "://" in spec:
        port, sep, baud = spec.rpartition("@")
        if not sep:
            return spec, int(default_baud)
    else:
        port, sep, baud = spec.rpartition(":")
        if not sep:
            return spec, int(default_baud)
        # a colon inside a device name (by-path names) is not a baud separator
        looks_like_baud = baud[:1].isdigit() and len(baud) <= 9 and not any(ch in baud for ch in "./-_:")
        if not baud.isdigit() and not looks_like_baud:
            return spec, int(default_baud)
    if not port:
        raise ConfigError(f"serial port {spec!r} has a baud rate but no port. {fix}")
    if not baud.isdigit():
        raise ConfigError(f"serial port {spec!r}: baud rate {baud!r} is not a whole number. {fix}")
    rate = int(baud)
    if not MIN_BAUD <= rate <= MAX_BAUD:
        raise ConfigError(f"serial port {spec!r}: baud rate {rate} is outside {MIN_BAUD}-{MAX_BAUD} bit/s. {fix}")
    return port, rate


class SerialWriter:
    """Write ``$PRGRR`` and ``$WIXDR`` for every published record.

    Parameters
    ----------
    port : device path or any pyserial URL (``/dev/ttyUSB0``, ``loop://``)
    baudrate : [bit/s]
    queue_size : records buffered before the oldest is dropped
    write_timeout_s : [s] a write that cannot finish in this time counts as a failure
    max_age_s : [s] records older than this when the port comes back are dropped (stale)
    backoff_s : (first, max) [s] reconnect delays
    formatter : record -> list of lines (default :func:`firmware_interface.nmea.sentences_for`)
    """

    def __init__(self, port: str, baudrate: int = 9600, *, queue_size: int = 100,
                 write_timeout_s: float = 2.0, max_age_s: float = 600.0,
                 backoff_s: tuple[float, float] = (0.5, 30.0),
                 formatter: Callable[[dict[str, Any]], list[str]] = sentences_for):
        self.port = port
        self.baudrate = int(baudrate)
        self.write_timeout_s = float(write_timeout_s)
        self.max_age_s = float(max_age_s)
        self.backoff_s = backoff_s
        self.formatter = formatter
        self._queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self._stop = threading.Event()
        self._serial = None
        self.sent = 0
        self.dropped = 0
        self.errors = 0
        self.fault = False
        self.last_error: str | None = None
        self._thread = threading.Thread(target=self._run, name="serial-out", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ API
    def publish(self, record: dict[str, Any]) -> None:
        """Queue a record; never blocks (drops the oldest when full)."""
        item = (time.monotonic(), record)
        while True:
            try:
                self._queue.put_nowait(item)
                return
            except queue.Full:
                try:
                    self._queue.get_nowait()
                    self.dropped += 1
                    self.fault = True
                except queue.Empty:
                    pass

    def close(self, timeout_s: float = 3.0) -> None:
        """Send what is queued (up to ``timeout_s``), then stop the thread and close the port."""
        deadline = time.monotonic() + timeout_s
        while not self._queue.empty() and time.monotonic() < deadline and not self.fault:
            time.sleep(0.02)
        self._stop.set()
        self._thread.join(timeout=max(0.1, deadline - time.monotonic()) + self.write_timeout_s)
        self._close_port()

    # ------------------------------------------------------------------ thread
    def _open(self):
        import serial

        return serial.serial_for_url(self.port, baudrate=self.baudrate, timeout=0,
                                     write_timeout=self.write_timeout_s)

    def _close_port(self) -> None:
        if self._serial is not None:
            try:
                self._serial.close()
            except Exception:  # noqa: BLE001 - closing a dead port
                pass
            self._serial = None

    def _run(self) -> None:
        delay = self.backoff_s[0]
        while not self._stop.is_set():
            try:
                t_queued, record = self._queue.get(timeout=0.2)
            except queue.Empty:
                continue
            if time.monotonic() - t_queued > self.max_age_s:
                self.dropped += 1
                continue
            while not self._stop.is_set():
                try:
                    if self._serial is None:
                        self._serial = self._open()
                    data = "".join(self.formatter(record)).encode("ascii")
                    written = self._serial.write(data)
                    if written is not None and written != len(data):
                        raise OSError(f"wrote {written} of {len(data)} bytes")
                    self._serial.flush()
                    self.sent += 1
                    if self.fault and self._queue.qsize() == 0:
                        log.info("serial output %s recovered", self.port)
                    self.fault = self._queue.full()
                    delay = self.backoff_s[0]
                    break
                except Exception as exc:  # noqa: BLE001 - any port failure: retry later
                    self.errors += 1
                    self.last_error = f"{type(exc).__name__}: {exc}"
                    if not self.fault:
                        log.warning("serial output %s failed (%s); retrying with backoff", self.port, self.last_error)
                    self.fault = True
                    self._close_port()
                    self._stop.wait(delay)
                    delay = min(delay * 2, self.backoff_s[1])
