"""Camera profiles: the TOML contract, validation errors that name key and fix."""

from __future__ import annotations

import numpy as np
import pytest

from raingauge.errors import ProfileError
from raingauge.profile import (
    default_profile,
    load_profile,
    profile_to_toml,
    shipped_profiles,
    write_profile,
)

GOOD = """
[camera]
name = "t"
width_px = 640
height_px = 480
frame_rate_hz = 30.0
focal_length_px = 5000.0
f_number = 2.8
focus_distance_m = 3.0
exposure_s = 0.004
noise_sigma_dn = 1.5
response = "linear"
"""


def write(tmp_path, text, name="p.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_shipped_profiles_load_and_are_valid():
    assert {"gauge-default", "canon_xl1"} <= set(shipped_profiles())
    d = default_profile()
    assert d.name == "gauge-default"
    assert d.shape == (720, 1280)
    assert d.exposure_s <= d.frame_interval_s
    xl1 = load_profile("canon_xl1")
    assert (xl1.width_px, xl1.height_px, xl1.frame_rate_hz) == (720, 480, 30.0)
    # The gauge default respects the paper's focus rule z0 <= 2 f a_min (a_min = 0.25 mm radius).
    assert d.focus_distance_m <= 2 * d.focal_length_px * 0.25e-3


def test_frozen_and_replace_validates(tmp_path):
    p = load_profile(write(tmp_path, GOOD))
    with pytest.raises(Exception):
        p.f_number = 4.0  # frozen
    q = p.replace(f_number=4.0)
    assert q.f_number == 4.0 and p.f_number == 2.8
    with pytest.raises(ProfileError, match="exposure_s"):
        p.replace(exposure_s=0.1)


@pytest.mark.parametrize(
    "edit, key",
    [
        (lambda t: t.replace('focal_length_px = 5000.0\n', ''), "focal_length_px"),
        (lambda t: t.replace('width_px = 640', 'width_px = "640"'), "width_px"),
        (lambda t: t.replace('focus_distance_m = 3.0', 'focus_distance_m = -1.0'), "focus_distance_m"),
        (lambda t: t.replace('exposure_s = 0.004', 'exposure_s = 0.05'), "exposure_s"),
        (lambda t: t.replace('f_number = 2.8', 'f_number = 0.0'), "f_number"),
        (lambda t: t.replace('noise_sigma_dn = 1.5', 'noise_sigma_dn = -2'), "noise_sigma_dn"),
        (lambda t: t + "bogus = 1\n", "bogus"),
    ],
)
def test_bad_values_name_file_key_and_fix(tmp_path, edit, key):
    path = write(tmp_path, edit(GOOD))
    with pytest.raises(ProfileError) as info:
        load_profile(path)
    msg = str(info.value)
    assert str(path) in msg
    assert key in msg
    assert "Fix" in msg or "remove it" in msg or "expected" in msg or "must" in msg


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(ProfileError, match="does not exist"):
        load_profile(tmp_path / "nope.toml")
    with pytest.raises(ProfileError, match="not valid TOML"):
        load_profile(write(tmp_path, "[camera\nname="))
    with pytest.raises(ProfileError, match=r"\[camera\]"):
        load_profile(write(tmp_path, "[lens]\nx = 1\n"))


def test_response_table_linearises_and_round_trips(tmp_path):
    codes = np.arange(256.0)
    table = 255.0 * (codes / 255.0) ** 2.2  # a gamma-encoded camera
    (tmp_path / "resp.txt").write_text("\n".join(f"{v:.6f}" for v in table))
    p = load_profile(write(tmp_path, GOOD.replace('response = "linear"', 'response = "resp.txt"')))
    assert not p.is_linear
    frame = np.array([[0, 128, 255]], dtype=np.uint8)
    lin = p.linearize(frame)
    assert lin.dtype == np.float32
    np.testing.assert_allclose(lin, table[[0, 128, 255]][None, :], rtol=1e-6)
    assert np.array_equal(p.delinearize(lin), frame)


def test_bad_response_tables(tmp_path):
    (tmp_path / "short.txt").write_text("1 2 3")
    with pytest.raises(ProfileError, match="256"):
        load_profile(write(tmp_path, GOOD.replace('response = "linear"', 'response = "short.txt"')))
    (tmp_path / "down.txt").write_text("\n".join(str(255 - i) for i in range(256)))
    with pytest.raises(ProfileError, match="monoton"):
        load_profile(write(tmp_path, GOOD.replace('response = "linear"', 'response = "down.txt"')))
    with pytest.raises(ProfileError, match="does not exist"):
        load_profile(write(tmp_path, GOOD.replace('response = "linear"', 'response = "gone.txt"')))


def test_write_then_load_round_trip(tmp_path):
    p = load_profile(write(tmp_path, GOOD)).replace(principal_point_px=[320.5, 240.25], f_number_range=[1.4, 16.0])
    out = write_profile(p, tmp_path / "out.toml", provenance={"date": "2026-01-01", "steps": ["geometry"]})
    q = load_profile(out)
    assert q == p
    assert q.provenance["steps"] == ["geometry"]
    assert "[camera]" in profile_to_toml(q)
