"""Radiometric response: a bracket rendered through a known non-linear camera is linearised."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.radiometry import (
    BracketError,
    calibrate_response,
    linearity,
    parse_exposure_name,
    read_bracket,
    response_table,
    write_table,
)
from calibration.synthetic import exposure_file_name, inverse_response_table, render_exposure_bracket
from raingauge.profile import load_response_table

CODES = np.arange(16, 251)


def _true_inverse(model: str) -> np.ndarray:
    """Relative exposure producing each code, by inverting the known response numerically."""
    return inverse_response_table(model) / 255.0


def _write_bracket(folder, images, times, *, names=None):
    folder.mkdir(parents=True, exist_ok=True)
    names = names or [exposure_file_name(t) for t in times]
    for im, name in zip(images, names):
        cv2.imwrite(str(folder / name), im)
    return folder


@pytest.mark.parametrize("model", ["gamma2.2", "film"])
@pytest.mark.parametrize("method", ["debevec", "robertson"])
def test_table_linearises_a_known_response_within_2_percent(model, method, tmp_path):
    images, truth = render_exposure_bracket(response=model, seed=1)
    folder = _write_bracket(tmp_path / "b", images, truth["exposures_s"])
    imgs, times, _ = read_bracket(folder)
    assert np.allclose(times, sorted(truth["exposures_s"]), rtol=1e-5)
    res = calibrate_response(imgs, times, method=method)
    ratio = res.table[CODES] / _true_inverse(model)[CODES]
    ratio /= np.median(ratio)  # the response is known up to a scale
    assert np.max(np.abs(ratio - 1)) < 0.02
    assert res.table[0] == 0 and res.table[255] == pytest.approx(255)
    assert np.all(np.diff(res.table) >= 0)
    # Linearised images are proportional to radiance x exposure (mid codes, away from quantisation).
    ref = None
    for im, t in zip(images, truth["exposures_s"]):
        sel = (im >= 64) & (im <= 240)
        r = res.table[im[sel]] / (truth["radiance"][sel] * t)
        ref = np.median(r) if ref is None else ref
        assert np.median(np.abs(r / ref - 1)) < 0.02
    # The reported linearity improves by an order of magnitude on the raw codes.
    assert res.linearity_rms < 0.03 < 0.3 < res.raw_linearity_rms
    assert not res.is_linear


def test_gamma_is_reported():
    images, truth = render_exposure_bracket(response="gamma2.2", seed=2)
    bgr = [cv2.cvtColor(i, cv2.COLOR_GRAY2BGR) for i in images]
    res = calibrate_response(bgr, truth["exposures_s"])
    assert res.gamma == pytest.approx(2.2, rel=0.05)


def test_linear_camera_is_recognised():
    images, truth = render_exposure_bracket(response="linear", seed=3)
    bgr = [cv2.cvtColor(i, cv2.COLOR_GRAY2BGR) for i in images]
    res = calibrate_response(bgr, truth["exposures_s"])
    assert res.is_linear
    assert res.gamma == pytest.approx(1.0, abs=0.05)


def test_linearity_metric_against_independent_expectation():
    # Through the exact inverse table the bracket is linear up to quantisation; through the identity it is not.
    images, truth = render_exposure_bracket(response="gamma2.2", noise_sigma_dn=0.0, seed=4)
    exact = _true_inverse("gamma2.2") * 255.0
    rms_exact, _ = linearity(images, np.array(truth["exposures_s"]), exact)
    rms_raw, _ = linearity(images, np.array(truth["exposures_s"]), np.arange(256.0))
    assert rms_exact < 0.02
    assert rms_raw > 0.3


@pytest.mark.parametrize("name, seconds", [
    ("exp_0.004s.png", 0.004), ("scene_2.5e-4s.tif", 2.5e-4), ("exp_1-250s.png", 1 / 250),
    ("b_1s.png", 1.0), ("exp_0.004.png", None), ("frame_12.png", None), ("exp_1-0s.png", None),
])
def test_exposure_from_file_name(name, seconds):
    got = parse_exposure_name(name)
    assert got == (pytest.approx(seconds) if seconds is not None else None)


def test_sidecar_file_wins(tmp_path):
    images, truth = render_exposure_bracket(seed=5)
    names = [f"img{i}.png" for i in range(len(images))]
    folder = _write_bracket(tmp_path / "b", images, truth["exposures_s"], names=names)
    lines = ["# file seconds"] + [f"{n} 1/{round(1 / t)}" for n, t in zip(names, truth["exposures_s"])]
    (folder / "exposures.txt").write_text("\n".join(lines) + "\n")
    _, times, got = read_bracket(folder)
    assert got == names  # already in exposure order
    assert np.allclose(times, [1 / round(1 / t) for t in truth["exposures_s"]])


def test_one_exposure_is_refused(tmp_path):
    images, _ = render_exposure_bracket(exposures_s=(0.004,), seed=6)
    folder = _write_bracket(tmp_path / "b", images + images, (0.004, 0.004), names=["a_0.004s.png", "b_0.004s.png"])
    with pytest.raises(BracketError, match="at least 3 different exposures"):
        read_bracket(folder)


def test_narrow_bracket_is_refused(tmp_path):
    times = (0.004, 0.005, 0.006)
    images, _ = render_exposure_bracket(exposures_s=times, seed=7)
    with pytest.raises(BracketError, match="at least 4x"):
        read_bracket(_write_bracket(tmp_path / "b", images, times))


def test_missing_exposure_and_unlisted_file(tmp_path):
    images, truth = render_exposure_bracket(seed=8)
    folder = _write_bracket(tmp_path / "b", images, truth["exposures_s"])
    cv2.imwrite(str(folder / "extra.png"), images[0])
    with pytest.raises(BracketError, match="no exposure time in the file name extra.png"):
        read_bracket(folder)
    (folder / "exposures.txt").write_text("extra.png 1/100\n")
    with pytest.raises(BracketError, match="is not listed in exposures.txt"):
        read_bracket(folder)


def test_unreadable_bracket_image(tmp_path):
    images, truth = render_exposure_bracket(seed=9)
    folder = _write_bracket(tmp_path / "b", images, truth["exposures_s"])
    (folder / "exp_0.5s.png").write_bytes(b"\x89PNG broken")
    with pytest.raises(BracketError, match="cannot be read"):
        read_bracket(folder)


def test_table_round_trips_through_the_profile_reader(tmp_path):
    curve = np.r_[np.nan, np.linspace(0.01, 4.0, 255) ** 2.2]
    table = response_table(curve)
    path = write_table(tmp_path / "t.txt", table)
    back = load_response_table(path)
    assert np.allclose(back, table, atol=1e-5)
    assert back[0] == 0 and back[255] == pytest.approx(255)
