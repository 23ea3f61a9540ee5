"""``airpose node``, ``launch``, ``export`` and ``keys``: the online runtime's commands
(:mod:`airpose_lib.runtime` does the work).

A drone is started again and again (by :mod:`airpose_lib.runtime.launcher`, and a restarted drone
must rejoin within a few frames), so this module imports only the standard library; the handlers
import the runtime (ZeroMQ, torch or ONNX Runtime) when they run.
"""
from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from airpose_lib.folder_lock import folder_lock  # these three: standard library only
from airpose_lib.paths import run_path
from airpose_lib.process_guard import die_with_parent

from .common import CLIError

__all__ = [
    "add_node",
    "add_launch",
    "add_export",
    "add_keys",
    "add_node_arguments",
    "build_node_parser",
    "check_inputs",
    "config_from_args",
]


# (flag, attribute, the test a given value must pass, what the value must be); checked before a
# drone starts (a zero window or rate would never end, a loss of 2 would drop everything).
_RANGES = (
    ("--id", "id", lambda v: 1 <= v <= 255, "a drone id 1..255"),
    ("--port", "port", lambda v: 1 <= v <= 65535, "a TCP port 1..65535"),
    ("--view", "view", lambda v: v >= 0, "a camera index >= 0"),
    ("--drones", "drones", lambda v: 1 <= v <= 255, "1..255 drones"),
    ("--window-ms", "window_ms", lambda v: v > 0, "> 0"),
    ("--rate", "rate", lambda v: v > 0, "> 0 frames per second"),
    ("--latency-budget-ms", "latency_budget_ms", lambda v: v > 0, "> 0"),
    ("--peer-timeout-ms", "peer_timeout_ms", lambda v: v > 0, "> 0"),
    ("--heartbeat-ms", "heartbeat_ms", lambda v: v > 0, "> 0"),
    ("--frames", "frames", lambda v: v >= 1, ">= 1 slots"),
    ("--threads", "threads", lambda v: v >= 1, ">= 1 threads"),
    ("--link-loss", "link_loss", lambda v: 0 <= v <= 1, "a probability in [0, 1]"),
)


def _check_ranges(args: argparse.Namespace) -> None:
    """A :class:`CLIError` naming the first numeric option of ``args`` out of its range."""
    for flag, attr, ok, what in _RANGES:
        value = getattr(args, attr, None)
        if value is not None and not ok(value):
            raise CLIError(f"{flag} {value}: give {what}")


def _peers_from_flags(args: argparse.Namespace) -> dict[int, str]:
    """``--peers`` -> ``{id: endpoint}``, or a :class:`CLIError` naming the bad entry."""
    from airpose_lib.errors import ConfigError  # standard library only
    from airpose_lib.runtime.transport import parse_peers

    try:
        peers = parse_peers(args.peers, args.host)
    except ConfigError as e:  # the flag's name in front of the entry's message
        raise CLIError(f"--peers: {e}") from None
    if args.id in peers:
        raise CLIError(f"--peers {' '.join(args.peers)}: lists this drone's own id {args.id}; give the other drones")
    return peers


def check_inputs(args: argparse.Namespace) -> None:
    """Fail before any process starts when ``--source``, ``--checkpoint`` or ``--onnx-dir`` is
    missing, ``--detector`` unknown or a numeric option out of range (the files' contents are
    checked when they are loaded)."""
    _check_ranges(args)
    if not str(args.source).startswith("synthetic"):
        if not Path(args.source).is_dir():
            raise CLIError(
                f"--source {args.source}: no such folder; give a recording folder in the official layout "
                "(machine_1/, machine_2/) or synthetic[:views=2,frames=300,...]")
        from airpose_lib.data.sequences.layout import DETECTOR_FILES  # the recordings' layout: light

        if args.detector not in DETECTOR_FILES:
            raise CLIError(f"--detector {args.detector}: unknown; give one of {', '.join(DETECTOR_FILES)}")
    if args.checkpoint is not None and not Path(args.checkpoint).is_file():
        raise CLIError(f"--checkpoint {args.checkpoint}: no such file; give a state_dict or a "
                              "checkpoints/*.pt of `airpose train`")
    if args.backend == "onnx" and (args.onnx_dir is None or not (Path(args.onnx_dir) / "meta.json").is_file()):
        what = "no meta.json in it" if args.onnx_dir and Path(args.onnx_dir).is_dir() else "no such folder"
        raise CLIError(f"--onnx-dir {args.onnx_dir}: {what}; give a folder written by `airpose export` "
                              "(it prints the folder)")


