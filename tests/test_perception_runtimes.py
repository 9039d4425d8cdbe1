"""Contract test of the inference runtimes, plus the benchmark's FLOP and latency helpers."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch

from perception import runtimes
from perception.bench import conv_flops, measure_latency
from perception.runtimes import (
    InferenceRuntime,
    available_runtimes,
    cached_onnx,
    calibration_batches,
    select_runtime,
)
from perception.zoo import build_model

TOLERANCE = {"torch": 1e-5, "onnx": 1e-5, "tensorrt": 5e-3, "onnx-int8": 2e-2, "torch-bf16": 3e-2}
"""Probability tolerance per runtime: fp32 exact to rounding; TensorRT fp16; int8; bf16."""
ARCHS = ("k8-d2-d4-k2", "k8-p2-k8-d2-k2")  # plain and pooled (bilinear upsampling in the graph)


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("wireavoid-cache")


@pytest.fixture(scope="module", params=ARCHS)
def model(request):
    torch.manual_seed(7)
    return build_model(request.param).eval()


def reference_probability(model: torch.nn.Module, batch: np.ndarray) -> np.ndarray:
    """softmax(logits)[:, 1] in float64: what every runtime must reproduce."""
    model64 = build_model(model.name).double().eval()
    model64.load_state_dict({k: v.double() for k, v in model.state_dict().items()})
    with torch.no_grad():
        logits = model64(torch.from_numpy(batch.astype(np.float64)))
    return torch.softmax(logits, 1)[:, 1].numpy()


@pytest.mark.parametrize("name", available_runtimes())
def test_every_runtime_matches_the_float64_reference(name, model, cache_dir):
    runtime = select_runtime(name, model, "rgb", threads=1, cache_dir=cache_dir)
    assert isinstance(runtime, InferenceRuntime)
    assert runtime.name.startswith(name)
    batch = np.concatenate(calibration_batches("rgb", 2, 45, 62, seed=99))
    prob = runtime.probability(batch)
    assert prob.shape == (2, 45, 62) and prob.dtype == np.float32
    assert prob.min() >= 0.0 and prob.max() <= 1.0
    np.testing.assert_allclose(prob, reference_probability(model, batch), atol=TOLERANCE[name])


def test_onnx_export_is_cached_by_weights(cache_dir, monkeypatch):
    torch.manual_seed(0)
    model = build_model("k4-k2")
    first = cached_onnx(model, 3, cache_dir)
    monkeypatch.setattr(runtimes, "export_onnx", lambda *a: pytest.fail("exported twice"))
    assert cached_onnx(model, 3, cache_dir) == first
    with torch.no_grad():
        model.body[0].bias.add_(1.0)
    monkeypatch.undo()
    assert cached_onnx(model, 3, cache_dir) != first


def test_auto_and_unknown_runtime_names(cache_dir):
    model = build_model("k4-k2")
    auto = select_runtime("auto", model, "rgb", cache_dir=cache_dir)
    assert auto.name == available_runtimes()[0]
    with pytest.raises(ValueError, match="unknown runtime"):
        select_runtime("tflite", model, "rgb")  # type: ignore[arg-type]
    if "tensorrt" not in available_runtimes():
        with pytest.raises(RuntimeError, match="not available"):
            select_runtime("tensorrt", model, "rgb")


def test_conv_flops_by_hand():
    # k2 at 10x10: (2 * 2*3*9 + 2 biases) per px = 110 -> 11,000
    assert conv_flops(build_model("k2"), 10, 10) == 11_000
    # k8-p2-k2 at 5x5: conv 3->8 (2*216 + 8) * 25 = 11,000; ceil pool -> 3x3; conv 8->2
    # (2*144 + 2) * 9 = 2,610
    assert conv_flops(build_model("k8-p2-k2"), 5, 5) == 13_610
    # its skip, conv 8->2 at the full 5x5: (2*144 + 2) * 25 = 7,250
    assert conv_flops(build_model("k8-p2-k2-s"), 5, 5) == 13_610 + 7_250
    # the default model, 131,904 mult-add flops + 258 bias adds per pixel at 240x320
    assert conv_flops(build_model("k32-k32-d1-d2-d4-d8-d16-d1-k2"), 240, 320) == (
        (131_904 + 258) * 240 * 320
    )


def test_measure_latency_with_an_injected_clock():
    ticks = itertools.count(0.0, 0.5)  # each clock() call advances 0.5 s
    calls = []
    lat = measure_latency(lambda: calls.append(1), lambda: next(ticks), repeats=4, warmup=3)
    assert len(calls) == 7
    assert lat.median_ms == pytest.approx(500.0) and lat.min_ms == pytest.approx(500.0)
