"""Per-streak measurement: sub-pixel width and length of rasterised streaks of known a, v, z."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raingauge.gauge.streaks import (
    change_images,
    depth_from_blur_m,
    detect_streaks,
    fit_cross_profile,
    measure_streaks,
    radius_from_width_m,
    velocity_from_length_m_s,
    wind_slopes,
)
from raingauge.profile import default_profile

CAM = default_profile()


def capsule_change(shape, *, x0, y0, dx, dy, width, contrast, ss=6):
    """Change image of a uniform streak (the paper's constant tau): a capsule of diameter
    ``width`` swept from (x0, y0) by (dx, dy), holding the drop's exposure area
    pi (w/2)^2 spread evenly (Eqs. 17, 23), times ``contrast`` (E_r - E_b).
    Supersampled ss x ss per pixel; independent of the gauge's own model."""
    m, n = shape
    r = width / 2.0
    off = (np.arange(ss) + 0.5) / ss - 0.5
    ys = (np.arange(m)[:, None] + off[None, :]).ravel()
    xs = (np.arange(n)[:, None] + off[None, :]).ravel()
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    length = math.hypot(dx, dy)
    ux, uy = dx / length, dy / length
    qx, qy = xx - x0, yy - y0
    t = np.clip(qx * ux + qy * uy, 0.0, length)
    inside = (qx - t * ux) ** 2 + (qy - t * uy) ** 2 <= r * r
    cover = inside.reshape(m, ss, n, ss).mean(axis=(1, 3))
    beta = math.pi * r * r / (2 * r * length + math.pi * r * r)
    return cover * beta * contrast


def measure_one(change, spike=None, *, c=3.0):
    spike = change if spike is None else spike
    labels, stats = detect_streaks(spike.astype(np.float32), c=c)
    assert np.any(stats[1:, 4] > 0), "no streak detected"
    big = int(np.argmax(stats[1:, 4]) + 1)
    return measure_streaks(change.astype(np.float32), labels, stats, CAM, select=[big])[0]


def focused_drop_changes(a_mm, v, z, *, seed, n=6):
    """``n`` noisy change images of a focused drop of radius ``a_mm`` [mm], speed ``v`` [m/s]
    at depth ``z`` [m] on the gauge camera, each with an independent noisy copy for detection."""
    rng = np.random.default_rng(seed)
    f, T = CAM.focal_length_px, CAM.exposure_s
    w = 2 * f * a_mm * 1e-3 / z
    motion = f * v * T / z
    shape = (int(motion + 40), 60)
    for _ in range(n):
        img = capsule_change(shape, x0=25.3 + rng.random(), y0=15.2 + rng.random(), dx=0.0, dy=motion,
                             width=w, contrast=140.0)
        change = img + rng.normal(0, 2.0 * math.sqrt(1.5), shape)
        yield change, img + rng.normal(0, 2.4, shape)


@pytest.mark.parametrize("a_mm, v, z", [(1.0, 4.4, 2.5), (2.0, 6.5, 2.45), (0.6, 2.5, 2.55)])
def test_width_and_length_recover_a_and_v(a_mm, v, z):
    """A focused drop of known radius, speed and depth, with sensor noise: the measured
    width and motion give back a and v (at the true z) within a few per cent."""
    f, T = CAM.focal_length_px, CAM.exposure_s
    errs_a, errs_v = [], []
    for change, detect in focused_drop_changes(a_mm, v, z, seed=int(a_mm * 10)):
        p = measure_one(change, detect)
        length = p.length_px
        errs_a.append(radius_from_width_m(p.width_px, z, focal_length_px=f) / (a_mm * 1e-3) - 1)
        errs_v.append(velocity_from_length_m_s(length, p.width_px, z, focal_length_px=f, exposure_s=T) / v - 1)
    assert abs(np.mean(errs_a)) < 0.06, errs_a
    assert abs(np.mean(errs_v)) < 0.03, errs_v
    assert np.std(errs_v) < 0.04


def test_slanted_streak_wind():
    """Wind slants the streak: the vertical motion, the slope and the width across it are
    still measured."""
    rng = np.random.default_rng(3)
    shape = (130, 90)
    img = capsule_change(shape, x0=20.4, y0=15.6, dx=25.0, dy=80.0, width=6.0, contrast=140.0)
    change = img + rng.normal(0, 2.0, shape)
    p = measure_one(change)
    assert p.motion_y_px == pytest.approx(80.0, abs=2.0)
    assert p.axis[2] == pytest.approx(25.0 / 80.0, abs=0.02)
    assert p.width_px == pytest.approx(6.0, rel=0.08)


def test_gaussian_blur_is_not_width():
    """Optical blur (a Gaussian of the edges) is fitted as spread, not width: a blurred
    streak keeps its width, and reports a larger blur than a sharp one."""
    import cv2

    rng = np.random.default_rng(4)
    shape = (100, 60)
    img = capsule_change(shape, x0=30.2, y0=15.0, dx=0.0, dy=60.0, width=7.0, contrast=140.0)
    blurred = cv2.GaussianBlur(img, (0, 0), 1.2)
    p_sharp = measure_one(img + rng.normal(0, 1.0, shape))
    p_blur = measure_one(blurred + rng.normal(0, 1.0, shape))
    assert p_blur.width_px == pytest.approx(7.0, rel=0.1)
    assert p_blur.blur_px > p_sharp.blur_px + 1.0
    assert p_blur.motion_y_px == pytest.approx(60.0, abs=1.5)


def test_cross_profile_fit_is_subpixel():
    """The box-Gaussian fit of a noiseless sampled box gives its width to 0.05 px."""
    xi = np.arange(-8, 8, 0.5) + 0.25
    for w in (1.6, 3.3, 7.9):
        # pixel-integrated box: exact overlap of [x-0.5, x+0.5] with [-w/2, w/2]
        vals = np.clip(np.minimum(xi + 0.5, w / 2) - np.maximum(xi - 0.5, -w / 2), 0, None) * 10.0
        fit = fit_cross_profile(xi, vals)
        assert fit["width"] == pytest.approx(w, abs=0.05)


def test_pieces_of_one_streak_are_merged():
    """A streak cut in two by a gap of a few rows (a dark patch behind it) is one streak."""
    shape = (120, 50)
    img = capsule_change(shape, x0=25.0, y0=10.0, dx=0.0, dy=90.0, width=4.0, contrast=140.0)
    img[55:59, :] = 0.0
    labels, stats = detect_streaks(img.astype(np.float32), c=3.0, smooth_px=1)
    assert np.count_nonzero(stats[:, 4]) == 1
    labels2, stats2 = detect_streaks(img.astype(np.float32), c=3.0, smooth_px=1, merge_gap_px=0)
    assert np.count_nonzero(stats2[:, 4]) == 2


def test_pieces_of_a_slanted_streak_are_merged_along_the_wind():
    """A streak slanted by the wind (dx/dy = 0.6) and cut into three pieces is one label
    when the detection knows the slant: its pieces are collinear along the fall, not in
    x.  A parallel streak 12 px beside it stays apart, and without the slant the pieces
    are not joined."""
    shape = (140, 160)
    img = capsule_change(shape, x0=30.0, y0=10.0, dx=66.0, dy=110.0, width=4.0, contrast=140.0)
    for gap in (45, 80):
        img[gap:gap + 3, :] = 0.0
    beside = capsule_change(shape, x0=44.0, y0=15.0, dx=60.0, dy=100.0, width=4.0, contrast=140.0)
    img = img + beside
    lab0, st0 = detect_streaks(img.astype(np.float32), c=3.0, smooth_px=1, slope=0.0)
    lab1, st1 = detect_streaks(img.astype(np.float32), c=3.0, smooth_px=1, slope=0.6)
    assert np.count_nonzero(st0[:, 4]) == 4          # three pieces and the streak beside
    assert np.count_nonzero(st1[:, 4]) == 2
    # the merged streak holds every pixel of the three pieces
    whole = capsule_change(shape, x0=30.0, y0=10.0, dx=66.0, dy=110.0, width=4.0, contrast=140.0) > 3.0
    on = np.unique(lab1[whole & (lab1 > 0)])
    assert on.size == 1 and st1[on[0], 4] > 0


def test_wind_slopes_cover_every_drop_size_slant():
    """The directions cover the slants u / v(D) of drops 0.5-5 mm in a cross wind, no two
    more than the step apart, the wind's sign kept; no wind: straight down only."""
    from raingauge.physics.drops import fall_velocity

    for u in (3.0, -1.5, 8.0):
        s = np.array(wind_slopes(u))
        want = u / np.array([float(fall_velocity(d * 1e-3, model="gunn_kinzer")) for d in (0.5, 1.0, 2.0, 5.0)])
        assert s.min() <= want.min() + 1e-9 and s.max() >= want.max() - 1e-9
        assert np.all(np.diff(s) <= 0.25 + 1e-9)
        assert np.all(np.sign(s) == np.sign(u))
        # every slant within half a step of one direction
        assert np.max(np.min(np.abs(want[:, None] - s[None, :]), axis=1)) <= 0.125 + 1e-9
    assert wind_slopes(0.0) == [0.0]


def test_faint_streaks_of_all_slants_are_found_with_wind_slopes():
    """In a cross wind a small drop slants more (dx/dy 1.3) than the big ones the rain's
    direction is measured on (0.45).  Smoothed along 0.45 alone, a thin faint streak at 1.3
    spreads off its own pixels and is lost in noise; smoothed along every slant it is found,
    and the streak at 0.45 still is.  The price: noise passes in more places (the largest
    of several smoothed changes), still under 1 in 100 pixels."""
    rng = np.random.default_rng(3)
    shape = (160, 200)
    steep = capsule_change(shape, x0=20.0, y0=20.0, dx=104.0, dy=80.0, width=1.6, contrast=400.0)
    flat = capsule_change(shape, x0=140.0, y0=20.0, dx=36.0, dy=80.0, width=1.6, contrast=400.0)
    slopes = wind_slopes(3.0)
    hits = {"one": [0, 0], "all": [0, 0]}
    noise_px = 0
    for _ in range(20):
        noise = rng.normal(0.0, 3.0, shape)
        img = (steep + flat + noise).astype(np.float32)
        for key, kw in (("one", {}), ("all", {"slopes": slopes})):
            labels, stats = detect_streaks(img, c=3.0, smooth_px=5, slope=0.45, **kw)
            for i, streak in enumerate((steep, flat)):
                core = streak > 0.5 * streak.max()
                on = [lab for lab in np.unique(labels[core & (labels > 0)]) if stats[lab, 4] > 0]
                covered = int(np.count_nonzero(core & np.isin(labels, on)))
                hits[key][i] += covered >= 0.5 * np.count_nonzero(core)
        blank = detect_streaks(noise.astype(np.float32), c=3.0, smooth_px=5, slope=0.45, slopes=slopes)[1]
        noise_px += int(blank[1:, 4].sum())
    assert hits["all"][0] >= 18 and hits["one"][0] <= 4
    assert hits["all"][1] >= 18 and hits["one"][1] >= 18
    assert noise_px / (20 * shape[0] * shape[1]) < 0.01


def test_clipped_streak_is_flagged():
    shape = (80, 50)
    img = capsule_change(shape, x0=25.0, y0=40.0, dx=0.0, dy=60.0, width=4.0, contrast=140.0)
    p = measure_one(img)
    assert p.clipped
    img2 = capsule_change(shape, x0=25.0, y0=10.0, dx=0.0, dy=50.0, width=4.0, contrast=140.0)
    assert not measure_one(img2).clipped


def test_change_images_spike_is_eq19():
    """spike = min(I_n - I_{n-1}, I_n - I_{n+1}); change = I_n - mean(neighbours)."""
    rng = np.random.default_rng(0)
    prev, cur, nxt = (rng.uniform(0, 255, (20, 30)).astype(np.float32) for _ in range(3))
    spike, change = change_images(prev, cur, nxt)
    np.testing.assert_allclose(spike, np.minimum(cur - prev, cur - nxt), atol=1e-4)
    np.testing.assert_allclose(change, cur - 0.5 * (prev + nxt), atol=1e-4)


def test_depth_from_blur_round_trip():
    """depth_from_blur_m inverts the thin-lens blur circle on both sides of the focus."""
    from raingauge.physics.camera import blur_circle_px

    kw = dict(focal_length_px=CAM.focal_length_px, f_number=CAM.f_number,
              focus_distance_m=CAM.focus_distance_m, pixel_pitch_m=CAM.pixel_pitch_m)
    for z in (2.2, 2.45, 2.6, 3.1):
        b = blur_circle_px(z, **kw)
        near, far = depth_from_blur_m(b, **kw)
        assert min(abs(near - z), abs(far - z)) < 1e-9
        assert near <= CAM.focus_distance_m <= far


def test_equations_invert_eq26():
    """a = w z / (2 f) inverts w = 2 f a / z (Eq. 26 as corrected); v from L = vT f/z + w."""
    from raingauge.physics.camera import streak_width_px

    f = CAM.focal_length_px
    w = float(streak_width_px(1.2e-3, 2.5, focal_length_px=f))
    assert radius_from_width_m(w, 2.5, focal_length_px=f) == pytest.approx(1.2e-3)
    L = f * 5.0 * CAM.exposure_s / 2.5 + w
    assert velocity_from_length_m_s(L, w, 2.5, focal_length_px=f, exposure_s=CAM.exposure_s) == pytest.approx(5.0)


@pytest.mark.parametrize("a_mm, v, z", [(1.0, 4.4, 2.5), (2.0, 6.5, 2.45), (0.6, 2.5, 2.55)])
def test_closed_form_table_recovers_a_and_v(a_mm, v, z):
    """The gauge's closed-form measurement (moments, box width, end crossings; all streaks at
    once) gives a and v of focused drops as well as the fits: same tolerances as above."""
    from raingauge.gauge.streaks import measure_streak_table

    f, T = CAM.focal_length_px, CAM.exposure_s
    errs_a, errs_v = [], []
    for change, detect in focused_drop_changes(a_mm, v, z, seed=int(a_mm * 10) + 7):
        change = change.astype(np.float32)
        labels, stats = detect_streaks(detect.astype(np.float32), c=3.0)
        big = int(np.argmax(stats[1:, 4]) + 1)
        tab = measure_streak_table(change, labels, stats, [big], noise_sigma=2.0 * math.sqrt(1.5))
        assert tab["ok"][0]
        wa, mot = tab["width_apparent"][0], tab["motion"][0]
        errs_a.append(radius_from_width_m(wa, z, focal_length_px=f) / (a_mm * 1e-3) - 1)
        errs_v.append(velocity_from_length_m_s(mot + wa, wa, z, focal_length_px=f, exposure_s=T) / v - 1)
        assert tab["chi2"][0] < 3.0            # a uniform streak fits its box
    assert abs(np.mean(errs_a)) < 0.06, errs_a
    assert abs(np.mean(errs_v)) < 0.03, errs_v
    assert np.std(errs_v) < 0.04


def test_closed_form_table_many_streaks_and_slant():
    """Several streaks in one frame, one slanted by wind, measured together: each one's
    motion, slope and width; and a two-signed change (an edge of moving scenery) fits
    the streak model badly (large chi2)."""
    from raingauge.gauge.streaks import measure_streak_table

    rng = np.random.default_rng(5)
    shape = (140, 200)
    img = capsule_change(shape, x0=20.4, y0=15.6, dx=25.0, dy=80.0, width=6.0, contrast=140.0)
    img += capsule_change(shape, x0=100.2, y0=20.0, dx=0.0, dy=60.0, width=4.0, contrast=140.0)
    edge = np.zeros(shape)
    edge[30:100, 160:164] = 12.0
    edge[30:100, 164:168] = -12.0
    change = (img + edge + rng.normal(0, 2.0, shape)).astype(np.float32)
    labels, stats = detect_streaks(change, c=3.0)
    sel = np.nonzero(stats[:, 4] > 0)[0]
    tab = measure_streak_table(change, labels, stats, sel, noise_sigma=2.0)
    xs = stats[sel, 0] + stats[sel, 2] / 2
    slanted = int(np.argmin(np.abs(xs - 33)))
    upright = int(np.argmin(np.abs(xs - 100)))
    scenery = int(np.argmin(np.abs(xs - 164)))
    assert tab["motion"][slanted] == pytest.approx(80.0, abs=2.0)
    assert tab["slope"][slanted] == pytest.approx(25.0 / 80.0, abs=0.02)
    assert tab["width_apparent"][slanted] == pytest.approx(6.0, rel=0.08)
    assert tab["motion"][upright] == pytest.approx(60.0, abs=1.5)
    assert tab["width_apparent"][upright] == pytest.approx(4.0, rel=0.1)
    assert tab["chi2"][upright] < 3.0
    assert not (tab["ok"][scenery] and tab["chi2"][scenery] <= 8.0)


def test_spike_image_is_eq19_in_int16_and_float():
    """The spike of Eq. (19), min(I_n - I_{n-1}, I_n - I_{n+1}), exact from 8-bit frames (int16)
    and from linearised float frames; detection gives the same streaks either way."""
    from raingauge.gauge.streaks import spike_image

    rng = np.random.default_rng(2)
    prev, cur, nxt = (rng.integers(0, 256, (60, 80)).astype(np.uint8) for _ in range(3))
    ref = np.minimum(cur.astype(int) - prev, cur.astype(int) - nxt)
    s16 = spike_image(prev, cur, nxt)
    assert s16.dtype == np.int16
    np.testing.assert_array_equal(s16, ref)
    sf = spike_image(*(x.astype(np.float32) for x in (prev, cur, nxt)))
    np.testing.assert_allclose(sf, ref, atol=1e-4)
    img = capsule_change((120, 60), x0=30.0, y0=20.0, dx=0.0, dy=70.0, width=4.0, contrast=140.0)
    base = rng.normal(60, 2, (120, 60))
    frames = [np.clip(base, 0, 255).astype(np.uint8), np.clip(base + img, 0, 255).astype(np.uint8),
              np.clip(base, 0, 255).astype(np.uint8)]
    _, st_i = detect_streaks(spike_image(*frames), c=3.0)
    _, st_f = detect_streaks(spike_image(*(x.astype(np.float32) for x in frames)), c=3.0)
    np.testing.assert_array_equal(st_i[st_i[:, 4] > 0, :4][2:-2], st_f[st_f[:, 4] > 0, :4][2:-2])
    assert np.count_nonzero(st_i[:, 4]) == np.count_nonzero(st_f[:, 4]) >= 1


def test_streak_in_many_pieces_is_one_label():
    """A faint streak broken into four pieces by three short gaps is one label: its box
    spans all pieces, its area is theirs together and all its pixels carry the label; a
    separate streak beside it keeps its own."""
    shape = (160, 80)
    img = capsule_change(shape, x0=20.0, y0=10.0, dx=0.0, dy=130.0, width=4.0, contrast=140.0)
    for gap in (40, 75, 110):
        img[gap:gap + 4, :] = 0.0
    img += capsule_change(shape, x0=60.0, y0=30.0, dx=0.0, dy=80.0, width=4.0, contrast=140.0)
    apart, st_apart = detect_streaks(img.astype(np.float32), c=3.0, smooth_px=1, merge_gap_px=0)
    labels, stats = detect_streaks(img.astype(np.float32), c=3.0, smooth_px=1)
    pieces = [k for k in np.nonzero(st_apart[:, 4])[0] if st_apart[k, 0] < 40]
    assert len(pieces) == 4
    streaks = np.nonzero(stats[:, 4])[0]
    assert len(streaks) == 2
    left = int(streaks[np.argmin(stats[streaks, 0])])
    x0 = st_apart[pieces, 0].min()
    y0 = st_apart[pieces, 1].min()
    x1 = (st_apart[pieces, 0] + st_apart[pieces, 2]).max()
    y1 = (st_apart[pieces, 1] + st_apart[pieces, 3]).max()
    np.testing.assert_array_equal(stats[left], [x0, y0, x1 - x0, y1 - y0, st_apart[pieces, 4].sum()])
    np.testing.assert_array_equal(labels == left, np.isin(apart, pieces))
    right = int(streaks[streaks != left][0])
    np.testing.assert_array_equal(labels == right, apart == right)


ENGINES = ["arrays", pytest.param("compiled", marks=pytest.mark.skipif(
    not __import__("raingauge.gauge._kernels", fromlist=["AVAILABLE"]).AVAILABLE, reason="numba not installed"))]


@pytest.mark.parametrize("engine", ENGINES)
def test_streak_table_does_not_depend_on_the_selection(engine):
    """Each streak's measurement is its own: measured alone or with all the others of the
    frame (whatever a screen keeps), it gives the same numbers.  Also for a wide streak
    (a near, defocused drop) whose box fit reaches beyond every other streak's pixels."""
    from raingauge.gauge.streaks import measure_streak_table

    rng = np.random.default_rng(9)
    shape = (150, 220)
    img = np.zeros(shape)
    for x0, y0, dx, w in ((20.3, 17.0, 0.0, 3.0), (31.7, 18.2, 4.0, 5.0), (60.0, 6.0, 0.0, 22.0),
                          (90.2, 24.0, 20.0, 6.5), (150.5, 30.0, 0.0, 1.6), (190.0, 34.0, -6.0, 9.0)):
        img += capsule_change(shape, x0=x0, y0=y0, dx=dx, dy=90.0, width=w, contrast=140.0)
    frames = [rng.normal(50.0, 2.0, shape).astype(np.float32) for _ in range(3)]
    frames[1] += img.astype(np.float32)
    spike = np.minimum(frames[1] - frames[0], frames[1] - frames[2])
    labels, stats = detect_streaks(spike, c=3.0)
    sel = np.nonzero(stats[:, 4] > 0)[0]
    assert sel.size >= 5
    assert stats[sel[0], 2] > 20                     # the wide streak comes first
    kw = dict(cur=frames[1], prev=frames[0], noise_sigma=2.0 * math.sqrt(1.5), engine=engine)
    together = measure_streak_table(tuple(frames), labels, stats, sel, **kw)
    for i, lab in enumerate(sel):
        alone = measure_streak_table(tuple(frames), labels, stats, [lab], **kw)
        for key in ("xm", "slope", "width_apparent", "motion", "plateau", "background_dn", "chi2"):
            np.testing.assert_allclose(alone[key], together[key][i:i + 1], rtol=1e-9, err_msg=key)
        mine = together["own_k"] == i
        np.testing.assert_array_equal(alone["own_y"], together["own_y"][mine])
        np.testing.assert_array_equal(alone["own_x"], together["own_x"][mine])


def test_box_width_fit_keeps_to_each_streak():
    """The least-squares box width of a streak whose pixels all lie inside the widest boxes
    tried (its band cut short of its edges) is fitted on its own pixels: the same alone as
    before the pixels of another streak."""
    from raingauge.gauge.streaks import _refine_box_width

    u0 = np.tile(np.linspace(-2.0, 2.0, 41), 10)     # 10 rows of a streak's plateau
    v0 = 1.0 + 0.1 * (2.0 - np.abs(u0))             # peaked, every box covering it fits alike
    u1 = np.linspace(-1.0, 1.0, 5)
    v1 = np.full(u1.size, -10.0)                      # (a darkening: moving scenery)
    alone = _refine_box_width(np.zeros(u0.size, np.int64), u0, v0, np.zeros(1), np.array([6.0]), 1)
    ks = np.concatenate([np.zeros(u0.size, np.int64), np.ones(u1.size, np.int64)])
    both = _refine_box_width(ks, np.concatenate([u0, u1]), np.concatenate([v0, v1]), np.zeros(2),
                             np.array([6.0, 2.0]), 2)
    assert both[0] == pytest.approx(alone[0], rel=1e-12)
    assert alone[0] < 6.0                             # the narrowest box holding all its pixels


def test_group_sums_equal_bincount_with_empty_groups():
    """The table's per-streak sums (one segment reduction over pixels ordered by streak,
    the segments found once and reused) equal np.bincount, also for streaks without pixels
    at the start, middle and end."""
    from raingauge.gauge.streaks import _Groups, _group_sum

    rng = np.random.default_rng(4)
    K = 12
    k = np.sort(rng.choice([1, 2, 3, 5, 6, 7, 8, 10], size=400))
    g = _Groups(k, K)
    for _ in range(3):
        v = rng.normal(0.0, 10.0, k.size)
        np.testing.assert_allclose(g.sum(v), np.bincount(k, v, K), rtol=1e-12, atol=1e-9)
        np.testing.assert_array_equal(_group_sum(k, v, K), g.sum(v))
    np.testing.assert_array_equal(_Groups(np.zeros(0, np.int64), 3).sum(np.zeros(0)), np.zeros(3))


def _offset_scene(offset_dn, *, seed):
    """A focused streak (w' = 3 px, 50 px of motion, contrast 140) in a change image that a
    wide, faint defocused drop over a neighbour frame shifts by a smooth offset (a Gaussian
    blob of peak ``offset_dn``, 40 px across), with noise: (change, streak alone)."""
    rng = np.random.default_rng(seed)
    shape = (110, 90)
    img = capsule_change(shape, x0=45.3, y0=20.2, dx=0.0, dy=50.0, width=3.0, contrast=140.0)
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    blob = offset_dn * np.exp(-0.5 * (((xx - 40.0) / 20.0) ** 2 + ((yy - 50.0) / 25.0) ** 2))
    noisy = img + rng.normal(0, 1.2, shape)
    return (noisy + blob).astype(np.float32), noisy.astype(np.float32)


@pytest.mark.parametrize("offset_dn", [-4.0, 4.0])
def test_flank_baseline_removes_the_offset_of_other_rain(offset_dn):
    """A near, defocused drop over frame n-1 or n+1 (or over n) shifts I_n - (I_{n-1} + I_{n+1})/2
    under a focused streak; measured against its flanks, the streak's plateau, total change
    and width are its own (within 6 %), while the plain measurement is off by over 20 %."""
    from raingauge.gauge.rejection import exposure_area_px2
    from raingauge.gauge.streaks import measure_streak_table

    got = {True: [], False: []}
    for seed in range(4):
        change, alone = _offset_scene(offset_dn, seed=seed)
        labels, stats = detect_streaks(alone, c=3.0)          # the same streak is detected
        big = int(np.argmax(stats[1:, 4]) + 1)
        plateau_true = 140.0 * math.pi * 1.5 ** 2 / (3.0 * 50.0 + math.pi * 1.5 ** 2) * 3.0
        for baseline in (True, False):
            tab = measure_streak_table(change, labels, stats, [big], noise_sigma=1.2, baseline=baseline)
            q = exposure_area_px2(tab["plateau"][0], tab["motion"][0], tab["width_apparent"][0])
            got[baseline].append((tab["plateau"][0] / plateau_true, q / (140.0 * math.pi * 1.5 ** 2),
                                  tab["width_apparent"][0] / 3.0))
    with_b = np.mean(got[True], axis=0)
    without = np.mean(got[False], axis=0)
    assert with_b == pytest.approx([1.0, 1.0, 1.0], abs=0.06), with_b
    assert abs(without[0] - 1.0) > 0.2, without


def test_flank_baseline_keeps_a_wide_defocused_streak():
    """A faint, wide (defocused) streak is detected only along its core; its flanks are taken
    beyond the width measured first, so the baseline does not eat it: its total change
    stays within 15 % of the truth."""
    from raingauge.gauge.rejection import exposure_area_px2
    from raingauge.gauge.streaks import measure_streak_table

    rng = np.random.default_rng(11)
    shape = (120, 90)
    width, motion, contrast = 10.0, 60.0, 240.0
    a_i = 1.75                                   # the drop's own image radius: spread 10 px wide
    img = capsule_change(shape, x0=45.0, y0=25.0, dx=0.0, dy=motion, width=width, contrast=1.0)
    beta = math.pi * a_i ** 2 / (width * motion + math.pi * width ** 2 / 4)
    img = img / img.max() * beta * contrast
    change = (img + rng.normal(0, 0.8, shape)).astype(np.float32)
    labels, stats = detect_streaks(change, c=3.0)
    big = int(np.argmax(stats[1:, 4]) + 1)
    assert stats[big, 4] / stats[big, 3] < width - 1.0        # only the core is detected
    tab = measure_streak_table(change, labels, stats, [big], noise_sigma=0.8)
    q = exposure_area_px2(tab["plateau"][0], tab["motion"][0], tab["width_apparent"][0])
    assert q / (contrast * math.pi * a_i ** 2) == pytest.approx(1.0, abs=0.15)


def test_hysteresis_keeps_a_faint_streak_whole():
    """A streak whose change hovers at the threshold (a drop over a bright, varying
    background, Eq. 17) passes c only in patches: plain detection cuts it short or in
    pieces, hysteresis along the fall keeps its whole length; isolated noise does not grow."""
    rng = np.random.default_rng(2)
    shape = (120, 60)
    img = capsule_change(shape, x0=30.0, y0=20.0, dx=0.0, dy=70.0, width=3.0, contrast=1.0)
    img = img / img.max()
    yy = np.arange(shape[0])[:, None]
    level = 3.2 + 1.2 * np.sin(yy / 2.5)                      # 2.0-4.4 DN along the streak
    change = (img * level + rng.normal(0, 0.5, shape)).astype(np.float32)
    found = {}
    for grow in (1.0, 0.5):
        labels, stats = detect_streaks(change, c=3.0, grow=grow, merge_gap_px=0)
        found[grow] = stats[1:][stats[1:, 4] > 0]
    assert len(found[0.5]) == 1 and found[0.5][0, 3] >= 70       # whole: 70 px of motion + its width
    assert len(found[1.0]) > 2 and found[1.0][:, 3].max() < 0.5 * 70
    noise = rng.normal(0, 0.5, shape).astype(np.float32)
    _, stats = detect_streaks(noise, c=3.0, grow=0.5)
    assert not np.any(stats[1:, 4] > 0)


@pytest.mark.skipif(not __import__("raingauge.gauge._kernels", fromlist=["AVAILABLE"]).AVAILABLE,
                    reason="numba not installed")
@pytest.mark.parametrize("background", ["uniform:0.05", "skimage:brick"])
def test_compiled_streak_table_equals_the_array_form(background):
    """The compiled per-streak loops (raingauge.gauge._kernels) measure simulated rain as the
    array form does, up to the order of summation: the same streaks measurable, the same
    own pixels, the numbers within 1e-6 (both with and without the division by the local
    contrast of Eq. 18).  A sum that differs in its last bit may move a pixel lying exactly
    on the edge of the moment's window (a streak on the pixel grid) to the other side: a
    few streaks may differ by that pixel."""
    from raingauge.gauge.streaks import PER_STREAK_KEYS, measure_streak_table
    from raingauge.render.simulator import render_clip

    prof = CAM.replace(width_px=480, height_px=270)
    frames, _ = render_clip(prof, n_frames=3, rain_rate_mm_h=50.0, seed=3, background=background)
    lin = [np.asarray(f, np.float32) for f in frames]
    labels, stats = detect_streaks(np.minimum(lin[1] - lin[0], lin[1] - lin[2]), c=3.0)
    sel = np.nonzero(stats[1:, 4] > 0)[0] + 1
    assert sel.size >= 20
    for contrast in (None, (200.0, 150.0)):
        kw = dict(valid=stats[:, 4] > 0, cur=lin[1], prev=lin[0], contrast=contrast, noise_sigma=2.0)
        a = measure_streak_table(tuple(lin), labels, stats, sel, engine="arrays", **kw)
        b = measure_streak_table(tuple(lin), labels, stats, sel, engine="compiled", **kw)
        np.testing.assert_array_equal(a["ok"], b["ok"])
        assert a["ok"].sum() >= 10
        for key in PER_STREAK_KEYS:
            if key == "ok":
                continue
            same = np.isclose(b[key], a[key], rtol=1e-6, atol=1e-6, equal_nan=True)
            assert same.mean() >= 0.95, (key, np.flatnonzero(~same))
        assert np.isclose(b["width_apparent"], a["width_apparent"], rtol=1e-6, equal_nan=True).sum() >= sel.size - 2
        for key in ("own_k", "own_y", "own_x"):
            np.testing.assert_array_equal(b[key], a[key])


@pytest.mark.skipif(not __import__("raingauge.gauge._kernels", fromlist=["AVAILABLE"]).AVAILABLE,
                    reason="numba not installed")
@pytest.mark.parametrize("frames_8bit", [False, True])
def test_compiled_table_is_its_passes_one_streak_at_a_time(frames_8bit):
    """The compiled table measures each streak's own pixels, then its profile, then (when it
    is wider than its detected rows) its profile again against the flanks beyond the width
    found, one streak after the other.  That is, to the last bit, the passes taken one at a
    time over all the streaks: the own pixels, the first pass, the second pass over the
    wide ones."""
    from raingauge.gauge import streaks as S
    from raingauge.render.simulator import render_clip

    prof = CAM.replace(width_px=480, height_px=270)
    frames, _ = render_clip(prof, n_frames=3, rain_rate_mm_h=100.0, seed=5, background="uniform:0.15")
    frames = [np.asarray(f, np.uint8) if frames_8bit else np.asarray(f, np.float32) for f in frames]
    lin = [f.astype(np.float32) for f in frames]
    labels, stats = detect_streaks(np.minimum(lin[1] - lin[0], lin[1] - lin[2]), c=3.0)
    sel = np.nonzero(stats[1:, 4] > 0)[0] + 1
    valid = stats[:, 4] > 0
    for contrast in (None, (200.0, 150.0)):
        kw = dict(margin_px=4, sigma_min=S.SHARP_SIGMA_PX, cur=frames[1], contrast=contrast, noise_sigma=2.0,
                  engine="compiled")
        own = S._own_streak_pixels(tuple(frames), labels, stats, sel, margin_px=4, cur=frames[1], prev=frames[0],
                                   contrast=contrast, engine="compiled")
        first = S._profile_pass(tuple(frames), labels, valid, own, baseline_width=np.zeros(sel.size), **kw)
        wide = np.flatnonzero(np.nan_to_num(first["width_apparent"]) > first["row_width"] + S.WIDE_MARGIN_PX)
        assert wide.size >= 5
        again = S._profile_pass(tuple(frames), labels, valid, S._subset_streaks(own, wide),
                                baseline_width=first["width_apparent"][wide], **kw)
        for key in S.PER_STREAK_KEYS:
            first[key][wide] = again[key]
        got = S.measure_streak_table(tuple(frames), labels, stats, sel, valid=valid, cur=frames[1], prev=frames[0],
                                     contrast=contrast, noise_sigma=2.0, engine="compiled")
        assert got.keys() == first.keys()
        for key in got:
            np.testing.assert_array_equal(got[key], first[key], err_msg=key)


@pytest.mark.skipif(not __import__("raingauge.gauge._kernels", fromlist=["AVAILABLE"]).AVAILABLE,
                    reason="numba not installed")
def test_compiled_median_equals_numpy():
    """The compiled loops' median (an insertion sort in place for short rows, np.sort
    beyond) is np.median's for odd, even and long inputs, and sorts NaN last as np.sort."""
    from raingauge.gauge import _kernels

    rng = np.random.default_rng(4)
    for n in (1, 2, 3, 7, 10, 64, 65, 200):
        for ties in (False, True):
            a = rng.normal(0.0, 5.0, n + 3)
            if ties:
                a = np.round(a)
            expect = np.median(a[:n])
            got = _kernels._median(a.copy(), n)
            assert got == expect or (np.isnan(got) and np.isnan(expect)), (n, ties)
    a = np.array([3.0, np.nan, 1.0, 2.0, np.nan, 0.5])
    b = a.copy()
    _kernels._sort_small(b, b.size)
    np.testing.assert_array_equal(b, np.sort(a))
    s4 = np.sort(a[:4])            # NaN sorted last, as by np.sort: the middle of the rest
    assert _kernels._median(a.copy(), 4) == 0.5 * (s4[1] + s4[2])
    assert math.isnan(_kernels._median(np.zeros(3), 0))


@pytest.mark.parametrize("engine", ENGINES)
def test_streak_table_reads_8bit_frames_as_their_float_image(engine):
    """The 8-bit frames of a linear camera measure exactly as their float32 image does."""
    from raingauge.gauge.streaks import measure_streak_table
    from raingauge.render.simulator import render_clip

    prof = CAM.replace(width_px=480, height_px=270)
    frames, _ = render_clip(prof, n_frames=3, rain_rate_mm_h=50.0, seed=3, background="skimage:brick")
    raw = [np.asarray(f, np.uint8) for f in frames]
    lin = [f.astype(np.float32) for f in raw]
    labels, stats = detect_streaks(np.minimum(lin[1] - lin[0], lin[1] - lin[2]), c=3.0)
    sel = np.nonzero(stats[1:, 4] > 0)[0] + 1
    assert sel.size >= 20
    for contrast in (None, (200.0, 150.0)):
        kw = dict(valid=stats[:, 4] > 0, contrast=contrast, noise_sigma=2.0, engine=engine)
        a = measure_streak_table(tuple(lin), labels, stats, sel, cur=lin[1], prev=lin[0], **kw)
        b = measure_streak_table(tuple(raw), labels, stats, sel, cur=raw[1], prev=raw[0], **kw)
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(b[key], a[key], err_msg=key)


@pytest.mark.skipif(not __import__("raingauge.gauge._kernels", fromlist=["AVAILABLE"]).AVAILABLE,
                    reason="numba not installed")
def test_compiled_labelling_equals_opencv():
    """The compiled labelling from a mask's runs (raingauge.gauge._kernels.label_components)
    gives OpenCV's 8-connected labels, their numbering and stats, on random masks of any
    shape, density and nonzero values (rows read as 8-pixel words, and with a ragged last
    word, included), an empty one and a dense
    one past 65000 pixels; 16-bit labels up to 65536 labels (a dense mask of few components
    too), 32-bit ones past them."""
    import cv2

    from raingauge.gauge import _kernels

    def opencv(mask):
        ltype = cv2.CV_16U if cv2.countNonZero(mask) < 65000 else cv2.CV_32S
        n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8, ltype=ltype)
        stats = stats[:, :5].copy()
        stats[0] = 0
        return n, labels, stats

    rng = np.random.default_rng(11)
    masks = [np.zeros((30, 40), np.uint8), ((rng.random((400, 400)) < 0.6) * 255).astype(np.uint8)]
    for k in range(150):
        shape = (int(rng.integers(1, 50)), int(rng.integers(1, 70)))
        # (any nonzero byte is set: 255, or 1-255 at random)
        value = 255 if k % 2 else rng.integers(1, 256, shape)
        masks.append(((rng.random(shape) < rng.uniform(0.01, 0.7)) * value).astype(np.uint8))
    for mask in masks:
        n, labels, stats = opencv(mask)
        n2, labels2, stats2 = _kernels.label_components(mask)
        assert n2 == n
        assert labels2.dtype == np.uint16
        np.testing.assert_array_equal(labels2, labels)
        np.testing.assert_array_equal(stats2, stats)
    assert np.count_nonzero(masks[1]) >= 65000
    # isolated pixels two apart: 66560 components, past what 16 bits number
    many = np.zeros((512, 520), np.uint8)
    many[::2, ::2] = 255
    n, labels, stats = opencv(many)
    n2, labels2, stats2 = _kernels.label_components(many)
    assert n2 == n == 66561 and labels2.dtype == np.int32
    np.testing.assert_array_equal(labels2, labels)
    np.testing.assert_array_equal(stats2, stats)


