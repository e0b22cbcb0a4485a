"""Modbus TCP and RTU, polled by clients written elsewhere (pyModbusTCP, umodbus, minimalmodbus)."""

from __future__ import annotations

import os
import random
import select
import socket
import struct
import threading
import time

import pytest

from firmware_interface import fields as F
from firmware_interface.modbus import ModbusOutput

pyModbusTCP = pytest.importorskip("pyModbusTCP.client")


def _record(**kw):
    rec = F.record_defaults()
    rec.update(time_unix=1_700_000_000.0, rain_rate_mm_h=12.34, accumulation_mm=1234.56,
               drops_counted=321, dm_mm=1.55, z_dbz=-3.2, intensity_class=3, synop_4680=62,
               status=F.status_word(camera_ok=True, rain_detected=True, calibrated=True),
               nt_m3=150.0, rain_rate_ci95_lo_mm_h=10.0, rain_rate_ci95_hi_mm_h=15.0,
               window_s=60.0, rain_duration_s=600.0,
               dsd_n_m3_mm=[0.0] + [10.0 ** (k / 10) for k in range(31)],
               dsd_d_mm=[0.1 * k for k in range(32)])
    rec.update(kw)
    return rec


class Server:
    def __init__(self, **kw):
        self.resets = []
        self.settings = []
        self.out = ModbusOutput(tcp=("127.0.0.1", 0), device_id=7, on_reset=lambda: self.resets.append(1),
                                on_setting=lambda n, v: self.settings.append((n, v)), model="test-cam", **kw)

    def __enter__(self):
        self.out.start()
        return self

    def __exit__(self, *exc):
        self.out.stop()

    def client(self, unit_id=1):
        return pyModbusTCP.ModbusClient(host="127.0.0.1", port=self.out.tcp_port, unit_id=unit_id, timeout=2.0)


def _wait_for(pred, timeout=3.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.01)
    return False


def test_pymodbustcp_reads_the_record_as_documented():
    rec = _record()
    with Server() as s:
        s.out.publish(rec)
        c = s.client()
        assert _wait_for(lambda: (c.read_input_registers(2, 1) or [0])[0] == 1234)
        regs = c.read_input_registers(0, 12)
        assert regs[0] >> 8 == 7 and regs[0] & 0xFF == F.FIRMWARE_VERSION_BYTE
        assert regs[1] == 0b1011
        assert regs[2] == 1234                                   # 12.34 mm/h x 100
        assert (regs[3] << 16 | regs[4]) == 123456               # 1234.56 mm, high word first
        assert regs[5] == 321 and regs[6] == 155
        assert struct.unpack(">h", struct.pack(">H", regs[7]))[0] == -32
        assert regs[8] == 3 and regs[9] == 62
        assert (regs[10] << 16 | regs[11]) == 1_700_000_000
        nd = c.read_input_registers(100, 32)
        assert nd[0] == 0x8000                                    # empty class
        assert [struct.unpack(">h", struct.pack(">H", w))[0] for w in nd[1:4]] == [0, 100, 200]
        fl = c.read_input_registers(200, 26)
        as_float = [struct.unpack(">f", struct.pack(">HH", fl[i], fl[i + 1]))[0] for i in range(0, 26, 2)]
        assert as_float[0] == pytest.approx(12.34, rel=1e-6)
        assert as_float[1] == pytest.approx(1234.56, rel=1e-6)
        assert as_float[2] == 321 and as_float[5] == 3.0 and as_float[12] == 600.0
        nd_f = c.read_input_registers(230, 64)
        assert struct.unpack(">f", struct.pack(">HH", nd_f[4], nd_f[5]))[0] == pytest.approx(10 ** 0.1, rel=1e-6)
        c.close()


def test_umodbus_reads_over_tcp():
    from umodbus.client import tcp

    with Server() as s:
        s.out.publish(_record(rain_rate_mm_h=0.5))
        sock = socket.create_connection(("127.0.0.1", s.out.tcp_port), timeout=2)
        try:
            def rate():
                return tcp.send_message(tcp.read_input_registers(slave_id=1, starting_address=2, quantity=1), sock)[0]
            assert _wait_for(lambda: rate() == 50)
            hold = tcp.send_message(tcp.read_holding_registers(slave_id=1, starting_address=0, quantity=3), sock)
            assert hold == [0, 1, 60]
        finally:
            sock.close()


