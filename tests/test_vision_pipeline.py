"""The streaming Derainer (Sec. 5 end to end) on hand-made clips and on simulator clips."""

from __future__ import annotations

import numpy as np
import pytest

from raingauge.vision import Derainer, derain_clip, temporal_median
from test_vision_synth import make_clip


def psnr(a, b, mask=None):
    d = a.astype(float) - b.astype(float)
    if mask is not None:
        d = d[mask]
    return 10 * np.log10(255.0 ** 2 / max(float(np.mean(d ** 2)), 1e-12))


def _run(frames, **kw):
    kw.setdefault("noise_sigma", 1.0)
    return list(Derainer(None, **kw).process(frames))


def test_one_output_per_input_with_first_last_and_repeated_frames():
    frames, clean, truth = make_clip(T=16, n_streaks=10, seed=2)
    seq = list(frames[:6]) + [frames[5].copy(), frames[5].copy()] + list(frames[6:])   # frame 5 shown 3 times
    out = _run(seq)
    assert [r.index for r in out] == list(range(len(seq)))
    assert [r.repeat for r in out][5:8] == [False, True, True]
    np.testing.assert_array_equal(out[6].frame, out[5].frame)
    assert all(r.frame.shape == frames[0].shape and r.frame.dtype == np.uint8 for r in out)
    # rain is removed from the first and the last frame too
    assert psnr(out[0].frame, clean[0]) > psnr(frames[0], clean[0]) + 1.0
    assert psnr(out[-1].frame, clean[-1]) > psnr(frames[-1], clean[-1]) + 1.0


def test_short_and_invalid_streams():
    frames, _, _ = make_clip(T=2, n_streaks=3)
    out = _run(frames)
    assert len(out) == 2 and np.array_equal(out[1].frame, frames[1])   # too short to detect: unchanged
    d = Derainer(None)
    d.push(frames[0])
    with pytest.raises(ValueError, match="shape"):
        d.push(frames[0][:10])
    with pytest.raises(ValueError, match="uint8"):
        d.push(frames[0].astype(np.float32))


def test_static_rain_detected_and_removed():
    frames, clean, truth = make_clip(T=36, n_streaks=8, seed=4)
    out = _run(frames)
    sl = slice(3, -3)
    det = np.stack([r.detected for r in out])[sl]
    tr = truth[sl]
    assert (det & tr).sum() / tr.sum() >= 0.8
    assert (det & tr).sum() / det.sum() >= 0.9
    derained = np.stack([r.frame for r in out])
    assert psnr(derained[sl], clean[sl]) > psnr(frames[sl], clean[sl]) + 5.0


@pytest.mark.parametrize("kw", [dict(moving_object=True), dict(ripples=True), dict(pan=(0.8, 0.3)),
                                dict(moving_object=True, ripples=True)])
def test_rain_free_motion_is_not_called_rain(kw):
    frames, clean, _ = make_clip(T=36, n_streaks=0, seed=5, **kw)
    out = _run(frames)
    called = np.mean([r.rain.mean() for r in out])
    assert called <= 0.0005                    # at most 0.05 % of the pixels
    assert psnr(np.stack([r.frame for r in out]), frames) > 45.0


def test_moving_object_kept_where_median_smears_it():
    frames, clean, truth = make_clip(T=36, n_streaks=10, seed=6, moving_object=True)
    derained, _ = derain_clip(frames, noise_sigma=1.0)
    med = temporal_median(frames, radius=2)
    obj = np.zeros(frames.shape, bool)
    obj[:, 36:68, :] = True                    # the band the object crosses
    sl = slice(3, -3)
    assert psnr(derained[sl], clean[sl], obj[sl]) >= psnr(med[sl], clean[sl], obj[sl]) + 3.0


def test_panning_camera_is_compensated():
    frames, clean, truth = make_clip(T=36, n_streaks=10, seed=7, pan=(0.8, 0.3))
    with_motion = _run(frames)
    static = _run(frames, motion="none")
    sl = slice(3, -3)
    rec = lambda out: np.sum([(r.detected & truth[r.index]).sum() for r in out[sl]]) / truth[sl].sum()
    assert rec(with_motion) > 0.6 and rec(with_motion) > rec(static) + 0.1
    derained = np.stack([r.frame for r in with_motion])
    assert psnr(derained[sl], clean[sl]) > psnr(frames[sl], clean[sl]) + 3.0


