"""Online runtime benchmark: the paper's hardware-in-the-loop test on loopback.

For 2 and 3 drone processes, the fixed 240 ms window (the paper) and the pipelined mode (20 fps,
150 ms budget: the paper's conjecture), with torch and/or ONNX Runtime, it reports per run

* achieved fps per drone (frames completed in time / schedule duration; mean and worst drone),
* end-to-end latency (shutter -> result) p50 / p95 over all drones' completed frames,
* the rate the drones agreed on (pipelined: an overloaded swarm processes every m-th slot,
  ``airpose_lib.runtime.rate``; ``--fixed-rate`` turns that off for every run),
* dropped-frame rate among the agreed slots (completed late + never started) and frames
  completed with a fallback,
* bytes published per frame by one drone (= bytes per peer link: PUB sends one copy to each),
* accuracy vs the offline computation of the same frames: max |online - offline| with the same
  exchange (0 = identical), and MPJPE between online and offline-with-perfect-exchange joints
  (differs from 0 only on fallback frames); MPJPE to the ground truth when the sequence has it,

plus the accuracy cost of float16 messages (in-process, perfect exchange, same frames).
The load average is printed with every run: other processes on the machine slow the drones.

    python benchmarks/online.py                       # generate (once) a 15 s three-drone sequence
    python benchmarks/online.py --source synthetic    # procedural frames, no rendering
    python benchmarks/online.py --quick               # 2 drones, R18 only, short runs

Weights: by default the cpu profile's trained AirPose (``<runs>/train/cpu/airpose/seed123``, from
``airpose reproduce --profile cpu``) when it exists, for the runs of its backbone and crop size;
``--checkpoint`` names another, ``--random-weights`` none. Other runs have random (seeded)
weights: timing does not depend on them, but then the accuracy columns only show online ==
offline, and the float16 cost of an untrained network is not that of a trained one. The
``weights`` column says which. Every row also gives its rate as a ratio to the paper's Jetson
TX2 test (3 fps achieved per drone, Sec. IV-D) and, for int8, to ONNX float32 in the same run.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _sequence(args) -> tuple[str, bool]:
    """The source spec, and whether it has ground truth."""
    if args.source.startswith("synthetic"):
        return args.source, False
    if args.source != "generate":
        return args.source, (Path(args.source) / "ground_truth.npz").is_file()
    from airpose_lib.data.sequences import PAPER_CAMERAS, CameraSpec, ensure_sequences
    from airpose_lib.reproduce.configs import kit_configs

    # The smoke profile's person 2 with a third drone (a copy of the second camera, 13 ms behind)
    # so that the same recording serves the 2- and the 3-drone runs.
    name = f"person2_{args.sequence_frames}_3views"
    third = CameraSpec("cam2", 1361.11, 1378.80, 978.02, 667.23)
    cfg = dataclasses.replace(kit_configs("smoke").sequences["person2"], n_frames=args.sequence_frames,
                              cameras=(*PAPER_CAMERAS, third), time_offsets=(0.0, 0.007, 0.013))
    t = time.time()
    path = ensure_sequences({name: cfg}, Path(args.out) / "sequences", progress=True)[name]
    print(f"sequence {path} ({args.sequence_frames} frames; {time.time() - t:.0f} s)")
    return str(path), True


#: Frames per second per drone the paper achieved on its two Jetson TX2 (Sec. IV-D).
TX2_FPS = 3.0
#: The trained network used by default (the cpu profile's Table I AirPose, first seed).
DEFAULT_CHECKPOINT = ("train", "cpu", "airpose", "seed123", "checkpoints", "last.pt")


def _default_checkpoint() -> str | None:
    from airpose_lib.paths import run_path

    path = run_path(*DEFAULT_CHECKPOINT)
    return str(path) if path.is_file() else None


def _checkpoint_for(checkpoint: str | None, backbone: str, size: int) -> str | None:
    """``checkpoint`` if its network is ``backbone`` at ``size`` px (else the run keeps random weights)."""
    if checkpoint is None:
        return None
    from airpose_lib.runtime.backends import checkpoint_settings

    net = checkpoint_settings(checkpoint)
    return checkpoint if (net.get("backbone"), net.get("input_size", size)) == (backbone, size) else None


def _export(spec, calibration: str | None = None) -> str:
    """The cached export of ``spec``'s network (``airpose export``), int8 stage 1 for ``onnx-int8``."""
    from airpose_lib.runtime.edge import ensure_export

    return str(ensure_export(spec, calibration_root=calibration, progress=True))


