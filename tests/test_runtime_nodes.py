"""Real drone processes on loopback (ports chosen free at run time): the results equal the same
frames computed in one process, and lost messages, a killed and restarted drone and malformed
packets are survived. Every run is bounded (frames, ``max_runtime_s``, launcher time-outs)."""
from __future__ import annotations

import json
import socket
import struct
import time
import zlib

import numpy as np
import zmq

from airpose_lib.runtime import launcher
from airpose_lib.runtime import results as R
from airpose_lib.runtime.backends import BackendSpec, FakeStageModel
from airpose_lib.runtime.launcher import launch
from airpose_lib.runtime.offline import offline_batched, offline_inputs, offline_staged
from airpose_lib.runtime.transport import free_ports

SYN = "synthetic:frames=400,size=480x270,seed=1"


def _run(tmp_path, n, options, **kw):
    options = {"source": SYN, "max_runtime_s": 30, **options}
    fleet = launch(n, tmp_path, options, lead_s=0.5, **kw)
    try:
        summaries = fleet.wait(60)
    finally:
        fleet.stop()
    assert fleet.returncodes() == {d: 0 for d in range(1, n + 1)}, (tmp_path / "node_1.log").read_text()[-2000:]
    return summaries, [R.load_node_results(tmp_path / f"node_{d}.npz") for d in range(1, n + 1)]


def _offline(merged, spec, used=True):
    src = f"{SYN},views={merged['frame_index'].shape[1]}"
    crops, P, _ = offline_inputs(src, merged["frame_index"], spec.input_size)
    np.testing.assert_array_equal(P, merged["P"])  # the same crop vectors
    masks = np.stack([merged["used_s2"], merged["used_s3"]], -1) if used else None
    return crops, P, offline_staged(spec, crops, P, used=masks)


def _full_exchange(merged):
    """(F,) frames where every view used every other view's messages."""
    V = merged["flags"].shape[1]
    everyone = sum(1 << v for v in range(V))
    want = np.array([everyone & ~(1 << v) for v in range(V)])
    return ((merged["used_s2"] == want) & (merged["used_s3"] == want)).all(1)


def _assert_equal(online, offline, rows=slice(None)):
    for key in ("phi6d", "theta6d", "beta", "tau"):
        np.testing.assert_array_equal(online[key][rows], offline[key][rows], err_msg=key)


def test_three_drones_pipelined_equal_offline(tmp_path):
    summaries, res = _run(tmp_path, 3, {"backend": "fake", "mode": "pipelined", "rate": 20, "frames": 30})
    m = R.merge_views(res)
    assert len(m["slot"]) >= 20
    assert (m["frame_index"] == m["frame_index"][:, :1]).all()  # same frame on every drone
    full = _full_exchange(m)
    assert full.mean() >= 0.7, m["flags"]
    _, _, off = _offline(m, BackendSpec(kind="fake"))
    _assert_equal(m, off)  # bit for bit, fallbacks included (replayed from the records)
    # frames with the full exchange equal the perfect-exchange computation (mean of 2 others)
    _, _, perfect = _offline(m, BackendSpec(kind="fake"), used=False)
    _assert_equal(m, perfect, full)
    for s in summaries.values():
        assert s["bytes_per_frame"] == 2 * (40 + 544) and s["rejected"] == {}
        assert s["nominal_fps"] == 20.0


