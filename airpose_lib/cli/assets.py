"""``airpose data list | verify NAME | fetch NAME``: the asset subcommands of ``airpose data``
over :mod:`airpose_lib.assets`.

:func:`add_asset_commands` adds them to the ``airpose data`` sub-parser group of :mod:`.data`.
Their errors are :class:`~airpose_lib.assets.manifest.AssetError`, a user error (printed without a
traceback, exit status 2); ``verify`` and ``fetch`` exit with 1 when the asset is not complete.
"""
from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_asset_commands"]

# Handlers import the library when they run (as every command group: the parser is built on
# every call and stays free of the libraries' imports).


def _how(manifest) -> str:
    if manifest.generated:
        return "generate"
    if manifest.registration_required:
        return "register"
    return "download" if manifest.fetchable else "manual"


def _cmd_list(args: argparse.Namespace) -> int:
    from airpose_lib.assets.locate import locate
    from airpose_lib.assets.manifest import list_manifests
    from airpose_lib.assets.verify import verify

    manifests = list_manifests()
    rows = []
    for m in manifests:
        loc = locate(m)
        if args.no_check:
            status = "-"
        else:
            status = "ok" if verify(m, checksums=False).ok else (
                "missing" if not loc.path.exists() else "incomplete")
        rows.append((m.name, m.kind, _how(m), status, f"{loc.path} ({loc.origin})"))
    header = ("NAME", "KIND", "GET BY", "STATUS", "FOLDER (from)")
    widths = [max(len(r[i]) for r in (header, *rows)) for i in range(4)]
    for row in (header, *rows):
        print("  ".join(c.ljust(w) for c, w in zip(row[:4], widths)) + "  " + row[4])
    print("\nstatus checks presence and sizes only; `airpose data verify NAME` also compares SHA-256 and "
          "says how to get what is missing.")
    return 0


def _cmd_verify(args: argparse.Namespace) -> int:
    from airpose_lib.assets.verify import verify

    report = verify(args.name, root=args.root, checksums=not args.no_checksums)
    print(report.text())
    return 0 if report.ok else 1


def _cmd_fetch(args: argparse.Namespace) -> int:
    from airpose_lib.assets.fetch import fetch

    report = fetch(args.name, root=args.root, base_url=args.base_url, progress=not args.quiet,
                   allow_unverified=args.allow_unverified)
    print(report.text())
    return 0 if report.ok else 1


def add_asset_commands(data_subparsers) -> None:
    """Add ``list``, ``verify`` and ``fetch`` to the ``airpose data`` sub-parser group."""
    lst = data_subparsers.add_parser(
        "list", help="list the datasets and assets the notebooks can use, and whether they are here",
        description="List every manifest in data_manifests/ (official AirPose data and checkpoints, "
                    "SMPL-X, VPoser, the kit's generated datasets): kind, how to get it, status and folder.")
    lst.add_argument("--no-check", action="store_true", help="do not look into the folders (faster)")
    lst.set_defaults(func=_cmd_list)

    ver = data_subparsers.add_parser(
        "verify", help="check an asset's files (presence, size, SHA-256) and say how to get what is missing",
        description="Check the folder of an asset against its manifest: each file is present, missing, "
                    "of another size or of another SHA-256. Prints how to get what is missing. Exit status "
                    "1 when the asset is not complete.")
    ver.add_argument("name", metavar="NAME", help="asset name (see `airpose data list`)")
    ver.add_argument("--root", type=Path, default=None,
                     help="folder to check (default: the asset's environment variable, the assets config "
                          "~/.config/airpose/assets.yaml, else <cache>/assets/NAME)")
    ver.add_argument("--no-checksums", action="store_true", help="skip the SHA-256 comparison (faster)")
    ver.set_defaults(func=_cmd_verify)

    fe = data_subparsers.add_parser(
        "fetch", help="download an asset's public files (checksummed; never replaces your files)",
        description="Download the public files of an asset into its folder, check their SHA-256 and "
                    "unpack archives. Files already there are kept (a wrong one is reported, not "
                    "replaced). Assets that need a registration (SMPL-X, VPoser) are refused with "
                    "instructions.")
    fe.add_argument("name", metavar="NAME", help="asset name (see `airpose data list`)")
    fe.add_argument("--root", type=Path, default=None, help="target folder (default: as for verify)")
    fe.add_argument("--base-url", default=None, metavar="URL",
                    help="download <URL>/<file name> instead of the manifest's URLs (a mirror)")
    fe.add_argument("--allow-unverified", action="store_true",
                    help="also download files whose SHA-256 is not published (the value obtained is printed)")
    fe.add_argument("--quiet", action="store_true", help="no progress bars")
    fe.set_defaults(func=_cmd_fetch)
