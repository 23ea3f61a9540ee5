"""Swarm keys: who may speak for which drone (CurveZMQ, built into pyzmq/libzmq).

Each drone ``d`` has a CURVE key pair: ``drone_<d>.key`` (public) and ``drone_<d>.key_secret``
(secret; czmq/pyzmq certificate format, ``zmq.auth.create_certificates``). A drone's PUB socket
is a CURVE server with its own secret key and accepts as subscribers only the public keys of its
swarm (a ZAP handler); each peer gets its own SUB socket that connects with that peer's public key
as ``curve_serverkey``. A packet therefore arrives on the socket of exactly one authenticated,
encrypted link, and the node rejects one whose drone id is not the drone at the other end of that
link (:mod:`.node`). CURVE's per-message nonces also make a link replay-proof; a repeated or
stale message from a member is still logged by the node.

Where a node finds the folder: ``airpose node --keys DIR``, else the environment variable
``AIRPOSE_SWARM_KEYS``. ``airpose launch`` makes the keys of a loopback swarm itself in
``<out>/keys/`` (mode 0700). For drones on several machines make them once with
``airpose keys --drones N --out DIR`` and copy to every drone its own ``drone_<d>.key_secret``
and every ``drone_<j>.key``. ``--insecure`` runs without authentication (trusted networks only).
"""
from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from airpose_lib.errors import UserError

__all__ = ["KEYS_ENV", "SwarmKeys", "SwarmKeyError", "create_swarm_keys", "load_swarm_keys", "keys_folder"]

KEYS_ENV = "AIRPOSE_SWARM_KEYS"


class SwarmKeyError(UserError, ValueError):
    """Missing or unreadable swarm keys; the message names the file and how to make it."""


@dataclass(frozen=True)
class SwarmKeys:
    """This drone's key pair and its peers' public keys (Z85-encoded bytes, as pyzmq takes them)."""

    drone: int
    public: bytes
    secret: bytes
    peers: dict[int, bytes] = field(default_factory=dict)
    folder: Path | None = None


def _name(drone: int) -> str:
    return f"drone_{int(drone)}"


def create_swarm_keys(folder: str | Path, drones: Iterable[int], force: bool = False) -> Path:
    """Make a key pair for each of ``drones`` in ``folder`` (mode 0700); existing ones are kept
    unless ``force``. Returns the folder."""
    import zmq.auth

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    os.chmod(folder, 0o700)
    for d in drones:
        if force or not (folder / f"{_name(d)}.key_secret").is_file():
            zmq.auth.create_certificates(str(folder), _name(d))
        os.chmod(folder / f"{_name(d)}.key_secret", 0o600)
    return folder


def keys_folder(option: str | Path | None) -> Path | None:
    """The keys folder from ``--keys``, else ``$AIRPOSE_SWARM_KEYS``; None if neither is set."""
    value = option if option else os.environ.get(KEYS_ENV)
    return Path(value).expanduser() if value else None


def _how(folder: Path) -> str:
    return (f"make them with `airpose keys --drones N --out {folder}` (or let `airpose launch` make a "
            "loopback swarm's keys)")


def load_swarm_keys(folder: str | Path, drone: int, peers: Iterable[int]) -> SwarmKeys:
    """Read drone ``drone``'s key pair and the public keys of ``peers`` from ``folder``."""
    import zmq.auth

    folder = Path(folder)
    if not folder.is_dir():
        raise SwarmKeyError(f"swarm keys folder {folder} does not exist; {_how(folder)}")

    def read(path: Path, secret: bool) -> tuple[bytes, bytes | None]:
        if not path.is_file():
            raise SwarmKeyError(f"{path} is missing (drone {path.stem.split('_')[-1]}'s "
                                f"{'secret' if secret else 'public'} key); {_how(folder)}")
        try:
            public, sec = zmq.auth.load_certificate(str(path))
        except (ValueError, OSError, IndexError) as e:
            raise SwarmKeyError(f"{path} is damaged or not a CURVE certificate ({e}); {_how(folder)}") from None
        if secret and not sec:
            raise SwarmKeyError(f"{path} holds no secret key; {_how(folder)}")
        return public, sec

    public, secret = read(folder / f"{_name(drone)}.key_secret", True)
    others = {int(j): read(folder / f"{_name(j)}.key", False)[0] for j in peers}
    return SwarmKeys(drone=int(drone), public=public, secret=secret, peers=others, folder=folder)
