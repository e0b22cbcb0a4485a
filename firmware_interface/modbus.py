"""Modbus TCP and RTU server publishing the gauge's records (pymodbus 3.16) [ModbusAP] [ModbusSerial].

The register map comes from :mod:`firmware_interface.fields` (see
``docs/modbus_registers.md``).  Input registers (function 04) hold the last
record; holding registers (03/06/16/23) hold three settings:

* 0 - write ``0x3247`` to reset accumulation and rain duration (reads 0);
* 1 - the Modbus unit id (1-247), effective right after the reply;
* 2 - the averaging window [s] (10-3600, a whole multiple of the step).

Anything else written (another value, another address) is refused with an
exception response (02 illegal address, 03 illegal value) and changes nothing.
Coils and discrete inputs do not exist: functions 01, 02, 05, 15 and 22 answer
exception 01 (illegal function), as do unknown function codes.  Function 43/14
(read device identification) answers vendor, product and version.

:class:`ModbusOutput` runs the servers on an asyncio loop in its own thread.
:meth:`ModbusOutput.publish` only hands the record to that loop and returns at
once, so a slow or hostile client never stalls measurement.

Notes
-----
pymodbus 3.16 serves its "simulator" datastore (``SimDevice``/``SimData``);
the unit id is fixed when a ``SimDevice`` is built, so the server's store is
wrapped in :class:`_UnitCore`, which answers the current unit id (plus 0 and
255 over TCP, the "this device" ids of Modbus TCP gateways) and treats any
other id as absent: RTU stays silent, as a slave on a shared line must, and
TCP answers exception 0B (gateway target failed to respond).
"""

from __future__ import annotations

import asyncio
import logging
import threading
from typing import Any, Callable

from firmware_interface.fields import (
    HOLDING_REGISTERS,
    RESET_MAGIC,
    input_register_image,
    record_defaults,
)

__all__ = ["ModbusOutput", "ModbusProcess", "parse_host_port", "identity_info", "VENDOR", "PRODUCT_CODE"]

log = logging.getLogger("raingauge.modbus")

VENDOR = "raingauge"
PRODUCT_CODE = "RGR"
PRODUCT_NAME = "raingauge camera rain gauge"

#: function codes that would address coils or discrete inputs, or mask-write
_NO_SUCH_FUNCTION = (1, 2, 5, 15, 22)
#: function codes the device implements
_SUPPORTED_FUNCTIONS = (3, 4, 6, 16, 23, 43)


def parse_host_port(spec: str, *, default_port: int = 502) -> tuple[str, int]:
    """``HOST:PORT`` (or ``:PORT``, ``HOST``) -> (host, port)."""
    from raingauge.errors import ConfigError

    host, sep, port = spec.rpartition(":")
    if not sep:
        host, port = spec, str(default_port)
    if not port.isdigit():
        raise ConfigError(f"Modbus TCP address {spec!r}: port {port!r} is not a number 0-65535. "
                          "Fix: e.g. 127.0.0.1:5020")
    if not 0 <= int(port) <= 65535:
        raise ConfigError(f"Modbus TCP address {spec!r}: port must be 0-65535. Fix: e.g. 127.0.0.1:5020")
    return host or "0.0.0.0", int(port)


def identity_info(*, model: str = "", version: str | None = None) -> dict[str, str]:
    """Device identification objects (function 43/14) by name."""
    if version is None:
        from raingauge import __version__ as version
    return {
        "VendorName": VENDOR,
        "ProductCode": PRODUCT_CODE,
        "MajorMinorRevision": version,
        "ProductName": PRODUCT_NAME,
        "ModelName": model or "camera",
    }


class _UnitCore:
    """The server's store: one device memory answering a changeable unit id."""

    def __init__(self, runtime, unit_id: int):
        self.runtime = runtime
        self.unit_id = unit_id

    def _device(self, device_id: int, *, tcp: bool):
        from pymodbus.exceptions import NoSuchIdException

        if device_id == self.unit_id or (tcp and device_id in (0, 255)):
            return self.runtime
        raise NoSuchIdException(f"unit id {device_id} (this device answers {self.unit_id})")

    def device_ids(self) -> list[int]:
        return [self.unit_id]


class _BoundCore:
    """Per-server view of a :class:`_UnitCore` (TCP accepts 0 and 255 as well)."""

    def __init__(self, core: _UnitCore, *, tcp: bool):
        self.core = core
        self.tcp = tcp

    def device_ids(self) -> list[int]:
        return self.core.device_ids()

    async def async_getValues(self, device_id, func_code, address, count=1):
        return await self.core._device(device_id, tcp=self.tcp).async_getValues(func_code, address, count)

    async def async_setValues(self, device_id, func_code, address, values):
        return await self.core._device(device_id, tcp=self.tcp).async_setValues(func_code, address, values)


