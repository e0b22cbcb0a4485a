"""`raingauge derain IN OUT`: image folders and videos, masks, needle maps, errors."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from raingauge.cli import main
from raingauge.videoio import read_frames
from test_vision_synth import make_clip


def _psnr(a, b):
    return 10 * np.log10(255.0 ** 2 / max(float(np.mean((a.astype(float) - b.astype(float)) ** 2)), 1e-12))


@pytest.fixture(scope="module")
def clip():
    return make_clip(T=20, n_streaks=8, seed=9)


def test_folder_in_folder_out_with_mask_and_needles(tmp_path, clip, capsys):
    frames, clean, truth = clip
    src = tmp_path / "in"
    src.mkdir()
    for i, f in enumerate(frames):
        cv2.imwrite(str(src / f"f{i:03d}.png"), f)
    rc = main(["derain", str(src), str(tmp_path / "out"), "--mask", str(tmp_path / "mask"),
               "--needles", str(tmp_path / "needles"), "--c", "3", "--l", "11", "--f", "30"])
    assert rc == 0
    out = read_frames(tmp_path / "out")
    assert out.shape == frames.shape                           # one output per input, gray stays gray
    assert _psnr(out, clean) > _psnr(frames, clean) + 3
    masks = read_frames(tmp_path / "mask", mode="gray")
    assert masks.shape == frames.shape and set(np.unique(masks)) <= {0, 255}
    assert ((masks > 0) & truth).sum() > 0.5 * (masks > 0).sum()
    needles = read_frames(tmp_path / "needles", mode="bgr")
    assert needles.shape == frames.shape + (3,)
    assert "rain direction" in capsys.readouterr().out


def test_video_in_video_out_keeps_repeated_frames(tmp_path, clip):
    frames, clean, _ = clip
    seq = np.concatenate([frames[:10], frames[9:10], frames[10:]])   # frame 9 repeated
    path = tmp_path / "in.mkv"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 30, (frames.shape[2], frames.shape[1]), False)
    for f in seq:
        w.write(f)
    w.release()
    assert main(["derain", str(path), str(tmp_path / "out.mkv"), "--quiet"]) == 0
    out = read_frames(tmp_path / "out.mkv", mode="gray")
    assert len(out) == len(seq)
    np.testing.assert_array_equal(out[9], out[10])


def test_clear_errors(tmp_path, clip, capsys):
    frames, _, _ = clip
    assert main(["derain", str(tmp_path / "missing"), str(tmp_path / "o")]) == 2
    assert "no such file" in capsys.readouterr().err
    short = tmp_path / "short"
    short.mkdir()
    for i in range(2):
        cv2.imwrite(str(short / f"{i}.png"), frames[i])
    assert main(["derain", str(short), str(tmp_path / "o2")]) == 2
    assert "at least 3 frames" in capsys.readouterr().err
    bad = tmp_path / "bad.mkv"
    bad.write_bytes(b"not a video at all")
    assert main(["derain", str(bad), str(tmp_path / "o3.mkv")]) == 2
    assert "cannot open" in capsys.readouterr().err
    assert main(["derain", str(short), str(tmp_path / "o4.mkv")]) == 2
    assert "must be a folder" in capsys.readouterr().err
    assert main(["derain", str(short), str(tmp_path / "o5"), "--l", "10"]) == 2
    assert "odd" in capsys.readouterr().err


@pytest.mark.parametrize("which", ["OUT", "--mask", "--needles"])
def test_unwritable_output_is_refused_clearly(tmp_path, clip, cli_error, which):
    """An output below a regular file cannot be created: a clear error, not a traceback."""
    frames, _, _ = clip
    src = tmp_path / "in"
    src.mkdir()
    for i, f in enumerate(frames[:4]):
        cv2.imwrite(str(src / f"f{i:03d}.png"), f)
    blocker = tmp_path / "afile"
    blocker.write_text("not a folder")
    bad = blocker / "sub"
    out = bad if which == "OUT" else tmp_path / "out"
    extra = [] if which == "OUT" else [which, bad]
    _, err = cli_error(["derain", src, out, *extra, "--quiet"], f"{bad}: cannot create the output folder")
    assert "Fix: give a path in a writable folder" in err
