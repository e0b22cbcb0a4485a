"""Hysteresis candidates (Eq. 19 at a lower threshold, anchored at c) and the fast paths of the pipeline."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from raingauge.vision import Derainer, candidates, hysteresis_candidates
from test_vision_synth import make_clip


def _triplet(spikes, shape=(20, 30)):
    """Flat frames of 50 DN with the given {(row, col): spike} added to the middle frame."""
    prev = np.full(shape, 50.0, np.float32)
    cur = prev.copy()
    for (r, c), v in spikes.items():
        cur[r, c] += v
    return prev, cur, prev.copy()


def test_hysteresis_keeps_faint_pixels_connected_to_a_spike_of_c():
    line = {(5, k): (4.0 if k == 10 else 2.0) for k in range(5, 15)}   # one pixel reaches c = 3
    lonely = {(15, k): 2.0 for k in range(5, 15)}                        # never reaches c
    prev, cur, nxt = _triplet({**line, **lonely})
    got = hysteresis_candidates(prev, cur, nxt, c=3.0, c_low=1.5)
    assert got[5, 5:15].all()                   # the whole streak, found from its bright pixel
    assert not got[15].any()                    # faint everywhere: noise-like, not kept
    assert got.sum() == 10
    # at c_low = c it is Eq. (19) itself
    np.testing.assert_array_equal(hysteresis_candidates(prev, cur, nxt, c=3.0, c_low=3.0),
                                  candidates(prev, cur, nxt, c=3.0))
    # min_high: two pixels at c needed
    assert not hysteresis_candidates(prev, cur, nxt, c=3.0, c_low=1.5, min_high=2).any()


def test_hysteresis_respects_tolerance_valid_and_slack():
    prev, cur, nxt = _triplet({(5, k): 4.0 for k in range(5, 15)})
    nxt[5, 5:8] += 1.0                                   # the neighbours disagree on 3 pixels
    assert hysteresis_candidates(prev, cur, nxt, c=3.0, c_low=1.5, tol=0.5).sum() == 7
    valid = np.ones(cur.shape, bool)
    valid[:, 10:] = False
    assert hysteresis_candidates(prev, cur, nxt, c=3.0, c_low=1.5, valid=valid).sum() == 5
    slack = np.full(cur.shape, 2.0, np.float32)          # 4 - 2 < c everywhere: nothing anchors
    assert not hysteresis_candidates(prev, cur, nxt, c=3.0, c_low=1.5, slack=slack).any()


def test_hysteresis_rejects_bad_thresholds():
    prev, cur, nxt = _triplet({})
    with pytest.raises(ValueError, match="c_low"):
        hysteresis_candidates(prev, cur, nxt, c=3.0, c_low=4.0)
    with pytest.raises(ValueError, match="c_low"):
        Derainer(None, c_low=-1.0)


def test_hysteresis_raises_recall_of_faint_streaks_without_false_rain():
    """Faint streaks (change 4-7 DN against c = 3, noise 0.7 DN) are found more completely."""
    frames, _, truth = make_clip(T=14, n_streaks=25, seed=1, noise=0.7, alpha=(4.0, 7.0), beta=0.01, width=3)
    tr = truth[2:-2]
    res = {}
    for c_low in (None, 3.0):       # default hysteresis, and the single threshold of the paper
        out = list(Derainer(None, c=3.0, noise_sigma=0.7, c_low=c_low).process(frames))
        det = np.stack([r.detected for r in out])[2:-2]
        res[c_low] = ((det & tr).sum() / tr.sum(), (det & tr).sum() / max(det.sum(), 1))
    assert res[None][0] >= res[3.0][0] + 0.04, res
    assert res[None][1] >= 0.95, res
    # rain-free: noise, a moving object and ripples are still not rain
    frames0, _, _ = make_clip(T=14, n_streaks=0, seed=2, noise=0.7, moving_object=True, ripples=True)
    out = list(Derainer(None, c=3.0, noise_sigma=0.7).process(frames0))
    assert np.mean([r.rain.mean() for r in out]) <= 0.0005
    assert np.mean([r.detected.mean() for r in out]) <= 0.0005


# ------------------------------------------------------------ fast paths
@pytest.mark.parametrize("shift", [(0.7, 0.2), (-1.4, 2.6), (3.0, -0.45), (0.0, 0.0)])
def test_translation_warp_is_an_accurate_cubic_shift(shift):
    from raingauge.vision.motion import _translate_cubic, warp_to

    dx, dy = shift
    yy, xx = np.mgrid[0:60, 0:80].astype(np.float64)
    smooth = lambda x, y: 100 + 40 * np.sin(2 * np.pi * (x / 17.0 + y / 23.0))   # noqa: E731
    img = smooth(xx, yy).astype(np.float32)
    out = _translate_cubic(img, dx, dy, a=-0.5)
    inner = (slice(6, -6), slice(6, -6))
    # out(x) = img(x + d): a smooth image is moved by d to within a hundredth of a gray level per DN/px
    assert out.shape == img.shape and np.abs(out - smooth(xx + dx, yy + dy))[inner].max() < 0.6
    # a ramp is reproduced exactly (OpenCV's cubic, a = -0.75, moves it by up to 0.04 px)
    ramp = np.tile(np.arange(40, dtype=np.float32), (8, 1))
    np.testing.assert_allclose(_translate_cubic(ramp, dx, 0.0, a=-0.5)[:, 6:-6], ramp[:, 6:-6] + np.float32(dx),
                               atol=1e-3)
    # warp_to takes this path for translations, with OpenCV's kernel (a = -0.75) and the valid mask
    M = np.array([[1, 0, dx], [0, 1, dy], [0, 0, 1]], dtype=np.float64)
    warped, valid = warp_to(img, M)
    if max(abs(dx), abs(dy)) >= 0.3:
        ref = cv2.warpAffine(img, M[:2], (80, 60), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP,
                             borderMode=cv2.BORDER_REPLICATE)
        assert np.abs(warped - ref)[inner].max() < 0.5      # OpenCV quantises the fraction to 1/32 px
        assert valid is not None and not valid.all() and valid[inner].all()


def test_translation_registration_is_accurate_on_a_rendered_pan():
    from raingauge.render.scenes import pan_exposure
    from raingauge.vision import MotionTracker

    rng = np.random.default_rng(0)
    tex = cv2.GaussianBlur(rng.uniform(0, 1, (200, 300)).astype(np.float32), (0, 0), 2.0)
    tex = 30 + 170 * (tex - tex.min()) / (tex.max() - tex.min())
    for vx, vy in ((21.0, 6.0), (-39.0, 13.5)):          # px/s at 30 frames/s
        tr = MotionTracker()
        for k in range(4):
            frame = pan_exposure(tex, (vx, vy), k / 30.0, 0.004) + rng.normal(0, 2, tex.shape).astype(np.float32)
            tr.add(frame)
        for k in range(3):
            np.testing.assert_allclose(tr.between(k, k + 1)[:2, 2], [vx / 30.0, vy / 30.0], atol=0.02)


def test_mask_shift_matches_opencv_nearest():
    from raingauge.vision.pipeline import _drop_isolated, _shift_nearest

    rng = np.random.default_rng(1)
    m = rng.random((50, 70)) < 0.3
    for dx, dy in ((2.2, -1.1), (-3.0, 0.4), (0.0, 0.0), (5.3, 7.6), (80.0, 0.0)):
        M = np.array([[1, 0, dx], [0, 1, dy]])
        ref = cv2.warpAffine(m.view(np.uint8), M, (70, 50), flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP)
        np.testing.assert_array_equal(_shift_nearest(m, dx, dy), ref.astype(bool))
    # isolated pixels go, pairs stay
    lone = np.zeros((10, 10), bool)
    lone[2, 2] = lone[6, 6] = lone[7, 7] = True
    kept = _drop_isolated(lone, 5)
    assert not kept[2, 2] and kept[6, 6] and kept[7, 7]
    np.testing.assert_array_equal(_drop_isolated(lone, 1), lone)


def test_hysteresis_faint_pixel_beyond_tolerance_links_the_streak_but_is_no_candidate():
    # A faint streak: one pixel at c, the rest at 2 DN; one faint pixel midway has
    # neighbours that disagree.  Dropped before the labelling it would cut the
    # streak and lose the far half (no pixel at c there); it still links, but
    # is not a candidate itself ((I_{n-1} + I_{n+1}) / 2 is no background there).
    prev, cur, nxt = _triplet({(5, k): (4.0 if k == 5 else 2.0) for k in range(5, 15)})
    nxt[5, 9] -= 1.0
    got = hysteresis_candidates(prev, cur, nxt, c=3.0, c_low=1.5, tol=0.5)
    assert got[5, 5:9].all() and got[5, 10:15].all() and not got[5, 9]
    assert got.sum() == 9
    nxt[5, 5] -= 1.0                                     # the only anchor fails the tolerance
    assert not hysteresis_candidates(prev, cur, nxt, c=3.0, c_low=1.5, tol=0.5).any()