def test_colour_detected_on_luminance_removed_on_every_channel():
    frames, clean, truth = make_clip(T=30, n_streaks=10, seed=8)
    tint = np.array([0.6, 0.9, 1.0])
    col = np.clip(frames[..., None] * tint, 0, 255).astype(np.uint8)
    col_clean = np.clip(clean[..., None] * tint, 0, 255).astype(np.uint8)
    out = np.stack([r.frame for r in _run(col)])
    assert out.shape == col.shape
    sl = slice(3, -3)
    for ch in range(3):
        assert psnr(out[sl, ..., ch], col_clean[sl, ..., ch]) > psnr(col[sl, ..., ch], col_clean[sl, ..., ch]) + 3.0


# ---------------------------------------------------------------- simulator clips
def _simulator():
    try:
        from raingauge.render.simulator import render_clip, small_profile
    except ImportError as exc:  # pragma: no cover - the simulator ships with raingauge
        pytest.skip(f"rain simulator not importable: {exc}")
    return render_clip, small_profile


def test_simulated_static_rain_precision_and_removal():
    render_clip, small_profile = _simulator()
    prof = small_profile(240, 180, noise_sigma_dn=0.7, exposure_s=0.008)
    kw = dict(n_frames=30, rain_rate_mm_h=25.0, seed=3, background="skimage:camera", depth_range_m=(2.0, 3.2))
    frames, truth = render_clip(prof, return_clean=True, return_masks=True, **kw)
    clean, rain_mask = truth["clean"], truth["rain_masks"]
    out = list(Derainer(prof).process(frames))
    sl = slice(3, -3)
    det = np.stack([r.detected for r in out])[sl]
    assert det.sum() > 0
    assert (det & rain_mask[sl]).sum() / det.sum() >= 0.9          # detected pixels are rain
    derained = np.stack([r.frame for r in out])
    assert psnr(derained[sl], clean[sl]) > psnr(frames[sl], clean[sl])


def test_simulated_rain_free_scene_motion_is_not_rain():
    render_clip, small_profile = _simulator()
    prof = small_profile(240, 180)
    # pan:20 is 2/3 px per frame: the scene is resampled at fractional shifts
    frames, _ = render_clip(prof, n_frames=30, rain_rate_mm_h=0.0, seed=4, background="skimage:camera",
                            motion="objects:2:90+ripples+pan:20")
    out = list(Derainer(prof).process(frames))
    assert np.mean([r.rain.mean() for r in out]) <= 0.0005


# ---------------------------------------------------------------- real video
@pytest.mark.shared_data
def test_nturain_clip_is_improved_on_y(shared_data):
    from raingauge.videoio import read_frames

    root = shared_data / "nturain_a1"
    if not (root / "rain").is_dir():
        pytest.skip(f"{root} not found")
    rain = read_frames(root / "rain", mode="bgr", limit=24)
    clean = read_frames(root / "clean", mode="bgr", limit=24)
    out = np.stack([r.frame for r in Derainer(None, f=20).process(rain)])

    def y(x):
        x = x.astype(np.float64)
        return 16.0 + (65.481 * x[..., 2] + 128.553 * x[..., 1] + 24.966 * x[..., 0]) / 255.0

    sl = slice(2, -2)
    ours = np.mean([psnr(a, b) for a, b in zip(y(out[sl]), y(clean[sl]))])
    rainy = np.mean([psnr(a, b) for a, b in zip(y(rain[sl]), y(clean[sl]))])
    med = np.mean([psnr(a, b) for a, b in zip(y(temporal_median(rain)[sl]), y(clean[sl]))])
    assert ours > rainy + 0.5 and ours > med


@pytest.mark.shared_data
def test_real_rain_static_repeats_and_direction(shared_data):
    from raingauge.videoio import read_frames
    from raingauge.vision import dominant_direction_deg

    root = shared_data / "real_rain_static"
    if not root.is_dir():
        pytest.skip(f"{root} not found")
    frames = read_frames(root, mode="bgr", limit=30)
    out = list(Derainer(None, f=20).process(frames))
    assert len(out) == len(frames)
    repeats = sum(r.repeat for r in out)
    assert 6 <= repeats <= 18                      # about 20 of 49 pairs are near-duplicates
    direction = dominant_direction_deg(out[-1].field)
    assert abs(direction - 90.0) < 20.0           # rain falls nearly vertically in this clip
    assert 0.001 < np.mean([r.rain.mean() for r in out]) < 0.1


