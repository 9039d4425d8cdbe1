"""Per-pixel wire-segmentation metrics of thesis 2.4.1: PR curve, AP, ROC AUC, ODS and OIS F1.

Every number comes from cumulative counts over one sorted threshold set: each pixel's score is
binned once with `np.searchsorted`, per-threshold counts are reverse cumulative sums of
`np.bincount` histograms, so no Python loop touches pixels or thresholds.

A pixel-distance tolerance (BSDS-style edge evaluation, Arbelaez et al. 2011) relaxes the
matching for thin, imprecisely labelled wires: with `tolerance_px = r`

- a predicted pixel is a true positive when a labelled wire pixel lies within Euclidean
  distance r of it (precision uses the wire mask dilated by a disk of radius r), and
- a labelled wire pixel is recalled at threshold t when some pixel within distance r of it
  scores >= t (recall uses the probability map max-filtered over the same disk).

This is the relaxed (many-to-one) form of the BSDS correspondence, not its one-to-one
bipartite matching; with r = 0 both reduce to exact per-pixel counting.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np


def default_thresholds() -> np.ndarray:
    """(K,) float64 ascending thresholds in [0, 1]: a uniform 1e-3 grid plus a logistic grid.

    The logistic part (sigmoid of -16..16) resolves confident networks whose scores pile up
    within 1e-4 of 0 or 1; 0.0 is included so the curve ends at recall 1.
    """
    uniform = np.arange(1001) / 1000.0
    logistic = 1.0 / (1.0 + np.exp(-np.linspace(-16.0, 16.0, 641)))
    return np.unique(np.concatenate([uniform, logistic]))


def disk_kernel(radius_px: int) -> np.ndarray:
    """(2r+1, 2r+1) uint8 disk: 1 where the Euclidean distance to the centre is <= r px."""
    r = int(radius_px)
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    return (xx * xx + yy * yy <= r * r).astype(np.uint8)


@dataclass(frozen=True)
class PixelCounts:
    """Per-threshold counts of one image or a dataset; arrays are (K,) int64 over thresholds.

    `tp_pred`: predicted pixels matched to a wire; `n_pred`: predicted pixels; `tp_true`:
    wire pixels recalled; `n_true`: wire pixels (scalar); `n_neg`: pixels matched to no wire
    (scalar), the denominator of the false-positive rate.
    """

    tp_pred: np.ndarray
    n_pred: np.ndarray
    tp_true: np.ndarray
    n_true: int
    n_neg: int


@dataclass(frozen=True)
class Metrics:
    """Dataset-level metrics of thesis 2.4.1 (Table 2.4 columns AP, AUC, ODS F-score).

    `precision`, `recall`, `fpr` are (K,) float64 curves at `thresholds` (ascending);
    precision is 1 where nothing is predicted. `ods_*` is the best single threshold over the
    dataset; `ois_f1` the F1 of the counts summed at each image's own best threshold (BSDS).
    `roc_auc` is NaN when the dataset has no wire pixel or no background pixel.
    """

    ap: float
    roc_auc: float
    ods_f1: float
    ods_threshold: float
    ods_precision: float
    ods_recall: float
    ois_f1: float
    precision: np.ndarray
    recall: np.ndarray
    fpr: np.ndarray
    thresholds: np.ndarray
    tolerance_px: int
    n_images: int


def _reverse_cumsum_hist(levels: np.ndarray, n_thresholds: int) -> np.ndarray:
    """(K,) int64: entry k counts the `levels` >= k (i.e. scores >= thresholds[k])."""
    hist = np.bincount(levels, minlength=n_thresholds)
    return np.cumsum(hist[::-1])[::-1].astype(np.int64)


def image_counts(
    prob: np.ndarray, mask: np.ndarray, thresholds: np.ndarray, tolerance_px: int = 0
) -> PixelCounts:
    """Per-threshold counts of one (H, W) probability map against its (H, W) wire mask.

    `mask` is nonzero on wire pixels. A pixel is predicted at threshold k when its score is
    >= thresholds[k]; scores below thresholds[0] are never predicted.
    """
    prob = np.asarray(prob, dtype=np.float32)
    truth = np.asarray(mask) != 0
    if prob.shape != truth.shape:
        raise ValueError(f"probability map {prob.shape} and mask {truth.shape} differ in shape")
    k = len(thresholds)
    if tolerance_px > 0:
        disk = disk_kernel(tolerance_px)
        matched = cv2.dilate(truth.astype(np.uint8), disk) != 0
        reach = cv2.dilate(prob, disk)  # grey dilation = max filter over the disk
    else:
        matched, reach = truth, prob
    # level = number of thresholds <= score, minus one; -1 (never predicted) is dropped.
    level = np.searchsorted(thresholds, prob.ravel(), side="right") - 1
    predicted = level >= 0
    level_true = np.searchsorted(thresholds, reach[truth], side="right") - 1
    match_flat = matched.ravel()
    return PixelCounts(
        tp_pred=_reverse_cumsum_hist(level[predicted & match_flat], k),
        n_pred=_reverse_cumsum_hist(level[predicted], k),
        tp_true=_reverse_cumsum_hist(level_true[level_true >= 0], k),
        n_true=int(truth.sum()),
        n_neg=int(matched.size - matched.sum()),
    )


def _precision_recall_f1(
    tp_pred: np.ndarray, n_pred: np.ndarray, tp_true: np.ndarray, n_true: int | np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Precision (1 where nothing is predicted), recall (0 without wires) and F1, elementwise."""
    with np.errstate(invalid="ignore", divide="ignore"):
        precision = np.where(n_pred > 0, tp_pred / np.maximum(n_pred, 1), 1.0)
        recall = np.where(n_true > 0, tp_true / np.maximum(n_true, 1), 0.0)
        denom = precision + recall
        f1 = np.where(denom > 0, 2.0 * precision * recall / np.where(denom > 0, denom, 1), 0.0)
    return precision, recall, f1


