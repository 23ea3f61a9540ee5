"""The ``airpose`` command: one module per command group, each over the library's functions.

=================  ===========================================================================
module             subcommands
=================  ===========================================================================
:mod:`.body`       ``body build``, ``body info``
:mod:`.data`       ``data generate``, ``data sequence``, and from :mod:`.assets` ``data list``,
                   ``data verify``, ``data fetch``
:mod:`.train`      ``pretrain``, ``train``
:mod:`.backbone`   ``backbone import`` (ImageNet weights as a backbone file)
:mod:`.eval`       ``eval``
:mod:`.prior`      ``prior train``, ``prior info``
:mod:`.fit`        ``fit`` (AirPose+)
:mod:`.finetune`   ``finetune``, ``predict``
:mod:`.node`       ``node``, ``launch``, ``export``, ``keys`` (the online runtime;
                   :mod:`.drone` is a drone's own process)
:mod:`.reproduce`  ``reproduce``
:mod:`.report`     ``report``
:mod:`.zoo`        ``zoo build``, ``zoo verify``, ``zoo list`` (the shipped networks)
:mod:`.common`     the user-error policy, path/range checks, ``--set`` parsing
=================  ===========================================================================

Building the parser imports only the standard library: every command group imports the library
in its handlers, when they run, so that ``airpose --help`` and a drone's start-up stay fast (no
torch, ZeroMQ, smplx, papermill or matplotlib).
"""
from __future__ import annotations

import argparse
import sys
import traceback
from collections.abc import Callable, Sequence

from .backbone import add_backbone
from .body import add_body
from .common import EXIT_USER_ERROR, CLIError, user_error_message
from .data import add_data
from .eval import add_eval
from .finetune import add_finetune, add_predict
from .fit import add_fit
from .node import add_export, add_keys, add_launch, add_node
from .prior import add_prior
from .report import add_report
from .reproduce import add_reproduce
from .train import add_pretrain, add_train
from .video import add_video
from .zoo import add_zoo

__all__ = ["CLIError", "build_parser", "main"]

# Subcommand builders, in help order; each adds its parser to the group.
_SUBCOMMANDS: tuple[Callable, ...] = (add_body, add_data, add_pretrain, add_backbone, add_train, add_eval, add_prior,
                                       add_fit, add_finetune, add_predict, add_node, add_launch, add_export,
                                       add_keys, add_reproduce, add_report, add_zoo, add_video)


def build_parser() -> argparse.ArgumentParser:
    """The ``airpose`` argument parser."""
    parser = _Parser(
        prog="airpose",
        description="Open reproducibility kit for AirPose (Saini et al., RA-L 2022).")
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    _add_debug_flag(parser)
    return parser


class _Parser(argparse.ArgumentParser):
    """argparse with the kit's error policy: a bad or missing flag is one line, exit status 2 (the
    usage is one ``--help`` away). Its subcommands' parsers are of this class too."""

    def error(self, message: str):
        self.exit(EXIT_USER_ERROR, f"airpose: error: {message}; see `{self.prog} --help`\n")


class _VersionAction(argparse.Action):
    """``--version``: the kit's version (:data:`airpose_lib.__version__`, its one home)."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, help="print the kit version and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        from airpose_lib import __version__  # the package root holds only the version

        print(f"{parser.prog} {__version__}")
        parser.exit()


def _add_debug_flag(parser: argparse.ArgumentParser, top: bool = True) -> None:
    """``--debug`` on the command and on every subcommand (``airpose train ... --debug`` works too)."""
    parser.add_argument("--debug", action="store_true", default=False if top else argparse.SUPPRESS,
                        help="on an error, show the Python traceback too")
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                _add_debug_flag(child, top=False)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status.

    Errors the user can fix (missing, damaged or foreign files, bad values, a busy or unwritable
    output folder) print one line ``airpose: error: <what, which file, the fix>`` and return 2;
    ``--debug`` also prints the traceback. Anything else is a bug and raises.
    """
    args = build_parser().parse_args(argv)
    try:
        if isinstance(getattr(args, "profile", None), str):
            from airpose_lib.profiles import loaded

            args.profile = loaded(args.profile)  # read once; every step of the command gets this reading
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("airpose: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - sorted into user errors and bugs below
        message = user_error_message(exc)
        if message is None:
            raise
        if args.debug:
            traceback.print_exception(exc)
        print(f"airpose: error: {message}", file=sys.stderr)
        return EXIT_USER_ERROR
