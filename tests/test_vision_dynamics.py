"""Dynamics of rain: oriented masks, R_b, direction, segmentation, needle map (Secs. 4.1, 5.1)."""

from __future__ import annotations

import numpy as np
import pytest

from raingauge.vision import (
    ORIENTATIONS_DEG, RainDynamics, dominant_direction_deg, needle_map, oriented_masks, rain_pixel_energies,
)
from test_vision_synth import streak_mask


def test_oriented_masks_follow_note_14():
    masks = oriented_masks(11)
    assert masks.shape == (18, 11, 11)                  # 0, 10, ..., 170 deg
    m0 = np.zeros((11, 11), np.float32)
    m0[4:7, :] = 1                                       # central row and its two neighbours
    np.testing.assert_array_equal(masks[0], m0)
    np.testing.assert_array_equal(masks[9], m0.T)        # 90 deg: vertical
    # rotating by 45 deg gives a diagonal band through the centre, rising to the right on screen
    m45 = oriented_masks(11, angles_deg=[45.0])[0]
    assert m45[0, 10] == 1 and m45[10, 0] == 1 and m45[0, 0] == 0
    with pytest.raises(ValueError):
        oriented_masks(10)


def test_energy_of_a_line_peaks_along_it():
    b = streak_mask((60, 60), 30, 30, 40, 70, width=1)
    rows, cols, E, w = rain_pixel_energies(b, masks=oriented_masks(11))
    assert w == 1.0 and E.shape == (b.sum(), 18)
    best = ORIENTATIONS_DEG[np.argmax(E.sum(axis=0))]
    assert best == 70.0


def _rain_fields(T, shape, angle, n, rng, width=2):
    out = []
    for _ in range(T):
        b = np.zeros(shape, bool)
        for _ in range(n):
            b |= streak_mask(shape, rng.uniform(0, shape[1]), rng.uniform(0, shape[0]), rng.uniform(15, 30),
                             angle + rng.uniform(-4, 4), width)
        out.append(b)
    return out


def test_rain_field_is_directional_and_segmented():
    rng = np.random.default_rng(0)
    dyn = RainDynamics((90, 120), l=11, f=30)
    for b in _rain_fields(30, (90, 120), 110.0, 8, rng):
        dyn.update(b)
    f = dyn.field()
    assert f.frames == 30
    assert f.rain.mean() > 0.8
    assert abs(dominant_direction_deg(f) - 110.0) < 8.0
    assert np.median(f.ratio[f.rain]) > 2.5


def test_isotropic_blobs_and_random_pixels_are_not_rain():
    rng = np.random.default_rng(1)
    dyn = RainDynamics((90, 120), l=11, f=30)
    for _ in range(30):
        b = rng.random((90, 120)) < 0.01                # noise spikes
        for _ in range(4):                               # compact blobs (object edges)
            y, x = rng.integers(5, 85), rng.integers(5, 115)
            b[y - 2:y + 3, x - 2:x + 3] = True
        dyn.update(b)
    f = dyn.field()
    assert f.rain.mean() < 0.01
    assert np.isnan(dominant_direction_deg(f)) or f.rain.sum() < 5


def test_running_window_forgets_old_frames():
    rng = np.random.default_rng(2)
    dyn = RainDynamics((60, 80), f=5)
    for b in _rain_fields(5, (60, 80), 90.0, 6, rng):
        dyn.update(b)
    assert dyn.field().rain.any()
    for _ in range(5):
        dyn.update(np.zeros((60, 80), bool))
    f = dyn.field()
    assert not f.rain.any() and np.allclose(f.events, 0, atol=1e-6)


def test_needle_map_draws_in_rain_region_only():
    rng = np.random.default_rng(3)
    shape = (90, 120)
    dyn = RainDynamics(shape)
    for b in _rain_fields(30, shape, 100.0, 8, rng):
        b[:, 60:] = False                                 # rain on the left half only
        dyn.update(b)
    f = dyn.field()
    img = np.full(shape, 80, np.uint8)
    out = needle_map(img, f, step_px=9)
    assert out.shape == shape + (3,) and out.dtype == np.uint8
    changed = np.any(out != 80, axis=2)
    assert changed[:, :50].mean() > 0.3
    assert changed[:, 75:].mean() < 0.02


# ------------------------------------------------------------- lag-one persistence
def _moving_edges(T, shape, rng, speed=2):
    """The false rain field of a textured object crossing at ``speed`` px/frame: its vertical edges."""
    xs = rng.uniform(0, 80, 10)
    ys = rng.uniform(10, 75, 10)
    out = []
    for t in range(T):
        b = np.zeros(shape, bool)
        for x, y in zip(xs, ys):
            if rng.random() < 0.9:
                b[int(y):int(y) + 8, int(x + 30 + speed * t) % shape[1]] = True
        out.append(b)
    return out


def test_lag_one_persistence_is_chance_for_rain_and_high_for_moving_texture():
    from raingauge.vision.dynamics import lag_one_persistence

    def ratio(fields):
        near = chance = 0.0
        for prev, b in zip(fields[:-1], fields[1:]):
            p, ch = lag_one_persistence(prev, b, radius_px=3)
            near += p.sum()
            chance += ch[b].sum()
        return near / chance

    rain = _rain_fields(20, (90, 120), 100.0, 8, np.random.default_rng(5))
    edges = _moving_edges(20, (90, 120), np.random.default_rng(6))
    # drops of consecutive frames are independent: persistence at the chance level
    assert 0.6 < ratio(rain) < 1.4
    # an object's edges reappear a couple of pixels away in the next frame
    assert ratio(edges) > 3.0


def test_directional_moving_texture_is_not_segmented_as_rain():
    shape = (90, 120)
    edges = _moving_edges(30, shape, np.random.default_rng(4))
    plain = RainDynamics(shape, persistence_px=0)       # direction and strength alone
    dyn = RainDynamics(shape)
    for b in edges:
        plain.update(b)
        dyn.update(b)
    # vertical edges moving sideways are strong and directional: the masks of note 14 take them for rain
    assert plain.field().rain.sum() > 30
    f = dyn.field()
    assert not f.rain.any()
    assert np.nanmax(np.where(np.isfinite(f.persistence), f.persistence, 0.0)) > 2.0


@pytest.mark.parametrize("seed, n", [(7, 10), (8, 20)])
def test_rain_keeps_its_region_with_the_persistence_test(seed, n):
    rng = np.random.default_rng(seed)
    shape = (90, 120)
    plain = RainDynamics(shape, persistence_px=0)
    dyn = RainDynamics(shape)
    for b in _rain_fields(30, shape, 95.0, n, rng):
        plain.update(b)
        dyn.update(b)
    f0, f = plain.field(), dyn.field()
    assert f0.rain.mean() > 0.5
    assert f.rain.sum() >= 0.97 * f0.rain.sum()
    assert np.median(f.persistence[f.rain]) < 1.3
