"""Training (thesis 2.3.3): balanced loss, optimisers, checkpoints, resume, shipped weights."""

import json

import numpy as np
import pytest
import torch

from perception.checkpoint import (
    load_checkpoint,
    metrics_path,
    read_checkpoint,
    save_checkpoint,
    shipped_checkpoint_path,
    warm_start,
)
from perception.inputs import network_input
from perception.params import DEFAULT_MODEL, FAST_MODEL, SyntheticParams, TrainingParams
from perception.training.loop import (
    HELD_OUT_SEED,
    evaluate_model,
    lr_factor,
    make_optimizer,
    step_indices,
    train,
)
from perception.training.losses import class_balance_weights, class_balanced_cross_entropy
from perception.training.synthetic import synthetic_sample
from perception.zoo import build_model

EASY = SyntheticParams(
    no_wire_probability=0.0,
    width_floor_min_px=2.0,
    width_floor_max_px=3.0,
    contrast_min=0.4,
    contrast_max=0.5,
    photo_probability=0.0,
)
"""Thick, high-contrast wires: learnable within a few dozen steps of a tiny model."""


def tiny_params(**overrides) -> TrainingParams:
    base = dict(
        model="k16-k16-d1-d2-k2",
        steps=40,
        batch=4,
        crop_height_px=48,
        crop_width_px=64,
        workers=0,
        photo_sources=[],
        eval_count=0,
        checkpoint_every=20,
        bf16=False,
        learning_rate=1e-2,
        seed=1,
    )
    base.update(overrides)
    return TrainingParams(**base)


def held_out_batch(count=8, h=48, w=64, params=EASY):
    pairs = [synthetic_sample(HELD_OUT_SEED, i, h, w, params) for i in range(count)]
    x = torch.from_numpy(np.stack([network_input(im) for im, _ in pairs]))
    y = torch.from_numpy(np.stack([m for _, m in pairs]).astype(np.int64))
    return x, y


def test_class_balance_weights_follow_hed():
    target = torch.zeros(2, 10, 10, dtype=torch.long)
    target[0, 0, :5] = 1  # 5 % wire pixels: beta = 0.95
    w = class_balance_weights(target, beta_max=0.99)
    assert w[0, 0, 0].item() == pytest.approx(0.95)
    assert w[0, 5, 5].item() == pytest.approx(0.05)
    assert w[1].unique().tolist() == pytest.approx([0.01])  # no wire: capped beta 0.99
    # Balanced: both classes carry the same total weight in image 0.
    assert w[0][target[0] == 1].sum().item() == pytest.approx(w[0][target[0] == 0].sum().item())


def test_balanced_loss_is_cross_entropy_weighted():
    logits = torch.randn(1, 2, 4, 4)
    target = torch.zeros(1, 4, 4, dtype=torch.long)
    target[0, 1, 1] = 1
    nll = torch.nn.functional.cross_entropy(logits, target, reduction="none")
    expected = (nll * class_balance_weights(target)).mean()
    assert class_balanced_cross_entropy(logits, target).item() == pytest.approx(expected.item())


def test_optimizers_and_schedule():
    params = build_model("k8-k2").parameters()
    assert isinstance(make_optimizer("adadelta", params), torch.optim.Adadelta)
    with pytest.raises(ValueError):
        make_optimizer("sgd", build_model("k8-k2").parameters())
    assert lr_factor(0, 100, 0.1) == pytest.approx(1.0)
    assert lr_factor(100, 100, 0.1) == pytest.approx(0.1)
    assert lr_factor(50, 100, 0.1) == pytest.approx(0.55)


def test_step_indices_are_disjoint_across_ranks_and_steps():
    seen = [i for s in range(3) for r in range(2) for i in step_indices(s, r, 2, 4)]
    assert sorted(seen) == list(range(24))


