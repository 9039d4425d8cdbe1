"""Synthetic wire generator (thesis 2.3.2): geometry, masks, determinism, distractors."""

import cv2
import numpy as np
import pytest

from geometry.camera import PinholeCamera
from perception.params import SyntheticParams
from perception.training import synthetic
from perception.training.backgrounds import Horizon, add_distractors, perspective_clouds
from perception.training.labels import label_mask, rasterise
from perception.training.loop import HELD_OUT_SEED
from perception.training.synthetic import (
    SyntheticWireDataset,
    WireBundle,
    catenary_height_m,
    composite_wires,
    horizon_anchor,
    horizon_of,
    level_view,
    rendered_sample,
    sample_bundle,
    synthetic_sample,
    wire_segments,
    with_local_contrast,
    write_dataset,
)


def level_camera(w=160, h=120, altitude_m=10.0, pitch_rad=0.0, roll_rad=0.0):
    camera = PinholeCamera(100.0, 100.0, w / 2, h / 2, w, h)
    return level_view(camera, np.array([0, 0, -altitude_m]), pitch_rad, roll_rad)


def east_wire(distance_m=20.0, height_m=10.0, diameter_m=0.4, floor_px=0.3, material="dark"):
    """Straight wire running east at `distance_m` north of the camera."""
    y = np.linspace(-200, 200, 400)
    line = np.stack([np.full_like(y, distance_m), y, np.full_like(y, -height_m)], 1)
    return WireBundle((line,), diameter_m, floor_px, material)


def render(bundle, cam, seed=0):
    grey = np.full((cam.camera.height_px, cam.camera.width_px, 3), 0.8, np.float32)
    image, mask, _ = composite_wires(
        np.random.default_rng(seed), grey, [bundle], cam, SyntheticParams()
    )
    return image, mask


def test_catenary_sag_matches_closed_form():
    span, a = 100.0, 500.0
    x = np.array([0.0, span / 2, span])
    z = catenary_height_m(x, a, span / 2)
    assert z[0] == pytest.approx(z[2])
    assert z[0] - z[1] == pytest.approx(a * (np.cosh(span / (2 * a)) - 1))


def test_horizon_of_level_and_rolled_camera():
    level = horizon_of(level_camera())
    assert level.v_center_px == pytest.approx(60.0, abs=1e-3) and level.slope == pytest.approx(
        0, abs=1e-6
    )
    nose_up = horizon_of(level_camera(pitch_rad=0.1))
    assert nose_up.v_center_px == pytest.approx(60 + 100 * np.tan(0.1), abs=1e-2)
    rolled = horizon_of(level_camera(roll_rad=0.2))
    assert abs(rolled.slope) == pytest.approx(np.tan(0.2), abs=1e-3)


def test_thick_wire_mask_matches_its_pixels():
    cam = level_camera()
    image, mask = render(east_wire(diameter_m=0.8), cam)  # 0.8 m at 20 m with fx 100: 4 px
    rows = np.nonzero(mask.any(axis=1))[0]
    assert mask.any(axis=0).all()  # labelled across the whole image
    assert 3 <= len(rows) <= 5 and abs(rows.mean() - cam.camera.cy_px) <= 1.0
    darkening = 0.8 - image.mean(axis=2)
    assert (darkening[mask > 0] > 0.2).mean() > 0.95  # labelled pixels show the wire
    assert (darkening[mask == 0] < 0.6).all()  # strongly covered pixels are labelled


def test_subpixel_wire_is_labelled_one_pixel_wide_and_drawn_faint():
    cam = level_camera()
    image, mask = render(east_wire(diameter_m=0.02, floor_px=0.35), cam)  # 0.1 px -> 0.35 floor
    per_column = mask.sum(axis=0)
    assert (per_column >= 1).all() and (per_column <= 2).all()
    darkening = 0.8 - image.mean(axis=2)
    column_max = darkening.max(axis=0)
    assert (column_max > 0.05).all() and (column_max < 0.6).all()  # visible but partial coverage
    labelled = darkening[mask > 0]
    assert (labelled > 0.02).all()


