"""Which autopilots the daemon listens to, decided once per boot from the pinned links alone.

The autopilot's system id is learnt only from autopilot HEARTBEATs (component
``autopilot_component_id``, a real autopilot type) that came over the pinned
link: on ``udpin`` the configured ``link.autopilot_address``, or else the one
loopback address whose heartbeats pinned it (an autopilot on another computer
is listened to only where ``link.autopilot_address`` names it; a router on
this computer forwards); a serial device or TCP peer is a link of its own. A
candidate is pinned once its heartbeats span ``wait_s`` of monotonic time
(``link.pin_wait_s``; at least two heartbeats: a sequence, not one frame). The
first candidate heard of a system id has the pin to itself while it keeps beating:
the same system id from another address is announced and ignored, never a
reason to stop listening; a candidate silent for ``CANDIDATE_SILENT_S`` is
forgotten, so one packet cannot hold the pin. Autopilots of other system ids
(two vehicles through one router, or each from its own port) are pinned each
to its own address, up to ``max_vehicles`` (``link.max_vehicles``; with
``link.system_id`` set, that one alone): each is monitored as its own
vehicle, and one past the bound is announced and ignored. ``system_id`` and
``address`` are the first pinned, ``vehicles`` every one. Once pinned, frames
from any other address are refused (but the HEARTBEATs of a new vehicle),
and so are the autopilot components of systems not pinned; a pin is never
moved to a newcomer.

Every refusal is counted by reason (``refused``); each (reason, source) is
written to the journal once (``announced`` bounds the set).
"""

from __future__ import annotations

import ipaddress
import logging
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from monitor.mavlink.decode import _NOT_AUTOPILOT_TYPES, MAV_AUTOPILOT_INVALID, MAV_TYPE_GCS  # the decoder's own test

log = logging.getLogger("propwatch.monitor.link")

PIN_WAIT_S = 2.0  # PX4 sends HEARTBEAT at 1 Hz: pinned at its third, about 2 s after it is first heard
MAX_CANDIDATES = 16
# A candidate silent this long (or the pin's wait, if longer) is forgotten: three of PX4's 1 Hz heartbeats missed.
CANDIDATE_SILENT_S = 3.0
MAX_ANNOUNCED = 64
MAX_VEHICLES = 4  # autopilots of distinct system ids monitored on one link (link.max_vehicles' default)
Origin = tuple[str, int] | None  # a udpin sender; None: the link has one peer (serial, TCP, udpout)


def is_autopilot_heartbeat(msg: Any, component_id: int) -> bool:
    return (
        msg.get_type() == "HEARTBEAT"
        and msg.get_srcComponent() == component_id
        and getattr(msg, "autopilot", MAV_AUTOPILOT_INVALID) != MAV_AUTOPILOT_INVALID
        and getattr(msg, "type", MAV_TYPE_GCS) not in _NOT_AUTOPILOT_TYPES
    )


def is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def describe(sys_id: int, origin: Origin) -> str:
    return f"system {sys_id}" + ("" if origin is None else f" at {origin[0]}:{origin[1]}")