def average_precision(precision: np.ndarray, recall: np.ndarray) -> float:
    """Area under the step PR curve, sum_k (R_k - R_{k+1}) P_k (thresholds ascending, 2.4.1).

    The same convention as scikit-learn's `average_precision_score` (no interpolation); the
    curve is closed at recall 0 beyond the highest threshold.
    """
    recall_next = np.append(recall[1:], 0.0)
    return float(np.sum((recall - recall_next) * precision))


def roc_auc(tpr: np.ndarray, fpr: np.ndarray) -> float:
    """Trapezoidal area under the ROC curve through (0, 0), the (K,) points and (1, 1)."""
    x = np.concatenate([[1.0], fpr, [0.0]])[::-1]
    y = np.concatenate([[1.0], tpr, [0.0]])[::-1]
    return float(np.sum(np.diff(x) * (y[1:] + y[:-1]) * 0.5))


def evaluate_predictions(
    probs: Sequence[np.ndarray],
    masks: Sequence[np.ndarray],
    tolerance_px: int = 0,
    thresholds: np.ndarray | None = None,
) -> Metrics:
    """Dataset metrics (thesis 2.4.1) of (H, W) wire probabilities in [0, 1] against masks.

    probs: per-image float (H, W) scores; masks: per-image (H, W), nonzero on wire pixels
    (sizes may differ between images); tolerance_px: matching radius in pixels (module doc);
    thresholds: ascending (K,) thresholds, `default_thresholds()` when None.
    """
    if len(probs) != len(masks):
        raise ValueError(f"{len(probs)} probability maps but {len(masks)} masks")
    if tolerance_px < 0:
        raise ValueError(f"tolerance_px must be >= 0, got {tolerance_px}")
    th = validated_thresholds(thresholds)
    per_image = [image_counts(p, m, th, tolerance_px) for p, m in zip(probs, masks, strict=True)]
    return metrics_from_counts(per_image, th, tolerance_px)


def validated_thresholds(thresholds: np.ndarray | None = None) -> np.ndarray:
    """(K,) float64 thresholds: `default_thresholds()` for None; ValueError unless ascending."""
    th = default_thresholds() if thresholds is None else np.asarray(thresholds, np.float64)
    if th.ndim != 1 or th.size == 0 or np.any(np.diff(th) <= 0):
        raise ValueError("thresholds must be a non-empty, strictly ascending 1-D array")
    return th


