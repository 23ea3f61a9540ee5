"""The runtime's pieces in one process: schedule and frame selection, message matching, peer
liveness, link emulation, the ZeroMQ transport, person box and crop, the fake stage model and
the result files."""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

from airpose_lib.data.network_input import (
    IMAGENET_MEAN,
    IMAGENET_STD,
    crop_input,
    network_box_margin,
    network_camera,
    person_box,
)
from airpose_lib.runtime import results as R
from airpose_lib.runtime.backends import FakeStageModel, fresh_copy
from airpose_lib.runtime.source import SyntheticSource, open_source
from airpose_lib.runtime.sync import CameraReplay, Mailbox, PeerTable, Schedule
from airpose_lib.runtime.transport import LinkConfig, LinkEmulator, Transport, endpoint, free_ports
from airpose_lib.runtime.wire import DATA, HELLO, decode_packet, encode_packet


# -- schedule and camera replay ------------------------------------------------------------------
def test_schedule_targets_lie_on_the_frame_grid():
    s = Schedule(t0=100.0, period_s=0.240, deadline_s=0.240, fps=30.0)
    # 240 ms = 7.2 frames: targets at frames 0, 7, 14, 22, 29, 36 (rounded), 4.17 slots per second
    frames = [round((s.target(k) - 100.0) * 30, 9) for k in range(6)]
    assert frames == [0, 7, 14, 22, 29, 36]
    assert s.deadline(3) == pytest.approx(s.target(3) + 0.240)
    assert abs(s.target(1000) - 100.0 - 240.0) <= 0.5 / 30
    k = s.first_slot_after(100.0 + 1.0)
    assert s.wake(k) >= 101.0 > s.wake(k - 1)
    assert s.first_slot_after(50.0) == 0


def test_replay_picks_the_same_frame_despite_clock_offsets():
    """Two drones with clocks off by a few ms (and cameras 7 ms apart, as the simulated data) pick
    the same frame for every slot."""
    fps, n = 30.0, 400
    t = np.arange(n) / fps
    s = Schedule(t0=0.0, period_s=0.05, deadline_s=0.15, fps=fps)
    a = CameraReplay(t, t0=0.0, offset_s=+0.004)
    b = CameraReplay(t + 0.007, t0=0.0, start=0.0, offset_s=-0.003)
    for k in range(200):
        ia, ib = a.select(s.target(k)), b.select(s.target(k))
        assert ia == ib == round(s.offset(k) * fps)
        assert abs(a.local_stamps[ia] - b.local_stamps[ib]) < 0.5 / fps  # matched by the tolerance
    with pytest.raises(ValueError):
        CameraReplay(np.array([0.0, 0.0]), 0.0)


# -- mailbox, peers ------------------------------------------------------------------------------
def _pkt(drone, stage, stamp, slot=0, value=0.0):
    return decode_packet(encode_packet(DATA, drone, stage=stage, slot=slot, stamp=stamp,
                                       payload=np.full(136, value, np.float32)))


def test_mailbox_matches_by_stamp_within_tolerance():
    box = Mailbox()
    box.put(_pkt(2, 1, 10.000, slot=5, value=1), 0.0)
    box.put(_pkt(2, 1, 10.050, slot=6, value=2), 0.0)
    box.put(_pkt(3, 1, 10.030, slot=5, value=3), 0.0)
    assert box.match(2, 1, 10.004, 0.010).payload[0] == 1
    assert box.match(2, 1, 10.046, 0.010).payload[0] == 2
    assert box.match(2, 1, 10.025, 0.010) is None  # between frames
    assert box.match(2, 2, 10.000, 0.010) is None  # other stage
    assert box.match(3, 1, 10.000, 0.010) is None and box.near_miss(3, 1, 5, 10.0, 0.010)
    assert not box.near_miss(2, 1, 5, 10.0, 0.010)
    box.put(_pkt(2, 2, 10.000, value=4), 0.0)
    assert box.latest(2, 10.000, 2, 0.01).payload[0] == 4  # its stage 2 of this frame
    assert box.latest(2, 10.000, 1, 0.01).payload[0] == 1  # not newer than stage 1
    assert box.latest(2, 9.0, 2, 0.01) is None
    box.prune(10.01)
    assert box.match(2, 1, 10.0, 0.01) is None and box.match(2, 1, 10.05, 0.01) is not None


