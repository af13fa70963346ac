"""``propwatch monitor`` (and ``python -m monitor``): the onboard monitor daemon.

    propwatch monitor --connect udpin:127.0.0.1:14540 [--config /etc/propwatch/monitor.yaml]
                      [--events PATH] [--model PATH] [--vehicle PATH] [--report PATH]

Exits 0 on SIGTERM/SIGINT or at the end of a .tlog; 2 with one clear line on
a bad config, model or connection (via ``monitor.cli``).
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import logging
import signal
import sys
import time
from pathlib import Path

from monitor.daemon.config import MonitorConfig, load_monitor_config, parse_address, parse_endpoint, parse_source
from monitor.daemon.events import EventWriter
from monitor.daemon.link import Link, LinkGuard, read_signing_key
from monitor.daemon.memory_adapter import VehicleMemory
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.sdnotify import Notifier
from monitor.daemon.service import Daemon
from monitor.logs.raw import LIFT_CMD
from monitor.model import Classifier, choose_esc
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

log = logging.getLogger("propwatch.monitor")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="propwatch monitor", description="Onboard propeller-fault monitor (MAVLink).")
    p.add_argument(
        "--connect",
        required=True,
        help="pymavlink URL: udpin:127.0.0.1:14540, udpout:H:P, tcp:H:P, /dev/ttyAMA0,921600, or a .tlog",
    )
    p.add_argument("--config", help="monitor YAML (see deploy/monitor.yaml); defaults for every key")
    p.add_argument(
        "--events",
        help="append one JSON line per alert, decision pause/resume and blind/recovered spell here (overrides events_path)",
    )
    p.add_argument("--model", help="classifier ONNX (overrides model_path)")
    p.add_argument(
        "--vehicle",
        help="vehicle YAML whose ESC curve overrides the model's, or a folder written by propwatch adapt (its model too)",
    )
    p.add_argument("--report", help="write counters and latency percentiles as JSON at exit")
    p.add_argument(
        "--state-dir",
        default=None,
        help="vehicle memory: one healthy baseline per vehicle here (overrides state_dir; default /var/lib/propwatch); "
        "'' turns it off",
    )
    p.add_argument("--tlog-speed", type=float, help="for a .tlog: 1 = recorded pace, 0 = as fast as possible")
    p.add_argument(
        "--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"], help="logging threshold (default INFO)"
    )
    return p.parse_args(argv)


def guard(cfg: MonitorConfig) -> LinkGuard:
    c = cfg.link
    return LinkGuard(
        signing_key=read_signing_key(c.signing_key_path) if c.signing_key_path else None,
        signing_link_id=c.signing_link_id,
        allow_addresses=tuple(parse_address(a) for a in c.allow_addresses),
        allow_sources=tuple(parse_source(s) for s in c.allow_sources),
        max_peers=c.max_peers,
        autopilot_address=parse_endpoint(c.autopilot_address, "link.autopilot_address") if c.autopilot_address else None,
        ground_stations=tuple(parse_endpoint(g, "link.ground_stations") for g in c.ground_stations),
        autopilot_component_id=c.autopilot_component_id,
        pin_wait_s=c.pin_wait_s,
        max_vehicles=c.max_vehicles,
    )


def main(argv: list[str] | None = None) -> int:
    started = time.monotonic()
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level, stream=sys.stderr, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    cfg = load_monitor_config(args.config)
    if args.model or args.vehicle:
        cfg = dataclasses.replace(cfg, airframe_declared=True)
    if not cfg.airframe_declared:
        log.info(
            "physics only: nothing declares this vehicle to be the classifier's airframe (airframe_declared, "
            "model_path or vehicle_path in the configuration, or --model/--vehicle); the network is silent"
        )
    model_path = args.model or cfg.model_path
    vehicle = args.vehicle or cfg.vehicle_path
    if vehicle and Path(vehicle).is_dir():  # a `propwatch adapt` folder: its model and calibrated vehicle
        model_path = args.model or str(Path(vehicle) / "classifier.onnx")
        vehicle = str(Path(vehicle) / "vehicle.yaml")
    classifier = Classifier(model_path, threads=cfg.inference.threads)
    esc = choose_esc(classifier, vehicle)
    pipeline = Pipeline(classifier, cfg, esc)
    tlog_speed = cfg.link.tlog_speed if args.tlog_speed is None else args.tlog_speed
    link = Link(args.connect, cfg.link.component_id, tlog_speed, cfg.link.system_id or None, guard(cfg))
    events = EventWriter(args.events or cfg.events_path or None, cfg.blind.events_retry_s, cfg.blind.events_backlog)
    # The geometry for the moment balance's rotor effectiveness: as diagnose, --vehicle else the default vehicle.
    state_dir = cfg.state_dir if args.state_dir is None else args.state_dir
    # Outputs at or below lift throttle (the log readers' airborne rule) are idle: what ends a flight without a
    # landed state. A second daemon on the state dir stops here (StateDirBusy: exit 2 naming the holder).
    idle_rpm = float(esc.cmd_to_rpm(LIFT_CMD[esc.cmd_unit]))
    memory = VehicleMemory(state_dir, cfg.resample.rate_hz, idle_rpm=idle_rpm) if state_dir else None
    daemon = Daemon(cfg, link, pipeline, events, Notifier(), vehicle=load_vehicle(vehicle or DEFAULT_VEHICLE), memory=memory)

    def on_signal(signum, _frame):
        log.info("signal %d: stopping", signum)
        daemon.stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    log.info("start-up took %.3f s", time.monotonic() - started)
    # Everything loaded so far (model, dialect tables) lives until exit: keep it out of the collector's
    # full passes, which would otherwise walk it in the middle of a step.
    gc.freeze()
    try:
        return daemon.run()
    finally:
        link.close()
        if args.report:
            daemon.write_report(args.report)
