"""Network speed on CPU: per-view drone latency (batch 1) and training throughput.

    python benchmarks/inference.py                 # everything (~3-4 min on 2 cores)
    python benchmarks/inference.py --quick         # fewer repeats, no ResNet-50 training

Per view, batch 1, AirPose variant: stage 1 (backbone + first iteration) and stages 2 + 3 (one
regressor iteration each, message in and out), in torch (NCHW and channels_last) and ONNX
Runtime, as ``DroneNode`` / ``OnnxDroneNode`` run them. Targets for ResNet-50 at 224 px:
stage 1 <= 40 ms, stages 2 + 3 <= 1 ms (the paper: ~43 ms and ~2.5 ms on a Jetson TX2).
Training: forward + backward + Adam step of the AirPose network (no body-model loss) on
``--train-batch`` images (half as many two-view samples), channels_last, images per second.

Wall times: median and best of the repeats. The machine is shared: the load average is printed
with every row, and wall times taken under load are pessimistic. The stage-1 CPU time of a
1-thread run hardly depends on the load; the unloaded 2-thread latency is a bit more than half
of it.
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import numpy as np
import torch


def _times_ms(fn, repeat: int, warmup: int = 2) -> tuple[float, float, float]:
    """Median and best wall time and median process CPU time of ``repeat`` calls, in ms.

    On a shared machine the best wall time is the closer estimate of the unloaded latency and
    the median is what one gets now. The CPU time of a 1-thread run barely depends on the load
    (it is not inflated by waiting for a core), so it is the load-robust figure.
    """
    for _ in range(warmup):
        fn()
    wall, cpu = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return 1000.0 * statistics.median(wall), 1000.0 * min(wall), 1000.0 * statistics.median(cpu)


def _load() -> str:
    return "{:.2f}/{:.2f}/{:.2f}".format(*os.getloadavg())


def _node_latency(node, image, P, repeat: int) -> tuple:
    """(stage 1 timings, stages 2+3 timings) of a DroneNode or OnnxDroneNode."""
    other = np.zeros(136, np.float32)
    node.stage1(image, P)

    def later():
        node._k = 1  # rerun stages 2 and 3 on the stored stage-1 result
        node.stage(2, [other])
        node.stage(3, [other])

    return _times_ms(lambda: node.stage1(image, P), repeat), _times_ms(later, max(repeat * 10, 50))


def _latency(model, size: int, repeat: int, threads: int, runtime: str, tmp: str) -> dict:
    """Wall times at ``threads`` threads, and stage-1 CPU time with one thread."""
    from airpose_lib.model import DroneNode
    from airpose_lib.model.onnx_export import OnnxDroneNode

    image = torch.from_numpy(np.random.default_rng(0).normal(size=(1, 3, size, size)).astype(np.float32))
    P = torch.tensor([[0.1, -0.1, 1.0]])
    result = {}
    for n in (threads, 1):
        if runtime == "onnx":
            node = OnnxDroneNode(tmp, num_threads=n)
            args = (image.numpy(), P.numpy())
        else:
            torch.set_num_threads(n)
            node = DroneNode(model)
            args = (image, P)
        s1, s23 = _node_latency(node, *args, repeat if n == threads else max(repeat // 2, 3))
        if n == threads:
            result["s1"], result["s23"] = s1, s23
        else:
            result["s1_cpu1"] = s1[2]
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

    med, best, _ = _times_ms(step, steps, warmup=1)
    return 2 * samples / (med / 1000.0), 2 * samples / (best / 1000.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=15, help="stage-1 repetitions per measurement")
    parser.add_argument("--train-batch", type=int, default=32, help="images per training step")
    parser.add_argument("--train-steps", type=int, default=3)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--no-train", action="store_true", help="latency only")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    if args.quick:
        args.repeat, args.train_steps = 5, 2

    from airpose_lib.model import build_model
    from airpose_lib.model.onnx_export import export_onnx

    configs = [("resnet50", 224), ("resnet18", 224), ("resnet18", 128)]
    print(f"torch {torch.__version__}, {args.threads} threads, {os.cpu_count()} CPUs; "
          f"load average at start {_load()} (the CPUs are shared with other work)\n")
    print("| backbone @ input | runtime | stage 1 ms, median / best | stages 2+3 ms, median / best "
          "| stage 1 CPU ms, 1 thread | load avg 1/5/15 min |")
    print("|---|---|---|---|---|---|")
    for backbone, size in configs:
        for label, runtime, cl in (("torch", "torch", False), ("torch channels_last", "torch", True),
                                   ("ONNX Runtime", "onnx", False)):
            torch.manual_seed(0)
            model = build_model("airpose", backbone, channels_last=cl).eval()
            with tempfile.TemporaryDirectory() as tmp:
                if runtime == "onnx":
                    export_onnx(model, tmp, input_size=size)
                r = _latency(model, size, args.repeat, args.threads, runtime, tmp)
            (m1, b1, _), (m23, b23, _) = r["s1"], r["s23"]
            print(f"| {backbone} @ {size} | {label} | {m1:.1f} / {b1:.1f} | {m23:.2f} / {b23:.2f} "
                  f"| {r['s1_cpu1']:.1f} | {_load()} |", flush=True)

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
