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


# ------------------------------------------------- the slope test given the noise
def _faint_streak(seed, *, amp=4.0, beta=0.01, sigma=1.0, length=20, lo=20.0, hi=24.0):
    """A streak of ``amp`` gray levels (Eq. 18, slope beta) on a low-contrast texture, noise sigma per frame."""
    rng = np.random.default_rng(seed)
    bg = texture((40, 40), seed=seed, lo=lo, hi=hi, blur=1.0)
    m = streak_mask(bg.shape, 20, 20, length, 95, width=2)
    frames = [bg + rng.normal(0, sigma, bg.shape).astype(np.float32) for _ in range(3)]
    frames[1][m] += amp + beta * (bg[m].mean() - bg[m])
    return frames, m


def test_faint_streaks_of_four_gray_levels_in_unit_noise_are_accepted():
    # c = 3, hysteresis down to 2 sigma: the pixels found of a 4-DN streak are
    # kept by Eq. (18).  Their background varies by a few noise levels only, so
    # the slope is barely measurable and the threshold that picked the pixels
    # biases it negative; a cut on the scatter of the selected pixels alone
    # rejected about one such streak in ten.
    from raingauge.vision import hysteresis_candidates

    kept, found = 0, 0
    for seed in range(40):
        frames, m = _faint_streak(seed)
        cand = hysteresis_candidates(*frames, c=3.0, c_low=2.0)
        acc, fits = photometric_filter(*frames, cand, beta_max=beta_max_for_exposure(1 / 30), noise_sigma=1.0)
        found += (cand & m).sum()
        kept += (acc & m).sum()
        assert (acc & m).sum() >= 0.5 * (cand & m).sum()      # every streak is accepted
    assert kept >= 0.98 * found and found >= 0.8 * 40 * m.sum()


def test_bright_blob_whose_change_grows_with_background_is_rejected():
    # A reflection brightening the scene by 15 %: Delta I = 0.15 I_b, beta = -0.15 (Eq. 18 needs beta >= 0).
    rng = np.random.default_rng(2)
    bg = texture((80, 80), seed=2, lo=40, hi=220)
    m = streak_mask(bg.shape, 40, 40, 40, 95, width=3)
    frames = [bg + rng.normal(0, 1.0, bg.shape).astype(np.float32) for _ in range(3)]
    frames[1][m] += 0.15 * bg[m]
    cand = candidates(*frames, c=3.0)
    acc, fits = photometric_filter(*frames, cand, beta_max=beta_max_for_exposure(1 / 30), noise_sigma=1.0)
    big = np.argmax(fits.area)
    assert fits.beta[big] == pytest.approx(-0.15, abs=0.02)
    assert not fits.slope_ok[big] and not acc[m].any()
    # the same blob, 12 gray levels at most, in the noise of a gauge camera (sigma 2): still refuted
    frames = [bg + rng.normal(0, 2.0, bg.shape).astype(np.float32) for _ in range(3)]
    frames[1][m] += 0.055 * bg[m]
    cand = candidates(*frames, c=3.0)
    acc, fits = photometric_filter(*frames, cand, beta_max=beta_max_for_exposure(1 / 30), noise_sigma=2.0)
    assert acc[m].sum() < 0.1 * m.sum()


def test_selection_pull_matches_monte_carlo_of_the_spike_test():
    from raingauge.vision.photometric import selection_pull

    rng = np.random.default_rng(0)
    sigma, c = 1.0, 3.0
    for s in (3.0, 4.41, 5.83):        # true change at c, one and two noise levels sqrt(2) sigma above
        e_prev = rng.normal(0, sigma, 400_000)
        e_cur = rng.normal(0, sigma, 400_000)
        sel = s + e_cur - e_prev >= c
        margin = (s - c) / (math.sqrt(2.0) * sigma)
        assert -e_prev[sel].mean() == pytest.approx(float(selection_pull(margin)) * sigma, abs=0.01)
    assert float(selection_pull(0.0)) == pytest.approx(math.sqrt(2 / math.pi) / math.sqrt(2.0) * 1.0, rel=1e-6)
    assert float(selection_pull(-3.0)) == float(selection_pull(0.0))     # below the threshold: the value at it
    assert float(selection_pull(6.0)) < 1e-6


