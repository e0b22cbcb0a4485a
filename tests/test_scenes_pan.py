"""A panning scene is rendered as a camera records it: equally sharp frames, exact motion."""

from __future__ import annotations

import numpy as np
import pytest

from raingauge.render.scenes import Scene, pan_exposure
from raingauge.render.simulator import render_clip, small_profile


def _sharpness(img):
    """Mean squared discrete Laplacian over the interior [gray levels^2]."""
    lap = (img[1:-1, :-2] + img[1:-1, 2:] + img[:-2, 1:-1] + img[2:, 1:-1] - 4.0 * img[1:-1, 1:-1])
    return float(np.mean(lap[8:-8, 8:-8].astype(np.float64) ** 2))


@pytest.mark.parametrize("motion", ["pan:20", "pan:20:35", "pan:7:90"])
def test_pan_frames_have_uniform_sharpness(motion):
    prof = small_profile(160, 120)
    sc = Scene(prof, "camera", motion=motion, seed=1)
    s = [_sharpness(sc.frame(k)) for k in range(9)]
    # a short resampling kernel (bilinear) makes fractional shifts blurrier than
    # whole-pixel ones by tens of per cent at this pan rate
    assert max(s) / min(s) < 1.03, s


def test_pan_moves_the_scene_by_speed_times_time():
    prof = small_profile(160, 120)          # 30 frames/s
    sc = Scene(prof, "camera", motion="pan:30", seed=1)   # 1 px per frame to the left on screen
    f0, f3 = sc.frame(0), sc.frame(3)
    # frame(t)(x) = scene(x + v t): frame 3 is frame 0 moved 3 px to the left
    err = np.abs(f3[10:-10, 10:-13] - f0[10:-10, 13:-10]).mean()
    err_other_way = np.abs(f3[10:-10, 13:-10] - f0[10:-10, 10:-13]).mean()
    assert err < 0.3 and err_other_way > 5 * err


def test_pan_exposure_blur_and_band_limit():
    rng = np.random.default_rng(0)
    img = rng.uniform(0, 200, (64, 96)).astype(np.float32)
    # no motion during the exposure, no PSF, whole-pixel shift: the scene itself
    out = pan_exposure(img, (30.0, 0.0), 0.0, 0.0, psf_sigma_px=0.0)
    np.testing.assert_allclose(out, img, atol=1e-3)
    # the mean level is kept and a long exposure blurs along the pan only
    blurred = pan_exposure(img, (300.0, 0.0), 0.0, 0.02, psf_sigma_px=0.0)   # 6 px of motion
    assert abs(blurred.mean() - img.mean()) < 0.05
    assert np.std(np.diff(blurred, axis=1)) < 0.3 * np.std(np.diff(img, axis=1))
    assert np.std(np.diff(blurred, axis=0)) > 0.2 * np.std(np.diff(img, axis=0))


def test_fractional_pan_without_rain_is_not_called_rain():
    from raingauge.vision import Derainer

    prof = small_profile(200, 150)
    frames, _ = render_clip(prof, n_frames=24, rain_rate_mm_h=0.0, seed=5, background="skimage:camera",
                            motion="pan:20")
    out = list(Derainer(prof).process(frames))
    assert np.mean([r.rain.mean() for r in out]) <= 0.0005


@pytest.mark.parametrize("size, seed", [((200, 150), 5), ((240, 180), 6)])
def test_pan_with_moving_objects_and_ripples_without_rain_is_not_called_rain(size, seed):
    """A pan, textured objects crossing it and ripples, all at once: at most 0.05 % of the pixels called rain.

    The objects move against the compensated background; their edges make
    one-frame spikes along one direction, which only the lag-one persistence
    of the binary field and the local-motion test tell from rain.
    """
    from raingauge.vision import Derainer

    prof = small_profile(*size)
    frames, _ = render_clip(prof, n_frames=30, rain_rate_mm_h=0.0, seed=seed, background="skimage:camera",
                            motion="objects:2:90+ripples+pan:30")
    out = list(Derainer(prof).process(frames))
    assert np.mean([r.rain.mean() for r in out]) <= 0.0005
