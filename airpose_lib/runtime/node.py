r"""One drone: camera replay, person box, staged network, message exchange, result stream.

Run as its own process (``airpose node --id 1 --port 5001 --peers 2@5002 ...`` or
``python -m airpose_lib.runtime.node ...``; :mod:`.launcher` starts N of them on loopback).

Per schedule slot (see :mod:`.sync`) a drone

1. wakes when its clock reads the slot's target + margin, picks its camera frame nearest the
   target, takes the person box from the frame's 2D detections and crops (``crop_input``);
2. runs stage 1 (backbone + iteration 1) and publishes its message;
3. for k = 2, 3: waits for the other drones' stage k-1 messages whose frame stamp matches its
   own within the tolerance, runs stage k, publishes (the last stage's message is not needed);
4. writes the frame's record (:mod:`.results`).

How long a stage waits and what replaces a missing message: :mod:`.stages`. The two modes,
``fixed`` (the paper's test: one frame per 240 ms window) and ``pipelined`` (acquisition,
stage 1 and the exchange of successive frames overlapped): :mod:`.loop`.

Authentication: the links are CurveZMQ (:mod:`.keys`), each peer on its own SUB socket; a
packet whose drone id is not the drone at the other end of its link is rejected as ``spoofed``,
a repeated stage message as ``replay`` (both logged, rate-limited, and counted in the summary's
``rejected``); a message for a frame already finished is counted as late and logged.
``--insecure`` (NodeConfig.insecure) runs without keys.

Faults: malformed or wrong-version packets are rejected with a log line (rate-limited), and
counted; a drone that dies stops being waited for after ``peer_timeout``; when it restarts (same
address, same ``t0``) it joins the schedule at the next slot and the others use its messages
again as soon as they arrive (ZeroMQ reconnects by itself).

Where each part lives: ``config`` (:class:`NodeConfig`), ``drone`` (:class:`DroneProcess`, the
parts put together), ``camera`` (frame selection, box, crop), ``stages`` (stage 1, waiting for
the peers, the later stages, fallbacks), ``messaging`` (packets out and in, refusals),
``startup`` (READY/START, heartbeats, rejoining), ``loop`` (the two modes' schedule loop),
``records`` (the frame records and the summary). This module is the process's entry point.
"""
from __future__ import annotations

import logging
import os
import sys

from .config import NodeConfig
from .drone import DroneProcess

__all__ = ["NodeConfig", "DroneProcess", "main"]


# -- command line ---------------------------------------------------------------------------------
def main(argv=None) -> int:
    """``python -m airpose_lib.runtime.node`` = ``airpose node``."""
    # One error policy (one line, exit status 2) for every command. Imported here, not at the top:
    # only the process needs the command line; `from airpose_lib.runtime.node import NodeConfig`
    # must not pull in the CLI.
    from airpose_lib.cli import main as cli_main

    return cli_main(["node", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":  # pragma: no cover
    status = main()
    # Everything is written and closed by now; skip the interpreter's teardown (torch's takes
    # seconds on a loaded machine, which would hold up the launcher and a restart).
    sys.stdout.flush()
    sys.stderr.flush()
    logging.shutdown()
    os._exit(status)