def add_node_arguments(p: argparse.ArgumentParser) -> None:
    """Options shared by ``airpose node`` and ``airpose launch`` (everything but id/port/peers)."""
    g = p.add_argument_group("schedule")
    g.add_argument("--mode", choices=("fixed", "pipelined"), default="fixed",
                   help="fixed: one frame per window, as the paper's test; pipelined: acquisition, "
                        "inference and exchange overlapped (default: fixed)")
    g.add_argument("--window-ms", type=float, default=240.0, help="fixed-mode window (default: 240)")
    g.add_argument("--rate", type=float, default=20.0, help="pipelined frame rate, Hz (default: 20)")
    g.add_argument("--latency-budget-ms", type=float, default=150.0,
                   help="pipelined per-frame deadline (default: 150)")
    g.add_argument("--fixed-rate", action="store_true",
                   help="pipelined: keep the rate even when overloaded (each drone skips slots on its own) "
                        "instead of agreeing with the others on a lower common rate over the heartbeat")
    g.add_argument("--max-rate-divisor", type=int, default=8,
                   help="pipelined: the lowest agreed rate is --rate / this (default: 8)")
    g.add_argument("--tolerance-ms", type=float, default=None,
                   help="stamp matching tolerance (default: half the camera frame period)")
    g.add_argument("--margin-ms", type=float, default=0.0, help="wake this long after a slot's target time")
    g.add_argument("--fallback", choices=("mean", "last"), default="mean",
                   help="a missing message is replaced by the mean parameters (the Fullcam "
                        "behaviour) or by that drone's last message (default: mean)")
    g.add_argument("--comm-timeout-ms", type=float, default=None,
                   help="wait at most this long per exchange (default: as long as the deadline allows)")
    g.add_argument("--peer-timeout-ms", type=float, default=1000.0,
                   help="silence after which a drone is no longer waited for (default: 1000)")
    g.add_argument("--heartbeat-ms", type=float, default=200.0)
    g.add_argument("--frames", type=int, default=None, help="schedule slots to run (default: the whole sequence)")
    g.add_argument("--start-s", type=float, default=None, help="sequence time of the first slot")
    g.add_argument("--max-runtime-s", type=float, default=None, help="stop after this long whatever happens")
    s = p.add_argument_group("camera and data")
    s.add_argument("--source", default="synthetic",
                   help="sequence folder (official layout), or synthetic[:views=2,frames=300,fps=30,"
                        "size=960x540,seed=0] (default: synthetic)")
    s.add_argument("--detector", default="openpose", help="detections used for the box (default: openpose)")
    s.add_argument("--min-confidence", type=float, default=0.2)
    s.add_argument("--box-margin-px", type=float, default=None,
                   help="person box = keypoints +- this many image pixels (default: the training crops' "
                        "mean margin, 120 px at the network camera's f = 1475, scaled to this camera)")
    s.add_argument("--preload", action="store_true",
                   help="decode the replayed frames into memory before the start (a camera delivers "
                        "raw frames; without it JPEG decoding counts as acquisition)")
    m = p.add_argument_group("network")
    m.add_argument("--backend", choices=("torch", "onnx", "onnx-int8", "fake"), default="torch",
                   help="onnx / onnx-int8: ONNX Runtime with a float32 / int8 stage 1, from --onnx-dir or "
                        "exported (and calibrated) into the kit cache on first use (`airpose export`)")
    m.add_argument("--variant", default="airpose")
    m.add_argument("--backbone", default="resnet18", help="resnet18 | resnet34 | resnet50 (default: resnet18)")
    m.add_argument("--input-size", type=int, default=128, help="crop side S in pixels (default: 128)")
    m.add_argument("--seed", type=int, default=0, help="seed of the random weights when no checkpoint is given")
    m.add_argument("--checkpoint", default=None, help="model state_dict or training checkpoint")
    m.add_argument("--onnx-dir", default=None, help="folder written by `airpose export`")
    m.add_argument("--threads", type=int, default=1, help="intra-op threads per drone (default: 1)")
    m.add_argument("--message-dtype", choices=("float32", "float16"), default="float32")
    m.add_argument("--fake-compute-ms", type=float, default=0.0, help=argparse.SUPPRESS)
    a = p.add_argument_group("authentication (CurveZMQ; see airpose_lib/runtime/keys.py)")
    a.add_argument("--insecure", action="store_true",
                   help="exchange messages without authentication (any process that reaches the "
                        "sockets can speak for any drone; trusted networks only)")
    n = p.add_argument_group("link emulation (applied to received packets)")
    n.add_argument("--link-latency-ms", type=float, default=0.0)
    n.add_argument("--link-jitter-ms", type=float, default=0.0)
    n.add_argument("--link-bandwidth-mbps", type=float, default=None, help="e.g. 50 (the paper's Wi-Fi)")
    n.add_argument("--link-loss", type=float, default=0.0, help="packet loss probability")
    n.add_argument("--link-seed", type=int, default=0)
    p.add_argument("--out", default=None,
                   help="result folder (default: <runs>/online, <runs> = $AIRPOSE_RUNS or runs/ at the checkout root)")


