"""Streak photometry: Eqs. (15)-(18), Eq. (29), the paper's bounds tau < 1.18 ms and beta < 0.039."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raingauge.physics import streaks
from raingauge.physics.drops import FALL_VELOCITY_MODELS, fall_velocity


def test_paper_tau_max_is_1_18_ms():
    # Appendix 10.2: tau < 4a/v = sqrt(a)/50 s with a = 3.5 mm
    assert streaks.tau_max_s() == pytest.approx(1.18e-3, abs=0.005e-3)
    assert streaks.tau_max_s() == pytest.approx(math.sqrt(3.5e-3) / 50)


def test_paper_beta_max_is_0_039_at_30_ms():
    assert round(streaks.beta_max(0.030), 3) == 0.039
    # with the typical video exposure 1/30 s the same bound is 0.035
    assert streaks.beta_max(1 / 30) == pytest.approx(0.0355, abs=0.0005)


def test_beta_max_scales_as_one_over_t():
    t = np.array([0.001, 0.004, 0.016, 0.064])
    b = np.array([streaks.beta_max(x) for x in t])
    assert np.allclose(b * t, streaks.tau_max_s())
    with pytest.raises(ValueError):
        streaks.beta_max(0.0)


@pytest.mark.parametrize("model", FALL_VELOCITY_MODELS)
def test_tau_max_grows_with_radius_under_every_law(model):
    # the bound is taken at the largest drop: 4 a / v(a) increases with a above
    # a ~ 0.4 mm, and no smaller drop exceeds its value at a = 2.9 mm
    radii = np.linspace(0.45e-3, 2.9e-3, 30)
    taus = [streaks.tau_max_s(r, model) for r in radii]
    assert np.all(np.diff(taus) > 0)
    small = np.linspace(0.1e-3, 0.45e-3, 20)
    assert max(streaks.tau_max_s(r, model) for r in small) < taus[-1]


def test_measured_laws_give_a_larger_bound_than_the_paper():
    # large drops are slower than 200 sqrt(a): the bound grows (documented in tau_max_s)
    a = 2.9e-3
    assert streaks.tau_max_s(a, "gunn_kinzer") > streaks.tau_max_s(a, "paper")
    with pytest.raises(ValueError, match="gunn_kinzer"):
        streaks.tau_max_s(3.5e-3, "gunn_kinzer")  # D = 7 mm lies beyond the table


def test_eq29_tau_and_its_bound():
    rng = np.random.default_rng(0)
    a_i = rng.uniform(0.5, 20.0, 2000)  # drops imaged wider than one pixel
    rho = rng.uniform(0, 1, 2000) * a_i
    v_i = rng.uniform(500, 20000, 2000)
    tau = streaks.tau_pixel_s(a_i, rho, v_i)
    assert np.all(tau <= (2 * a_i + 1) / v_i + 1e-15)
    assert np.all(tau < 4 * a_i / v_i)
    # centred crossing: the whole diameter plus one pixel
    assert streaks.tau_pixel_s(3.0, 0.0, 1000.0) == pytest.approx(7.0 / 1000)
    # grazing: only the pixel width
    assert streaks.tau_pixel_s(3.0, 3.5, 1000.0) == pytest.approx(1.0 / 1000)


def test_eq29_bound_is_independent_of_distance():
    # a_i = f a / z, v_i = f v / z: 4 a_i / v_i = 4 a / v for any f, z
    a, v = 1e-3, fall_velocity(2e-3, "gunn_kinzer")
    for f, z in [(3155, 1.0), (8000, 5.0), (7000, 0.3)]:
        a_i, v_i = f * a / z, f * v / z
        assert 4 * a_i / v_i == pytest.approx(streaks.tau_bound_s(a, v))


def test_eq15_integral_equals_eq16():
    t_exp, tau = 0.030, 0.0009
    e_r, e_b = 180.0, 60.0
    t = np.linspace(0, t_exp, 300001)
    start = 0.011
    e = np.where((t >= start) & (t < start + tau), e_r, e_b)
    i15 = streaks.exposure_intensity(t, e)
    i16 = streaks.motion_blurred_intensity(tau, t_exp, e_r, e_b)
    assert i15 == pytest.approx(i16, rel=1e-3)


def test_eq16_limits():
    # tau = 0: background only; tau = T: drop only
    assert streaks.motion_blurred_intensity(0.0, 0.02, 200.0, 50.0) == pytest.approx(0.02 * 50)
    assert streaks.motion_blurred_intensity(0.02, 0.02, 200.0, 50.0) == pytest.approx(0.02 * 200)
    with pytest.raises(ValueError):
        streaks.motion_blurred_intensity(0.03, 0.02, 200.0, 50.0)


def test_eq17_eq18_linear_in_background():
    rng = np.random.default_rng(1)
    t_exp = 0.016
    tau = 0.0008
    e_r = 150.0
    e_b = rng.uniform(0, 255 / t_exp, 100)
    i_b = e_b * t_exp
    d17 = streaks.delta_intensity(tau, e_r, e_b)
    b = streaks.beta(tau, t_exp)
    a = streaks.alpha(tau, e_r)
    d18 = streaks.delta_from_background(i_b, beta=b, alpha=a)
    assert np.allclose(d17, d18)
    # slope recovered by a straight-line fit equals -tau/T
    slope, intercept = np.polyfit(i_b, d17, 1)
    assert slope == pytest.approx(-tau / t_exp) and intercept == pytest.approx(tau * e_r)


def test_pixel_noise_from_rain_falls_as_one_over_sqrt_t():
    """Fig. 15(a): the visibility of rain falls as 1/sqrt(T), from Eqs. (15)-(16) and (29).

    A pixel is crossed by drops at a Poisson rate; within an exposure T each
    crossing adds tau (E_r - E_b) (Eq. 16 summed over drops), tau from Eq. (29).
    The gain keeps I_b fixed (Eq. 20: k ~ 1/T), so the normalised intensity
    is I / T.  Its standard deviation over frames scales as T^-1/2.
    """
    rng = np.random.default_rng(2)
    rate_per_s = 40.0
    e_r, e_b = 200.0, 60.0
    a_i, v_i = 2.0, 6000.0  # px, px/s
    exposures = np.array([0.004, 0.008, 0.016, 0.032, 0.064])
    sigmas = []
    for t in exposures:
        k = rng.poisson(rate_per_s * t, size=40000)
        total = k.sum()
        tau = streaks.tau_pixel_s(a_i, rng.uniform(0, a_i, total), v_i)
        frame = np.repeat(np.arange(k.size), k)
        # drops overlapping in one exposure cannot cover the pixel for longer than T
        tau_sum = np.minimum(np.bincount(frame, weights=tau, minlength=k.size), t)
        intensity = streaks.motion_blurred_intensity(tau_sum, t, e_r, e_b) / t
        sigmas.append(intensity.std())
    slope = np.polyfit(np.log(exposures), np.log(sigmas), 1)[0]
    assert slope == pytest.approx(-0.5, abs=0.03)


def test_no_streak_without_exposure_time():
    # T -> 0 limit of Eq. (18): beta = tau / T undefined; a zero-length exposure is refused
    with pytest.raises(ValueError):
        streaks.beta(1e-4, 0.0)


@pytest.mark.parametrize("bad", [0.0, -0.01, float("nan"), float("inf"), "fast"])
def test_every_exposure_argument_is_checked_the_same_way(bad):
    calls = [lambda: streaks.beta(1e-4, bad), lambda: streaks.beta_max(bad),
             lambda: streaks.motion_blurred_intensity(1e-4, bad, 100.0, 50.0)]
    for call in calls:
        with pytest.raises(ValueError, match="exposure_s must be a finite number > 0"):
            call()
