"""History database: WAL, every field stored, CSV export, sqlite-utils CLI, kill -9, full disk."""

from __future__ import annotations

import csv
import io
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from firmware_interface.fields import csv_header, record_defaults
from raingauge.cli import main as cli_main
from raingauge.errors import InputError
from raingauge.history import History, StorageFull, parse_iso

T0 = 1_790_000_000.0  # 2026-09-21T14:13:20Z


def _record(i: int, **kw):
    rec = record_defaults()
    rec.update(time_unix=T0 + 10 * i, t_start_s=10 * i - 60, t_end_s=10 * i, window_s=60.0,
               rain_rate_mm_h=0.5 * i, accumulation_mm=0.01 * i, drops_counted=i,
               quality=["few_drops"] if i % 2 else [], exposure_s=0.004, f_number=2.0,
               focus_distance_m=2.5, frame_rate_hz=30.0, status=1,
               dsd_d_mm=[0.062 + 0.125 * k for k in range(32)], dsd_n_m3_mm=[float(i + k) for k in range(32)])
    rec.update(kw)
    return rec


def test_wal_and_every_field_round_trips(tmp_path):
    h = History(tmp_path / "h.sqlite")
    for i in range(5):
        h.append(_record(i))
    assert h.db.journal_mode == "wal"
    rows = list(h.rows())
    assert len(rows) == 5 and list(rows[0]) == csv_header()
    r = rows[3]
    assert r["rain_rate_mm_h"] == 1.5 and r["quality"] == "few_drops" and r["drops_counted"] == 3
    assert r["dsd_n_m3_mm_32"] == 34.0 and r["exposure_s"] == 0.004
    assert r["time_utc"].endswith("Z") and parse_iso(r["time_utc"]) == T0 + 30
    assert r["dm_mm"] is None  # NaN stored as NULL
    h.close()


def test_settings_survive_reopen(tmp_path):
    h = History(tmp_path / "h.sqlite")
    h.append(_record(0), settings={"accumulation_mm": 1.25, "unit_id": 4})
    h.close()
    h = History(tmp_path / "h.sqlite")
    assert h.settings() == {"accumulation_mm": 1.25, "unit_id": 4}
    h.close()


def test_retention_deletes_old_rows(tmp_path):
    now = time.time()
    h = History(tmp_path / "h.sqlite", retention_days=1.0)
    h.append(_record(0, time_unix=now - 3 * 86400))   # the first append prunes: gone at once
    h.append(_record(1, time_unix=now - 0.5 * 86400))
    assert [r["time_unix"] for r in h.rows()] == [now - 0.5 * 86400]
    assert h.prune(now=now + 86400) == 1
    assert h.count() == 0
    with pytest.raises(Exception, match="retention"):
        History(tmp_path / "x.sqlite", retention_days=0)


