"""Is the completeness probe faithful?  Its drops against the same drops in the video.

The probe (:class:`raingauge.gauge.completeness.CompletenessProbe`) corrects the sample
volume by what the gauge makes of artificial drops added to copies of its frames; the
correction is only as good as those drops are like the real ones.  :func:`probe_fidelity`
renders, into a simulated rain clip, extra drops of one radius a at one depth z (in every
frame, anywhere in it, composed over the frame's linear intensity before the sensor's
noise and rounding, as the simulator composes its rain), pins the probe to the same a
and z (:meth:`CompletenessProbe.pin`) and returns the shares of each the gauge counted,
and the rain it credits each with on average ((2 a_m)^3 v_m / kappa(a_m) at its measured
size and speed, 0 when not counted: what the probe's ratio sums).  Where the probe is
faithful the two agree within their scatter: both are the same chance, that the gauge
counts a drop of that size at that depth in that scene, and the same measurement of it.  The extra drops are part of the scene's rain, in frames n - 1 and n + 1
too, for the probe's drops as for one another: placed only in every second frame, they
would hide the probe's drops (of frames between theirs) from the three-frame test and
never one another.

``benchmarks/diag_probe_fidelity.py`` prints it for chosen sizes and depths.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["scatter", "probe_fidelity"]


def scatter(shape, n: int, length_px: float, radius_px: float, rng, *, edge_px: float = 12.0) -> np.ndarray:
    """Centres (x, y) [px] of ``n`` vertical streaks of ``length_px`` and ``radius_px``, each
    anywhere in the frame with ``edge_px`` to spare at its edge (uniformly, independently:
    they may overlap, as drops of the rain do)."""
    m, w = shape
    hx = radius_px + edge_px
    hy = 0.5 * length_px + radius_px + edge_px
    if not (w > 2 * hx and m > 2 * hy):
        raise ValueError(f"a streak of {length_px:.1f} x {2 * radius_px:.1f} px does not fit a {w}x{m} frame")
    return np.column_stack([rng.uniform(hx, w - hx, int(n)), rng.uniform(hy, m - hy, int(n))])


def probe_fidelity(profile, *, radius_m: float, depth_m: float, background: str = "ramp:150:190",
                   motion: str | None = None, drop_brightness_dn: float = 250.0, rain_rate_mm_h: float = 2.0,
                   dsd: str | None = "gamma", dsd_params: dict | None = None, seconds: float = 30.0,
                   seed: int = 12, given_brightness: bool = True, coverage: float = 0.01, wind_m_s: float = 0.0) -> dict:
    """The shares of extra drops and of the probe's drops of one radius and depth the
    gauge counted, in one simulated clip (module docstring).

    Parameters
    ----------
    profile : CameraProfile
        A linear camera (the extra drops are composed in linear intensity).
    radius_m, depth_m : float
        The drops' radius a [m] and depth z [m].
    background, motion : str
        The clip's scene and moving objects (:func:`raingauge.render.simulator.simulate`).
    drop_brightness_dn : float
        E_r of the clip's drops and of the extra ones [gray levels].
    rain_rate_mm_h, dsd, dsd_params :
        The clip's rain (``dsd_params`` defaults to mu = 3 for the gamma spectrum).
    seconds : float
        Length of the clip [s].
    seed : int
        Seed of the clip and of the extra drops.
    given_brightness : bool
        Give the gauge E_r (its own estimate leans on the focus of the streaks it sees,
        and many drops of one size and depth move it).
    coverage : float
        Share of the frame the extra drops' streaks cover, with a 3 px border each [-]
        (sets how many there are per frame).
    wind_m_s : float
        Cross wind of the clip [m/s] (to image right): the clip's drops and the extra ones
        drift with it, each extra streak slanted by f u T / z over its length f v T / z.

    Returns
    -------
    dict: ``real`` (the extra drops) and ``probe``, each (counted, total); ``real_share``
    and ``probe_share``, each (mean, standard error) of the rain credited per drop
    [m^4/s / (m^3/px^2)]; ``model_p`` the
    model's pass probability averaged over the probe's drops; ``drop_brightness_dn`` the
    gauge's E_r; ``radius_px`` and ``length_px`` of the streak; ``focus_streaks`` and
    ``focus_probe``, each (percentile fixed point, median, count) of the photometric focus
    q': of the gauge's latest brightness samples (the extra drops' streaks, with the clip's
    own rain, measured against ``drop_brightness_dn``) and of the probe's latest drops
    (against the E_r they were drawn with), the two sets the drop brightness is estimated
    from (:func:`raingauge.gauge.gauge.drop_brightness_dn`); ``rejections`` the gauge's
    count of the streaks of the video (the extra drops and the clip's rain) each test
    turned away (:attr:`RainGauge.rejections`).  An extra drop is counted when a
    counted drop of its frame lies within the streak's radius + 3 px across and a quarter
    of its length + 3 px along from its centre (and a quarter of its slant more across).
    """
    from raingauge.gauge.gauge import RainGauge
    from raingauge.gauge.volume import _pitch, whole_streak_area_px2
    from raingauge.physics.camera import blur_circle_px
    from raingauge.physics.drops import fall_velocity
    from raingauge.render.simulator import compose_rain, render_streaks, simulate

    if not profile.is_linear:
        raise ValueError("probe_fidelity composes its drops in linear intensity: give a linear camera profile")
    m, n = profile.shape
    f = profile.focal_length_px
    a, z = float(radius_m), float(depth_m)
    v = float(fall_velocity(2.0 * a))
    a_i = f * a / z
    blur = float(blur_circle_px(z, focal_length_px=f, f_number=profile.f_number,
                                focus_distance_m=profile.focus_distance_m, pixel_pitch_m=_pitch(profile)))
    r = 0.5 * (max(2.0 * a_i, 1.0) + blur)
    length = f * v * profile.exposure_s / z
    dx = f * float(wind_m_s) * profile.exposure_s / z
    per_frame = max(1, int(round(coverage * m * n / ((2.0 * r + 6.0) * (length + 2.0 * r + 6.0)))))
    if dsd == "gamma" and dsd_params is None:
        dsd_params = {"mu": 3.0}
    sim = simulate(profile, seconds=seconds, seed=seed, background=background, motion=motion,
                   drop_brightness_dn=drop_brightness_dn, rain_rate_mm_h=rain_rate_mm_h, dsd=dsd,
                   dsd_params=dsd_params, truth_linear=True, truth_drops=False, wind_m_s=wind_m_s)
    g = RainGauge(profile, window_s=seconds, step_s=seconds, keep_drops=True,
                  drop_brightness_dn=drop_brightness_dn if given_brightness else None)
    if g.probe is None:
        raise ValueError("the gauge runs without the completeness probe for this profile")
    g.probe.pin(a, z)
    g.probe.outcomes = []
    rng = np.random.default_rng(seed + 1)
    noise = float(profile.noise_sigma_dn)
    fps = profile.frame_rate_hz
    placed = {}
    for k, (_frame, ft) in enumerate(sim):
        c = scatter((m, n), per_frame, length, r + 0.5 * abs(dx), rng)
        half = np.array([0.5 * dx, 0.5 * length])
        beta, _ = render_streaks((m, n), c - half, c + half, np.full(len(c), r), np.full(len(c), math.pi * a_i ** 2))
        lin = compose_rain(ft["linear"], beta, drop_brightness_dn=drop_brightness_dn)
        placed[k] = c
        # the simulator's sensor of a linear camera: noise, then rounding to 8 bits
        frame = np.clip(np.rint(lin + noise * rng.standard_normal(lin.shape)), 0, 255).astype(np.uint8)
        g.process(frame, t_s=k / fps)
    g.flush()
    found = {}
    for d in g.drops:
        # the drop's share of the rate as the probe credits it, (2 a_m)^3 v_m / kappa(a_m):
        # its weight is 1 / (kappa c A_R / Delta) (c the probe's correction, A_R / Delta the
        # whole-streak area per frame period)
        area = float(whole_streak_area_px2(np.array([d["ux"] * profile.exposure_s, d["motion_px"]]),
                                           d["apparent_width_px"], profile.shape)) / g._frame_interval
        share = d["diameter_m"] ** 3 * d["velocity_m_s"] * d["weight_s_m3"] * d["probe_correction"] * area
        found.setdefault(int(round(d["t"] * fps)), []).append((d["x"], d["y"], share))
    hits = total = 0
    real_shares = []
    for k, c in placed.items():
        total += len(c)
        got = np.array(found.get(k, []), dtype=float).reshape(-1, 3)
        shares = np.zeros(len(c))
        if got.size:
            near = ((np.abs(got[None, :, 0] - c[:, None, 0]) <= r + 3.0 + 0.25 * abs(dx))
                    & (np.abs(got[None, :, 1] - c[:, None, 1]) <= 0.25 * length + 3.0))
            hits += int(near.any(axis=1).sum())
            shares = (near * got[None, :, 2]).sum(axis=1)
        real_shares.append(shares)
    real_shares = np.concatenate(real_shares) if real_shares else np.zeros(0)
    out = np.array([(counted, p, e) for _a, _z, counted, p, e in g.probe.outcomes], dtype=float).reshape(-1, 3)
    # the photometric focus q' of the streaks' brightness samples against the clip's E_r (each
    # over its own background), and of the probe's drops against the E_r they were drawn with
    backgrounds, samples = g._brightness.arrays()
    with np.errstate(all="ignore"):
        q_streaks = (samples - backgrounds) / np.maximum(drop_brightness_dn - backgrounds, 1.0)
    q_probe = g._probe_focus.arrays()[0]
    return {"real": (hits, total), "probe": (int(out[:, 0].sum()), len(out)),
            "real_share": _mean_se(real_shares), "probe_share": _mean_se(out[:, 2]),
            "model_p": float(out[:, 1].mean()) if len(out) else math.nan,
            "drop_brightness_dn": float(g.drop_brightness_estimate_dn), "radius_px": r, "length_px": length,
            "focus_streaks": _focus_summary(q_streaks, g.volume.q_min),
            "focus_probe": _focus_summary(q_probe, g.volume.q_min),
            "rejections": dict(g.rejections)}


def _focus_summary(q, q_min: float) -> tuple[float, float, int]:
    """(the fixed point of the percentile E_r is taken at, the median, the count) of focus
    values q' [-] (NaN, NaN, 0 without any)."""
    from raingauge.gauge.gauge import BRIGHTNESS_PERCENTILE, focus_percentile

    q = np.asarray(q, dtype=float)
    q = q[np.isfinite(q)]
    if q.size == 0:
        return math.nan, math.nan, 0
    return (float(focus_percentile(q, q_min=q_min, percentile=BRIGHTNESS_PERCENTILE)), float(np.median(q)),
            int(q.size))


def _mean_se(x) -> tuple[float, float]:
    """Mean and its standard error [same units]."""
    x = np.asarray(x, dtype=float)
    if x.size < 2:
        return math.nan, math.nan
    return float(x.mean()), float(x.std(ddof=1) / math.sqrt(x.size))
