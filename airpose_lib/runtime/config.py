"""Settings of one drone process (:class:`NodeConfig`): what ``airpose node`` and the launcher
fill in; plain data, so the CLI can build one without importing the runtime's machinery."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

from .backends import BackendSpec
from .transport import LinkConfig

__all__ = ["NodeConfig"]


@dataclass
class NodeConfig:
    """Everything one drone needs (all drones of a run share all but id, port, peers, offset).

    Times are milliseconds in the fields ending in ``_ms``.
    """

    drone_id: int
    port: int
    peers: dict[int, str]  # other drones: id -> endpoint
    source: str = "synthetic"
    view: int | None = None  # camera of the source; default drone_id - 1
    backend: BackendSpec = field(default_factory=BackendSpec)
    mode: str = "fixed"  # "fixed" or "pipelined"
    window_ms: float = 240.0  # fixed
    rate_hz: float = 20.0  # pipelined
    latency_budget_ms: float = 150.0  # pipelined
    adaptive_rate: bool = True  # pipelined: overloaded drones agree on a lower common rate (runtime.rate)
    max_rate_divisor: int = 8  # pipelined: the lowest common rate is rate_hz / this
    tolerance_ms: float | None = None  # stamp matching; default half a frame period
    margin_ms: float = 0.0  # wake after the target shutter time
    clock_offset_ms: float = 0.0
    fallback: str = "mean"  # "mean" or "last"
    comm_timeout_ms: float | None = None
    peer_timeout_ms: float = 1000.0
    heartbeat_ms: float = 200.0
    frames: int | None = None  # schedule slots; None = until the sequence ends
    start_s: float | None = None  # sequence time of slot 0; default the first stamp
    t0: float | None = None  # start (epoch s, own clock); None = read "START <t0>" on stdin
    out_dir: str = "runs/online"
    link: LinkConfig = field(default_factory=LinkConfig)
    host: str = "127.0.0.1"
    max_runtime_s: float | None = None
    detector: str = "openpose"
    min_confidence: float = 0.2
    box_margin_px: float | None = None  # None: source.network_box_margin of the view's K
    preload: bool = False  # decode the replayed frames into memory before the start
    keys: str | None = None  # folder of the swarm's CURVE keys (runtime.keys); None: $AIRPOSE_SWARM_KEYS
    insecure: bool = False  # no authentication (trusted networks only)

    @property
    def period_s(self) -> float:
        return self.window_ms / 1000.0 if self.mode == "fixed" else 1.0 / self.rate_hz

    @property
    def deadline_s(self) -> float:
        return self.window_ms / 1000.0 if self.mode == "fixed" else self.latency_budget_ms / 1000.0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["peers"] = {str(k): v for k, v in self.peers.items()}
        return d
