"""Removal (Sec. 5.2), global motion compensation and the baselines."""

from __future__ import annotations

import numpy as np
import pytest

from raingauge.vision import (
    MOG2Detector, MotionTracker, estimate_motion, find_runs, remove_rain, replace_single, temporal_median,
    warp_to,
)
from raingauge.vision.removal import run_prefilter
from test_vision_synth import texture


def _window(shape=(30, 40), level=80.0):
    return [np.full(shape, level, np.float32) for _ in range(7)]


def test_replace_single_uses_mean_of_neighbours_on_every_channel():
    prev = np.full((4, 4, 3), 10.0, np.float32)
    nxt = np.full((4, 4, 3), 30.0, np.float32)
    cur = np.full((4, 4, 3), 99.0, np.float32)
    mask = np.zeros((4, 4), bool)
    mask[1, 2] = True
    out = replace_single(prev, cur, nxt, mask)
    np.testing.assert_array_equal(out[1, 2], [20.0, 20.0, 20.0])
    assert (out[~mask] == 99.0).all()


@pytest.mark.parametrize("run, expect", [((-1, 0), (1, 4)), ((0, 1), (2, 5)), ((-2, 0), (0, 4)),
                                         ((-1, 1), (1, 5)), ((0, 2), (2, 6))])
def test_find_runs_two_and_three_frames(run, expect):
    lum = _window()
    for k in range(3 + run[0], 3 + run[1] + 1):
        lum[k][10, 10] += 25.0 + k          # different drops: different brightness
    flat, before, after = find_runs(lum, c=3.0)
    assert list(flat) == [10 * 40 + 10]
    assert (before[0], after[0]) == expect


def test_find_runs_ignores_single_spikes_steps_and_long_changes():
    lum = _window()
    lum[3][5, 5] += 30                      # a one-frame spike (Eq. 19 handles it)
    for k in range(3, 7):
        lum[k][6, 6] += 30                  # a step: the scene changed
    for k in range(0, 7):
        lum[k][7, 7] += 30 if k % 2 else 0  # flicker longer than three frames
    flat, _, _ = find_runs(lum, c=3.0)
    assert 5 * 40 + 5 not in flat and 6 * 40 + 6 not in flat


def test_run_prefilter_keeps_runs_and_drops_isolated_coincidences():
    shape = (20, 20)
    rises = [np.zeros(shape, bool) for _ in range(5)]
    falls = [np.zeros(shape, bool) for _ in range(5)]
    rises[1][5:10, 5] = True                # run (-1, 0) on a streak of 5 pixels
    falls[2][5:10, 5] = True
    rises[2][15, 15] = falls[3][15, 15] = True   # a lone pixel
    pre = run_prefilter(rises, falls)
    assert pre[6:9, 5].all() and not pre[15, 15]     # the streak's inner pixels have two neighbours


def test_remove_rain_only_inside_region_and_for_runs():
    rng = np.random.default_rng(0)
    bg = texture((40, 60), seed=1)
    frames = [bg + rng.normal(0, 0.3, bg.shape).astype(np.float32) for _ in range(7)]
    rain = np.zeros(bg.shape, bool)
    rain[5:25, 10:12] = True                 # a one-frame streak in frame n
    frames[3][rain] += 30
    for k in (3, 4):                         # drops in frames n and n+1 on another streak
        frames[k][5:25, 40:42] += 25 + 5 * k
    region = np.zeros(bg.shape, bool)
    region[:, :30] = True                    # the second streak half outside the region
    region[:15, 40:42] = True
    out, replaced = remove_rain(frames, frames, rain, region, c=3.0, grow_px=0, beta_max=0.3, noise_sigma=0.3,
                                min_pixels=5)
    assert np.abs(out[rain] - bg[rain]).max() < 2.0
    assert replaced[5:15, 40:42].all() and not replaced[15:25, 40:42].any()
    assert np.abs(out[5:15, 40:42] - bg[5:15, 40:42]).max() < 2.0
    assert replaced.sum() == rain.sum() + 20
    # colour: the same pixels are cleaned on every channel
    col = [np.dstack([f, f * 0.5, f * 0.25]) for f in frames]
    out_c, rep_c = remove_rain(col, frames, rain, region, c=3.0, grow_px=0)
    np.testing.assert_allclose(out_c[..., 1][rain], 0.5 * out[rain], rtol=1e-5)


