"""Network speed on CPU: per-view drone latency (batch 1) and training throughput.

    python benchmarks/inference.py                 # everything (~5 min on 2 cores)
    python benchmarks/inference.py --quick         # fewer repeats, no ResNet-50 training
    python benchmarks/inference.py --no-train --runtimes onnx onnx-int8   # fp32 vs int8 only

Per view, batch 1, AirPose variant: stage 1 (backbone + first iteration) and stages 2 + 3 (one
regressor iteration each, message in and out), as ``DroneNode`` / ``OnnxDroneNode`` run them:
in torch (NCHW, channels_last, and ``torch-bf16``: the channels_last backbone under bfloat16
autocast, the kit's one bf16 path, since ONNX Runtime's x86 CPU provider runs no bf16
convolutions) and in ONNX Runtime with a float32 or an int8 stage 1 (``airpose_lib.model.quantize``:
static QDQ, per-channel weights, calibrated on the kit's still-frame crops: ``--calibration DIR``,
default the smoke profile's dataset, ``airpose data generate --profile smoke``). Targets for ResNet-50 at 224 px: stage 1 <= 40 ms, stages 2 + 3
<= 1 ms, int8 stage 1 <= 0.5 x float32 (the paper: ~43 ms and ~2.5 ms on a Jetson TX2).
Training: forward + backward + Adam step of the AirPose network (no body-model loss) on
``--train-batch`` images (half as many two-view samples), channels_last, images per second.

The runtimes of one configuration are timed *interleaved* (one call of each in turn, repeated),
so that a change of load on the shared machine hits all of them alike: the ratio columns (to
ONNX Runtime float32 of the same run, and to the paper's TX2 numbers) are the robust figures;
wall times are median and best of the repeats, printed with the load average. The stage-1 CPU
time of a 1-thread run hardly depends on the load; the unloaded 2-thread latency is a bit more
than half of it. Random (seeded) weights: the speed does not depend on them.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import numpy as np
import torch

#: The paper's per-view timings on a Jetson TX2 (Sec. IV-D), ms.
TX2_STAGE1_MS = 43.0
TX2_STAGES23_MS = 2.5
RUNTIMES = {"torch": "torch", "torch-cl": "torch channels_last", "torch-bf16": "torch channels_last, bf16 backbone",
            "onnx": "ONNX Runtime fp32", "onnx-int8": "ONNX Runtime int8"}


def _interleaved_ms(fns: dict[str, Callable], repeat: int, warmup: int = 2) -> dict[str, tuple[float, float, float]]:
    """Median and best wall time and median process CPU time of ``repeat`` calls of each
    function, in ms, the functions called in turn (a load change affects all of them alike).

    On a shared machine the best wall time is the closer estimate of the unloaded latency and
    the median is what one gets now. The CPU time of a 1-thread run barely depends on the load
    (it is not inflated by waiting for a core), so it is the load-robust figure.
    """
    for _ in range(warmup):
        for fn in fns.values():
            fn()
    wall: dict[str, list] = {k: [] for k in fns}
    cpu: dict[str, list] = {k: [] for k in fns}
    for _ in range(repeat):
        for k, fn in fns.items():
            t, c = time.perf_counter(), time.process_time()
            fn()
            wall[k].append(time.perf_counter() - t)
            cpu[k].append(time.process_time() - c)
    return {k: (1000.0 * statistics.median(wall[k]), 1000.0 * min(wall[k]), 1000.0 * statistics.median(cpu[k]))
            for k in fns}


def _load() -> str:
    return "{:.2f}/{:.2f}/{:.2f}".format(*os.getloadavg())


def _later(node) -> Callable:
    """Stages 2 and 3 rerun on the node's stored stage-1 result."""
    other = np.zeros(136, np.float32)

    def run():
        node._k = 1
        node.stage(2, [other])
        node.stage(3, [other])

    return run


class _Bf16Backbone(torch.nn.Module):
    """A backbone run under CPU bfloat16 autocast (AVX-512 BF16 / AMX kernels where the CPU has
    them), its pooled feature returned in float32 so the regressor and the messages stay float32."""

    def __init__(self, backbone: torch.nn.Module):
        super().__init__()
        self.inner = backbone

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        with torch.autocast("cpu", dtype=torch.bfloat16):
            return self.inner(x).float()


def _nodes(runtimes, backbone: str, size: int, threads: int, folders: dict) -> dict:
    """One DroneNode / OnnxDroneNode per runtime, ``threads`` intra-op threads each."""
    from airpose_lib.model import DroneNode, build_model
    from airpose_lib.model.onnx_export import OnnxDroneNode

    nodes = {}
    for rt in runtimes:
        if rt.startswith("torch"):
            torch.manual_seed(0)
            model = build_model("airpose", backbone, channels_last=rt in ("torch-cl", "torch-bf16")).eval()
            if rt == "torch-bf16":
                model.backbone = _Bf16Backbone(model.backbone)
            nodes[rt] = DroneNode(model)
        else:
            nodes[rt] = OnnxDroneNode(folders[rt], num_threads=threads, precision="int8" if rt == "onnx-int8" else "fp32")
    return nodes


