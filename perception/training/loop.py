"""Training of zoo models on synthetic wires (thesis 2.3.3, 2.4.2), on CPU or GPU, with DDP.

- Data: ``SyntheticWireDataset`` generated on the fly; step s of rank r uses the images
  ``(seed, (s * world + r) * batch + i)``, so a run is reproducible and resumes exactly.
- Loss: HED class-balanced cross-entropy (``perception.training.losses``, 2.3.3).
- Optimisers: Adam or AdaDelta (the thesis' choice, 2.4.2), cosine-decayed learning rate.
- Speed: channels_last and bf16 autocast (CPU with AVX512-BF16/AMX, or CUDA).
- Checkpoints every ``checkpoint_every`` steps (atomic), resumable with the optimiser state.
- DDP: launched by ``torchrun --nproc-per-node N`` (WORLD_SIZE > 1), NCCL on GPUs, else gloo;
  rank 0 writes checkpoints, evaluates and shows progress.
- Held-out evaluation: ``eval_count`` images of the fixed held-out seed ``HELD_OUT_SEED``.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from perception.checkpoint import read_checkpoint, save_checkpoint, warm_start
from perception.inputs import input_channels, network_input
from perception.params import SyntheticParams, TrainingParams
from perception.training.losses import class_balanced_cross_entropy
from perception.training.synthetic import SyntheticWireDataset, rendered_sample
from perception.zoo import build_model, resolve_name

HELD_OUT_SEED = 1_000_000
"""Seed of the held-out synthetic set; training seeds are below it."""


def bf16_supported(device: torch.device) -> bool:
    """Whether bf16 autocast is fast here: CUDA with bf16, or a CPU with AVX512-BF16 / AMX."""
    if device.type == "cuda":
        return torch.cuda.is_bf16_supported()
    capability = torch.backends.cpu.get_cpu_capability()
    if capability == "AVX512_BF16" or "AMX" in capability:
        return True
    if os.path.exists("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as f:
            flags = f.read()
        return "avx512_bf16" in flags or "amx_bf16" in flags
    return False


def make_optimizer(name: str, parameters, learning_rate: float = 0.0) -> torch.optim.Optimizer:
    """Adam (default lr 1e-3) or AdaDelta (default lr 1.0, thesis 2.4.2)."""
    if name == "adam":
        return torch.optim.Adam(parameters, lr=learning_rate or 1e-3)
    if name == "adadelta":
        return torch.optim.Adadelta(parameters, lr=learning_rate or 1.0)
    raise ValueError(f"unknown optimizer {name!r}; expected adam or adadelta")


def lr_factor(step: int, steps: int, final_fraction: float) -> float:
    """Cosine decay of the learning rate from 1 to final_fraction over the run."""
    progress = min(max(step / max(steps, 1), 0.0), 1.0)
    return final_fraction + (1 - final_fraction) * 0.5 * (1 + math.cos(math.pi * progress))


def step_indices(step: int, rank: int, world: int, batch: int) -> list[int]:
    """Synthetic image indices of one step on one rank: disjoint across ranks and steps."""
    first = (step * world + rank) * batch
    return list(range(first, first + batch))


def _distributed() -> tuple[int, int, torch.device]:
    """(rank, world size, device); initialises the process group under torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not torch.distributed.is_initialized():
        backend = "nccl" if torch.cuda.is_available() else "gloo"
        torch.distributed.init_process_group(backend)
    rank = int(os.environ.get("RANK", "0"))
    if torch.cuda.is_available():
        local = int(os.environ.get("LOCAL_RANK", "0"))
        torch.cuda.set_device(local)
        return rank, world, torch.device("cuda", local)
    return rank, world, torch.device("cpu")


