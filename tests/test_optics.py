"""Drop optics, Eqs. (5)-(14) of Garg & Nayar 2007, against the paper and a 3-D ray tracer."""

from __future__ import annotations

import numpy as np
import pytest

from raingauge.physics import optics
from raingauge.render.raytrace import Sphere, StarSurface, pinhole_rays, trace

MU = optics.MU_WATER


# ----------------------------------------------------------------------------------------
# values stated in Sec. 4.2
# ----------------------------------------------------------------------------------------

def test_field_of_view_is_about_165_degrees():
    # Sec. 4.2.2 and Fig. 8(a): "the field of view of the raindrop is approximately 165 deg"
    fov = np.degrees(optics.drop_field_of_view(MU))
    assert abs(fov - 165.0) < 1.0
    # the same number from Eq. (7) itself: the largest theta_r over the visible normals
    theta_n = np.linspace(np.pi / 2, np.pi, 100001)
    theta_r, _ = optics.refraction_mapping(theta_n, 0.0, mu=MU)
    assert abs(2 * np.degrees(theta_r.max()) - fov) < 0.01


def test_drop_transmits_about_94_percent_and_refraction_dominates():
    # Sec. 4.2.1: "a raindrop transmits 94% of the incident radiance"; Sec. 4.2.3: "only
    # attenuated by 6%" -- the disc average of the single-surface transmission 1 - k
    assert abs(optics.mean_transfer(MU, component="interface") - 0.94) < 0.01
    # at the centre both surfaces pass 96% (k = 2% at normal incidence)
    assert abs(optics.transfer_refraction(0.0, MU) - 0.96) < 0.002
    # "the radiance of the drop is mainly due to the refraction" (Fig. 5); uniform L_e = 1
    share = optics.refraction_share(MU)
    assert 0.85 < share < 0.92
    # Eq. (14) with N <= 2 accounts for nearly all the light (a lossless drop returns L_e)
    assert 0.99 < optics.mean_transfer(MU, component="total") <= 1.0
    # "specular and internal reflection are only prominent at the periphery"
    i_centre, i_rim = np.radians(20.0), np.radians(85.0)
    for comp in (optics.transfer_specular, lambda i, mu: optics.transfer_internal(i, mu, n_reflections=1)):
        assert comp(i_centre, MU) < 0.05 < comp(i_rim, MU)


def test_fresnel_is_the_mean_of_s_and_p():
    # Note 5 (slip): unpolarised reflectance is (k_s + k_p) / 2; at Brewster's angle k_p = 0
    brewster = np.arctan(MU)
    q = np.arcsin(np.sin(brewster) / MU)
    ks = (np.sin(brewster - q) / np.sin(brewster + q)) ** 2
    assert optics.fresnel_reflectance(brewster, MU) == pytest.approx(ks / 2, rel=1e-9)
    # reciprocity used to derive Eq. (9): k(q, 1/mu) = k(i, mu)
    i = np.linspace(0, np.radians(89), 50)
    q = optics.refraction_angle(i, MU)
    np.testing.assert_allclose(optics.fresnel_reflectance(q, 1 / MU), optics.fresnel_reflectance(i, MU),
                               rtol=1e-9, atol=1e-12)
    # total internal reflection from inside beyond the critical angle
    assert optics.fresnel_reflectance(np.radians(60), 1 / MU) == 1.0


def test_mu_one_reflects_nothing_and_does_not_bend():
    # limiting case: a "drop" of air is invisible
    alpha = np.radians(3.0)
    # normals the tilted camera ray can reach: incidence below 90 deg
    theta_n = np.linspace(np.pi / 2 + alpha + 0.01, np.pi, 200)
    i = optics.incidence_angle(theta_n)
    assert np.all(optics.fresnel_reflectance(i, 1.0) < 1e-12)
    assert np.all(optics.transfer_specular(i, 1.0) < 1e-12)
    assert np.all(optics.transfer_internal(i, 1.0, n_reflections=1) < 1e-12)
    np.testing.assert_allclose(optics.transfer_refraction(i, 1.0), 1.0)
    phi_n = 0.7
    r = optics.direction(*optics.refraction_mapping(theta_n, phi_n, alpha=alpha, mu=1.0))
    v = np.array([np.sin(alpha) * np.cos(phi_n), np.sin(alpha) * np.sin(phi_n), np.cos(alpha)])
    np.testing.assert_allclose(r, np.broadcast_to(v, r.shape), atol=1e-12)

    def env(d):
        return 100.0 + 50.0 * d[..., 0] - 30.0 * d[..., 2]

    L = optics.composite_radiance(theta_n, phi_n, env, alpha=alpha, mu=1.0)
    np.testing.assert_allclose(L, env(v), atol=1e-9)
    # and the 3-D tracer agrees: every pixel sees straight through
    o = np.stack([np.linspace(-0.9, 0.9, 50), np.zeros(50), np.full(50, -5.0)], axis=1)
    d = np.tile([0.0, 0.0, 1.0], (50, 1))
    res = trace(Sphere(1.0), o, d, lambda oo, dd: env(dd), mu=1.0)
    np.testing.assert_allclose(res.radiance, env(d[0]), atol=1e-9)