class _TcpFunctionEcho:
    """Make exception replies to unknown function codes name that function (TCP).

    pymodbus answers a request it cannot decode with function code 0x80 and
    exception 01; the Modbus specification wants the request's code + 0x80, and
    exception 03 when a supported function carries a bad count.  The request's
    function code is remembered by transaction id from the raw MBAP frames and
    patched into such replies.
    """

    def __init__(self, size: int = 1024):
        self.size = size
        self.by_tid: dict[bytes, int] = {}

    def __call__(self, sending: bool, data: bytes) -> bytes:
        if len(data) < 8:
            return data
        tid = bytes(data[0:2])
        if not sending:
            if len(self.by_tid) >= self.size:
                self.by_tid.clear()
            self.by_tid[tid] = data[7]
            return data
        if len(data) >= 9 and data[7] == 0x80:
            fc = self.by_tid.get(tid)
            if fc is not None and fc < 0x80:
                # A supported function that failed to decode had a bad count or length.
                code = 0x03 if fc in _SUPPORTED_FUNCTIONS else data[8]
                return data[:7] + bytes([fc | 0x80, code]) + data[9:]
        return data


class ModbusOutput:
    """Modbus TCP and/or RTU slave serving the last record.

    Parameters
    ----------
    tcp : (host, port) or None.  Port 0 picks a free port (see :attr:`tcp_port`).
    rtu : dict(port=..., baudrate=19200, parity="N", stopbits=1) or None.
    unit_id : Modbus unit id 1-247.
    device_id : 0-255, high byte of input register 0.
    window_s, step_s : [s] current window and the step it must be a multiple of.
    on_reset : called (from the server thread) when 0x3247 is written.
    on_setting : called as ``on_setting(name, value)`` for ``unit_id`` / ``window_s``.
    model : ModelName in the device identification (the camera profile name).
    """

    def __init__(self, *, tcp: tuple[str, int] | None = None, rtu: dict | None = None,
                 unit_id: int = 1, device_id: int = 1, window_s: float = 60.0, step_s: float = 10.0,
                 on_reset: Callable[[], None] | None = None,
                 on_setting: Callable[[str, int], None] | None = None, model: str = ""):
        from raingauge.errors import ConfigError

        if tcp is None and rtu is None:
            raise ConfigError("Modbus output needs a TCP address or an RTU port. Fix: give --modbus-tcp HOST:PORT or --modbus-rtu PORT[:BAUD]")
        if not 1 <= int(unit_id) <= 247:
            raise ConfigError(f"Modbus unit id {unit_id} is out of range. Fix: use 1-247")
        self.tcp = tcp
        self.rtu = rtu
        self.unit_id = int(unit_id)
        self.device_id = int(device_id)
        self.window_s = int(round(window_s))
        self.step_s = float(step_s)
        self.on_reset = on_reset
        self.on_setting = on_setting
        self.model = model
        self.tcp_port: int | None = None
        self.requests_refused = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._servers: list = []
        self._core: _UnitCore | None = None
        self._status = 0
        self._last_record: dict[str, Any] = record_defaults()

    # ------------------------------------------------------------------ device model
    def _simdevice(self):
        from pymodbus.simulator import DataType, SimData, SimDevice

        image = input_register_image(self._last_record, device_id=self.device_id)
        inputs = [SimData(address=a, values=words, datatype=DataType.REGISTERS) for a, words in sorted(image.items())]
        holding = [SimData(address=0, values=[0, self.unit_id, self.window_s], datatype=DataType.REGISTERS)]
        # Coils / discrete inputs must be declared; every access to them is refused by _action.
        coils = [SimData(address=0, values=[False] * 16, datatype=DataType.BITS)]
        discrete = [SimData(address=0, values=[False] * 16, datatype=DataType.BITS)]
        return SimDevice(id=self.unit_id, simdata=(coils, discrete, holding, inputs), action=self._action)

    def _validate_holding(self, address: int, values: list[int]) -> bool:
        by_addr = {h.address: h for h in HOLDING_REGISTERS}
        for i, v in enumerate(values):
            h = by_addr.get(address + i)
            if h is None:
                return False
            if h.special:
                if v not in h.special:
                    return False
            elif not h.minimum <= v <= h.maximum:
                return False
            if h.name == "window_s" and (v % self.step_s) != 0:
                return False
        return True

    async def _action(self, function_code, start_address, address, count, registers, set_values):
        from pymodbus.constants import ExcCodes

        if function_code in _NO_SUCH_FUNCTION:
            self.requests_refused += 1
            return ExcCodes.ILLEGAL_FUNCTION
        if function_code in (3, 4) or not set_values:
            return None  # reads, and our own updates (clients never write with 03/04)
        values = [int(v) for v in set_values]
        if not self._validate_holding(address, values):
            self.requests_refused += 1
            return ExcCodes.ILLEGAL_VALUE
        loop = asyncio.get_running_loop()
        by_addr = {h.address: h.name for h in HOLDING_REGISTERS}
        for i, v in enumerate(values):
            name = by_addr[address + i]
            if name == "reset":
                # After the reply has echoed the value: read back 0 again.
                loop.call_soon(registers.__setitem__, 0 - start_address, 0)
                loop.call_soon(self._do_reset)
            elif name == "unit_id" and v != self.unit_id:
                loop.call_soon(self._set_unit_id, v)
            elif name == "window_s" and v != self.window_s:
                self.window_s = v
                self._notify("window_s", v)
        return None

    def _notify(self, name: str, value: int) -> None:
        if self.on_setting is not None:
            try:
                self.on_setting(name, value)
            except Exception:  # noqa: BLE001 - never let a callback break the server
                log.exception("setting callback for %s failed", name)

    def _set_unit_id(self, value: int) -> None:
        log.info("Modbus unit id changed %d -> %d", self.unit_id, value)
        self.unit_id = value
        self._core.unit_id = value
        self._notify("unit_id", value)

    def _do_reset(self) -> None:
        log.info("accumulation reset over Modbus (0x%04X)", RESET_MAGIC)
        rec = dict(self._last_record)
        rec["accumulation_mm"] = 0.0
        rec["rain_duration_s"] = 0.0
        self._last_record = rec
        asyncio.get_running_loop().create_task(self._write_record(rec))
        if self.on_reset is not None:
            try:
                self.on_reset()
            except Exception:  # noqa: BLE001
                log.exception("reset callback failed")

    # ------------------------------------------------------------------ lifecycle
    def start(self, timeout_s: float = 10.0) -> "ModbusOutput":
        """Start the servers on their own thread; raises ConfigError when a port cannot be opened."""
        from raingauge.errors import ConfigError

        pm_log = logging.getLogger("pymodbus")
        if pm_log.level == logging.NOTSET:
            # pymodbus logs every malformed frame and foreign unit id at ERROR with a hex
            # dump; on a field line that is noise. Configure "pymodbus" to see it.
            pm_log.setLevel(logging.CRITICAL)
        ready = threading.Event()
        error: list[BaseException] = []

        def run() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            asyncio.set_event_loop(loop)
            try:
                loop.run_until_complete(self._start_servers())
            except BaseException as exc:  # noqa: BLE001 - reported to start()
                error.append(exc)
                ready.set()
                loop.close()
                return
            ready.set()
            try:
                loop.run_forever()
            finally:
                loop.run_until_complete(self._shutdown_servers())
                loop.close()

        self._thread = threading.Thread(target=run, name="modbus", daemon=True)
        self._thread.start()
        if not ready.wait(timeout_s):
            raise ConfigError("Modbus server did not start in time")
        if error:
            exc = error[0]
            where = []
            if self.tcp:
                where.append(f"TCP {self.tcp[0]}:{self.tcp[1]}")
            if self.rtu:
                where.append(f"RTU {self.rtu.get('port')}")
            raise ConfigError(f"Modbus server cannot listen on {', '.join(where)}: {exc}. "
                              "Fix: choose a free port (or one above 1024 without root) / an existing serial device") from None
        return self

    async def _start_servers(self) -> None:
        from pymodbus import ModbusDeviceIdentification
        from pymodbus.server import ModbusSerialServer, ModbusTcpServer

        device = self._simdevice()
        identity = ModbusDeviceIdentification(info_name=identity_info(model=self.model))
        if self.tcp is not None:
            server = ModbusTcpServer(device, identity=identity, address=tuple(self.tcp),
                                     trace_packet=_TcpFunctionEcho())
            self._adopt(server, tcp=True)
            await server.serve_forever(background=True)
            sockets = getattr(server.transport, "sockets", None) or []
            self.tcp_port = sockets[0].getsockname()[1] if sockets else self.tcp[1]
            self._servers.append(server)
        if self.rtu is not None:
            rtu = dict(self.rtu)
            server = ModbusSerialServer(
                device, identity=identity, port=rtu["port"], baudrate=int(rtu.get("baudrate", 19200)),
                parity=rtu.get("parity", "N"), stopbits=int(rtu.get("stopbits", 1)),
                ignore_missing_devices=True,
            )
            self._adopt(server, tcp=False)
            await server.serve_forever(background=True)
            self._servers.append(server)

    def _adopt(self, server, *, tcp: bool) -> None:
        """Replace the server's per-id store by the shared, unit-id aware one."""
        runtime = next(iter(server.context.devices.values()))
        if self._core is None:
            self._core = _UnitCore(runtime, self.unit_id)
        server.context = _BoundCore(self._core, tcp=tcp)

    async def _shutdown_servers(self) -> None:
        for server in self._servers:
            try:
                await server.shutdown()
            except Exception:  # noqa: BLE001
                log.exception("Modbus server shutdown")
        self._servers.clear()

    def stop(self) -> None:
        """Stop the servers and the thread."""
        if self._loop is not None and self._thread is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=5)
        self._thread = None

    def __enter__(self) -> "ModbusOutput":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ updates
    async def _write_record(self, record: dict[str, Any]) -> None:
        image = input_register_image(record, device_id=self.device_id)
        image[1] = [self._status]
        runtime = self._core.runtime
        # No suspension point between the writes: a client sees one whole record.
        for address, words in image.items():
            await runtime.async_setValues(4, address, words)

    async def _write_status(self, status: int) -> None:
        await self._core.runtime.async_setValues(4, 1, [status])

    def publish(self, record: dict[str, Any]) -> None:
        """Serve ``record`` from now on (non-blocking, thread-safe)."""
        self._last_record = dict(record)
        if record.get("status") is not None:
            self._status = int(record["status"]) & 0xFFFF
        if self._loop is not None and self._core is not None and not self._loop.is_closed():
            asyncio.run_coroutine_threadsafe(self._write_record(self._last_record), self._loop)

    def set_status(self, status: int) -> None:
        """Update only the status register (e.g. camera lost between records)."""
        self._status = int(status) & 0xFFFF
        if self._loop is not None and self._core is not None and not self._loop.is_closed():
            asyncio.run_coroutine_threadsafe(self._write_status(self._status), self._loop)

    def set_window(self, window_s: float) -> None:
        """Mirror a window change made elsewhere (config) into holding register 2."""
        self.window_s = int(round(window_s))

        async def write():
            await self._core.runtime.async_setValues(3, 2, [self.window_s])

        if self._loop is not None and self._core is not None:
            asyncio.run_coroutine_threadsafe(write(), self._loop)


