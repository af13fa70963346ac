"""The path of one MAVLink message through the daemon: which of our modules it enters, and how often it comes back.

    python -m bench.message_path                 # synthetic 30-s flight, propeller 3 fails at 17 s, shipped model
    python -m bench.message_path --tlog F.tlog   # a recorded flight instead

Every message of the flight goes through ``Daemon.handle`` (as ``propwatch monitor`` does, with the vehicle's
geometry) under ``sys.setprofile``. Each Python call or return that moves execution from one of the repository's
modules to another is an *entry* of the module it lands in (library frames, numpy's and pymavlink's, are not
counted: the module that called them is still the one running). Per message:

- modules visited: the distinct repository modules the message entered;
- returns: entries into a module the message had already left (entries - modules visited);
- hub entries: entries into ``monitor/daemon/service.py`` (the daemon's loop), and the calls it makes per stage
  (``from_hub``: modules entered straight from it; the stages are the pipeline, which shows the message to
  ``monitor/daemon/autopilot.py`` once decoded, and decide, which hands each step to ``monitor/daemon/announce.py``);

as means over all messages, over the messages that completed a classified grid step, and for the message whose
step raised the first FAULT (with its entries per module). The figures count calls, not time: a profile hook
slows the run many times over.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from bench import REPO

HUB = "monitor/daemon/service.py"
ROOTS = tuple(str(REPO / d) + "/" for d in ("monitor", "offline"))


def module_of(frame, cache: dict) -> str | None:
    path = frame.f_code.co_filename
    name = cache.get(path, False)
    if name is False:
        name = cache[path] = path[len(str(REPO)) + 1 :] if path.startswith(ROOTS) else None
    return name


def trace_message(daemon, msg, received_s: float) -> list[str]:
    """The sequence of repository modules ``daemon.handle(msg)`` runs in, consecutive repeats collapsed."""
    seq: list[str] = []
    cache: dict = {}

    def hook(frame, event, arg):
        if event == "call":
            mod = module_of(frame, cache)
        elif event == "return":
            back = frame.f_back
            mod = module_of(back, cache) if back is not None else None
        else:
            return
        if mod is not None and (not seq or seq[-1] != mod):
            seq.append(mod)

    sys.setprofile(hook)
    try:
        daemon.handle(msg, received_s)
    finally:
        sys.setprofile(None)
    return seq


def build(args, work: Path):
    from pymavlink.dialects.v20 import common as mavlink

    from monitor.daemon.config import MonitorConfig
    from monitor.daemon.events import EventWriter
    from monitor.daemon.pipeline import Pipeline
    from monitor.daemon.sdnotify import Notifier
    from monitor.daemon.service import Daemon
    from monitor.mavlink.player import read_tlog
    from monitor.model import Classifier, choose_esc
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
    from tests.test_daemon_helpers import synth_flight, toy_model, write_tlog

    model = Path(args.model) if args.model else REPO / "models" / "classifier.onnx"
    if not model.is_file():
        model = toy_model(work / "toy.onnx")
    tlog = Path(args.tlog) if args.tlog else None
    if tlog is None:
        frames = synth_flight(args.seconds, faulty=(3,), fault_from_s=17.0, seed=args.seed, pos_hz=30.0, imu_hz=50.0)
        tlog = write_tlog(work / "flight.tlog", frames)
    parser = mavlink.MAVLink(None)
    msgs = [m for _, f, _ in read_tlog(tlog) for m in (parser.parse_buffer(f) or [])]
    clf = Classifier(str(model))
    cfg = MonitorConfig()
    vehicle = load_vehicle(DEFAULT_VEHICLE)

    class NullLink:  # what the daemon sends is not under test
        url, is_log, is_udpout, eof = "null:", False, False, False

        def __getattr__(self, name):
            return lambda *a, **k: None

    daemon = Daemon(cfg, NullLink(), Pipeline(clf, cfg, choose_esc(clf, "")), EventWriter(None), Notifier({}), vehicle=vehicle)
    return daemon, msgs, model


def summarise(paths: list[list[str]]) -> dict:
    if not paths:
        return {"messages": 0}
    visited = [len(set(p)) for p in paths]
    entries = [len(p) for p in paths]
    from_hub: Counter = Counter()
    for p in paths:
        from_hub.update(b for a, b in zip(p, p[1:]) if a == HUB)
    return {
        "messages": len(paths),
        "modules_visited_mean": round(sum(visited) / len(paths), 2),
        "returns_mean": round(sum(e - v for e, v in zip(entries, visited)) / len(paths), 2),
        "modules_visited_max": max(visited),
        "returns_max": max(e - v for e, v in zip(entries, visited)),
        "hub_entries_mean": round(sum(p.count(HUB) for p in paths) / len(paths), 2),
        "from_hub_mean": {k: round(v / len(paths), 2) for k, v in from_hub.most_common()},
    }


def run(args) -> dict:
    with tempfile.TemporaryDirectory(prefix="propwatch-path-") as tmp:
        daemon, msgs, model = build(args, Path(tmp))
        all_paths, step_paths, fault_path = [], [], None
        for m in msgs:
            classified, alerts = daemon.pipeline.stats["classified"], daemon.counters.alerts
            before = daemon.decision.level.copy()
            path = trace_message(daemon, m, time.perf_counter())
            all_paths.append(path)
            if daemon.pipeline.stats["classified"] > classified:
                step_paths.append(path)
            if fault_path is None and daemon.counters.alerts > alerts and "fault" in daemon.decision.level:
                if "fault" not in before:
                    fault_path = path
    out = {
        "model": str(model),
        "all_messages": summarise(all_paths),
        "classified_step_messages": summarise(step_paths),
        "first_fault_message": None,
    }
    if step_paths:
        out["classified_step_messages"]["last_path"] = step_paths[-1]
    if fault_path is not None:
        out["first_fault_message"] = {
            **summarise([fault_path]),
            "entries_per_module": dict(Counter(fault_path).most_common()),
            "path": fault_path,
        }
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tlog", help="replay this .tlog instead of a synthetic flight")
    p.add_argument("--model", help="ONNX model (default models/classifier.onnx, else the tests' toy model)")
    p.add_argument("--seconds", type=float, default=30.0, help="synthetic flight length")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true", help="the figures as JSON (with the first FAULT's whole path)")
    args = p.parse_args(argv)
    out = run(args)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"model: {out['model']}")
    for key in ("all_messages", "classified_step_messages", "first_fault_message"):
        s = out[key]
        if not s:
            print(f"{key}: none")
            continue
        print(
            f"{key}: {s['messages']} messages, modules visited {s['modules_visited_mean']} (max {s['modules_visited_max']}), "
            f"returns {s['returns_mean']} (max {s['returns_max']}), hub entries {s['hub_entries_mean']}"
        )
        print("  from the hub:", ", ".join(f"{k} {v}" for k, v in s["from_hub_mean"].items()))
    if out["first_fault_message"]:
        print("  entries per module:", ", ".join(f"{k} {v}" for k, v in out["first_fault_message"]["entries_per_module"].items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