def test_detection_from_8bit_frames_equals_that_of_their_spike_image():
    """detect_streaks on the three 8-bit frames (one compiled pass summing Eq. (19) along the
    fall, where numba is installed) labels exactly as on their int16 spike image, with and
    without hysteresis, for odd and even smoothing lengths and thresholds off the integers;
    slanted rain falls back to the spike image."""
    from raingauge.gauge.streaks import spike_image
    from raingauge.render.simulator import render_clip

    prof = CAM.replace(width_px=480, height_px=270)
    frames, _ = render_clip(prof, n_frames=3, rain_rate_mm_h=50.0, seed=5, background="skimage:brick")
    trio = tuple(np.asarray(f, np.uint8) for f in frames)
    rng = np.random.default_rng(8)
    noise = tuple(rng.integers(0, 256, (23, 17)).astype(np.uint8) for _ in range(3))
    for three in (trio, noise):
        spike = spike_image(*three)
        for c, grow, n_s, slope in ((3.0, 1.0, 5, 0.0), (2.7, 0.6, 5, 0.0), (3.3, 0.5, 4, 0.0), (2.0, 1.0, 7, 0.0),
                                    (3.0, 1.0, 5, 0.2)):
            a = detect_streaks(spike, c=c, grow=grow, smooth_px=n_s, slope=slope)
            b = detect_streaks(three, c=c, grow=grow, smooth_px=n_s, slope=slope)
            assert b[0].dtype == a[0].dtype
            np.testing.assert_array_equal(b[0], a[0])
            np.testing.assert_array_equal(b[1], a[1])
    assert np.count_nonzero(detect_streaks(trio, c=3.0)[1][:, 4] > 0) >= 20