def metrics_from_counts(
    per_image: Sequence[PixelCounts], thresholds: np.ndarray, tolerance_px: int = 0
) -> Metrics:
    """Dataset metrics from per-image counts (`image_counts`), e.g. accumulated while streaming
    a dataset from disk without keeping its probability maps."""
    if len(per_image) == 0:
        raise ValueError("no images to evaluate")
    th = thresholds
    tp_pred = np.stack([c.tp_pred for c in per_image])  # (N, K)
    n_pred = np.stack([c.n_pred for c in per_image])
    tp_true = np.stack([c.tp_true for c in per_image])
    n_true = np.array([c.n_true for c in per_image], dtype=np.int64)
    n_neg = int(sum(c.n_neg for c in per_image))

    precision, recall, f1 = _precision_recall_f1(
        tp_pred.sum(0), n_pred.sum(0), tp_true.sum(0), int(n_true.sum())
    )
    # ODS/OIS choose among thresholds > 0: threshold 0 calls every pixel a wire, which is no
    # operating point (BSDS likewise sweeps thresholds strictly inside (0, 1)).
    first = int(th[0] <= 0.0) if len(th) > 1 else 0
    best = first + int(np.argmax(f1[first:]))
    fp = n_pred.sum(0) - tp_pred.sum(0)
    fpr = fp / n_neg if n_neg > 0 else np.full(len(th), np.nan)
    auc = roc_auc(recall, fpr) if n_neg > 0 and n_true.sum() > 0 else float("nan")

    # OIS: each image at its best threshold, ties to the highest one: false positives only
    # fall as the threshold rises, so an image whose F1 is flat (no wire, or never hit) adds
    # its fewest false positives. Counts are then summed (BSDS convention).
    _, _, f1_img = _precision_recall_f1(tp_pred, n_pred, tp_true, n_true[:, None])
    k_img = f1_img.shape[1] - 1 - np.argmax(f1_img[:, first:][:, ::-1], axis=1)
    rows = np.arange(len(per_image))
    _, _, f1_ois = _precision_recall_f1(
        tp_pred[rows, k_img].sum(),
        n_pred[rows, k_img].sum(),
        tp_true[rows, k_img].sum(),
        int(n_true.sum()),
    )
    return Metrics(
        ap=average_precision(precision, recall),
        roc_auc=auc,
        ods_f1=float(f1[best]),
        ods_threshold=float(th[best]),
        ods_precision=float(precision[best]),
        ods_recall=float(recall[best]),
        ois_f1=float(f1_ois),
        precision=precision,
        recall=recall,
        fpr=fpr,
        thresholds=th,
        tolerance_px=int(tolerance_px),
        n_images=len(per_image),
    )


_RECALL_TOLERANCE_PX = 2
_FALSE_DISTANCE_PX = 4
_FALSE_FRAME_PX = 50
_BACKGROUND_PX = 7  # window whose stereo surfaces tell what a wire pixel is seen against