def test_estimate_motion_translation_subpixel():
    big = texture((400, 520), seed=4, blur=2.5)
    ref = big[40:280, 40:360]
    mov = big[40 + 2:280 + 2, 40 - 3:360 - 3]          # mov(x, y) = ref(x - 3, y + 2)
    M = estimate_motion(ref, mov, model="translation")   # aligned(x) = mov(M x) = ref(x)
    assert M[0, 2] == pytest.approx(3.0, abs=0.1) and M[1, 2] == pytest.approx(-2.0, abs=0.1)
    al, valid = warp_to(mov, M)
    assert np.abs(al - ref)[valid].mean() < 1.0
    with pytest.raises(ValueError, match="translation"):
        estimate_motion(ref, mov, model="homographyX")


def test_motion_tracker_chains_a_pan_and_static_needs_no_warp():
    big = texture((300, 420), seed=5, blur=2.5)
    tr = MotionTracker()
    for k in range(5):
        tr.add(big[30:230, 30 + 2 * k:330 + 2 * k])        # pans 2 px per frame
    M = tr.between(0, 4)
    assert M[0, 2] == pytest.approx(8.0, abs=0.2)
    f = big[:200, :300]
    same, valid = warp_to(f, np.eye(3))
    assert same is f and valid is None


def test_temporal_median_and_mog2_baselines():
    frames = np.full((9, 20, 30), 50, np.uint8)
    frames[4, 5, 5] = 200                                  # a rain spike
    med = temporal_median(frames, radius=2)
    assert med.shape == frames.shape and med[4, 5, 5] == 50
    rng = np.random.default_rng(0)
    scene = np.clip(60 + rng.normal(0, 2, (32, 30, 40)), 0, 255).astype(np.uint8)
    scene[30:, 10:20, 5:13] = 220                            # an object walks in
    det = MOG2Detector(history=20)
    masks = [det.apply(f) for f in scene]
    assert masks[30][10:20, 5:13].mean() > 0.9               # MOG2 calls the object "rain" too
    assert masks[30][25:, 20:].mean() < 0.05


def _crossing(bright=4.5, faint=2.5, seed=0):
    """A faint streak of frame n crossed by a fainter drop of frame n+1: 7 frames, the streak, the crossing.

    At the crossing I_n - I_{n+1} = bright - faint < c = 3: Eq. (19) leaves a gap.
    """
    rng = np.random.default_rng(seed)
    bg = texture((40, 40), seed=3, lo=40, hi=80)
    lum = [bg + rng.normal(0, 0.3, bg.shape).astype(np.float32) for _ in range(7)]
    streak = np.zeros(bg.shape, bool)
    streak[5:30, 20:22] = True
    lum[3][streak] += bright
    cross = np.zeros(bg.shape, bool)
    cross[15:18, 14:28] = True                          # a drop of frame n+1 across it
    lum[4][cross] += faint
    return lum, streak, cross


def test_multi_frame_hits_fill_the_gap_where_a_faint_drop_crosses_a_streak():
    from raingauge.vision.removal import ArrayWindow, multi_frame_hits

    lum, streak, cross = _crossing()
    gap = streak & cross
    b = streak & ~gap                                    # Eq. (19) misses the crossing: I_n - I_{n+1} < c there
    win = ArrayWindow(lum, lum)
    flat, before, after = multi_frame_hits(win, b, c=3.0, tol=1.5, beta_max=0.3, noise_sigma=0.3)
    found = np.zeros(b.shape, bool)
    found.ravel()[flat] = True
    assert found[gap].all() and not found[~streak].any()
    assert set(before) == {2} and set(after) == {5}      # background from frames n-1 and n+2
    # the paper's rule (every frame of the run c above the unaffected ones) leaves the gap
    flat, _, _ = multi_frame_hits(win, b, c=3.0, tol=1.5, beta_max=0.3, noise_sigma=0.3, near_px=0)
    assert not np.isin(np.flatnonzero(gap.ravel()), flat).any()
    # and without a detected streak next to it, a lone faint pair is left alone
    flat, _, _ = multi_frame_hits(win, np.zeros_like(b), c=3.0, tol=1.5, beta_max=0.3, noise_sigma=0.3)
    assert flat.size == 0