def test_wire_width_follows_depth():
    cam = level_camera()
    _, near_w, _ = wire_segments(east_wire(distance_m=10, diameter_m=0.1, floor_px=0.1), cam, 20)
    _, far_w, _ = wire_segments(east_wire(distance_m=40, diameter_m=0.1, floor_px=0.1), cam, 20)
    assert near_w.max() == pytest.approx(1.0, rel=0.02)  # fx * D / z = 100 * 0.1 / 10
    assert far_w.max() == pytest.approx(0.25, rel=0.02)


def test_poles_and_distractors_are_never_labelled():
    cam = level_camera()
    pole = (np.array([20.0, 5.0, -14.0]), np.array([20.0, 5.0, 0.0]), 0.6)
    bundle = east_wire(diameter_m=0.05)
    with_pole = WireBundle(bundle.conductors_ned_m, 0.05, 0.3, "dark", (pole,))
    image, mask = render(with_pole, cam)
    segments, widths, _ = wire_segments(bundle, cam, 12)
    coverage = rasterise(segments, widths, cam.camera.height_px, cam.camera.width_px, 4)
    assert np.array_equal(mask, label_mask(segments, coverage))
    pole_column = round(cam.camera.cx_px + 100 * 5 / 20)
    top_v = round(cam.camera.cy_px - 100 * 4 / 20)  # pole top 4 m above the camera, 20 m ahead
    assert (0.8 - image[top_v + 2 : top_v + 16, pole_column].mean(axis=1) > 0.1).all()
    assert not mask[: int(cam.camera.cy_px) - 3, pole_column].any()
    assert not mask[int(cam.camera.cy_px) + 3 :, pole_column].any()


def test_images_without_wires_have_empty_masks_despite_straight_edges():
    params = SyntheticParams(no_wire_probability=1.0)
    edges = 0
    for i in range(6):
        image, mask = synthetic_sample(5, i, 96, 128, params)
        assert not mask.any()
        edges += int((cv2.Canny(image, 50, 150) > 0).sum())
    assert edges > 0


def test_distractors_draw_strong_straight_edges():
    rng = np.random.default_rng(3)
    drawn = 0
    for _ in range(8):
        img = np.full((96, 128, 3), 0.5, np.float32)
        add_distractors(rng, img, Horizon(40.0, 0.0))
        drawn += int((np.abs(img - 0.5).max(axis=2) > 0.1).sum())
    assert drawn > 500


def test_samples_are_deterministic_and_varied():
    a_img, a_mask = synthetic_sample(11, 4, 72, 96)
    b_img, b_mask = synthetic_sample(11, 4, 72, 96)
    c_img, _ = synthetic_sample(11, 5, 72, 96)
    assert np.array_equal(a_img, b_img) and np.array_equal(a_mask, b_mask)
    assert not np.array_equal(a_img, c_img)
    assert a_img.dtype == np.uint8 and a_img.shape == (72, 96, 3)
    assert a_mask.dtype == np.uint8 and set(np.unique(a_mask)) <= {0, 1}


def test_most_samples_have_thin_wires():
    masks = [synthetic_sample(2, i, 96, 128)[1] for i in range(24)]
    with_wires = [m for m in masks if m.any()]
    assert len(with_wires) >= 16
    fraction = np.mean([m.mean() for m in with_wires])
    assert 0.001 < fraction < 0.2  # wires are a small share of the pixels, as in USF (4.9 %)


def test_dataset_items_and_rgble_channels():
    item = SyntheticWireDataset(0, 10, 48, 64, "rgble")[3]
    x, y = item
    assert tuple(x.shape) == (5, 48, 64) and tuple(y.shape) == (48, 64)
    assert y.dtype.is_floating_point is False and set(y.unique().tolist()) <= {0, 1}


