"""Bounded work for every byte: forged boot times move neither the grid nor the reboot detection (docs/SECURITY.md).

The daemon with a recording link (``fuzz_helpers``) is fed a PX4-like flight of system 1 with propeller 3
faulty; the forger's messages carry the same ids, their CRCs are right, only their boot times lie.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
from fuzz_helpers import decoded, feed, make_daemon, px4_stream
from pymavlink.dialects.v20 import common as mavlink
from test_daemon_helpers import toy_model

from monitor.daemon.clockguard import CONFIRM_SAMPLES
from monitor.daemon.resampler import StreamingHold, StreamSpec
from monitor.model import Classifier

# The toy network raises FAULT (the default lets only the omega^2 shares): about 8 s of saturated windows after the
# first 5-s window and the first clock's confirmation, by ~116 s of boot time.
RULE = {"alerts": {"fault_evidence": "all"}}
FLIGHT = (100.0, 125.0)


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return Classifier(toy_model(tmp_path_factory.mktemp("model") / "toy.onnx"))


def interleave(genuine: list, forged: list) -> list:
    """Every forged message, spread evenly over the genuine ones (the k-th after genuine k * G / F)."""
    at: dict[int, list] = {}
    for k, m in enumerate(forged):
        at.setdefault(k * len(genuine) // len(forged), []).append(m)
    return [x for i, m in enumerate(genuine) for x in (m, *at.get(i, []))]


def far_future_attitudes(n: int, seed: int = 0) -> list:
    """ATTITUDE of system 1 with boot times hours to weeks ahead (plausible angles: only the time lies)."""
    rng = np.random.default_rng(seed)
    return [
        decoded(mavlink.MAVLink_attitude_message(int(rng.integers(3_600_000, 2**32 - 1)), 0.01, 0.01, 0.3, 0.0, 0.0, 0.0))
        for _ in range(n)
    ]


def test_far_future_attitudes_at_100_per_second_add_no_grid_steps_and_the_fault_is_still_raised(toy, caplog):
    caplog.set_level(logging.INFO)
    genuine = px4_stream(*FLIGHT, faulty=(3,))
    forged = far_future_attitudes(int(100 * (FLIGHT[1] - FLIGHT[0])))
    clean, _ = make_daemon(toy, None, RULE)
    feed(clean, genuine)
    daemon, link = make_daemon(toy, None, RULE)
    feed(daemon, interleave(genuine, forged))
    stats = daemon.pipeline.stats
    assert stats["steps"] <= clean.pipeline.stats["steps"] + 2  # not thousands of empty steps per message
    assert stats["clock_resets"] == stats["clock_steps_back"] == stats["clock_jumps"] == 0
    refused = daemon.pipeline.decoder.clock_guard.refused
    assert len(forged) <= refused <= len(forged) + CONFIRM_SAMPLES  # the forged ones, and the first clock's wait
    assert daemon.counters.alerts >= 1 and any("PROP 3" in t for t, _ in link.statustexts())
    told = [r for r in caplog.records if "clock jumped" in r.getMessage()]
    assert len(told) == 1  # told once, then counted


def test_random_valid_crc_payloads_fake_no_reboot(toy):
    rng = np.random.default_rng(7)
    kinds = [mavlink.MAVLink_attitude_message, mavlink.MAVLink_servo_output_raw_message]
    junk = []
    for _ in range(600):  # random bytes of each message's payload length, framed with a correct CRC
        kind = kinds[int(rng.integers(len(kinds)))]
        msg = mavlink.MAVLink(None).decode(
            bytearray(_frame_with_payload(kind, rng.integers(0, 256, kind.unpacker.size, dtype=np.uint8).tobytes()))
        )
        junk.append(msg)
    daemon, link = make_daemon(toy, None, RULE)
    feed(daemon, interleave(px4_stream(*FLIGHT, faulty=(3,)), junk))
    stats = daemon.pipeline.stats
    assert stats["clock_resets"] == 0 and stats["clock_jumps"] == 0, stats
    assert daemon.counters.alerts >= 1


def _frame_with_payload(kind, payload: bytes) -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    msg = kind.__new__(kind)
    mavlink.MAVLink_message.__init__(msg, kind.id, kind.msgname)
    return bytes(msg._pack(mav, kind.crc_extra, payload))


def test_a_real_reboot_is_still_seen_and_a_real_forward_jump_is_one_clock_event(toy):
    daemon, _ = make_daemon(toy, None, RULE)
    feed(daemon, px4_stream(100.0, 108.0))
    feed(daemon, px4_stream(2.0, 9.0, seed=2))  # the autopilot rebooted: its clock starts again
    stats = daemon.pipeline.stats
    assert stats["clock_resets"] == 1
    steps = stats["steps"]
    entered, enter = [], daemon.blind.enter
    daemon.blind.enter = lambda reason, detail: (entered.append(reason), enter(reason, detail))[1]
    feed(daemon, px4_stream(3609.0, 3616.0, seed=3))  # its boot clock jumps an hour forward and runs on
    assert stats["clock_jumps"] == 1 and stats["clock_resets"] == 1
    assert entered == ["clock jumped"]  # a jump forward is told as one, not as a step back
    assert stats["steps"] - steps <= 7.0 * 20 + 2  # the new clock's steps only, no hour of empty ones
    # Each of the three clocks (the first, after the reboot, after the jump) waited for CONFIRM_SAMPLES agreeing.
    assert daemon.pipeline.decoder.clock_guard.refused == 3 * (CONFIRM_SAMPLES - 1)
    assert stats["classified"] > 0


def test_the_hold_emits_a_bounded_number_of_steps_per_sample():
    spec = StreamSpec(1, 250_000, True)
    hold = StreamingHold(50_000, {"a": spec, "b": StreamSpec(1, 3_000_000, False)})
    hold.push("a", 1_000_000, [0.0])
    steps = hold.push("a", 1_000_000 + 3_600 * 1_000_000, [0.0])  # an hour ahead
    assert 1 <= len(steps) <= 3_000_000 // 50_000 + 2  # past the oldest max_age every instant is empty
    assert steps[0].skipped_before > 70_000
