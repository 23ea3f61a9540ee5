"""``airpose zoo build | verify | list``: a profile's shipped networks (``results/<profile>/networks/``)."""
from __future__ import annotations

import argparse

from .common import parse_profile

__all__ = ["add_zoo"]


def _cmd_zoo_build(args: argparse.Namespace) -> int:
    from airpose_lib.experiments.zoo_build import build_shipped
    from airpose_lib.reproduce.configs import kit_configs

    print(f"wrote {build_shipped(kit_configs(args.profile), progress=not args.quiet)}")
    return 0


def _cmd_zoo_verify(args: argparse.Namespace) -> int:
    from airpose_lib.paths import RunFolders
    from airpose_lib.zoo import read_manifest, verified, zoo_dir

    folder = zoo_dir(RunFolders.of(args.profile))
    for name in read_manifest(folder):  # raises one line on the first damaged file
        print(f"ok  {verified(folder, name).relative_to(folder.parent)}")
    return 0


def _cmd_zoo_list(args: argparse.Namespace) -> int:
    from airpose_lib.paths import RunFolders
    from airpose_lib.zoo import zoo_dir, zoo_table

    print(zoo_table(zoo_dir(RunFolders.of(args.profile))))
    return 0


def add_zoo(sub) -> None:
    zp = sub.add_parser("zoo", help="the shipped networks of a profile (results/<profile>/networks/)",
                        description="The trained networks a profile ships so that its notebooks run without "
                                    "training: build them from the profile's runs, check them, list them.")
    zsub = zp.add_subparsers(dest="zoo_command", metavar="COMMAND", required=True)
    for name, func, text in (
            ("build", _cmd_zoo_build, "train what is missing (the first seed's four variants, the recordings' "
                                      "fine-tunings, the prior) and write the float16 files and manifest"),
            ("verify", _cmd_zoo_verify, "check every shipped file's size and SHA-256 against the manifest"),
            ("list", _cmd_zoo_list, "print the manifest as a table")):
        p = zsub.add_parser(name, help=text, description=text[0].upper() + text[1:] + ".")
        p.add_argument("--profile", type=parse_profile, default="cpu", help="the shipping profile (default: cpu)")
        if name == "build":
            p.add_argument("--quiet", action="store_true", help="no progress bars")
        p.set_defaults(func=func)