def build_node_parser(p: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    """Parser of ``airpose node`` (or fill ``p``)."""
    p = p or argparse.ArgumentParser(prog="airpose node", description="Run one drone of the online runtime.")
    p.add_argument("--id", type=int, required=True, help="this drone's id (1..255); camera view = id - 1")
    p.add_argument("--port", type=int, required=True, help="port this drone publishes on")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default: loopback)")
    p.add_argument("--peers", nargs="*", default=[], help="the other drones: ID@PORT or ID@HOST:PORT")
    p.add_argument("--view", type=int, default=None, help="camera of the source (default: id - 1)")
    p.add_argument("--t0", default=None,
                   help="start time (epoch s, this drone's clock); 'stdin' = wait for 'START <t0>' "
                        "(the launcher); default: the next multiple of 10 s at least 5 s away")
    p.add_argument("--clock-offset-ms", type=float, default=0.0, help="emulated clock error of this drone")
    p.add_argument("--keys", default=None, metavar="DIR",
                   help="folder with this drone's drone_<id>.key_secret and the peers' drone_<j>.key "
                        "(default: $AIRPOSE_SWARM_KEYS; make them with `airpose keys`)")
    add_node_arguments(p)
    return p


def config_from_args(args: argparse.Namespace, drone_id: int, port: int, peers: dict[int, str],
                     t0: float | None, clock_offset_ms: float = 0.0, host: str = "127.0.0.1",
                     view: int | None = None):
    """A :class:`~airpose_lib.runtime.config.NodeConfig` from parsed options."""
    from airpose_lib.runtime.backends import BackendSpec
    from airpose_lib.runtime.config import NodeConfig
    from airpose_lib.runtime.transport import LinkConfig

    backend = BackendSpec(kind=args.backend, variant=args.variant, backbone=args.backbone,
                          input_size=args.input_size, seed=args.seed, checkpoint=args.checkpoint,
                          onnx_dir=args.onnx_dir, threads=args.threads, message_dtype=args.message_dtype,
                          fake_compute_ms=args.fake_compute_ms)
    link = LinkConfig(args.link_latency_ms, args.link_jitter_ms, args.link_bandwidth_mbps, args.link_loss,
                      args.link_seed + drone_id)
    return NodeConfig(drone_id=drone_id, port=port, peers=peers, source=args.source, view=view,
                      backend=backend, mode=args.mode, window_ms=args.window_ms, rate_hz=args.rate,
                      latency_budget_ms=args.latency_budget_ms, adaptive_rate=not args.fixed_rate,
                      max_rate_divisor=args.max_rate_divisor, tolerance_ms=args.tolerance_ms,
                      margin_ms=args.margin_ms, clock_offset_ms=clock_offset_ms, fallback=args.fallback,
                      comm_timeout_ms=args.comm_timeout_ms, peer_timeout_ms=args.peer_timeout_ms,
                      heartbeat_ms=args.heartbeat_ms, frames=args.frames, start_s=args.start_s, t0=t0,
                      out_dir=args.out if args.out is not None else str(run_path("online")), link=link, host=host, max_runtime_s=args.max_runtime_s,
                      detector=args.detector, min_confidence=args.min_confidence,
                      box_margin_px=args.box_margin_px, preload=args.preload,
                      keys=getattr(args, "keys", None), insecure=args.insecure)


