"""The daemon's adapter of vehicle memory (``monitor.memory``): one baseline per vehicle in the state dir, judged
from take-off, learnt on landing.

State dir (``monitor.memory.store``): ``STATE_DIR/vehicles/<vehicle key>/baseline.json`` (``monitor.memory.baseline``
format; the key is ``uid-<autopilot uid>`` where AUTOPILOT_VERSION gave one, else ``sysid-<n>``). The daemon holds the
state dir's lock for its run: a second daemon on it refuses to start (``StateDirBusy``, naming the holder's pid). A
state dir that is not safely ours (another user's, writable by others, a link below it) turns the memory off for the
run, said in STATUS and the log; monitoring goes on. ``propwatch baseline note`` on a baseline records maintenance
under the same write lock; the daemon re-reads the file at each take-off and inside its own write.

- With a ready baseline, each second airborne the flight so far is judged against it (``monitor.memory.judge``): a
  confident verdict naming one set is a FAULT; a fault-level one whose set is not yet one, a SUSPECT naming every
  set it keeps. Each is announced once per flight, from the first seconds after take-off, so
  damage present before take-off is heard in flight.
- A flight ends at disarm after a landing (the autopilot's landed state), or, where the autopilot sends none, after
  ``IDLE_LANDED_S`` of outputs at idle. It is learnt when it flew at least ``MIN_LEARN_S`` past take-off, raised no
  SUSPECT and no FAULT from any evidence, was judged healthy where a baseline exists, and, with signing on, every
  frame it used was verified. Every flight's outcome (learnt, or not learnt and why) is logged and returned for the
  events file. A flight whose stream merely stopped never disarms in our eyes and is never learnt.
- A baseline that cannot be read, is of a newer propwatch or of another airframe is never replaced: learning for
  that vehicle pauses, STATUS says why and names ``propwatch baseline reset``.
- Identity: the autopilot's uid is taken once per autopilot boot (``new_boot``); a different uid while armed, or a
  second one in the same boot, is ignored and announced; a new vehicle after a reboot is announced. STATUS names the
  vehicle whose history is used.
"""

from __future__ import annotations

import ctypes
import datetime as _dt
import errno
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.decision.rule import Announcement
from monitor.memory.baseline import MIN_FLIGHTS, BaselineError, VehicleBaseline
from monitor.memory.judge import judge, statistic_of
from monitor.memory.learn import set_aside_outliers
from monitor.memory.store import StateDir, StateDirBusy, StateDirError, baseline_path
from monitor.memory.summary import ShareAccumulator
from monitor.memory.through_time import judge_through_time

log = logging.getLogger("propwatch.monitor")

MIN_LEARN_S = 30.0  # accepted airborne seconds before a flight can become history ("too short to count")
JUDGE_PERIOD_S = 1.0
# Accepted seconds before the first judgement (two 2-s blocks of the flight's own wander): chosen, not measured,
# the fewest blocks that give a wander at all.
MIN_JUDGE_S = 4.0
# Outputs at idle this long before a disarm end a flight where the autopilot sends no landed state. Chosen, not
# measured: twice PX4's land detector trigger time (LNDMC_TRIG_TIME, 1 s).
IDLE_LANDED_S = 2.0
# Longest wait at a landing for another writer of the state dir (`propwatch baseline note`: milliseconds): the loop
# waits in it, and the unit's watchdog (WatchdogSec=10, pinged every 5 s) must still be pinged in time. Chosen.
WRITE_WAIT_S = 3.0
SEVERITY = {"fault": 2, "suspect": 4}  # MAV_SEVERITY_CRITICAL / WARNING, as the decision's own alerts
try:  # glibc's: hands back the heap that freed objects left (None elsewhere: nothing is handed back)
    _malloc_trim = ctypes.CDLL(None).malloc_trim
except (OSError, AttributeError):
    _malloc_trim = None


def today_utc() -> str | None:
    """The companion's UTC date, None where its clock is plainly unset (before 2020: no real-time clock)."""
    now = _dt.datetime.now(_dt.timezone.utc)
    return now.date().isoformat() if now.year >= 2020 else None


def _return_heap() -> None:
    """After a landing's read-modify-write: the whole history was read, judged and written, and the heap it needed
    grows with the history; glibc keeps it after the objects are gone. Handed back, the daemon's RSS grows ~4 kB
    per learnt flight, else ~10 kB (``python -m bench.bench_memory_faults --only rss --landings 150``)."""
    if _malloc_trim is not None:
        _malloc_trim(0)