# ---------------------------------------------------------------- scene motion and removal
def test_local_motion_mask_finds_moving_texture_not_rain():
    from raingauge.vision.pipeline import local_motion_mask

    rng = np.random.default_rng(0)
    tex = np.kron(rng.uniform(40, 200, (24, 24)), np.ones((2, 2))).astype(np.float32)   # fine texture
    bg = np.full((120, 160), 90.0, np.float32)

    def frame(x):
        f = bg.copy()
        f[30:78, x:x + 48] = tex
        return f + rng.normal(0, 0.7, bg.shape).astype(np.float32)

    prev, cur, nxt = frame(40), frame(43), frame(46)           # 3 px per frame to the right
    mask = local_motion_mask(prev, cur, nxt, c=6.0, tol=6.0, window_px=15, min_px=30)
    assert mask[30:78, 50:85].mean() > 0.5                     # the object's interior and edges
    assert not mask[:, 120:].any() and not mask[100:].any()    # the static background
    # rain: one-frame bright streaks in each of the three frames, static background
    still = [bg + rng.normal(0, 0.7, bg.shape).astype(np.float32) for _ in range(3)]
    for f in still:
        for _ in range(40):
            y, x = rng.integers(0, 100), rng.integers(0, 158)
            f[y:y + 20, x:x + 2] += rng.uniform(10, 40)
    assert not local_motion_mask(*still, c=6.0, tol=6.0, window_px=15, min_px=30).any()


def test_local_motion_mask_sparse_path_counts_like_the_whole_frame_box_filter():
    """Sparse sweeping pixels (a static scene) take the block path: same mask as the direct count."""
    import cv2

    from raingauge.vision.pipeline import _sweeping, local_motion_mask

    rng = np.random.default_rng(3)
    for trial in range(30):
        H, W = int(rng.integers(48, 96)), int(rng.integers(48, 96))
        w, min_px = int(rng.choice([5, 8, 15])), int(rng.integers(2, 12))
        prev = np.full((H, W), 100.0, np.float32) + rng.normal(0, 0.5, (H, W)).astype(np.float32)
        nxt = prev + rng.normal(0, 0.5, (H, W)).astype(np.float32)
        cur = prev + rng.normal(0, 0.5, (H, W)).astype(np.float32)
        # a few small clusters of pixels swept through three values, edges and corners included
        for _ in range(int(rng.integers(1, 4))):
            y, x = int(rng.integers(0, H)), int(rng.integers(0, W))
            ys = np.clip(y + rng.integers(-3, 4, 12), 0, H - 1)
            xs = np.clip(x + rng.integers(-3, 4, 12), 0, W - 1)
            nxt[ys, xs] += 30.0
            cur[ys, xs] += 60.0
        e, where = _sweeping(prev, cur, nxt, c=6.0, tol=6.0)
        assert where is not None                      # the sparse path was taken
        count = cv2.boxFilter((e > 0).astype(np.float32), cv2.CV_32F, (w, w), normalize=False,
                              borderType=cv2.BORDER_CONSTANT)
        expected = count >= min_px - 0.5
        got = local_motion_mask(prev, cur, nxt, c=6.0, tol=6.0, window_px=w, min_px=min_px)
        assert np.array_equal(got, expected), trial


def test_moving_objects_in_rain_are_left_alone():
    render_clip, small_profile = _simulator()
    import cv2

    prof = small_profile(240, 180, noise_sigma_dn=0.7, exposure_s=0.008)
    frames, truth = render_clip(prof, return_clean=True, n_frames=30, seed=3, background="skimage:camera",
                                rain_rate_mm_h=25.0, depth_range_m=(2.0, 3.2), motion="objects:3:90")
    clean = truth["clean"]
    c16 = clean.astype(np.int16)
    moving = np.zeros(frames.shape, bool)
    moving[1:] |= np.abs(c16[1:] - c16[:-1]) > 2
    moving[:-1] |= np.abs(c16[1:] - c16[:-1]) > 2
    moving = np.stack([cv2.dilate(m.view(np.uint8), np.ones((5, 5), np.uint8)).astype(bool) for m in moving])
    out = np.stack([r.frame for r in Derainer(prof).process(frames)])
    sl = slice(3, -3)
    m = moving[sl]
    assert m.mean() > 0.03
    # the moving objects are barely touched, the rain elsewhere is removed
    assert psnr(out[sl], clean[sl], m) > psnr(frames[sl], clean[sl], m) - 1.0
    assert psnr(out[sl], clean[sl]) > psnr(frames[sl], clean[sl]) + 0.3