def test_a_share_of_the_items_are_crops_of_labelled_frames(tmp_path):
    """`frames_share` of the items come from the frame folders, cropped (and mirrored) with
    their masks; the rest are the synthetic images they would have been."""
    frame = np.full((30, 40, 3), 200, np.uint8)
    frame[12, :, :] = 10  # a dark wire along row 12, labelled
    mask = np.zeros((30, 40), np.uint8)
    mask[12] = 255
    (tmp_path / "f").mkdir()
    cv2.imwrite(str(tmp_path / "f" / "a.png"), frame)
    cv2.imwrite(str(tmp_path / "f" / "a_mask.png"), mask)
    folders = (str(tmp_path / "f"),)
    mixed = SyntheticWireDataset(5, 200, 48, 64, frame_folders=folders, frames_share=0.5)
    sources = []
    for i in range(200):
        image, label = mixed.sample(i)
        from_frame = bool((image == 200).mean() > 0.9)  # resized up: 48/30 = 1.6 times
        sources.append(from_frame)
        if from_frame:
            rows = np.nonzero(label.any(axis=1))[0]
            assert label.dtype == np.uint8 and 1 <= len(rows) <= 3  # the wire, resized
            assert (image[rows, :, 0] < 120).mean() > 0.5  # where the label says
        else:
            np.testing.assert_array_equal(image, synthetic_sample(5, i, 48, 64)[0])
    assert 0.35 < np.mean(sources) < 0.65
    with pytest.raises(ValueError, match="no image/mask pairs"):
        SyntheticWireDataset(0, 1, 8, 8, frame_folders=(str(tmp_path),), frames_share=1.0).sample(0)


def test_write_dataset_round_trip(tmp_path):
    out = write_dataset(tmp_path / "ds", 3, 9, 40, 56)
    image, mask = synthetic_sample(9, 2, 40, 56)
    read_image = cv2.imread(str(out / "images" / "000002.png"))[..., ::-1]
    read_mask = cv2.imread(str(out / "masks" / "000002.png"), cv2.IMREAD_GRAYSCALE)
    assert np.array_equal(read_image, image)
    assert np.array_equal(read_mask > 0, mask > 0)
    assert (out / "synth.json").exists()


def test_wire_colour_keeps_a_least_contrast_to_its_background():
    background = np.full((20, 20, 3), 0.4, np.float32)
    background[:, 10:] = 0.95  # bright right half: no room to get brighter
    same = background.copy()
    out = with_local_contrast(same, background, 0.2)
    weights = np.array([0.299, 0.587, 0.114])
    diff = np.abs((out - background) @ weights)
    assert (diff[:, :7] >= 0.2 - 1e-5).all() and (diff[:, 13:] >= 0.2 - 1e-5).all()
    assert (out[:, 13:] < background[:, 13:]).all()  # pushed darker where it cannot be brighter
    dark = np.full_like(background, 0.0)
    assert np.array_equal(with_local_contrast(dark, background, 0.2)[:, :7], dark[:, :7])


def test_labels_lie_on_the_rendered_wires_and_bound_the_exact_metric():
    from perception.training.loop import coverage_ceiling_ap

    samples = [rendered_sample(HELD_OUT_SEED, i, 120, 160) for i in range(16)]
    masks = [s[1] for s in samples]
    coverages = [s[2] for s in samples]
    labelled = np.concatenate([c[m > 0] for m, c in zip(masks, coverages, strict=True)])
    assert len(labelled) > 500 and (labelled > 0).mean() > 0.99
    # an ideal detector of the rendering scores ~1 at pixel-exact matching: the label is what is
    # drawn (with centreline-only labels, a 1-px wire straddling two pixels held this to 0.87)
    assert coverage_ceiling_ap(masks, coverages) > 0.98


@pytest.mark.parametrize(
    ("row_px", "width_px", "rows"),
    [(10.0, 0.3, [10]), (10.5, 1.0, [10, 11]), (10.5, 4.0, [9, 10, 11, 12])],
)
def test_label_is_the_centreline_plus_the_pixels_the_wire_covers_at_least_half(
    row_px, width_px, rows
):
    segments = np.array([[[0.0, row_px], [39.0, row_px]]])
    coverage = rasterise(segments, np.array([width_px]), 24, 40, 4)
    mask = label_mask(segments, coverage)
    assert np.flatnonzero(mask.max(axis=1)).tolist() == rows  # sub-pixel: 1 px; straddling: both
    assert (mask[rows, 1:-1] == 1).all() and (coverage[mask == 0] < 0.5).all()


