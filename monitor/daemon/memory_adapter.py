"""The daemon's adapter of vehicle memory (``monitor.memory``): one baseline per vehicle in the state dir, judged
from take-off, learnt on landing.

State dir layout: ``STATE_DIR/vehicles/<vehicle key>/baseline.json`` (``monitor.memory.baseline`` format; the key
is ``uid-<autopilot uid>`` where AUTOPILOT_VERSION gave one, else ``sysid-<n>``). ``propwatch baseline note`` on
that file records maintenance; the daemon re-reads it at each take-off and before each write, so a note made while
it runs is kept.

- With a ready baseline, each second airborne the flight so far is judged against it (``monitor.memory.judge``): a
  confident verdict naming one set is a FAULT; a fault-level one whose set is not yet one, a SUSPECT naming every
  set it keeps. Each is announced once per flight, from the first seconds after take-off, so
  damage present before take-off is heard in flight.
- A flight is learnt when it ended in landing and disarm, flew at least ``MIN_LEARN_S`` past take-off, raised no
  SUSPECT and no FAULT from any evidence, was judged healthy where a baseline exists, and, with signing on, every
  frame it used was verified. A flight whose stream merely stopped never disarms in our eyes and is never learnt.
- Writes are atomic (``write_atomic``). A state dir that cannot be written is said in STATUS; monitoring goes on.
"""

from __future__ import annotations

import datetime as _dt
import logging
import re
from pathlib import Path

import numpy as np

from monitor.decision.rule import Announcement
from monitor.errors import PropwatchError
from monitor.memory.baseline import BASELINE_FILE, MIN_FLIGHTS, VehicleBaseline
from monitor.memory.judge import judge, statistic_of
from monitor.memory.learn import set_aside_outliers
from monitor.memory.summary import ShareAccumulator

log = logging.getLogger("propwatch.monitor")

MIN_LEARN_S = 30.0  # accepted airborne seconds before a flight can become history ("too short to count")
JUDGE_PERIOD_S = 1.0
# Accepted seconds before the first judgement (two 2-s blocks of the flight's own wander): chosen, not measured,
# the fewest blocks that give a wander at all.
MIN_JUDGE_S = 4.0
SEVERITY = {"fault": 2, "suspect": 4}  # MAV_SEVERITY_CRITICAL / WARNING, as the decision's own alerts


def today_utc() -> str | None:
    """The companion's UTC date, None where its clock is plainly unset (before 2020: no real-time clock)."""
    now = _dt.datetime.now(_dt.timezone.utc)
    return now.date().isoformat() if now.year >= 2020 else None


def vehicle_key(uid: int | None, sysid: int | None) -> str | None:
    if uid:
        return f"uid-{uid:016x}"
    return None if sysid is None else f"sysid-{int(sysid)}"