def vehicle_key(uid: int | None, sysid: int | None) -> str | None:
    if uid:
        return f"uid-{uid:016x}"
    return None if sysid is None else f"sysid-{int(sysid)}"


@dataclass(frozen=True)
class History:
    """What the daemon keeps of a vehicle's baseline between reads: its counts for STATUS."""

    flights: int  # in the file, set aside ones included
    active: int  # the normal rests on these
    compared_with: str  # ``VehicleBaseline.compared_with_text``


class _NotHealthy(Exception):
    """The flight is unlike the vehicle's history as read inside the write: not learnt, nothing written."""


class VehicleMemory:
    def __init__(
        self,
        state_dir: str | Path,
        rate_hz: float,
        motor_names=("1", "2", "3", "4"),
        idle_rpm: float | None = None,
        shared: VehicleMemory | None = None,
    ) -> None:
        """Open and hold the state dir. Raises ``StateDirBusy`` where another daemon holds it; any other reason it
        cannot be used turns the memory off for the run (``status`` says why). ``idle_rpm``: the mean rotor speed
        at or below which the outputs are at idle (None: a flight ends only by a landed state). ``shared``: the
        memory of another vehicle on the same link, whose hold of the state dir this one uses."""
        self.state_dir = Path(state_dir)
        self.rate_hz = float(rate_hz)
        self.motor_names = tuple(motor_names)
        self.idle_rpm = idle_rpm
        self.uid: int | None = None
        self.sysid: int | None = None
        self._uid_this_boot = False  # a uid was taken since the autopilot's last boot: no other until the next one
        self.history: History | None = None  # the baseline's counts (None: no usable baseline)
        self.normal = None
        self.off = ""  # the state dir cannot be used this run ('' = it can)
        self.paused = ""  # learning paused for this vehicle: its baseline cannot be used
        self.problem = ""  # the last write failed ('' once one succeeds)
        self._status: str | None = None  # STATUS suffix, made again only when something it shows changes
        self.learnt = 0
        self.store: StateDir | None = None
        self.owner = shared is None  # holds the state dir (another vehicle's memory in it shares this one's hold)
        if shared is not None:
            self.store, self.off = shared.store, shared.off
            self._reset_flight()
            return
        try:
            self.store = StateDir.open(self.state_dir)
            removed = self.store.hold()
        except StateDirBusy:
            if self.store is not None:
                self.store.close()
            raise
        except (StateDirError, OSError) as exc:
            if self.store is not None:
                self.store.close()
            self.store = None
            self.off = f"vehicle memory off for this run: {exc}"
            log.error("%s; monitoring goes on", self.off)
        else:
            if removed:
                log.warning("vehicle memory: removed %d temporary files a crash left: %s", len(removed), ", ".join(removed))
        self._reset_flight()

    def sharing(self) -> VehicleMemory:
        """Another vehicle's memory in the same state dir, under this one's hold (another vehicle on the link)."""
        return VehicleMemory(self.state_dir, self.rate_hz, self.motor_names, self.idle_rpm, shared=self)

    def close(self) -> None:
        if self.store is not None and self.owner:
            self.store.close()
        self.store = None

    # -- identity and the file
    @property
    def key(self) -> str | None:
        return vehicle_key(self.uid, self.sysid)

    @property
    def path(self) -> Path | None:
        k = self.key
        return None if k is None else baseline_path(self.state_dir, k)

    @property
    def needs_uid(self) -> bool:
        """Whether an AUTOPILOT_VERSION uid is still to be taken in this autopilot boot."""
        return not self._uid_this_boot

    def new_boot(self) -> None:
        """The autopilot rebooted (its boot time went back): the next uid it gives is taken, and announced if new."""
        self._uid_this_boot = False

    def identify(self, sysid: int | None = None, uid: int | None = None, armed: bool = False) -> str | None:
        """The autopilot's system id (the first one stays) or uid (once per boot, never while armed or in flight).
        Returns a notice to announce (log and events) where a uid was ignored or the vehicle changed, else None."""
        before = self.key
        notice = None
        if sysid is not None and self.sysid is None:
            self.sysid = sysid
        if uid and uid == self.uid:
            self._uid_this_boot = True
        elif uid:
            if armed or self.acc is not None:  # asked again after the disarm (needs_uid)
                notice = f"vehicle uid {uid:016x} while armed ignored: this flight stays {before}'s"
            elif self._uid_this_boot:
                notice = f"a second vehicle uid {uid:016x} in one autopilot boot ignored: still {before}"
            else:
                if self.uid is not None:
                    notice = f"vehicle changed: uid {self.uid:016x} -> {uid:016x}; the history of uid-{uid:016x} is used"
                self.uid, self._uid_this_boot = uid, True
        if notice:
            log.warning("vehicle memory: %s", notice)
        if self.key != before and self.acc is None:
            self.load()
        return notice

    def load(self) -> None:
        """(Re-)read this vehicle's baseline: a missing file is an empty history; one that cannot be used pauses
        learning for the vehicle (never replaced)."""
        k = self.key
        if k is None or self.store is None:
            return
        try:
            b = self.store.load(k)
        except (BaselineError, StateDirError, OSError) as exc:
            self._adopt(None, f"{exc}")
        else:
            self._adopt(b)

    def _adopt(self, b: VehicleBaseline | None, unusable: str = "") -> None:
        """Keep what the flights need of baseline ``b`` (its normal, its counts for STATUS), not ``b``: the history
        stays on disk between landings. ``unusable``: why the file could not be read (learning pauses)."""
        k = self.key
        self.normal, self.history, self._status = None, None, None
        paused = unusable
        try:
            self.normal = self._normal_of(b)
        except BaselineError as exc:
            paused, b = str(exc), None
        if b is not None:
            self.history = History(len(b.flights), len(b.active()), b.compared_with_text())
        if paused:
            why = (
                f"learning paused for {k}: {paused}; "
                f"`propwatch baseline reset --state-dir {self.state_dir} --vehicle {k}` moves it aside"
            )
            if why != self.paused:
                log.error("vehicle memory: %s", why)
            self.paused = why
            return
        self.paused = ""

    def status(self) -> str:
        """The STATUS suffix: the vehicle and what the flight is compared with, or why with no history. Read at
        every grid step: made once per change."""
        if self._status is None:
            k = self.key or "an unknown vehicle"
            if self.off or self.paused:
                self._status = f"; {self.off or self.paused}"
            elif self.problem:
                self._status = f"; vehicle {k}: {self.problem}"
            elif self.normal is not None:
                self._status = f"; vehicle {k}: {self.history.compared_with}"
            else:
                n = 0 if self.history is None else self.history.active
                self._status = f"; no vehicle baseline yet for {k} ({n} of {MIN_FLIGHTS} flights)"
        return self._status

    def brief(self) -> str:
        """The memory in a few words, for a STATUS that names several vehicles: the vehicle and its flights."""
        k = self.key or "vehicle unknown"
        if self.off:
            return "memory off"
        if self.paused:
            return f"{k}: learning paused"
        if self.problem:
            return f"{k}: {'disk full' if self.problem == 'disk full' else 'state dir not writable'}"
        if self.normal is not None:
            return f"{k}: {self.history.active} flights"
        return f"{k}: {0 if self.history is None else self.history.active} of {MIN_FLIGHTS} flights"

    # -- the flight
    def _reset_flight(self) -> None:
        self.acc: ShareAccumulator | None = None
        self.in_flight = False
        self.landed = False
        self.alerted = False
        self._announced: set[str] = set()
        self._next_judge = 0
        self.last_verdict: dict | None = None
        self._idle_since: float | None = None  # boot time (s) the outputs went to idle while airborne
        self._last_t = 0.0

    def discard(self, why: str) -> None:
        """The flight so far is no evidence (reboot, clock step): never learnt."""
        if self.acc is not None:
            log.info("vehicle memory: flight discarded (%s)", why)
        self._reset_flight()

    def alert_raised(self) -> None:
        self.alerted = True

    def _track_idle(self, t_s: float, airborne: bool, motor_rpm) -> None:
        self._last_t = t_s
        idle = (
            airborne
            and self.idle_rpm is not None
            and motor_rpm is not None
            and float(np.sum(motor_rpm)) / len(motor_rpm) <= self.idle_rpm  # the mean (NaN compares False: not idle)
        )
        if not idle:
            self._idle_since = None
        elif self._idle_since is None:
            self._idle_since = t_s

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
        self._track_idle(t_s, airborne, motor_rpm)
        x = np.full(4, np.nan) if motor_rpm is None else (np.asarray(motor_rpm, dtype=np.float64) / 1000.0) ** 2
        # Outputs at idle (below the log readers' lift throttle) lift nothing: not flight evidence. Skipped, not a
        # landing: a dip to idle in flight does not restart the take-off settle time.
        if self._idle_since is None or not airborne:
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
        faulty = bool(v["faulty_propellers"] or v.get("imbalance_rotors"))  # an imbalance: load off centre or damage
        level = ("fault" if v["confidence"] == "confident" and v["faulty_propellers"] else "suspect") if faulty else ""
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
        """Disarm: learn the flight where it qualifies. ``authenticated`` None: signing off. Returns what happened
        ("no flight" where nothing flew since the last disarm; else "learnt" or "not learnt: why"), logged."""
        acc, landed, alerted = self.acc, self.landed, self.alerted
        idle_s = (self._last_t - self._idle_since + 1.0 / self.rate_hz) if self._idle_since is not None else 0.0
        self._reset_flight()
        if acc is None:
            return "no flight"
        s = acc.summary
        why = ""
        if not landed and idle_s < IDLE_LANDED_S:
            why = f"disarmed in the air (no landed state, outputs at idle {idle_s:.1f} of {IDLE_LANDED_S:g} s before disarm)"
        elif s.seconds < MIN_LEARN_S:
            why = f"too short to count ({s.seconds:.0f} of {MIN_LEARN_S:.0f} s)"
        elif alerted:
            why = "it raised an alert"
        elif authenticated is False:
            why = "not every frame was signed and verified"
        elif self.off:
            why = self.off
        elif self.key is None:
            why = "vehicle unknown"
        if not why and self.paused:
            self.load()  # paused at take-off: the file may have been reset or repaired since
            why = self.paused and f"learning paused for {self.key} (its baseline cannot be used)"
        if why:
            return self._said(f"not learnt: {why}")
        try:
            b = self.store.update(self.key, lambda b: self._learn(b, s, acc.marks), WRITE_WAIT_S)
        except _NotHealthy:
            _return_heap()
            return self._said("not learnt: not healthy against the vehicle's history")
        except StateDirBusy as exc:
            return self._said(f"not learnt: {exc}")
        except (BaselineError, StateDirError) as exc:  # the file as read inside the write cannot be used
            self.load()
            if self.paused:
                return self._said(f"not learnt: learning paused for {self.key} (its baseline cannot be used)")
            return self._said(f"not learnt: learning paused for {self.key}: {exc}")
        except OSError as exc:
            full = exc.errno in (errno.ENOSPC, errno.EDQUOT)
            self.problem = "disk full" if full else f"state dir not writable ({self.state_dir}): {exc}"
            self._status = None
            log.error("vehicle memory: %s; monitoring goes on", self.problem)
            return self._said(f"not learnt: {self.problem}")
        self.problem = ""
        self.learnt += 1
        self._adopt(b)  # the baseline just written: its normal for the next flight, without reading it again
        del b
        _return_heap()
        log.info("vehicle memory: flight learnt (%.0f s); %s", s.seconds, self.status().lstrip("; "))
        return "learnt"

    def _normal_of(self, b: VehicleBaseline | None):
        """Baseline ``b``'s normal (None where there is no baseline or it is not ready). Raises ``BaselineError``
        where ``b`` cannot be this vehicle's: another airframe's rotors or basis, or checked values that still give
        no normal."""
        if b is None:
            return None
        if tuple(b.motor_names) != self.motor_names or b.basis != "omega2":
            raise BaselineError(
                f"{self.path}: rotors {list(b.motor_names)} on {b.basis} shares, this monitor's "
                f"{list(self.motor_names)} on omega2 (another airframe)"
            )
        if not b.ready:
            return None
        try:
            return b.normal()
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise BaselineError(f"{self.path}: its flights give no normal ({exc})") from exc

    def _learn(self, b: VehicleBaseline | None, s, marks) -> VehicleBaseline:
        """Inside the state dir's write lock: the flight judged against the baseline as it is on disk (notes made
        while it flew included), through time (``monitor.memory.through_time``: a change its mean dilutes is not
        learnt), then added. Raises ``BaselineError`` where that baseline cannot be used."""
        normal = self._normal_of(b)
        if normal is not None:
            v = judge_through_time(normal, s, marks)
            if v["label"] != 1 or v["confidence"] == "suspect" or v.get("imbalance_rotors"):
                raise _NotHealthy
        b = b or VehicleBaseline(self.key, "daemon", self.motor_names, "omega2")
        b.add(f"flight {len(b.flights) + 1}", today_utc(), s, "no fault")
        for name in set_aside_outliers(b):
            log.warning("vehicle memory: %s set aside: unlike the vehicle's other flights", name)
        return b

    @staticmethod
    def _said(what: str) -> str:
        log.info("vehicle memory: flight %s", what)
        return what