def test_two_drones_float16_clock_offset_and_lost_messages(tmp_path):
    """Fixed windows, half-precision messages, clocks 4 ms apart and 15 % of the packets lost."""
    summaries, res = _run(tmp_path, 2, {"backend": "fake", "window_ms": 80, "frames": 24,
                                        "message_dtype": "float16", "link_loss": 0.15},
                          clock_offsets_ms=(0.0, 4.0))
    m = R.merge_views(res)
    assert len(m["slot"]) >= 18
    assert np.all(np.abs(np.diff(m["stamp"], axis=1) - 0.004) < 0.0025)  # offset + the camera jitter
    spec = BackendSpec(kind="fake", message_dtype="float16")
    _, _, off = _offline(m, spec)
    _assert_equal(m, off)  # bit for bit, the fallbacks (mean parameters) included
    fallback = (m["flags"] & (R.FALLBACK_S2 | R.FALLBACK_S3)) != 0
    assert fallback.any() and sum(s["link_lost"] for s in summaries.values()) > 0
    _, _, perfect = _offline(m, spec, used=False)
    rows = fallback.any(1)
    assert not np.array_equal(m["theta6d"][rows], perfect["theta6d"][rows])
    full = _full_exchange(m)
    assert full.sum() >= 3
    _assert_equal(m, perfect, full)
    _, _, f32 = _offline(m, BackendSpec(kind="fake"), used=False)
    d = np.abs(m["theta6d"][full] - f32["theta6d"][full]).max()
    assert 0 < d < 1e-2  # half-precision messages: a small, non-zero change
    for s in summaries.values():
        assert s["bytes_per_frame"] == 2 * (40 + 272)


def test_torch_drones_equal_offline(tmp_path):
    opts = {"backend": "torch", "backbone": "resnet18", "input_size": 64, "frames": 4}
    summaries, res = _run(tmp_path, 2, opts)
    m = R.merge_views(res)
    assert len(m["slot"]) >= 3
    spec = BackendSpec(kind="torch", backbone="resnet18", input_size=64)
    crops, P, off = _offline(m, spec)
    _assert_equal(m, off)  # same kernels, same thread count: bit for bit
    full = _full_exchange(m)
    assert full.any()
    batched = offline_batched(spec, crops[full], P[full])
    for key in ("phi6d", "theta6d", "beta", "tau"):
        np.testing.assert_allclose(m[key][full], batched[key], rtol=1e-4, atol=1e-4, err_msg=key)


def _frames(path):
    try:
        return R.read_jsonl(path)[1]
    except FileNotFoundError:
        return []


def test_killed_drone_restarts_and_rejoins(tmp_path):
    options = {"backend": "fake", "source": SYN, "mode": "pipelined", "rate": 20, "frames": 200,
               "peer_timeout_ms": 300, "max_runtime_s": 40}
    fleet = launch(2, tmp_path, options)
    try:
        path1 = tmp_path / "node_1.jsonl"
        t_end = time.time() + 20
        while len(_frames(path1)) < 20 and time.time() < t_end:
            time.sleep(0.1)
        fleet.kill(2)
        t_kill = time.time()
        while time.time() < t_end:  # drone 1 carries on alone
            if sum(r["flags"] & R.NO_PEERS != 0 for r in _frames(path1)) >= 5:
                break
            time.sleep(0.1)
        fleet.restart(2)
        summaries = fleet.wait(60)
    finally:
        fleet.stop()
    assert fleet.returncodes() == {1: 0, 2: 0}
    one = R.load_node_results(tmp_path / "node_1.npz")
    assert one.summary["slots"] == 200
    f = one.frames
    alone = (f["flags"] & R.NO_PEERS) != 0
    with_two = f["used_s2"] == 2
    first_alone = np.argmax(alone)
    assert alone.sum() >= 5 and with_two[:first_alone].sum() >= 15
    assert with_two[first_alone:].sum() >= 10, "drone 2 did not rejoin"  # after the restart
    assert time.time() - t_kill < 60
    # drone 2's stream: two runs (meta records), the second a restart joining mid-schedule
    records = [json.loads(line) for line in open(tmp_path / "node_2.jsonl")]
    metas = [i for i, r in enumerate(records) if r["kind"] == "meta"]
    assert [records[i]["restart"] for i in metas] == [False, True]
    before = [r["slot"] for r in records[:metas[1]] if r["kind"] == "frame"]
    after = [r["slot"] for r in records[metas[1]:] if r["kind"] == "frame"]
    assert before and after and min(after) > max(before) and after[-1] == 199  # joined mid-schedule
    two = R.load_node_results(tmp_path / "node_2.npz")
    assert two.summary["valid"] >= 10
    m = R.merge_views([one, R.load_node_results(tmp_path / "node_2.jsonl")])
    _, _, off = _offline(m, BackendSpec(kind="fake"))
    _assert_equal(m, off)
    assert 1 in summaries and 2 in summaries


