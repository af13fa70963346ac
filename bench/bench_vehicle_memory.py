"""Vehicle memory on same-airframe fleets: diagnose, the daemon and the cost, beside the references, in one run.

    python -m bench.bench_vehicle_memory [--evalsim-airframes 24] [--ours-airframes 12] [--daemon-airframes 6]
                                         [--out out/vehicle-memory]

Fleets (simulated into --out unless there): the evaluation-only simulator's set ``vehicles`` (seed 0) and our
simulator's same-airframe fleet (``offline/vehicles/ours.py``, seed 0; the thresholds were measured on seed 1).
Each airframe: 3 healthy references, then 9 later flights (payload 0 to +25 %, wind, new routes), 5 of them with
one propeller damaged from take-off.

1. Diagnose: each later flight against its vehicle's 3 references (vehicle memory), beside the omega^2-share
   reference (flight-mean share minus the references' mean, argmax) and today's nominal diagnose verdict.
2. Daemon (``propwatch monitor --state-dir``, tlog replayed as fast as it goes): per airframe a fresh state dir, the 3
   references replayed (learnt at landing and disarm), then every later flight in order (healthy ones learnt too):
   seconds from take-off to the first FAULT, the propellers it names, any FAULT on a healthy flight.
3. Cost: the daemon's CPU seconds with and without --state-dir on the same replays, as a share of one core at
   real pace (CPU difference over flown seconds); learning: summarise + learn seconds per 10 min of log beyond reading.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench import REPO
from offline.vehicles.evaluate import format_table, load_fleet, nominal_verdicts, score, table

FLIGHTS_PER_AIRFRAME = 12


def ensure_fleets(out: Path, ev_airframes: int, ours_airframes: int) -> dict[str, Path]:
    from offline.evalsim.sets import write_set
    from offline.vehicles.ours import write_fleet

    ev, ours = out / "evalsim-vehicles", out / "ours-vehicles"
    if (
        not (ev / "manifest.json").is_file()
        or json.loads((ev / "manifest.json").read_text())["config"]["flights"] < ev_airframes * 12
    ):
        write_set("vehicles", ev, flights=ev_airframes * FLIGHTS_PER_AIRFRAME, seed=0)
    if (
        not (ours / "manifest.json").is_file()
        or json.loads((ours / "manifest.json").read_text())["config"]["flights"] < ours_airframes * 12
    ):
        write_fleet(ours, ours_airframes * FLIGHTS_PER_AIRFRAME, seed=0)
    return {"evalsim": ev, "ours": ours}


def _run_daemon(log: Path, state_dir: str, events: Path) -> float:
    """CPU seconds of one daemon run over ``log`` (children's user + system time)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    cmd = [sys.executable, "-m", "monitor.cli", "monitor", "--connect", str(log), "--tlog-speed", "0", "--events", str(events)]
    subprocess.run([*cmd, "--state-dir", state_dir], check=True, capture_output=True, cwd=REPO, timeout=600)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def daemon_replays(fleet: Path, airframes: int) -> dict:
    from monitor.logs import read_log
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

    esc = load_vehicle(DEFAULT_VEHICLE).esc
    by = load_fleet(fleet)
    rows, cpu_with, cpu_without, flown_s = [], 0.0, 0.0, 0.0
    for af in sorted(by)[:airframes]:
        with tempfile.TemporaryDirectory() as tmp:
            state = Path(tmp) / "state"
            for f in by[af]:
                ev = Path(tmp) / "events.jsonl"
                ev.unlink(missing_ok=True)
                cpu_with += _run_daemon(Path(f["file"]), str(state), ev)
                cpu_without += _run_daemon(Path(f["file"]), "", Path(tmp) / "events0.jsonl")
                t = read_log(f["file"], esc=esc, rate_hz=20.0, extras=False)
                air = np.flatnonzero(t.airborne)
                takeoff_s = t.timestamp_us[air[0]] / 1e6 if len(air) else 0.0
                flown_s += len(air) / 20.0
                alerts = [json.loads(x) for x in ev.read_text().splitlines() if '"event": "alert"' in x]
                faults = [a for a in alerts if a["level"] == "fault"]
                first = faults[0] if faults else None
                rows.append(
                    {"name": f["name"], "reference": f["reference"], "faulty": f["faulty"], "loss": f["loss"],
                     "fault_s": None if first is None else first["time_boot_ms"] / 1000 - takeoff_s,
                     "named": None if first is None else first["faulty_propellers"], "evidence": None if first is None else first["evidence"],
                     "one_set": first is not None and "hypothesis_sets" not in first,
                     "suspect": any(a["level"] == "suspect" for a in alerts)}
                )  # fmt: skip
    later = [r for r in rows if not r["reference"]]
    dmg = [r for r in later if r["faulty"] and r["loss"] >= 0.06]
    return {
        "airframes": airframes,
        "damaged_ge_6": len(dmg),
        "named_within_15_s": sum(
            r["fault_s"] is not None and r["fault_s"] <= 15 and r["named"] == r["faulty"] and r["one_set"] for r in dmg
        ),
        "alerted_within_15_s": sum(r["fault_s"] is not None and r["fault_s"] <= 15 for r in dmg),
        "wrong_propeller": sum(r["named"] is not None and r["named"] != r["faulty"] for r in later if r["faulty"]),
        "fault_s": sorted(r["fault_s"] for r in dmg if r["fault_s"] is not None),
        "healthy_later": sum(not r["faulty"] for r in later),
        "healthy_with_fault": sum(not r["faulty"] and r["named"] is not None for r in later),
        "references_with_fault": sum(r["reference"] and r["named"] is not None for r in rows),
        "healthy_with_suspect": sum(not r["faulty"] and r["suspect"] for r in later),
        "wrong_single_named": sum(
            r["named"] is not None and r["one_set"] and r["named"] != r["faulty"] for r in later if r["faulty"]
        ),
        "cpu_share_of_core_with": cpu_with / flown_s,
        "cpu_share_of_core_without": cpu_without / flown_s,
        "rows": rows,
    }


def learning_cost(fleet: Path) -> dict:
    """Seconds to summarise and learn, per 10 min of log, beyond reading it."""
    from monitor.logs import read_log
    from monitor.memory.learn import learn_baseline
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

    esc = load_vehicle(DEFAULT_VEHICLE).esc
    by = load_fleet(fleet)
    refs = [f for f in next(iter(by.values())) if f["reference"]]
    t0 = time.perf_counter()
    tables = [read_log(f["file"], esc=esc, rate_hz=20.0, extras=False) for f in refs]
    read_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(10):
        learn_baseline(tables, [f["name"] for f in refs], vehicle_id="bench")
    learn_s = (time.perf_counter() - t0) / 10
    flown_s = sum(len(t) for t in tables) / 20.0
    return {"read_s": read_s, "learn_s": learn_s, "log_s": flown_s, "learn_s_per_10_min": learn_s * 600 / flown_s}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m bench.bench_vehicle_memory", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--out", type=Path, default=REPO / "out" / "vehicle-memory")
    p.add_argument("--evalsim-airframes", type=int, default=24)
    p.add_argument("--ours-airframes", type=int, default=12)
    p.add_argument("--daemon-airframes", type=int, default=6, help="airframes of each fleet replayed through the daemon")
    p.add_argument("--no-nominal", action="store_true", help="skip today's nominal diagnose row (slow)")
    args = p.parse_args(argv)
    fleets = ensure_fleets(args.out, args.evalsim_airframes, args.ours_airframes)
    res = {}
    for name, fleet in fleets.items():
        rows = score(load_fleet(fleet, marks=True))  # judged through time, as diagnose --baseline
        t = table(rows, None if args.no_nominal else nominal_verdicts(rows))
        res[name] = {"diagnose": t}
        print(f"\n## {name}: {fleet} ({len(rows)} later flights)\n")
        print(format_table(t))
        ge8 = [r for r in rows if len(r["faulty"]) == 1 and r["loss"] >= 0.08]
        right8 = sum(r["memory"]["faulty_propellers"] == r["faulty"] and r["memory"]["confidence"] == "confident" for r in ge8)
        print(f"\nsingles >= 8 %: vehicle memory confident exact {right8} of {len(ge8)}")
        res[name]["singles_ge_8"] = [right8, len(ge8)]
        if args.daemon_airframes:
            d = daemon_replays(fleet, args.daemon_airframes)
            res[name]["daemon"] = {k: v for k, v in d.items() if k != "rows"}
            fs = d["fault_s"]
            print(
                f"daemon ({d['airframes']} airframes): damaged >= 6 %: {d['named_within_15_s']} of {d['damaged_ge_6']} named alone within "
                f"15 s of take-off ({d['alerted_within_15_s']} FAULT of any set) (median {np.median(fs) if fs else float('nan'):.1f} s, max {max(fs) if fs else float('nan'):.1f} s); "
                f"a FAULT naming one wrong set {d['wrong_single_named']}; FAULT on {d['healthy_with_fault']} of {d['healthy_later']} healthy later "
                f"flights ({d['healthy_with_suspect']} with a SUSPECT) and {d['references_with_fault']} references; CPU at real pace {100 * d['cpu_share_of_core_with']:.2f} % of a core "
                f"with --state-dir, {100 * d['cpu_share_of_core_without']:.2f} % without (same replays, same run)"
            )
    c = learning_cost(fleets["evalsim"])
    res["learning"] = c
    print(
        f"\nlearning: {c['learn_s']:.3f} s for {c['log_s']:.0f} s of log ({c['learn_s_per_10_min']:.3f} s per 10 min), reading took {c['read_s']:.2f} s"
    )
    (args.out / "bench.json").write_text(json.dumps(res, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
