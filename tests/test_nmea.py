"""Serial sentences: checksums, length, pynmea2 reading them from a pseudo-terminal."""

from __future__ import annotations

import os
import time

import pynmea2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_interface import nmea
from firmware_interface.fields import record_defaults
from firmware_interface.serial_out import SerialWriter, parse_port_spec


def _record(**kw):
    rec = record_defaults()
    rec.update(time_unix=1_700_000_000.0, rain_rate_mm_h=12.345, accumulation_mm=3.21,
               drops_counted=456, dm_mm=1.62, intensity_class=3, status=0b1011,
               rain_duration_s=1230.0)
    rec.update(kw)
    return rec


def test_checksum_known_sentence():
    # A textbook GPS sentence with its published checksum.
    line = "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47"
    body = line[1:line.index("*")]
    assert f"{nmea.checksum(body):02X}" == "47"


def test_prgrr_fields_in_documented_order():
    line = nmea.prgrr(_record())
    assert line.endswith("\r\n") and len(line) <= 82
    fields = nmea.parse(line)
    # time 22:13:20 UTC, rate, accumulation, drops, Dm, class, status hex
    assert fields == ["PRGRR", "221320", "12.35", "3.21", "456", "1.62", "3", "0B"]


def test_invalid_values_are_empty_fields():
    line = nmea.prgrr(_record(rain_rate_mm_h=float("nan"), dm_mm=None, intensity_class=None))
    fields = nmea.parse(line)
    assert fields[2] == "" and fields[5] == "" and fields[6] == ""


def test_wixdr_vaisala_rain_group():
    msg = pynmea2.parse(nmea.wixdr(_record()).strip())
    assert msg.talker == "WI" and msg.sentence_type == "XDR"
    groups = [msg.data[i:i + 4] for i in range(0, len(msg.data), 4)]
    assert groups == [["V", "3.21", "M", "0"], ["Z", "1230", "s", "0"], ["R", "12.3", "M", "0"]]


def test_bad_checksum_is_rejected():
    line = nmea.prgrr(_record()).strip()
    broken = line[:-2] + ("00" if line[-2:] != "00" else "01")
    with pytest.raises(ValueError, match="checksum"):
        nmea.parse(broken)
    with pytest.raises(pynmea2.ChecksumError):
        pynmea2.parse(broken, check=True)


@settings(max_examples=200, deadline=None)
@given(rate=st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True)),
       acc=st.floats(min_value=-1e12, max_value=1e12), drops=st.integers(-10, 10**12),
       status=st.integers(0, 0xFFFF))
def test_any_record_gives_valid_short_sentences(rate, acc, drops, status):
    for line in nmea.sentences_for(_record(rain_rate_mm_h=rate, accumulation_mm=acc,
                                           drops_counted=drops, status=status)):
        assert len(line) <= nmea.MAX_LEN
        nmea.parse(line)
        pynmea2.parse(line.strip(), check=True)


def test_port_spec():
    assert parse_port_spec("/dev/ttyUSB0:4800") == ("/dev/ttyUSB0", 4800)
    assert parse_port_spec("/dev/ttyUSB0") == ("/dev/ttyUSB0", 9600)
    assert parse_port_spec("COM3:19200", default_baud=9600) == ("COM3", 19200)
    # pyserial URLs keep their own colons; baud after '@'
    assert parse_port_spec("socket://10.0.0.5:7000") == ("socket://10.0.0.5:7000", 9600)
    assert parse_port_spec("socket://10.0.0.5:7000@4800") == ("socket://10.0.0.5:7000", 4800)
    assert parse_port_spec("loop://") == ("loop://", 9600)
    # by-path device names contain colons that are not baud separators
    by_path = "/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0-port0"
    assert parse_port_spec(by_path) == (by_path, 9600)
    assert parse_port_spec(by_path + ":115200") == (by_path, 115200)


@pytest.mark.parametrize("spec, words", [
    ("/dev/ttyUSB0:96OO", "not a whole number"),
    ("/dev/ttyUSB0:9600baud", "not a whole number"),
    ("/dev/ttyUSB0:12", "outside"),
    ("/dev/ttyUSB0:99999999", "outside"),
    (":9600", "no port"),
    ("", "empty"),
    ("socket://h:7000@fast", "not a whole number"),
])
def test_malformed_port_spec_is_refused_with_a_fix(spec, words):
    from raingauge.errors import ConfigError

    with pytest.raises(ConfigError, match=words) as exc:
        parse_port_spec(spec)
    assert "Fix:" in str(exc.value)


def _read_lines(fd, n, timeout_s=5.0) -> list[str]:
    buf = b""
    deadline = time.monotonic() + timeout_s
    while buf.count(b"\n") < n and time.monotonic() < deadline:
        try:
            chunk = os.read(fd, 4096)
        except BlockingIOError:
            time.sleep(0.01)
            continue
        buf += chunk
    return buf.decode("ascii").splitlines()


def test_pynmea2_reads_the_serial_port_through_a_pty():
    master, slave = os.openpty()
    os.set_blocking(master, False)
    writer = SerialWriter(os.ttyname(slave), 9600)
    try:
        writer.publish(_record())
        writer.publish(_record(rain_rate_mm_h=0.0, accumulation_mm=3.25))
        lines = _read_lines(master, 4)
    finally:
        writer.close()
        os.close(master)
        os.close(slave)
    assert len(lines) == 4
    msgs = [pynmea2.parse(line, check=True) for line in lines]
    # $P + maker code RGR, sentence R; pynmea2 keeps the rest of the talker field in data[0]
    assert [m.manufacturer for m in msgs[0::2]] == ["RGR", "RGR"]
    assert msgs[0].data[1:] == ["221320", "12.35", "3.21", "456", "1.62", "3", "0B"]
    assert [m.sentence_type for m in msgs[1::2]] == ["XDR", "XDR"]
    assert lines[0].startswith("$PRGRR,221320,12.35,")
    assert lines[2].startswith("$PRGRR,221320,0.00,3.25,")
    assert writer.sent == 2 and not writer.fault


def test_missing_port_never_blocks_publish_and_recovers_when_plugged_in(tmp_path):
    """The adapter is unplugged: publish returns at once, the fault is raised and the oldest
    records are dropped; plugged in again (here: the device name appears), sending resumes."""
    port = tmp_path / "ttyRG0"
    writer = SerialWriter(str(port), 9600, queue_size=3, backoff_s=(0.05, 0.1))
    master = slave = None
    try:
        t0 = time.monotonic()
        for i in range(50):
            writer.publish(_record(drops_counted=i))
        assert time.monotonic() - t0 < 1.0
        time.sleep(0.3)
        assert writer.fault and writer.errors >= 1 and writer.dropped >= 46
        master, slave = os.openpty()
        os.set_blocking(master, False)
        os.symlink(os.ttyname(slave), port)
        expected = 50 - writer.dropped          # what was kept: the in-flight record and the queue
        lines = _read_lines(master, 2 * expected)
        sent = [int(nmea.parse(line)[4]) for line in lines if line.startswith("$PRGRR")]
        assert len(sent) == expected and sent == sorted(sent) and sent[-1] == 49
        assert _wait(lambda: not writer.fault)
        writer.publish(_record(drops_counted=99))
        assert nmea.parse(_read_lines(master, 2)[0])[4] == "99"
    finally:
        writer.close(timeout_s=0.5)
        for fd in (master, slave):
            if fd is not None:
                os.close(fd)


def _wait(pred, timeout=3.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.02)
    return False