def _packet(kind, drone, stage=0, slot=0, stamp=0.0, payload=b"", version=1, dtype=0):
    """A packet built independently of runtime.wire (the documented layout)."""
    head = struct.pack("<4sBBBBBBHIIddI", b"APZ\x00", version, kind, drone, stage, dtype, 0, len(payload), 0,
                       slot, stamp, time.time(), 0)
    crc = zlib.crc32(payload, zlib.crc32(head))
    return head[:-4] + struct.pack("<I", crc) + payload


def _pose_as(ctx, keys, me: int, port: int):
    """A PUB socket speaking as drone ``me`` (its CURVE key pair from the launcher's keys folder)."""
    import zmq.auth

    pub = ctx.socket(zmq.PUB)
    pub.setsockopt(zmq.LINGER, 0)
    pub.curve_publickey, pub.curve_secretkey = zmq.auth.load_certificate(str(keys / f"drone_{me}.key_secret"))
    pub.curve_server = True
    pub.bind(f"tcp://127.0.0.1:{port}")
    return pub


def _listen_to(ctx, keys, me: int, drone: int, port: int):
    """A SUB socket of drone ``me`` subscribed to drone ``drone``'s PUB (CURVE client)."""
    import zmq.auth

    sub = ctx.socket(zmq.SUB)
    sub.setsockopt(zmq.LINGER, 0)
    sub.curve_publickey, sub.curve_secretkey = zmq.auth.load_certificate(str(keys / f"drone_{me}.key_secret"))
    sub.curve_serverkey = zmq.auth.load_certificate(str(keys / f"drone_{drone}.key"))[0]
    sub.connect(f"tcp://127.0.0.1:{port}")
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    return sub


def test_a_port_taken_before_the_drone_binds_it_moves_the_fleet(tmp_path, monkeypatch):
    """free_ports only says a port is free *now*; another process may bind it before the drone
    does (a CI failure). The launcher then starts the drones again on new ports instead of
    failing the run. Here the first port handed out is already listening."""
    squatter = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    squatter.bind(("127.0.0.1", 0))
    squatter.listen()
    taken = squatter.getsockname()[1]
    real, excluded = launcher.free_ports, []

    def taken_first(n, host="127.0.0.1", exclude=()):
        excluded.append(set(exclude))
        return [taken, *real(n - 1, host, exclude)] if len(excluded) == 1 else real(n, host, exclude)

    monkeypatch.setattr(launcher, "free_ports", taken_first)
    try:
        summaries, _ = _run(tmp_path, 2, {"backend": "fake", "window_ms": 80, "frames": 6})
    finally:
        squatter.close()
    assert len(excluded) == 2 and taken in excluded[1]  # moved once, never back to the taken port
    assert set(summaries) == {1, 2} and all(s["valid"] >= 4 for s in summaries.values())
    log = (tmp_path / "node_1.log").read_text()
    assert "Address already in use" in log and f"launcher: port {taken} was taken" in log


def test_a_drone_that_fails_for_another_reason_is_not_restarted(tmp_path):
    options = {"backend": "fake", "source": "synthetic:frames=400,size=480x270,seed=1,nonsense=3"}
    try:
        launch(1, tmp_path, options)
    except launcher.LaunchError as e:
        assert "exited before READY" in str(e)
    else:
        raise AssertionError("a drone with a bad source reached READY")
    assert "was taken" not in (tmp_path / "node_1.log").read_text()