def _slanted_sums(spike, n, slopes):
    """The spike summed over n rows along each slope, the largest: float64, the frame
    reflected at its borders (numpy's 'symmetric', OpenCV's BORDER_REFLECT), each row read
    between its two columns as v0 + frac (v1 - v0)."""
    half = n // 2
    reach = int(max(abs(s) for s in slopes) * half) + 2
    pad = np.pad(spike.astype(np.float64), ((half, n - 1 - half), (reach, reach + 1)), mode="symmetric")
    M, N = spike.shape
    best = np.full((M, N), -np.inf)
    for slope in slopes:
        acc = np.zeros((M, N))
        for i in range(n):
            x = slope * (i - half)
            x0 = math.floor(x)
            f = x - x0
            v0 = pad[i:i + M, reach + x0:reach + x0 + N]
            v1 = pad[i:i + M, reach + x0 + 1:reach + x0 + 1 + N]
            acc += v0 + f * (v1 - v0)
        best = np.maximum(best, acc)
    return best


@pytest.mark.skipif(not __import__("raingauge.gauge._kernels", fromlist=["AVAILABLE"]).AVAILABLE,
                    reason="numba not installed")
def test_compiled_slanted_detection_sums_along_the_fall_exactly():
    """In a cross wind the compiled pass (raingauge.gauge._kernels.slant_masks) thresholds the
    largest over the directions of the spike summed along each.  Against an independent sum
    in float64: on whole gray levels along the direction search's quarter-pixel slopes, where
    sums equal thresholds exactly, the very same masks (a sum equal to c reaches it); along
    the wind's slopes the same but within 1e-4 gray levels of a threshold.  OpenCV's filters
    (smoothed_spike, float32) agree but for such ties.  Simulated rain in a 3 m/s wind (int16
    and float32 spikes, the three 8-bit frames) and noise, one direction or several, with
    and without hysteresis, odd and even lengths; detect_streaks then labels these masks."""
    import cv2

    from raingauge.gauge import _kernels
    from raingauge.gauge.gauge import DIRECTION_SEARCH_SLOPES
    from raingauge.gauge.streaks import _label_and_merge, smoothed_spike, spike_image
    from raingauge.render.simulator import render_clip

    prof = CAM.replace(width_px=480, height_px=270)
    frames, _ = render_clip(prof, n_frames=3, rain_rate_mm_h=30.0, seed=4, background="skimage:brick",
                            wind_m_s=3.0)
    trio = tuple(np.asarray(f, np.uint8) for f in frames)
    rng = np.random.default_rng(12)
    noise = np.rint(rng.normal(0.0, 4.0, (41, 70))).astype(np.int16)
    slopes3 = wind_slopes(3.0)
    search = list(DIRECTION_SEARCH_SLOPES)
    cases = ((3.0, 1.0, 5, slopes3[2], slopes3), (2.7, 0.6, 5, slopes3[0], slopes3), (3.3, 0.5, 4, 0.4, ()),
             (2.0, 0.6, 7, -0.9, (-1.5, -0.3, 0.0, 1.2)), (3.0, 0.6, 5, 0.0, search), (2.2, 0.5, 6, 0.25, search))
    n_set = n_ties = 0
    for spike in (spike_image(*trio), spike_image(*trio).astype(np.float32), noise):
        for c, grow, n_s, slope, slopes in cases:
            extra = [v for v in slopes if abs(v - slope) >= 0.05]
            exact = _slanted_sums(spike, n_s, [slope, *extra])
            cv = smoothed_spike(spike, smooth_px=n_s, slope=slope, slopes=extra)
            mask, low = _kernels.slant_masks(spike, n_s, [slope, *extra], c, c * grow)
            quarter = all(float(v * 4).is_integer() for v in (slope, *extra)) and spike.dtype == np.int16
            for got, thr in ((mask, c), (low, c * grow)):
                level = n_s * thr
                want = exact >= level * (1 - 1e-9)
                if quarter:
                    np.testing.assert_array_equal(got > 0, want, err_msg=str((c, grow, n_s, slope)))
                    n_ties += np.count_nonzero(np.abs(exact - level) < 1e-9 * level)
                else:
                    off = (got > 0) != want
                    assert np.all(np.abs(exact[off] - level) < 1e-4), (c, grow, n_s, slope)
                # OpenCV's float32 filters: the same but where the sum is the threshold
                off = (got > 0) != (cv2.compare(cv, thr, cv2.CMP_GE) > 0)
                assert np.all(np.abs(exact[off] - level) < 1e-4), (c, grow, n_s, slope)
            n_set += np.count_nonzero(mask)
            assert _kernels.slant_masks(spike, n_s, [slope, *extra], c)[1] is None
            if spike.shape[1] >= 64:
                # detect_streaks's compiled path: the labels of these masks
                a = detect_streaks(spike, c=c, grow=grow, smooth_px=n_s, slope=slope, slopes=slopes)
                b = _label_and_merge(mask, low if grow < 1.0 else None, min_pixels=6, merge_gap_px=6.0,
                                     slope=slope, grow_slopes=extra, grow_rows=6)
                np.testing.assert_array_equal(a[0], b[0])
                np.testing.assert_array_equal(a[1], b[1])
    assert n_set > 10000 and n_ties > 100
    # the three 8-bit frames label as their spike image
    a = detect_streaks(trio, c=3.0, grow=0.6, slope=slopes3[2], slopes=slopes3)
    b = detect_streaks(spike_image(*trio), c=3.0, grow=0.6, slope=slopes3[2], slopes=slopes3)
    np.testing.assert_array_equal(a[0], b[0])
    assert np.count_nonzero(a[1][:, 4] > 0) >= 20
    with pytest.raises(ValueError, match="at least one direction"):
        _kernels.slant_masks(noise, 5, [], 3.0)