def _latency(runtimes, backbone: str, size: int, repeat: int, threads: int, folders: dict) -> dict:
    """Per runtime: stage 1 and stages 2+3 (median, best, cpu) at ``threads`` threads, and the
    stage-1 CPU time with one thread."""
    x = np.random.default_rng(0).normal(size=(1, 3, size, size)).astype(np.float32)
    P = np.array([[0.1, -0.1, 1.0]], np.float32)
    args = {rt: ((torch.from_numpy(x), torch.from_numpy(P)) if rt.startswith("torch") else (x, P)) for rt in runtimes}
    result: dict[str, dict] = {rt: {} for rt in runtimes}
    for n in sorted({threads, 1}, reverse=True):
        torch.set_num_threads(n)  # torch's threads are per process: every torch node uses n
        nodes = _nodes(runtimes, backbone, size, n, folders)
        for rt, node in nodes.items():
            node.stage1(*args[rt])
        s1 = _interleaved_ms({rt: (lambda node=node, a=args[rt]: node.stage1(*a)) for rt, node in nodes.items()},
                             repeat if n == threads else max(repeat // 2, 3))
        if n == threads:
            s23 = _interleaved_ms({rt: _later(node) for rt, node in nodes.items()}, max(repeat * 10, 50))
            for rt in runtimes:
                result[rt]["s1"], result[rt]["s23"] = s1[rt], s23[rt]
        if n == 1:
            for rt in runtimes:
                result[rt]["s1_cpu1"] = s1[rt][2]
    torch.set_num_threads(threads)
    return result


def _train_throughput(backbone: str, size: int, batch: int, steps: int) -> tuple[float, float]:
    from airpose_lib.model import build_model

    torch.manual_seed(0)
    model = build_model("airpose", backbone, channels_last=True).train()
    opt = torch.optim.Adam(model.parameters(), lr=5e-5, amsgrad=True)
    samples = max(batch // 2, 1)
    images = torch.randn(samples, 2, 3, size, size)
    P = torch.rand(samples, 2, 3)

    def step():
        out = model(images, P)
        loss = out["theta6d"].square().mean() + out["tau"].square().mean() + out["beta"].square().mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    med, best, _ = _interleaved_ms({"step": step}, steps, warmup=1)["step"]
    return 2 * samples / (med / 1000.0), 2 * samples / (best / 1000.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=15, help="stage-1 repetitions per measurement")
    parser.add_argument("--runtimes", nargs="+", choices=tuple(RUNTIMES), default=list(RUNTIMES))
    parser.add_argument("--configs", nargs="+", default=["resnet50@224", "resnet18@224", "resnet18@128"],
                        help="BACKBONE@SIZE (default: resnet50@224 resnet18@224 resnet18@128)")
    parser.add_argument("--calibration", default=None,
                        help="still-frame dataset of the int8 calibration (default: the smoke profile's)")
    parser.add_argument("--train-batch", type=int, default=32, help="images per training step")
    parser.add_argument("--train-steps", type=int, default=3)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--no-train", action="store_true", help="latency only")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    if args.quick:
        args.repeat, args.train_steps = 5, 2

    from airpose_lib.runtime.backends import BackendSpec
    from airpose_lib.runtime.edge import ensure_export

    configs = [(c.split("@")[0], int(c.split("@")[1])) for c in args.configs]
    print(f"torch {torch.__version__}, {args.threads} threads, {os.cpu_count()} CPUs; "
          f"load average at start {_load()} (the CPUs are shared with other work)\n")
    print("| backbone @ input | runtime | stage 1 ms, median / best | stage 1 vs ONNX fp32 | stage 1 vs TX2 "
          "| stages 2+3 ms, median / best | stages 2+3 vs TX2 | stage 1 CPU ms, 1 thread | load avg 1/5/15 min |")
    print("|---|---|---|---|---|---|---|---|---|")
    for backbone, size in configs:
        folders = {}
        for rt in args.runtimes:
            if rt.startswith("onnx"):  # cached in <cache>/onnx (the int8 calibration takes ~1 min once)
                folders[rt] = ensure_export(BackendSpec(kind=rt, backbone=backbone, input_size=size, seed=0),
                                            calibration_root=args.calibration)
        r = _latency(args.runtimes, backbone, size, args.repeat, args.threads, folders)
        ref = r["onnx"]["s1"][0] if "onnx" in r else None
        for rt in args.runtimes:
            (m1, b1, _), (m23, b23, _) = r[rt]["s1"], r[rt]["s23"]
            vs = f"{m1 / ref:.2f}x" if ref else "-"
            print(f"| {backbone} @ {size} | {RUNTIMES[rt]} | {m1:.1f} / {b1:.1f} | {vs} | {m1 / TX2_STAGE1_MS:.2f}x "
                  f"| {m23:.2f} / {b23:.2f} | {m23 / TX2_STAGES23_MS:.2f}x | {r[rt]['s1_cpu1']:.1f} | {_load()} |",
                  flush=True)

    if args.no_train:
        return
    print("\n| backbone @ input | training images/s, fwd+bwd+Adam (median / best step) | batch (images) | load avg |")
    print("|---|---|---|---|")
    for backbone, size in configs:
        if args.quick and backbone == "resnet50":
            continue
        batch = args.train_batch if backbone != "resnet50" else max(args.train_batch // 2, 2)
        med, best = _train_throughput(backbone, size, batch, args.train_steps)
        print(f"| {backbone} @ {size} | {med:.1f} / {best:.1f} | {batch} | {_load()} |", flush=True)


if __name__ == "__main__":
    main()
