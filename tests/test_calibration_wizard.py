"""`raingauge calibrate` end to end: scripted, interactive (answered through a pseudo-terminal), bad input."""

from __future__ import annotations

import json
import os
import shutil
import sys
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibration.synthetic import inverse_response_table, write_demo_captures
from raingauge.cli import main
from raingauge.profile import load_profile


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    folder = tmp_path_factory.mktemp("captures")
    truth = write_demo_captures(folder, seed=7)
    return folder, truth


def _batch(captures, out, *extra):
    folder, _ = captures
    return main(["calibrate", "--checkerboard", str(folder / "checkerboard"), "--pattern", "9x6",
                 "--square-m", "0.025", "--bracket", str(folder / "bracket"), "--still", str(folder / "still"),
                 "--dry", str(folder / "dry"), "--out", str(out), *extra])


def test_scripted_calibration_writes_a_profile_the_gauge_loads(captures, tmp_path, capsys):
    folder, truth = captures
    out = tmp_path / "site.toml"
    assert _batch(captures, out, "--f-numbers", "2,2.8,4,5.6") == 0
    prof = load_profile(out)
    g = truth["geometry"]
    assert prof.focal_length_px == pytest.approx(g["focal_length_px"], rel=0.01)
    assert (prof.width_px, prof.height_px) == tuple(g["image_size"])
    assert np.allclose(prof.principal_point_px, g["principal_point_px"], atol=5)
    # The response table sits beside the profile, referenced by a relative path, and linearises
    # the known camera within 2% (up to scale) over the usable codes.
    doc = tomllib.loads(out.read_text())
    assert doc["camera"]["response"] == "site.response.txt"
    assert (tmp_path / "site.response.txt").is_file()
    codes = np.arange(16, 251)
    ratio = prof.response_table[codes] / inverse_response_table(truth["bracket"]["response"])[codes]
    assert np.max(np.abs(ratio / np.median(ratio) - 1)) < 0.02
    # Noise measured in linear units through that table.
    assert prof.noise_sigma_dn == pytest.approx(truth["still"]["sigma_dn"], rel=0.10)
    assert prof.detection_threshold_dn > 2 * prof.noise_sigma_dn
    # Focus plan: z0 = 2 f a_min, widest of the given F-numbers.
    assert prof.focus_distance_m == pytest.approx(2 * prof.focal_length_px * 0.5e-3, rel=1e-6)
    assert prof.f_number == 2.0
    prov = doc["provenance"]
    assert prov["steps_done"] == ["geometry", "response", "noise", "focus", "dry_run"]
    assert prov["steps_not_calibrated"] == []
    assert prov["geometry"]["calibrated"] and prov["residuals"]["geometry_rms_px"] < 0.5
    assert prov["residuals"]["response_linearity_rms"] < 0.03
    assert "dry_run_false_per_min" in prov["residuals"]
    assert prov["date"].endswith("Z")
    assert "wrote" in capsys.readouterr().out


def test_steps_not_run_keep_the_base_and_are_marked(captures, tmp_path):
    folder, _ = captures
    out = tmp_path / "noise-only.toml"
    assert main(["calibrate", "--still", str(folder / "still"), "--base", "canon_xl1", "--out", str(out)]) == 0
    prof = load_profile(out)
    base = load_profile("canon_xl1")
    for key in ("focal_length_px", "width_px", "height_px", "f_number", "focus_distance_m", "exposure_s"):
        assert getattr(prof, key) == getattr(base, key)
    assert prof.is_linear
    assert prof.noise_sigma_dn != base.noise_sigma_dn
    prov = tomllib.loads(out.read_text())["provenance"]
    assert prov["steps_done"] == ["noise"]
    assert prov["geometry"] == {"calibrated": False, "kept_from": "canon_xl1",
                                "keys": ["focal_length_px", "principal_point_px", "distortion", "width_px",
                                         "height_px"]}
    assert prov["response"]["calibrated"] is False
    assert set(prov["steps_not_calibrated"]) == {"geometry", "response", "focus", "dry_run"}


