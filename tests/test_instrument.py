"""The field instrument: configuration, sources, the loop, outputs off the loop, faults, SIGTERM."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from firmware_interface.fields import STATUS_BITS
from raingauge.errors import ConfigError, InputError, SourceError
from raingauge.history import History
from raingauge.instrument.config import DEFAULTS, config_from_dict, load_config
from raingauge.instrument.loop import Accumulator, Diagnostics, Instrument
from raingauge.instrument.sources import (
    CameraSource, FileSource, FrameSource, Grabber, SimulatedSource, open_source,
)
from raingauge.profile import load_profile

REPO = Path(__file__).resolve().parents[1]
SHAPE = (24, 32)


def small_profile(**kw):
    return load_profile("gauge-default").replace(width_px=SHAPE[1], height_px=SHAPE[0], **kw)


class StepGauge:
    """Test double of raingauge.gauge.RainGauge (same constructor and methods): one record per
    step whose rate is the mean gray level of the step's frames / 10 [mm/h]."""

    def __init__(self, profile, *, window_s, step_s, velocity_model, clock_start_s):
        self.window, self.step = window_s, step_s
        self.next = clock_start_s + step_s
        self.acc = 0.0
        self.sum = 0.0
        self.n = 0

    def _record(self):
        rate = self.sum / self.n / 10.0 if self.n else 0.0
        self.acc += rate * self.step / 3600.0
        rec = {"t_start_s": self.next - self.window, "t_end_s": self.next, "rain_rate_mm_h": rate,
               "rain_rate_ci95_mm_h": [0.8 * rate, 1.2 * rate], "accumulation_mm": self.acc,
               "drops_counted": self.n, "drops_rejected_defocus": 0, "dsd_d_mm": [0.1 * k for k in range(32)],
               "dsd_n_m3_mm": [float(k) for k in range(32)], "nt_m3": 1.0, "dm_mm": 1.0, "z_dbz": 20.0,
               "intensity_class": "moderate", "synop_4680": 62, "quality": []}
        self.sum, self.n = 0.0, 0
        return rec

    def process(self, frame, t_s=None):
        out = []
        while t_s >= self.next:
            out.append(self._record())
            self.next += self.step
        self.sum += float(np.mean(frame))
        self.n += 1
        return out

    def flush(self):
        return [self._record()] if self.n else []


class ListSource(FrameSource):
    """A recorded source of constant frames."""

    def __init__(self, n, value=50, fps=10.0, shape=SHAPE, bad_every=0):
        self.n, self.value, self.frame_rate_hz, self.shape, self.bad_every = n, value, fps, shape, bad_every
        self.name = "list"
        self.i = 0

    def read(self):
        if self.i >= self.n:
            return None
        self.i += 1
        if self.bad_every and self.i % self.bad_every == 0:
            return np.zeros((5, 5), np.uint8)       # wrong size: corrupt
        return np.full(self.shape, self.value, np.uint8)


class FlakyCamera(FrameSource):
    """A live camera that vanishes after some frames and comes back after an outage."""

    live = True

    def __init__(self, *, fps=50.0, frames_before_loss=40, outage_s=1.5, value=100):
        self.frame_rate_hz, self.frames_before_loss, self.outage_s, self.value = fps, frames_before_loss, outage_s, value
        self.name = "flaky camera"
        self.count = 0
        self.back_at = 0.0
        self.lost_once = False
        self.open_failures = 0

    def open(self):
        if time.monotonic() < self.back_at:
            self.open_failures += 1
            raise SourceError("no such device")

    def read(self):
        time.sleep(1.0 / self.frame_rate_hz)
        self.count += 1
        if self.count == self.frames_before_loss and not self.lost_once:
            self.lost_once = True
            self.back_at = time.monotonic() + self.outage_s
            raise SourceError("device unplugged")
        return np.full(SHAPE, self.value, np.uint8)


# ---------------------------------------------------------------------- configuration
def test_default_config_is_the_embedded_simulation():
    cfg = load_config(None)
    assert cfg.source["uri"] == "simulate:10"
    assert cfg.modbus["tcp"] == "127.0.0.1:5020" and cfg.camera["profile"] == "gauge-default"
    assert cfg.history["path"] == "raingauge.sqlite"