# ----------------------------------------------------------------------------------------
# the mappings against the 3-D tracer
# ----------------------------------------------------------------------------------------

def _exit_directions(surface, rho, phi, alpha=0.0, mu=MU):
    """Per-path exit directions and weights from the tracer, for image points (rho, phi)."""
    n = rho.size
    normal = np.stack([rho * np.cos(phi), rho * np.sin(phi), -np.sqrt(1 - rho ** 2)], axis=1)
    v = np.stack([np.sin(alpha) * np.cos(phi), np.sin(alpha) * np.sin(phi),
                  np.full(n, np.cos(alpha))], axis=1)
    origins = normal - 3.0 * v
    res = trace(surface, origins, v, lambda o, d: np.concatenate([d, np.ones((len(d), 1))], axis=1),
                mu=mu, max_internal=2)
    out = {}
    for lab, comp in res.components.items():
        w = comp[:, 3]
        out[lab] = (comp[:, :3] / np.where(w > 0, w, 1)[:, None], w)
    return out


@pytest.mark.parametrize("alpha_deg", [0.0, 4.0])
def test_mappings_and_transfer_functions_match_ray_tracer(alpha_deg):
    rng = np.random.default_rng(1)
    n = 3000
    rho = np.sqrt(rng.uniform(0.0, 0.97, n))
    phi = rng.uniform(-np.pi, np.pi, n)
    alpha = np.radians(alpha_deg)
    # the normal at the traced entry point (the ray is aimed at it)
    theta_n = np.pi - np.arcsin(rho)
    paths = _exit_directions(Sphere(1.0), rho, phi, alpha)
    i = optics.incidence_angle(theta_n, alpha)
    expected = {
        0: (optics.refraction_mapping(theta_n, phi, alpha=alpha, mu=MU), optics.transfer_refraction(i, MU)),
        -1: (optics.specular_mapping(theta_n, phi, alpha=alpha), optics.transfer_specular(i, MU)),
        1: (optics.internal_reflection_mapping(theta_n, phi, n_reflections=1, alpha=alpha, mu=MU),
            optics.transfer_internal(i, MU, n_reflections=1)),
        2: (optics.internal_reflection_mapping(theta_n, phi, n_reflections=2, alpha=alpha, mu=MU),
            optics.transfer_internal(i, MU, n_reflections=2)),
    }
    for lab, ((th, ph), weight) in expected.items():
        d_trace, w_trace = paths[lab]
        cosang = np.clip(np.sum(d_trace * optics.direction(th, ph), axis=1), -1, 1)
        assert np.degrees(np.arccos(cosang)).max() < 0.01, f"path {lab}: direction"
        np.testing.assert_allclose(w_trace, weight, atol=1e-4, err_msg=f"path {lab}: transfer")


def test_internal_reflection_azimuth_slip():
    # Eq. (12) prints phi_p = pi - phi_n; the tracer puts the exit ray at pi + phi_n
    rho = np.array([0.5, 0.8])
    phi = np.array([np.pi / 2, 1.0])
    d_trace, _ = _exit_directions(Sphere(1.0), rho, phi)[1]
    theta_p, _ = optics.internal_reflection_mapping(np.pi - np.arcsin(rho), phi, n_reflections=1, mu=MU)
    printed = optics.direction(theta_p, np.pi - phi)
    assert np.all(np.sum(d_trace * printed, axis=1) < 0.99)


def test_marching_surface_agrees_with_analytic_sphere():
    rho = np.linspace(0.0, 0.98, 40)
    phi = np.linspace(0, 2 * np.pi, 40)
    a = _exit_directions(Sphere(1.0), rho, phi)
    for march in (0, 16):
        b = _exit_directions(StarSurface(lambda u: np.ones(u.shape[:-1]), 1.0, n_march=march), rho, phi)
        for lab in (-1, 0, 1, 2):
            np.testing.assert_allclose(b[lab][0], a[lab][0], atol=1e-5)
            np.testing.assert_allclose(b[lab][1], a[lab][1], atol=1e-6)


def test_inverse_refraction_mapping_round_trip():
    theta_n = np.linspace(np.pi / 2 + 1e-3, np.pi, 300)
    theta_r, _ = optics.refraction_mapping(theta_n, 0.0, mu=MU)
    np.testing.assert_allclose(optics.normal_theta_from_refraction(theta_r, MU), theta_n, atol=1e-9)
    assert np.isnan(optics.normal_theta_from_refraction(np.radians(85.0), MU))


