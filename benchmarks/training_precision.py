"""One training step in float32 against bfloat16 autocast (``precision: bf16``), with and without
channels_last, as ratios measured in one run.

    taskset -c 1 env OMP_NUM_THREADS=1 python benchmarks/training_precision.py            # ~3 min
    python benchmarks/training_precision.py --quick                                       # ResNet-18 only
    python benchmarks/training_precision.py --device cuda --batch 30                      # a GPU, + fp16

A step is what the engine does for ``task: supervised`` (:func:`airpose_lib.engine.loop.run_engine`):
the AirPose network's forward on ``--batch`` two-view samples under the kit's autocast
(:func:`airpose_lib.engine.launch.autocast`), a loss in float32, backward and an Adam (AMSGrad)
step. The loss is a plain squared error of the network's outputs, not the body-model loss (its
cost does not change with the precision, so the ratios here are an upper bound of the whole
step's; the regressor task, the cpu profile's, runs only the regressor and gains less). Random
(seeded) weights and images: the speed does not depend on them.

The four set-ups are timed interleaved (one step of each in turn, repeated), so that a change of
load on a shared machine hits them alike: the ratio to fp32 NCHW of the same run is the robust
figure; the load average is printed with the table.

On a CPU the table is printed twice: for the kernels this CPU runs, then (in a child process)
with the CPU limited to AVX2 (``ONEDNN_MAX_CPU_ISA=AVX2 ATEN_CPU_CAPABILITY=avx2``), what an
AVX2-only laptop runs, each with the precision ``precision: auto`` picks there
(:func:`airpose_lib.engine.launch.resolve_precision`). ``--kernels native`` prints only the first.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

import torch

from airpose_lib.engine.launch import autocast, grad_scaler, resolve_precision
from airpose_lib.model import build_model

SETUPS = {"fp32": ("fp32", False), "fp32 channels_last": ("fp32", True), "bf16": ("bf16", False),
          "bf16 channels_last": ("bf16", True)}
#: fp16 autocast needs a loss scaler and CUDA (the engine refuses it on a CPU).
CUDA_SETUPS = {"fp16": ("fp16", False), "fp16 channels_last": ("fp16", True)}


def make_step(backbone: str, size: int, batch: int, precision: str, channels_last: bool, device: str = "cpu"):
    """A closure running one training step; its model and data built once (seeded)."""
    torch.manual_seed(0)
    dev = torch.device(device)
    model = build_model("airpose", backbone=backbone, channels_last=channels_last).train().to(dev)
    opt = torch.optim.Adam(model.parameters(), lr=5e-5, amsgrad=True)
    images = torch.randn(batch, 2, 3, size, size, device=dev)
    P = torch.randn(batch, 2, 3, device=dev) * 0.1
    scaler = grad_scaler(precision, dev)  # fp16 only, as the engine

    def step() -> None:
        with autocast(precision, dev.type):
            out = model(images, P)
        loss = sum(v.float().pow(2).mean() for k, v in out.items() if isinstance(v, torch.Tensor))
        opt.zero_grad(set_to_none=True)
        if scaler is None:
            loss.backward()
            opt.step()
        else:
            scaler.scale(loss).backward()
            scaler.step(opt)
            scaler.update()
        if dev.type == "cuda":
            torch.cuda.synchronize(dev)  # the time of the step, not of its launch
    return step


def bench(backbone: str, size: int, batch: int, repeat: int, device: str = "cpu") -> list[tuple[str, float, float]]:
    setups = {**SETUPS, **(CUDA_SETUPS if device.startswith("cuda") else {})}
    steps = {name: make_step(backbone, size, batch, *cfg, device=device) for name, cfg in setups.items()}
    for fn in steps.values():  # warm-up (allocations, oneDNN / cuDNN kernel choice)
        fn()
        fn()
    times: dict[str, list[float]] = {k: [] for k in steps}
    for _ in range(repeat):
        for name, fn in steps.items():
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    base = statistics.median(times["fp32"])
    return [(name, statistics.median(t), base / statistics.median(t)) for name, t in times.items()]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--batch", type=int, default=4, help="two-view samples per step (default 4: 8 crops)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="ResNet-18 at 128 px only")
    ap.add_argument("--device", default="cpu", help="cpu (default) or cuda / cuda:N (adds fp16 with a loss scaler)")
    ap.add_argument("--kernels", choices=("both", "native"), default="both",
                    help="CPU: both kernel paths (default: this CPU's, then AVX2 in a child process) or native only")
    args = ap.parse_args(argv)
    configs = [("resnet18", 128)] + ([] if args.quick else [("resnet50", 224)])
    where = (torch.cuda.get_device_name(torch.device(args.device)) if args.device.startswith("cuda")
             else f"{torch.get_num_threads()} thread(s)")
    limit = os.environ.get("ONEDNN_MAX_CPU_ISA")
    picked, why = resolve_precision("auto", args.device if args.device != "cpu" else "cpu")
    print(f"\nkernels: {'ONEDNN_MAX_CPU_ISA=' + limit if limit else 'this CPU'}"
          f" (ATen {torch.backends.cpu.get_cpu_capability()}); precision auto picks {picked} ({why})")
    print(f"torch {torch.__version__}, {where}, batch {args.batch} two-view samples, "
          f"median of {args.repeat} interleaved steps; load average before: {os.getloadavg()}")
    print("| backbone @ px | set-up | step [s] | img/s | speed-up vs fp32 |")
    print("|---|---|---|---|---|")
    for backbone, size in configs:
        for name, t, ratio in bench(backbone, size, args.batch, args.repeat, args.device):
            print(f"| {backbone} @ {size} | {name} | {t:.3f} | {2 * args.batch / t:.1f} | {ratio:.2f}x |")
    print(f"load average after: {os.getloadavg()}")
    if args.device == "cpu" and args.kernels == "both" and not limit:
        env = {**os.environ, "ONEDNN_MAX_CPU_ISA": "AVX2", "ATEN_CPU_CAPABILITY": "avx2"}
        rest = [a for a in (argv if argv is not None else sys.argv[1:]) if not a.startswith("--kernels")]
        subprocess.run([sys.executable, __file__, *rest, "--kernels", "native"], env=env, check=True)


if __name__ == "__main__":
    main()
