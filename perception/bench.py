"""Inference benchmark pieces: analytic FLOP counts, latency statistics, the fp32 GEMM peak.

The clock is passed in (`clock() -> s`, e.g. `time.perf_counter`), so this module keeps no
wall clock of its own; `wireavoid bench perception` wires it to the runtimes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn


def conv_flops(model: nn.Module, height_px: int, width_px: int) -> int:
    """Floating-point operations of one forward pass, counted from the conv layers.

    2 x (multiply-adds) + bias adds of every `Conv2d`, at the output size each one has in a
    forward pass of a (1, C, height_px, width_px) input (so a skip at full resolution counts
    at full resolution). ReLU, pooling, upsampling and the softmax are not counted.
    """
    flops = 0

    def count(module: nn.Conv2d, _inputs: tuple, output: torch.Tensor) -> None:
        nonlocal flops
        kh, kw = module.kernel_size
        macs_per_px = module.out_channels * (module.in_channels // module.groups) * kh * kw
        bias = module.out_channels if module.bias is not None else 0
        flops += (2 * macs_per_px + bias) * output.shape[-2] * output.shape[-1]

    convs = [m for m in model.modules() if isinstance(m, nn.Conv2d)]
    hooks = [m.register_forward_hook(count) for m in convs]
    try:
        with torch.no_grad():
            model(torch.zeros(1, convs[0].in_channels, height_px, width_px))
    finally:
        for hook in hooks:
            hook.remove()
    return int(flops)


@dataclass(frozen=True)
class Latency:
    """Latency statistics of repeated calls, ms."""

    median_ms: float
    min_ms: float
    p90_ms: float
    repeats: int


def measure_latency(
    fn: Callable[[], object], clock: Callable[[], float], repeats: int = 10, warmup: int = 2
) -> Latency:
    """Latency of `fn()` over `repeats` timed calls after `warmup` untimed ones."""
    for _ in range(warmup):
        fn()
    times_s = []
    for _ in range(repeats):
        start_s = clock()
        fn()
        times_s.append(clock() - start_s)
    ms = np.asarray(times_s) * 1e3
    return Latency(
        median_ms=float(np.median(ms)),
        min_ms=float(ms.min()),
        p90_ms=float(np.percentile(ms, 90)),
        repeats=repeats,
    )


def sgemm_gflops(
    clock: Callable[[], float], threads: int, size: int = 2048, repeats: int = 5
) -> dict[str, float]:
    """Measured fp32 matrix-multiply rate, GFLOP/s, of numpy (its BLAS) and torch.

    Both at `threads` threads (numpy's BLAS limited through threadpoolctl); the best of
    `repeats` (size x size) @ (size x size) products, 2 size^3 flops each.
    """
    import torch
    from threadpoolctl import threadpool_limits

    rng = np.random.default_rng(0)
    a = rng.standard_normal((size, size), dtype=np.float32)
    b = rng.standard_normal((size, size), dtype=np.float32)
    flop = 2.0 * size**3
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    ta, tb = torch.from_numpy(a), torch.from_numpy(b)
    try:
        torch_ms = measure_latency(lambda: ta @ tb, clock, repeats, 1).min_ms
        with threadpool_limits(limits=threads, user_api="blas"):
            numpy_ms = measure_latency(lambda: a @ b, clock, repeats, 1).min_ms
    finally:
        torch.set_num_threads(previous)
    return {"torch": flop / torch_ms / 1e6, "numpy": flop / numpy_ms / 1e6}