def test_example_config_in_deploy_is_valid():
    cfg = load_config(REPO / "deploy" / "raingauge.toml")
    assert set(cfg.as_dict()) == set(DEFAULTS)


@pytest.mark.parametrize("doc,match", [
    ({"modbus": {"tpc": "x"}}, r"\[modbus\]\.tpc: unknown key; valid keys of \[modbus\]: tcp"),
    ({"modbuss": {}}, r"unknown section \[modbuss\]"),
    ({"gauge": {"window_s": 45, "step_s": 10}}, r"\[gauge\]\.window_s: .*not a whole multiple.*Fix: window_s ="),
    ({"modbus": {"unit_id": 300}}, r"\[modbus\]\.unit_id: must be 1-247.*Fix: unit_id = 1"),
    ({"modbus": {"tcp": "host:99999"}}, r"\[modbus\]\.tcp"),
    ({"source": {"realtime": "yes"}}, r"\[source\]\.realtime: expected true or false"),
    ({"history": {"retention_days": -1}}, r"\[history\]\.retention_days: must be >= 0"),
    ({"diagnostics": {"frames": 2}}, r"\[diagnostics\]\.frames: needs at least 3"),
    ({"gauge": {"window_s": float("inf")}}, r"\[gauge\]\.window_s: expected a finite number, got inf.*Fix: window_s ="),
    ({"gauge": {"step_s": float("nan")}}, r"\[gauge\]\.step_s: expected a finite number, got nan.*Fix: step_s ="),
])
def test_config_errors_name_key_and_fix(doc, match):
    with pytest.raises(ConfigError, match=match):
        config_from_dict(doc, source="test.toml")


