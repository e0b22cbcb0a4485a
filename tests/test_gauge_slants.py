"""The detection of slanted streaks when the change is smoothed along the wind's slants
(raingauge.gauge.slants), checked against the gauge's own smoothing of noise frames."""

import numpy as np
import pytest
from scipy.special import ndtr

from raingauge.gauge.rejection import detection_margin
from raingauge.gauge.slants import slant_captures, slant_margin
from raingauge.gauge.streaks import smoothed_spike, wind_slopes

NOISE = 3.0
C = 3.0


def _streaks(shape, slope, contrast, rows, xs):
    """A band 2 px wide across the rows along dx/dy = slope, each pixel changed by the part
    of it the band covers, one band from each of ``xs``; and the pixel nearest each band's
    centre line on each row (the streak's best pixel)."""
    img = np.zeros(shape, np.float32)
    y = np.arange(*rows)
    mid = 0.5 * (rows[0] + rows[1])
    cols = np.arange(shape[1])
    best = []
    for x0 in xs:
        centre = x0 + slope * (y - mid)
        lo = np.maximum(cols[None, :] - 0.5, centre[:, None] - 1.0)
        hi = np.minimum(cols[None, :] + 0.5, centre[:, None] + 1.0)
        img[y] += contrast * np.clip(hi - lo, 0.0, 1.0).astype(np.float32)
        best.append((y, np.rint(centre).astype(int)))
    return img, best


@pytest.fixture(scope="module")
def noise_spike():
    """The spike min(I_n - I_{n-1}, I_n - I_{n+1}) of three frames of pure noise."""
    rng = np.random.default_rng(3)
    f = [rng.normal(100.0, NOISE, (420, 1100)).astype(np.float32) for _ in range(3)]
    return f[1] - np.maximum(f[0], f[2])


@pytest.mark.parametrize("which", [0, 2, 5])
def test_the_largest_over_the_slants_finds_faint_streaks_as_the_model_says(noise_spike, which):
    """Faint streaks drawn into the spike of noise frames and smoothed as detect_streaks
    smooths them in a 3 m/s wind: at each streak's best pixel the share at or above c,
    along its own slant alone and the largest over the wind's slants, is the model's to
    0.03; the largest finds a streak of 3 gray levels at least 1.4 times as often as its
    own slant, the model's lift to 15 %."""
    slopes = wind_slopes(3.0)
    s_true = slopes[which]
    w_across = 2.0 / np.sqrt(1.0 + s_true ** 2)           # a band 2 px wide across the rows
    for contrast in (3.0, 5.0):
        img, best = _streaks(noise_spike.shape, s_true, contrast, (60, 360), range(200, 900, 35))
        spike = noise_spike + img
        own = smoothed_spike(spike, smooth_px=5, slope=s_true)
        big = smoothed_spike(spike, smooth_px=5, slope=slopes[0], slopes=slopes[1:])
        p_own = np.mean(np.concatenate([own[y, x] >= C for y, x in best]))
        p_big = np.mean(np.concatenate([big[y, x] >= C for y, x in best]))
        m_own = slant_margin(contrast, w_across, threshold_dn=C, noise_sigma_dn=NOISE, slopes=[s_true],
                             streak_slope=s_true)
        m_big = slant_margin(contrast, w_across, threshold_dn=C, noise_sigma_dn=NOISE, slopes=slopes,
                             streak_slope=s_true)
        assert float(ndtr(m_own)) == pytest.approx(p_own, abs=0.03)
        assert float(ndtr(m_big)) == pytest.approx(p_big, abs=0.03)
        if contrast == 3.0:
            assert p_big > 1.4 * p_own
            assert float(ndtr(m_big) / ndtr(m_own)) == pytest.approx(p_big / p_own, rel=0.15)


def test_one_straight_slant_is_the_columns_detection_margin():
    """Smoothed straight down along the streak alone, a streak at least 2 px wide has the
    margin of detection_margin, the model of the detection without wind."""
    a = np.linspace(0.5, 20.0, 40)
    for w in (2.0, 3.5, 8.0):
        for noise in (1.0, 3.0):
            m = slant_margin(a, w, threshold_dn=C, noise_sigma_dn=noise, slopes=[0.0], streak_slope=0.0)
            np.testing.assert_allclose(m, detection_margin(a, w, threshold_dn=C, noise_sigma_dn=noise),
                                       rtol=1e-6, atol=1e-6)   # (the kernels are float32)


def test_more_slants_never_find_less_and_brighter_streaks_are_found_more():
    """The largest over more slants is at least any one of them (to the draws' resolution);
    the margin grows with the streak's change, and without noise to lift it the slants
    add little to a bright streak."""
    slopes = wind_slopes(3.0)
    a = np.linspace(1.0, 12.0, 60)
    for s_true in (slopes[0], 0.5 * (slopes[2] + slopes[3]), slopes[-1]):
        all_ = slant_margin(a, 2.0, threshold_dn=C, noise_sigma_dn=NOISE, slopes=slopes, streak_slope=s_true)
        assert np.all(np.diff(all_) >= -1e-9)
        for k in range(len(slopes)):
            one = slant_margin(a, 2.0, threshold_dn=C, noise_sigma_dn=NOISE, slopes=[slopes[k]],
                               streak_slope=s_true)
            assert np.all(all_ >= one - 0.05)
        p_all, p_near = ndtr(all_), ndtr(slant_margin(a, 2.0, threshold_dn=C, noise_sigma_dn=NOISE,
                                                       slopes=slopes[:2] if s_true < 0.5 else slopes[-2:],
                                                       streak_slope=s_true))
        bright = a >= 10.0
        assert np.all(p_all[bright] - p_near[bright] < 0.02)


def test_captures_are_whole_along_the_streaks_own_slant_and_fall_off_the_others():
    """A band 2 px or more across is gathered whole by a kernel along its own slant and
    less by one that leaves it at its ends; a band far wider than the kernels' spread is
    gathered whole by every slant."""
    slopes = [0.0, 0.25, 0.5, 1.0]
    g = slant_captures(2.0, 0.0, slopes)
    assert g[0] == pytest.approx(1.0)
    assert np.all(np.diff(g) < 0)
    np.testing.assert_allclose(slant_captures(12.0, 0.0, slopes), 1.0, atol=1e-12)
    # a narrow band: the pixel nearest its centre holds part of it
    assert 0.5 < slant_captures(1.0, 0.0, [0.0])[0] < 1.0
