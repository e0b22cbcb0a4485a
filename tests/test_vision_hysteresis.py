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
def test_translation_warp_matches_opencv_cubic(shift):
    from raingauge.vision.motion import _translate_cubic

    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.uniform(0, 255, (60, 80)).astype(np.float32), (0, 0), 2.0)
    M = np.array([[1, 0, shift[0]], [0, 1, shift[1]]])
    ref = cv2.warpAffine(img, M, (80, 60), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP,
                         borderMode=cv2.BORDER_REPLICATE)
    out = _translate_cubic(img, *shift)
    # OpenCV quantises the fraction to 1/32 px; the rest is the same cubic convolution
    assert out.shape == img.shape and np.abs(out - ref)[4:-4, 4:-4].max() < 0.5
    # and it does move the image: a smooth image shifted by (dx, dy) matches the shift
    if shift == (3.0, -0.45):
        np.testing.assert_allclose(_translate_cubic(img, 3.0, 0.0)[:, :-3], img[:, 3:], atol=1e-3)


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