def _assert_nothing_written(outdir: Path):
    assert sorted(p.name for p in outdir.iterdir()) == []


@pytest.mark.parametrize("case", ["unreadable", "no_pattern", "one_exposure"])
def test_bad_input_gives_a_clear_error_and_writes_nothing(captures, tmp_path, capsys, case):
    folder, _ = captures
    bad = tmp_path / "bad"
    shutil.copytree(folder, bad, ignore=shutil.ignore_patterns("truth.json", "view_05.png", "view_06.png"))
    outdir = tmp_path / "out"
    outdir.mkdir()
    pattern = "9x6"
    if case == "unreadable":
        (bad / "checkerboard" / "view_03.png").write_bytes(b"\x89PNG\r\n\x1a\n truncated")
        expect = "view_03.png: cannot be read"
    elif case == "no_pattern":
        pattern = "8x5"
        expect = "8x5 checkerboard pattern was not found"
    else:
        for p in (bad / "bracket").iterdir():
            if not p.name.startswith("exp_0.004s"):
                p.unlink()
        expect = "at least 3 different exposures"
    code = main(["calibrate", "--checkerboard", str(bad / "checkerboard"), "--pattern", pattern,
                 "--square-m", "0.025", "--bracket", str(bad / "bracket"), "--out", str(outdir / "x.toml")])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("raingauge: error:") and expect in err and "Fix:" in err
    _assert_nothing_written(outdir)


def test_missing_square_size_and_nothing_to_do(captures, tmp_path, capsys):
    folder, _ = captures
    code = main(["calibrate", "--checkerboard", str(folder / "checkerboard"), "--out", str(tmp_path / "x.toml")])
    assert code == 2 and "--square-m" in capsys.readouterr().err
    _assert_nothing_written(tmp_path)


# ------------------------------------------------------------------- interactive
def _spawn(args, cwd):
    pexpect = pytest.importorskip("pexpect")
    env = dict(os.environ, PYTHONUNBUFFERED="1", COLUMNS="200")
    child = pexpect.spawn(sys.executable, ["-m", "raingauge", "calibrate", *args], cwd=str(cwd), env=env,
                          encoding="utf-8", timeout=90, dimensions=(50, 250))
    return child


def _answer(child, prompt: str, answer: str):
    child.expect_exact(prompt)
    child.sendline(answer)


def _exit_status(child) -> int:
    """Wait for the wizard to end; its exit status."""
    child.expect(__import__("pexpect").EOF)
    child.close()
    return child.exitstatus


def _skip_the_rest_and_write(child, name: str) -> int:
    """Skip the noise, focus and dry-run steps, keep the profile name, confirm writing; the exit status."""
    _answer(child, "Still scene", "")
    _answer(child, "Plan the focus distance and aperture? [Y/n]:", "n")
    _answer(child, "Dry run", "")
    _answer(child, f"Profile name [{name}]:", "")
    _answer(child, "? [Y/n]:", "")
    return _exit_status(child)