def test_tiny_training_run_decreases_held_out_loss(tmp_path):
    params = tiny_params()
    x, y = held_out_batch()
    torch.manual_seed(params.seed)
    initial = build_model(params.model)
    with torch.no_grad():
        before = class_balanced_cross_entropy(initial(x), y).item()
    summary = train(params, tmp_path / "m.pt", progress=False, synthetic=EASY)
    model, meta = load_checkpoint(tmp_path / "m.pt")
    with torch.no_grad():
        after = class_balanced_cross_entropy(model(x), y).item()
    assert after < 0.95 * before  # measured 0.90 (deterministic: seeded data and init)
    history = summary["training"]["loss_history"]
    assert [h[0] for h in history] == [20, 40]
    assert meta["training"]["step"] == 40 and meta["arch"] == params.model


def test_checkpoint_round_trip(tmp_path):
    model = build_model("f6c2", in_channels=5)
    path = save_checkpoint(tmp_path / "c.pt", model, "f6c2", "rgble", {"step": 3}, {"ap": 0.5})
    loaded, meta = load_checkpoint(path)
    x = torch.randn(1, 5, 20, 30)
    with torch.no_grad():
        assert torch.equal(model.eval()(x), loaded(x))
    assert meta["input_mode"] == "rgble" and meta["in_channels"] == 5
    assert len(meta["normalisation"]["mean"]) == 5
    assert meta["training"] == {"step": 3} and meta["metrics"] == {"ap": 0.5}
    assert "optimizer_state" not in read_checkpoint(path)
    torch.save({"not": "ours"}, tmp_path / "x.pt")
    with pytest.raises(ValueError):
        load_checkpoint(tmp_path / "x.pt")


def test_warm_start_moves_weights_across_a_pooling_layer(tmp_path):
    flat = build_model("k16-k16-d1-d2-k2")
    save_checkpoint(tmp_path / "flat.pt", flat, "k16-k16-d1-d2-k2", "rgb")
    pooled = warm_start(build_model("k16-k16-p2-d1-d2-k2"), tmp_path / "flat.pt", "rgb")
    for a, b in zip(flat.parameters(), pooled.parameters(), strict=True):
        assert torch.equal(a, b)
    skipped = warm_start(build_model("k16-k16-p2-d1-d2-k2-s"), tmp_path / "flat.pt", "rgb")
    assert torch.equal(skipped.body[0].weight, flat.body[0].weight)
    assert not skipped.skip.weight.any()  # a skip the checkpoint lacks stays zero
    with pytest.raises(ValueError, match="weights"):
        warm_start(build_model("k16-k32-d1-d2-k2"), tmp_path / "flat.pt", "rgb")
    params = tiny_params(model="k16-k16-p2-d1-d2-k2", steps=2, init_from=str(tmp_path / "flat.pt"))
    train(params, tmp_path / "tuned.pt", progress=False, synthetic=EASY)
    tuned = read_checkpoint(tmp_path / "tuned.pt")["state_dict"]["body.0.weight"]
    assert 0 < (tuned - flat.body[0].weight).abs().max() < 0.05  # started from, then moved


class Interrupted(Exception):
    pass


def test_resume_continues_exactly_where_it_stopped(tmp_path):
    params = tiny_params(steps=12, checkpoint_every=6)
    train(params, tmp_path / "straight.pt", progress=False)

    def crash(step, _training):
        if step == 6:
            raise Interrupted

    with pytest.raises(Interrupted):
        train(params, tmp_path / "resumed.pt", progress=False, on_checkpoint=crash)
    assert read_checkpoint(tmp_path / "resumed.pt")["training"]["step"] == 6
    train(params, tmp_path / "resumed.pt", resume=True, progress=False)
    a = read_checkpoint(tmp_path / "straight.pt")["state_dict"]
    b = read_checkpoint(tmp_path / "resumed.pt")["state_dict"]
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=1e-4, atol=1e-5)


# Recorded at 240x320 on the 64 standard held-out images when the weights were shipped
# (default 0.67 exact and 0.86 with 2 px of tolerance; the pooled fast model's phase 4 0.602
# and 0.872, beside phase 3's 0.600 and 0.866 on the same images, which recorded 0.617 and
# 0.875 on the photo pool installed when it shipped); against the 0.9, these bounds
# guard against regressions, here and on a quick re-measurement.
SHIPPED_HELD_OUT_AP = {DEFAULT_MODEL: (0.67, 0.86), FAST_MODEL: (0.59, 0.86)}