def test_hysteresis_reach_along_all_directions_is_one_dilation():
    """The hysteresis's reach along every direction the change was smoothed along, one
    dilation by the union of the lines (streaks._reach_union), is the largest of the
    dilations along each line, pixel for pixel: the wind's slants, the direction search's
    13, one upright, lines of both signs and widths."""
    import cv2

    from raingauge.gauge.streaks import _reach_kernel, _reach_union

    rng = np.random.default_rng(3)
    for g, slopes in ((6, wind_slopes(3.0)), (6, [0.0]), (6, [0.0, 0.5]), (4, list(np.arange(-6, 7) * 0.25)),
                      (6, [-0.9, 1.2, 0.03]), (3, [2.5, -0.2])):
        mask = ((rng.random((90, 130)) < 0.02) * 255).astype(np.uint8)
        want = cv2.dilate(mask, _reach_kernel(g, slopes[0]))
        for other in slopes[1:]:
            want = cv2.max(want, cv2.dilate(mask, _reach_kernel(g, other)))
        got = cv2.dilate(mask, _reach_union(g, slopes))
        np.testing.assert_array_equal(got, want)
        assert np.count_nonzero(got) > np.count_nonzero(mask)


@pytest.mark.skipif(not __import__("raingauge.gauge._kernels", fromlist=["AVAILABLE"]).AVAILABLE,
                    reason="numba not installed")