def test_interactive_wizard_end_to_end(captures, tmp_path):
    folder, truth = captures
    out = tmp_path / "field.toml"
    child = _spawn(["--out", str(out)], tmp_path)
    _answer(child, "Base profile (values for the steps you skip) [gauge-default]:", "")
    _answer(child, "Checkerboard views: folder of images, video file or camera:N (empty: skip):",
            str(folder / "checkerboard"))
    _answer(child, "Inner corners COLSxROWS [9x6]:", "")
    _answer(child, "Square size [m] [0.025]:", "0.025")
    child.expect(r"focal length\s+(\d+\.\d+) px")
    f_seen = float(child.match.group(1))
    _answer(child, "Accept this result? [Y/n]:", "")
    _answer(child, "Exposure bracket folder", str(folder / "bracket"))
    _answer(child, "Method, debevec or robertson [debevec]:", "robertson")
    child.expect_exact("linearity")
    _answer(child, "Accept this result? [Y/n]:", "y")
    _answer(child, "Still scene: folder, video or camera:N without rain (empty: skip):", str(folder / "still"))
    child.expect_exact("threshold c")
    _answer(child, "Accept this result? [Y/n]:", "")
    _answer(child, "Plan the focus distance and aperture? [Y/n]:", "")
    _answer(child, "Pixel pitch [m] [5e-06]:", "")
    _answer(child, "F-numbers of the lens", "1.8,2.8,4")
    _answer(child, "Radius of the smallest drop [m] [0.0005]:", "")
    child.expect_exact("sample volume")
    _answer(child, "Focus distance you set on the lens [m]", "")
    _answer(child, "F-number you set on the lens [1.8]:", "2.8")
    _answer(child, "Accept this result? [Y/n]:", "")
    _answer(child, "Dry run: folder, video or camera:N of some seconds without rain (empty: skip):",
            str(folder / "dry"))
    child.expect_exact("false detections")
    _answer(child, "Accept this result? [Y/n]:", "")
    _answer(child, "Profile name [field]:", "field-cam")
    _answer(child, f"Write {out}? [Y/n]:", "")
    child.expect_exact(f"wrote {out}")
    assert _exit_status(child) == 0
    prof = load_profile(out)
    assert prof.name == "field-cam"
    assert prof.focal_length_px == pytest.approx(f_seen, abs=0.01)
    assert prof.focal_length_px == pytest.approx(truth["geometry"]["focal_length_px"], rel=0.01)
    assert prof.f_number == 2.8  # what the technician set, not the plan's F/1.8
    assert prof.focus_distance_m == pytest.approx(2 * prof.focal_length_px * 0.5e-3, rel=1e-3)
    assert not prof.is_linear
    prov = prof.provenance
    assert prov["response"]["method"] == "robertson"
    assert prov["steps_done"] == ["geometry", "response", "noise", "focus", "dry_run"]
    assert not (tmp_path / "field.toml.state.json").exists()  # finished: no session left behind


def test_interactive_session_resumes_after_interruption(captures, tmp_path):
    folder, _ = captures
    out = tmp_path / "resumed.toml"
    state = tmp_path / "resumed.toml.state.json"
    child = _spawn(["--out", str(out)], tmp_path)
    _answer(child, "Base profile (values for the steps you skip) [gauge-default]:", "")
    _answer(child, "Checkerboard views: folder of images, video file or camera:N (empty: skip):",
            str(folder / "checkerboard"))
    _answer(child, "Inner corners COLSxROWS [9x6]:", "")
    _answer(child, "Square size [m] [0.025]:", "")
    _answer(child, "Accept this result? [Y/n]:", "")
    child.expect_exact("Exposure bracket folder")
    child.sendeof()  # the technician's laptop battery dies here
    child.expect_exact("the session is saved")
    assert _exit_status(child) == 1
    assert not out.exists()
    saved = json.loads(state.read_text())
    assert list(saved["results"]) == ["geometry"]

    child = _spawn(["--out", str(out)], tmp_path)
    _answer(child, "(steps done: geometry)? [Y/n]:", "")
    _answer(child, "Redo it? [y/N]:", "")
    _answer(child, "Exposure bracket folder", "")
    assert _skip_the_rest_and_write(child, "resumed") == 0
    prof = load_profile(out)
    assert prof.focal_length_px == pytest.approx(saved["results"]["geometry"]["camera"]["focal_length_px"])
    assert prof.provenance["steps_done"] == ["geometry"]
    assert prof.focus_distance_m == load_profile("gauge-default").focus_distance_m
    assert not state.exists()


