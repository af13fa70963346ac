"""``make demo``: the main job end to end on the shipped models and the bundled real data.

1. Simulate two flights with the shipped LSTM propeller models (healthy, and
   propeller 3 bent) as PX4-like .tlog files with ground-truth sidecars.
2. Diagnose both with the shipped classifier, exactly as an engineer would
   (``propwatch diagnose --json``), and compare with the ground truth.
3. Diagnose real logs from ``--data``: the ArduPilot DataFlash log and, when
   the Crazyflie model is shipped, one healthy and one cut-propeller CrazyPAD
   flight.
4. Fleet: a small simulated fleet (3 vehicles, one bending a propeller), the
   logs above and the real logs into ``propwatch fleet ingest`` (Ray), then
   ``propwatch fleet report``; prints the site's path.

Each step runs the real command in a subprocess and prints what it said, every
warning included; every diagnosis also writes its ``--report`` (an HTML page and
a PNG of the probability timeline and signals) under ``OUT/reports``, and the
demo prints where.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

from monitor.labels import faulty_for
from monitor.resources import shipped

REPO = Path(__file__).resolve().parent.parent


def _propwatch(*args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "monitor.cli", *args]
    print("$ propwatch " + " ".join(args), flush=True)
    return subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)


def _verdict_line(res: dict) -> str:
    """What ``propwatch diagnose`` says of one log, in its own words (``summary``, monitor/diagnose/verdict.py)."""
    if res.get("error"):
        return f"error: {res['error']}"
    return f"{res['summary']['headline']}\n     next step: {res['summary']['next_step']}"


def _diagnose(log: Path, reports: Path, *extra: str) -> dict:
    r = _propwatch("diagnose", str(log), "--json", "--report", str(reports), *extra)
    try:
        res = json.loads(r.stdout)
    except json.JSONDecodeError:
        res = {
            "error": (r.stderr or r.stdout).strip().splitlines()[-1] if (r.stderr or r.stdout).strip() else f"exit {r.returncode}"
        }
    print("  -> " + _verdict_line(res))
    for w in res.get("warnings", []):
        print(f"     warning: {w}")
    for line in r.stderr.splitlines():
        if m := re.match(r"report: (.+) and (.+)$", line):
            print(f"     picture: {m.group(2)}\n     page:    {m.group(1)}")
    return res


# The demo's simulated flights: (folder, label, fault condition); tests/test_verdict_agreement.py flies the same.
DEMO_CASES = (("healthy", "1", "bent"), ("prop3-bent", "4", "bent"), ("prop1-cracked", "2", "cracked"))
DEMO_SEED = 7


def simulate_args(out: Path, case: tuple[str, str, str], duration_s: float) -> list[str]:
    """``propwatch simulate`` arguments for one demo flight."""
    name, label, fault = case
    return ["--out", str(out / name), "--label", label, "--fault", fault, "--seed", str(DEMO_SEED),
            "--duration-s", str(duration_s), "--format", "tlog"]  # fmt: skip


def run(out: Path, data: Path, duration_s: float = 40.0) -> int:
    out.mkdir(parents=True, exist_ok=True)
    print(f"== 1. simulate ({duration_s:.0f} s flights, shipped LSTM propeller models)")
    cases = DEMO_CASES
    failures = 0
    for case in cases:
        r = _propwatch("simulate", *simulate_args(out, case, duration_s))
        if r.returncode != 0:
            print(r.stderr)
            return r.returncode
    print("\n== 2. diagnose the simulated flights, declared the paper's quad (--vehicle models/vehicle.yaml)")
    for name, label, fault in cases:
        logs = sorted((out / name).glob("*.tlog"))
        res = _diagnose(logs[0], out / "reports" / name, "--vehicle", str(shipped("vehicle.yaml")))
        got = (res.get("verdict") or {}).get("label")
        ok = got == int(label)
        failures += 0 if ok else 1
        truth = "healthy" if label == "1" else f"propeller(s) {'+'.join(map(str, faulty_for(int(label))))} {fault}"
        print(f"     truth: {truth} -> the most likely answer is {'right' if ok else 'WRONG'}")

    print("\n== 3. real logs")
    ardu = data / "ardupilot_log171" / "log171.bin"
    if ardu.is_file():
        print("  (an ArduCopter of unknown build, no airframe declared: physics judges alone; read the warnings)")
        _diagnose(ardu, out / "reports")
    else:
        print(f"  (skipped: {ardu} not found)")
    cf_model = shipped("crazyflie-classifier.onnx")
    cp = data / "crazypad" / "motor"
    if cf_model.is_file() and cp.is_dir():
        for sub in ("normal_flight", "cut_propeller_M3_4mm_3.5mm_39.5mm"):
            files = sorted((cp / sub).glob("*.csv.gz"))
            if files:
                # The vehicle YAML selects its own shipped model (models/crazyflie-classifier.onnx).
                _diagnose(files[0], out / "reports" / sub, "--format", "crazypad", "--vehicle", str(shipped("crazyflie.yaml")))
    else:
        print("  (CrazyPAD skipped: model or data not found)")
    fleet_step(out, data)
    print(f"\nsimulated logs and sidecars are in {out}; reports (open the .html) in {out / 'reports'}")
    return 0 if failures == 0 else 1


def fleet_step(out: Path, data: Path) -> None:
    """4. The fleet view: a small simulated fleet, the demo's logs and the real logs into one database and site."""
    from offline.fleet_sim import FleetSpec, write_fleet

    print("\n== 4. fleet: ingest (Ray) into a DuckDB health database, then the static web report")
    write_fleet(
        out / "fleet-sim", FleetSpec(vehicles=3, flights=4, duration_s=20.0, faulty_vehicle=2, fault_from_flight=2, seed=7)
    )
    real = [data / "px4_ulog", data / "ardupilot_log171", data / "crazypad" / "motor" / "normal_flight"]
    real += [data / "crazypad" / "motor" / "cut_propeller_M3_4mm_3.5mm_39.5mm"]
    own = [out / "fleet-sim"] + [out / name for name in ("healthy", "prop3-bent", "prop1-cracked")]
    paths = [str(p) for p in own + real if p.is_dir()]
    db = out / "fleet.duckdb"
    r = _propwatch("fleet", "ingest", *paths, "--db", str(db), "--format", "crazypad", "--vehicle-from-dir", "1", "--no-progress")
    print("  " + (r.stdout.strip() or r.stderr.strip()[-400:]).replace("\n", "\n  "))
    if r.returncode == 2:
        return
    r = _propwatch("fleet", "report", "--db", str(db), "--out", str(out / "fleet-site"))
    print("  " + (r.stdout.strip() or r.stderr.strip()[-400:]))
    if r.returncode == 0:
        print(f"  fleet site: {out / 'fleet-site' / 'index.html'}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m offline.demo", description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=REPO / "out" / "demo", help="folder for logs and reports (default out/demo)")
    p.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data", help="real data (default ../shared/data)")
    p.add_argument("--duration-s", type=float, default=40.0, help="seconds per simulated flight (default 40)")
    a = p.parse_args(argv)
    return run(a.out, a.data, a.duration_s)


if __name__ == "__main__":
    sys.exit(main())