def test_remove_rain_fills_the_crossing_with_the_unaffected_frames():
    lum, streak, cross = _crossing()
    gap = streak & cross
    region = np.ones(streak.shape, bool)
    out, replaced = remove_rain(lum, lum, streak & ~gap, region, c=3.0, grow_px=0, tol=1.5, beta_max=0.3,
                                noise_sigma=0.3, near_px=2)
    assert replaced[streak].all() and not replaced[~streak].any()
    expect = 0.5 * (lum[2] + lum[5])
    np.testing.assert_allclose(out[gap], expect[gap], atol=1e-4)
    _, replaced = remove_rain(lum, lum, streak & ~gap, region, c=3.0, grow_px=0, tol=1.5, beta_max=0.3,
                              noise_sigma=0.3)
    assert not replaced[gap].any()                       # the paper's rule, the default


def test_one_frame_rain_pixel_with_disagreeing_neighbours_is_not_given_their_mean():
    # (I_{n-1} + I_{n+1}) / 2 is the background only when the two agree (Eq. 19);
    # here a drop brightened frame n+1 too, and the mean would keep half of it.
    lum = _window()
    rain = np.zeros(lum[3].shape, bool)
    rain[5:15, 5] = True
    for k in range(7):
        lum[k] = lum[k].copy()
    lum[3][rain] += 20.0
    lum[4][5:15, 5] += 8.0                               # the neighbour disagrees by 8 > tol
    region = np.ones(rain.shape, bool)
    out, replaced = remove_rain(lum, lum, rain, region, c=3.0, grow_px=0, tol=2.0)
    # a 2-frame run [n, n+1]: the background comes from frames n-1 and n+2
    np.testing.assert_allclose(out[rain], 80.0)
    _, replaced = remove_rain(lum, lum, rain, region, c=3.0, grow_px=0, tol=2.0, runs=False)
    assert not replaced.any()
    out, replaced = remove_rain(lum, lum, rain, region, c=3.0, grow_px=0, tol=None, runs=False)
    np.testing.assert_allclose(out[rain], 84.0)         # without a tolerance: the paper's mean


def test_window_run_candidates_match_the_run_prefilter_of_every_rise_and_fall():
    from raingauge.vision.removal import ArrayWindow

    rng = np.random.default_rng(1)
    lum = [rng.normal(100, 2.0, (60, 80)).astype(np.float32) for _ in range(7)]
    for k in (2, 3, 4):
        lum[k][10:30, 20:23] += 15.0                      # a 3-frame run [n-1, n+1]
    win = ArrayWindow(lum, lum)
    rises = [lum[k] - lum[k - 1] >= 3.0 for k in range(1, 6)]
    falls = [lum[k] - lum[k + 1] >= 3.0 for k in range(1, 6)]
    expect = run_prefilter(rises, falls)
    np.testing.assert_array_equal(win.run_candidates(3.0), expect)
    assert expect[12:28, 21].all()


@pytest.mark.parametrize("background", ["uniform:40", "uniform:200"])
def test_motion_tracker_sees_no_motion_in_rain_over_a_featureless_scene(background):
    # over a featureless background the phase-correlation peak is one of the noise or of the
    # rain's own fall (shifts of tens of pixels): a static camera must not be moved by whole
    # pixels (a stray fraction of a pixel misaligns nothing on such a scene)
    from raingauge.profile import default_profile
    from raingauge.render.simulator import render_clip

    prof = default_profile().replace(width_px=480, height_px=270)
    frames, _ = render_clip(prof, n_frames=16, rain_rate_mm_h=30.0, seed=3, background=background)
    tr = MotionTracker()
    for f in frames:
        tr.add(f.astype(np.float32))
    worst = max(np.abs(tr.between(k - 1, k)[:2, 2]).max() for k in range(1, len(frames)))
    assert worst < 1.0


def test_motion_tracker_follows_a_pan_of_several_pixels_in_rain():
    # the check against false peaks keeps a true shift of a textured scene, rain or not
    big = texture((420, 600), seed=6, blur=2.0)
    rng = np.random.default_rng(1)
    tr = MotionTracker()
    for k in range(6):
        f = big[40 + 3 * k:240 + 3 * k, 40 + 5 * k:360 + 5 * k].copy()     # 5 px right, 3 px down per frame
        ys, xs = rng.integers(0, 190, 60), rng.integers(0, 320, 60)
        for j in range(12):                                                 # streaks 12 px long
            f[np.minimum(ys + j, 199), xs] += 60.0
        tr.add(f)
    M = tr.between(0, 5)
    assert M[0, 2] == pytest.approx(25.0, abs=0.3) and M[1, 2] == pytest.approx(15.0, abs=0.3)