def test_malformed_packets_are_logged_not_fatal(tmp_path):
    """The test poses as drone 2 (with drone 2's key): it answers drone 1's stage messages (so
    drone 1 uses them) and sends junk in between."""
    (port,) = free_ports(1)
    ctx = zmq.Context()
    options = {"backend": "fake", "source": SYN, "window_ms": 100, "frames": 20, "max_runtime_s": 30}
    fleet = launch(1, tmp_path, options, extra_peers={2: f"tcp://127.0.0.1:{port}"}, start=False)
    pub = _pose_as(ctx, tmp_path / "keys", 2, port)
    try:
        fleet.start()
        sub = _listen_to(ctx, tmp_path / "keys", 2, 1, fleet.ports[1])
        junk = [b"hello", b"\x00" * 60, _packet(2, 2, version=2), _packet(2, 2)[:-1] + b"\x00",
                _packet(1, 2, stage=1, payload=b"\x00" * 100), _packet(2, 9), _packet(7, 2)]
        answered, n, t_end = 0, 0, time.time() + 25
        while fleet.procs[1].poll() is None and time.time() < t_end:
            pub.send(_packet(2, 2, stamp=time.time()))  # HELLO: drone 2 is alive
            pub.send(junk[n % len(junk)])
            n += 1
            if sub.poll(20):
                buf = sub.recv()
                kind, drone, stage = buf[5], buf[6], buf[7]
                if kind == 1 and drone == 1:  # DATA: answer with the same stamp, our own numbers
                    slot, stamp = struct.unpack_from("<Id", buf, 16)
                    payload = np.full(136, 0.01 * stage, "<f4").tobytes()
                    pub.send(_packet(1, 2, stage=stage, slot=slot, stamp=stamp, payload=payload))
                    answered += 1
        summaries = fleet.wait(30)
    finally:
        fleet.stop()
        ctx.destroy(linger=0)
    assert fleet.returncodes() == {1: 0}
    s = summaries[1]
    assert s["valid"] >= 15
    # drone 9's HELLO came over drone 2's link: a spoof (before any check of the id itself)
    assert set(s["rejected"]) == {"magic", "short", "version", "crc", "payload_size", "spoofed", "kind"}
    log = (tmp_path / "node_1.log").read_text()
    assert "rejected a" in log and "CRC mismatch" in log
    res = R.load_node_results(tmp_path / "node_1.npz")
    assert (res.frames["used_s2"][res.valid] == 2).mean() >= 0.7  # drone 2's answers were used