def aerial_camera(pitch_deg=-60.0, altitude_m=30.0, w=160, h=120):
    camera = PinholeCamera(90.0, 90.0, w / 2, h / 2, w, h)
    return level_view(camera, np.array([0.0, 0.0, -altitude_m]), np.deg2rad(pitch_deg), 0.05)


def test_ground_homography_maps_texture_pixels_where_the_camera_projects_them():
    from perception.training.aerial import ground_homography

    cam = aerial_camera()
    origin, res = np.array([-20.0, -35.0]), 0.1
    homography = ground_homography(
        cam.camera_from_world.rotation, cam.position_ned_m, cam.camera.intrinsic_matrix(),
        origin, res,
    )  # fmt: skip
    tex = np.array([[10.0, 20.0], [300.0, 450.0], [600.0, 100.0]])  # (tu, tv) px
    ground = np.stack([origin[0] + tex[:, 1] * res, origin[1] + tex[:, 0] * res, 0 * tex[:, 0]], 1)
    expected, depth = cam.project(ground)
    assert (depth > 0).all()
    mapped = cv2.perspectiveTransform(tex[None], homography)[0]
    np.testing.assert_allclose(mapped, expected, atol=1e-6)


def test_aerial_views_look_down_at_cluttered_ground_and_label_only_wires():
    params = SyntheticParams(aerial_probability=1.0, no_wire_probability=1.0)
    edges = 0
    for i in range(6):
        image, mask = synthetic_sample(7, i, 96, 128, params)
        assert not mask.any()  # lane markings, kerbs, roofs, rows and shadows are no wires
        edges += int((cv2.Canny(image, 50, 150) > 0).sum())
    assert edges > 6 * 96 * 128 * 0.01
    wired = SyntheticParams(aerial_probability=1.0, fittings_probability=1.0, tower_probability=1.0)
    masks = [synthetic_sample(8, i, 96, 128, wired)[1] for i in range(12)]
    assert sum(m.any() for m in masks) >= 8
    widths = [m.sum() / max(1, m.any(axis=1).sum()) for m in masks if m.any()]
    assert max(widths) > 1.5  # the aerial width floor reaches several pixels


def test_wire_shadows_darken_the_ground_but_stay_unlabelled():
    from perception.training.synthetic import draw_shadows, shadow_points

    sun = np.array([0.0, 0.6, 0.8])  # sunlight travelling east and down
    points = np.array([[5.0, 0.0, -8.0]])
    np.testing.assert_allclose(shadow_points(points, sun), [[5.0, 6.0, 0.0]])
    # an east-west wire 10 m up, 2 m north; its shadow falls 7.5 m further north (sun 53 deg
    # high from the south): 28 px from the image centre against the wire's 9 px
    cam = aerial_camera(pitch_deg=-89.0, altitude_m=30.0)
    y = np.linspace(-60, 60, 200)
    wire = np.stack([np.full_like(y, 2.0), y, np.full_like(y, -10.0)], 1)
    bundle = WireBundle((wire,), 0.05, 1.0, "dark")
    ground = np.full((120, 160, 3), 0.7, np.float32)
    shaded = ground.copy()
    sun = np.array([np.cos(0.93), 0.0, np.sin(0.93)])  # travelling north, 53 deg high
    draw_shadows(shaded, np.ones((120, 160), bool), [bundle], cam, sun, 0.6, 4)
    darker = ground.mean(axis=2) - shaded.mean(axis=2) > 0.01
    assert darker.any(axis=0).mean() > 0.9  # a faint shadow line across the image
    _, mask, _ = composite_wires(np.random.default_rng(1), shaded, [bundle], cam, SyntheticParams())
    assert mask.any(axis=0).mean() > 0.9 and (mask > 0)[darker].mean() < 0.05


