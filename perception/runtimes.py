"""Inference runtimes behind one interface: torch eager, ONNX Runtime, TensorRT.

Every runtime maps a normalised network input batch (N, C, H, W) float32 (see
`perception.inputs`) to wire probabilities (N, H, W) float32 in [0, 1]: the softmax of the
two logits of thesis 2.3.1 is baked into the graph as sigmoid(l_wire - l_background), so no
runtime needs a post-pass. Construction may do I/O (ONNX export, engine build, caches);
`probability` does none.

`select_runtime("auto", ...)` prefers TensorRT (Jetson/GPU), then ONNX Runtime (the fastest
fp32 CPU path measured on the development machine), then torch; `wireavoid bench perception`
measures them side by side. Two reduced-precision CPU paths are opt-in by name: torch bf16
autocast ('torch-bf16', about 2x faster on AVX512-BF16 CPUs) and statically quantised int8
ONNX ('onnx-int8').

On the Jetson (JetPack ships `tensorrt` and a CUDA torch): `runtime="auto"` exports the ONNX
graph once, builds an fp16 TensorRT engine from it (minutes, on the first load only) and caches
it beside the graph in `default_cache_dir()`, keyed by model digest, TensorRT version and GPU.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import logging
import os
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Literal, Protocol, get_args, runtime_checkable

import numpy as np
import torch
from torch import nn

RuntimeName = Literal["auto", "torch", "torch-bf16", "onnx", "onnx-int8", "tensorrt"]
ONNX_OPSET = 18
"""ONNX opset of the export (ONNX Runtime >= 1.14; TensorRT 10, JetPack >= 6.1, parses it)."""


@runtime_checkable
class InferenceRuntime(Protocol):
    """A loaded model that turns network inputs into wire probabilities."""

    name: str
    """Short identifier: 'torch', 'torch-bf16', 'onnx', 'onnx-int8', 'tensorrt'."""

    def probability(self, batch: np.ndarray) -> np.ndarray:
        """(N, H, W) float32 wire probabilities in [0, 1] of an (N, C, H, W) float32 batch."""
        ...


class WireProbability(nn.Module):
    """Wraps a zoo model: (N, C, H, W) input -> (N, H, W) softmax probability of 'wire'."""

    def __init__(self, model: nn.Module) -> None:
        super().__init__()
        self.model = model

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """softmax(logits)[:, 1] = sigmoid(l_1 - l_0), computed in float32."""
        logits = self.model(x).float()
        return torch.sigmoid(logits[:, 1] - logits[:, 0])


def cpu_threads(requested: int = 0) -> int:
    """Threads for CPU inference: `requested`, or every core this process may run on if 0."""
    if requested > 0:
        return requested
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


class TorchRuntime:
    """Torch eager on CPU (channels_last; optional bf16 autocast) or CUDA.

    `threads` sets torch's process-wide intra-op thread count on CPU (0 = every core).
    """

    def __init__(
        self,
        model: nn.Module,
        threads: int = 0,
        channels_last: bool = True,
        bf16: bool = False,
        device: str = "cpu",
    ) -> None:
        self.name = "torch-bf16" if bf16 else "torch"
        self.device = torch.device(device)
        self.channels_last = channels_last
        self.bf16 = bf16
        self.module = WireProbability(model).eval().to(self.device)
        if channels_last:
            self.module = self.module.to(memory_format=torch.channels_last)
        if self.device.type == "cpu":
            torch.set_num_threads(cpu_threads(threads))

    def probability(self, batch: np.ndarray) -> np.ndarray:
        """(N, H, W) float32 probabilities of an (N, C, H, W) float32 batch."""
        x = torch.from_numpy(np.ascontiguousarray(batch, dtype=np.float32)).to(self.device)
        if self.channels_last:
            x = x.contiguous(memory_format=torch.channels_last)
        with (
            torch.inference_mode(),
            torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.bf16),
        ):
            return self.module(x).float().cpu().numpy()


def model_digest(model: nn.Module) -> str:
    """Hex SHA-256 of a model's architecture string and weights: the key of export caches."""
    h = hashlib.sha256(repr(model).encode())
    for key, value in model.state_dict().items():
        h.update(key.encode())
        h.update(value.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


def default_cache_dir() -> Path:
    """Where exported ONNX graphs and TensorRT engines are cached: $XDG_CACHE_HOME/wireavoid."""
    root = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(root) / "wireavoid"


@contextlib.contextmanager
def quiet_logging(name: str) -> Iterator[None]:
    """Raise logger `name` ('' = root) to ERROR for the duration of the block."""
    logger = logging.getLogger(name or None)
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def export_onnx(model: nn.Module, in_channels: int, path: Path) -> Path:
    """Export `WireProbability(model)` to ONNX at `path` with dynamic batch, height and width.

    Uses the torch.export-based exporter (`dynamo=True`, the default since torch 2.9), which
    needs the `onnxscript` package. Written to a temporary file and renamed, so a concurrent
    reader never sees half a graph.
    """
    module = WireProbability(model).eval()
    example = torch.zeros(2, in_channels, 64, 64)  # batch 2: size-1 dims would specialise
    batch = torch.export.Dim("batch", min=1, max=64)
    height = torch.export.Dim("height", min=16, max=8192)
    width = torch.export.Dim("width", min=16, max=8192)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    # quiet: "torchvision is not installed" notes and torch-internal pytree deprecations
    with quiet_logging("torch.onnx"), warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        program = torch.onnx.export(
            module,
            (example,),
            input_names=["image"],
            output_names=["wire_probability"],
            dynamic_shapes=({0: batch, 2: height, 3: width},),
            opset_version=ONNX_OPSET,
            dynamo=True,
            verbose=False,
        )
        program.save(str(tmp))
    tmp.replace(path)
    return path


def cached_onnx(model: nn.Module, in_channels: int, cache_dir: Path | None = None) -> Path:
    """Path of the ONNX export of `model`, exporting it on the first call (keyed by digest)."""
    cache_dir = cache_dir or default_cache_dir()
    key = f"{model_digest(model)[:20]}_c{in_channels}_opset{ONNX_OPSET}_torch{torch.__version__}"
    path = cache_dir / "onnx" / f"{key}.onnx"
    if not path.exists():
        export_onnx(model, in_channels, path)
    return path


class OnnxRuntime:
    """ONNX Runtime on the CPU execution provider, all graph optimisations on."""

    def __init__(self, onnx_path: Path, threads: int = 0, name: str = "onnx") -> None:
        import onnxruntime as ort

        self.name = name
        options = ort.SessionOptions()
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.intra_op_num_threads = cpu_threads(threads)
        options.inter_op_num_threads = 1
        options.log_severity_level = 3
        self.session = ort.InferenceSession(
            str(onnx_path), options, providers=["CPUExecutionProvider"]
        )
        self.input_name = self.session.get_inputs()[0].name

    def probability(self, batch: np.ndarray) -> np.ndarray:
        """(N, H, W) float32 probabilities of an (N, C, H, W) float32 batch."""
        x = np.ascontiguousarray(batch, dtype=np.float32)
        return self.session.run(None, {self.input_name: x})[0]


def tensorrt_available() -> bool:
    """True when the `tensorrt` Python package is importable and CUDA is usable (Jetson, GPU)."""
    return importlib.util.find_spec("tensorrt") is not None and torch.cuda.is_available()


class TensorRtRuntime:
    """TensorRT engine built from the ONNX export (Jetson / NVIDIA GPU), fp16 when supported.

    The engine is serialised to `engine_path` and reused. Its optimisation profile covers
    inputs from 16x16 to `max_hw_px`, tuned for `opt_hw_px` (the camera resolution). Buffers
    are torch CUDA tensors, so no pycuda is needed; TensorRT >= 8.6 API (`execute_async_v3`).
    """

    def __init__(
        self,
        onnx_path: Path,
        engine_path: Path,
        in_channels: int,
        opt_hw_px: tuple[int, int] = (480, 640),
        max_hw_px: tuple[int, int] = (1088, 1920),
        fp16: bool = True,
    ) -> None:
        import tensorrt as trt

        self.name = "tensorrt"
        self._logger = trt.Logger(trt.Logger.WARNING)
        if not engine_path.exists():
            engine_path.parent.mkdir(parents=True, exist_ok=True)
            engine_path.write_bytes(
                self._build(trt, onnx_path, in_channels, opt_hw_px, max_hw_px, fp16)
            )
        runtime = trt.Runtime(self._logger)
        self.engine = runtime.deserialize_cuda_engine(engine_path.read_bytes())
        self.context = self.engine.create_execution_context()
        self.stream = torch.cuda.Stream()

    def _build(self, trt, onnx_path, in_channels, opt_hw_px, max_hw_px, fp16) -> bytes:
        """Serialised engine of the ONNX graph with a dynamic-shape optimisation profile."""
        builder = trt.Builder(self._logger)
        # explicit batch: required by TensorRT 8.x, the default (flag ignored) from 10.0
        network = builder.create_network(1 << int(trt.NetworkDefinitionCreationFlag.EXPLICIT_BATCH))
        parser = trt.OnnxParser(network, self._logger)
        if not parser.parse(onnx_path.read_bytes()):
            errors = "; ".join(str(parser.get_error(i)) for i in range(parser.num_errors))
            raise RuntimeError(f"TensorRT could not parse {onnx_path}: {errors}")
        config = builder.create_builder_config()
        if fp16 and builder.platform_has_fast_fp16:
            config.set_flag(trt.BuilderFlag.FP16)
        profile = builder.create_optimization_profile()
        profile.set_shape(
            "image", (1, in_channels, 16, 16), (1, in_channels, *opt_hw_px),
            (1, in_channels, *max_hw_px),
        )  # fmt: skip
        config.add_optimization_profile(profile)
        serialised = builder.build_serialized_network(network, config)
        if serialised is None:
            raise RuntimeError(f"TensorRT failed to build an engine from {onnx_path}")
        return bytes(serialised)

    def probability(self, batch: np.ndarray) -> np.ndarray:
        """(N, H, W) float32 probabilities of an (N, C, H, W) float32 batch (run one by one)."""
        outputs = []
        for image in np.ascontiguousarray(batch, dtype=np.float32):
            x = torch.from_numpy(image[None]).cuda()
            y = torch.empty((1, *x.shape[2:]), dtype=torch.float32, device="cuda")
            self.context.set_input_shape("image", tuple(x.shape))
            self.context.set_tensor_address("image", x.data_ptr())
            self.context.set_tensor_address("wire_probability", y.data_ptr())
            if not self.context.execute_async_v3(self.stream.cuda_stream):
                raise RuntimeError("TensorRT execution failed")
            self.stream.synchronize()
            outputs.append(y.cpu().numpy())
        return np.concatenate(outputs)


def calibration_batches(
    input_mode: str, count: int = 8, height_px: int = 240, width_px: int = 320, seed: int = 8128
) -> list[np.ndarray]:
    """(1, C, H, W) float32 network inputs of seeded synthetic wire images (2.3.2), for int8
    calibration: the activation ranges of scenes with wires, not of random noise."""
    from perception.inputs import network_input
    from perception.training.synthetic import synthetic_sample

    images = [synthetic_sample(seed, i, height_px, width_px)[0] for i in range(count)]
    return [network_input(image, input_mode)[None] for image in images]  # type: ignore[arg-type]


def cpu_has_vnni() -> bool:
    """True if this x86 CPU has int8 dot products (AVX512-VNNI or AVX-VNNI); False elsewhere."""
    try:
        flags = Path("/proc/cpuinfo").read_text().split()
    except OSError:
        return False
    return "avx512_vnni" in flags or "avx_vnni" in flags


def quantized_onnx(onnx_path: Path, calibration: list[np.ndarray]) -> Path:
    """Path of the int8 version of an ONNX graph, quantising it on the first call.

    Static quantisation by ONNX Runtime (QOperator format: QLinearConv, which uses AVX512-VNNI
    / AVX-VNNI int8 dot products): per-channel int8 weights, uint8 activations with MinMax
    ranges from `calibration` (network input batches). Without VNNI, ONNX Runtime multiplies
    u8 x s8 with VPMADDUBSW, whose int16 sums saturate; there the weights are quantised to
    7 bits (`reduce_range`), as ONNX Runtime's documentation advises. Cached beside the fp32
    graph, keyed by a digest of the calibration data and the weight range.
    """
    from onnxruntime.quantization import (
        CalibrationDataReader,
        QuantFormat,
        QuantType,
        quantize_static,
    )

    reduce_range = not cpu_has_vnni()
    digest = hashlib.sha256(b"".join(c.tobytes() for c in calibration)).hexdigest()[:12]
    bits = "7bit" if reduce_range else "8bit"
    path = onnx_path.with_name(f"{onnx_path.stem}_int8_{bits}_{digest}.onnx")
    if path.exists():
        return path

    class Reader(CalibrationDataReader):
        def __init__(self) -> None:
            self.batches = iter(calibration)

        def get_next(self) -> dict[str, np.ndarray] | None:
            batch = next(self.batches, None)
            return None if batch is None else {"image": batch}

    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    with quiet_logging(""):  # the root logger's "consider pre-processing" advice
        quantize_static(
            str(onnx_path),
            str(tmp),
            Reader(),
            quant_format=QuantFormat.QOperator,
            per_channel=True,
            weight_type=QuantType.QInt8,
            activation_type=QuantType.QUInt8,
            reduce_range=reduce_range,
        )
    tmp.replace(path)
    return path


def available_runtimes() -> list[str]:
    """Concrete runtimes usable in this process: full precision first, fastest first
    (TensorRT > ONNX > torch), then the reduced-precision CPU ones ('onnx-int8', and
    'torch-bf16' where oneDNN has bf16 kernels), which are used only when named."""
    names = ["tensorrt"] if tensorrt_available() else []
    onnx = importlib.util.find_spec("onnxruntime") and importlib.util.find_spec("onnxscript")
    names += ["onnx", "torch", "onnx-int8"] if onnx else ["torch"]
    if torch.ops.mkldnn._is_mkldnn_bf16_supported():
        names.append("torch-bf16")
    return names


def select_runtime(
    name: RuntimeName,
    model: nn.Module,
    input_mode: str = "rgb",
    threads: int = 0,
    cache_dir: Path | None = None,
) -> InferenceRuntime:
    """The runtime called `name` for `model`, which takes `input_mode` inputs.

    'auto' takes the first of `available_runtimes()`, never a reduced-precision CPU one.
    Raises ValueError for an unknown name and RuntimeError when a named runtime is missing.
    """
    from perception.inputs import input_channels

    if name == "auto":
        name = available_runtimes()[0]  # type: ignore[assignment]
    if name not in get_args(RuntimeName):
        raise ValueError(f"unknown runtime {name!r}; expected one of {get_args(RuntimeName)}")
    if name not in available_runtimes():
        raise RuntimeError(f"runtime {name!r} is not available here: {available_runtimes()}")
    if name in ("torch", "torch-bf16"):
        device = "cuda" if torch.cuda.is_available() else "cpu"
        return TorchRuntime(model, threads=threads, bf16=name == "torch-bf16", device=device)
    channels = input_channels(input_mode)
    onnx_path = cached_onnx(model, channels, cache_dir)
    if name == "onnx":
        return OnnxRuntime(onnx_path, threads=threads)
    if name == "onnx-int8":
        int8_path = quantized_onnx(onnx_path, calibration_batches(input_mode))
        return OnnxRuntime(int8_path, threads=threads, name="onnx-int8")
    import tensorrt as trt

    device = torch.cuda.get_device_name().replace(" ", "_")
    engine = onnx_path.with_name(f"{onnx_path.stem}_trt{trt.__version__}_{device}.engine")
    return TensorRtRuntime(onnx_path, engine, channels)
