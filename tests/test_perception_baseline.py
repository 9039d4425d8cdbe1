"""Candamo baseline (thesis 2.4.3) and the 4.4.1 post-processing it shares code with."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from perception.baseline import (
    candamo_scores,
    filtered_edges,
    lsd_scores,
    rasterised_lines,
    window_lines,
)
from perception.metrics import evaluate_predictions
from perception.params import PerceptionParams
from perception.postprocess import (
    continued_wires,
    remove_small_components,
    stereo_surface,
    wire_mask,
)


def test_small_8_connected_components_are_removed():
    binary = np.zeros((10, 12), bool)
    binary[1, 1:4] = True  # 3 px
    for i in range(5):  # a 5-px diagonal chain: one component only with 8-connectivity
        binary[4 + i, 2 + i] = True
    binary[2:5, 9:12] = True  # 9 px block
    kept = remove_small_components(binary, 5)
    assert kept[4:9, 2:7].trace() == 5 and kept[2:5, 9:12].all()
    assert not kept[1].any()
    np.testing.assert_array_equal(remove_small_components(binary, 0), binary)
    assert not remove_small_components(binary, 10).any()


def test_wire_mask_thresholds_at_095_and_drops_speckles():
    prob = np.zeros((20, 30), np.float32)
    prob[5, :] = 0.95  # a 30-px wire exactly at the threshold: kept ("< 0.95" is removed)
    prob[10, :] = 0.949  # just below
    prob[15, 3:6] = 1.0  # 3-px speckle
    mask = wire_mask(prob, PerceptionParams())
    expected = np.zeros_like(mask)
    expected[5] = True
    np.testing.assert_array_equal(mask, expected)
    low = wire_mask(prob, PerceptionParams(confidence_threshold=0.9, min_wire_component_px=0))
    assert low[10].all() and low[15, 3:6].all()


def test_a_straight_wire_found_in_part_is_continued_past_both_ends():
    mask = np.zeros((60, 200), bool)
    cv2.line(mask.view(np.uint8), (80, 30), (119, 35), 1, 2)  # 40 px, 7 degrees, 2 px thick
    mask[5:50, 20] = True  # a ladder rail: vertical, not a wire crossing the path
    mask[45, 150:160] = True  # too short to say which way it runs
    continued = continued_wires(mask, 30.0, 30.0, 1.0)
    assert (continued >= mask).all()
    added = continued & ~mask
    cols = np.nonzero(added.any(axis=0))[0]
    assert 34 <= cols.min() <= 42 and 157 <= cols.max() <= 165  # one length on each side
    rows = np.nonzero(added[:, 45])[0]  # on the line's extension: 30 - 35 * 5 / 39 = 25.5
    assert 24.5 <= rows.mean() <= 26.5 and len(rows) <= 5  # about as thick as found
    assert not added[:, :30].any()  # not the rail, not the speckle: only the line
    assert not added[44:47, 140:].any()
    far = continued_wires(mask, 30.0, 30.0, 10.0)  # clipped at the border
    assert far[:, 0].any() and far[:, -1].any() and far.shape == mask.shape
    np.testing.assert_array_equal(continued_wires(mask, 30.0, 30.0, 0.0), mask)
    np.testing.assert_array_equal(continued_wires(mask, 30.0, 5.0, 1.0), mask)  # too steep
    np.testing.assert_array_equal(continued_wires(mask, 50.0, 30.0, 1.0), mask)  # too short


def test_a_continuation_stops_where_stereo_sees_a_surface():
    """The shadow of a pole on the ground, marked by the CNN, is not drawn on across the
    ground; a wire against the sky is continued as before (to the border)."""
    mask = np.zeros((60, 200), bool)
    mask[10, 80:120] = True  # a wire against the sky
    cv2.line(mask.view(np.uint8), (80, 40), (119, 50), 1, 1)  # a shadow on the ground, 14 deg
    disparity = np.zeros((120, 400), np.float32)  # 2x the mask: sky, no return
    disparity[60:] = 3.0  # the ground below row 30 of the mask: returns
    disparity[60:62, ::7] = np.nan  # a few texture-less pixels do not make it sky
    disparity[20, 300] = 3.0  # nor does a stray return make the sky a surface
    surface = stereo_surface(disparity, mask.shape)
    assert surface[30:].all() and not surface[:30].any()
    gated = continued_wires(mask, 30.0, 30.0, 4.0, surface)
    free = continued_wires(mask, 30.0, 30.0, 4.0)
    assert gated[10].all() and free[10].all()  # the sky wire reaches both borders
    shadow = gated[30:] & ~mask[30:]
    assert shadow.sum() <= 3 and free[30:].sum() > mask[30:].sum() + 60
    with pytest.raises(ValueError, match="integer up-scale"):
        stereo_surface(disparity[:, :399], mask.shape)


def test_rasterised_lines_give_one_score_level_per_thickness():
    lines = np.array([[10.0, np.pi / 2]], np.float32)  # y = 10, horizontal
    scores = rasterised_lines((21, 30), lines, max_thickness_px=5)
    assert scores[10].min() == pytest.approx(1.0)  # covered by the 1-px line
    assert np.count_nonzero(scores[:, 15] >= 1.0) == 1
    # thresholding at level (T + 1 - t) / T reproduces the t-px-thick rasterisation
    canvas = np.zeros((21, 30), np.uint8)
    cv2.line(canvas, (-100, 10), (100, 10), 1, 3)
    np.testing.assert_array_equal(scores >= 0.6 - 1e-6, canvas > 0)
    levels = np.unique(scores)
    np.testing.assert_allclose(levels, np.round(levels * 5) / 5, atol=1e-6)


def wire_scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """RGB image: smooth noisy gradient with a thin dark straight wire, and its 1-px mask."""
    rng = np.random.default_rng(seed)
    h, w = 240, 320
    grad = np.linspace(120, 200, w)[None, :, None] * np.ones((h, 1, 3))
    image = np.clip(grad + rng.normal(0, 4, (h, w, 3)), 0, 255).astype(np.uint8)
    mask = np.zeros((h, w), np.uint8)
    cv2.line(mask, (0, 60), (319, 170), 1, 1)
    image[mask > 0] = 40
    return image, mask


def test_baseline_finds_a_straight_wire_in_every_window_it_crosses():
    image, mask = wire_scene()
    params = PerceptionParams()
    near_edges = cv2.dilate(filtered_edges(image, params).astype(np.uint8), np.ones((3, 3)))
    assert near_edges[mask > 0].mean() > 0.9
    scores = candamo_scores(image, params)
    assert scores.shape == mask.shape and scores.dtype == np.float32
    relaxed = evaluate_predictions([scores], [mask], tolerance_px=2)
    assert relaxed.ods_f1 > 0.6
    # noise-only edges are removed by the 30-px component filter: nothing far from the wire
    far = cv2.dilate(mask, np.ones((15, 15), np.uint8)) == 0
    assert scores[far].max() == 0.0


def test_baseline_on_a_flat_image_and_single_window():
    flat = np.full((64, 64, 3), 128, np.uint8)
    assert not candamo_scores(flat).any()
    image, _ = wire_scene(1)
    one_window = PerceptionParams(baseline_windows=1)
    lines = window_lines(filtered_edges(image, one_window), one_window)
    assert 1 <= len(lines) <= one_window.baseline_max_lines_per_window
    # the wire direction: y = 60 + 110/319 x -> normal angle theta = atan2(319, -110) ~ 109 deg
    assert np.degrees(lines[0, 1]) == pytest.approx(np.degrees(np.arctan2(319, -110)), abs=2)


def test_lsd_baseline_draws_segments_with_their_width_and_scores_them_by_length():
    image = np.full((120, 400), 200, np.uint8)
    cv2.line(image, (10, 30), (390, 30), 40, 3)  # a long dark wire, 380 px
    cv2.line(image, (100, 90), (160, 90), 40, 3)  # a short dark stroke, 60 px
    scores = lsd_scores(image, PerceptionParams(lsd_baseline_full_length_px=200.0))
    assert scores[28:33, 50:350].max(axis=0).min() == pytest.approx(1.0)  # long: saturated
    short = scores[88:93, 110:150].max()
    assert 0.2 < short < 0.35  # LSD finds the stroke's edges, ~60 px of 200
    assert scores[50:70].max() == 0.0 and scores[:20].max() == 0.0  # nothing in flat areas
    # a fixed 2-px drawing marks a narrower band around each edge than 6 px does
    wide = lsd_scores(image, PerceptionParams(lsd_baseline_width_px=6))
    assert (wide > 0).sum() > 1.5 * (scores > 0).sum()


def test_lsd_baseline_finds_a_dark_line_on_blurred_noise():
    rng = np.random.default_rng(0)
    image = (rng.normal(120, 25, (160, 240))).clip(0, 255).astype(np.uint8)
    image = cv2.GaussianBlur(image, (0, 0), 2.0)
    truth = np.zeros_like(image)
    cv2.line(image, (0, 40), (239, 120), 20, 2)
    cv2.line(truth, (0, 40), (239, 120), 1, 2)
    result = evaluate_predictions([lsd_scores(image)], [truth], tolerance_px=2)
    assert result.ods_f1 > 0.8
