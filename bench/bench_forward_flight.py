"""False alarms in fast forward flight with blade flapping, on the evaluation-only simulator.

On the one real flight here flown fast (ArduPilot log171) the front rotors' omega^2 shares trim by up to 0.27
with forward speed (docs/ALERTS.md "On real flights"): the aerodynamic trim of forward flight (blade flapping).
Our register draws flapping and the shares' baseline is a plane in airspeed (docs/ALERTS.md "The shares' baseline
follows the airspeed").
This bench measures the effect in evalsim's ``forward_flight`` set (healthy, routes at up to 10 m/s, flapping
drawn from 0 to log171's trim, ``offline.evalsim.sets.FLAPPING_MAX``) against the same flights without flapping
(a paired control: same seeds, routes, wind and noise), replayed through the shipped decision rule as
``make evaluate-alerts`` does; ``--compare-with CHECKOUT`` adds that checkout's rule on the same flights.

Evaluation only: never used to choose a threshold or a setting.

    python -m bench.bench_forward_flight --flights 48 --card   # ~7 min on 2 cores
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace

import numpy as np

from monitor.decision.config import DecisionConfig
from monitor.decision.rotor_share import _YAW_FREE, BASELINE_S, SHARE_AVERAGE_S
from monitor.decision.thresholds import file_sha256, load_calibration
from monitor.model import Classifier
from monitor.vehicle import REPO_ROOT
from offline.alerts.evaluate import _revision, cached
from offline.alerts.flights import ALERT_FLIGHT_FIELDS, evalsim_specs
from offline.alerts.previous import previous_rule
from offline.alerts.rules import decision_rule
from offline.evalsim.sets import FLAPPING_MAX, build_set


def share_excursion(f) -> float:
    """Largest |yaw-free omega^2 share (mean over SHARE_AVERAGE_S) - the flight's first BASELINE_S| of any rotor."""
    w2 = np.asarray(f.motor_rpm, dtype=np.float64) ** 2
    s = w2 / w2.mean(axis=1, keepdims=True)
    x = s @ _YAW_FREE.T
    n, b = int(round(SHARE_AVERAGE_S * f.rate_hz)), int(round(BASELINE_S * f.rate_hz))
    ok = np.isfinite(x).all(axis=1)
    x = x[ok]
    if len(x) < b + n:
        return float("nan")
    c = np.cumsum(np.vstack([np.zeros(4), x]), axis=0)
    means = (c[n:] - c[:-n]) / n
    return float(np.abs(means[b:] - x[:b].mean(axis=0)).max())


def ground_speed_m_s(table) -> np.ndarray:
    v = np.asarray(table.vel_ned_m_s, dtype=np.float64)[np.asarray(table.airborne, bool)]
    return np.linalg.norm(v[:, :2], axis=1)


def score(flights, tables, run) -> dict:
    hours = sum(f.hours for f in flights)
    alerts = [run(f) for f in flights]
    faults = [[a for a in al if a[1] == "fault"] for al in alerts]
    suspects = [[a for a in al if a[1] == "suspect"] for al in alerts]
    speed = np.concatenate([ground_speed_m_s(t) for t in tables])
    exc = np.array([share_excursion(f) for f in flights])
    return {
        "flights": len(flights),
        "classified_h": round(hours, 3),
        "false_alarms": sum(len(x) for x in faults),
        "false_alarms_per_hour": round(sum(len(x) for x in faults) / hours, 2),
        "flights_with_a_fault": sum(bool(x) for x in faults),
        "suspects_per_hour": round(sum(len(x) for x in suspects) / hours, 2),
        "ground_speed_p50_p90_max_m_s": [round(float(q), 1) for q in np.percentile(speed, [50, 90, 100])],
        "share_excursion_p50_p90_max": [round(float(q), 3) for q in np.nanpercentile(exc, [50, 90, 100])],
        "first_fault_texts": [
            f"{f.name}: {a[0]:.1f} s PROP {'+'.join(map(str, a[2]))}" for f, x in zip(flights, faults) for a in x[:1]
        ][:8],
    }


COLUMNS = (
    "flights (same seeds)",
    "classified h",
    "FAULT alerts (flights)",
    "false alarms / h",
    "suspect / h",
    "ground speed p50 / p90 / max",
    "largest yaw-free share excursion p50 / p90 / max",
)


def table_cells(name: str, r: dict) -> tuple[str, ...]:
    sp, ex = r["ground_speed_p50_p90_max_m_s"], r["share_excursion_p50_p90_max"]
    return (
        name,
        f"{r['classified_h']}",
        f"{r['false_alarms']} ({r['flights_with_a_fault']} of {r['flights']})",
        f"{r['false_alarms_per_hour']}",
        f"{r['suspects_per_hour']}",
        f"{sp[0]} / {sp[1]} / {sp[2]} m/s",
        f"{ex[0]} / {ex[1]} / {ex[2]}",
    )


