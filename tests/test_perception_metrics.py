"""Metrics of thesis 2.4.1 against hand-computed cases and brute-force references."""

from __future__ import annotations

import numpy as np
import pytest

from perception.metrics import (
    MaskScore,
    average_precision,
    default_thresholds,
    disk_kernel,
    evaluate_predictions,
    roc_auc,
)


def _brute_force(probs, masks, thresholds, tolerance_px=0):
    """Per-threshold (precision, recall, fpr, f1) with explicit loops over thresholds/pixels."""
    r = tolerance_px
    rows = []
    for t in thresholds:
        tp_pred = n_pred = tp_true = n_true = fp = n_neg = 0
        for p, m in zip(probs, masks, strict=True):
            h, w = p.shape
            for y in range(h):
                for x in range(w):
                    near = [
                        (yy, xx)
                        for yy in range(max(0, y - r), min(h, y + r + 1))
                        for xx in range(max(0, x - r), min(w, x + r + 1))
                        if (yy - y) ** 2 + (xx - x) ** 2 <= r * r
                    ]
                    matched = any(m[yy, xx] for yy, xx in near)
                    n_neg += not matched
                    if p[y, x] >= t:
                        n_pred += 1
                        tp_pred += matched
                        fp += not matched
                    if m[y, x]:
                        n_true += 1
                        tp_true += any(p[yy, xx] >= t for yy, xx in near)
        precision = tp_pred / n_pred if n_pred else 1.0
        recall = tp_true / n_true if n_true else 0.0
        f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
        rows.append((precision, recall, fp / n_neg, f1))
    return np.array(rows)


def _sklearn_style_ap(scores, labels):
    """AP = sum_n (R_n - R_{n-1}) P_n over descending unique scores (scikit-learn's formula)."""
    order = np.argsort(-scores, kind="stable")
    s, y = scores[order], labels[order]
    ap, prev_recall = 0.0, 0.0
    for t in np.unique(s)[::-1]:
        pred = s >= t
        tp = np.sum(y[pred])
        precision, recall = tp / pred.sum(), tp / y.sum()
        ap += (recall - prev_recall) * precision
        prev_recall = recall
    return ap


def test_hand_computed_four_pixels():
    # scores 0.9 (wire), 0.8 (bg), 0.6 (wire), 0.1 (bg)
    prob = np.array([[0.9, 0.8], [0.6, 0.1]], np.float32)
    mask = np.array([[1, 0], [1, 0]], np.uint8)
    m = evaluate_predictions([prob], [mask], thresholds=np.array([0.0, 0.5, 0.7, 0.85, 0.95]))
    # t=0.85: P=1 R=.5; t=0.7: P=.5 R=.5; t=.5: P=2/3 R=1; t=0: P=.5 R=1; t=.95: nothing.
    np.testing.assert_allclose(m.precision, [0.5, 2 / 3, 0.5, 1.0, 1.0])
    np.testing.assert_allclose(m.recall, [1.0, 1.0, 0.5, 0.5, 0.0])
    assert m.ap == pytest.approx(0.5 * 1.0 + 0.5 * 2 / 3)
    assert m.ods_f1 == pytest.approx(0.8)  # P=2/3, R=1
    assert m.ods_threshold == pytest.approx(0.5)
    # ROC: positives ranked 1st and 3rd of 4 -> AUC = 3/4 pairs ordered correctly.
    assert m.roc_auc == pytest.approx(0.75)


def test_perfect_and_inverted_predictions():
    rng = np.random.default_rng(0)
    mask = rng.random((20, 30)) < 0.1
    perfect = evaluate_predictions([mask.astype(np.float32)], [mask])
    assert perfect.ap == pytest.approx(1.0)
    assert perfect.roc_auc == pytest.approx(1.0)
    assert perfect.ods_f1 == pytest.approx(1.0)
    assert perfect.ois_f1 == pytest.approx(1.0)
    inverted = evaluate_predictions([(~mask).astype(np.float32)], [mask])
    assert inverted.roc_auc == pytest.approx(0.0)
    assert inverted.ap < 0.15  # precision of "everything" is the wire fraction


def test_ap_and_auc_equal_rank_statistics_with_exact_thresholds():
    rng = np.random.default_rng(1)
    probs = [rng.random((7, 9)).astype(np.float32) for _ in range(3)]
    masks = [rng.random((7, 9)) < 0.3 for _ in range(3)]
    scores = np.concatenate([p.ravel() for p in probs]).astype(np.float64)
    labels = np.concatenate([m.ravel() for m in masks])
    m = evaluate_predictions(probs, masks, thresholds=np.unique(scores.astype(np.float32)))
    assert m.ap == pytest.approx(_sklearn_style_ap(scores, labels), abs=1e-12)
    # AUC = probability that a random wire pixel outranks a random background pixel (no ties).
    pos, neg = scores[labels], scores[~labels]
    mann_whitney = np.mean(pos[:, None] > neg[None, :])
    assert m.roc_auc == pytest.approx(mann_whitney, abs=1e-12)


@pytest.mark.parametrize("tolerance_px", [0, 1, 2])
def test_curves_match_brute_force(tolerance_px):
    rng = np.random.default_rng(2 + tolerance_px)
    probs = [np.round(rng.random((6, 8)), 2).astype(np.float32) for _ in range(2)]
    masks = [rng.random((6, 8)) < 0.15 for _ in range(2)]
    thresholds = np.linspace(0.0, 1.0, 11)
    m = evaluate_predictions(probs, masks, tolerance_px=tolerance_px, thresholds=thresholds)
    ref = _brute_force(probs, masks, thresholds, tolerance_px)
    np.testing.assert_allclose(m.precision, ref[:, 0], atol=1e-12)
    np.testing.assert_allclose(m.recall, ref[:, 1], atol=1e-12)
    np.testing.assert_allclose(m.fpr, ref[:, 2], atol=1e-12)
    assert m.ods_f1 == pytest.approx(ref[1:, 3].max())  # threshold 0 is no operating point


