"""benchmarks/diag_brightness_sampling.py: the reference that gives a known E_r, and the
bootstrap spread of E_r over the streaks' and the probe's samples."""

from __future__ import annotations


import numpy as np
import pytest
from bench_helpers import load_benchmark

from raingauge.gauge import RainGauge
from raingauge.gauge.gauge import BRIGHTNESS_PERCENTILE, PROBE_FOCUS_SAMPLES, drop_brightness_dn
from raingauge.profile import default_profile

CAM = default_profile().replace(width_px=320, height_px=240)


@pytest.fixture(scope="module")
def diag():
    return load_benchmark("diag_brightness_sampling")


def _samples(n, rng, *, e_b=40.0, contrast=160.0, textured=False):
    b = e_b + (rng.uniform(-20.0, 20.0, n) if textured else rng.normal(0.0, 0.5, n))
    q = np.clip(rng.normal(0.95, 0.06, n), 0.0, None)
    return b, b + q * (e_b + contrast - b)


@pytest.mark.parametrize("textured", [False, True])
def test_reference_for_gives_the_target_brightness(diag, textured):
    rng = np.random.default_rng(3)
    b, x = _samples(3000, rng, textured=textured)
    for target in (190.0, 200.0, 215.0):
        q = diag.reference_for(x, b, 0.6, BRIGHTNESS_PERCENTILE, target)
        assert drop_brightness_dn(x, b, q_min=0.6, q_ref=q, percentile=BRIGHTNESS_PERCENTILE) == \
            pytest.approx(target, abs=0.01)
    # a brighter target needs a smaller reference
    assert diag.reference_for(x, b, 0.6, BRIGHTNESS_PERCENTILE, 190.0) > \
        diag.reference_for(x, b, 0.6, BRIGHTNESS_PERCENTILE, 215.0)


def test_bootstrap_spread_falls_as_the_square_root_of_the_samples(diag):
    rng = np.random.default_rng(5)
    spreads = []
    for n in (500, 2000):
        g = RainGauge(CAM, velocity_model="gunn_kinzer")
        g._brightness.extend(*_samples(n, rng))
        out = diag.bootstrap(g, draws=200, seed=1)
        assert not out["from_probe"] and np.isnan(out["sd_probe"])   # the model's reference
        assert out["n_streaks"] == n
        assert out["e_now"] == pytest.approx(g.drop_brightness_estimate_dn, rel=1e-9)
        spreads.append(out["sd_streaks"])
    assert spreads[0] > 0
    assert spreads[0] / spreads[1] == pytest.approx(2.0, rel=0.3)


def test_bootstrap_takes_the_probe_samples_once_they_set_the_reference(diag):
    """Below PROBE_FOCUS_SAMPLES the model's reference stands and the probe leaves no spread;
    from then on the spread its samples leave falls as one over their square root (the
    bootstrap spread of one percentile is itself noisy: averaged over four sample sets)."""
    small, large = [], []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        g = RainGauge(CAM, velocity_model="gunn_kinzer")
        g._brightness.extend(*_samples(2000, rng))
        too_few = rng.normal(0.93, 0.05, PROBE_FOCUS_SAMPLES - 1)
        g._probe_focus.extend(too_few, np.ones(too_few.size))
        assert np.isnan(diag.bootstrap(g, draws=5, seed=2)["sd_probe"])
        one = rng.normal(0.93, 0.05, 1)
        g._probe_focus.extend(one, np.ones(1))
        out = diag.bootstrap(g, draws=100, seed=2)
        assert out["from_probe"] and out["n_probe"] == PROBE_FOCUS_SAMPLES
        small.append(out["sd_probe"])
        more = rng.normal(0.93, 0.05, 4 * PROBE_FOCUS_SAMPLES)
        g._probe_focus.extend(more, np.ones(more.size))
        out = diag.bootstrap(g, draws=100, seed=2)
        assert out["n_probe"] == 5 * PROBE_FOCUS_SAMPLES
        assert out["e_now"] == pytest.approx(g.drop_brightness_estimate_dn, rel=1e-9)
        large.append(out["sd_probe"])
    assert min(small) > 0
    assert np.mean(small) / np.mean(large) == pytest.approx(np.sqrt(5.0), rel=0.25)