class Accuracy:
    """Online vs offline comparisons (joints through the open body model)."""

    def __init__(self, source: str, has_gt: bool):
        import torch

        from airpose_lib.body import load_body_model

        torch.set_num_threads(2)
        self.source = source
        self.body = load_body_model("open", "neutral")
        self.gt = None
        if has_gt:
            from airpose_lib.data.sequences.reader import load_sequence

            self.gt = load_sequence(source, detectors=("openpose",), missing_detections="zero").ground_truth

    def joints(self, out: dict, P: np.ndarray, K: np.ndarray):
        """(F, V, 22, 3) camera-frame joints of outputs (F, V, ...)."""
        import torch

        from airpose_lib.model import posed_joints_and_vertices, to_smplx_params

        t = {k: torch.from_numpy(np.ascontiguousarray(out[k])).double() for k in ("phi6d", "theta6d", "beta", "tau")}
        Kt = torch.from_numpy(np.broadcast_to(K[None], (P.shape[0], *K.shape)).copy())
        params = to_smplx_params(t, torch.from_numpy(P).double(), Kt)
        return posed_joints_and_vertices(self.body, params, joints_only=True)["joints"][..., :22, :]

    @staticmethod
    def mpjpe_mm(a, b) -> float:
        from airpose_lib.eval.metrics import mpjpe

        return float(1000 * mpjpe(a, b).mean())

    def compare(self, merged: dict, spec) -> dict:
        from airpose_lib.runtime.offline import max_abs_difference, offline_inputs, offline_staged

        if len(merged["slot"]) == 0:
            return {}
        F, V = merged["frame_index"].shape
        src = self.source if not self.source.startswith("synthetic") else f"{self.source},views={V}"
        crops, P, _ = offline_inputs(src, merged["frame_index"], spec.input_size, boxes=merged["bbox"])
        masks = np.stack([merged["used_s2"], merged["used_s3"]], -1)
        same = offline_staged(spec, crops, P, used=masks)
        everyone = (1 << V) - 1
        full = np.all([(masks[:, v] == (everyone & ~(1 << v))).all(-1) for v in range(V)], axis=0)
        perfect = {k: v.copy() for k, v in same.items()}
        if (~full).any():
            redo = offline_staged(spec, crops[~full], P[~full])
            for k in perfect:
                perfect[k][~full] = redo[k]
        J_on, J_off = self.joints(merged, P, merged["K"]), self.joints(perfect, P, merged["K"])
        out = {"frames": int(F), "max_abs_vs_offline": max(max_abs_difference(merged, same).values()),
               "mpjpe_vs_offline_mm": self.mpjpe_mm(J_on, J_off), "fallback_frames": int((~full).sum())}
        if self.gt is not None:
            import torch

            g = torch.from_numpy(self.gt["j3d_cam"][merged["frame_index"], np.arange(V)[None]])
            out["mpjpe_gt_online_mm"] = self.mpjpe_mm(J_on, g)
            out["mpjpe_gt_offline_mm"] = self.mpjpe_mm(J_off, g)
        return out

    def float16_cost(self, spec, frames: int) -> dict:
        """MPJPE between float32- and float16-message runs of the same frames (perfect exchange)."""
        from airpose_lib.runtime.offline import offline_inputs, offline_staged

        src = self.source if not self.source.startswith("synthetic") else f"{self.source},views=2"
        idx = np.repeat(np.arange(frames)[:, None], 2, 1)
        crops, P, _ = offline_inputs(src, idx, spec.input_size)
        K = np.stack([np.asarray(self._K(src, v)) for v in range(2)])
        a = offline_staged(spec, crops, P)
        b = offline_staged(dataclasses.replace(spec, message_dtype="float16"), crops, P)
        out = {"frames": frames, "mpjpe_f16_vs_f32_mm": self.mpjpe_mm(self.joints(a, P, K), self.joints(b, P, K)),
               "max_abs_theta6d": float(np.abs(a["theta6d"] - b["theta6d"]).max()),
               "max_abs_tau_m": float(np.abs(a["tau"] - b["tau"]).max())}
        if self.gt is not None:
            out["mpjpe_gt_pose_rounded_mm"] = self.quantised_gt_pose_mm()
        return out

    def quantised_gt_pose_mm(self) -> float:
        """MPJPE between the ground-truth poses and the same poses sent as float16 messages (6D
        and betas rounded): what a network that passed the other view's pose straight through
        would lose. Random weights barely depend on the message, so this is the telling number."""
        import torch

        from airpose_lib.geometry import axis_angle_to_rot6d, rot6d_to_matrix
        from airpose_lib.model import posed_joints_and_vertices

        theta = torch.from_numpy(self.gt["theta"]).double()  # (F, 21, 3) axis-angle
        beta = torch.from_numpy(np.broadcast_to(self.gt["betas"], (len(theta), 10)).copy()).double()
        r6 = axis_angle_to_rot6d(theta)
        J = [posed_joints_and_vertices(self.body, {"theta": rot6d_to_matrix(x), "beta": b}, joints_only=True)
             ["joints"][..., :22, :] for x, b in ((r6, beta), (r6.half().double(), beta.half().double()))]
        return self.mpjpe_mm(J[1], J[0])

    @staticmethod
    def _K(src, v):
        from airpose_lib.runtime.source import open_source

        return open_source(src).view(v).K


