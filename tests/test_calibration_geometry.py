"""Geometric calibration against checkerboards rendered through a known camera."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.geometry import (
    GeometryQualityError,
    calibrate_geometry,
    calibrate_views,
    find_corners,
    parse_pattern,
    read_views,
)
from calibration.synthetic import render_checkerboard_views
from raingauge.errors import InputError, RaingaugeError

TRUE_F = 480.0
DIST = (-0.12, 0.05, 0.0005, -0.0004, 0.0)


@pytest.fixture(scope="module")
def views():
    images, truth = render_checkerboard_views(n_views=8, image_size=(400, 300), focal_length_px=TRUE_F,
                                              distortion=DIST, seed=3)
    return images, truth


def test_corners_found_where_the_camera_projects_them(views):
    images, truth = views
    for img, true_corners in zip(images[:3], truth["corners_px"][:3]):
        corners = find_corners(img, (9, 6))
        assert corners is not None
        err = np.linalg.norm(corners.reshape(-1, 2) - true_corners, axis=1)
        assert np.sqrt(np.mean(err ** 2)) < 0.2  # sub-pixel
        assert err.max() < 0.5


def test_recovers_focal_length_principal_point_and_distortion(views):
    images, truth = views
    res = calibrate_views([(f"v{i}", im) for i, im in enumerate(images)], (9, 6), 0.025)
    assert res.focal_length_px == pytest.approx(TRUE_F, rel=0.01)
    assert res.fx_px == pytest.approx(TRUE_F, rel=0.01)
    assert res.fy_px == pytest.approx(TRUE_F, rel=0.01)
    assert np.allclose(res.principal_point_px, truth["principal_point_px"], atol=4.0)
    assert res.distortion[0] == pytest.approx(DIST[0], abs=0.03)  # k1
    assert res.rms_px < 0.3
    assert res.image_size == (400, 300)
    assert len(res.views_used) == 8 and not res.views_rejected
    # The reported uncertainty covers the actual error.
    assert abs(res.focal_length_px - TRUE_F) < 4 * res.focal_length_std_px + 0.5
    text = res.summary()
    assert "focal length" in text and "RMS reprojection" in text


def test_too_few_views_says_how_many_more(views):
    images, _ = views
    with pytest.raises(GeometryQualityError) as exc:
        calibrate_views([(f"v{i}", im) for i, im in enumerate(images[:3])], (9, 6), 0.025)
    msg = str(exc.value)
    assert "only 3" in msg and "7 more views" in msg and "tilted" in msg


def test_square_on_views_do_not_determine_f():
    images, _ = render_checkerboard_views(n_views=6, image_size=(400, 300), focal_length_px=TRUE_F,
                                          max_tilt_deg=2.0, seed=5)
    with pytest.raises(GeometryQualityError, match="tilted"):
        calibrate_views([(f"v{i}", im) for i, im in enumerate(images)], (9, 6), 0.025)


def test_pattern_not_found_names_the_pattern(views, tmp_path):
    images, _ = views
    for i, im in enumerate(images[:5]):
        cv2.imwrite(str(tmp_path / f"v{i}.png"), im)
    with pytest.raises(GeometryQualityError, match="7x5 checkerboard pattern was not found"):
        calibrate_geometry(tmp_path, "7x5", 0.025)


def test_folder_and_video_sources(views, tmp_path):
    from raingauge.videoio import FrameWriter

    images, _ = views
    folder = tmp_path / "views"
    folder.mkdir()
    for i, im in enumerate(images):
        cv2.imwrite(str(folder / f"v{i:02d}.png"), im)
    res = calibrate_geometry(folder, "9x6", 0.025)
    assert res.focal_length_px == pytest.approx(TRUE_F, rel=0.01)
    video = tmp_path / "views.mkv"
    writer = FrameWriter(video, fps=5.0)
    for im in images:
        writer.write(im)
    writer.close()
    got = read_views(video)
    assert len(got) == len(images)
    assert calibrate_views(got, (9, 6), 0.025).focal_length_px == pytest.approx(TRUE_F, rel=0.01)


def test_unreadable_image_is_named(views, tmp_path):
    images, _ = views
    cv2.imwrite(str(tmp_path / "a.png"), images[0])
    (tmp_path / "b.png").write_bytes(b"not an image at all")
    with pytest.raises(InputError, match="b.png: cannot be read"):
        read_views(tmp_path)


def test_empty_or_missing_folder(tmp_path):
    with pytest.raises(InputError, match="no images"):
        read_views(tmp_path)
    with pytest.raises(InputError, match="no such folder"):
        read_views(tmp_path / "nope")


@pytest.mark.parametrize("text", ["9", "9x", "axb", "2x5", "6x6"])
def test_bad_patterns_are_rejected(text):
    with pytest.raises(RaingaugeError, match="pattern"):
        parse_pattern(text)


def test_pattern_parsing():
    assert parse_pattern("9x6") == (9, 6)
    assert parse_pattern(" 7 X 5 ") == (7, 5)


def test_live_capture_keeps_distinct_views(views, tmp_path):
    """capture_views reads any OpenCV source; a video stands in for the camera here."""
    from calibration.geometry import capture_views
    from raingauge.videoio import FrameWriter

    images, _ = views
    video = tmp_path / "live.mkv"
    writer = FrameWriter(video, fps=10.0)
    for im in images:
        for _ in range(3):  # the board held still for three frames
            writer.write(cv2.cvtColor(im, cv2.COLOR_GRAY2BGR))
    writer.close()
    seen = []
    got = capture_views(str(video), (9, 6), n_views=20, on_view=lambda k, n: seen.append(k))
    assert 5 <= len(got) <= len(images)  # repeated frames of one pose are kept once
    assert seen == list(range(1, len(got) + 1))
    assert calibrate_views(got, (9, 6), 0.025).focal_length_px == pytest.approx(TRUE_F, rel=0.01)
