"""The grid search of thesis 2.4.2 on synthetic data: train, evaluate, time a subset of the zoo.

Each model is trained with the same ``TrainingParams`` (seed, data, steps), evaluated on the
same held-out synthetic set (AP, ROC AUC, ODS F1; 2.4.1) and timed on this machine's CPU with
batch 1 (torch eager, channels_last, fp32), giving a table like Table 2.2 with the thesis'
synthetic-training column replaced by held-out synthetic AP.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from perception.params import TrainingParams
from perception.zoo import build_model, grid_label, parameter_count, resolve_name


def cpu_latency_ms(name: str, in_channels: int, height_px: int, width_px: int) -> float:
    """Median batch-1 CPU latency of a randomly initialised model, torch eager fp32, ms."""
    from perception.bench import measure_latency
    from perception.runtimes import TorchRuntime

    runtime = TorchRuntime(build_model(name, in_channels))
    batch = np.zeros((1, in_channels, height_px, width_px), np.float32)
    return measure_latency(lambda: runtime.probability(batch), time.perf_counter, 5, 1).median_ms


def table_markdown(rows: list[dict[str, Any]], latency_hw_px: tuple[int, int]) -> str:
    """Table 2.2-like markdown: label, model, parameters, APs, ODS F1, AUC, CPU latency."""
    h, w = latency_hw_px
    lines = [
        f"| grid | model | params | AP | AP (2 px) | ODS F1 | ROC AUC | CPU ms {h}x{w} |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['label'] or '-'} | {r['model']} | {r['parameters']:,} | {r['ap']:.3f} | "
            f"{r['ap_tol2px']:.3f} | {r['ods_f1']:.3f} | {r['roc_auc']:.3f} | "
            f"{r['latency_ms']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def run_grid_search(
    models: list[str],
    out_dir: str | Path,
    steps: int,
    batch: int,
    crop_hw_px: tuple[int, int],
    input_mode: str = "rgb",
    optimizer: str = "adam",
    eval_count: int = 32,
    latency_hw_px: tuple[int, int] = (240, 320),
    photo_sources: tuple[str, ...] = ("skimage",),
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Train and evaluate each model; write ``table.md``, ``table.json`` and checkpoints."""
    from perception.inputs import input_channels
    from perception.training.loop import train

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in models:
        arch = resolve_name(name)
        label = grid_label(arch)
        params = TrainingParams(
            model=arch,
            input_mode=input_mode,
            steps=steps,
            batch=batch,
            crop_height_px=crop_hw_px[0],
            crop_width_px=crop_hw_px[1],
            optimizer=optimizer,
            eval_count=eval_count,
            photo_sources=list(photo_sources),
            checkpoint_every=steps,
        )
        start_s = time.perf_counter()
        summary = train(params, out / f"{label or arch}_{input_mode}.pt", progress=progress)
        held_out = summary["metrics"]["held_out_synthetic"]
        channels = input_channels(input_mode)
        rows.append(
            {
                "label": label,
                "model": arch,
                "parameters": parameter_count(build_model(arch, channels)),
                "ap": held_out["ap"],
                "ap_tol2px": held_out["ap_tol2px"],
                "ods_f1": held_out["ods_f1"],
                "roc_auc": held_out["roc_auc"],
                "latency_ms": cpu_latency_ms(arch, channels, *latency_hw_px),
                "train_s": time.perf_counter() - start_s,
                "final_loss": summary["training"]["loss_history"][-1][1],
            }
        )
        (out / "table.json").write_text(json.dumps(rows, indent=2) + "\n")
        (out / "table.md").write_text(table_markdown(rows, latency_hw_px))
    return rows