def run_one(cfg: dict, source: str, out_root: Path, acc: Accuracy | None, keep: bool) -> dict:
    from airpose_lib.runtime import results as R
    from airpose_lib.runtime.backends import BackendSpec
    from airpose_lib.runtime.launcher import launch

    period = 0.240 if cfg["mode"] == "fixed" else 1.0 / cfg.get("extra", {}).get("rate", 20.0)
    slots = int(round(cfg["seconds"] / period))
    out = out_root / cfg["name"]
    if out.exists():
        shutil.rmtree(out)
    options = {"source": source, "backend": cfg["backend"], "backbone": cfg["backbone"],
               "input_size": cfg["size"], "mode": cfg["mode"], "frames": slots, "preload": True,
               "message_dtype": cfg.get("dtype", "float32"), "onnx_dir": cfg.get("onnx_dir"),
               "max_runtime_s": cfg["seconds"] + 120, **cfg.get("extra", {})}
    load0 = os.getloadavg()
    fleet = launch(cfg["drones"], out, options)
    summaries = fleet.wait(cfg["seconds"] + 300)
    load1 = os.getloadavg()
    res = [R.load_node_results(out / f"node_{d}.npz") for d in range(1, cfg["drones"] + 1)]
    lat = np.concatenate([r.frames["latency"][r.valid] for r in res])
    # slots of the swarm's agreed rate (runtime.rate): a slot the drones agreed to leave out is not a drop
    slots_all = sum(int(((r.frames["flags"] & R.RATE_SKIPPED) == 0).sum()) for r in res)
    valid_all = sum(int(r.valid.sum()) for r in res)
    fps = [s["fps"] for s in summaries.values()]
    agreed = [s.get("agreed_fps") or s["nominal_fps"] for s in summaries.values()]
    row = {**{k: v for k, v in cfg.items() if k != "onnx_dir"}, "slots_per_drone": slots,
           "fps_mean": float(np.mean(fps)), "fps_min": float(np.min(fps)), "agreed_fps": float(np.mean(agreed)),
           "latency_p50_ms": 1000 * float(np.percentile(lat, 50)) if len(lat) else None,
           "latency_p95_ms": 1000 * float(np.percentile(lat, 95)) if len(lat) else None,
           "drop_rate": 1.0 - valid_all / slots_all if slots_all else 1.0,
           "fallback_rate": sum(s["fallback_frames"] for s in summaries.values()) / max(valid_all, 1),
           "bytes_per_frame": float(np.mean([s["bytes_per_frame"] for s in summaries.values()])),
           "stage1_ms": 1000 * float(np.median([s["timing_median"].get("stage1", np.nan) for s in summaries.values()])),
           "acquire_ms": 1000 * float(np.median([s["timing_median"].get("acquire", np.nan)
                                                  for s in summaries.values()])),
           "loadavg_before": load0[0], "loadavg_after": load1[0]}
    if acc is not None:
        spec = BackendSpec(kind=cfg["backend"], backbone=cfg["backbone"], input_size=cfg["size"],
                           message_dtype=cfg.get("dtype", "float32"), onnx_dir=cfg.get("onnx_dir"),
                           checkpoint=cfg.get("extra", {}).get("checkpoint"))
        row.update(acc.compare(R.merge_views(res), spec))
    if not keep:
        for f in out.glob("*.jsonl"):
            f.unlink()
    print(json.dumps(row), flush=True)
    return row