def test_peer_table_liveness():
    peers = PeerTable(frozenset({2, 3}), timeout_s=1.0)
    assert peers.alive(0.0) == set() and not peers.all_heard()
    assert peers.heard(2, 0.0) is True and peers.heard(2, 0.5) is False
    peers.heard(3, 0.2)
    assert peers.alive(0.9) == {2, 3} and peers.all_heard()
    assert peers.alive(1.3) == {2}  # 3 last heard at 0.2, 2 at 0.5
    peers.bye(2)
    assert peers.alive(1.3) == set()
    assert peers.heard(3, 1.4) is True and peers.alive(1.4) == {3}  # rejoined


# -- link emulation and transport -------------------------------------------------------------------
def test_link_emulator_latency_bandwidth_loss():
    em = LinkEmulator(LinkConfig(latency_ms=5.0, bandwidth_mbps=1.0))
    for _ in range(10):
        em.admit(2, bytes(1250), now=0.0)  # 10 kbit each: 10 ms on a 1 Mbps link, queued
    assert em.release(0.0149) == []
    assert len(em.release(0.0151)) == 1
    assert len(em.release(0.1049)) == 8 and len(em.release(0.1051)) == 1
    em2 = LinkEmulator(LinkConfig(loss=0.3, seed=1))
    for _ in range(2000):
        em2.admit(2, b"x", 0.0)
    # binomial(2000, 0.3): mean 600, sd 20.5
    assert 520 < em2.lost < 680 and len(em2.release(0.0)) == 2000 - em2.lost
    assert not LinkConfig().active and LinkConfig(loss=0.1).active


def test_transport_pub_sub_on_loopback():
    pa, pb = free_ports(2)
    a = Transport(endpoint(pa), [endpoint(pb)])
    b = Transport(endpoint(pb), [endpoint(pa)], link=LinkConfig(latency_ms=20.0))
    try:
        got, t_end = [], time.time() + 5.0
        while not got and time.time() < t_end:  # PUB/SUB drops until the subscription is up
            a.send(encode_packet(HELLO, 1))
            got, _ = b.poll(0.05)
            for _ in range(10):
                if got:
                    break
                more, _ = b.poll(0.01)
                got += more
        assert got and got[0][0] == 0 and decode_packet(got[0][1]).drone == 1  # 0: peer ids not given
        # the emulated 20 ms latency holds a packet back
        msg = encode_packet(DATA, 1, stage=1, payload=np.ones(136, np.float32))
        t = time.time()
        a.send(msg)
        received = []
        while msg not in received and time.time() - t < 2.0:
            pkts, _ = b.poll(0.05)
            received += [buf for _, buf in pkts]
        assert msg in received and time.time() - t >= 0.019
        assert a.bytes_sent >= len(msg) and a.packets_sent >= 2
    finally:
        a.close()
        b.close()


# -- sources, box, crop -----------------------------------------------------------------------------
def test_person_box_from_detections():
    kp = np.array([[100, 200, 0.9], [300, 600, 0.8], [150, 250, 0.1], [250, 400, 0.5], [120, 300, 0.6]], float)
    box = person_box(kp, (1000, 700), min_confidence=0.2, margin_px=20, min_points=4)
    np.testing.assert_allclose(box, [80, 180, 320, 620])
    np.testing.assert_allclose(person_box(kp * [1, 1, 1], (310, 610), margin_px=20, min_points=4), [80, 180, 309, 609])
    assert person_box(kp, (1000, 700), min_confidence=0.7, min_points=4) is None
    assert person_box(None, (1000, 700)) is None
    assert person_box(np.zeros((25, 3)), (1000, 700)) is None  # OpenPose's "missing" = zeros


def test_default_box_margin_frames_the_person_as_the_training_crops():
    """The default margin is the training boxes' mean (joints +- 20 px, each side out by U(0, 200)
    px at f = 1475: 120 px), in the image's own pixels; so the same person seen at full and at
    half resolution gets the same P, with the crop scale of an average training crop."""
    K = network_camera()
    assert network_box_margin(K) == pytest.approx(120.0)
    K_half = K.copy()
    K_half[:2] *= 0.5  # the same camera at 960x540
    assert network_box_margin(K_half) == pytest.approx(60.0)
    K_long = K.copy()
    K_long[0, 0] = K_long[1, 1] = 2950.0  # twice the focal length, same resolution
    assert network_box_margin(K_long, K_net=K) == pytest.approx(240.0)

    rng = np.random.default_rng(0)
    xy = np.column_stack([rng.uniform(900, 1000, 25), rng.uniform(400, 640, 25)])  # a 240 px tall person
    kp = np.column_stack([xy, np.ones(25)])
    S = 128
    P = {}
    for name, KK, scale in (("full", K, 1.0), ("half", K_half, 0.5)):
        size = (int(1920 * scale), int(1080 * scale))
        box = person_box(kp * [scale, scale, 1], size, margin_px=network_box_margin(KK))
        P[name] = crop_input(np.zeros((size[1], size[0], 3), np.uint8), box, KK, S)[1][0]
    np.testing.assert_allclose(P["half"], P["full"], atol=1e-6)
    extent = max(np.ptp(xy[:, 0]), np.ptp(xy[:, 1]))
    assert P["full"][2] == pytest.approx(S / (extent + 2 * 120.0), rel=1e-6)  # s of P