def test_compiled_union_find_equals_the_dict_form():
    """The compiled union-find of the merge of pieces gives the members and roots of the
    dict-based one (each pair's second set under its first's root, pairs in order)."""
    from raingauge.gauge import _kernels
    from raingauge.gauge.streaks import union_roots_dict

    rng = np.random.default_rng(6)
    for _ in range(300):
        n = int(rng.integers(2, 60))
        first, second = rng.integers(0, n, (2, int(rng.integers(0, 80))))
        members, roots = _kernels.union_roots(n, first, second)
        expect = union_roots_dict(first, second)
        np.testing.assert_array_equal(members, expect[0])
        np.testing.assert_array_equal(roots, expect[1])


def test_streak_table_engine_is_checked():
    from raingauge.gauge.streaks import measure_streak_table

    labels = np.zeros((20, 20), np.int32)
    stats = np.zeros((1, 5), np.int64)
    with pytest.raises(ValueError, match="engine"):
        measure_streak_table(np.zeros((20, 20), np.float32), labels, stats, [], engine="gpu")


def test_growth_reaches_along_the_slanted_fall():
    """The hysteresis growth follows the fall: a faint streak slanted by the wind (0.7 px
    across per row) that passes the threshold c only in a short bright stretch takes its
    pixels at or above grow c for grow_rows rows either way along its slant.  Grown down the
    columns, it kept less: the 3-px streak leaves a column within four rows."""
    shape = (120, 120)
    slope, c = 0.7, 3.0
    img = np.zeros(shape, np.float32)
    rows = np.arange(20, 100)
    x = 30.0 + slope * (rows - 20)
    for r, xc in zip(rows, x):
        lo = int(np.floor(xc - 1.0))
        img[r, lo:lo + 3] = 0.8 * c           # faint: above grow c = 0.6 c, under c
    img[57:63] *= 1.5                         # a bright stretch of 6 rows: 1.2 c
    labels, stats = detect_streaks(img, c=c, smooth_px=1, slope=slope, grow=0.6, grow_rows=6, merge_gap_px=0)
    big = np.argmax(stats[:, 4])
    assert stats[big, 3] >= 6 + 2 * 6 - 1     # the bright rows and 6 more either way
    # smoothed along several directions (a cross wind's sizes, the search for the rain's
    # direction), it reaches along each of them
    labels2, stats2 = detect_streaks(img, c=c, smooth_px=1, slope=0.0, slopes=[-0.7, 0.7], grow=0.6, grow_rows=6,
                                     merge_gap_px=0)
    assert stats2[np.argmax(stats2[:, 4]), 3] >= 6 + 2 * 6 - 1
    # straight down, the same growth keeps the stretch and at most four rows either way
    labels0, stats0 = detect_streaks(img, c=c, smooth_px=1, slope=0.0, grow=0.6, grow_rows=6, merge_gap_px=0)
    assert stats0[np.argmax(stats0[:, 4]), 3] <= 6 + 2 * 4


