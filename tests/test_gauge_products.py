"""Window products: Eq. (28) over counted drops, DSD moments, intensity, SYNOP 4680, interval."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raingauge.gauge.products import (
    intensity_class,
    intensity_code,
    poisson_interval,
    rate_interval,
    synop_4680,
    window_products,
)
from raingauge.physics import drops as D


def _population(rate_mm_h, volume_m3, rng):
    """Drops present in a volume for a Marshall-Palmer DSD (independent of the gauge)."""
    dsd = D.MarshallPalmer(rate_mm_h)
    n = rng.poisson(dsd.concentration_m3() * volume_m3)
    d = dsd.sample_diameters(n, rng)
    v = D.fall_velocity(d, model="gunn_kinzer")
    return d, v


def test_rate_is_eq28_over_the_drops():
    """Each drop sampled in V with weight g = duration / V gives rho_i = 1/V: the window
    rate equals rain_rate_from_drops (Eq. 28 over the population)."""
    rng = np.random.default_rng(0)
    d, v = _population(10.0, 5.0, rng)
    out = window_products(d, v, np.full(d.size, 60.0 / 5.0), 60.0)
    assert out["rain_rate_mm_h"] == pytest.approx(D.rain_rate_from_drops(d, v, 5.0), rel=1e-12)
    assert out["nt_m3"] == pytest.approx(d.size / 5.0)
    assert out["drops_counted"] == d.size


def test_moments_match_physics_dsd_moments():
    """N(D) in the Parsivel classes and the moments agree with dsd_moments on the binned
    spectrum (same classes, so Dm, Z, LWC, Nw match to binning within a few per cent)."""
    rng = np.random.default_rng(1)
    d, v = _population(20.0, 20.0, rng)
    out = window_products(d, v, np.full(d.size, 1.0 / 20.0), 1.0)
    centres = D.PARSIVEL_D_CENTRES_MM * 1e-3
    widths = D.PARSIVEL_D_WIDTHS_MM * 1e-3
    n_m4 = np.asarray(out["dsd_n_m3_mm"]) * 1e3
    ref = D.dsd_moments(centres, widths, n_m4, D.fall_velocity(centres, model="gunn_kinzer"))
    assert out["nt_m3"] == pytest.approx(ref["nt_m3"], rel=1e-9)
    assert out["dm_mm"] == pytest.approx(ref["dm_mm"], rel=0.03)
    assert out["lwc_g_m3"] == pytest.approx(ref["lwc_g_m3"], rel=0.05)
    assert out["z_dbz"] == pytest.approx(ref["z_dbz"], abs=0.3)
    assert out["nw_mm1_m3"] == pytest.approx(ref["nw_mm1_m3"], rel=0.15)
    # and against the continuous Marshall-Palmer DSD the population came from
    cont = D.dsd_moments_continuous(D.MarshallPalmer(20.0), velocity_model="gunn_kinzer")
    assert out["dm_mm"] == pytest.approx(cont["dm_mm"], rel=0.05)


def test_empty_window():
    out = window_products([], [], [], 60.0, empty_scale_mm_h=0.01)
    assert out["rain_rate_mm_h"] == 0.0
    assert out["rain_rate_ci95_mm_h"][0] == 0.0
    assert out["rain_rate_ci95_mm_h"][1] == pytest.approx(0.01 * 3.689, rel=1e-3)
    assert math.isnan(out["dm_mm"]) and math.isnan(out["z_dbz"])
    with pytest.raises(ValueError):
        window_products([], [], [], 0.0)


@pytest.mark.parametrize("rate, name, code, synop", [
    (0.0, "none", 0, 0), (0.01, "none", 0, 0), (0.5, "light", 1, 61), (2.49, "light", 1, 61),
    (2.5, "moderate", 2, 62), (9.99, "moderate", 2, 62), (10.0, "heavy", 3, 63),
    (49.9, "heavy", 3, 63), (50.0, "violent", 4, 63), (float("nan"), "none", 0, 0)])
def test_intensity_and_synop(rate, name, code, synop):
    assert intensity_class(rate) == name
    assert intensity_code(name) == code
    assert synop_4680(rate, 1.2) == synop


def test_drizzle_codes():
    assert synop_4680(0.1, 0.4) == 51
    assert synop_4680(0.3, 0.4) == 52
    assert synop_4680(1.0, 0.4) == 53


def test_poisson_interval_known_values():
    """Garwood interval: n = 0 -> [0, 3.689]; n = 10 -> [4.795, 18.39]."""
    assert poisson_interval(0) == pytest.approx((0.0, 3.6889), abs=1e-3)
    lo, hi = poisson_interval(10)
    assert lo == pytest.approx(4.7954, abs=1e-3) and hi == pytest.approx(18.390, abs=1e-2)


def test_rate_interval_covers_truth_in_95_percent():
    """Counting statistics: windows drawn from a known population (Poisson number of drops,
    sizes from the DSD) have 95 % intervals that cover the true rate about 95 % of the time."""
    rng = np.random.default_rng(2)
    volume = 0.3
    dsd = D.MarshallPalmer(5.0)
    true_rate = D.rain_rate_mm_h(dsd, velocity_model="gunn_kinzer")
    hits = 0
    trials = 300
    for _ in range(trials):
        d, v = _population(5.0, volume, rng)
        contrib = 3.6e6 * math.pi / 6 * d ** 3 * v / volume
        lo, hi = rate_interval(contrib, systematic_rel=0.0)
        hits += lo <= true_rate <= hi
    assert 0.90 <= hits / trials <= 0.99
