"""`wireavoid` commands of the training domain: zoo, synth, train, grid-search (thesis ch. 2)."""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path
from typing import Annotated

import typer

from perception.params import DEFAULT_MODEL, SyntheticParams, TrainingParams

_TRAINING = TrainingParams()  # the option defaults below come from the typed params
_SYNTHETIC = SyntheticParams()
PhotosOption = Annotated[
    list[str] | None,
    typer.Option(
        "--photos",
        help="real-photo backgrounds: 'skimage' and/or folders (repeatable; default: skimage)",
    ),
]


def _photos(photos: list[str] | None) -> tuple[str, ...]:
    """Photo sources, 'skimage' by default."""
    return tuple(photos or _TRAINING.photo_sources)


def _hw(text: str) -> tuple[int, int]:
    """'HxW' -> (H, W) pixels."""
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise typer.BadParameter(f"expected HxW, e.g. 176x240, got {text!r}") from exc
    return h, w


def zoo(
    names: Annotated[
        list[str] | None, typer.Argument(help="names or grid labels (default: all 30)")
    ] = None,
    in_channels: Annotated[int, typer.Option(help="input channels: 3 (RGB) or 5 (RGBLE)")] = 3,
    as_json: Annotated[bool, typer.Option("--json", help="print JSON")] = False,
) -> None:
    """List zoo models (Table 2.1 grid) with their parameter counts (Table 2.3)."""
    from perception.zoo import ZOO, build_model, grid_label, parameter_count, resolve_name

    rows = []
    for name in names or list(ZOO):
        arch = resolve_name(name)
        try:
            count = parameter_count(build_model(arch, in_channels))
        except ValueError as exc:
            raise typer.BadParameter(str(exc)) from exc
        rows.append({"label": grid_label(arch), "model": arch, "parameters": count})
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    for row in rows:
        typer.echo(f"{row['label'] or '-':5} {row['parameters']:>10,}  {row['model']}")


def synth(
    out: Annotated[Path, typer.Option(help="output folder: images/, masks/, synth.json")] = Path(
        "synthetic-wires"
    ),
    count: Annotated[int, typer.Option(min=1, help="number of images")] = 100,
    seed: Annotated[int, typer.Option(help="dataset seed (the held-out set uses 1000000)")] = 0,
    size: Annotated[str, typer.Option(help="image size HxW, px")] = "240x320",
    photos: PhotosOption = None,
) -> None:
    """Write a synthetic wire dataset: RGB PNG images and 0/255 PNG masks (2.3.2)."""
    from perception.training.synthetic import write_dataset

    h, w = _hw(size)
    path = write_dataset(out, count, seed, h, w, photo_sources=_photos(photos))
    typer.echo(f"wrote {count} images and masks to {path}")


def real_photos(
    out: Annotated[Path, typer.Option(help="output folder: images/, masks/")] = Path("real-wires"),
    annotations: Annotated[
        Path | None, typer.Option(help="annotation JSON (default: the committed set)")
    ] = None,
    dev: Annotated[
        bool,
        typer.Option(
            "--dev",
            help="the development set: the committed set plus perception/data/real_dev.json",
        ),
    ] = False,
) -> None:
    """Write the labelled real photographs that are installed (images/, masks/) for `evaluate`.

    The photos come from Debian packages; a missing or changed photo is skipped with a note.
    """
    import hashlib

    import cv2
    import numpy as np

    from perception.training.real_photos import (
        ANNOTATIONS,
        DEV_ANNOTATIONS,
        labelled_photos,
        wire_mask,
    )

    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "masks").mkdir(parents=True, exist_ok=True)
    written, missing = 0, set()
    photos = labelled_photos(annotations or ANNOTATIONS)
    if dev:
        photos += labelled_photos(DEV_ANNOTATIONS)
    for photo in photos:
        if not photo.path.is_file():
            missing.add(photo.debian_package)
            typer.echo(f"skipped {photo.name}: {photo.path} is not installed", err=True)
            continue
        data = photo.path.read_bytes()
        if hashlib.sha256(data).hexdigest() != photo.sha256:
            typer.echo(f"skipped {photo.name}: {photo.path} is not the labelled file", err=True)
            continue
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        h, w = photo.size_px
        image = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(out / "images" / f"{photo.name}.png"), image)
        cv2.imwrite(str(out / "masks" / f"{photo.name}.png"), wire_mask(photo) * 255)
        written += 1
    if missing:
        typer.echo(f"to add them: apt-get install {' '.join(sorted(missing))}", err=True)
    if written == 0:
        raise typer.BadParameter("none of the labelled photos is installed")
    typer.echo(f"wrote {written} labelled photos to {out}")