def run_node(args: argparse.Namespace) -> int:
    """Handler of ``airpose node``."""
    from airpose_lib.runtime.drone import DroneProcess

    check_inputs(args)
    peers = _peers_from_flags(args)
    if args.t0 == "stdin":  # started by a launcher: never outlive it
        die_with_parent()
        t0 = None
    elif args.t0 is None:
        t0 = math.ceil((time.time() + 5.0) / 10.0) * 10.0  # drones started by hand meet there
        print(f"t0 = {t0!r} (start all drones before then)", flush=True)
    else:
        t0 = float(args.t0)
    cfg = config_from_args(args, args.id, args.port, peers, t0,
                           args.clock_offset_ms, args.host, args.view)
    DroneProcess(cfg).run()
    return 0


# -- launch ------------------------------------------------------------------------------------
_LAUNCH_OWN = ("drones", "clock_offsets_ms", "lead_s", "timeout_s")


def add_launch_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--drones", type=int, default=2, help="number of drone processes (default: 2)")
    p.add_argument("--clock-offsets-ms", type=float, nargs="*", default=None,
                   help="per-drone clock errors, e.g. 0 3 (default: all 0)")
    p.add_argument("--lead-s", type=float, default=1.0, help="start this long after all drones are ready")
    p.add_argument("--timeout-s", type=float, default=3600.0, help="kill the drones after this long")
    add_node_arguments(p)


def run_launch(args: argparse.Namespace) -> int:
    """Handler of ``airpose launch``: start the drones on loopback, wait, print their summaries."""
    from airpose_lib.runtime.launcher import format_summaries, launch

    check_inputs(args)
    out = Path(args.out) if args.out is not None else run_path("online")
    # Every node option that differs from its default is passed on to the drones.
    node_defaults = vars(add_node_defaults())
    options = {k: v for k, v in vars(args).items()
               if k in node_defaults and k not in (*_LAUNCH_OWN, "out") and v != node_defaults[k]}
    # One launcher per folder (its drones are its children); stale=(): drones started by hand may
    # write there too, and their temp files are not ours to remove.
    with folder_lock(out, "online run folder", stale=()):
        fleet = launch(args.drones, out, options, clock_offsets_ms=args.clock_offsets_ms, lead_s=args.lead_s,
                       threads=args.threads)
        summaries = fleet.wait(args.timeout_s)
    print(format_summaries(summaries))
    missing = sorted(set(range(1, args.drones + 1)) - set(summaries))
    if missing:
        print(f"drone(s) {missing} ended without a summary; see {out}/node_<id>.log")
        return 1
    return 0


def add_node_defaults() -> argparse.Namespace:
    p = argparse.ArgumentParser(add_help=False)
    add_node_arguments(p)
    return p.parse_args([])