@pytest.mark.parametrize("engine", ["compiled", "arrays"])
def test_slanted_streaks_motion_is_the_drops_vertical_motion(engine):
    """A cross wind slants a drop's streak by u / v(a); its rows cut the end caps
    obliquely.  Measured on the simulator's noise-free capsules of 1.4-2.5 px radius slanted
    by 0 to 1.25, the motion is the drop's vertical motion within 0.2 px (the ends placed as
    an upright streak's, it was 0.23-0.34 px short at a slant of 0.5 and 0.80-1.25 px at
    1.25), by either engine."""
    from raingauge.gauge import _kernels
    from raingauge.gauge.streaks import detect_streaks, measure_streak_table, spike_image
    from raingauge.render.simulator import compose_rain, render_streaks

    if engine == "compiled" and not _kernels.AVAILABLE:
        pytest.skip("the compiled engine needs numba")
    rng = np.random.default_rng(31)
    for r_px in (1.4, 1.83, 2.5):
        for slope in (0.0, 0.5, 0.75, 1.0, 1.25):
            errors = []
            for _ in range(4):
                length = rng.uniform(30.0, 60.0)
                xc, yc = 110 + rng.uniform(-0.5, 0.5), 70 + rng.uniform(-0.5, 0.5)
                half = np.array([0.5 * slope * length, 0.5 * length])
                beta, _ = render_streaks((140, 220), np.array([[xc, yc]]) - half, np.array([[xc, yc]]) + half,
                                         [r_px], [math.pi * (0.9 * r_px) ** 2])
                bg = np.full((140, 220), 40.0, np.float32)
                frames = (bg, compose_rain(bg, beta.astype(np.float32), drop_brightness_dn=200.0).astype(np.float32),
                          bg)
                labels, stats = detect_streaks(spike_image(*frames), c=3.0, slope=slope,
                                               slopes=[slope] if slope else None)
                k = 1 + int(np.argmax(stats[1:, 4]))
                tab = measure_streak_table(frames, labels, stats, np.array([k]), cur=frames[1], prev=frames[0],
                                           noise_sigma=0.5, engine=engine)
                errors.append(float(tab["motion"][0]) - length)
            assert abs(np.mean(errors)) < 0.2, (r_px, slope, errors)