def test_interactive_step_error_can_be_retried(captures, tmp_path):
    folder, _ = captures
    broken = tmp_path / "broken"
    broken.mkdir()
    cv2.imwrite(str(broken / "exp_0.01s.png"), np.full((20, 20), 100, np.uint8))
    out = tmp_path / "retry.toml"
    child = _spawn(["--out", str(out)], tmp_path)
    _answer(child, "Base profile (values for the steps you skip) [gauge-default]:", "")
    _answer(child, "Checkerboard views", "")
    _answer(child, "Exposure bracket folder", str(broken))
    _answer(child, "Method, debevec or robertson [debevec]:", "")
    child.expect_exact("error: exposure bracket")
    _answer(child, "Try this step again? [Y/n]:", "")
    _answer(child, "Exposure bracket folder", str(folder / "bracket"))
    _answer(child, "Method, debevec or robertson [debevec]:", "")
    _answer(child, "Accept this result? [Y/n]:", "")
    assert _skip_the_rest_and_write(child, "retry") == 0
    prof = load_profile(out)
    assert prof.provenance["steps_done"] == ["response"]
    assert not prof.is_linear


def test_demo_mode(tmp_path, capsys):
    out = tmp_path / "demo.toml"
    assert main(["calibrate", "--demo", "--out", str(out), "--demo-dir", str(tmp_path / "captures")]) == 0
    text = capsys.readouterr().out
    assert "recovered against truth" in text
    truth = json.loads((tmp_path / "captures" / "truth.json").read_text())
    assert load_profile(out).focal_length_px == pytest.approx(truth["geometry"]["focal_length_px"], rel=0.01)


def test_video_sources_for_still_and_dry_run(captures, tmp_path):
    from raingauge.videoio import FrameWriter, read_frames

    folder, truth = captures
    for name in ("still", "dry"):
        writer = FrameWriter(tmp_path / f"{name}.mkv", fps=25.0)
        for frame in read_frames(folder / name, mode="gray"):
            writer.write(frame)
        writer.close()
    out = tmp_path / "video.toml"
    assert main(["calibrate", "--bracket", str(folder / "bracket"), "--still", str(tmp_path / "still.mkv"),
                 "--dry", str(tmp_path / "dry.mkv"), "--out", str(out)]) == 0
    prof = load_profile(out)
    assert prof.noise_sigma_dn == pytest.approx(truth["still"]["sigma_dn"], rel=0.10)
    dry = prof.provenance["dry_run"]
    assert dry["frame_rate_hz"] == pytest.approx(25.0)  # the video's own rate, not the profile's 30
    assert dry["seconds"] == pytest.approx((45 - 2) / 25.0, rel=1e-3)


def test_unreadable_still_frame_writes_nothing(captures, tmp_path, capsys):
    folder, _ = captures
    still = tmp_path / "still"
    shutil.copytree(folder / "still", still)
    (still / "frame_005.png").write_bytes(b"garbage")
    outdir = tmp_path / "out"
    outdir.mkdir()
    assert main(["calibrate", "--still", str(still), "--out", str(outdir / "x.toml")]) == 2
    assert "1 image(s) cannot be read" in capsys.readouterr().err
    _assert_nothing_written(outdir)


@pytest.mark.parametrize("args, message", [
    (["--false-rate", "2"], "--false-rate"),
    (["--false-rate", "nan"], "--false-rate"),
    (["--square-m", "-1"], "--square-m -1.0 is not a positive number"),
    (["--views", "2"], "at least 5"),
    (["--f-numbers", "abc"], "F-numbers 'abc'"),
    (["--a-min-m", "0"], "--a-min-m"),
    (["--focus-m", "nan"], "--focus-m"),
    (["--max-rms-px", "0"], "--max-rms-px"),
    (["--base", "no-such-camera"], "no-such-camera"),
    (["--square-m", "abc"], "invalid float value: 'abc'"),
])
def test_bad_options_are_refused_before_any_step_runs(captures, tmp_path, cli_error, args, message):
    folder, _ = captures
    out, err = cli_error(["calibrate", "--checkerboard", folder / "checkerboard", "--square-m", "0.025",
                          "--still", folder / "still", "--out", tmp_path / "x.toml", *args], message)
    assert "Fix" in err
    assert "==" not in out                      # no step reported a result
    _assert_nothing_written(tmp_path)