def test_crop_input_geometry_and_padding():
    H, W, S = 400, 600, 64
    image = np.zeros((H, W, 3), np.uint8)
    image[150:250, 280:320] = 255  # the person: 40 x 100 px
    image[210, 300] = (255, 0, 0)  # a red marker
    image[:, 100:150] = 255  # something outside the (square) crop region's box
    bbox = np.array([250.0, 100.0, 350.0, 300.0])  # 100 x 200: padded left and right
    K = np.array([[500.0, 0, 299.0], [0, 500.0, 199.0], [0, 0, 1]])
    crop, P = crop_input(image, bbox, K, S, K_net=K)
    assert crop.shape == (1, 3, S, S) and crop.dtype == np.float32 and P.shape == (1, 3)
    # P by hand: centre (300, 200), side 200
    np.testing.assert_allclose(P[0], [300 / 299 - 1, 200 / 199 - 1, S / 200], rtol=1e-6)
    # by default P is formed in the networks' training camera (f 1475, centre (959.5, 539.5)):
    # the box scaled by k = 1475 / 500 about the principal point; the crop itself is the same
    crop_v, P_v = crop_input(image, bbox, K, S)
    k = 1475.0 / 500.0
    np.testing.assert_allclose(P_v[0], [(k * 1 + 959.5) / 959.5 - 1, (k * 1 + 539.5) / 539.5 - 1, S / (200 * k)],
                               rtol=1e-6)
    np.testing.assert_allclose(crop_v, crop, atol=1e-5)
    rgb = crop[0].transpose(1, 2, 0) * IMAGENET_STD + IMAGENET_MEAN
    # the marker lands at s (u - ccx) + S/2 = 0.32 * (300 - 300) + 32, 0.32 * 10 + 32
    r = rgb[..., 0] - rgb[..., 1]
    assert np.unravel_index(np.argmax(r), r.shape) == (35, 32)
    # the box covers crop columns 0.32 * (250 - 300) + 32 = 16 .. 48; outside is black
    assert np.abs(rgb[:, :15]).max() < 1e-5 and np.abs(rgb[:, 50:]).max() < 1e-5
    assert rgb[32, 30].min() > 0.9  # inside the person


def test_synthetic_source():
    src = open_source("synthetic:views=3,frames=20,fps=25,size=320x240,seed=4,missing=3+5")
    assert src.num_views == 3 and src.fps == 25.0
    v = src.view(2)
    img = v.image(7)
    assert img.shape == (240, 320, 3) and img.dtype == np.uint8
    assert not np.array_equal(img, v.image(8))
    assert v.keypoints(3) is None and v.keypoints(4).shape == (25, 3)
    box = person_box(v.keypoints(4), (320, 240), margin_px=0)
    np.testing.assert_allclose(box, np.clip(v.boxes[4], 0, [319, 239, 319, 239]), atol=1e-3)
    assert np.all(np.diff(v.stamps) > 0)
    with pytest.raises(ValueError):
        open_source("synthetic:colour=red")
    assert isinstance(SyntheticSource().view(0).K, np.ndarray)


# -- the fake stage model ---------------------------------------------------------------------------
def _run_pair(proto, x, P, exchange=True):
    a, b = fresh_copy(proto), fresh_copy(proto)
    ma, mb = a.stage1(x[0], P), b.stage1(x[1], P)
    for k in range(2, proto.num_stages + 1):
        ma, mb = a.stage(k, [mb] if exchange else []), b.stage(k, [ma] if exchange else [])
    return a.result(), ma


