"""Detection of rain: Eq. (19) candidates, streaks and the Eq. (18) photometric test."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raingauge.vision import (
    beta_max_for_exposure, candidates, detect_streaks, fit_streaks, label_streaks, luminance,
    photometric_filter,
)
from test_vision_synth import make_clip, streak_mask, texture


def _triplet(shape=(60, 80), level=100.0):
    base = np.full(shape, level, np.float32)
    return base.copy(), base.copy(), base.copy()


def test_candidates_eq19_needs_spike_against_both_neighbours():
    prev, cur, nxt = _triplet()
    cur[10, 10] += 3.0          # exactly c against both: a candidate
    cur[20, 20] += 2.9          # below c
    cur[30, 30] += 10.0         # a step that stays: brighter in n and n+1
    nxt[30, 30] += 10.0
    cur[40, 40] -= 10.0         # a dark spike is never rain
    prev[50, 50] -= 5.0         # brighter than n-1 only
    m = candidates(prev, cur, nxt, c=3.0)
    assert m[10, 10]
    assert m.sum() == 1


def test_candidates_tolerance_and_valid_mask():
    prev, cur, nxt = _triplet()
    cur[5, 5] += 20
    prev[5, 5] += 8           # background changed between n-1 and n+1
    cur[6, 6] += 20
    assert candidates(prev, cur, nxt, c=3)[5, 5]
    assert not candidates(prev, cur, nxt, c=3, tol=4.0)[5, 5]
    valid = np.ones_like(cur, bool)
    valid[6, 6] = False
    assert not candidates(prev, cur, nxt, c=3, valid=valid)[6, 6]


def test_candidates_rejects_bad_threshold_and_shapes():
    prev, cur, nxt = _triplet()
    with pytest.raises(ValueError, match="positive"):
        candidates(prev, cur, nxt, c=0)
    with pytest.raises(ValueError, match="shape"):
        candidates(prev[:10], cur, nxt)
    with pytest.raises(ValueError, match="luminance"):
        candidates(prev, np.dstack([cur] * 3), nxt)


def test_luminance_of_gray_bgr():
    img = np.zeros((2, 2, 3), np.float32)
    img[..., 2] = 100.0   # red
    assert luminance(img)[0, 0] == pytest.approx(29.9, abs=0.05)
    assert luminance(img[..., 2]).dtype == np.float32


def test_beta_max_scales_with_exposure_and_matches_paper():
    # Sec. 4.3 / App. 10.2: beta < 0.039 for T = 30 ms (tau_max = 1.18 ms)
    assert beta_max_for_exposure(0.030) == pytest.approx(0.039, abs=0.0006)
    assert beta_max_for_exposure(0.004) == pytest.approx(beta_max_for_exposure(0.030) * 7.5, rel=1e-9)
    with pytest.raises(ValueError):
        beta_max_for_exposure(0.0)


def test_label_streaks_counts_8_connected_components():
    m = np.zeros((20, 20), bool)
    m[2, 2] = m[3, 3] = True      # diagonal neighbours: one streak
    m[10, 5:9] = True
    labels, n = label_streaks(m)
    assert n == 2 and labels[2, 2] == labels[3, 3] != labels[10, 6]
    assert label_streaks(m, connectivity=4)[1] == 3


def _one_streak(beta, alpha=30.0, noise=0.5, seed=0, exposure_bg=None):
    rng = np.random.default_rng(seed)
    bg = texture((80, 80), seed=seed, lo=40, hi=220)
    m = streak_mask(bg.shape, 40, 40, 50, 95, width=2)
    frames = [bg + rng.normal(0, noise, bg.shape).astype(np.float32) for _ in range(3)]
    frames[1][m] += alpha - beta * bg[m]
    return frames, m, bg


def test_photometric_accepts_eq18_streak_and_recovers_slope():
    frames, m, _ = _one_streak(beta=0.03)
    cand = candidates(*frames, c=3.0)
    acc, fits = photometric_filter(*frames, cand, beta_max=beta_max_for_exposure(0.03), noise_sigma=0.5)
    assert len(fits) == 1 and fits.accepted[0]
    assert fits.beta[0] == pytest.approx(0.03, abs=0.01)
    assert fits.alpha[0] == pytest.approx(30.0, abs=2.0)
    assert (acc & m).sum() >= 0.95 * m.sum()
    s = fits[0]
    assert s.orientation_deg == pytest.approx(95, abs=3)
    assert s.length_px == pytest.approx(50, rel=0.15)
    assert s.coords.shape[0] == s.area


def test_photometric_rejects_slope_outside_range_set_by_exposure():
    # A moving object of uniform brightness over a textured background: Delta I = I_obj - I_b, slope 1.
    frames, m, bg = _one_streak(beta=1.0, alpha=240.0)
    cand = candidates(*frames, c=3.0)
    acc, fits = photometric_filter(*frames, cand, beta_max=beta_max_for_exposure(0.03), noise_sigma=0.5)
    assert not acc.any()
    assert fits.beta[np.argmax(fits.area)] == pytest.approx(1.0, abs=0.1)
    # beta = 0.15 is impossible for T = 30 ms (beta_max 0.039) but fine for T = 4 ms (0.296).
    frames, m, _ = _one_streak(beta=0.15, alpha=45.0)
    cand = candidates(*frames, c=3.0)
    assert not photometric_filter(*frames, cand, beta_max=beta_max_for_exposure(0.030), noise_sigma=0.5)[0].any()
    assert photometric_filter(*frames, cand, beta_max=beta_max_for_exposure(0.004), noise_sigma=0.5)[0].sum() > 0.9 * m.sum()


def test_photometric_rejects_non_linear_change():
    rng = np.random.default_rng(5)
    frames, m, bg = _one_streak(beta=0.0, alpha=0.0)
    frames[1][m] += rng.uniform(5, 80, m.sum()).astype(np.float32)   # texture moving in: no line
    cand = candidates(*frames, c=3.0)
    acc, fits = photometric_filter(*frames, cand, beta_max=0.3, noise_sigma=0.5)
    big = np.argmax(fits.area)
    assert not fits.linear[big] and not acc[m].any()


def test_photometric_keeps_streak_on_uniform_background():
    prev, cur, nxt = _triplet()
    m = streak_mask(cur.shape, 40, 30, 30, 90)
    cur[m] += 12.0
    acc, fits = photometric_filter(prev, cur, nxt, candidates(prev, cur, nxt), beta_max=0.04, noise_sigma=1.0)
    assert acc[m].all() and math.isinf(fits.beta_se[0])


def test_small_noise_clusters_are_discarded_before_fitting():
    prev, cur, nxt = _triplet()
    cur[5, 5:8] += 10           # 3 pixels < min_pixels
    fits = fit_streaks(prev, cur, nxt, candidates(prev, cur, nxt), beta_max=0.3, min_pixels=5)
    assert len(fits) == 0


def test_detect_streaks_on_synthetic_rain_recall_and_precision():
    frames, clean, truth = make_clip(T=5, shape=(120, 160), n_streaks=8, noise=1.0, seed=11)
    rec, prec = [], []
    for n in range(1, 4):
        f = [x.astype(np.float32) for x in frames[n - 1:n + 2]]
        mask, streaks = detect_streaks(*f, c=3.0, beta_max=beta_max_for_exposure(1 / 30), noise_sigma=1.0)
        rec.append((mask & truth[n]).sum() / truth[n].sum())
        prec.append((mask & truth[n]).sum() / max(mask.sum(), 1))
        assert all(s.accepted for s in streaks.accepted_only())
    # Streaks overlapping other streaks of the neighbouring frames are missed (note 16).
    assert np.mean(rec) > 0.8 and np.mean(prec) > 0.95
