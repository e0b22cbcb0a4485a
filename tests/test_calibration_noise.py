"""Noise sigma from still frames of known noise, and the Eq. (19) threshold it implies."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.noise import calibrate_noise, detection_threshold, false_candidate_rate
from calibration.synthetic import inverse_response_table as inverse_table
from calibration.synthetic import render_still_frames
from raingauge.errors import InputError


@pytest.mark.parametrize("sigma", [0.8, 2.0, 4.0])
def test_constant_noise_within_10_percent(sigma):
    frames, truth = render_still_frames(read_sigma_dn=sigma, n_frames=12, seed=1)
    res = calibrate_noise(frames)
    assert res.noise_sigma_dn == pytest.approx(truth["sigma_dn"], rel=0.10)
    assert np.all(np.abs(res.sigma_dn / sigma - 1) < 0.15)  # flat against intensity
    assert res.shot_gain_dn < 0.01
    assert res.still_fraction > 0.97
    assert not any("not still" in w for w in res.warnings)


def test_signal_dependent_noise_model():
    frames, truth = render_still_frames(read_sigma_dn=1.0, shot_gain_dn=0.05, n_frames=16, seed=2)
    res = calibrate_noise(frames)
    assert res.noise_sigma_dn == pytest.approx(truth["sigma_dn"], rel=0.10)
    assert res.shot_gain_dn == pytest.approx(0.05, rel=0.2)
    assert res.read_sigma_dn == pytest.approx(1.0, rel=0.25)
    # Sigma rises with intensity, and the threshold is set for the noisiest level.
    assert res.sigma_dn[-1] > 1.5 * res.sigma_dn[0]
    assert res.threshold_sigma_dn == pytest.approx(res.measured_sigma_dn.max())
    assert res.sigma_at(200.0) == pytest.approx(np.sqrt(1.0 + 0.05 * 200), rel=0.1)


def test_noise_through_a_nonlinear_camera_is_measured_in_linear_units():
    frames, truth = render_still_frames(read_sigma_dn=2.0, response="gamma2.2", n_frames=12, seed=3)
    raw = calibrate_noise(frames)
    lin = calibrate_noise(frames, table=inverse_table("gamma2.2"))
    assert lin.noise_sigma_dn == pytest.approx(truth["sigma_dn"], rel=0.10)
    # Without linearisation the gamma curve squeezes the bright end: sigma depends on level.
    assert raw.sigma_dn[0] > 1.5 * raw.sigma_dn[-1]


def test_false_candidate_rate_matches_the_detector():
    """The bivariate-normal rate agrees with Eq. (19) candidates counted on pure noise."""
    from raingauge.vision.candidates import candidates

    rng = np.random.default_rng(4)
    sigma = 1.5
    c = detection_threshold(sigma, false_rate=2e-3)
    frames = 100.0 + rng.normal(0.0, sigma, (3, 400, 500))
    rate = candidates(frames[0], frames[1], frames[2], c=c).mean()
    assert rate == pytest.approx(2e-3, rel=0.15)
    assert false_candidate_rate(c, sigma) == pytest.approx(2e-3, rel=1e-3)


def test_threshold_limits_and_scaling():
    # c scales with sigma; a noiseless camera gets the one-code floor; the paper's c = 3
    # corresponds to a camera of sigma about 0.9 gray levels at the default rate.
    assert detection_threshold(2.0) == pytest.approx(2 * detection_threshold(1.0), rel=1e-4)
    assert detection_threshold(0.0) == 1.0
    assert 2.5 < detection_threshold(0.9) < 3.5
    assert detection_threshold(1.0, false_rate=1e-5) > detection_threshold(1.0, false_rate=1e-3)
    with pytest.raises(ValueError):
        detection_threshold(1.0, false_rate=0.5)


def test_moving_scene_is_flagged():
    frames, _ = render_still_frames(read_sigma_dn=1.0, n_frames=12, seed=5)
    frames = frames.copy()
    frames[::2, :, 40:60] = np.roll(frames[::2, :, 40:60], 7, axis=2)  # something swings back and forth
    frames[1::2, :, 40:60] = 255 - frames[1::2, :, 40:60]
    res = calibrate_noise(frames)
    assert any("not still" in w for w in res.warnings)


def test_too_few_frames_and_saturated_scene():
    frames, _ = render_still_frames(n_frames=3)
    with pytest.raises(InputError, match="at least 4"):
        calibrate_noise(frames)
    with pytest.raises(InputError, match="black or saturated"):
        calibrate_noise(np.full((6, 20, 20), 255, np.uint8))


def test_frames_streamed_one_at_a_time_give_the_same_result():
    frames, _ = render_still_frames(read_sigma_dn=1.5, n_frames=8, seed=6)
    a = calibrate_noise(frames)
    b = calibrate_noise(iter(list(frames)))
    assert a.noise_sigma_dn == pytest.approx(b.noise_sigma_dn, rel=1e-12)
    assert a.c_dn == pytest.approx(b.c_dn, rel=1e-12)


def test_quantisation_is_removed_from_the_sensor_noise_but_kept_for_the_threshold():
    """Sheppard's correction: 8-bit codes add 1/12 gray level^2 of variance on a linear camera."""
    frames, truth = render_still_frames(read_sigma_dn=0.6, n_frames=16, seed=7)
    res = calibrate_noise(frames)
    assert res.noise_sigma_dn == pytest.approx(0.6, rel=0.05)
    recorded = np.sqrt(np.mean(res.measured_sigma_dn ** 2))
    assert recorded == pytest.approx(np.sqrt(0.36 + 1 / 12), rel=0.05)
    assert res.c_dn == pytest.approx(detection_threshold(res.measured_sigma_dn.max()))
