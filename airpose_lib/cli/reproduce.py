"""``airpose reproduce``: run the notebooks of a profile and check notebook 02's table against
``results/<profile>/``."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import CLIError, parse_profile

__all__ = ['add_reproduce']

# Handlers import the library when they run, never at module level: the whole parser is built
# on every call (``airpose --help``, a drone's start-up) and must not import torch, ZeroMQ,
# smplx or papermill.


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from airpose_lib.reproduce import load_catalog, load_profile, run_profile
    from airpose_lib.reproduce.runner import check_parameters

    if args.list:
        prof = load_profile(args.profile)
        check_parameters(prof, load_catalog())
        print(f"profile {prof['name']}: {prof['description']}")
        for entry in load_catalog():
            params = prof["notebooks"].get(entry.name, {})
            print(f"  {entry.name:<24} {entry.file:<28} {params}")
        return 0
    if args.write_reference:  # before hours of notebooks, not after: reference results need a clean commit
        from airpose_lib.eval.reference import require_clean_checkout

        require_clean_checkout()
    report = run_profile(args.profile, only=args.only, out_dir=args.out, figures_dir=args.figures,
                         kernel_name=args.kernel, keep_going=args.keep_going,
                         log_output=args.log_output and not args.quiet, verbose=not args.quiet,
                         data_source=args.data_source)
    if not report.ok:
        print(f"\nreproduction FAILED (report: {report.run_dir}/report.json)", file=sys.stderr)
        print(report.failure_message(), file=sys.stderr)
        return 1
    if args.quiet:
        print(report.figures_dir)
    else:
        print(f"figures collected in {report.figures_dir}")
    from airpose_lib.reproduce.configs import kit_configs

    configs = kit_configs(args.profile)  # the reading the run started with (checked unchanged by the runner)
    differs = _check_reference(report, args.write_reference, configs.networks)
    if args.require_agreement and differs:
        print(f"\nreproduction DIFFERS from the committed reference in {', '.join(differs)} "
              f"(the notebooks' reference_check.md under {report.run_dir})", file=sys.stderr)
        return 1
    return _write_reference_report(report, configs.folders) if args.write_reference else 0


def _check_reference(report, write: bool, networks=None) -> list[str]:
    """After notebook 02 (Table I) and notebook 05 (the recordings' claims): their results against
    ``results/<profile>/``, or installed there with ``--write-reference``. Here, not in the
    runner: the runner imports nothing of the kit. ``networks``: the profile's ``networks:``
    section (None: it trains its own).

    Returns:
        the notebooks whose own check (shipped networks) found this run outside its tolerances.
    """
    from airpose_lib.eval.agreement import CHECK_FILE
    from airpose_lib.eval.reference import recordings_report, reference_report
    from airpose_lib.experiments.shipped import shipped_from

    done = {r.name: r for r in report.results if r.status == "ok"}
    if write and not {"02_ablation_table", "05_airpose_plus"} & set(done):
        raise CLIError("--write-reference: neither 02_ablation_table nor 05_airpose_plus ran; add --only "
                       "02_ablation_table (Table I) or --only 03 04 05 (the recordings)")
    command = " ".join(["airpose", *sys.argv[1:]])
    messages, differs = [], []
    for name, report_of in (("02_ablation_table", lambda out: reference_report(out / "results", report.profile,
                                                                               write=write, command=command)),
                            ("05_airpose_plus", lambda out: recordings_report(out, report.profile, write=write,
                                                                             command=command))):
        if name not in done:
            continue
        out = Path(done[name].parameters["output_dir"])
        check = out / CHECK_FILE
        if not write and (done[name].parameters.get("compare_reference") is False or shipped_from(networks)):
            # the notebook's own check: no comparison, or the agreement of shipped networks
            line = check.read_text().splitlines()[0] if check.is_file() else "no check"
            messages.append(f"{name}: {line}")
            differs += [name] if line.startswith("DIFFERS") else []
        else:
            messages.append(report_of(out))
    for msg in messages:
        if msg:
            print(msg)
    return differs


def _write_reference_report(report, folders=None) -> int:
    """With ``--write-reference`` after a run of every catalogued notebook: the run's HTML report
    into ``results/<profile>/report/``, size-capped, beside the reference tables it shows."""
    from airpose_lib.eval.reference import reference_dir
    from airpose_lib.paths import RunFolders
    from airpose_lib.reproduce import load_catalog
    from airpose_lib.reproduce.report import REFERENCE_MAX_BYTES, REFERENCE_MAX_IMAGE_PX, build_report

    from .report import print_report_result

    ran = {r.name for r in report.results if r.status == "ok"}
    missing = [e.name for e in load_catalog() if e.name not in ran]
    out = reference_dir(folders if folders is not None else RunFolders.of(report.profile)) / "report"
    if missing:
        print(f"reference report: {out} not written: it shows a whole run, and {missing} did not run in this "
              f"call (run the profile without --only to write it)")
        return 0
    return print_report_result(build_report(report.profile, run_dir=report.run_dir, figures_dir=report.figures_dir,
                                            out_dir=out, max_image_px=REFERENCE_MAX_IMAGE_PX,
                                            max_bytes=REFERENCE_MAX_BYTES))


def add_reproduce(sub) -> None:
    rep = sub.add_parser(
        "reproduce", help="run the notebooks with a profile and collect the figures",
        description="Execute the catalogued notebooks (notebooks/NN_*.ipynb) in order with papermill, "
                    "with the sizes of a profile, write the executed notebooks to "
                    "<out>/<profile>/notebooks/ and collect the figures into <figures>. Fails "
                    "(exit 1) if a notebook raises or an expected figure is missing.")
    rep.add_argument("--profile", type=parse_profile, default="smoke",
                     help="smoke: minutes on a CPU; cpu: hours on a CPU; paper: the paper's sizes "
                          "(GPU); the sizes are in airpose_lib/profiles/; or the path of your own profile "
                          "YAML (e.g. `inherits: cpu` and changes; its folders and results/<name>/ are "
                          "named after the file) (default: smoke)")
    rep.add_argument("--only", nargs="+", metavar="NAME",
                     help="run only these notebooks (names or unique prefixes, e.g. 00_body_model or 00)")
    rep.add_argument("--out", type=Path, default=None,
                     help="run folder (default: $AIRPOSE_RUNS, else runs/ at the checkout root; training "
                          "runs of `airpose train` are found there too)")
    rep.add_argument("--figures", type=Path, default=None,
                     help="where figures are collected (default: figures/<profile>/ at the checkout root)")
    rep.add_argument("--data-source", choices=("generated", "official"), default=None,
                     help="data_source of every notebook that takes one (official: the official assets, "
                          "see `airpose data list`); a profile's per-notebook data_source wins "
                          "(default: each notebook's, generated)")
    rep.add_argument("--kernel", default="python3", help="Jupyter kernel name (default: python3)")
    rep.add_argument("--keep-going", action="store_true",
                     help="run the remaining notebooks after a failure")
    rep.add_argument("--log-output", action="store_true", help="stream the notebooks' cell output")
    rep.add_argument("--list", action="store_true",
                     help="list the notebooks and the profile's parameters, run nothing")
    rep.add_argument("--quiet", action="store_true",
                     help="print only failures and where the figures are (no per-notebook lines or table)")
    rep.add_argument("--write-reference", action="store_true",
                     help="store notebook 02's Table I files as the reference in results/<profile>/, "
                          "notebook 05's recording tables in results/<profile>/recordings/ and, when every "
                          "notebook ran, the run's HTML report in results/<profile>/report/; refused unless "
                          "the checkout is a clean commit (default: only compare with them)")
    rep.add_argument("--require-agreement", action="store_true",
                     help="exit 1 when a profile on shipped networks (`networks: shipped:`) finds this run "
                          "outside the tolerances of its reference (notebooks 02 and 05 check it)")
    rep.set_defaults(func=_cmd_reproduce)