def test_fake_stage_model_uses_the_messages():
    g = np.random.default_rng(0)
    x = [g.normal(size=(1, 3, 16, 16)).astype(np.float32) for _ in range(2)]
    P = np.array([[0.1, -0.2, 0.5]], np.float32)
    proto = FakeStageModel(seed=3)
    out, m = _run_pair(proto, x, P)
    assert m.shape == (136,) and m.dtype == np.float32
    assert out["theta6d"].shape == (1, 21, 6) and out["tau"].shape == (1, 3) and out["beta"].shape == (1, 10)
    out2, m2 = _run_pair(proto, x, P)  # copies keep their own state: same inputs, same numbers
    np.testing.assert_array_equal(m, m2)
    _, alone = _run_pair(proto, x, P, exchange=False)
    assert not np.allclose(m, alone, atol=1e-3)  # the other view matters
    _, half = _run_pair(FakeStageModel(seed=3, message_dtype="float16"), x, P)
    assert half.dtype == np.float16 and 0 < np.abs(half.astype(np.float32) - m).max() < 1e-2
    c = fresh_copy(proto)
    with pytest.raises(RuntimeError):
        c.stage(2, [])
    c.stage1(x[0], P)
    with pytest.raises(ValueError):
        c.stage(3, [])


# -- result files -------------------------------------------------------------------------------
def _record(slot, flags=0, value=0.0, used=((2,), (2,))):
    return {"kind": "frame", "drone": 1, "view": 0, "slot": slot, "frame_index": 2 * slot, "stamp": 1.0 + slot,
            "shutter": 1.0 + slot, "target": 1.0 + slot, "t_done": 1.05 + slot, "latency": 0.05,
            "used": [list(u) for u in used], "timing": {"stage1": 0.01}, "flags": flags,
            "phi6d": np.full(6, value, np.float32), "theta6d": np.full(126, value, np.float32),
            "beta": np.full(10, value, np.float32), "tau": np.array([0, 0, 10 + value], np.float32),
            "P": np.array([0.1, 0.2, 0.5], np.float32), "bbox": np.array([1, 2, 3, 4.0])}


def test_result_stream_roundtrip(tmp_path):
    w = R.ResultWriter(tmp_path / "node_1.jsonl", {"drone": 1, "view": 0, "K": np.eye(3) * 2, "input_size": 64})
    vals = np.random.default_rng(0).normal(size=3).astype(np.float32)
    w.write(_record(0, value=vals[0]))
    w.write(_record(1, flags=R.FALLBACK_S2 | R.NO_PEERS, value=vals[1], used=((), (2,))))
    w.write({"kind": "frame", "slot": 2, "flags": R.SKIPPED, "used": [], "timing": {}})
    w.write(_record(3, flags=R.DROPPED, value=vals[2]))
    w.close()
    with open(tmp_path / "node_1.jsonl", "a") as f:
        f.write('{"kind": "frame", "slot": 9, "fl')  # a killed writer's last line
    res = R.load_node_results(tmp_path / "node_1.jsonl")
    assert len(res) == 4 and res.valid.tolist() == [True, True, False, False]
    assert res.frames["theta6d"].shape == (4, 21, 6) and res.frames["theta6d"][1, 3, 2] == vals[1]  # exact
    assert np.isnan(res.frames["theta6d"][2]).all()
    assert res.frames["used_s2"].tolist() == [2, 0, -1, 2] and R.mask_to_ids(6) == [2, 3]
    R.write_npz(tmp_path / "node_1.jsonl", tmp_path / "node_1.npz")
    res2 = R.load_node_results(tmp_path / "node_1.npz")
    for k, v in res.frames.items():
        np.testing.assert_array_equal(v, res2.frames[k])
    assert res2.meta["input_size"] == 64
    pred = R.predictions(res)
    assert pred["theta6d"].shape == (2, 21, 6) and pred["K"].shape == (2, 3, 3) and pred["K"][0, 0, 0] == 2
    assert R.describe_flags(R.FALLBACK_S2 | R.DROPPED) == ["fallback_s2", "dropped"]
    # eval reads it like offline predictions: camera-frame SMPL-X parameters
    from airpose_lib.model import to_smplx_params

    params = to_smplx_params(pred, pred["P"], pred["K_net"])  # P lives in the network's camera
    assert params["theta"].shape == (2, 21, 3, 3) and params["tau"].shape == (2, 3)
    assert pred["K_net"][0, 0, 0] == 1475.0


