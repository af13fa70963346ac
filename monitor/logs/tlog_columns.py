"""A clean tlog's 50 Hz streams decoded as whole columns, with the shared decoder's meaning.

``monitor.mavlink.decode.MavlinkDecoder`` takes one message at a time (the daemon's way): on a 30-minute tlog
that is ~280 000 Python calls, most of what ``propwatch diagnose`` spends. Here ATTITUDE, SERVO_OUTPUT_RAW,
LOCAL_POSITION_NED, HIGHRES_IMU and SCALED_IMU, nearly every message of such a log, are decoded column by column with that decoder's rules:
only the autopilot's messages (from the first HEARTBEAT ``MavlinkDecoder._is_autopilot`` takes), stamped on its
boot clock, PWM 0 and 65535 unknown; likewise the accelerometer (HIGHRES_IMU of the first IMU, SCALED_IMU in
milli-g). The few other messages (HEARTBEAT, SYS_STATUS, BATTERY_STATUS,
EXTENDED_SYS_STATE, VIBRATION) still go through the decoder itself, each with the boot clock it would have had.

Only what the columns reproduce exactly is done here. A reboot (a clock going back), a SERVO_OUTPUT_RAW clock
that wraps, a configured system id or any other message type from the autopilot returns None, and the reader
decodes the file message by message. tests/test_logs_tlog_columns.py checks that both give the same flight.
"""

from __future__ import annotations

import numpy as np

from monitor.logs.mavbulk import Group, messages
from monitor.mavlink import decode as md

# Messages decoded here as columns (their handler's arithmetic below), and the ones left to the decoder.
COLUMN_TYPES = ("ATTITUDE", "SERVO_OUTPUT_RAW", "LOCAL_POSITION_NED", "HIGHRES_IMU", "SCALED_IMU")
DECODER_TYPES = ("HEARTBEAT", "SYS_STATUS", "BATTERY_STATUS", "EXTENDED_SYS_STATE", "VIBRATION")


def _by_type(groups: list[Group]) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Message name -> (rows, values, sys ids, comp ids), the groups of one type joined in file order."""
    parts: dict[str, list[Group]] = {}
    for g in groups:
        parts.setdefault(g.cls.msgname, []).append(g)
    out = {}
    for name, gs in parts.items():
        if len(gs) == 1:  # one group's rows are in file order already
            g = gs[0]
            out[name] = (g.rows, g.values, g.sys_id, g.comp_id)
            continue
        rows = np.concatenate([g.rows for g in gs])
        order = np.argsort(rows, kind="stable")
        out[name] = (
            rows[order],
            np.concatenate([g.values for g in gs])[order],
            np.concatenate([g.sys_id for g in gs])[order],
            np.concatenate([g.comp_id for g in gs])[order],
        )
    return out


def _first_autopilot_heartbeat(hb, component_id: int) -> tuple[int, int] | None:
    """(row, system id) of the first HEARTBEAT ``MavlinkDecoder._is_autopilot`` takes as the autopilot's."""
    if hb is None:
        return None
    rows, v, sys_id, comp = hb
    ok = (comp == component_id) & (v["autopilot"] != md.MAV_AUTOPILOT_INVALID)
    ok &= ~np.isin(v["type"], list(md._NOT_AUTOPILOT_TYPES))
    hit = np.flatnonzero(ok)
    return None if len(hit) == 0 else (int(rows[hit[0]]), int(sys_id[hit[0]]))