def train(
    model: Annotated[str, typer.Option(help="zoo name or grid label")] = DEFAULT_MODEL,
    steps: Annotated[int, typer.Option(min=1, help="optimiser steps")] = _TRAINING.steps,
    batch: Annotated[
        int, typer.Option(min=1, help="images per step and process")
    ] = _TRAINING.batch,
    crop: Annotated[str, typer.Option(help="training image size HxW, px")] = (
        f"{_TRAINING.crop_height_px}x{_TRAINING.crop_width_px}"
    ),
    input_mode: Annotated[
        str, typer.Option("--input", help="rgb or rgble (2.3.4)")
    ] = _TRAINING.input_mode,
    optimizer: Annotated[str, typer.Option(help="adam or adadelta (2.4.2)")] = _TRAINING.optimizer,
    lr: Annotated[float, typer.Option(help="learning rate; 0 = optimiser default")] = (
        _TRAINING.learning_rate
    ),
    final_lr_fraction: Annotated[
        float, typer.Option(help="cosine decay of the learning rate down to this fraction")
    ] = _TRAINING.final_lr_fraction,
    balance_beta_max: Annotated[
        float, typer.Option(help="cap of the HED class-balance weight beta (2.3.3)")
    ] = _TRAINING.balance_beta_max,
    seed: Annotated[
        int, typer.Option(help="training data and initialisation seed")
    ] = _TRAINING.seed,
    workers: Annotated[int, typer.Option(min=0, help="data-generation worker processes")] = (
        _TRAINING.workers
    ),
    photos: PhotosOption = None,
    frames: Annotated[
        list[Path] | None,
        typer.Option(
            "--frames",
            help="labelled image folder mixed into the batches (repeatable; `wireavoid "
            "sil-frames` writes one)",
        ),
    ] = None,
    frames_share: Annotated[
        float, typer.Option(min=0, max=1, help="share of the items cropped from --frames")
    ] = _TRAINING.frames_share,
    photo_probability: Annotated[
        float, typer.Option(min=0, max=1, help="share of backgrounds that are real photos")
    ] = _SYNTHETIC.photo_probability,
    contrast_min: Annotated[
        float,
        typer.Option(min=0, max=1, help="least wire-background luminance difference (0-1)"),
    ] = _SYNTHETIC.contrast_min,
    aerial_probability: Annotated[
        float,
        typer.Option(min=0, max=1, help="share of views pitched down at cluttered ground"),
    ] = _SYNTHETIC.aerial_probability,
    horizon_wire_probability: Annotated[
        float,
        typer.Option(min=0, max=1, help="share of forward views with a level wire on the horizon"),
    ] = _SYNTHETIC.horizon_wire_probability,
    horizon_contrast_min: Annotated[
        float,
        typer.Option(min=0, max=1, help="least luminance difference of those horizon wires"),
    ] = _SYNTHETIC.horizon_contrast_min,
    ground_shadow_probability: Annotated[
        float,
        typer.Option(min=0, max=1, help="share of forward views with wire shadows on the ground"),
    ] = _SYNTHETIC.ground_shadow_probability,
    perspective_cloud_probability: Annotated[
        float,
        typer.Option(min=0, max=1, help="share of cloudy skies with clouds in perspective"),
    ] = _SYNTHETIC.perspective_cloud_probability,
    fittings_probability: Annotated[
        float, typer.Option(min=0, max=1, help="share of bundles with insulators and spacers")
    ] = _SYNTHETIC.fittings_probability,
    tower_probability: Annotated[
        float, typer.Option(min=0, max=1, help="share of supported bundles on lattice towers")
    ] = _SYNTHETIC.tower_probability,
    sensor_effects_probability: Annotated[
        float,
        typer.Option(
            min=0, max=1, help="share of images with vignetting, over-exposure, resampling"
        ),
    ] = _SYNTHETIC.sensor_effects_probability,
    checkpoint_every: Annotated[int, typer.Option(min=1, help="steps between checkpoints")] = (
        _TRAINING.checkpoint_every
    ),
    eval_count: Annotated[
        int, typer.Option(min=0, help="held-out images evaluated")
    ] = _TRAINING.eval_count,
    bf16: Annotated[bool, typer.Option(help="bf16 autocast where supported")] = _TRAINING.bf16,
    out: Annotated[Path, typer.Option(help="checkpoint .pt; metrics JSON beside it")] = Path(
        "wire-model.pt"
    ),
    resume: Annotated[bool, typer.Option(help="continue from the checkpoint at --out")] = False,
    init_from: Annotated[
        Path | None,
        typer.Option(help="start from this checkpoint's weights (same shapes, layer by layer)"),
    ] = None,
) -> None:
    """Train a zoo model on on-the-fly synthetic wires (2.3.3); torchrun for DDP."""
    from perception.checkpoint import write_metrics_json
    from perception.training.loop import train as run_training

    h, w = _hw(crop)
    params = TrainingParams(
        model=model,
        input_mode=input_mode,
        steps=steps,
        batch=batch,
        crop_height_px=h,
        crop_width_px=w,
        optimizer=optimizer,
        learning_rate=lr,
        final_lr_fraction=final_lr_fraction,
        balance_beta_max=balance_beta_max,
        seed=seed,
        workers=workers,
        photo_sources=list(_photos(photos)),
        frame_folders=[str(f) for f in frames or []],
        frames_share=frames_share,
        checkpoint_every=checkpoint_every,
        eval_count=eval_count,
        bf16=bf16,
        init_from=str(init_from or ""),
    )
    command = "wireavoid " + shlex.join(sys.argv[1:])
    synthetic = SyntheticParams(
        photo_probability=photo_probability,
        contrast_min=contrast_min,
        aerial_probability=aerial_probability,
        horizon_wire_probability=horizon_wire_probability,
        horizon_contrast_min=horizon_contrast_min,
        ground_shadow_probability=ground_shadow_probability,
        perspective_cloud_probability=perspective_cloud_probability,
        fittings_probability=fittings_probability,
        tower_probability=tower_probability,
        sensor_effects_probability=sensor_effects_probability,
    )
    summary = run_training(params, out, resume=resume, synthetic=synthetic, command=command)
    if _rank0():
        record = {
            "checkpoint": out.name,
            "command": command,
            "training": {k: v for k, v in summary["training"].items() if k != "loss_history"},
            "final_loss": summary["training"]["loss_history"][-1][1]
            if summary["training"]["loss_history"]
            else None,
            "metrics": summary["metrics"],
        }
        write_metrics_json(out, record)
        typer.echo(json.dumps(summary["metrics"], indent=2))


