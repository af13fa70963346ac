"""``python -m offline.alerts.evaluate`` (``make evaluate-alerts``; ``--calibrate`` for ``make calibrate-alerts``).

Calibrate: healthy flights (seeds from ``--calibration-seed``) -> ``models/decision-calibration.json``.
Evaluate: independent flights (other seeds): healthy, single-propeller and pair onsets, replayed through
each rule; writes ``OUT/alerts.json`` (rows + sizes + manifest) and ``OUT/alerts.md`` (the card table).

The issue's full size is >= 10 healthy flight-hours per simulator and >= 200 onset flights:
``--healthy-hours 10 --onset-flights 200`` (the default); smaller runs say their size in the table.
Only our simulator is wired in here; the evaluation-only simulator (offline/evalsim) is not on this branch.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from monitor.daemon.config import AlertConfig
from monitor.decision import DEFAULT_CALIBRATION, DecisionConfig, load_calibration, thresholds
from monitor.model import Classifier
from monitor.vehicle import REPO_ROOT, load_vehicle
from offline.alerts.calibrate import calibrate, write_calibration
from offline.alerts.flights import FlightSet, simulate_set
from offline.alerts.rules import consecutive_rule, decision_rule, px4_rule, summarise
from offline.manifest import make_manifest

FLIGHT_S = 80.0


def parse_args(argv):
    p = argparse.ArgumentParser(prog="python -m offline.alerts.evaluate", description=__doc__.split("\n")[0])
    p.add_argument("--model", default=str(REPO_ROOT / "models" / "classifier.onnx"))
    p.add_argument("--vehicle", default=str(REPO_ROOT / "models" / "vehicle.yaml"))
    p.add_argument("--out", default="out/alerts", help="where alerts.json and alerts.md go")
    p.add_argument("--healthy-hours", type=float, default=10.0, help="healthy flight-hours to evaluate on")
    p.add_argument("--onset-flights", type=int, default=200, help="onset flights (3/4 single propeller, 1/4 pairs)")
    p.add_argument("--calibrate", action="store_true", help="(re)write the calibration first")
    p.add_argument("--calibration-hours", type=float, default=2.0)
    p.add_argument("--calibration-out", default=str(DEFAULT_CALIBRATION))
    p.add_argument("--calibration-seed", type=int, default=100)
    p.add_argument("--seed", type=int, default=200, help="first seed of the evaluation flights (never the calibration's)")
    return p.parse_args(argv)


def _n(hours: float) -> int:
    return max(1, math.ceil(hours * 3600.0 / FLIGHT_S))


def main(argv=None) -> int:
    args = parse_args(argv)
    started = time.monotonic()
    clf = Classifier(args.model)
    vehicle = load_vehicle(args.vehicle)
    cfg = DecisionConfig()
    if args.calibrate:
        fs = FlightSet("healthy", n_flights=_n(args.calibration_hours), seed=args.calibration_seed)
        healthy = simulate_set(vehicle, fs, clf, log=lambda m: print(m, file=sys.stderr))
        cal = calibrate(healthy, args.model, cfg, {"flight_set": fs.__dict__, "simulator": "offline.sim (ours)"})
        path = write_calibration(cal, args.calibration_out, {"flight_set": fs.__dict__}, args.calibration_seed)
        print(f"calibration: {path} {cal['fits']}", file=sys.stderr)
    if args.seed == args.calibration_seed:
        print("--seed must differ from --calibration-seed (evaluate on flights the calibration never saw)", file=sys.stderr)
        return 2
    calibration = load_calibration(args.calibration_out)
    th = thresholds(cfg, clf.info.window / clf.info.sample_rate_hz, None, calibration)
    log = lambda m: print(m, file=sys.stderr)  # noqa: E731
    n_single = max(1, round(0.75 * args.onset_flights))
    sets = {
        "healthy": FlightSet("healthy", n_flights=_n(args.healthy_hours), seed=args.seed),
        "single": FlightSet("single", n_flights=n_single, seed=args.seed + 1),
        "pair": FlightSet("pair", n_flights=max(1, args.onset_flights - n_single), seed=args.seed + 2),
    }
    flights = {k: simulate_set(vehicle, fs, clf, log=log) for k, fs in sets.items()}
    onset = flights["single"] + flights["pair"]
    rules = {
        f"decision (CUSUM, {cfg.false_alarms_per_hour}/h target)": decision_rule(cfg, calibration, use_stored=False),
        "today: P >= 0.9 for 20 windows": consecutive_rule(AlertConfig(threshold=0.9, consecutive=20)),
        "PX4 imbalanced-prop metric (FD_IMB_PROP_THR 30)": px4_rule(),
    }
    rows = {}
    for name, run in rules.items():
        alerts = {"healthy": [run(f) for f in flights["healthy"]], "onset": [run(f) for f in onset]}
        rows[name] = summarise(alerts, flights["healthy"], onset)
        log(f"{name}: {rows[name]}")
    result = {
        "simulator": "offline.sim (ours): random routes, payload 0-0.6 kg, wind <= 6 m/s, motor spread 6 %, CG 1 cm",
        "thresholds": th.as_dict(),
        "rows": rows,
        "sets": {k: fs.__dict__ for k, fs in sets.items()},
        "cpu_s": round(time.process_time(), 1),
        "wall_s": round(time.monotonic() - started, 1),
        "manifest": make_manifest("alert-evaluation", vars(args), args.seed),
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "alerts.json").write_text(json.dumps(result, indent=1, default=str) + "\n", encoding="utf-8")
    (out / "alerts.md").write_text(markdown(result) + "\n", encoding="utf-8")
    print(markdown(result))
    return 0


def _f(v, unit: str = "") -> str:
    return "-" if v is None else f"{v}{unit}"


def markdown(r: dict) -> str:
    first = next(iter(r["rows"].values()))
    lines = [
        f"Alert rules on {r['simulator']}: {first['healthy_flights']} healthy flights "
        f"({first['healthy_hours']} flight-hours), {first['single_onsets']} single-propeller and "
        f"{first['pair_onsets']} pair onsets (bent or cracked, onset 25-50 s). Decision thresholds (nat-s; "
        f"null = disabled): suspect {r['thresholds']['suspect']}, fault {r['thresholds']['fault']} "
        f"({r['thresholds']['source']}).",
        "",
        "| rule | false alarms / h (95 % upper) | suspect / h | single detected | median / p95 latency | "
        "wrong-propeller alerts | alerts before onset | pairs overlapping truth |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, v in r["rows"].items():
        det = "-" if v["single_detected"] is None else f"{100 * v['single_detected']:.1f} %"
        pair = "-" if v["pair_alert_overlaps_truth"] is None else f"{100 * v['pair_alert_overlaps_truth']:.0f} %"
        lines.append(
            f"| {name} | {v['false_alarms_per_hour']} ({v['false_alarms_per_hour_upper95']}) | "
            f"{v['suspect_false_alarms_per_hour']} | {det} | {_f(v['latency_median_s'], ' s')} / "
            f"{_f(v['latency_p95_s'], ' s')} | {v['wrong_propeller_alerts']} | {v['alerts_before_onset']} | {pair} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