def test_export_command_time_window(tmp_path, capsys):
    db = tmp_path / "h.sqlite"
    h = History(db)
    for i in range(10):
        h.append(_record(i))
    h.close()
    start = parse_iso("2026-09-21T14:13:40Z")
    assert start == T0 + 20
    out = tmp_path / "out.csv"
    assert cli_main(["export", "--db", str(db), "--from", "2026-09-21T14:13:40Z",
                     "--to", "2026-09-21T14:14:20", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [float(r["time_unix"]) for r in rows] == [T0 + 20, T0 + 30, T0 + 40, T0 + 50, T0 + 60]
    assert list(rows[0]) == csv_header()
    capsys.readouterr()
    assert cli_main(["export", "--db", str(db), "--csv", "-"]) == 0
    assert len(capsys.readouterr().out.strip().splitlines()) == 11
    assert cli_main(["export", "--db", str(db), "--from", "yesterday"]) == 2
    assert "ISO 8601" in capsys.readouterr().err
    assert cli_main(["export", "--db", str(tmp_path / "none.sqlite")]) == 2


def test_sqlite_utils_cli_reads_the_database_while_it_is_written(tmp_path):
    exe = Path(sys.executable).with_name("sqlite-utils")
    if not exe.exists():
        pytest.skip("sqlite-utils CLI not installed beside the interpreter")
    db = tmp_path / "h.sqlite"
    h = History(db)
    for i in range(3):
        h.append(_record(i))
    out = subprocess.run([str(exe), "rows", str(db), "records", "--csv"], capture_output=True, text=True,
                         check=True, timeout=60).stdout
    h.append(_record(3))  # the writer keeps its connection open
    rows = list(csv.DictReader(io.StringIO(out)))
    assert len(rows) == 3 and float(rows[2]["rain_rate_mm_h"]) == 1.0
    h.close()


def test_plot_command_writes_png(tmp_path):
    db = tmp_path / "h.sqlite"
    h = History(db)
    for i in range(12):
        h.append(_record(i, missing=1 if i == 5 else 0))
    h.close()
    png = tmp_path / "p.png"
    assert cli_main(["plot", "--db", str(db), "--png", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


WRITER = r"""
import sys
from raingauge.history import History
from firmware_interface.fields import record_defaults
h = History(sys.argv[1])
i = int(sys.argv[2])
while True:
    rec = record_defaults()
    rec.update(time_unix=1.79e9 + i, rain_rate_mm_h=float(i), dsd_n_m3_mm=[float(i)] * 32)
    h.append(rec)
    print(i, flush=True)
    i += 1
"""


def test_kill_9_mid_write_loses_no_committed_record(tmp_path):
    db = tmp_path / "h.sqlite"
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    committed: list[int] = []
    start = 0
    for _ in range(3):
        proc = subprocess.Popen([sys.executable, str(script), str(db), str(start)], stdout=subprocess.PIPE, text=True)
        try:
            while len(committed) < start + 40:
                line = proc.stdout.readline()
                assert line, "writer died"
                committed.append(int(line))
        finally:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(10)
            proc.stdout.close()
        h = History(db)  # restart: opens, recovers the WAL
        assert h.integrity_ok()
        stored = {int(r["rain_rate_mm_h"]) for r in h.rows()}
        assert set(committed) <= stored
        start = max(stored) + 1
        h.close()


def test_full_disk_raises_storage_full_and_keeps_old_rows(tmp_path):
    h = History(tmp_path / "h.sqlite")
    h.append(_record(0))
    pages = h.db.execute("PRAGMA page_count").fetchone()[0]
    h.db.execute(f"PRAGMA max_page_count={pages}")
    with pytest.raises(StorageFull, match="full"):
        for i in range(1, 1000):
            h.append(_record(i))
    n = h.count()
    assert n >= 1 and h.integrity_ok()
    h.db.execute("PRAGMA max_page_count=1073741823")
    h.append(_record(2000))
    assert h.count() == n + 1
    h.close()


def test_bad_times_and_paths():
    with pytest.raises(InputError, match="ISO 8601"):
        parse_iso("22/11/2026")
    assert parse_iso("2026-11-22") == parse_iso("2026-11-22T00:00:00+00:00")


@pytest.mark.parametrize("command", [["export"], ["plot", "--png", "out.png"]])
@pytest.mark.parametrize("content, message", [
    (b"this is not a database, just text" * 40, "not a usable SQLite database"),
    (None, "cannot open the history database"),  # a folder given as --db
])
def test_reading_commands_refuse_a_file_that_is_no_database(tmp_path, cli_error, command, content, message):
    db = tmp_path / "notdb.sqlite"
    if content is None:
        db.mkdir()
    else:
        db.write_bytes(content)
    argv = [command[0], "--db", str(db), *[str(tmp_path / a) if a.endswith(".png") else a for a in command[1:]]]
    _, err = cli_error(argv, message)
    assert "Fix: give the --db that `raingauge run` writes" in err
    assert not (tmp_path / "out.png").exists()


@pytest.mark.parametrize("command, option", [(["export"], "--csv"), (["plot"], "--png")])
@pytest.mark.parametrize("target", ["folder", "missing/out.file"])
def test_reading_commands_refuse_an_unwritable_output(tmp_path, cli_error, command, option, target):
    db = tmp_path / "h.sqlite"
    h = History(db)
    for i in range(3):
        h.append(_record(i))
    h.close()
    (tmp_path / "folder").mkdir()
    out = tmp_path / target
    _, err = cli_error([*command, "--db", db, option, out], f"{option} {out}: cannot write")
    assert "Fix: give a writable file path" in err
    assert not (tmp_path / "missing").exists() and not (tmp_path / "folder.png").exists()


def test_plot_writes_png_to_the_name_given(tmp_path):
    """Without a .png suffix the plot still goes to exactly OUT (as PNG), not to OUT.png."""
    db = tmp_path / "h.sqlite"
    h = History(db)
    for i in range(3):
        h.append(_record(i))
    h.close()
    out = tmp_path / "history-plot"
    assert cli_main(["plot", "--db", str(db), "--png", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (tmp_path / "history-plot.png").exists()