def ship_weights(
    src: Annotated[Path, typer.Argument(help="trained checkpoint (.pt)")],
    dst: Annotated[
        Path | None, typer.Option(help="default: perception/weights/ARCH_MODE.pt")
    ] = None,
    interpolate_with: Annotated[
        Path | None,
        typer.Option(
            help="write alpha * SRC + (1 - alpha) * this checkpoint (same architecture; usually "
            "the weights SRC was fine-tuned from): WiSE-FT's weight-space ensemble"
        ),
    ] = None,
    alpha: Annotated[
        float, typer.Option(min=0.0, max=1.0, help="SRC's share with --interpolate-with")
    ] = 1.0,
) -> None:
    """Copy a trained checkpoint without optimiser state into perception/weights/ + its JSON.

    With --interpolate-with REF --alpha A the weights written are A * SRC + (1 - A) * REF
    (WiSE-FT, Wortsman et al. 2022): a fine-tune blended with the weights it started from,
    which keeps part of what the fine-tune forgot. SRC's metrics and mask threshold are not
    carried over; run `calibrate-threshold` on the result.
    """
    from perception.checkpoint import WEIGHTS_DIR, read_checkpoint, ship_checkpoint

    try:
        payload = read_checkpoint(src)
        target = dst or WEIGHTS_DIR / f"{payload['arch']}_{payload['input_mode']}.pt"
        written = ship_checkpoint(src, target, interpolate_with=interpolate_with, alpha=alpha)
    except (OSError, ValueError) as err:
        raise typer.BadParameter(str(err)) from err
    blend = (
        "" if interpolate_with is None else f" ({alpha:g} of {src}, the rest {interpolate_with})"
    )
    typer.echo(f"wrote {written}{blend}")


def _rank0() -> bool:
    """Whether this process is rank 0 of a torchrun launch (or not launched by torchrun)."""
    import os

    return os.environ.get("RANK", "0") == "0"


def grid_search(
    models: Annotated[
        list[str] | None, typer.Option("--models", help="grid labels or names (repeatable)")
    ] = None,
    steps: Annotated[int, typer.Option(min=1, help="training steps per model")] = 300,
    batch: Annotated[int, typer.Option(min=1)] = 8,
    crop: Annotated[str, typer.Option(help="training image size HxW, px")] = "128x160",
    input_mode: Annotated[str, typer.Option("--input", help="rgb or rgble")] = "rgb",
    optimizer: Annotated[str, typer.Option()] = "adam",
    eval_count: Annotated[int, typer.Option(min=1, help="held-out images per model")] = 32,
    latency_size: Annotated[str, typer.Option(help="CPU latency measured at HxW, px")] = "240x320",
    photos: PhotosOption = None,
    out: Annotated[Path, typer.Option(help="folder: checkpoints, table.md, table.json")] = Path(
        "grid-search"
    ),
) -> None:
    """Train and evaluate a subset of the zoo; write a Table 2.2-like table (2.4.2)."""
    from perception.training.grid_search import run_grid_search

    h, w = _hw(crop)
    lh, lw = _hw(latency_size)
    rows = run_grid_search(
        models or ["f6c1", "f6c3", "f6c5"],
        out,
        steps=steps,
        batch=batch,
        crop_hw_px=(h, w),
        input_mode=input_mode,
        optimizer=optimizer,
        eval_count=eval_count,
        latency_hw_px=(lh, lw),
        photo_sources=_photos(photos),
    )
    typer.echo((out / "table.md").read_text())
    typer.echo(f"{len(rows)} models; table in {out / 'table.md'}")


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add this domain's commands to the root app and its benchmarks to `wireavoid bench`."""
    app.command("zoo")(zoo)
    app.command("synth")(synth)
    app.command("real-photos")(real_photos)
    app.command("train")(train)
    app.command("grid-search")(grid_search)
    app.command("ship-weights")(ship_weights)
