"""Model checkpoints: architecture name, input mode, normalisation, weights, training metadata.

A checkpoint is a ``torch.save`` dict of plain types (loadable with ``weights_only=True``):
``format``, ``arch``, ``input_mode``, ``in_channels``, ``normalisation`` (see
``perception.inputs.NORMALISATION``), ``state_dict``, ``training`` (command, steps, seed,
losses, ...), ``metrics`` (held-out evaluation) and, for resumable training checkpoints only,
``optimizer_state``, and optionally ``mask_threshold`` (the mask threshold chosen on real
photographs, `wireavoid calibrate-threshold`, which `WireSegmenter.mask` then uses). The
shipped default lives in ``perception/weights/`` with its metrics in a
JSON file of the same stem beside it.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import torch
from torch import nn

from perception.inputs import NORMALISATION, input_channels
from perception.params import DEFAULT_MODEL
from perception.zoo import build_model, resolve_name

FORMAT = "wireavoid-checkpoint-1"
WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"


def shipped_checkpoint_path(model: str) -> Path:
    """Path of the shipped weights of a zoo name or grid label (RGB before RGBLE).

    The path may not exist: only the default model and its pooled variant
    (`FAST_MODEL`) ship weights.
    """
    name = resolve_name(model)
    shipped = [WEIGHTS_DIR / f"{name}_{mode}.pt" for mode in ("rgb", "rgble")]
    return next((p for p in shipped if p.is_file()), shipped[0])


def default_checkpoint_path() -> Path:
    """Path of the shipped default model: k32-k32-d1-d2-d4-d8-d16-d1-k2, RGB, synthetic-trained."""
    return shipped_checkpoint_path(DEFAULT_MODEL)


def metrics_path(checkpoint_path: str | os.PathLike) -> Path:
    """The JSON file beside a checkpoint that records its metrics and training command."""
    return Path(checkpoint_path).with_suffix(".json")


def save_checkpoint(
    path: str | os.PathLike,
    model: nn.Module,
    arch: str,
    input_mode: str,
    training: dict[str, Any] | None = None,
    metrics: dict[str, Any] | None = None,
    optimizer: torch.optim.Optimizer | None = None,
) -> Path:
    """Write a checkpoint atomically (temp file + rename) and return its path.

    Weights are stored as fp32 on CPU whatever device/dtype the model trained in; DDP's
    ``module.`` prefixes are stripped. With ``optimizer`` the checkpoint can be resumed.
    """
    module = getattr(model, "module", model)
    state = {k: v.detach().to("cpu", torch.float32) for k, v in module.state_dict().items()}
    payload: dict[str, Any] = {
        "format": FORMAT,
        "arch": arch,
        "input_mode": input_mode,
        "in_channels": input_channels(input_mode),
        "normalisation": {k: v[: input_channels(input_mode)] for k, v in NORMALISATION.items()},
        "state_dict": state,
        "training": training or {},
        "metrics": metrics or {},
    }
    if optimizer is not None:
        payload["optimizer_state"] = optimizer.state_dict()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    tmp.replace(path)
    return path


def warm_start(model: nn.Module, path: str | os.PathLike, input_mode: str) -> nn.Module:
    """Load a checkpoint's weights into `model` tensor by tensor, in layer order.

    The architectures may differ in their parameter-free layers (a `p2` pool moves the
    Sequential's indices), an RGB checkpoint may start an RGBLE model (its first layer gets
    zero weights on the L and E channels, so it starts as exactly the RGB model), and `model`
    may add a skip (`-s`, `perception.zoo`) that the
    checkpoint lacks, which then keeps its zero initialisation; every other weight and bias must
    match in shape; ValueError otherwise.
    """
    payload = read_checkpoint(path)
    source = dict(payload["state_dict"])
    if payload["input_mode"] != input_mode:
        if (payload["input_mode"], input_mode) != ("rgb", "rgble"):
            raise ValueError(f"{path} takes {payload['input_mode']} input, not {input_mode}")
        first = next(iter(source))  # RGB -> RGBLE: the L and E channels start at zero weight
        extra = input_channels(input_mode) - input_channels("rgb")
        w = source[first]
        source[first] = torch.cat([w, w.new_zeros(w.shape[0], extra, *w.shape[2:])], dim=1)
    target = model.state_dict()
    if not any(k.startswith("skip.") for k in source):
        target = {k: v for k, v in target.items() if not k.startswith("skip.")}
    shapes = [tuple(v.shape) for v in target.values()], [tuple(v.shape) for v in source.values()]
    if shapes[0] != shapes[1]:
        raise ValueError(f"{path} ({payload['arch']}) has weights {shapes[1]}, need {shapes[0]}")
    model.load_state_dict(dict(zip(target, source.values(), strict=True)), strict=False)
    return model


def read_checkpoint(path: str | os.PathLike) -> dict[str, Any]:
    """The raw checkpoint dict (CPU tensors); ValueError if the file is not one of ours."""
    payload = torch.load(Path(path), map_location="cpu", weights_only=True)
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"{path} is not a {FORMAT} checkpoint")
    return payload


def load_checkpoint(path: str | os.PathLike | None = None) -> tuple[nn.Module, dict[str, Any]]:
    """(model in eval mode on CPU, metadata) of a checkpoint, by default the shipped one.

    The metadata holds everything but the weights and optimizer state: ``arch``,
    ``input_mode``, ``in_channels``, ``normalisation``, ``training``, ``metrics``, ``path``.
    """
    path = Path(path) if path is not None else default_checkpoint_path()
    payload = read_checkpoint(path)
    model = build_model(payload["arch"], payload["in_channels"])
    model.load_state_dict(payload["state_dict"])
    model.eval()
    meta = {k: v for k, v in payload.items() if k not in ("state_dict", "optimizer_state")}
    meta.setdefault("mask_threshold", None)
    meta["path"] = str(path)
    return model, meta


def record_mask_threshold(
    path: str | os.PathLike, threshold: float, record: dict[str, Any]
) -> Path:
    """Store a mask threshold (and `record`, how it was chosen) in a checkpoint, atomically,
    and under "mask_threshold" in the JSON beside it when that exists."""
    if not 0.0 < threshold < 1.0:
        raise ValueError(f"a mask threshold lies in (0, 1), got {threshold}")
    path = Path(path)
    payload = read_checkpoint(path)
    payload["mask_threshold"] = float(threshold)
    payload["mask_threshold_record"] = dict(record)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    tmp.replace(path)
    meta = metrics_path(path)
    if meta.is_file():
        doc = json.loads(meta.read_text())
        doc["mask_threshold"] = {"value": float(threshold), **record}
        write_metrics_json(path, doc)
    return path


def write_metrics_json(checkpoint_path: str | os.PathLike, record: dict[str, Any]) -> Path:
    """Write the human-readable record (metrics, command, data) beside a checkpoint."""
    out = metrics_path(checkpoint_path)
    out.write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")
    return out


def interpolated_state(
    fine_tuned: dict[str, torch.Tensor], reference: dict[str, torch.Tensor], alpha: float
) -> dict[str, torch.Tensor]:
    """alpha * fine_tuned + (1 - alpha) * reference, tensor by tensor.

    Beyond the thesis (which fine-tunes on real data, 2.4.4, and ships the result): the
    weight-space ensemble of WiSE-FT (Wortsman et al., CVPR 2022, eq. 1) of a fine-tune and
    the weights it started from. Both lie in one basin, so the blend is a working network
    that keeps part of what the fine-tune learned (here: the simulated cameras' wires) and
    part of what it forgot (here: faint real wires against the sky). ValueError unless both
    hold the same tensors, or if alpha is outside [0, 1].
    """
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha lies in [0, 1], got {alpha}")
    shapes = {k: tuple(v.shape) for k, v in fine_tuned.items()}
    if shapes != {k: tuple(v.shape) for k, v in reference.items()}:
        raise ValueError("the two checkpoints hold different tensors (architectures differ)")
    return {
        k: alpha * v + (1.0 - alpha) * reference[k] if v.is_floating_point() else v.clone()
        for k, v in fine_tuned.items()
    }


def ship_checkpoint(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    extra: dict[str, Any] | None = None,
    interpolate_with: str | os.PathLike | None = None,
    alpha: float = 1.0,
) -> Path:
    """Copy a trained checkpoint without its optimiser state (the form committed to weights/),
    and write its metrics JSON beside it: metrics, training command and settings, `extra`.

    With `interpolate_with` (a checkpoint of the same architecture, usually the weights `src`
    was fine-tuned from) the weights written are `interpolated_state(src, it, alpha)`. The
    record then names both and alpha; `src`'s metrics and mask threshold, which belong to
    other weights, are not carried over (calibrate the threshold again).
    """
    payload = read_checkpoint(src)
    model = build_model(payload["arch"], payload["in_channels"])
    state, metrics = payload["state_dict"], payload["metrics"]
    interpolation: dict[str, Any] = {}
    if interpolate_with is not None:
        reference = read_checkpoint(interpolate_with)
        if (reference["arch"], reference["input_mode"]) != (payload["arch"], payload["input_mode"]):
            raise ValueError(
                f"{interpolate_with} is {reference['arch']} ({reference['input_mode']}), "
                f"{src} is {payload['arch']} ({payload['input_mode']})"
            )
        state = interpolated_state(state, reference["state_dict"], alpha)
        metrics = {}
        interpolation = {
            "interpolation": {
                "fine_tuned": str(src),
                "reference": str(interpolate_with),
                "reference_sha256": hashlib.sha256(Path(interpolate_with).read_bytes()).hexdigest(),
                "alpha": alpha,
                "method": "WiSE-FT: alpha * fine_tuned + (1 - alpha) * reference",
            }
        }
    model.load_state_dict(state)
    training = payload["training"]
    # read everything from `interpolate_with` before `dst` (possibly the same file) is written
    path = save_checkpoint(dst, model, payload["arch"], payload["input_mode"], training, metrics)
    record = {
        "checkpoint": path.name,
        "arch": payload["arch"],
        "input_mode": payload["input_mode"],
        "command": training.get("command", ""),
        "training": {k: v for k, v in training.items() if k != "loss_history"},
        "final_loss": training["loss_history"][-1][1] if training.get("loss_history") else None,
        "metrics": metrics,
        **interpolation,
        **(extra or {}),
    }
    write_metrics_json(path, record)
    if payload.get("mask_threshold") is not None and not interpolation:
        record_mask_threshold(
            path, payload["mask_threshold"], payload.get("mask_threshold_record", {})
        )
    return path
