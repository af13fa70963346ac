"""More than one vehicle on one link: each autopilot system id its own monitor, the first one's daemon routing.

Two autopilots through one router (or each from its own port) are two vehicles: the daemon that runs the loop
monitors the first system id it identifies, and ``Vehicles`` gives every other autopilot system id its own monitor
(a ``Daemon`` of the same kind whose loop never runs: its own pipeline and resampler, decision, blind spells,
alerts and vehicle memory, keyed by that system id or its uid, in the same state dir). Each message goes to the
monitor of its source system; what belongs to no other vehicle (the first vehicle's, a ground station's) stays with
the first. Such a monitor speaks as a component of its vehicle, to its autopilot's pinned address
(``VehicleLink``), and every alert of it names its system id. systemd's STATUS (sent by the first's daemon) names
each vehicle by system id with its memory in a few words: the first's whole text, then each other's first clause
(``status``).

On a live link the pin (``monitor.daemon.pin``) already decided which autopilots are vehicles; on a recorded log
the first autopilot HEARTBEAT of a system id makes it one. Either way there are at most ``link.max_vehicles``, a
configured ``link.system_id`` allows that one alone, and a system id past the bound is announced once (a flood of
forged system ids cannot grow the daemon's memory: each vehicle holds one model window and one flight).
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Any

from monitor.daemon.pin import MAX_ANNOUNCED, is_autopilot_heartbeat
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.sdnotify import Notifier

log = logging.getLogger("propwatch.monitor")


class VehicleLink:
    """The link as one vehicle's monitor uses it: what it sends goes as that system, to its autopilot's address;
    everything else is the shared link's."""

    def __init__(self, link: Any, system_id: int):
        self._link = link
        self.system_id = system_id

    def __getattr__(self, name: str) -> Any:
        return getattr(self._link, name)

    def set_system_id(self, system_id: int) -> None:
        """Fixed for this vehicle (the shared link keeps the first vehicle's)."""

    def send_heartbeat(self) -> None:
        self._link.send_heartbeat(as_system=self.system_id)

    def send_statustext(self, text: str, severity: int) -> None:
        self._link.send_statustext(text, severity, as_system=self.system_id)

    def send_named_value_float(self, time_boot_ms: int, name: str, value: float) -> None:
        self._link.send_named_value_float(time_boot_ms, name, value, as_system=self.system_id)


class Vehicles:
    def __init__(self, first: Any, limit: int):
        """``first``: the daemon that runs the loop (its configuration, link, model, events and memory are shared);
        ``limit``: vehicles at most, the first included."""
        self.first = first
        self.limit = limit
        self.others: dict[int, Any] = {}  # system id -> its monitor
        self.refused: set[int] = set()  # system ids past the bound, announced once each (bounded)

    def route(self, msg: Any) -> Any | None:
        """The monitor of another vehicle that ``msg`` belongs to, None for the first's (or nobody's)."""
        sys_id = msg.get_srcSystem()
        other = self.others.get(sys_id)
        if other is not None:
            return other
        first = self.first.autopilot.system_id
        if first is None or sys_id == first or not is_autopilot_heartbeat(msg, self.first.cfg.link.autopilot_component_id):
            return None
        if 1 + len(self.others) >= self.limit:
            if sys_id not in self.refused and len(self.refused) < MAX_ANNOUNCED:
                self.refused.add(sys_id)
                log.warning(
                    "another autopilot, system %d, not monitored: %d vehicles already (link.max_vehicles)", sys_id, self.limit
                )
            return None
        other = self.others[sys_id] = self._monitor(sys_id)
        other.announce.status_changed = self.first.announce.publish_status
        self.first.announce.compose = self.status
        log.warning(
            "another autopilot: system %d monitored as its own vehicle (%d of at most %d)",
            sys_id,
            1 + len(self.others),
            self.limit,
        )
        return other

    def _monitor(self, sys_id: int) -> Any:
        d = self.first
        cfg = dataclasses.replace(d.cfg, link=dataclasses.replace(d.cfg.link, system_id=sys_id))
        memory = d.memory.sharing() if d.memory is not None else None
        pipeline = Pipeline(d.pipeline.classifier, cfg, d.pipeline.esc)
        return type(d)(cfg, VehicleLink(d.link, sys_id), pipeline, d.events, Notifier({}), d.geometry, memory, one=True)

    def status(self, first_text: str) -> str:
        """systemd's STATUS with several vehicles: ``system N (its memory): ...`` for each, the first's text
        (``first_text``) whole, each other's first clause ("airborne: deciding", "last alert: ...", "BLIND: ...")."""
        parts = [f"{_named(self.first.autopilot.system_id, self.first.memory)}: {first_text}"]
        for sys_id, o in self.others.items():
            parts.append(f"{_named(sys_id, o.memory)}: {o.announce.status_text.split('; ', 1)[0] or 'starting'}")
        return " | ".join(parts)

    def wake_at(self, now: float, first: float | None) -> float | None:
        """When the earliest next grid step of any vehicle can complete (the loop sleeps until then)."""
        wakes = [w for w in (first, *(o.pipeline.wake_at(now) for o in self.others.values())) if w is not None]
        return min(wakes, default=None)

    def report(self) -> dict:
        return {str(k): o.report() for k, o in self.others.items()}


def _named(sys_id: int | None, memory: Any) -> str:
    return f"system {sys_id}" + (f" ({memory.brief()})" if memory is not None else "")
