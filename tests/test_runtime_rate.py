"""The swarm's common rate (runtime.rate): the divisor rule by hand, its hysteresis, the HELLO field."""
from __future__ import annotations

import math

import pytest

from airpose_lib.runtime.rate import RateAgreement, needed_divisor, takes_slot
from airpose_lib.runtime.wire import DATA, HELLO, decode_packet, encode_packet

PERIOD = 0.05  # 20 Hz


@pytest.mark.parametrize("stage1_ms, m", [(0, 1), (30, 1), (40, 1), (41, 2), (80, 2), (81, 3), (119, 3),
                                          (1000, 8), (math.nan, 1)])
def test_needed_divisor_by_hand(stage1_ms, m):
    # m periods of 50 ms, 80 % of them for stage 1: 40 ms fits in 1, 80 ms in 2, 120 ms in 3; at most 8
    assert needed_divisor(stage1_ms / 1000, PERIOD, headroom=0.8, max_divisor=8) == m


def test_divisor_rises_at_once_and_falls_one_step_after_settling():
    r = RateAgreement(PERIOD, settle_s=2.0, window=3)
    for t in (0.0, 0.1, 0.2):
        r.observe(t, 0.110)  # 110 ms: needs 3
    assert r.own == 3
    # 55 ms at divisor 3: at divisor 2 the load would be 1.5x, 82 ms > 80 ms: stays at 3
    for i in range(50):
        r.observe(1.0 + 0.1 * i, 0.055)
    assert r.own == 3
    # 45 ms: one step down predicts 67 ms, which fits 2 periods; the divisor falls 2 s after the
    # median first said so (the second 45 ms frame of a window of 3)
    times = [10.0 + 0.1 * i for i in range(40)]
    fell = None
    for t in times:
        r.observe(t, 0.045)
        if fell is None and r.own == 2:
            fell = t
    assert r.own == 2 and fell == pytest.approx(10.1 + 2.0)

def test_fixed_rate_never_changes_and_overload_steps_are_rate_limited():
    fixed = RateAgreement(PERIOD, adaptive=False)
    fixed.observe(0.0, 1.0)
    fixed.overloaded(0.0)
    assert fixed.own == 1
    r = RateAgreement(PERIOD, settle_s=2.0)
    for t in (0.0, 0.1, 0.2, 0.9, 1.0):  # a backlog: five skips in one second
        r.overloaded(t)
    assert r.own == 3  # at 0.0 and at 1.0 (one step per half settle time)


def test_swarm_takes_the_largest_divisor_of_living_drones():
    r = RateAgreement(PERIOD)
    r.heard(2, 4)
    r.heard(3, 2)
    assert r.divisor(alive={2, 3}) == 4
    assert r.divisor(alive={3}) == 2  # drone 2 is silent: its request no longer counts
    m = r.divisor(alive={2, 3})
    assert takes_slot(8, m) and not takes_slot(9, m)


def test_hello_carries_the_divisor_and_other_kinds_do_not():
    hello = decode_packet(encode_packet(HELLO, 3, rate_divisor=5))
    assert hello.rate_divisor == 5
    old = bytearray(encode_packet(HELLO, 3))  # a sender that leaves the byte 0: every slot
    assert old[9] == 1 and decode_packet(bytes(old)).rate_divisor == 1
    data = decode_packet(encode_packet(DATA, 3, stage=1, payload=[0.0] * 136, rate_divisor=5))
    assert data.rate_divisor == 1
    with pytest.raises(ValueError):
        encode_packet(HELLO, 3, rate_divisor=0)