class VehicleMemory:
    def __init__(self, state_dir: str | Path, rate_hz: float, motor_names=("1", "2", "3", "4")) -> None:
        self.state_dir = Path(state_dir)
        self.rate_hz = float(rate_hz)
        self.motor_names = tuple(motor_names)
        self.uid: int | None = None
        self.sysid: int | None = None
        self.baseline: VehicleBaseline | None = None
        self.normal = None
        self._problem = ""  # why the state dir cannot be used ('' = fine)
        self._status: str | None = None  # STATUS suffix, made again only when the baseline or the problem changes
        self.learnt = 0
        self._reset_flight()

    # -- identity and the file
    @property
    def key(self) -> str | None:
        return vehicle_key(self.uid, self.sysid)

    @property
    def path(self) -> Path | None:
        k = self.key
        return None if k is None else self.state_dir / "vehicles" / re.sub(r"[^A-Za-z0-9_.-]", "_", k) / BASELINE_FILE

    def identify(self, sysid: int | None = None, uid: int | None = None) -> None:
        changed = (uid and uid != self.uid) or (self.uid is None and sysid is not None and sysid != self.sysid)
        self.sysid = sysid if sysid is not None else self.sysid
        self.uid = uid or self.uid
        if changed and not self.in_flight:
            self.load()

    def load(self) -> None:
        """(Re-)read this vehicle's baseline; a missing file is an empty history, a bad one is said and not used."""
        p = self.path
        if p is None:
            return
        self.normal, self._status = None, None
        if not p.is_file():
            self.baseline = None
            return
        try:
            self.baseline = VehicleBaseline.load(p)
            self.problem = ""
        except PropwatchError as exc:
            self.baseline, self.problem = None, f"vehicle baseline unusable: {exc}"
            log.error("%s", self.problem)
            return
        if self.baseline.ready and tuple(self.baseline.motor_names) == self.motor_names:
            self.normal = self.baseline.normal()

    @property
    def problem(self) -> str:
        return self._problem

    @problem.setter
    def problem(self, text: str) -> None:
        self._problem, self._status = text, None

    def status(self) -> str:
        """The STATUS suffix: what the flight is compared with, or why with no history. Read at every grid step: made
        once per change of the baseline or the problem."""
        if self._status is None:
            if self.problem:
                self._status = f"; {self.problem}"
            elif self.normal is not None:
                self._status = f"; vehicle memory: {self.baseline.compared_with_text()}"
            else:
                k = 0 if self.baseline is None else len(self.baseline.active())
                self._status = f"; no vehicle baseline yet ({k} of {MIN_FLIGHTS} flights)"
        return self._status

    # -- the flight
    def _reset_flight(self) -> None:
        self.acc: ShareAccumulator | None = None
        self.in_flight = False
        self.landed = False
        self.alerted = False
        self._announced: set[str] = set()
        self._next_judge = 0
        self.last_verdict: dict | None = None

    def discard(self, why: str) -> None:
        """The flight so far is no evidence (reboot, clock step): never learnt."""
        if self.acc is not None:
            log.info("vehicle memory: flight discarded (%s)", why)
        self._reset_flight()

    def alert_raised(self) -> None:
        self.alerted = True

    def step(self, t_s: float, airborne: bool, motor_rpm, roll_rad: float, pitch_rad: float) -> Announcement | None:
        if airborne and not self.in_flight:
            if self.acc is None:  # take-off: a new flight (a touch-and-go keeps the one in progress)
                self.load()
                self.acc = ShareAccumulator("omega2", self.rate_hz)
            self.in_flight, self.landed = True, False
        elif not airborne and self.in_flight:
            self.in_flight, self.landed = False, True
        if self.acc is None:
            return None
        x = np.full(4, np.nan) if motor_rpm is None else (np.asarray(motor_rpm, dtype=np.float64) / 1000.0) ** 2
        self.acc.step(x, roll_rad, pitch_rad, airborne)
        s = self.acc.summary
        if self.normal is None or not airborne or s.n < self._next_judge or s.seconds < MIN_JUDGE_S:
            return None
        self._next_judge = s.n + int(round(JUDGE_PERIOD_S * self.rate_hz))
        v = self.last_verdict = judge(self.normal, s)
        # FAULT names one set; a fault-level statistic whose set is not yet one is a SUSPECT naming every set it keeps
        # (the flight's own wander shrinks as it goes on, and the set with it). Below the fault level nothing is said
        # in flight: judged every second, the suspect level alone spoke on 7 of 24 healthy later flights of our
        # simulator's fleet (python -m bench.bench_vehicle_memory, seed 0, 6 airframes), the fault level on none.
        faulty = bool(v["faulty_propellers"])
        level = ("fault" if v["confidence"] == "confident" else "suspect") if faulty else ""
        if not level or level in self._announced or (level == "suspect" and "fault" in self._announced):
            return None
        self._announced.add(level)
        self.alerted = True
        sets = tuple(tuple(h["faulty_propellers"]) for h in v["hypotheses"] if h["faulty_propellers"])
        named = " or ".join("+".join(map(str, h)) for h in sets[:3]) or "?"
        text = f"PROP {named} DAMAGED vs vehicle history" if level == "fault" else f"PROP {named}? vs vehicle history"
        stat = tuple(statistic_of(v, (k,)) for k in range(1, 5))
        return Announcement(
            t_s, level, tuple(v["faulty_propellers"]) or sets[0], text[:50], SEVERITY[level], stat, "vehicle memory", sets=sets
        )

    def disarmed(self, authenticated: bool | None) -> str:
        """Disarm: learn the flight where it qualifies. ``authenticated`` None: signing off. Returns what happened."""
        acc, landed, alerted, verdict = self.acc, self.landed, self.alerted, self.last_verdict
        self._reset_flight()
        if acc is None or not landed:
            return "no flight"
        s = acc.summary
        why = ""
        if s.seconds < MIN_LEARN_S:
            why = f"too short to count ({s.seconds:.0f} of {MIN_LEARN_S:.0f} s)"
        elif alerted:
            why = "it raised an alert"
        elif authenticated is False:
            why = "not every frame was signed and verified"
        elif self.path is None:
            why = "vehicle unknown"
        if why:
            log.info("vehicle memory: flight not learnt: %s", why)
            return f"not learnt: {why}"
        try:
            self.load()  # notes made while we flew
            if self.normal is not None:
                verdict = judge(self.normal, s)
                if verdict["label"] != 1 or verdict["confidence"] == "suspect":
                    return "not learnt: not healthy against the vehicle's history"
            b = self.baseline or VehicleBaseline(self.key, "daemon", self.motor_names, "omega2")
            b.add(f"flight {len(b.flights) + 1}", today_utc(), s, "no fault")
            for name in set_aside_outliers(b):
                log.warning("vehicle memory: %s set aside: unlike the vehicle's other flights", name)
            self.path.parent.mkdir(parents=True, exist_ok=True)
            b.save(self.path)
        except (OSError, PropwatchError) as exc:
            self.problem = f"state dir not writable ({self.state_dir}): {exc}"
            log.error("vehicle memory: %s; monitoring goes on", self.problem)
            return f"not learnt: {self.problem}"
        self.problem = ""
        self.learnt += 1
        self.load()
        log.info("vehicle memory: flight learnt (%.0f s); %s", s.seconds, self.status().lstrip("; "))
        return "learnt"