# ---------------------------------------------------------------------- in its own process
def _child_main() -> int:
    """``python -m firmware_interface.modbus``: the server process of :class:`ModbusProcess`.

    Reads JSON lines on stdin (first the :class:`ModbusOutput` arguments, then
    ``["publish", record]``, ``["status", word]``, ``["window", s]``), writes
    JSON event lines on its own stdout (``["started", port]``, ``["error", text]``,
    ``["reset"]``, ``["setting", name, value]``) and exits at end of input, which
    is also what happens when the instrument dies.
    """
    import json
    import os
    import sys

    events = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # anything else printed goes to stderr, not into the event stream
    lock = threading.Lock()

    def emit(*event) -> None:
        with lock:
            events.write(json.dumps(event) + "\n")

    kwargs = json.loads(sys.stdin.readline() or "{}")
    nice = int(kwargs.pop("nice", 0))
    if nice:
        try:
            os.nice(nice)  # measurement first: the server yields the CPU to the gauge
        except OSError:
            pass
    if kwargs.get("tcp") is not None:
        kwargs["tcp"] = tuple(kwargs["tcp"])
    out = ModbusOutput(**kwargs, on_reset=lambda: emit("reset"),
                       on_setting=lambda name, value: emit("setting", name, value))
    try:
        out.start()
    except Exception as exc:  # noqa: BLE001 - reported to the parent
        emit("error", str(exc))
        return 1
    emit("started", out.tcp_port)
    try:
        for line in sys.stdin:
            try:
                cmd = json.loads(line)
            except ValueError:
                continue
            kind = cmd[0]
            if kind == "publish":
                out.publish(cmd[1])
            elif kind == "status":
                out.set_status(cmd[1])
            elif kind == "window":
                out.set_window(cmd[1])
            elif kind == "stop":
                break
    finally:
        out.stop()
    return 0