def wire_probabilities(
    model: nn.Module, images_rgb: list[np.ndarray], mode: str
) -> list[np.ndarray]:
    """(H, W) float32 wire probabilities of RGB uint8 images, one by one (torch runtime, fp32)."""
    from perception.runtimes import TorchRuntime

    device = next(model.parameters()).device
    runtime = TorchRuntime(model, threads=torch.get_num_threads(), device=str(device))
    batches = (network_input(image, mode)[None] for image in images_rgb)  # type: ignore[arg-type]
    return [runtime.probability(x)[0] for x in batches]


def held_out_set(
    count: int,
    height_px: int,
    width_px: int,
    params: SyntheticParams | None = None,
    photo_sources: tuple[str, ...] = (),
) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """The first `count` held-out synthetic (images, masks, coverages), seed ``HELD_OUT_SEED``;
    coverages: the wires' anti-aliased footprints (`rendered_sample`)."""
    dataset = SyntheticWireDataset(
        HELD_OUT_SEED, count, height_px, width_px, "rgb", params, photo_sources
    )
    samples = [
        rendered_sample(HELD_OUT_SEED, i, height_px, width_px, dataset.params, dataset.pool)
        for i in range(count)
    ]
    images, masks, coverages = zip(*samples, strict=True)
    return list(images), list(masks), list(coverages)


def coverage_ceiling_ap(masks: list[np.ndarray], coverages: list[np.ndarray]) -> float:
    """Pixel-exact AP (2.4.1) of the renderer's own anti-aliased coverage as the prediction.

    What an ideal detector of the rendering, before blur, noise and JPEG, would score: near 1,
    since labels mark the drawn footprint (`perception.training.labels.label_mask`); what a
    network loses below it is detection, not label ambiguity.
    """
    from perception.metrics import evaluate_predictions

    return evaluate_predictions(coverages, masks, tolerance_px=0).ap


def evaluate_model(
    model: nn.Module, mode: str, images: list[np.ndarray], masks: list[np.ndarray]
) -> dict[str, float]:
    """AP, ROC AUC, ODS/OIS F1 (2.4.1), exact and with 1 and 2 px tolerance, of a model."""
    from perception.metrics import evaluate_predictions

    probs = wire_probabilities(model, images, mode)
    exact = evaluate_predictions(probs, masks, tolerance_px=0)
    relaxed = evaluate_predictions(probs, masks, tolerance_px=2)
    return {
        "ap": exact.ap,
        "roc_auc": exact.roc_auc,
        "ods_f1": exact.ods_f1,
        "ods_threshold": exact.ods_threshold,
        "ois_f1": exact.ois_f1,
        "ap_tol1px": evaluate_predictions(probs, masks, tolerance_px=1).ap,
        "ap_tol2px": relaxed.ap,
        "ods_f1_tol2px": relaxed.ods_f1,
        "n_images": exact.n_images,
    }