# -- export ------------------------------------------------------------------------------------
def add_export_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``airpose export``."""
    p.add_argument("--checkpoint", default=None,
                   help="training checkpoint or state_dict (default: random weights from --seed)")
    p.add_argument("--quantize", choices=("none", "int8"), default="none",
                   help="int8: also write a statically quantised stage 1 (ONNX Runtime QDQ, per-channel "
                        "weights) calibrated on still-frame crops (default: none)")
    p.add_argument("--calibration", default=None, metavar="DIR",
                   help="still-frame dataset of the calibration crops (default: the checkpoint's training "
                        "data, else the smoke profile's dataset)")
    p.add_argument("--calibration-samples", type=int, default=32,
                   help="evenly spaced train samples, every view (default: 32)")
    p.add_argument("--calibration-method", choices=("minmax", "percentile", "entropy"), default="minmax")
    p.add_argument("--per-tensor", action="store_true", help="one weight scale per tensor, not per channel")
    p.add_argument("--quantize-regressor", action="store_true",
                   help="quantise stage 1's regressor layers too (default: the backbone only)")
    p.add_argument("--variant", default="airpose", help="(random weights) network variant")
    p.add_argument("--backbone", default="resnet18", help="(random weights) resnet18 | resnet34 | resnet50")
    p.add_argument("--input-size", type=int, default=128, help="crop side S (a checkpoint's own wins)")
    p.add_argument("--seed", type=int, default=0, help="(random weights) seed")
    p.add_argument("--out", default=None, help="parent folder (default: <cache>/onnx)")
    p.add_argument("--force", action="store_true", help="rebuild even if the folder exists")


def run_export(args: argparse.Namespace) -> int:
    """Handler of ``airpose export``: prints the export folder (use it as --onnx-dir)."""
    from airpose_lib.runtime.backends import BackendSpec

    if args.checkpoint and not Path(args.checkpoint).is_file():
        raise CLIError(f"--checkpoint {args.checkpoint}: no such file; give a checkpoints/*.pt of `airpose train`")
    if args.calibration and not (Path(args.calibration) / "manifest.yaml").is_file():
        raise CLIError(f"--calibration {args.calibration} is not a still-frame dataset (no manifest.yaml); "
                       "make one with `airpose data generate --profile smoke`")
    from airpose_lib.model.quantize import QuantSettings
    from airpose_lib.runtime.edge import ensure_export

    precision = "int8" if args.quantize == "int8" else "fp32"
    spec = BackendSpec(kind="onnx-int8" if precision == "int8" else "onnx", variant=args.variant,
                       backbone=args.backbone, input_size=args.input_size, seed=args.seed,
                       checkpoint=args.checkpoint)
    settings = QuantSettings(per_channel=not args.per_tensor, calibration=args.calibration_method,
                             backbone_only=not args.quantize_regressor)
    folder = ensure_export(spec, precision, args.calibration, args.calibration_samples, settings,
                           root=args.out, force=args.force, progress=True)
    print(folder)
    return 0


# -- the subcommands -----------------------------------------------------------------------------
def add_node(sub) -> None:
    node = sub.add_parser(
        "node", help="run one drone of the online runtime (one process per drone)",
        description="One drone: replays its camera of a sequence in real time, runs the staged "
                    "network and exchanges the 136-number messages with the other drones over "
                    "ZeroMQ (fixed 240 ms windows as the paper, or pipelined). Writes "
                    "<out>/node_<id>.{jsonl,npz,summary.json}.")
    build_node_parser(node)
    node.set_defaults(func=run_node)


def add_launch(sub) -> None:
    launch = sub.add_parser(
        "launch", help="start N drone processes on loopback and print what they achieved",
        description="Start --drones drone processes (airpose node) on 127.0.0.1 with free ports and a "
                    "common start time, wait for them and print fps, latency, drops and bytes per drone.")
    add_launch_arguments(launch)
    launch.set_defaults(func=run_launch)


def add_export(sub) -> None:
    export = sub.add_parser(
        "export", help="export a network's drone stages to ONNX (optionally int8), cached",
        description="Export stage 1 and stages 2+ of a network to ONNX, and with --quantize int8 a "
                    "statically quantised stage 1 calibrated on the kit's still-frame crops, into "
                    "<cache>/onnx/<name>-<key>/ keyed by the checkpoint's bytes, the calibration crops "
                    "and the settings (reused when they match). Prints the folder, for "
                    "`airpose node --backend onnx|onnx-int8 --onnx-dir DIR`.")
    add_export_arguments(export)
    export.set_defaults(func=run_export)


def _cmd_keys(args: argparse.Namespace) -> int:
    from airpose_lib.runtime.keys import create_swarm_keys

    _check_ranges(args)
    folder = create_swarm_keys(args.out, range(1, args.drones + 1), force=args.force)
    print(f"CURVE keys of drones 1..{args.drones} in {folder}: give drone d its drone_<d>.key_secret and "
          f"every drone_<j>.key, then `airpose node --keys DIR` (or AIRPOSE_SWARM_KEYS=DIR)")
    return 0


def add_keys(sub) -> None:
    keys = sub.add_parser(
        "keys", help="make the CurveZMQ keys of a drone swarm (for `airpose node --keys`)",
        description="Make one CURVE key pair per drone (drone_<d>.key public, drone_<d>.key_secret "
                    "secret) in a folder of mode 0700. `airpose launch` makes its own for a loopback "
                    "swarm; this is for drones started by hand or on several machines.")
    keys.add_argument("--drones", type=int, required=True, help="drones 1..N")
    keys.add_argument("--out", type=Path, required=True, help="keys folder")
    keys.add_argument("--force", action="store_true", help="replace existing key pairs")
    keys.set_defaults(func=_cmd_keys)
