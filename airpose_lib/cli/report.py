"""``airpose report``: the static HTML report of a reproduction (the executed notebooks and the
collected figures)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import CLIError, parse_profile

__all__ = ["add_report", "print_report_result"]

# Handlers import the library when they run (see cli/__init__.py): nbconvert is not imported to
# build the parser.


def print_report_result(result) -> int:
    """Print where the report is and its size; every problem on stderr. Returns the exit status
    (1 when a notebook is missing or failed, or a catalogue figure is missing)."""
    print(result.summary())
    if result.ok:
        return 0
    print(f"\nreport FAILED: {len(result.problems)} problem(s); the report shows them on its first page",
          file=sys.stderr)
    for line in result.problems:
        print(f"  {line}", file=sys.stderr)
    return 1


def _cmd_report(args: argparse.Namespace) -> int:
    from airpose_lib.paths import profile_name, runs_root
    from airpose_lib.reproduce.report import DEFAULT_MAX_IMAGE_PX, build_report

    name = profile_name(args.profile)  # an own profile file's run is named after the file
    run_dir = (args.runs if args.runs is not None else runs_root()) / name
    max_px = args.max_image_px if args.max_image_px is not None else DEFAULT_MAX_IMAGE_PX
    if max_px < 64:
        raise CLIError(f"--max-image-px {max_px}: give at least 64 pixels")
    try:
        result = build_report(name, run_dir=run_dir, figures_dir=args.figures, out_dir=args.out,
                              max_image_px=max_px)
    except (FileNotFoundError, FileExistsError) as e:
        raise CLIError(str(e)) from None
    return print_report_result(result)


def add_report(sub) -> None:
    rep = sub.add_parser(
        "report", help="build the static HTML report of a reproduction",
        description="Build a static HTML report (opens offline in a browser) from the notebooks "
                    "`airpose reproduce --profile P` executed (<runs>/<P>/notebooks/) and the figures it "
                    "collected (figures/<P>/): an index page with the provenance (commit, machine, wall "
                    "times) and every figure with its caption from figures/README.md, then one page per "
                    "notebook in the paper's order (nbconvert). Fails (exit 1) if a notebook is missing or "
                    "has an error output, or a figure of the catalogue is missing; the report is written "
                    "all the same.")
    rep.add_argument("--profile", type=parse_profile, default="smoke",
                     help="the reproduction's profile, a name or your own profile YAML (default: smoke)")
    rep.add_argument("--runs", type=Path, default=None,
                     help="run root of `airpose reproduce --out` (default: $AIRPOSE_RUNS, else runs/ at the "
                          "checkout root)")
    rep.add_argument("--figures", type=Path, default=None,
                     help="the collected figures (default: figures/<profile>/ at the checkout root)")
    rep.add_argument("--out", type=Path, default=None,
                     help="report folder, replaced as a whole (default: <runs>/<profile>/report/)")
    rep.add_argument("--max-image-px", type=int, default=None, metavar="PX",
                     help="longer side of every image in the report, in pixels (default: 1200, "
                          "reproduce.report.DEFAULT_MAX_IMAGE_PX)")
    rep.set_defaults(func=_cmd_report)