def test_config_file_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[source\nuri = 1")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(tmp_path / "none.toml")


# ---------------------------------------------------------------------- sources
def test_open_source_kinds(tmp_path):
    prof = small_profile()
    assert isinstance(open_source("simulate:2.5", profile=prof), SimulatedSource)
    assert open_source("simulate:2.5", profile=prof).rain_rate_mm_h == 2.5
    cam = open_source("0", profile=prof)
    assert isinstance(cam, CameraSource) and cam.target == 0 and cam.live
    assert open_source("rtsp://127.0.0.1:8554/cam", profile=prof).target == "rtsp://127.0.0.1:8554/cam"
    (tmp_path / "frames").mkdir()
    assert isinstance(open_source(str(tmp_path / "frames"), profile=prof), FileSource)
    with pytest.raises(InputError, match="simulate:RATE"):
        open_source(str(tmp_path / "nothing.mkv"), profile=prof)
    with pytest.raises(InputError, match="simulate:10"):
        open_source("simulate:lots", profile=prof)


def test_image_folder_with_corrupt_frames_skips_and_counts(tmp_path):
    import cv2

    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(6):
        cv2.imwrite(str(folder / f"{i:03d}.png"), np.full(SHAPE, 10 * i, np.uint8))
    (folder / "003.png").write_bytes(b"\x89PNG garbage")                  # unreadable
    cv2.imwrite(str(folder / "004.png"), np.zeros((8, 8), np.uint8))       # wrong size
    g = Grabber(FileSource(folder), shape=SHAPE).start()
    got = []
    while not (g.finished.is_set() and g.queue.empty()):
        item = g.get(0.2)
        if item:
            got.append(item)
    g.stop()
    assert [int(f[0, 0]) for _, f in got] == [0, 10, 20, 50]
    assert g.corrupt_frames + g.source_corrupt_frames == 2
    assert [t for t, _ in got] == pytest.approx([0, 1 / 30, 2 / 30, 5 / 30])  # frames keep their slots


def test_grabber_reconnects_with_backoff():
    cam = FlakyCamera(frames_before_loss=10, outage_s=0.6)
    g = Grabber(cam, shape=SHAPE, backoff_s=(0.05, 0.2)).start()
    n = 0
    deadline = time.monotonic() + 10
    while g.reconnects == 0 and time.monotonic() < deadline:
        if g.get(0.1):
            n += 1
    while n < 15 and time.monotonic() < deadline:
        if g.get(0.1):
            n += 1
    g.stop()
    assert g.reconnects == 1 and cam.open_failures >= 2 and n >= 15


# ---------------------------------------------------------------------- the loop
def _instrument(source, tmp_path=None, **kw):
    prof = small_profile()
    hist = History(tmp_path / "h.sqlite") if tmp_path is not None else None
    records = []
    kw.setdefault("window_s", 1.0)
    kw.setdefault("step_s", 0.5)
    kw.setdefault("gauge_factory", StepGauge)
    inst = Instrument(prof, Grabber(source, shape=SHAPE, backoff_s=(0.05, 0.2)), history=hist,
                      on_record=records.append, wall_t0=1.79e9, **kw)
    return inst, records, hist


def test_loop_records_every_step_with_all_fields(tmp_path):
    inst, records, _ = _instrument(ListSource(50, value=50, fps=10.0, bad_every=10), tmp_path)
    summary = inst.run()
    # 50 frames over 5 s at 10 Hz, 5 corrupt: records at 0.5 s steps, the last one flushed
    assert summary["corrupt_frames"] == 5 and summary["frames"] == 45
    assert len(records) == 10
    r = records[3]
    assert r["rain_rate_mm_h"] == pytest.approx(5.0) and r["intensity_class"] == 2
    assert r["time_unix"] == pytest.approx(1.79e9 + 2.0) and r["time_utc"].endswith("Z")
    assert r["status"] & (1 << STATUS_BITS["camera_ok"]) and r["status"] & (1 << STATUS_BITS["rain_detected"])
    assert not r["status"] & (1 << STATUS_BITS["calibrated"])          # shipped default profile
    assert r["accumulation_mm"] == pytest.approx(4 * 5.0 * 0.5 / 3600)
    assert r["exposure_s"] == 0.004 and r["window_s"] == 1.0
    h = History(tmp_path / "h.sqlite", readonly=True)
    rows = list(h.rows())
    assert len(rows) == 10 and rows[3]["rain_rate_mm_h"] == pytest.approx(5.0)
    assert h.settings()["accumulation_mm"] == pytest.approx(records[-1]["accumulation_mm"])
    h.close()


def test_camera_lost_gives_missing_records_not_zero_rain(tmp_path):
    inst, records, _ = _instrument(FlakyCamera(frames_before_loss=40, outage_s=1.5), tmp_path,
                                   stall_timeout_s=0.3)

    threading.Timer(4.0, inst.stop).start()
    summary = inst.run()
    missing = [r for r in records if r["missing"]]
    good = [r for r in records if not r["missing"]]
    assert summary["reconnects"] == 1
    assert len(missing) >= 2 and len(good) >= 3
    for r in missing:
        assert math.isnan(r["rain_rate_mm_h"]) and "camera_lost" in r["quality"]
        assert not r["status"] & (1 << STATUS_BITS["camera_ok"])
        assert r["status"] & (1 << STATUS_BITS["low_confidence"])
    # no rain is added while the camera is gone
    i = records.index(missing[0])
    assert missing[-1]["accumulation_mm"] == records[i - 1]["accumulation_mm"]
    # measurement resumed after the outage
    assert any(not r["missing"] for r in records[records.index(missing[-1]) + 1:])
    ends = [r["t_end_s"] for r in records]
    assert ends == sorted(ends)
    h = History(tmp_path / "h.sqlite", readonly=True)
    stored = list(h.rows())
    assert len(stored) == len(records)
    assert sum(r["missing"] for r in stored) == len(missing) and all(r["rain_rate_mm_h"] is None for r in stored if r["missing"])
    h.close()


class StuckOutput:
    """An output whose publish would block for ever if called on the loop (it must be queued)."""

    def __init__(self):
        from firmware_interface.serial_out import SerialWriter

        self.master, self.slave = os.openpty()  # nobody reads the master: the port fills and stalls
        self.writer = SerialWriter(os.ttyname(self.slave), 9600, queue_size=4, write_timeout_s=0.5,
                                   backoff_s=(0.05, 0.1),
                                   formatter=lambda rec: ["$" + "X" * 20000 + "\r\n"])

    def publish(self, rec):
        self.writer.publish(rec)

    @property
    def fault(self):
        return self.writer.fault

    def close(self):
        self.writer.close(timeout_s=0.2)
        os.close(self.master)
        os.close(self.slave)


def test_a_stuck_serial_port_never_stalls_measurement():
    stuck = StuckOutput()
    inst, records, _ = _instrument(ListSource(200, fps=100.0), None, outputs=[stuck], window_s=0.2, step_s=0.1)
    # fast source: 200 frames = 2 s of source time, played as fast as the loop goes
    t0 = time.monotonic()
    summary = inst.run()
    elapsed = time.monotonic() - t0
    assert summary["frames"] == 200 and len(records) == 20
    assert stuck.writer.dropped > 0 or stuck.writer.errors > 0
    assert records[-1]["status"] & (1 << STATUS_BITS["output_fault"])
    assert elapsed < 10.0  # the loop ran at source speed, not at the port's (would be 20 x 0.5 s timeouts)


def test_full_disk_raises_storage_fault_and_loses_nothing(tmp_path):
    from firmware_interface.modbus import ModbusOutput
    from pyModbusTCP.client import ModbusClient

    modbus = ModbusOutput(tcp=("127.0.0.1", 0), window_s=1, step_s=0.5).start()
    inst, records, hist = _instrument(ListSource(140, fps=20.0), tmp_path, outputs=[modbus], modbus=modbus)
    hist.append({"time_unix": 0.0, "quality": []})   # a row from before
    pages = hist.db.execute("PRAGMA page_count").fetchone()[0]
    hist.db.execute(f"PRAGMA max_page_count={pages}")  # the disk is full
    inst.history_writer.retry_s = 0.2
    source = inst.grabber.source

    statuses = []

    def poll():
        c = ModbusClient(host="127.0.0.1", port=modbus.tcp_port, unit_id=1, timeout=1)
        while not inst._stop.is_set():
            regs = c.read_input_registers(1, 1)
            if regs:
                statuses.append(regs[0])
            time.sleep(0.05)

    def free_space():
        deadline = time.monotonic() + 10
        while not inst.history_writer.fault and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(1.5)
        hist.db.execute("PRAGMA max_page_count=1073741823")

    source.realtime = True
    threading.Thread(target=poll, daemon=True).start()
    threading.Thread(target=free_space, daemon=True).start()
    summary = inst.run()
    inst._stop.set()
    assert summary["frames"] == 140                 # measurement went on
    assert any(s & (1 << STATUS_BITS["storage_fault"]) for s in statuses)
    assert any(r["status"] & (1 << STATUS_BITS["storage_fault"]) for r in records)
    h = History(tmp_path / "h.sqlite", readonly=True)
    assert h.count() == len(records) + 1 and h.integrity_ok()
    h.close()


def test_modbus_reset_resets_the_instrument_accumulation(tmp_path):
    from firmware_interface.fields import RESET_MAGIC
    from firmware_interface.modbus import ModbusOutput
    from pyModbusTCP.client import ModbusClient

    holder = {}
    modbus = ModbusOutput(tcp=("127.0.0.1", 0), window_s=1, step_s=0.5,
                          on_reset=lambda: holder["inst"].reset_accumulation())
    modbus.start()
    src = ListSource(100, value=200, fps=20.0)
    src.realtime = True
    inst, records, _ = _instrument(src, tmp_path, outputs=[modbus], modbus=modbus,
                                   accumulator=Accumulator(5.0, 100.0))
    holder["inst"] = inst

    def reset_later():
        time.sleep(2.5)
        ModbusClient(host="127.0.0.1", port=modbus.tcp_port, unit_id=1, timeout=1).write_single_register(0, RESET_MAGIC)

    threading.Thread(target=reset_later, daemon=True).start()
    inst.run()
    accs = [r["accumulation_mm"] for r in records]
    assert accs[0] > 5.0                                  # resumed from the stored 5 mm
    drop = [i for i in range(1, len(accs)) if accs[i] < accs[i - 1]]
    assert len(drop) == 1 and accs[drop[0]] < 0.1         # one reset, from zero again
    h = History(tmp_path / "h.sqlite", readonly=True)     # what a restart resumes from
    assert h.settings()["accumulation_mm"] == pytest.approx(accs[-1])
    h.close()


def test_diagnostics_write_snapshot_and_survive_failures(tmp_path, caplog):
    prof = small_profile()
    diag = Diagnostics(tmp_path / "diag", prof, keep=2)
    rng = np.random.default_rng(0)
    frames = [rng.integers(40, 60, SHAPE, dtype=np.uint8) for _ in range(8)]
    out = diag.snapshot(frames, 1.79e9, 4.0, 60.0)
    assert sorted(p.name for p in out.iterdir()) == ["advice.json", "derained.png", "frame.png", "needles.png"]
    advice = json.loads((out / "advice.json").read_text())
    assert advice["rain_rate_mm_h"] == 4.0 and advice["advice"]["goal"] == "gauge"
    assert advice["current"]["exposure_s"] == prof.exposure_s
    # a profile the advisor cannot use: logged, the rest still written, nothing raised
    bad = Diagnostics(tmp_path / "diag2", None)
    out2 = bad.snapshot(frames, 1.79e9 + 10, 4.0, 60.0)
    assert (out2 / "frame.png").is_file() and bad.failures["advisor"] == 1
    assert "the gauge is not affected" in caplog.text
    for k in range(3):
        diag.snapshot(frames, 1.79e9 + 100 * (k + 1), 4.0, 60.0)
    assert len([p for p in (tmp_path / "diag").iterdir()]) == 2
    diag.close()
    bad.close()


# ---------------------------------------------------------------------- end to end, real gauge
def test_run_end_to_end_on_the_simulated_camera_then_sigterm(tmp_path):
    """`raingauge run` on simulated rain with the real gauge: records printed, served over Modbus
    TCP, sent as NMEA on a pty, stored in SQLite; SIGTERM flushes and exits 0."""
    import re

    import pynmea2
    from pyModbusTCP.client import ModbusClient

    pytest.importorskip("raingauge.gauge").RainGauge
    pytest.importorskip("raingauge.render.simulator").simulate
    db = tmp_path / "rg.sqlite"
    master, slave = os.openpty()
    os.set_blocking(master, False)
    cmd = [sys.executable, "-m", "raingauge", "run", "--source", "simulate:20", "--sim-size", "96x72",
           "--fast", "--step", "1", "--window", "2", "--db", str(db), "--modbus-tcp", "127.0.0.1:0",
           "--serial", os.ttyname(slave), "--diagnostics", "off"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    out_lines, err_lines = [], []
    threading.Thread(target=lambda: out_lines.extend(iter(proc.stdout.readline, "")), daemon=True).start()
    threading.Thread(target=lambda: err_lines.extend(iter(proc.stderr.readline, "")), daemon=True).start()
    serial_bytes = b""
    try:
        deadline = time.monotonic() + 90
        while sum(line.startswith("20") for line in out_lines) < 3 and time.monotonic() < deadline:
            assert proc.poll() is None, "".join(err_lines)
            try:
                serial_bytes += os.read(master, 4096)
            except BlockingIOError:
                pass
            time.sleep(0.1)
        port = int(re.search(r"Modbus TCP on 127\.0\.0\.1:(\d+)", "".join(err_lines)).group(1))
        regs = ModbusClient(host="127.0.0.1", port=port, unit_id=1, timeout=2).read_input_registers(0, 12)
        assert regs is not None and regs[1] & (1 << STATUS_BITS["camera_ok"])
        assert (regs[10] << 16 | regs[11]) > 1.7e9
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(30) == 0, "".join(err_lines)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    time.sleep(0.2)
    try:
        serial_bytes += os.read(master, 65536)
    except BlockingIOError:
        pass
    os.close(master)
    os.close(slave)
    printed = [line for line in out_lines if line.startswith("20")]
    h = History(db, readonly=True)
    rows = list(h.rows())
    assert len(rows) == len(printed) >= 3 and h.integrity_ok()
    assert all(r["rain_rate_mm_h"] is not None and r["missing"] == 0 for r in rows)
    assert rows[-1]["accumulation_mm"] >= rows[0]["accumulation_mm"]
    h.close()
    sentences = [pynmea2.parse(line, check=True) for line in serial_bytes.decode().splitlines() if line]
    assert len(sentences) >= 4 and {type(s).__name__ for s in sentences} >= {"XDR"}
    assert "records" in "".join(err_lines)


def test_run_command_reports_bad_configuration(tmp_path, capsys):
    from raingauge.cli import main

    assert main(["run", "--config", str(tmp_path / "none.toml")]) == 2
    assert "does not exist" in capsys.readouterr().err
    cfg = tmp_path / "c.toml"
    cfg.write_text('[gauge]\nwindow_s = 25\nstep_s = 10\n')
    assert main(["run", "--config", str(cfg)]) == 2
    err = capsys.readouterr().err
    assert "[gauge].window_s" in err and "Fix:" in err
    assert main(["run", "--source", "simulate:lots", "--db", "off", "--modbus-tcp", "off"]) == 2
    assert "simulate:10" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="WIDTHxHEIGHT"):
        from raingauge.commands import run as run_cmd
        import argparse

        p = argparse.ArgumentParser()
        run_cmd.add_arguments(p)
        run_cmd.run(p.parse_args(["--sim-size", "big"]))


# ---------------------------------------------------------------------- a gauge slower than the camera
class SlowStepGauge(StepGauge):
    """StepGauge that needs ``cost_s`` per frame, and remembers the frame times it was given."""

    cost_s = 0.02

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.times = []

    def process(self, frame, t_s=None):
        time.sleep(self.cost_s)
        self.times.append(t_s)
        return super().process(frame, t_s)


def _slow_run(realtime):
    src = ListSource(150, value=80, fps=200.0)          # 0.75 s of camera time; the gauge takes 50 frames/s
    src.realtime = realtime
    gauges = []

    def factory(*a, **kw):
        gauges.append(SlowStepGauge(*a, **kw))
        return gauges[-1]

    records = []
    inst = Instrument(small_profile(), Grabber(src, shape=SHAPE, queue_size=16), window_s=0.2, step_s=0.1,
                      gauge_factory=factory, on_record=records.append, wall_t0=1.79e9)
    return inst.run(), records, gauges[0].times


def test_a_paced_source_drops_frames_explicitly_when_the_gauge_is_slower():
    """A camera (or a file / the simulated camera played in real time) does not wait for the gauge:
    frames it cannot take are dropped, but never silently - counted per record and flagged, and the
    frames measured keep their true times, so the gauge sees the gaps."""
    summary, records, times = _slow_run(realtime=True)
    assert summary["dropped_frames"] > 0
    assert summary["frames"] + summary["dropped_frames"] == 150          # every frame measured or counted
    assert sum(r["frames"] for r in records) == summary["frames"]
    assert sum(r["dropped_frames"] for r in records) == summary["dropped_frames"]
    for r in records:
        assert ("dropped_frames" in r["quality"]) == (r["dropped_frames"] > 0)
    steps = np.diff(np.asarray(times) * 200.0)
    assert np.allclose(steps, np.round(steps)) and steps.max() >= 2     # true frame slots, with gaps
    # the backlog is dropped at once: mostly runs of consecutive frames, not a gap at every frame
    assert np.mean(np.round(steps) == 1) > 0.5
    assert times[-1] == pytest.approx(149 / 200.0)                        # the lag stayed bounded


def test_an_unpaced_source_waits_for_the_gauge_and_loses_nothing():
    summary, records, times = _slow_run(realtime=False)
    assert summary["dropped_frames"] == 0 and summary["frames"] == 150
    assert all(r["dropped_frames"] == 0 and "dropped_frames" not in r["quality"] for r in records)
    assert np.allclose(np.diff(times), 1 / 200.0)


def test_dropped_frames_are_stored_in_the_history(tmp_path):
    src = ListSource(120, value=80, fps=200.0)
    src.realtime = True
    inst, records, _ = _instrument(src, tmp_path, gauge_factory=SlowStepGauge, window_s=0.2, step_s=0.1)
    summary = inst.run()
    h = History(tmp_path / "h.sqlite", readonly=True)
    rows = list(h.rows())
    assert sum(r["dropped_frames"] for r in rows) == summary["dropped_frames"] > 0
    assert all(("dropped_frames" in (r["quality"] or "")) == (r["dropped_frames"] > 0) for r in rows)
    h.close()


# ---------------------------------------------------------------------- worker processes
def test_simulated_camera_renders_in_its_own_process():
    pytest.importorskip("raingauge.render.simulator").simulate
    from raingauge.instrument.sources import scaled_profile

    prof = scaled_profile(load_profile("gauge-default"), 64, 48)
    local = SimulatedSource(5.0, prof, seed=3, limit_frames=6, process=False)
    remote = SimulatedSource(5.0, prof, seed=3, limit_frames=6, process=True, prefetch=2)
    local.open()
    remote.open()
    try:
        proc = remote._proc
        assert proc.pid != os.getpid() and proc.is_alive()
        a = [local.read() for _ in range(6)]
        b = [remote.read() for _ in range(6)]
        assert local.read() is None and remote.read() is None
    finally:
        local.close()
        remote.close()
    assert all(f.shape == prof.shape and f.dtype == np.uint8 for f in b)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))                # the same camera either way
    assert not proc.is_alive()