# ---------------------------------------------------------------- the resampling shortcuts
def test_window_resampling_matches_bilinear_interpolation():
    from raingauge.vision.pipeline import _StreamWindow, _sample_bilinear

    rng = np.random.default_rng(1)
    import cv2

    img = cv2.GaussianBlur(rng.uniform(0, 255, (60, 80)).astype(np.float32), (0, 0), 2.0)
    M = np.array([[1.0, 0.0, 1.37], [0.0, 1.0, -0.62], [0.0, 0.0, 1.0]])
    idx = rng.choice(img.size, 500, replace=False)

    class Fake(_StreamWindow):
        def __init__(self):
            self.shape = img.shape
            self._M = [M]
            self._moved = [True]
            self._coord_cache = None

    got = Fake()._at(img, 0, idx)[:, 0]
    ref = _sample_bilinear(img, M, idx)[:, 0]
    # cv2.remap quantises the fraction to 1/32 px: a few hundredths of a gray level here
    assert np.abs(got - ref).max() < 0.2 and np.abs(got - ref).mean() < 0.05


def test_registration_slack_fast_path_bounds_the_gradient_magnitude():
    from raingauge.vision.pipeline import registration_slack

    rng = np.random.default_rng(2)
    import cv2

    img = cv2.GaussianBlur(rng.uniform(0, 255, (50, 70)), (0, 0), 1.5).astype(np.uint8)
    fast = registration_slack(img, registration_px=0.5).astype(np.float32)
    exact = registration_slack(img.astype(np.float32), registration_px=0.5)
    assert fast.dtype == np.float32 and exact.shape == img.shape
    # |gx| + |gy| lies between the magnitude and sqrt(2) times it (each term rounded to a gray level)
    assert np.all(fast >= exact - 1.0)
    assert np.all(fast <= np.sqrt(2.0) * exact + 1.001)


def test_detected_includes_a_drop_seen_in_two_consecutive_frames():
    """Sec. 5.2: a drop at one place in frames 15 and 16 has no one-frame spike, yet it is rain."""
    from test_vision_synth import streak_mask, texture

    rng = np.random.default_rng(3)
    shape = (90, 120)
    bg = texture(shape, seed=4, lo=40, hi=160)
    lum = np.stack([bg + rng.normal(0, 0.5, shape).astype(np.float32) for _ in range(30)])
    pair = streak_mask(shape, 60, 45, 24, 100, width=2)
    keep_out = np.zeros(shape, bool)
    keep_out[28:63, 52:69] = True                      # near the pair, frames 12-19 hold no other drop
    rain = np.zeros(lum.shape, bool)
    for t in range(30):                                # one-frame rain all over: a rain region
        for _ in range(12):
            m = streak_mask(shape, rng.uniform(5, 115), rng.uniform(5, 85), rng.uniform(12, 24),
                            100 + rng.uniform(-4, 4), 2)
            if not (12 <= t <= 19 and (m & keep_out).any()):
                rain[t] |= m
    for t in (15, 16):
        rain[t] |= pair
    lum[rain] += 25.0 - 0.02 * np.broadcast_to(bg, lum.shape)[rain]     # Eq. (18)
    frames = np.clip(np.rint(lum), 0, 255).astype(np.uint8)
    out = _run(frames, noise_sigma=0.5)
    for n in (15, 16):
        assert out[n].region[pair].all()
        assert not out[n].b[pair].any()                       # Eq. (19) sees no one-frame spike ...
        assert out[n].detected[pair].mean() >= 0.9            # ... the reported detection has the drop
        assert not (out[n].detected & ~out[n].b & ~rain[n]).any()   # the run hits are all rain
    # a moving object in the rain sweeps its pixels through several frames:
    # the run tests find rain around it, never the object
    frames, _, truth = make_clip(T=24, n_streaks=12, seed=5, moving_object=True, noise=0.5)
    out = _run(frames, noise_sigma=0.5)
    runs = np.stack([r.detected & ~r.b for r in out])
    assert runs.sum() > 200 and not (runs & ~truth).any()


def test_relaxed_run_test_widens_the_detection_only():
    # `raingauge derain` runs with near_px=0 (its outputs are the frames and the removed
    # pixels): the relaxed run test next to the streaks must change neither
    frames, _, _ = make_clip(T=20, n_streaks=14, seed=7)
    full = _run(frames)                   # library default near_px=1
    lean = _run(frames, near_px=0)
    assert len(full) == len(lean) == len(frames)
    extra = 0
    for a, b in zip(full, lean):
        np.testing.assert_array_equal(a.frame, b.frame)
        np.testing.assert_array_equal(a.rain, b.rain)
        np.testing.assert_array_equal(a.b, b.b)
        assert not (b.detected & ~a.detected).any()       # near_px=1 only adds pixels
        extra += int((a.detected & ~b.detected).sum())
    assert extra > 0                      # ... and on this clip it does add some