def test_uniform_sky_energy_is_conserved_by_the_tracer():
    # a lossless drop under a uniform sky has the sky's radiance everywhere (all paths)
    rng = np.random.default_rng(3)
    n = 2000
    rho, phi = np.sqrt(rng.uniform(0, 0.98, n)), rng.uniform(0, 2 * np.pi, n)
    o = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), np.full(n, -4.0)])
    res = trace(Sphere(1.0), o, np.tile([0, 0, 1.0], (n, 1)), lambda oo, dd: np.ones(len(dd)), mu=MU,
                max_internal=12, min_weight=1e-9)
    assert np.abs(res.radiance - 1.0).max() < 1e-3


def test_unknown_component_is_rejected():
    with pytest.raises(ValueError, match="valid"):
        optics.composite_radiance(np.pi, 0.0, lambda d: 1.0, components=("rainbow",))
    with pytest.raises(ValueError, match="valid"):
        optics.mean_transfer(component="rainbow")


# ----------------------------------------------------------------------------------------
# Fig. 6: acrylic ball (mu = 1.49, a = 0.875 in), camera 85 in away
# ----------------------------------------------------------------------------------------

A_IN, CAM_IN, MU_ACR = 0.875, 85.0, optics.MU_ACRYLIC


def _ball_rays(npx, r_img, supersample=1):
    f = r_img * CAM_IN / A_IN
    o, d = pinhole_rays((npx, npx), position=(0, 0, -CAM_IN), forward=(0, 0, 1), right=(1, 0, 0),
                        focal_length_px=f, supersample=supersample)
    return o.reshape(-1, 3), d.reshape(-1, 3), f