def test_merge_views_joins_on_slots(tmp_path):
    out = []
    for d in (1, 2):
        w = R.ResultWriter(tmp_path / f"node_{d}.jsonl", {"drone": d, "view": d - 1, "K": np.eye(3) * d})
        for slot in range(4):
            flags = R.DROPPED if (d, slot) == (2, 1) else 0
            w.write({**_record(slot, flags, value=10 * d + slot), "drone": d, "view": d - 1})
        w.close()
        out.append(R.load_node_results(tmp_path / f"node_{d}.jsonl"))
    m = R.merge_views(out[::-1])
    assert m["slot"].tolist() == [0, 2, 3] and m["theta6d"].shape == (3, 2, 21, 6)
    np.testing.assert_array_equal(m["beta"][:, :, 0], [[10, 20], [12, 22], [13, 23]])
    assert m["K"].shape == (2, 3, 3) and m["K"][1, 0, 0] == 2 and m["K_net"][1, 0, 0] == 1475.0
    allm = R.merge_views(out, valid_only=False)
    assert allm["slot"].tolist() == [0, 1, 2, 3] and allm["flags"][1].tolist() == [0, R.DROPPED]
    json.dumps(R._jsonable({"a": np.float32(1.5), "b": np.arange(2)}))


# -- command line -----------------------------------------------------------------------------------
def test_node_and_launch_command_lines():
    from airpose_lib import cli
    from airpose_lib.cli.node import config_from_args
    from airpose_lib.runtime.transport import parse_peers

    assert parse_peers(["2@5002,3@10.0.0.3:5003", "4@tcp://h:1"]) == {
        2: "tcp://127.0.0.1:5002", 3: "tcp://10.0.0.3:5003", 4: "tcp://h:1"}
    with pytest.raises(ValueError):
        parse_peers(["5002"])
    a = cli.build_parser().parse_args(
        ["node", "--id", "2", "--port", "5002", "--peers", "1@5001", "--mode", "pipelined", "--rate", "15",
         "--message-dtype", "float16", "--link-loss", "0.1", "--backend", "fake", "--preload"])
    cfg = config_from_args(a, a.id, a.port, parse_peers(a.peers), t0=123.0, clock_offset_ms=2.0)
    assert cfg.period_s == pytest.approx(1 / 15) and cfg.deadline_s == pytest.approx(0.150)
    assert cfg.peers == {1: "tcp://127.0.0.1:5001"} and cfg.backend.message_dtype == "float16"
    assert cfg.link.loss == 0.1 and cfg.preload and cfg.clock_offset_ms == 2.0 and cfg.host == "127.0.0.1"
    b = cli.build_parser().parse_args(["launch", "--drones", "3", "--window-ms", "300", "--clock-offsets-ms", "0", "1",
                                       "2"])
    assert b.drones == 3 and b.window_ms == 300 and b.clock_offsets_ms == [0, 1, 2] and b.func is not None
    from airpose_lib.runtime.launcher import node_options

    assert node_options({"backend": "fake", "window_ms": 60, "preload": True, "checkpoint": None, "x": False}) == [
        "--backend", "fake", "--window-ms", "60", "--preload"]


# -- authentication (CurveZMQ) ----------------------------------------------------------------------
def _first_packets(rx: Transport, send, seconds: float = 3.0) -> list:
    got, t_end = [], time.time() + seconds
    while not got and time.time() < t_end:  # PUB/SUB drops until the subscription is up
        send()
        got, _ = rx.poll(0.05)
    return got