CARD_TITLE = "Alert decisions in fast forward flight with blade flapping (evaluation-only simulator)"


def card_table(result: dict, argv_text: str):
    """The card's table of this run (``--card``): both rows, with what they are."""
    from offline.classifier.card_tables import CardTable

    note = (
        "Healthy flights of evalsim's `forward_flight` set (routes at up to 10 m/s; blade flapping drawn from 0 to "
        f"{result['flapping_max']:.1e} N m per rad/s per m/s, the forward-flight trim of the one real quad here "
        "flown fast, ArduPilot log171), and the same flights without flapping, replayed through the shipped decision "
        "rule (and, where a row says so, the previous one: its baseline a constant). The rule is calibrated on our "
        "simulator with flapping drawn; this simulator is never used to choose anything (docs/ALERTS.md). A share excursion is the largest 2-s mean of a rotor's yaw-free share "
        "of omega^2 against the flight's first 10 s (a 10 % thrust loss moves it by 0.05)."
    )
    rows = tuple(table_cells(name, r) for name, r in result["rows"].items())
    return CardTable(
        "alerts-forward-flight", CARD_TITLE, note, COLUMNS, rows, f"python -m bench.bench_forward_flight {argv_text}"
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--flights", type=int, default=48)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=80.0)
    p.add_argument("--model", default=str(REPO_ROOT / "models" / "classifier.onnx"))
    p.add_argument("--json", action="store_true")
    p.add_argument("--card", action="store_true", help="upsert the table into models/classifier.card-tables.json")
    p.add_argument("--cache", default="", help="keep the simulated flights here (pickles keyed by set and model)")
    p.add_argument(
        "--compare-with", default="", help="a checkout whose decision rule and calibration give rows of their own (previous)"
    )
    a = p.parse_args(argv)
    t0 = time.monotonic()
    clf = Classifier(a.model)
    specs = build_set("forward_flight", flights=a.flights, seed=a.seed, duration_s=a.duration)
    twins = [replace(s, airframe=s.airframe.with_(flapping_nm_per_rad_s_m_s=0.0)) for s in specs]
    runs = {"": decision_rule(DecisionConfig(), load_calibration(), use_stored=False)}
    if a.compare_with:
        runs[f"previous ({_revision(a.compare_with)}): "] = previous_rule(a.compare_with)
    log = lambda m: print(f"evalsim forward_flight: {m}", file=sys.stderr)  # noqa: E731
    sha = file_sha256(a.model)
    rows = {}
    for name, ss, twin in (
        ("10 m/s, flapping 0..log171's trim", specs, False),
        ("10 m/s, no flapping (same flights)", twins, True),
    ):
        key = {"kind": "forward-flight", "n": a.flights, "seed": a.seed, "duration_s": a.duration, "twin": twin}
        key.update(model=sha, fields=ALERT_FLIGHT_FIELDS)
        pairs = cached(a.cache, key, lambda ss=ss: evalsim_specs(ss, clf, log=log))
        for prefix, run in runs.items():
            rows[prefix + name] = score([fl for fl, _ in pairs], [t for _, t in pairs], run)
    result = {"set": "evalsim forward_flight", "seed": a.seed, "flapping_max": FLAPPING_MAX, "rows": rows}
    result["wall_s"] = round(time.monotonic() - t0, 1)
    if a.card:
        from offline.classifier.card_tables import TABLES_FILE, upsert_table

        cmd = f"--flights {a.flights} --seed {a.seed} --card" + (" --compare-with <previous checkout>" if a.compare_with else "")
        upsert_table(REPO_ROOT / "models" / TABLES_FILE, card_table(result, cmd))
        print(f"card table 'alerts-forward-flight' written to models/{TABLES_FILE}; run `make card-text`", file=sys.stderr)
    if a.json:
        print(json.dumps(result, indent=1))
        return 0
    print(f"evalsim forward_flight, seed {a.seed}: {a.flights} healthy flights of {a.duration:.0f} s, shipped decision rule")
    print("| " + " | ".join(COLUMNS) + " |")
    print("|" + "---|" * len(COLUMNS))
    for name, r in rows.items():
        print("| " + " | ".join(table_cells(name, r)) + " |")
    for name, r in rows.items():
        if r["first_fault_texts"]:
            print(f"{name}: " + "; ".join(r["first_fault_texts"]))
    print(f"wall {result['wall_s']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