def test_fig6_checkerboard_corners_eq7_vs_ray_tracer():
    board_z = 6.0                          # checkerboard 6 in behind the ball's centre
    npx, r_img = 161, 75.0
    o, d, f = _ball_rays(npx, r_img)

    def board_xy(oo, dd):
        t = (board_z - oo[:, 2]) / dd[:, 2]
        p = oo + t[:, None] * dd
        ok = (t > 0) & (dd[:, 2] > 0)
        return np.stack([np.where(ok, p[:, 0], np.nan), np.where(ok, p[:, 1], np.nan),
                         np.ones(len(oo))], axis=1)

    res = trace(Sphere(A_IN), o, d, board_xy, mu=MU_ACR, max_internal=0, specular=False)
    comp = res.components[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        bx, by = comp[:, 0] / comp[:, 2], comp[:, 1] / comp[:, 2]
    ok = (res.hit & np.isfinite(bx) & np.isfinite(by)).reshape(npx, npx)
    bx, by = bx.reshape(npx, npx), by.reshape(npx, npx)
    # corners of a board of 1 in squares, 10 x 10 squares centred on the ball
    g = np.arange(-5, 6, dtype=float)
    cx_b, cy_b = (a.ravel() + 0.5 for a in np.meshgrid(g, g))
    # where the tracer images each corner: nearest traced pixel, then an affine fit of
    # board position against pixel position over its 5 x 5 neighbourhood, inverted
    rr, cc = np.nonzero(ok)
    traced = np.full((cx_b.size, 2), np.nan)
    for k, (xc, yc) in enumerate(zip(cx_b, cy_b)):
        j = np.argmin((bx[rr, cc] - xc) ** 2 + (by[rr, cc] - yc) ** 2)
        r0, c0 = rr[j], cc[j]
        win = (slice(max(r0 - 2, 0), r0 + 3), slice(max(c0 - 2, 0), c0 + 3))
        wr, wc = np.mgrid[win]
        m = ok[win]
        if m.sum() < 12:
            continue
        design = np.column_stack([wc[m], wr[m], np.ones(m.sum())])
        coef, *_ = np.linalg.lstsq(design, np.column_stack([bx[win][m], by[win][m]]), rcond=None)
        traced[k] = np.linalg.solve(coef[:2].T, np.array([xc, yc]) - coef[2])
    good = np.all(np.isfinite(traced), axis=1)
    assert good.sum() > 80
    centre = (npx - 1) / 2.0
    diameter = 2 * r_img

    # (a) Eq. (7) with the ray leaving the drop where it exits (Fig. 20(a)) and each
    #     camera ray's own alpha: tabulate image radius -> board radius along a meridian
    theta_n = np.linspace(np.pi / 2 + 1e-4, np.pi, 40001)
    bx_s, bz_s = A_IN * np.sin(theta_n), A_IN * np.cos(theta_n)
    alpha = np.arctan2(bx_s, bz_s + CAM_IN)
    rho_img = f * bx_s / (bz_s + CAM_IN)
    th_r, ph_r = optics.refraction_mapping(theta_n, 0.0, alpha=alpha, mu=MU_ACR)
    r_dir = optics.direction(th_r, ph_r)
    e = A_IN * optics.refraction_exit_point(theta_n, 0.0, alpha=alpha, mu=MU_ACR)
    valid = r_dir[:, 2] > 0
    board_r = -(e[:, 0] + (board_z - e[:, 2]) * r_dir[:, 0] / np.where(valid, r_dir[:, 2], 1))
    order = np.argsort(board_r[valid])
    corner_r = np.hypot(cx_b, cy_b)
    corner_phi = np.arctan2(cy_b, cx_b)
    rho = np.interp(corner_r, board_r[valid][order], rho_img[valid][order])
    pred = np.column_stack([centre + rho * np.cos(corner_phi + np.pi), centre + rho * np.sin(corner_phi + np.pi)])
    err = np.hypot(*(pred - traced)[good].T)
    rms_full = np.sqrt(np.mean(err ** 2)) / diameter
    assert rms_full < 0.01            # Fig. 6 I(b): "less than 1% of the diameter of the sphere"

    # (b) Eq. (7) under the paper's assumptions (orthographic, distant board): the
    #     parallax of a board 7 radii away costs a few per cent (see refraction_exit_point)
    theta_n_c = optics.normal_theta_from_refraction(np.arctan2(corner_r, board_z), MU_ACR)
    rho_c = f / CAM_IN * A_IN * np.sin(theta_n_c)
    pred_d = np.column_stack([centre + rho_c * np.cos(corner_phi + np.pi),
                              centre + rho_c * np.sin(corner_phi + np.pi)])
    err_d = np.hypot(*(pred_d - traced)[good].T)
    rms_distant = np.sqrt(np.mean(err_d ** 2)) / diameter
    assert 0.01 < rms_distant < 0.05
    assert rms_full < 0.1 * rms_distant


def test_fig6_photometry_eq9_vs_ray_tracer():
    # Fig. 6 II: the ball 9 in in front of a calibrated light box that fills its view (a plane
    # beyond the ball: only its radiance matters, the rays leaving forward all reach it)
    box_level = 230.0
    npx, r_img = 121, 55.0
    o, d, _ = _ball_rays(npx, r_img, supersample=2)

    def light_box(oo, dd):
        return np.where(dd[:, 2] > 0, box_level, 0.0)   # the box plane, radiance box_level

    def env(dirs):
        return np.where(dirs[..., 2] > 0, box_level, 0.0)

    refr = trace(Sphere(A_IN), o, d, light_box, mu=MU_ACR, max_internal=0, specular=False)
    full = trace(Sphere(A_IN), o, d, light_box, mu=MU_ACR, max_internal=8)
    hit = refr.hit.reshape(npx, npx, 4).mean(-1)
    img_refr = refr.radiance.reshape(npx, npx, 4).mean(-1)
    img_full = full.radiance.reshape(npx, npx, 4).mean(-1)

    # the model image: Eq. (6) maps pixel -> normal, Eq. (9) / Eq. (14) give the radiance
    c = (npx - 1) / 2.0
    sub = (np.arange(2) + 0.5) / 2 - 0.5
    yy, xx = np.mgrid[0:npx, 0:npx].astype(float)
    model9 = np.zeros((npx, npx))
    model14 = np.zeros((npx, npx))
    for sy in sub:
        for sx in sub:
            x, y = (xx + sx - c) / r_img, (yy + sy - c) / r_img
            rho = np.hypot(x, y)
            inside = rho < 1
            theta_n = np.pi - np.arcsin(np.clip(rho, 0, 1))
            phi_n = np.arctan2(y, x)
            model9 += np.where(inside, optics.composite_radiance(
                theta_n, phi_n, env, mu=MU_ACR, components=("refraction",)), box_level)
            model14 += np.where(inside, optics.composite_radiance(theta_n, phi_n, env, mu=MU_ACR),
                                box_level)
    model9 /= 4
    model14 /= 4
    ball = hit > 0
    rms9 = np.sqrt(np.mean((model9 - img_refr)[ball] ** 2))
    rms14 = np.sqrt(np.mean((model14 - img_full)[ball] ** 2))
    assert rms9 < 3.0                 # Fig. 6 II(d): "The RMS error is 3 gray levels"
    assert rms14 < 3.0
    # the rim is darker than the centre (Fresnel), in both
    centre_px = (slice(int(c) - 3, int(c) + 4),) * 2
    rim = ball & (np.hypot(xx - c, yy - c) > 0.9 * r_img) & (hit > 0.99)
    assert img_refr[rim].mean() < 0.8 * img_refr[centre_px].mean()