def test_diagnostics_run_in_an_idle_priority_process(tmp_path):
    prof = small_profile()
    rng = np.random.default_rng(1)
    frames = [rng.integers(40, 60, SHAPE, dtype=np.uint8) for _ in range(6)]
    idle = Diagnostics(tmp_path / "idle", prof).start((6,) + SHAPE)
    try:
        pid = idle.pid
        assert pid != os.getpid()
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:                 # lowered after its imports
            if os.sched_getscheduler(pid) == os.SCHED_IDLE or os.getpriority(os.PRIO_PROCESS, pid) == 19:
                break
            time.sleep(0.1)
        assert os.sched_getscheduler(pid) == os.SCHED_IDLE or os.getpriority(os.PRIO_PROCESS, pid) == 19
    finally:
        idle.close()
    diag = Diagnostics(tmp_path / "diag", prof, priority="normal")
    try:
        assert diag.submit(frames, time_unix=1.79e9, rain_rate_mm_h=3.0, window_s=60.0)
        assert not diag.submit(frames, time_unix=1.79e9 + 1, rain_rate_mm_h=3.0, window_s=60.0)  # one at a time
        deadline = time.monotonic() + 60
        while diag.snapshots == 0 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert diag.snapshots == 1 and diag.skipped == 1
        (snap,) = list((tmp_path / "diag").iterdir())
        assert snap.name == "20260921T141320Z"
        assert {"frame.png", "derained.png", "needles.png", "advice.json"} <= {p.name for p in snap.iterdir()}
    finally:
        diag.close()
    with pytest.raises(ValueError, match="valid"):
        Diagnostics(tmp_path / "x", prof, priority="low")