def test_tolerance_accepts_a_one_pixel_offset():
    mask = np.zeros((20, 20), bool)
    mask[10, 2:18] = True
    prob = np.zeros((20, 20), np.float32)
    prob[11, 2:18] = 1.0  # the prediction is one row off the label
    exact = evaluate_predictions([prob], [mask])
    relaxed = evaluate_predictions([prob], [mask], tolerance_px=1)
    assert exact.ods_f1 < 0.1
    assert relaxed.ods_f1 == pytest.approx(1.0)
    assert relaxed.ap == pytest.approx(1.0)


def test_ois_picks_each_images_own_threshold():
    # Image A separates at 0.7, image B at 0.3: no single threshold is perfect for both.
    mask = np.array([[1, 0]], bool)
    a = np.array([[0.8, 0.6]], np.float32)
    b = np.array([[0.4, 0.2]], np.float32)
    m = evaluate_predictions([a, b], [mask, mask], thresholds=np.linspace(0, 1, 11))
    assert m.ois_f1 == pytest.approx(1.0)
    assert m.ods_f1 == pytest.approx(0.8)  # t in (0.2, 0.4]: TP 2, FP 1, R 1 -> F = 0.8


def test_image_without_wires_counts_only_its_false_positives_in_ois():
    empty = np.zeros((4, 4), bool)
    wire = np.zeros((4, 4), bool)
    wire[1, :] = True
    m = evaluate_predictions(
        [np.where(wire, 0.9, 0.1).astype(np.float32), np.full((4, 4), 0.5, np.float32)],
        [wire, empty],
    )
    assert m.ois_f1 == pytest.approx(1.0)
    assert np.isfinite(m.roc_auc)


def test_helpers_and_validation():
    assert disk_kernel(1).tolist() == [[0, 1, 0], [1, 1, 1], [0, 1, 0]]
    th = default_thresholds()
    assert th[0] == 0.0 and th[-1] == 1.0 and np.all(np.diff(th) > 0)
    assert 0.95 in th
    assert average_precision(np.array([1.0, 1.0]), np.array([1.0, 0.0])) == pytest.approx(1.0)
    assert roc_auc(np.array([1.0, 1.0]), np.array([1.0, 0.0])) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="differ in shape"):
        evaluate_predictions([np.zeros((2, 2))], [np.zeros((2, 3))])
    with pytest.raises(ValueError, match="masks"):
        evaluate_predictions([np.zeros((2, 2))], [])
    with pytest.raises(ValueError, match="ascending"):
        evaluate_predictions([np.zeros((2, 2))], [np.zeros((2, 2))], thresholds=np.array([1, 0]))


def test_ois_ignores_an_image_whose_wire_is_never_hit():
    wire = np.zeros((4, 4), bool)
    wire[1, :] = True
    hit = np.where(wire, 0.9, 0.1).astype(np.float32)
    missed = np.where(wire, 0.0, 0.3).astype(np.float32)  # F1 = 0 at every threshold > 0
    m = evaluate_predictions([hit, missed], [wire, wire], thresholds=np.linspace(0, 1, 11))
    # image 2 sits at threshold 1.0: no prediction, its 4 wire pixels missed -> R = 1/2, P = 1
    assert m.ois_f1 == pytest.approx(2 / 3)
    assert m.ois_f1 >= m.ods_f1


def test_mask_score_counts_recall_within_2_px_and_false_marks_beyond_4_px():
    truth = np.zeros((40, 100), bool)
    truth[20, 10:90] = True  # an 80 px wire
    mask = np.zeros_like(truth)
    mask[22, 10:50] = True  # its left half, 2 px off: found
    mask[26, 50:70] = True  # 6 px off: neither finds the wire nor lies near it
    mask[5, 0:60] = True  # a false line in the sky
    one = MaskScore.of(mask, truth)
    assert (one.wire_px, one.wire_found_px, one.mask_px, one.false_px) == (80, 40, 120, 80)
    assert (one.frames, one.frames_with_false) == (1, 1)
    two = one + MaskScore.of(truth, truth)
    assert two.summary() == {
        "wire_recall": 0.75,
        "false_share": round(80 / 200, 4),
        "frames_with_false_marks": 1,
    }
    assert MaskScore().summary()["wire_recall"] == 0.0


def test_mask_score_splits_recall_by_what_stereo_sees_behind_the_wire():
    truth = np.zeros((40, 100), bool)
    truth[20, 10:90] = True  # an 80 px wire: its right half before the ground, its left sky
    surface = np.zeros_like(truth)
    surface[:, 50:] = True  # stereo returns from column 50 on
    mask = np.zeros_like(truth)
    mask[20, 10:50] = True  # the CNN finds the part against the sky (and 2 px on, in tolerance)
    score = MaskScore.of(mask, truth, surface)
    assert (score.surface_wire_px, score.surface_wire_found_px) == (40, 2)
    summary = (score + MaskScore.of(truth, truth, surface)).summary()
    assert summary["wire_recall_against_surfaces"] == round(42 / 80, 4)
    assert summary["wire_recall_against_sky"] == 1.0
    assert summary["wire_recall"] == round(122 / 160, 4)
    assert "wire_recall_against_surfaces" not in MaskScore.of(mask, truth).summary()
    all_sky = MaskScore.of(mask, truth, np.zeros_like(truth)).summary()  # keys kept, no wire
    assert all_sky["wire_recall_against_surfaces"] == 0.0
    assert all_sky["wire_recall_against_sky"] == round(42 / 80, 4)