def test_curve_links_tell_the_sender_and_refuse_outsiders(tmp_path):
    """Drone 2 hears drone 1 over an authenticated link tagged with 1; a process without drone 1's
    secret key listening at drone 1's address (a plain PUB, or one with a key of its own) is
    never heard."""
    import zmq

    from airpose_lib.runtime.keys import create_swarm_keys, load_swarm_keys

    keys = create_swarm_keys(tmp_path / "keys", [1, 2])
    pa, pb, pc, pd, pe, pf = free_ports(6)
    a = Transport(endpoint(pa), {2: endpoint(pb)}, keys=load_swarm_keys(keys, 1, [2]))
    b = Transport(endpoint(pb), {1: endpoint(pa)}, keys=load_swarm_keys(keys, 2, [1]))
    # b also believes drone 1 speaks at pc, where an impostor without drone 1's secret key listens
    c = Transport(endpoint(pd), {1: endpoint(pc)}, keys=load_swarm_keys(keys, 2, [1]))
    d = Transport(endpoint(pf), {1: endpoint(pe)}, keys=load_swarm_keys(keys, 2, [1]))
    ctx = zmq.Context()
    plain = ctx.socket(zmq.PUB)
    plain.setsockopt(zmq.LINGER, 0)
    plain.bind(endpoint(pc))
    try:
        got = _first_packets(b, lambda: a.send(encode_packet(HELLO, 1)))
        assert got and got[0][0] == 1 and decode_packet(got[0][1]).drone == 1
        assert b.authenticated
        assert _first_packets(c, lambda: plain.send(encode_packet(HELLO, 1)), 1.5) == []
        rogue = ctx.socket(zmq.PUB)  # CURVE server with a key pair that is not drone 1's
        rogue.setsockopt(zmq.LINGER, 0)
        public, secret = zmq.curve_keypair()
        rogue.curve_secretkey, rogue.curve_publickey, rogue.curve_server = secret, public, True
        rogue.bind(endpoint(pe))
        assert _first_packets(d, lambda: rogue.send(encode_packet(HELLO, 1)), 1.5) == []
    finally:
        for t in (a, b, c, d):
            t.close()
        ctx.destroy(linger=0)


def test_a_refused_handshake_is_logged_once_per_address(tmp_path, caplog):
    """Outsiders' SUB sockets (key pairs not of the swarm) from one address, five handshakes: the
    drone's ZAP handler refuses each, and logs the first one only."""
    import logging
    import time

    import zmq

    from airpose_lib.runtime.keys import create_swarm_keys, load_swarm_keys

    keys = create_swarm_keys(tmp_path / "keys", [1, 2])
    (port,) = free_ports(1)
    drone = Transport(endpoint(port), {2: endpoint(free_ports(1)[0])}, keys=load_swarm_keys(keys, 1, [2]))
    ctx = zmq.Context()
    outsiders = []
    refusals = []
    real = drone.auth.credentials_providers["*"].callback
    drone.auth.credentials_providers["*"].callback = lambda d, k: refusals.append(k) or real(d, k)
    try:
        with caplog.at_level(logging.WARNING, logger="airpose.runtime"):
            for _ in range(5):
                sub = ctx.socket(zmq.SUB)
                sub.setsockopt(zmq.LINGER, 0)
                sub.curve_publickey, sub.curve_secretkey = zmq.curve_keypair()
                sub.curve_serverkey = load_swarm_keys(keys, 1, [2]).public
                sub.connect(endpoint(port))
                outsiders.append(sub)
            deadline = time.monotonic() + 10
            while len(refusals) < 5 and time.monotonic() < deadline:
                time.sleep(0.05)
        assert len(refusals) == 5  # every handshake reached the handler and was refused
        logged = [r.getMessage() for r in caplog.records if "refused a CURVE handshake" in r.getMessage()]
        assert logged == ["refused a CURVE handshake from 127.0.0.1: its key is not one of the swarm's "
                          "(further refusals from this address are not logged)"], logged
    finally:
        drone.close()
        ctx.destroy(linger=0)


def test_swarm_keys_errors_name_the_file(tmp_path):
    from airpose_lib.runtime.keys import SwarmKeyError, create_swarm_keys, load_swarm_keys

    keys = create_swarm_keys(tmp_path / "keys", [1])
    assert (keys.stat().st_mode & 0o777) == 0o700
    with pytest.raises(SwarmKeyError, match="drone_2.key is missing"):
        load_swarm_keys(keys, 1, [2])
    (keys / "drone_1.key_secret").write_text("garbage")
    with pytest.raises(SwarmKeyError, match="drone_1.key_secret"):
        load_swarm_keys(keys, 1, [])


@pytest.mark.parametrize("box", [[600.0, 10.0, 700.0, 80.0], [-90.0, -50.0, -10.0, -5.0], [10.0, 300.0, 50.0, 400.0],
                                 [50.0, 50.0, 50.0, 80.0]])
def test_crop_input_refuses_a_box_outside_the_image(box):
    image = np.full((270, 480, 3), 128, np.uint8)
    K = np.array([[500.0, 0, 240], [0, 500.0, 135], [0, 0, 1]])
    with pytest.raises(ValueError, match="does not overlap"):
        crop_input(image, np.array(box), K, 64)
    crop, _ = crop_input(image, np.array([470.0, 260.0, 600.0, 400.0]), K, 64)  # partly inside: fine
    assert np.isfinite(crop).all() and (crop != crop.min()).any()