def _running(pid):
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")


def test_worker_processes_end_when_the_instrument_is_killed(tmp_path):
    """kill -9 of the instrument leaves no renderer or diagnostics process behind."""
    pytest.importorskip("raingauge.render.simulator").simulate
    script = (
        "import sys, time\n"
        "from raingauge.instrument.loop import Diagnostics\n"
        "from raingauge.instrument.sources import SimulatedSource, scaled_profile\n"
        "from raingauge.profile import load_profile\n"
        "p = scaled_profile(load_profile('gauge-default'), 48, 32)\n"
        "d = Diagnostics(sys.argv[1], p).start((4,) + p.shape)\n"
        "s = SimulatedSource(5.0, p, prefetch=2)\n"
        "s.open()\n"
        "print(d.pid, s._proc.pid, flush=True)\n"
        "time.sleep(120)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script, str(tmp_path / "d")], stdout=subprocess.PIPE, text=True)
    try:
        pids = [int(v) for v in proc.stdout.readline().split()]
        assert len(pids) == 2 and all(_running(p) for p in pids)
    finally:
        proc.kill()
        proc.wait()
    # (the workers poll for their parent; a loaded machine can take a while to schedule them)
    deadline = time.monotonic() + 60
    while any(_running(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(_running(p) for p in pids)


@pytest.mark.parametrize("duration", ["-1", "0", "nan"])
def test_run_refuses_a_duration_that_is_not_positive(cli_error, duration):
    _, err = cli_error(["run", "--duration", duration, "--db", "off", "--modbus-tcp", "off", "--quiet"],
                       "must be a positive number of seconds")
    assert f"--duration {duration}" in err


@pytest.mark.parametrize("spec, message", [
    ("host:99999", "Modbus TCP address 'host:99999': port must be 0-65535"),
    (":abc", "Modbus TCP address ':abc': port 'abc' is not a number 0-65535"),
    ("10.0.0.1:", "Modbus TCP address '10.0.0.1:': port '' is not a number 0-65535"),
])
def test_run_refuses_a_bad_modbus_tcp_address(cli_error, spec, message):
    _, err = cli_error(["run", "--modbus-tcp", spec, "--duration", "1", "--db", "off", "--quiet"], message)
    assert err.count("Fix:") == 1, err
    assert "[modbus].tcp" in err


@pytest.mark.parametrize("toml, message", [
    ("[gauge]\nwindow_s = 1e400\n", "key [gauge].window_s: expected a finite number, got inf"),
    ("[diagnostics]\ninterval_s = nan\n", "key [diagnostics].interval_s: expected a finite number, got nan"),
    ("[gauge]\nwindow_s = \"abc\"\n", "key [gauge].window_s: expected a number, got 'abc'"),
    ("[gauge]\ncompleteness_probe = \"yes\"\n", "key [gauge].completeness_probe: expected true or false"),
    ("[source\nuri =\n", "not valid TOML"),
])
def test_run_refuses_a_malformed_config_file(tmp_path, cli_error, toml, message):
    cfg = tmp_path / "raingauge.toml"
    cfg.write_text(toml)
    _, err = cli_error(["run", "--config", cfg, "--duration", "1", "--db", "off", "--modbus-tcp", "off", "--quiet"],
                       message)
    assert "Fix:" in err


@pytest.mark.parametrize("source, message", [
    ("simulate:-3", "the rain rate must be a finite number >= 0 mm/h"),
    ("simulate:inf", "the rain rate must be a finite number >= 0 mm/h"),
    ("simulate:abc", "the rain rate 'abc' is not a number"),
])
def test_run_refuses_a_bad_simulated_rain_rate(cli_error, source, message):
    _, err = cli_error(["run", "--source", source, "--duration", "1", "--db", "off", "--modbus-tcp", "off", "--quiet"],
                       message)
    assert "Fix: e.g. simulate:10" in err


@pytest.mark.parametrize("option, spec, message", [
    ("--serial", "/dev/ttyUSB0:96OO", "baud rate '96OO' is not a whole number"),
    ("--modbus-rtu", "/dev/ttyUSB1:12", "baud rate 12 is outside"),
])
def test_run_refuses_a_malformed_serial_port(cli_error, option, spec, message):
    _, err = cli_error(["run", option, spec, "--duration", "1", "--db", "off", "--modbus-tcp", "off", "--quiet"],
                       message)
    assert "Fix:" in err


def test_run_refuses_a_recording_with_no_usable_frames(tmp_path, cli_error):
    import cv2

    wrong_size = tmp_path / "wrong_size"
    wrong_size.mkdir()
    for i in range(4):
        cv2.imwrite(str(wrong_size / f"{i:03d}.png"), np.full((90, 120), 40, np.uint8))
    _, err = cli_error(["run", "--source", wrong_size, "--sim-size", "160x120", "--fast", "--db", "off",
                        "--modbus-tcp", "off", "--quiet"], "gave 0 usable frame(s) (4 unreadable or not")
    assert "Fix:" in err
    two = tmp_path / "two"
    two.mkdir()
    for i in range(2):
        cv2.imwrite(str(two / f"{i:03d}.png"), np.full((720, 1280), 40, np.uint8))
    cli_error(["run", "--source", two, "--fast", "--db", "off", "--modbus-tcp", "off", "--quiet"],
              "the gauge needs at least 3 consecutive frames")


def test_config_switches_the_completeness_probe(tmp_path):
    """[gauge].completeness_probe reaches the gauge the instrument builds (on by default)."""
    from raingauge.commands.run import build_instrument
    from raingauge.instrument.config import config_from_dict
    from raingauge.instrument.loop import make_gauge

    made = []

    def factory(*a, **kw):
        made.append(kw)
        return make_gauge(*a, **kw)

    for flag in (False, True):
        cfg = config_from_dict({"gauge": {"completeness_probe": flag}, "modbus": {"tcp": ""},
                                "history": {"path": ""}, "diagnostics": {"enabled": False},
                                "source": {"uri": "simulate:5", "size": [96, 64]}})
        inst = build_instrument(cfg, print_records=False, gauge_factory=factory)
        inst._new_gauge(0.0)
        assert (inst._gauge.probe is not None) == flag
    assert made[0]["completeness_probe"] is False and "completeness_probe" not in made[1]
