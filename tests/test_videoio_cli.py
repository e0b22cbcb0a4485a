"""Frame I/O (video files and image folders) and the command-line front end."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from raingauge import cli
from raingauge.errors import InputError
from raingauge.videoio import FrameReader, FrameWriter, read_frames


def clip(n=5, color=False):
    rng = np.random.default_rng(1)
    shape = (24, 32, 3) if color else (24, 32)
    return [rng.integers(0, 256, shape, dtype=np.uint8) for _ in range(n)]


@pytest.mark.parametrize("target", ["out.mkv", "frames"])
@pytest.mark.parametrize("color", [False, True])
def test_lossless_round_trip(tmp_path, target, color):
    frames = clip(color=color)
    with FrameWriter(tmp_path / target, fps=25) as w:
        for f in frames:
            w.write(f)
    back = read_frames(tmp_path / target)
    assert back.shape == (len(frames),) + frames[0].shape
    assert np.array_equal(back, np.stack(frames))


def test_folder_reads_in_name_order_and_counts_corrupt(tmp_path):
    import cv2

    for i, v in [(3, 30), (1, 10), (2, 20)]:
        cv2.imwrite(str(tmp_path / f"{i:03d}.png"), np.full((4, 4), v, np.uint8))
    (tmp_path / "004.png").write_bytes(b"not a png")
    r = FrameReader(tmp_path)
    values = [int(f[0, 0]) for f in r]
    assert values == [10, 20, 30]
    assert r.corrupt_frames == 1


def test_unreadable_inputs_give_clear_errors(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        FrameReader(tmp_path / "missing.mkv")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no images"):
        FrameReader(tmp_path / "empty")
    bad = tmp_path / "bad.mkv"
    bad.write_bytes(b"\x00" * 100)
    with pytest.raises(InputError):
        read_frames(bad)


def test_cli_help_lists_every_command(capsys):
    assert cli.main([]) == 0
    out = capsys.readouterr().out
    for name in cli.COMMANDS:
        assert name in out


def test_cli_reports_errors_without_traceback(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "raingauge", "profile", str(tmp_path / "none.toml")],
        capture_output=True, text=True,
    )
    assert proc.returncode == 2
    assert "raingauge: error: camera profile" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_every_registered_command_module_exists():
    import importlib

    for name, module in cli.COMMANDS.items():
        mod = importlib.import_module(module)
        assert callable(mod.add_arguments) and callable(mod.run), name
        assert (mod.__doc__ or "").strip(), f"{name} needs a docstring (its help line)"