class AutopilotPin:
    def __init__(
        self,
        system_id: int | None,
        component_id: int,
        address: Origin = None,
        wait_s: float = PIN_WAIT_S,
        clock: Callable[[], float] = time.monotonic,
        one_peer: bool = False,
        max_vehicles: int = MAX_VEHICLES,
    ):
        """``one_peer``: the link has a single peer (serial, TCP, udpout), so a configured system id pins at once,
        as does a configured system id with a configured address. ``max_vehicles``: autopilots of distinct system
        ids pinned at most (1 with a configured system id)."""
        self.configured_system_id = system_id
        self.component_id = component_id
        self.configured_address = address
        self.wait_s = wait_s
        self.clock = clock
        self.system_id: int | None = None  # pinned
        self.address: Origin = address  # pinned (configured, or learnt with the system id)
        self.max_vehicles = 1 if system_id is not None else max(1, int(max_vehicles))
        self.vehicles: dict[int, Origin] = {}  # every pinned system id -> its address (the first is system_id's)
        self.conflict = ""  # the last candidate ignored because another was heard first (for the report)
        self._candidates: dict[tuple[int, Origin], list[float]] = {}  # -> heartbeat times (monotonic)
        self.refused: Counter = Counter()
        self.announced: set[tuple[str, str]] = set()
        if system_id is not None and (one_peer or address is not None):
            self.system_id = system_id  # nothing left to learn
            self.vehicles[system_id] = address

    @property
    def pinned(self) -> bool:
        return self.system_id is not None

    def admit(self, msg: Any, origin: Origin) -> bool:
        reason, who = self._why(msg, origin)
        if not reason:
            return True
        self.refused[reason] += 1
        self.announce(reason, who, describe(msg.get_srcSystem(), origin))
        return False

    def announce(self, reason: str, who: str, first: str) -> None:
        """Once per (reason, who): ``who`` is the address for frames from elsewhere, else the system."""
        if (reason, who) in self.announced or len(self.announced) >= MAX_ANNOUNCED:
            return
        self.announced.add((reason, who))
        log.warning("refused: %s (%s, first from %s); counted from now on, not logged again", reason, who, first)

    def _why(self, msg: Any, origin: Origin) -> tuple[str, str]:
        sys_id, comp_id = msg.get_srcSystem(), msg.get_srcComponent()
        if self.configured_address is not None and origin is not None and origin != self.configured_address:
            return "not the pinned autopilot link", f"{origin[0]}:{origin[1]}"
        if self.pinned:
            if origin is not None and origin not in self.vehicles.values():
                if sys_id not in self.vehicles and is_autopilot_heartbeat(msg, self.component_id):
                    return self._another_vehicle(sys_id, origin)
                return "not the pinned autopilot link", f"{origin[0]}:{origin[1]}"
            if comp_id != self.component_id:
                return "", ""
            if sys_id in self.vehicles:
                home = self.vehicles[sys_id]
                return self._same_system(sys_id, home) if origin is not None and origin != home else ("", "")
            if is_autopilot_heartbeat(msg, self.component_id):
                return self._another_vehicle(sys_id, origin)
            return "another autopilot", describe(sys_id, origin)
        if not is_autopilot_heartbeat(msg, self.component_id):
            return "before the autopilot was pinned", "any"
        return self._another_vehicle(sys_id, origin)

    def _another_vehicle(self, sys_id: int, origin: Origin) -> tuple[str, str]:
        """An autopilot HEARTBEAT of a system id not pinned: a candidate, where it may be one."""
        if origin is not None and self.configured_address is None and not is_loopback(origin[0]):
            return "an autopilot on another computer (link.autopilot_address names one to listen to)", f"{origin[0]}:{origin[1]}"
        if self.configured_system_id is not None and sys_id != self.configured_system_id:
            return "another autopilot", describe(sys_id, origin)
        if self.pinned and len(self.vehicles) >= self.max_vehicles:
            return f"another autopilot past the {self.max_vehicles} monitored (link.max_vehicles)", describe(sys_id, origin)
        return self._candidate(sys_id, origin)

    @staticmethod
    def _same_system(sys_id: int, first: Origin) -> tuple[str, str]:
        why = f"the same system from another address, heard after {describe(sys_id, first)} (link.autopilot_address chooses)"
        return why, describe(sys_id, first)

    def _candidate(self, sys_id: int, origin: Origin) -> tuple[str, str]:
        now = self.clock()
        silent = max(self.wait_s, CANDIDATE_SILENT_S)
        for k in [k for k, beats in self._candidates.items() if now - beats[-1] > silent]:
            del self._candidates[k]
        key = (sys_id, origin)
        if key not in self._candidates:
            if len(self._candidates) >= MAX_CANDIDATES:
                return "before the autopilot was pinned", "any"
            self._candidates[key] = []
        self._candidates[key].append(now)
        # The earliest heard of those still beating: of this system id, or of any where one vehicle is monitored.
        first = next(k for k in self._candidates if k[0] == sys_id or self.max_vehicles == 1)
        if key != first:
            self.conflict = f"{describe(*key)} ignored: {describe(*first)} heard first"
            if sys_id == first[0]:
                return self._same_system(sys_id, first[1])[0], describe(*key)
            return f"another autopilot, heard after {describe(*first)} (link.system_id chooses)", describe(*key)
        beats = self._candidates[key]
        if len(beats) >= 2 and beats[-1] - beats[0] >= self.wait_s:
            address = origin if origin is not None else self.address
            if self.system_id is None:
                self.system_id, self.address = sys_id, address
            self.vehicles[sys_id] = address
            for k in [k for k in self._candidates if k[0] == sys_id or self.max_vehicles == 1]:
                del self._candidates[k]
            log.info(
                "autopilot pinned: %s (%d heartbeats over %.1f s)", describe(sys_id, origin), len(beats), beats[-1] - beats[0]
            )
            return "", ""
        return "before the autopilot was pinned", "any"

    def address_of(self, sys_id: int | None) -> Origin:
        """Where the autopilot of ``sys_id`` is answered (the first pinned's address for None or one not pinned)."""
        return self.vehicles.get(sys_id, self.address) if sys_id is not None else self.address
