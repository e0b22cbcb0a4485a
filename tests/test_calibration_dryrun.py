"""Dry run: false detections on rain-free video, and the scene-motion warning."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.dryrun import dry_run, scene_motion
from calibration.noise import detection_threshold
from calibration.synthetic import render_dry_clip
from raingauge.errors import InputError


def test_still_scene_calibrated_threshold_has_no_motion_warning():
    frames, truth = render_dry_clip(n_frames=40, sigma_dn=1.5, seed=1)
    c = detection_threshold(1.5)
    res = dry_run(frames, frame_rate_hz=30.0, exposure_s=0.004, c_dn=c, noise_sigma_dn=1.5)
    assert not any("shifts" in w or "change between" in w for w in res.warnings)
    assert res.shift_px_per_frame < 0.25
    assert res.seconds == pytest.approx(38 / 30.0)
    # The candidate rate is about the rate the threshold was set for (1e-3 per pixel and frame).
    assert 2e-4 < res.candidate_fraction < 3e-3
    assert res.false_per_minute == pytest.approx(res.false_streaks / res.seconds * 60.0)


def test_lower_threshold_gives_more_false_detections():
    frames, _ = render_dry_clip(n_frames=30, sigma_dn=3.0, seed=2)
    low = dry_run(frames, frame_rate_hz=30.0, exposure_s=0.004, c_dn=1.0, noise_sigma_dn=3.0)
    high = dry_run(frames, frame_rate_hz=30.0, exposure_s=0.004, c_dn=detection_threshold(3.0, false_rate=1e-5),
                   noise_sigma_dn=3.0)
    assert low.candidate_fraction > 20 * high.candidate_fraction
    assert low.false_streaks > high.false_streaks
    assert high.false_streaks == 0


def test_drifting_scene_is_warned_and_its_shift_measured():
    frames, _ = render_dry_clip(n_frames=20, sigma_dn=1.0, drift_px_per_frame=0.8, seed=3)
    res = dry_run(frames, frame_rate_hz=30.0, exposure_s=0.004, c_dn=3.0, noise_sigma_dn=1.0)
    assert res.shift_px_per_frame == pytest.approx(0.8, abs=0.15)
    assert any("shifts by" in w for w in res.warnings)
    shift, changed = scene_motion(frames.astype(np.float32), noise_sigma_dn=1.0)
    assert changed > 0.02


def test_too_few_frames():
    frames, _ = render_dry_clip(n_frames=3)
    with pytest.raises(InputError, match="at least 5"):
        dry_run(frames, frame_rate_hz=30.0, exposure_s=0.004, c_dn=3.0, noise_sigma_dn=1.0)


def test_frames_of_two_sizes_or_colour_frames_are_refused():
    from calibration.noise import calibrate_noise

    frames, _ = render_dry_clip(n_frames=8, seed=4)
    mixed = [*frames[:4], frames[4][:, :-2], *frames[5:]]
    with pytest.raises(InputError, match="differ in size"):
        dry_run(mixed, frame_rate_hz=30.0, exposure_s=0.004, c_dn=3.0, noise_sigma_dn=1.0)
    with pytest.raises(InputError, match="still frames differ in size"):
        calibrate_noise(iter(mixed))
    colour = [np.dstack([f] * 3) for f in frames]
    with pytest.raises(InputError, match=r"expected gray \(M, N\) frames"):
        dry_run(iter(colour), frame_rate_hz=30.0, exposure_s=0.004, c_dn=3.0, noise_sigma_dn=1.0)
    with pytest.raises(InputError, match=r"expected gray \(M, N\) frames"):
        calibrate_noise(iter(colour))


def test_live_camera_names():
    from calibration.frames import camera_device, is_camera

    assert is_camera("camera:0") and not is_camera("views/camera:0.png")
    assert camera_device("camera:2") == 2 and camera_device("camera:/dev/video1") == "/dev/video1"
    assert not is_camera("views") and not is_camera("clip.mkv")
