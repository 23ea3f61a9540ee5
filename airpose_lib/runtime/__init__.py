"""Online, decentralised runtime: one OS process per drone, 136-number messages over ZeroMQ.

Modules: ``wire`` (the versioned packet format), ``keys`` (the swarm's CurveZMQ key pairs),
``transport`` (ZeroMQ PUB/SUB, authenticated per-peer links, link emulation, free ports), ``sync`` (clocks, the frame schedule, camera replay, message matching, peer
liveness), ``source`` (frame sources: the official-layout sequences of ``airpose_lib.data`` or a
procedural stand-in; person box and crop), ``backends`` (the staged-model protocol: torch,
ONNX Runtime or a fast fake), ``node`` (one drone: ``airpose node``; its settings in ``config``,
its parts in ``drone``, ``camera``, ``stages``, ``messaging``, ``startup``, ``loop`` and
``records``), ``launcher`` (N drones on
loopback: ``airpose launch``), ``results`` (the per-drone record stream and its readers),
``offline`` (the same frames computed in one process, the reference), ``edge`` (the cached,
optionally int8-quantised ONNX export of a drone's network), ``options`` (CLI).

Names are imported lazily, so ``import airpose_lib.runtime`` is cheap (the CLI builds its parser
from ``options`` without importing ZeroMQ or torch).
"""
from __future__ import annotations

from airpose_lib._lazy import lazy_namespace

_MODULES = ("wire", "keys", "transport", "sync", "source", "backends", "config", "camera", "stages", "messaging",
            "startup", "loop", "records", "drone", "node", "launcher", "results", "offline", "edge", "options")
__getattr__, __dir__ = lazy_namespace(__name__, globals(), _MODULES)