def test_holding_registers_reset_window_unit_id():
    with Server() as s:
        s.out.publish(_record())
        c = s.client()
        assert _wait_for(lambda: c.read_input_registers(3, 2) == [1, 0xE240])
        # illegal values change nothing and answer exception 03
        assert not c.write_single_register(0, 0x1234) and c.last_except == 3
        assert not c.write_single_register(2, 25) and c.last_except == 3      # not a multiple of 10 s
        assert not c.write_single_register(2, 5) and c.last_except == 3
        assert not c.write_single_register(1, 0) and c.last_except == 3
        assert not c.write_multiple_registers(1, [5, 7]) and c.last_except == 3   # 7 s window
        assert not c.write_single_register(3, 1) and c.last_except == 2       # no such register
        assert c.read_holding_registers(0, 3) == [0, 1, 60]
        assert c.read_input_registers(3, 2) == [1, 0xE240] and s.resets == [] and s.settings == []
        # the reset
        assert c.write_single_register(0, F.RESET_MAGIC)
        assert _wait_for(lambda: c.read_input_registers(3, 2) == [0, 0])
        assert s.resets == [1] and c.read_holding_registers(0, 1) == [0]
        # window
        assert c.write_multiple_registers(2, [120])
        assert c.read_holding_registers(2, 1) == [120] and ("window_s", 120) in s.settings
        # unit id: effective after the reply
        assert c.write_single_register(1, 9)
        assert _wait_for(lambda: ("unit_id", 9) in s.settings)
        assert c.read_input_registers(0, 1) is None and c.last_except == 0x0B
        c9 = s.client(unit_id=9)
        assert c9.read_input_registers(0, 1) == [(7 << 8) | F.FIRMWARE_VERSION_BYTE]


def test_illegal_addresses_and_functions():
    with Server() as s:
        c = s.client()
        assert c.read_input_registers(12, 1) is None and c.last_except == 2     # gap in the map
        assert c.read_input_registers(130, 3) is None and c.last_except == 2    # runs off the N(D) block
        assert c.read_input_registers(60000, 1) is None and c.last_except == 2
        assert c.read_holding_registers(0, 4) is None and c.last_except == 2
        assert c.read_coils(0, 1) is None and c.last_except == 1
        assert c.read_discrete_inputs(0, 1) is None and c.last_except == 1
        assert not c.write_single_coil(0, True) and c.last_except == 1


def test_device_identification():
    with Server() as s:
        c = s.client()
        info = c.read_device_identification()
        assert info is not None
        assert info.vendor_name == b"raingauge"
        assert info.product_code == b"RGR"
        from raingauge import __version__

        assert info.major_minor_revision == __version__.encode()


def _mbap(tid, unit, pdu):
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


def _recv(sock, timeout=2.0):
    sock.settimeout(timeout)
    return sock.recv(1024)


def test_garbage_and_unknown_functions_get_exceptions_and_server_keeps_serving():
    rng = random.Random(5)
    with Server() as s:
        s.out.publish(_record())
        port = s.out.tcp_port
        # unknown function codes -> exception 01
        with socket.create_connection(("127.0.0.1", port), timeout=2) as sock:
            for fc in (0x09, 0x0A, 0x41, 0x64, 0x7F):
                sock.sendall(_mbap(7, 1, bytes([fc, 0, 0, 0, 1])))
                answer = _recv(sock)
                assert answer[7] == fc | 0x80 and answer[8] == 1, answer.hex()
        # random bytes from several connections, some then cut mid-frame
        for _ in range(20):
            with socket.create_connection(("127.0.0.1", port), timeout=2) as sock:
                sock.sendall(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300))))
                try:
                    sock.settimeout(0.05)
                    sock.recv(1024)
                except (socket.timeout, ConnectionResetError):
                    pass
        # an oversize count and a zero count -> exception 03
        with socket.create_connection(("127.0.0.1", port), timeout=2) as sock:
            for count in (0, 200):
                sock.sendall(_mbap(9, 1, struct.pack(">BHH", 4, 0, count)))
                answer = _recv(sock)
                assert answer[7] == 0x84 and answer[8] == 3, answer.hex()
        c = s.client()
        assert c.read_input_registers(2, 1) == [1234]


# ---------------------------------------------------------------------- RTU over a pty pair
class PtyLink:
    """Two pseudo-terminals joined back to back (what ``socat pty pty`` does)."""

    def __init__(self):
        self.m1, self.s1 = os.openpty()
        self.m2, self.s2 = os.openpty()
        self.a = os.ttyname(self.s1)
        self.b = os.ttyname(self.s2)
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._pump, daemon=True)
        self._t.start()

    def _pump(self):
        pairs = {self.m1: self.m2, self.m2: self.m1}
        while not self._stop.is_set():
            r, _, _ = select.select(list(pairs), [], [], 0.05)
            for fd in r:
                try:
                    data = os.read(fd, 4096)
                except OSError:
                    continue
                if data:
                    os.write(pairs[fd], data)

    def close(self):
        self._stop.set()
        self._t.join(1)
        for fd in (self.m1, self.s1, self.m2, self.s2):
            try:
                os.close(fd)
            except OSError:
                pass