def train(
    params: TrainingParams,
    out_path: str | os.PathLike,
    resume: bool = False,
    synthetic: SyntheticParams | None = None,
    progress: bool = True,
    command: str = "",
    on_checkpoint: Callable[[int, dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Train `params.model` on synthetic data; write checkpoints to `out_path`; return a summary.

    The summary (also stored in the checkpoint's ``training``/``metrics``) holds the loss
    history (mean per 20 steps), seconds per step, and the held-out metrics when eval_count > 0.
    """
    from tqdm import tqdm

    out_path = Path(out_path)
    rank, world, device = _distributed()
    arch = resolve_name(params.model)
    torch.manual_seed(params.seed)
    model = build_model(arch, input_channels(params.input_mode)).to(device)
    model = model.to(memory_format=torch.channels_last)
    optimizer = make_optimizer(params.optimizer, model.parameters(), params.learning_rate)
    start, history = 0, []
    if resume and out_path.exists():
        payload = read_checkpoint(out_path)
        if payload["arch"] != arch or payload["input_mode"] != params.input_mode:
            raise ValueError(f"{out_path} holds {payload['arch']} {payload['input_mode']}")
        model.load_state_dict(payload["state_dict"])
        if "optimizer_state" in payload:
            optimizer.load_state_dict(payload["optimizer_state"])
        start = int(payload["training"].get("step", 0))
        history = list(payload["training"].get("loss_history", []))
    elif params.init_from:
        warm_start(model, params.init_from, params.input_mode)
    net: nn.Module = model
    if world > 1:
        net = nn.parallel.DistributedDataParallel(
            model, device_ids=[device.index] if device.type == "cuda" else None
        )
    dataset = SyntheticWireDataset(
        params.seed,
        (params.steps * world + world) * params.batch,
        params.crop_height_px,
        params.crop_width_px,
        params.input_mode,
        synthetic,
        tuple(params.photo_sources),
        tuple(params.frame_folders),
        params.frames_share,
    )
    indices = [
        i for s in range(start, params.steps) for i in step_indices(s, rank, world, params.batch)
    ]
    loader = torch.utils.data.DataLoader(
        dataset,
        batch_size=params.batch,
        sampler=indices,
        num_workers=params.workers,
        pin_memory=device.type == "cuda",
        prefetch_factor=4 if params.workers > 0 else None,
    )
    use_bf16 = params.bf16 and bf16_supported(device)
    base_lr = optimizer.defaults["lr"]  # constructor's lr, unchanged by a resumed state
    training: dict[str, Any] = {
        "arch": arch,
        "params": params.model_dump(),
        "synthetic": (synthetic or SyntheticParams()).model_dump(),
        "command": command,
        "world_size": world,
        "device": str(device),
        "bf16": use_bf16,
        "torch": str(torch.__version__),
    }

    def checkpoint(step: int) -> None:
        if rank != 0:
            return
        training.update(step=step, loss_history=history)
        save_checkpoint(out_path, model, arch, params.input_mode, training, optimizer=optimizer)
        if on_checkpoint is not None:
            on_checkpoint(step, training)

    bar = tqdm(total=params.steps, initial=start, disable=not progress or rank != 0, desc=arch)
    window: list[float] = []
    t0 = time.perf_counter()
    step = start
    net.train()
    for x, y in loader:
        for group in optimizer.param_groups:
            group["lr"] = base_lr * lr_factor(step, params.steps, params.final_lr_fraction)
        x = x.to(device, non_blocking=True).contiguous(memory_format=torch.channels_last)
        y = y.to(device, non_blocking=True)
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=use_bf16):
            logits = net(x)
        loss = class_balanced_cross_entropy(logits, y, params.balance_beta_max)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        step += 1
        window.append(float(loss.detach()))
        if len(window) == 20 or step == params.steps:
            history.append([step, float(np.mean(window))])
            bar.set_postfix(loss=f"{history[-1][1]:.4f}")
            window = []
        bar.update(1)
        if step % params.checkpoint_every == 0 or step == params.steps:
            checkpoint(step)
    bar.close()
    elapsed = time.perf_counter() - t0
    training["seconds_per_step"] = elapsed / max(step - start, 1)
    metrics: dict[str, Any] = {}
    if rank == 0 and params.eval_count > 0:
        images, masks, coverages = held_out_set(
            params.eval_count,
            params.eval_height_px,
            params.eval_width_px,
            synthetic,
            tuple(params.photo_sources),
        )
        metrics = {"held_out_synthetic": evaluate_model(model, params.input_mode, images, masks)}
        metrics["held_out_synthetic"].update(
            seed=HELD_OUT_SEED,
            height_px=params.eval_height_px,
            width_px=params.eval_width_px,
            coverage_ceiling_ap=coverage_ceiling_ap(masks, coverages),
        )
    if rank == 0:
        training.update(step=step, loss_history=history)
        save_checkpoint(out_path, model, arch, params.input_mode, training, metrics, optimizer)
    if world > 1:
        torch.distributed.destroy_process_group()
    return {"training": training, "metrics": metrics}
