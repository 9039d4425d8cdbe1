"""Class-balanced cross-entropy of HED (Xie and Tu 2015, eq. 2), used by thesis 2.3.3."""

from __future__ import annotations

import torch
from torch.nn import functional as F


def class_balance_weights(target: torch.Tensor, beta_max: float = 0.99) -> torch.Tensor:
    """Per-pixel weights (N, H, W): beta on wire pixels, 1 - beta on the rest, per image.

    beta = |Y-| / |Y| is the image's share of background pixels (HED eq. 2); it is capped at
    beta_max so that images with few or no wire pixels still weigh their negatives.
    """
    positives = target.flatten(1).float().mean(dim=1)
    beta = (1.0 - positives).clamp(max=beta_max)[:, None, None]
    return torch.where(target > 0, beta, 1.0 - beta)


def class_balanced_cross_entropy(
    logits: torch.Tensor, target: torch.Tensor, beta_max: float = 0.99
) -> torch.Tensor:
    """Mean over pixels of the class-balanced cross-entropy of (N, 2, H, W) logits (2.3.3).

    target: (N, H, W) integer mask, 1 on wire pixels. Computed in fp32 whatever the logits' dtype.
    """
    nll = F.cross_entropy(logits.float(), target.long(), reduction="none")
    return (nll * class_balance_weights(target, beta_max)).mean()