def test_slope_uncertainty_noise_floor_flat_background_and_bright_streaks():
    from raingauge.vision.photometric import slope_uncertainty

    # a line fitted exactly (rss = 0) is still uncertain by the noise of y, 2 sigma^2
    se, shift = slope_uncertainty(np.array([50.0]), np.array([0.0]), np.array([10.0]), np.array([0.0]),
                                  noise_sigma=1.5)
    assert se[0] == pytest.approx(math.sqrt(2 * 1.5 ** 2 / 50.0)) and shift[0] == 0.0
    # a larger residual than the noise is used as it is
    se, _ = slope_uncertainty(np.array([50.0]), np.array([80.0]), np.array([10.0]), np.array([0.0]), noise_sigma=1.0)
    assert se[0] == pytest.approx(math.sqrt(80.0 / 8 / 50.0))
    # no background contrast: no slope can be measured
    se, shift = slope_uncertainty(np.array([0.0]), np.array([1.0]), np.array([10.0]), np.array([2.0]), noise_sigma=1.0)
    assert math.isinf(se[0]) and math.isinf(shift[0])
    with pytest.raises(ValueError, match="noise_sigma"):
        slope_uncertainty(np.ones(1), np.ones(1), np.ones(1), np.ones(1), noise_sigma=float("nan"))
    # bright streaks (40 DN on unit noise) get no selection allowance: beta = 0.01 is kept, -0.1 refuted
    for beta, ok in ((0.01, True), (-0.1, False)):
        frames, m = _faint_streak(0, amp=40.0, beta=beta, lo=40.0, hi=200.0)
        fits = fit_streaks(*frames, candidates(*frames, c=3.0), beta_max=0.3, noise_sigma=1.0)
        big = np.argmax(fits.area)
        assert fits.beta[big] == pytest.approx(beta, abs=0.01)
        assert bool(fits.accepted[big]) is ok


def test_slope_error_is_cluster_robust_over_blocks_of_pixels():
    # Residuals shared by blocks of pixels (the partly covered edge of a streak, two
    # drops in one component) make the independent-pixel error too small; for a
    # streak that error refutes (here beta = -0.05) the sandwich variance over
    # 8 x 8 blocks, computed here by hand, is used instead.
    rng = np.random.default_rng(4)
    shape = (40, 40)
    x = texture(shape, seed=4, lo=30, hi=90)
    m = np.zeros(shape, bool)
    m[4:36, 10:14] = True
    rows, cols = np.nonzero(m)
    block_err = rng.normal(0, 2.0, (5, 5))[rows // 8, cols // 8]
    y = np.zeros(shape, np.float32)
    y[m] = 20.0 + 0.05 * x[m] + block_err + rng.normal(0, 0.2, m.sum())
    nxt = np.zeros(shape, np.float32)
    fits = fit_streaks(x, y, nxt, m, beta_max=0.3, noise_sigma=0.0, min_pixels=5, cluster_px=8)
    fits_iid = fit_streaks(x, y, nxt, m, beta_max=0.3, noise_sigma=0.0, min_pixels=5, cluster_px=0)
    xs, ys = x[m].astype(np.float64), y[m].astype(np.float64)
    sxx = np.sum((xs - xs.mean()) ** 2)
    slope, icpt = np.polyfit(xs, ys, 1)
    r = ys - (icpt + slope * xs)
    var_iid = np.sum(r ** 2) / (xs.size - 2) / sxx
    blocks = (rows // 8) * 5 + cols // 8
    g = np.array([np.sum(r[blocks == b] * (xs[blocks == b] - xs.mean())) for b in np.unique(blocks)])
    var_cr = g.size / (g.size - 1) * np.sum(g ** 2) / sxx ** 2
    assert var_cr > 2 * var_iid and -slope + 2 * math.sqrt(var_iid) < 0
    assert fits.beta[0] == pytest.approx(-slope, rel=1e-4)
    assert fits.beta_se[0] == pytest.approx(math.sqrt(var_cr), rel=1e-3)
    assert fits_iid.beta_se[0] == pytest.approx(math.sqrt(var_iid), rel=1e-3)
