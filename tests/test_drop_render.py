"""The world in a drop (Sec. 4.2.2, Fig. 7): rendering a drop from an environment map and undoing it."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from raingauge.cli import main
from raingauge.physics import optics
from raingauge.render import drop as dr

GRID = 0.4          # spacing of the lines on the plane z = 1 [-]
HALF_WIDTH = 0.03   # half width of a line [-]


def _line_plane(dirs):
    """Scene: a plane z = 1 behind the drop ruled with dark straight lines; grey behind the camera."""
    z = dirs[..., 2]
    zz = np.where(z > 0, z, 1.0)
    x, y = dirs[..., 0] / zz, dirs[..., 1] / zz
    on = (np.abs(x - np.round(x / GRID) * GRID) < HALF_WIDTH) | (np.abs(y - np.round(y / GRID) * GRID) < HALF_WIDTH)
    return np.where(z > 0, np.where(on, 30.0, 200.0), 120.0)


@pytest.fixture(scope="module")
def line_env():
    return _line_plane(dr.equirect_directions(768, 1536))


@pytest.fixture(scope="module")
def drop_in_canvas(line_env):
    size = 201
    img, cov = dr.render_drop(line_env, size_px=size, supersample=2)
    canvas = np.full((size + 120, size + 170), 60.0, np.float32)
    r0, c0 = 50, 90
    canvas[r0:r0 + size, c0:c0 + size] = img * cov + (1 - cov) * 60.0
    return canvas, (c0 + (size - 1) / 2.0, r0 + (size - 1) / 2.0, size / 2.0)


def test_model_render_matches_ray_tracer(line_env):
    for alpha in (0.0, np.radians(20.0)):
        model, cov = dr.render_drop(line_env, size_px=61, alpha_rad=alpha, azimuth_rad=0.4)
        traced, _ = dr.render_drop(line_env, size_px=61, alpha_rad=alpha, azimuth_rad=0.4, method="raytrace")
        inside = cov > 0.99
        assert np.sqrt(np.mean((model - traced)[inside] ** 2)) < 0.5      # gray levels of 0..200
        assert np.abs(model - traced)[inside].max() < 3.0


def test_centre_of_drop_sees_straight_behind_it_along_the_view(line_env):
    # Eq. (7): at the centre of the drop's image theta_r = 0: the scene along the viewing ray
    env = np.zeros((90, 180))
    env[40:50, 100:110] = 100.0          # a bright patch at lon ~ +22 deg, lat ~ 0
    dirs = dr.equirect_directions(90, 180)
    target = dirs[45, 105]
    alpha = np.arccos(target[2])
    azimuth = np.arctan2(target[1], target[0])
    img, _ = dr.render_drop(env, size_px=41, alpha_rad=alpha, azimuth_rad=azimuth,
                            components=("refraction",))
    assert img[20, 20] == pytest.approx(100.0 * optics.transfer_refraction(0.0), rel=0.02)
    straight, _ = dr.render_drop(env, size_px=41, components=("refraction",))
    assert straight[20, 20] < 1.0


def test_render_is_resolution_independent(line_env):
    means = []
    for size in (31, 63, 127):
        img, cov = dr.render_drop(line_env, size_px=size, supersample=3)
        means.append(img[cov > 0.99].mean())
    assert np.ptp(means) < 0.03 * np.mean(means)


def test_find_drop_locates_the_drop(drop_in_canvas):
    canvas, (cx, cy, r) = drop_in_canvas
    fx, fy, fr = dr.find_drop(canvas)
    assert abs(fx - cx) < 1.0 and abs(fy - cy) < 1.0
    assert abs(fr - r) < 0.01 * r + 0.5


def test_round_trip_recovers_perspective_view_with_straight_lines(line_env, drop_in_canvas):
    canvas, (cx, cy, r) = drop_in_canvas
    size, fov = 121, 70.0
    view = dr.drop_to_perspective(canvas, center_xy=(cx, cy), radius_px=r, fov_deg=fov, size_px=size)
    truth = dr.perspective_view(line_env, fov_deg=fov, size_px=size)
    c = (size - 1) / 2.0
    yy, xx = np.mgrid[0:size, 0:size]
    central = np.hypot(xx - c, yy - c) < 0.35 * size
    # recovered view matches the environment (Fresnel-flattened; specular/internal add a little)
    assert np.median(np.abs(view - truth)[central]) < 12.0
    assert np.corrcoef(view[central], truth[central])[0, 1] > 0.85
    # a vertical scene line at x = GRID on the plane: straight in the recovered view
    f = (size / 2.0) / np.tan(np.radians(fov) / 2.0)
    col_line = c + f * GRID
    # rows between the horizontal lines at y = -GRID and +GRID (crossings excluded)
    rows = np.arange(int(c - f * GRID + 5), int(c + f * GRID - 4))
    cols = np.arange(int(col_line - 8), int(col_line + 9))

    def line_centres(img):
        band = img[np.ix_(rows, cols)]
        dark = np.clip(band.max(axis=1, keepdims=True) - band, 0, None)
        # skip the rows near the horizontal line y = 0 that crosses the band
        crossing = np.abs(rows - c) < 7
        return (dark * cols).sum(1) / dark.sum(1), ~crossing

    cent, use = line_centres(view)
    assert use.sum() > 0.6 * use.size
    rows, cent = rows[use], cent[use]
    fit = np.polyval(np.polyfit(rows, cent, 1), rows)
    assert np.sqrt(np.mean((cent - fit) ** 2)) < 0.5
    assert abs(np.mean(cent) - col_line) < 1.0
    # whereas in the drop's own image (Eq. 7) the same stretch of line is bent by pixels
    ys = np.linspace(-GRID, GRID, 41)
    theta_r = np.arctan(np.hypot(GRID, ys))
    rho = r * np.sin(optics.normal_theta_from_refraction(theta_r, optics.MU_WATER))
    phi = np.arctan2(ys, GRID) + np.pi
    px, py = rho * np.cos(phi), rho * np.sin(phi)
    sagitta = np.abs(px - np.polyval(np.polyfit(py, px, 1), py)).max()
    assert sagitta > 2.0


def test_drop_view_cli(tmp_path, drop_in_canvas, capsys):
    canvas, (cx, cy, r) = drop_in_canvas
    src = tmp_path / "drop.png"
    cv2.imwrite(str(src), np.clip(canvas, 0, 255).astype(np.uint8))
    out = tmp_path / "view.png"
    assert main(["drop-view", str(src), "--out", str(out), "--fov", "80"]) == 0
    img = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert img is not None and img.shape[0] == img.shape[1] and abs(img.shape[0] - 2 * r) <= 2
    assert "found at" in capsys.readouterr().out
    out2 = tmp_path / "view2.png"
    assert main(["drop-view", str(src), "--out", str(out2), "--center", f"{cx}", f"{cy}",
                 "--radius", f"{r}", "--size", "64"]) == 0
    assert cv2.imread(str(out2), cv2.IMREAD_UNCHANGED).shape == (64, 64)
    # colour and 16-bit images keep their channels and depth
    colour = tmp_path / "drop_rgb.png"
    cv2.imwrite(str(colour), np.dstack([np.clip(canvas, 0, 255).astype(np.uint8)] * 3))
    assert main(["drop-view", str(colour), "--out", str(out2), "--size", "48"]) == 0
    assert cv2.imread(str(out2), cv2.IMREAD_UNCHANGED).shape == (48, 48, 3)
    deep = tmp_path / "drop16.png"
    cv2.imwrite(str(deep), (np.clip(canvas, 0, 255) * 257).astype(np.uint16))
    assert main(["drop-view", str(deep), "--out", str(out2), "--size", "48"]) == 0
    assert cv2.imread(str(out2), cv2.IMREAD_UNCHANGED).dtype == np.uint16


@pytest.mark.parametrize("args, message", [
    (["missing.png"], "not found"),
    (["drop.png", "--center", "10", "10"], "together"),
    (["drop.png", "--fov", "170"], "field of view"),
    (["flat.png"], "--center"),
    (["drop.png", "--center", "5000", "10", "--radius", "20"], "outside"),
])
def test_drop_view_cli_bad_input(tmp_path, drop_in_canvas, capsys, args, message):
    canvas, _ = drop_in_canvas
    cv2.imwrite(str(tmp_path / "drop.png"), np.clip(canvas, 0, 255).astype(np.uint8))
    cv2.imwrite(str(tmp_path / "flat.png"), np.full((50, 50), 7, np.uint8))
    argv = ["drop-view", str(tmp_path / args[0]), *args[1:], "--out", str(tmp_path / "o.png")]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_unknown_render_method_is_rejected(line_env):
    with pytest.raises(ValueError, match="valid"):
        dr.render_drop(line_env, size_px=9, method="pathtrace")


@pytest.mark.parametrize("args, message", [
    (["."], "is a folder"),
    (["garbage.png"], "cannot decode"),
    (["drop.png", "--out", "{tmp}/o.xyz"], "no image of that extension"),
    (["drop.png", "--out", "{tmp}/missing/o.png"], "does not exist"),
    (["drop.png", "--fov", "abc"], "invalid float value: 'abc'"),
    (["drop.png", "--mu", "0.5"], "--mu"),
    (["drop.png", "--size", "3"], "--size"),
    (["drop.png", "--center", "30", "30", "--radius", "0"], "--radius"),
])
def test_drop_view_cli_refuses_before_writing(tmp_path, cli_error, args, message):
    cv2.imwrite(str(tmp_path / "drop.png"), np.full((40, 40), 90, np.uint8))
    (tmp_path / "garbage.png").write_bytes(b"not an image")
    rest = [a.format(tmp=tmp_path) for a in args[1:]]
    if "--out" not in rest:
        rest += ["--out", str(tmp_path / "o.png")]
    cli_error(["drop-view", tmp_path / args[0], *rest], message)
    assert not list(tmp_path.glob("o.*"))
