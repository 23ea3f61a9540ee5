"""Stage 1 in OpenVINO against ONNX Runtime, float32 and int8, on this machine's CPU.

The runtime's ONNX backends run the kit's exports (``airpose export``, int8: static QDQ,
per-channel weights, calibrated on the kit's crops) in ONNX Runtime. OpenVINO reads the same
ONNX files; this benchmark times both on the same graphs, interleaved (one call of each in turn,
repeated), so a change of load hits all alike; the ratio to ONNX Runtime float32 of the same
run is the robust figure. OpenVINO is not a dependency of the kit:

    pip install openvino            # in the kit's venv, under constraints.txt
    python benchmarks/inference_openvino.py                   # ResNet-50 @ 224, 1 thread
    python benchmarks/inference_openvino.py --configs resnet18@128 --threads 2

It also reports the largest absolute difference of OpenVINO's stage-1 outputs from ONNX
Runtime's on the same input (the two must compute the same network).
"""
from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import time
from pathlib import Path

import numpy as np


def _ort_runner(path: Path, feeds: dict, threads: int):
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads, opts.inter_op_num_threads = threads, 1
    session = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    mine = {i.name: feeds[i.name] for i in session.get_inputs()}
    return lambda: session.run(None, mine)


def _ov_runner(path: Path, feeds: dict, threads: int):
    import openvino as ov

    compiled = ov.Core().compile_model(str(path), "CPU", {"INFERENCE_NUM_THREADS": threads,
                                                          "PERFORMANCE_HINT": "LATENCY"})
    request = compiled.create_infer_request()
    # OpenVINO may rename an input after a cast; every input keeps its ONNX name among its names
    mine = {i.get_any_name(): feeds[next(n for n in i.get_names() if n in feeds)] for i in compiled.inputs}
    return lambda: list(request.infer(mine).values())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--configs", nargs="+", default=["resnet50@224"], help="BACKBONE@SIZE (default: resnet50@224)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--repeat", type=int, default=20)
    p.add_argument("--calibration", default=None, help="still-frame dataset of the int8 calibration")
    args = p.parse_args()
    try:
        import openvino  # noqa: F401
    except ImportError:
        raise SystemExit("openvino is not installed: pip install -c constraints.txt openvino") from None

    from airpose_lib.runtime.backends import BackendSpec
    from airpose_lib.runtime.edge import ensure_export

    print(f"openvino {importlib.metadata.version('openvino')}, {args.threads} thread(s), {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()}\n")
    print("| backbone @ input | runtime | precision | stage 1 ms, median / best | vs ONNX Runtime fp32 "
          "| max abs vs ONNX Runtime | load avg |")
    print("|---|---|---|---|---|---|---|")
    rng = np.random.default_rng(0)
    for config in args.configs:
        backbone, size = config.split("@")[0], int(config.split("@")[1])
        folder = Path(ensure_export(BackendSpec(kind="onnx-int8", backbone=backbone, input_size=size, seed=0),
                                    calibration_root=args.calibration))
        files = {k: folder / v["file"] for k, v in json.loads((folder / "meta.json").read_text())["stage1"].items()}
        feeds = {"image": rng.random((1, 3, size, size), dtype=np.float32), "P": np.zeros((1, 3), np.float32)}
        runners = {}
        for precision, path in files.items():
            runners[("ONNX Runtime", precision)] = _ort_runner(path, feeds, args.threads)
            runners[("OpenVINO", precision)] = _ov_runner(path, feeds, args.threads)
        outputs = {k: run() for k, run in runners.items()}  # also the warm-up
        times: dict = {k: [] for k in runners}
        for _ in range(args.repeat):
            for k, run in runners.items():
                t = time.perf_counter()
                run()
                times[k].append(1000 * (time.perf_counter() - t))
        ref = np.median(times[("ONNX Runtime", "fp32")])
        for (rt, precision), ms in times.items():
            diff = max(float(np.abs(np.asarray(a) - np.asarray(b)).max())
                       for a, b in zip(outputs[(rt, precision)], outputs[("ONNX Runtime", precision)]))
            print(f"| {backbone} @ {size} | {rt} | {precision} | {np.median(ms):.1f} / {min(ms):.1f} "
                  f"| {np.median(ms) / ref:.2f}x | {diff:.2e} | {os.getloadavg()[0]:.1f} |", flush=True)


if __name__ == "__main__":
    main()