def test_minimalmodbus_over_rtu():
    minimalmodbus = pytest.importorskip("minimalmodbus")
    link = PtyLink()
    out = ModbusOutput(rtu={"port": link.a, "baudrate": 19200}, unit_id=3, device_id=7)
    try:
        out.start()
        out.publish(_record())
        inst = minimalmodbus.Instrument(link.b, 3)
        inst.serial.baudrate = 19200
        inst.serial.timeout = 1.0
        inst.clear_buffers_before_each_transaction = True
        time.sleep(0.3)
        # line noise first: the slave loses at most one request, then answers again
        inst.serial.write(bytes(random.Random(3).randrange(256) for _ in range(200)))
        time.sleep(0.3)
        answers = []
        for _ in range(3):
            try:
                answers.append(inst.read_register(2, 2, functioncode=4))
            except minimalmodbus.NoResponseError:
                answers.append(None)
        assert answers[1:] == [pytest.approx(12.34)] * 2
        assert inst.read_register(2, 2, functioncode=4) == pytest.approx(12.34)
        assert inst.read_long(3, functioncode=4, byteorder=minimalmodbus.BYTEORDER_BIG) == 123456
        assert inst.read_register(7, 1, functioncode=4, signed=True) == pytest.approx(-3.2)
        assert inst.read_float(200, functioncode=4) == pytest.approx(12.34, rel=1e-6)
        assert inst.read_registers(0, 3, functioncode=3) == [0, 3, 60]
        with pytest.raises(minimalmodbus.IllegalRequestError):
            inst.write_register(2, 7, functioncode=6)
        inst.write_register(0, F.RESET_MAGIC, functioncode=6)
        assert _wait_for(lambda: inst.read_long(3, functioncode=4) == 0)
        # another unit on the shared line: the gauge stays silent
        other = minimalmodbus.Instrument(link.b, 4)
        other.serial.timeout = 0.3
        with pytest.raises(minimalmodbus.NoResponseError):
            other.read_register(2, functioncode=4)
        inst.serial.close()
    finally:
        out.stop()
        link.close()


def test_server_in_its_own_process_same_interface():
    from firmware_interface.modbus import ModbusProcess

    events = []
    out = ModbusProcess(tcp=("127.0.0.1", 0), device_id=7, on_reset=lambda: events.append("reset"),
                        on_setting=lambda n, v: events.append((n, v)))
    with out:
        out.publish(_record())
        c = pyModbusTCP.ModbusClient(host="127.0.0.1", port=out.tcp_port, unit_id=1, timeout=2.0)
        assert _wait_for(lambda: (c.read_input_registers(2, 1) or [0])[0] == 1234)
        out.set_status(0b10001)
        assert _wait_for(lambda: c.read_input_registers(1, 1) == [0b10001])
        assert c.write_single_register(0, F.RESET_MAGIC) and c.write_single_register(2, 30)
        assert _wait_for(lambda: events == ["reset", ("window_s", 30)])
        assert not c.write_single_register(2, 31) and c.last_except == 3
        port = out.tcp_port
    # stopped: nothing listens on the port any more
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", port))
        s.listen()
    from raingauge.errors import ConfigError

    with pytest.raises(ConfigError, match="1-247"):
        ModbusProcess(tcp=("127.0.0.1", 0), unit_id=0)
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    try:
        with pytest.raises(ConfigError, match="cannot listen"):
            ModbusProcess(tcp=("127.0.0.1", busy.getsockname()[1])).start()
    finally:
        busy.close()


CHILD = r"""
import sys, time
from firmware_interface.modbus import ModbusProcess
out = ModbusProcess(tcp=("127.0.0.1", 0)).start()
print(out.tcp_port, out._proc.pid, flush=True)  # no __main__ guard needed
time.sleep(60)
"""


def test_server_process_exits_when_the_instrument_is_killed(tmp_path):
    """After kill -9 of the instrument the server process frees the port, so a restart can bind it."""
    import signal
    import subprocess
    import sys

    script = tmp_path / "child.py"
    script.write_text(CHILD)
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    try:
        port, child_pid = (int(v) for v in proc.stdout.readline().split())
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        proc.stdout.close()

    def gone():
        try:
            os.kill(child_pid, 0)
        except ProcessLookupError:
            return True
        try:  # a zombie waiting for its (dead) parent counts as gone
            return open(f"/proc/{child_pid}/stat").read().split(")")[1].split()[0] == "Z"
        except OSError:
            return True

    assert _wait_for(gone, timeout=10)
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", port))
        s.listen()