@pytest.mark.parametrize("arch", sorted(SHIPPED_HELD_OUT_AP))
def test_shipped_model_finds_held_out_synthetic_wires(arch):
    path = shipped_checkpoint_path(arch)
    model, meta = load_checkpoint(path)
    assert meta["arch"] == arch and meta["input_mode"] == "rgb"
    record = json.loads(metrics_path(path).read_text())["metrics"]["held_out_synthetic"]
    exact, tol2px = SHIPPED_HELD_OUT_AP[arch]
    assert record["ap"] >= exact and record["ap_tol2px"] >= tol2px
    assert record["seed"] == HELD_OUT_SEED and record["n_images"] == 64
    pairs = [synthetic_sample(HELD_OUT_SEED, i, 120, 160) for i in range(12)]
    metrics = evaluate_model(model, "rgb", [p[0] for p in pairs], [p[1] for p in pairs])
    assert metrics["roc_auc"] > 0.9
    assert metrics["ap_tol2px"] > 0.88  # measured 0.91 (default), 0.94 (fast)
    assert metrics["ap_tol2px"] > metrics["ap"]


def test_grid_search_writes_a_table(tmp_path):
    from perception.training.grid_search import run_grid_search

    rows = run_grid_search(
        ["f6c1", "k8-d2-k2"],
        tmp_path,
        steps=3,
        batch=2,
        crop_hw_px=(32, 40),
        eval_count=2,
        latency_hw_px=(32, 40),
        photo_sources=(),
        progress=False,
    )
    assert [r["parameters"] for r in rows] == [10_722, 224 + 584 + 146]
    assert all(0 <= r["ap"] <= 1 and r["latency_ms"] > 0 for r in rows)
    table = (tmp_path / "table.md").read_text()
    assert "| f6c1 | k32-k32-k2 | 10,722 |" in table and "k8-d2-k2" in table
    assert json.loads((tmp_path / "table.json").read_text())[1]["label"] is None


def test_train_command_records_the_loss_schedule_and_photo_settings(tmp_path):
    from typer.testing import CliRunner

    from companion.cli import app

    out = tmp_path / "m.pt"
    args = [
        "train",
        "--model",
        "k8-d2-k2",
        "--steps",
        "2",
        "--batch",
        "2",
        "--crop",
        "32x40",
        "--workers",
        "0",
        "--eval-count",
        "0",
        "--no-bf16",
        "--photo-probability",
        "0",
        "--balance-beta-max",
        "0.9",
        "--final-lr-fraction",
        "0.5",
        "--contrast-min",
        "0.04",
        "--out",
        str(out),
    ]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    training = read_checkpoint(out)["training"]
    assert training["params"]["balance_beta_max"] == 0.9
    assert training["params"]["final_lr_fraction"] == 0.5
    assert training["synthetic"]["photo_probability"] == 0.0
    assert training["synthetic"]["contrast_min"] == 0.04
    assert json.loads(metrics_path(out).read_text())["training"]["step"] == 2


def test_rgble_model_warm_started_from_rgb_weights_starts_as_the_rgb_model(tmp_path):
    from perception.checkpoint import warm_start

    torch.manual_seed(0)
    rgb = build_model("k32-p2-d2-k2", 3).eval()
    path = save_checkpoint(tmp_path / "rgb.pt", rgb, "k32-p2-d2-k2", "rgb")
    rgble = warm_start(build_model("k32-p2-d2-k2", 5), path, "rgble").eval()
    image = synthetic_sample(3, 0, 48, 64)[0]
    with torch.no_grad():
        a = rgb(torch.from_numpy(network_input(image, "rgb"))[None])
        b = rgble(torch.from_numpy(network_input(image, "rgble"))[None])
    torch.testing.assert_close(a, b)
    save_checkpoint(tmp_path / "le.pt", rgble, "k32-p2-d2-k2", "rgble")
    with pytest.raises(ValueError, match="takes rgble input"):  # no way back to RGB
        warm_start(build_model("k32-p2-d2-k2", 3), tmp_path / "le.pt", "rgb")