def test_spoofed_and_replayed_packets_are_rejected_and_logged(tmp_path):
    """Drone 1 of a swarm {1, 2, 3}: the test is drone 2 (answers every stage message, and sends
    each answer twice: a replay) and drone 3, a member that claims to be drone 2 and sends other
    numbers first. Only drone 2's own answers are used; the spoofs and replays are rejected,
    logged and counted."""
    p2, p3 = free_ports(2)
    ctx = zmq.Context()
    options = {"backend": "fake", "source": SYN, "window_ms": 100, "frames": 20, "max_runtime_s": 30}
    fleet = launch(1, tmp_path, options, extra_peers={2: f"tcp://127.0.0.1:{p2}", 3: f"tcp://127.0.0.1:{p3}"},
                   start=False)
    keys = tmp_path / "keys"
    drone2, drone3 = _pose_as(ctx, keys, 2, p2), _pose_as(ctx, keys, 3, p3)
    sent = {"spoof": 0, "replay": 0}
    try:
        fleet.start()
        sub = _listen_to(ctx, keys, 2, 1, fleet.ports[1])
        t_end = time.time() + 25
        while fleet.procs[1].poll() is None and time.time() < t_end:
            drone2.send(_packet(2, 2, stamp=time.time()))  # HELLO: drone 2 is alive (drone 3 stays silent)
            if sub.poll(20):
                buf = sub.recv()
                kind, drone, stage = buf[5], buf[6], buf[7]
                if kind == 1 and drone == 1:
                    slot, stamp = struct.unpack_from("<Id", buf, 16)
                    spoof = _packet(1, 2, stage=stage, slot=slot, stamp=stamp,
                                    payload=np.full(136, 0.5, "<f4").tobytes())
                    drone3.send(spoof)  # "I am drone 2", over drone 3's link
                    sent["spoof"] += 1
                    time.sleep(0.002)
                    answer = _packet(1, 2, stage=stage, slot=slot, stamp=stamp,
                                     payload=np.full(136, 0.01 * stage, "<f4").tobytes())
                    drone2.send(answer)
                    drone2.send(answer)  # the same message again
                    sent["replay"] += 1
        summaries = fleet.wait(30)
    finally:
        fleet.stop()
        ctx.destroy(linger=0)
    assert fleet.returncodes() == {1: 0}
    s = summaries[1]
    assert s["authenticated"] is True
    assert sent["spoof"] >= 10 and s["rejected"].get("spoofed", 0) >= 10
    assert s["rejected"].get("replay", 0) >= 10
    log = (tmp_path / "node_1.log").read_text()
    assert "claims to be drone 2 but came over the link of drone 3 (authenticated)" in log
    assert "replay of drone 2's data message of slot" in log
    assert log.count("claims to be drone 2") <= 3 + s["rejected"]["spoofed"] // 100  # rate-limited
    # Drone 1's outputs are those computed offline with drone 2's real answers (0.01, 0.02), never
    # with the spoof's 0.5.
    m = R.merge_views([R.load_node_results(tmp_path / "node_1.npz")])
    used2, used3 = m["used_s2"][:, 0] == 2, m["used_s3"][:, 0] == 2  # drone 2's bit
    assert used2.mean() >= 0.7, m["used_s2"][:, 0]  # drone 2's answers were used
    crops, P, _ = offline_inputs(f"{SYN},views=1", m["frame_index"], 128)
    for i in range(len(used2)):
        ref = FakeStageModel()
        ref.stage1(crops[i, 0], P[i, 0])
        ref.stage(2, [np.full(136, 0.01, np.float32)] if used2[i] else [])
        ref.stage(3, [np.full(136, 0.02, np.float32)] if used3[i] else [])
        np.testing.assert_allclose(m["theta6d"][i, 0], ref.result()["theta6d"][0], atol=1e-6)


def test_overloaded_drones_agree_on_a_lower_common_rate(tmp_path):
    """Stage 1 of 110 ms at 20 Hz (50 ms slots): no drone keeps up with every slot. Over the
    heartbeat both settle on every 3rd slot (110 ms fits in 80 % of 150 ms), process the same
    slots, and complete them with each other's messages, instead of skipping on their own."""
    summaries, _ = _run(tmp_path, 2, {"backend": "fake", "fake_compute_ms": 110, "mode": "pipelined", "rate": 20,
                                      "frames": 120, "heartbeat_ms": 100})
    frames = {d: {r["slot"]: r for r in _frames(tmp_path / f"node_{d}.jsonl")} for d in (1, 2)}
    late = range(60, 120)  # after the first 3 s
    # On a quiet machine both drones ask for exactly 3; a loaded one may stretch stage 1 past
    # 120 ms, and then 4. Either way the two agree, slot by slot, on one lower rate.
    divisors = {d: [frames[d][k]["divisor"] for k in late] for d in (1, 2)}
    assert min(divisors[1] + divisors[2]) >= 3, divisors
    agree = sum(a == b for a, b in zip(divisors[1], divisors[2]))
    assert agree >= 0.9 * len(late), divisors
    taken = {d: {k for k in late if not frames[d][k]["flags"] & R.RATE_SKIPPED} for d in (1, 2)}
    assert len(taken[1] ^ taken[2]) <= 0.1 * len(taken[1] | taken[2]), taken
    assert all(k % frames[1][k]["divisor"] == 0 for k in taken[1])
    for d in (1, 2):
        done = [frames[d][k] for k in taken[d] if not frames[d][k]["flags"] & R.INVALID]
        assert len(done) >= 0.8 * len(taken[d]), f"drone {d}: {len(done)} of {len(taken[d])} completed"
        assert sum(r["used"][0] == [3 - d] for r in done) >= 0.8 * len(done)  # with the other's message
        s = summaries[d]
        assert s["rate_skipped"] > 0 and s["agreed_fps"] < 10 and s["drop_rate"] < 0.2
