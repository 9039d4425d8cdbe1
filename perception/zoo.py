"""The model zoo of the grid search (thesis 2.3.1, Tables 2.1-2.3), built from thesis names.

A name is a '-'-separated list of layers, all 3x3 convolutions (2.3.1):

- ``kN``: convolution to N channels + ReLU (the last ``k2`` has no ReLU: it gives the logits),
- ``p2``: 2x2 max-pool (the logits are bilinearly upsampled back to the input size),
- ``dN``: context layer, a 3x3 convolution with dilation N keeping the channel count + ReLU
  (Yu and Koltun's context module), padded so that the feature map keeps its size.
- ``s`` (beyond the thesis; only last, after ``k2``, in a model with a pool): a skip connection
  as in FCN (Long et al. 2015). The full-resolution features entering the first pool give
  logits of their own through a 3x3 convolution to 2 channels, added to the upsampled logits,
  so that a pooled model places a wire to the pixel again. Zero-initialised: ``...-k2-s``
  starts as exactly ``...-k2``.

The grid of Table 2.1 stacks each context module c1-c5 over each front end f1-f6. The front
ends f3, f4 and f5 follow the prose of 2.3.1 and the headers of Table 2.2 ("halve the channels
of the last two layers of f2" gives k32-k32-k32-k32; f4 and f5 append two layers to f2 and f3),
not the shorter strings printed in Table 2.1: only this reading reproduces every parameter
count of Table 2.3, whose model strings for these front ends are one layer short of their own
counts (e.g. "k32-k32-k32-d1-d2-d4-d8-d16-d1-k2" is listed with 84,706 parameters, which is
the count of k32-k32-k32-k32-d1-...; parsed literally that string has 75,458).
"""

from __future__ import annotations

import re

import torch
from torch import nn
from torch.nn import functional as F

FRONT_ENDS: dict[str, str] = {
    "f1": "k64-k64-p2-k128-k128",
    "f2": "k32-k32-k64-k64",
    "f3": "k32-k32-k32-k32",
    "f4": "k32-k32-k64-k64-k64-k64",
    "f5": "k32-k32-k32-k32-k32-k32",
    "f6": "k32-k32",
}
"""Front-end modules of Table 2.1 (f3-f5 as defined by the prose of 2.3.1, see module doc)."""

CONTEXT_MODULES: dict[str, str] = {
    "c1": "k2",
    "c2": "d1-d2-d1-k2",
    "c3": "d1-d2-d4-d1-k2",
    "c4": "d1-d2-d4-d8-d1-k2",
    "c5": "d1-d2-d4-d8-d16-d1-k2",
}
"""Context modules of Table 2.1 (c1 is the bare logits layer)."""

ZOO: dict[str, str] = {
    f"{f}{c}": f"{front}-{context}"
    for f, front in FRONT_ENDS.items()
    for c, context in CONTEXT_MODULES.items()
}
"""All 30 grid models of Table 2.1: grid label (e.g. 'f6c5') -> architecture name."""

_LAYER = re.compile(r"^([kpd])(\d+)$")
SKIP = "s"
"""Trailing token of a model with an FCN-style full-resolution skip (see module doc)."""


class WireNet(nn.Module):
    """Fully convolutional wire segmenter: (N, C, H, W) image -> (N, 2, H, W) logits (2.3.1).

    Any H, W work; with pooling layers the logits are upsampled back to (H, W).
    """

    def __init__(self, name: str, in_channels: int = 3) -> None:
        super().__init__()
        self.name = name
        self.in_channels = in_channels
        layers: list[nn.Module] = []
        channels = in_channels
        self.downsample = 1
        self.skip: nn.Conv2d | None = None
        skip_channels = 0
        tokens = parse_name(name)
        for i, (kind, value) in enumerate(tokens):
            last = i == len(tokens) - 1
            if kind == "p":
                layers.append(nn.MaxPool2d(value, value, ceil_mode=True))
                skip_channels = skip_channels or channels
                self.downsample *= value
                continue
            out = value if kind == "k" else channels
            dilation = value if kind == "d" else 1
            layers.append(nn.Conv2d(channels, out, 3, padding=dilation, dilation=dilation))
            if not last:
                layers.append(nn.ReLU(inplace=True))
            channels = out
        self.body = nn.Sequential(*layers)
        if has_skip(name):
            self.skip = nn.Conv2d(skip_channels, 2, 3, padding=1)
            nn.init.zeros_(self.skip.weight)
            nn.init.zeros_(self.skip.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Logits (N, 2, H, W) of [not-wire, wire] at the input resolution."""
        full_res = None
        h = x
        for layer in self.body:
            if full_res is None and isinstance(layer, nn.MaxPool2d):
                full_res = h
            h = layer(h)
        if self.downsample > 1:
            h = F.interpolate(h, size=x.shape[-2:], mode="bilinear", align_corners=False)
        if self.skip is not None:
            h = h + self.skip(full_res)
        return h


def parse_name(name: str) -> list[tuple[str, int]]:
    """Layers of a thesis model name as (kind, value) pairs; raises ValueError if malformed.

    The name must end in ``k2`` (two-class logits, 2.3.1), or in ``k2-s`` with a skip (only
    in a model with a pool), and may not start with a context layer. The ``s`` is not a layer.
    """
    tokens = []
    parts = name.strip().split("-")
    if has_skip(name):
        parts = parts[:-1]
        if not any(part.startswith("p") for part in parts):
            raise ValueError(f"model name {name!r} has a skip ('-s') but no pool to skip")
    for part in parts:
        match = _LAYER.match(part)
        if match is None or int(match.group(2)) < 1:
            raise ValueError(f"bad layer {part!r} in model name {name!r}")
        tokens.append((match.group(1), int(match.group(2))))
    if tokens[-1] != ("k", 2):
        raise ValueError(f"model name {name!r} must end in k2 (two-class logits)")
    if tokens[0][0] == "d":
        raise ValueError(f"model name {name!r} starts with a context layer: nothing to keep")
    return tokens


def has_skip(name: str) -> bool:
    """Whether a model name ends in the full-resolution skip token ``s`` (see module doc)."""
    return name.strip().rsplit("-", 1)[-1] == SKIP


def resolve_name(name_or_label: str) -> str:
    """Architecture name of a grid label ('f6c5') or of an architecture name itself."""
    return ZOO.get(name_or_label, name_or_label)


def build_model(name: str, in_channels: int = 3) -> nn.Module:
    """Randomly initialised model from its thesis name or grid label; 3 (RGB) or 5 (RGBLE) in."""
    return WireNet(resolve_name(name), in_channels)


def parameter_count(model: nn.Module) -> int:
    """Number of trainable parameters (weights + biases), as counted in Table 2.3."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def grid_label(name: str) -> str | None:
    """Grid label ('f6c5') of an architecture name, or None when it is not in the grid."""
    for label, arch in ZOO.items():
        if arch == name:
            return label
    return None