class ModbusProcess:
    """:class:`ModbusOutput` run in a child process, same interface.

    Serving many clients costs CPU time in the Python interpreter that holds
    it; in a separate process a flood of requests cannot take the interpreter
    lock from the measuring loop.  The child is ``python -m
    firmware_interface.modbus``; records go to it as JSON lines through a
    queue and a writer thread (``publish`` never blocks: when the child falls
    behind, records are dropped and :attr:`fault` is raised), resets and
    setting changes come back and call ``on_reset`` / ``on_setting`` on a
    thread of this process.  The child runs at a lower priority (``nice``,
    default +10) so that when the CPU is short the gauge keeps it and Modbus
    answers a little later; it exits when its input closes, also when this
    process dies.
    """

    def __init__(self, *, on_reset: Callable[[], None] | None = None,
                 on_setting: Callable[[str, int], None] | None = None, nice: int = 10, **kwargs):
        ModbusOutput(**kwargs)  # validate the arguments here, with the same errors
        self.kwargs = dict(kwargs, nice=int(nice))
        self.on_reset = on_reset
        self.on_setting = on_setting
        self.tcp = kwargs.get("tcp")
        self.tcp_port: int | None = None
        self.fault = False
        self.dropped = 0
        self._proc = None
        self._queue = None
        self._threads: list[threading.Thread] = []

    def start(self, timeout_s: float = 30.0) -> "ModbusProcess":
        import json
        import queue as _queue
        import subprocess
        import sys

        from raingauge.errors import ConfigError

        self._proc = subprocess.Popen([sys.executable, "-m", "firmware_interface.modbus"],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1)
        self._proc.stdin.write(json.dumps(self.kwargs) + "\n")
        self._proc.stdin.flush()
        first: list = []
        ready = threading.Event()

        def read_first():
            line = self._proc.stdout.readline()
            first.append(json.loads(line) if line else ["error", "the server process ended at start"])
            ready.set()

        threading.Thread(target=read_first, daemon=True).start()
        if not ready.wait(timeout_s):
            self._kill()
            raise ConfigError("Modbus server process did not start in time")
        if first[0][0] != "started":
            self._kill()
            raise ConfigError(first[0][1])
        self.tcp_port = first[0][1]
        self._queue = _queue.Queue(maxsize=1000)
        for target, name in ((self._write_commands, "modbus-commands"), (self._read_events, "modbus-events")):
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)
        return self

    def _kill(self) -> None:
        if self._proc is not None and self._proc.poll() is None:
            self._proc.kill()
        if self._proc is not None:
            self._proc.wait(5)

    def _write_commands(self) -> None:
        import json

        while True:
            cmd = self._queue.get()
            try:
                self._proc.stdin.write(json.dumps(cmd) + "\n")
                self._proc.stdin.flush()
            except (OSError, ValueError):
                if not self.fault:
                    log.error("Modbus server process is gone (exit code %s)", self._proc.poll())
                self.fault = True
                return
            if cmd[0] == "stop":
                return

    def _read_events(self) -> None:
        import json

        for line in self._proc.stdout:
            try:
                ev = json.loads(line)
                if ev[0] == "reset" and self.on_reset is not None:
                    self.on_reset()
                elif ev[0] == "setting" and self.on_setting is not None:
                    self.on_setting(ev[1], ev[2])
            except Exception:  # noqa: BLE001
                log.exception("Modbus event %r", line)

    def _send(self, cmd) -> None:
        import queue as _queue

        if self._queue is None:
            return
        try:
            self._queue.put_nowait(cmd)
        except _queue.Full:
            self.dropped += 1
            self.fault = True

    def publish(self, record: dict[str, Any]) -> None:
        self._send(["publish", _jsonable(record)])

    def set_status(self, status: int) -> None:
        self._send(["status", int(status)])

    def set_window(self, window_s: float) -> None:
        self._send(["window", float(window_s)])

    def stop(self) -> None:
        if self._proc is None:
            return
        self._send(["stop"])
        try:
            self._proc.wait(5)
        except Exception:  # noqa: BLE001 - subprocess.TimeoutExpired
            self._kill()
        for t in self._threads:
            t.join(2)
        for f in (self._proc.stdin, self._proc.stdout):
            try:
                f.close()
            except (OSError, ValueError):
                pass
        self._proc = None

    def __enter__(self) -> "ModbusProcess":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _jsonable(record: dict[str, Any]) -> dict[str, Any]:
    """Plain JSON types (numpy scalars and arrays to floats and lists)."""
    out: dict[str, Any] = {}
    for k, v in record.items():
        if hasattr(v, "tolist"):
            v = v.tolist()
        elif isinstance(v, (list, tuple)):
            v = [x.item() if hasattr(x, "item") else x for x in v]
        out[k] = v
    return out


if __name__ == "__main__":  # pragma: no cover - the child of ModbusProcess
    raise SystemExit(_child_main())