def decode_columns(groups: list[Group], n_frames: int, dec: md.MavlinkDecoder, add) -> dict | None:
    """Samples of a clean file: the 50 Hz streams as columns, {"att", "rate", "cmd", "vel"} -> (t_us, values); the
    other messages' samples passed to ``add`` (in file order) as the decoder gives them. None: decode per message."""
    if dec.system_id is not None or dec.clock_us is not None:
        return None
    by = _by_type(groups)
    first = _first_autopilot_heartbeat(by.get("HEARTBEAT"), dec.component_id)
    if first is None:
        return None
    hb_row, sid = first

    def accepted(name):
        rows, v, s, c = by[name]
        keep = (rows >= hb_row) & (s == sid) & (c == dec.component_id)
        return rows[keep], v[keep]

    for name in by:
        if name not in COLUMN_TYPES + DECODER_TYPES and len(accepted(name)[0]):
            return None  # a message of the autopilot's that only the decoder reads
    cols = {name: accepted(name) if name in by else (np.zeros(0, np.int64), None) for name in COLUMN_TYPES}
    att_rows, att = cols["ATTITUDE"]
    servo_rows, servo = cols["SERVO_OUTPUT_RAW"]
    pos_rows, pos = cols["LOCAL_POSITION_NED"]
    hi_rows, hi = cols["HIGHRES_IMU"]
    if len(hi_rows):  # the decoder reads the first IMU only (id 0; absent in MAVLink 1, zero-filled here)
        first_imu = hi["id"] == 0
        hi_rows, hi = hi_rows[first_imu], hi[first_imu]
    sc_rows, sc = cols["SCALED_IMU"]

    # The boot clock: every timed message of the autopilot's in file order (VIBRATION with a time too).
    timed_rows = [att_rows, servo_rows, pos_rows, hi_rows, sc_rows]
    timed_t = [
        att["time_boot_ms"].astype(np.int64) * md.US_PER_MS if len(att_rows) else np.zeros(0, np.int64),
        servo["time_usec"].astype(np.int64) if len(servo_rows) else np.zeros(0, np.int64),
        pos["time_boot_ms"].astype(np.int64) * md.US_PER_MS if len(pos_rows) else np.zeros(0, np.int64),
        hi["time_usec"].astype(np.int64) if len(hi_rows) else np.zeros(0, np.int64),
        sc["time_boot_ms"].astype(np.int64) * md.US_PER_MS if len(sc_rows) else np.zeros(0, np.int64),
    ]
    if "VIBRATION" in by:
        vib_rows, vib = accepted("VIBRATION")
        stamped = vib["time_usec"] != 0
        timed_rows.append(vib_rows[stamped])
        timed_t.append(vib["time_usec"][stamped].astype(np.int64))
    rows = np.concatenate(timed_rows)
    order = np.argsort(rows, kind="stable")
    rows, t = rows[order], np.concatenate(timed_t)[order]
    if len(t) == 0:
        return None
    clock = np.maximum.accumulate(t)  # the clock after each timed message
    before = np.concatenate([[t[0]], clock[:-1]])  # before it (the first sets it)
    if np.any(t < before - dec.reboot_jump_us):
        return None  # a reboot: sessions are the decoder's business
    # SERVO_OUTPUT_RAW's 32-bit time is unwrapped to the candidate nearest the clock before it
    # (MavlinkDecoder.unwrap_u32_us): taken as is above, which holds while no candidate lies nearer.
    is_servo = np.isin(rows, servo_rows)
    if np.any(np.round((before[is_servo] - t[is_servo]) / float(1 << 32)) > 0):
        return None

    # The other messages through the decoder, each with the clock it would have found there.
    others = [g for g in groups if g.cls.msgname in DECODER_TYPES]
    if others:
        msgs = messages(others, n_frames)
        where = np.sort(np.concatenate([g.rows for g in others]))
        before_each = np.searchsorted(rows, where, side="left").tolist()  # timed messages before each
        for r, i in zip(where.tolist(), before_each):
            dec.clock_us = None if i == 0 else int(clock[i - 1])
            for sample in dec.decode(msgs[r]):
                add(sample)
    dec.clock_us = int(clock[-1])

    def f64(v, *names):
        return np.stack([v[k].astype(np.float64) for k in names], axis=1) if len(v) else np.zeros((0, len(names)))

    out = {"att": (), "rate": (), "cmd": (), "vel": ()}
    if len(att_rows):
        t_att = att["time_boot_ms"].astype(np.int64) * md.US_PER_MS
        out["att"] = (t_att, f64(att, "roll", "pitch", "yaw"))
        out["rate"] = (t_att, f64(att, "rollspeed", "pitchspeed", "yawspeed"))
    if len(servo_rows):
        port0 = servo["port"] == 0  # outputs 1..8: motors 1..4 are outputs 1..4
        pwm = f64(servo[port0], "servo1_raw", "servo2_raw", "servo3_raw", "servo4_raw")
        pwm[(pwm == 0.0) | (pwm == float(md.UINT16_UNKNOWN))] = np.nan
        out["cmd"] = (servo["time_usec"][port0].astype(np.int64), pwm)
    if len(pos_rows):
        out["vel"] = (pos["time_boot_ms"].astype(np.int64) * md.US_PER_MS, f64(pos, "vx", "vy", "vz"))
    if len(hi_rows):
        out["acc_HIGHRES_IMU"] = (hi["time_usec"].astype(np.int64), f64(hi, "xacc", "yacc", "zacc"))
    if len(sc_rows):
        out["acc_SCALED_IMU"] = (
            sc["time_boot_ms"].astype(np.int64) * md.US_PER_MS,
            f64(sc, "xacc", "yacc", "zacc") * md.M_S2_PER_MG,
        )
    return out