def test_horizon_wires_hang_level_at_the_camera_height_along_the_horizon():
    cam = level_camera(altitude_m=3.35, roll_rad=0.05)
    horizon = horizon_of(cam)
    params = SyntheticParams()
    rng = np.random.default_rng(3)
    for _ in range(20):
        anchor = horizon_anchor(rng, params, cam)
        assert -anchor[2] == pytest.approx(3.35, abs=1e-6)
        assert 2.5 <= np.linalg.norm(anchor[:2]) <= 60.0
        uv, _ = cam.project(anchor[None])
        v_line = horizon.v_center_px + horizon.slope * (uv[0, 0] - 80)
        assert uv[0, 1] == pytest.approx(v_line, abs=0.01)
    bundles = [sample_bundle(rng, params, cam, on_horizon=True) for _ in range(30)]
    assert all(b is not None and b.on_horizon for b in bundles)
    # every conductor runs near the camera's height over the span around its anchor
    heights = [-np.median(c[:, 2]) for b in bundles for c in b.conductors_ned_m]
    assert np.median(np.abs(np.array(heights) - 3.35)) < 1.5
    looking_down = level_camera(pitch_rad=-1.2)  # the horizon above the image
    assert horizon_anchor(rng, params, looking_down) is None


def test_horizon_wire_option_labels_wires_and_leaves_other_seeds_unchanged():
    level = SyntheticParams(horizon_wire_probability=1.0, no_wire_probability=0.0)
    assert sum(synthetic_sample(11, i, 96, 128, level)[1].any() for i in range(12)) >= 10
    # no extra random draw when the option is off: earlier seeds render as before
    off = SyntheticParams(horizon_wire_probability=0.0)
    a, b = synthetic_sample(5, 1, 48, 64, off), synthetic_sample(5, 1, 48, 64)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_perspective_clouds_flatten_into_streaks_towards_the_horizon_and_stay_above_it():
    horizon = Horizon(v_center_px=150.0, slope=0.0, focal_px=160.0)

    def anisotropy(band: np.ndarray) -> float:
        """Mean vertical over mean horizontal gradient: cot(elevation) for a flat layer."""
        return float(np.abs(np.diff(band, axis=0)).mean() / np.abs(np.diff(band, axis=1)).mean())

    low, high = [], []
    for seed in range(8):
        cover = perspective_clouds(np.random.default_rng(seed), 200, 320, horizon)
        assert cover.shape == (200, 320) and cover[151:].max() == 0.0  # none below the horizon
        low.append(anisotropy(cover[122:136]))  # 5-10 deg above the horizon: cot 5.7-11
        high.append(anisotropy(cover[0:30]))  # 37-43 deg: cot 1.1-1.3
    assert np.median(low) > 3.5 and np.median(low) > 2.5 * np.median(high)


def test_ground_shadows_darken_forward_views_below_the_horizon_and_are_never_labelled(
    monkeypatch,
):
    drawn, synthetic_draw_shadows = [], synthetic.draw_shadows

    def recorded(img, ground, *args):
        before = img.copy()
        synthetic_draw_shadows(img, ground, *args)
        drawn.append((ground, before.sum(axis=2) - img.sum(axis=2) > 0.02))

    monkeypatch.setattr(synthetic, "draw_shadows", recorded)
    p = SyntheticParams(ground_shadow_probability=1.0, photo_probability=0.0, no_wire_probability=0)
    darker_px, labelled_px = 0, 0
    for i in range(16):
        _, mask, _ = rendered_sample(3, i, 96, 128, p)
        ground, dark = drawn[-1]
        assert not dark[~ground].any()  # only the ground below the horizon is shaded
        darker_px += int(dark.sum())
        labelled_px += int((dark & (mask > 0)).sum())
    assert len(drawn) == 16 and darker_px > 300 and labelled_px < 0.1 * darker_px
    # no extra random draw when both options are off: earlier seeds render as before
    a = synthetic_sample(5, 2, 48, 64, SyntheticParams(perspective_cloud_probability=0.0))
    b = synthetic_sample(5, 2, 48, 64)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