@dataclass(frozen=True)
class MaskScore:
    """Summed counts of binary wire masks against true wire masks (the mask the map gets,
    not a probability map): true wire pixels and those within 2 px of the mask, mask pixels
    and those farther than 4 px from any wire, frames and frames with over 50 such pixels;
    with the frames' stereo surfaces, the true wire pixels seen against a surface (the
    ground, trees, buildings: most pixels around them hold a stereo return) and those found."""

    wire_px: int = 0
    wire_found_px: int = 0
    mask_px: int = 0
    false_px: int = 0
    frames: int = 0
    frames_with_false: int = 0
    surface_wire_px: int = 0
    surface_wire_found_px: int = 0
    frames_with_surfaces: int = 0

    @classmethod
    def of(
        cls, mask: np.ndarray, truth: np.ndarray, surface: np.ndarray | None = None
    ) -> MaskScore:
        """The counts of one (H, W) bool `mask` against its (H, W) bool `truth`; `surface`:
        (H, W) bool, where stereo sees a surface (`postprocess.stereo_surface`), or None."""
        mask, truth = np.asarray(mask, bool), np.asarray(truth, bool)
        found = truth & (cv2.dilate(mask.astype(np.uint8), disk_kernel(_RECALL_TOLERANCE_PX)) > 0)
        false_px = int((mask & far_from_wires(truth)).sum())
        against = np.zeros_like(truth)
        if surface is not None:
            share = cv2.blur(np.asarray(surface, np.float32), (_BACKGROUND_PX, _BACKGROUND_PX))
            against = truth & (share > 0.5)
        return cls(
            int(truth.sum()),
            int(found.sum()),
            int(mask.sum()),
            false_px,
            1,
            int(false_px > _FALSE_FRAME_PX),
            int(against.sum()),
            int((against & found).sum()),
            int(surface is not None),
        )

    def __add__(self, other: MaskScore) -> MaskScore:
        pairs = zip(vars(self).values(), vars(other).values(), strict=True)
        return MaskScore(*(a + b for a, b in pairs))

    def summary(self) -> dict[str, float | int]:
        """`wire_recall`, `false_share` (of mask pixels) and `frames_with_false_marks`; when
        scored with surfaces, `wire_recall_against_surfaces` and `wire_recall_against_sky`."""
        out: dict[str, float | int] = {
            "wire_recall": round(self.wire_found_px / max(self.wire_px, 1), 4),
            "false_share": round(self.false_px / max(self.mask_px, 1), 4),
            "frames_with_false_marks": self.frames_with_false,
        }
        if self.frames_with_surfaces:
            sky_px = self.wire_px - self.surface_wire_px
            sky_found = self.wire_found_px - self.surface_wire_found_px
            out["wire_recall_against_surfaces"] = round(
                self.surface_wire_found_px / max(self.surface_wire_px, 1), 4
            )
            out["wire_recall_against_sky"] = round(sky_found / max(sky_px, 1), 4)
        return out


def far_from_wires(truth: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels farther than 4 px from any pixel of the (H, W) true wire mask,
    where a mask pixel is a false mark (`MaskScore`)."""
    near = cv2.dilate(np.asarray(truth, np.uint8), disk_kernel(_FALSE_DISTANCE_PX)) > 0
    return ~near


def _pooled_false_share(masks: Sequence[np.ndarray], far: Sequence[np.ndarray]) -> float:
    false_px = sum(int((np.asarray(m, bool) & f).sum()) for m, f in zip(masks, far, strict=True))
    return false_px / max(sum(f.size for f in far), 1)


def false_mark_share(masks: Sequence[np.ndarray], truths: Sequence[np.ndarray]) -> float:
    """Share of all pixels of the images that their masks mark falsely (`MaskScore`: farther
    than 4 px from any true wire), pooled over the images."""
    return _pooled_false_share(masks, [far_from_wires(t) for t in truths])


def threshold_for_false_share(
    probs: Sequence[np.ndarray],
    truths: Sequence[np.ndarray],
    target_share: float,
    mask_at: Callable[[np.ndarray, float], np.ndarray],
    resolution: float = 1e-4,
) -> float:
    """The lowest threshold in [0.5, 1) at which the masks `mask_at(prob, threshold)` mark at
    most `target_share` of the images' pixels falsely (`false_mark_share`), to `resolution`
    (1 - `resolution` when none does).

    Beyond 4.4.1's fixed 0.95: a model's threshold chosen so that it marks as much of real,
    wire-free scenery as a reference does, photographs without wires being enough. Bisection,
    since a thresholded, speckle-filtered mask only loses pixels as the threshold rises.
    """

    far = [far_from_wires(t) for t in truths]

    def share(threshold: float) -> float:
        return _pooled_false_share([mask_at(p, threshold) for p in probs], far)

    low, high = 0.5, 1.0 - resolution
    if share(low) <= target_share:
        return low
    while high - low > resolution:  # share(low) > target; share(high) <= target or high ~ 1
        middle = 0.5 * (low + high)
        low, high = (low, middle) if share(middle) <= target_share else (middle, high)
    return high