def _table(rows: list[dict]) -> str:
    head = ("| run | drones | mode | backend | net | weights | fps/drone (min) | vs TX2 | vs fp32 | agreed fps "
            "| p50 ms | p95 ms | dropped | fallback | B/frame | stage 1 ms | max abs vs offline | MPJPE vs offline mm "
            "| MPJPE vs truth mm | load |")
    lines = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    same_run = (lambda r: r["name"].replace(r["backend"], "", 1))  # noqa: E731 - the run but its backend
    fp32 = {same_run(r): r["fps_mean"] for r in rows if r["backend"] == "onnx"}
    for r in rows:
        key = same_run(r)
        vs_fp32 = (f"{r['fps_mean'] / fp32[key]:.2f}x" if r["backend"] == "onnx-int8" and fp32.get(key) else "-")
        f = (lambda x, p=1: "-" if x is None else f"{x:.{p}f}")  # noqa: E731
        mode = r["mode"] + (f" {r['extra']['rate']:g} Hz / {r['extra']['latency_budget_ms']:g} ms"
                            if "rate" in r.get("extra", {}) else "")
        weights = "trained" if r.get("extra", {}).get("checkpoint") else "random"
        lines.append(f"| {r['name']} | {r['drones']} | {mode} | {r['backend']} | {r['backbone']}@{r['size']}"
                     f"{' f16' if r.get('dtype') == 'float16' else ''} | {weights} "
                     f"| {f(r['fps_mean'], 2)} ({f(r['fps_min'], 2)}) | {r['fps_mean'] / TX2_FPS:.2f}x | {vs_fp32} "
                     f"| {f(r.get('agreed_fps'), 2)} "
                     f"| {f(r['latency_p50_ms'])} | {f(r['latency_p95_ms'])} | {100 * r['drop_rate']:.1f}% "
                     f"| {100 * r['fallback_rate']:.1f}% | {r['bytes_per_frame']:.0f} | {f(r['stage1_ms'])} "
                     f"| {r.get('max_abs_vs_offline', '-')} | {f(r.get('mpjpe_vs_offline_mm'), 3)} "
                     f"| {f(r.get('mpjpe_gt_online_mm'), 1)} "
                     f"| {r['loadavg_before']:.1f}/{r['loadavg_after']:.1f} |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--source", default="generate",
                   help="'generate' (a rendered three-drone sequence, made once), 'synthetic[...]' or "
                        "a sequence folder with as many views as drones (default: generate)")
    p.add_argument("--sequence-frames", type=int, default=450, help="frames of the generated sequence (30 fps)")
    p.add_argument("--seconds", type=float, default=10.0, help="schedule length of each run")
    p.add_argument("--backends", default="torch,onnx", help="comma-separated: torch, onnx, onnx-int8")
    p.add_argument("--calibration", default=None,
                   help="still-frame dataset of the onnx-int8 calibration (default: the checkpoint's "
                        "training data, else the smoke profile's)")
    p.add_argument("--drones", default="2,3", help="comma-separated drone counts (ResNet-50: only the "
                   "ONNX backends run more than 2)")
    p.add_argument("--no-r50", action="store_true", help="skip the ResNet-50 runs")
    p.add_argument("--no-accuracy", action="store_true")
    p.add_argument("--quick", action="store_true", help="2 drones, ResNet-18, 5 s runs")
    p.add_argument("--checkpoint", default=None,
                   help="trained weights, for the runs of its backbone and crop size (default: the cpu "
                        "profile's trained AirPose when it exists)")
    p.add_argument("--random-weights", action="store_true", help="no trained weights at all")
    p.add_argument("--fixed-rate", action="store_true",
                   help="pipelined runs keep 20 Hz when overloaded (each drone skips on its own) instead of "
                        "agreeing on a lower common rate")
    p.add_argument("--f16-frames", type=int, default=40, help="frames for the float16 accuracy cost")
    p.add_argument("--out", default=str(ROOT / "runs" / "online_bench"))
    p.add_argument("--keep", action="store_true", help="keep the drones' .jsonl streams")
    p.add_argument("--only", default=None, help="run only the runs whose names contain one of these (comma-separated)")
    args = p.parse_args()
    if args.quick:
        args.drones, args.no_r50, args.seconds = "2", True, 5.0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    source, has_gt = _sequence(args)
    print(f"load average {os.getloadavg()} on {os.cpu_count()} cores (other processes share them)")
    from airpose_lib.runtime.backends import BackendSpec

    acc = None if args.no_accuracy else Accuracy(source, has_gt)
    backends = args.backends.split(",")
    onnx = {}
    configs = []
    checkpoint = None if args.random_weights else (args.checkpoint or _default_checkpoint())
    print(f"weights: {checkpoint or 'random'}")
    for backbone, size in [("resnet18", 128)] + ([] if args.no_r50 else [("resnet50", 224)]):
        others = ("resnet18", "resnet50")
        if args.only and all(any(b in o for b in others if b != backbone) for o in args.only.split(",")):
            continue  # every --only filter names another network: do not export (or calibrate) this one
        ckpt = _checkpoint_for(checkpoint, backbone, size)
        extra = {"checkpoint": ckpt} if ckpt else {}
        for backend in backends:
            if backend.startswith("onnx"):
                onnx[(backend, backbone, size)] = _export(BackendSpec(
                    kind=backend, backbone=backbone, input_size=size, checkpoint=ckpt), args.calibration)
        for backend in backends:
            for n in map(int, args.drones.split(",")):
                if backbone == "resnet50" and n > 2 and not backend.startswith("onnx"):
                    continue
                modes = [("fixed", {}), ("pipelined", {})]
                if backbone == "resnet50":  # 20 fps cannot fit: the fastest pipelined rate that does
                    modes.append(("pipelined", {"rate": 10.0, "latency_budget_ms": 250.0} if backend.startswith("onnx")
                                  else {"rate": 5.0, "latency_budget_ms": 300.0}))
                for mode, more in modes:
                    tag = f"_{more['rate']:g}hz" if more else ""
                    if mode == "pipelined" and args.fixed_rate:
                        more = {**more, "fixed_rate": True}
                    configs.append({"name": f"{backend}_{backbone}_{n}d_{mode}{tag}", "drones": n, "mode": mode,
                                    "backend": backend, "backbone": backbone, "size": size,
                                    "seconds": args.seconds,
                                    "onnx_dir": onnx.get((backend, backbone, size)),
                                    "extra": {**extra, **more}})
    b0 = backends[-1]
    od = onnx.get((b0, "resnet18", 128))
    ckpt18 = _checkpoint_for(checkpoint, "resnet18", 128)
    extra = {"checkpoint": ckpt18} if ckpt18 else {}
    configs.append({"name": f"{b0}_resnet18_2d_pipelined_f16", "drones": 2, "mode": "pipelined", "backend": b0,
                    "backbone": "resnet18", "size": 128, "seconds": args.seconds, "dtype": "float16", "onnx_dir": od,
                    "extra": dict(extra)})
    configs.append({"name": f"{b0}_resnet18_2d_pipelined_wifi", "drones": 2, "mode": "pipelined", "backend": b0,
                    "backbone": "resnet18", "size": 128, "seconds": args.seconds, "onnx_dir": od,
                    "extra": {**extra, "link_bandwidth_mbps": 50, "link_latency_ms": 2, "link_jitter_ms": 3,
                              "link_loss": 0.01}})
    if args.only:
        configs = [c for c in configs if any(p in c["name"] for p in args.only.split(","))]
    rows = []
    for cfg in configs:
        rows.append(run_one(cfg, source, out, acc, args.keep))
    f16 = []
    if acc is not None:
        for backbone, size in [("resnet18", 128)] + ([] if args.no_r50 else [("resnet50", 224)]):
            spec = BackendSpec(kind="torch", backbone=backbone, input_size=size,
                               checkpoint=_checkpoint_for(checkpoint, backbone, size))
            f16.append({"net": f"{backbone}@{size}", **acc.float16_cost(spec, args.f16_frames)})
    report = {"source": source, "cpu_count": os.cpu_count(), "loadavg_end": os.getloadavg(), "runs": rows,
              "float16": f16, "checkpoint": args.checkpoint}
    (out / "results.json").write_text(json.dumps(report, indent=1))
    print()
    print(_table(rows))
    for r in f16:
        print(f"float16 messages, {r['net']}: MPJPE change {r['mpjpe_f16_vs_f32_mm']:.4f} mm over {r['frames']} "
              f"frames x 2 views (max |d theta6d| {r['max_abs_theta6d']:.2e}, max |d tau| {r['max_abs_tau_m']:.2e} m)")
    if f16 and "mpjpe_gt_pose_rounded_mm" in f16[0]:
        print(f"float16 rounding of the ground-truth poses themselves (a network passing the other view's pose "
              f"through): MPJPE {f16[0]['mpjpe_gt_pose_rounded_mm']:.4f} mm")
    print(f"load average at the end {os.getloadavg()} (2 cores shared with other processes)")
    print(f"results: {out / 'results.json'}")


if __name__ == "__main__":
    sys.exit(main())
