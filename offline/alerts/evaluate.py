"""propwatch evaluate alerts (make evaluate-alerts); with --calibrate it is propwatch tune alerts.

Calibrate (``offline.tune.alerts``, first when ``--calibrate``): healthy flights (seeds from
``--calibration-seed``) -> ``models/decision-calibration.json``.
Evaluate: independent flights (other seeds): healthy, single-propeller and pair onsets, replayed through
each rule; writes ``OUT/alerts.json`` (rows + sizes + manifest) and ``OUT/alerts.md`` (the card table).

Two simulators, scored separately: ours (offline.sim; random routes, payload, wind, motor spread, CG offset
per vehicle variant; the calibration's simulator, on other seeds) and the evaluation-only one
(offline.evalsim: its healthy set, one nuisance per flight, and its onset set, 5-20 % thrust loss on singles
and pairs; never used to calibrate). The issue's full size is >= 10 healthy flight-hours per simulator and
>= 200 onset flights: ``--healthy-hours 10 --onset-flights 200`` (the default); smaller runs say their
size in the table.

Healthy hours are *classified* hours, the time the false-alarm rate is divided by (``AlertFlight.hours``:
a flight counts from its first full classifier window, so an 80-s flight counts 75.05 s). The flight count
that reaches them is computed up front (``healthy_flight_count``); the output gives flown and classified
hours. Our healthy set is the flown-hours set of earlier runs (``ceil(H h / 80 s)`` flights, cached and
unchanged) with the extra flights appended as a second set (``FlightSet.first_flight``); evalsim's flight i
depends on (seed, i) only, so its larger set extends the smaller one.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import pickle
import sys
import time
from pathlib import Path

from monitor.decision.config import DecisionConfig
from monitor.decision.thresholds import DEFAULT_CALIBRATION, Calibration, file_sha256, load_calibration, thresholds
from monitor.model import Classifier
from monitor.vehicle import REPO_ROOT, load_vehicle
from offline.alerts.flights import ALERT_FLIGHT_FIELDS, FlightSet, evalsim_set, simulate_set
from offline.alerts.previous import previous_rule
from offline.alerts.rules import consecutive_rule, decision_rule, px4_rule, summarise
from offline.classifier.consecutive import ConsecutiveConfig
from offline.manifest import make_manifest
from offline.sim.assumptions import REGISTER

FLIGHT_S = 80.0
EVALSIM_BLOCK = 8  # evalsim simulates 8 flights per batch
# evalsim's flights reach us through a .tlog and the log reader, whose grid starts at the first grid instant at
# or after the first message: an 80-s flight gives 1599 or 1600 samples at 20 Hz (measured on its healthy set).
EVALSIM_SAMPLES_SHORT = 1


def parse_args(argv):
    tune = "--calibrate" in (sys.argv[1:] if argv is None else argv)  # propwatch tune alerts puts it first
    p = argparse.ArgumentParser(prog=f"propwatch {'tune' if tune else 'evaluate'} alerts", description=__doc__.split("\n")[0])
    p.add_argument("--model", default=str(REPO_ROOT / "models" / "classifier.onnx"))
    p.add_argument("--vehicle", default=str(REPO_ROOT / "models" / "vehicle.yaml"))
    p.add_argument("--out", default="out/alerts", help="where alerts.json and alerts.md go")
    p.add_argument(
        "--healthy-hours",
        type=float,
        default=10.0,
        help="classified healthy flight-hours to evaluate on (the hours the false-alarm rate is divided by: each "
        "flight counts from its first full classifier window); as many 80-s flights as reach them",
    )
    p.add_argument("--onset-flights", type=int, default=200, help="onset flights (3/4 single propeller, 1/4 pairs)")
    p.add_argument(
        "--evalsim-healthy-hours", type=float, default=None, help="evalsim's classified healthy hours (default: --healthy-hours)"
    )
    p.add_argument("--evalsim-onset-flights", type=int, default=None, help="evalsim's (default: --onset-flights)")
    p.add_argument("--calibrate", action="store_true", help="(re)write the calibration first")
    p.add_argument(
        "--calibration-hours", type=float, default=2.0, help="flown hours of calibration flights (ceil(H h / 80 s) flights)"
    )
    p.add_argument("--calibration-out", default=str(DEFAULT_CALIBRATION))
    p.add_argument("--calibration-seed", type=int, default=100)
    p.add_argument("--seed", type=int, default=200, help="first seed of the evaluation flights (never the calibration's)")
    p.add_argument("--no-evalsim", action="store_true", help="score on our simulator only")
    p.add_argument("--physics", default="randomised", choices=("randomised", "fixed"), help="how our flights draw physics")
    p.add_argument("--pickup-fraction", type=float, default=0.25, help="our healthy flights with a mid-flight payload step")
    p.add_argument("--cache", default="", help="keep classified flight sets here (pickles keyed by set and model)")
    p.add_argument("--list-alerts", action="store_true", help="also list every alert per flight in alerts.json")
    p.add_argument("--compare-suspect-rate", type=float, default=None, help="one more row: the rule at this suspect rate")
    p.add_argument(
        "--compare-with",
        default="",
        help="a checkout (e.g. ../main) whose decision rule and models/decision-calibration.json give one more row",
    )
    return p.parse_args(argv)


def flown_flight_count(hours: float) -> int:
    """Flights of FLIGHT_S in ``hours`` flown hours."""
    return max(1, math.ceil(hours * 3600.0 / FLIGHT_S))


def classified_s(duration_s: float, rate_hz: float, window: int, samples_short: int = 0) -> float:
    """Seconds of one flight the evaluation counts (``AlertFlight.hours``): one classified window per sample
    from the first full window on, ``(samples - window + 1) / rate`` with ``duration x rate`` samples, less
    ``samples_short`` where the log reader can lose the last one."""
    samples = round(duration_s * rate_hz) - samples_short
    if samples < window:
        raise ValueError(f"a {duration_s} s flight at {rate_hz} Hz has {samples} samples, fewer than one {window}-sample window")
    return (samples - window + 1) / rate_hz


def healthy_flight_count(hours: float, per_flight_s: float) -> int:
    """The fewest flights of ``per_flight_s`` classified seconds that reach ``hours`` classified hours."""
    return max(1, math.ceil(hours * 3600.0 / per_flight_s - 1e-9))  # 10 h of 75.0-s flights is 480, not 481


def healthy_sets(hours: float, per_flight_s: float, **kw) -> list[FlightSet]:
    """Our healthy flights for ``hours`` classified hours: the flown-hours set (``flown_flight_count(hours)`` flights, the set
    earlier runs drew and cached) and, when that falls short, the rest appended as a second set."""
    n = healthy_flight_count(hours, per_flight_s)
    first = min(n, flown_flight_count(hours))
    sets = [FlightSet("healthy", n_flights=first, **kw)]
    if n > first:
        sets.append(FlightSet("healthy", n_flights=n - first, first_flight=first, **kw))
    return sets


def set_key(fs: FlightSet, model_sha: str) -> dict:
    """The cache key of one of our flight sets; ``first_flight`` joins it only when set, so sets cached before
    the field existed keep their key. ``fields``: what an ``AlertFlight`` holds (a set cached without a field
    is simulated again); ``register``: randomised physics' assumption ranges."""
    key = {**fs.__dict__, "model": model_sha, "fields": ALERT_FLIGHT_FIELDS}
    if fs.physics == "randomised":  # the register's ranges make the flights (a new assumption makes new ones)
        key["register"] = hashlib.sha256(json.dumps(REGISTER.to_mapping(), sort_keys=True).encode()).hexdigest()[:16]
    if fs.first_flight == 0:
        del key["first_flight"]
    return key


def cached(cache: str, key: dict, make):
    """``make()``, or its pickle from ``cache`` when the same key (set, model digest) was made before."""
    if not cache:
        return make()
    digest = hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:16]
    path = Path(cache) / f"{key.get('kind', 'set')}-{digest}.pkl"
    if path.is_file():
        return pickle.loads(path.read_bytes())
    out = make()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_bytes(pickle.dumps(out))
    tmp.replace(path)
    return out


def evalsim_cached(cache: str, kind: str, n: int, seed: int, clf, sha: str, log) -> list:
    """evalsim's first ``n`` flights of set ``kind``, cached in blocks of EVALSIM_BLOCK: a larger set reuses a smaller one's."""
    out = []
    for start in range(0, n, EVALSIM_BLOCK):
        m = min(EVALSIM_BLOCK, n - start)
        key = {"kind": f"evalsim-{kind}", "start": start, "n": m, "seed": seed, "duration_s": FLIGHT_S, "model": sha}
        key["fields"] = ALERT_FLIGHT_FIELDS
        out += cached(cache, key, lambda s=start, m=m: evalsim_set(kind, m, seed, clf, FLIGHT_S, log=log, start=s))
    return out


def log(message: str) -> None:
    print(message, file=sys.stderr)


def our_flights(args: argparse.Namespace, vehicle, clf, fs: FlightSet) -> list:
    """One of our flight sets, classified (from ``--cache`` when it was made before for this model)."""
    return cached(args.cache, set_key(fs, file_sha256(args.model)), lambda: simulate_set(vehicle, fs, clf, log=log))


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--calibrate" in argv:  # the calibration is `propwatch tune alerts`'s, which then runs this evaluation
        from monitor.cli import main as propwatch

        return propwatch(["tune", "alerts", *(a for a in argv if a != "--calibrate")])
    return evaluate(parse_args(argv))


def evaluate(args: argparse.Namespace) -> int:
    """Score the rules on independent flights of both simulators; write ``OUT/alerts.json`` and ``OUT/alerts.md``."""
    started = time.monotonic()
    clf = Classifier(args.model)
    vehicle = load_vehicle(args.vehicle)
    cfg = DecisionConfig()
    sha = file_sha256(args.model)

    def ours(fs: FlightSet):
        return our_flights(args, vehicle, clf, fs)

    def theirs(kind: str, n: int):
        return evalsim_cached(args.cache, kind, n, args.seed, clf, sha, log)

    ours_kw = dict(physics=args.physics)
    if args.seed == args.calibration_seed:
        print("--seed must differ from --calibration-seed (evaluate on flights the calibration never saw)", file=sys.stderr)
        return 2
    calibration = load_calibration(args.calibration_out)
    th = thresholds(cfg, clf.info.window / clf.info.sample_rate_hz, None, calibration)
    n_single = max(1, round(0.75 * args.onset_flights))
    rate_hz, window = clf.info.sample_rate_hz, clf.info.window
    per_flight_s = {
        "ours": classified_s(FLIGHT_S, rate_hz, window),
        "evalsim": classified_s(FLIGHT_S, rate_hz, window, EVALSIM_SAMPLES_SHORT),
    }
    asked_h = {"ours": args.healthy_hours, "evalsim": args.evalsim_healthy_hours or args.healthy_hours}
    healthy = healthy_sets(
        asked_h["ours"],
        per_flight_s["ours"],
        seed=args.seed,
        pickup_fraction=args.pickup_fraction if args.physics == "randomised" else 0.0,
        **ours_kw,
    )
    sets = {
        **{"healthy" if i == 0 else f"healthy from flight {fs.first_flight}": fs for i, fs in enumerate(healthy)},
        "single": FlightSet("single", n_flights=n_single, seed=args.seed + 1, **ours_kw),
        "pair": FlightSet("pair", n_flights=max(1, args.onset_flights - n_single), seed=args.seed + 2, **ours_kw),
    }
    flights = {
        "ours": {
            "healthy": [f for fs in healthy for f in ours(fs)],
            "onset": ours(sets["single"]) + ours(sets["pair"]),
        }
    }
    if not args.no_evalsim:
        flights["evalsim"] = {
            "healthy": theirs("healthy", healthy_flight_count(asked_h["evalsim"], per_flight_s["evalsim"])),
            "onset": theirs("onset", args.evalsim_onset_flights or args.onset_flights),
        }
    hours = {
        sim: {
            "flights": len(fl["healthy"]),
            "flown_h": round(len(fl["healthy"]) * FLIGHT_S / 3600.0, 3),
            "classified_h": round(sum(f.hours for f in fl["healthy"]), 3),
            "asked_classified_h": asked_h[sim],
        }
        for sim, fl in flights.items()
    }
    for sim, h in hours.items():
        log(f"{sim}: {h['flights']} healthy flights, {h['flown_h']} h flown, {h['classified_h']} h classified")
        if h["classified_h"] < h["asked_classified_h"]:
            log(f"WARNING: {sim}: {h['classified_h']} classified hours, fewer than the {h['asked_classified_h']} asked")
    rules = {
        f"decision (CUSUM, {cfg.false_alarms_per_hour}/h fault, {cfg.suspect_false_alarms_per_hour}/h suspect target)": decision_rule(
            cfg, calibration, use_stored=False
        ),
        "today: P >= 0.9 for 20 windows": consecutive_rule(ConsecutiveConfig(threshold=0.9, consecutive=20)),
        "PX4 imbalanced-prop metric (FD_IMB_PROP_THR 30)": px4_rule(),
    }
    if cfg.suspect_evidence == "all":  # the configurable alternative: the network raises nothing, it only words
        physics_suspects = dataclasses.replace(cfg, suspect_evidence="physics")
        rules["the same with alerts.suspect_evidence: physics"] = decision_rule(physics_suspects, calibration, use_stored=False)
    if calibration is not None:  # ablation: the same rule with the network's statistics off (omega^2 shares alone)
        share_only = Calibration({**calibration.fits, "absolute": None, "change": None}, *_rest(calibration))
        rules["ablation: decision on omega^2 shares alone (network off)"] = decision_rule(cfg, share_only, use_stored=False)
        no_pair = Calibration({**calibration.fits, "pair": None}, *_rest(calibration))
        rules["ablation: without the pair statistic (yaw balance off)"] = decision_rule(cfg, no_pair, use_stored=False)
    if args.compare_suspect_rate is not None:
        other = dataclasses.replace(cfg, suspect_false_alarms_per_hour=args.compare_suspect_rate)
        rules[f"the same at a {other.suspect_false_alarms_per_hour}/h suspect target"] = decision_rule(
            other, calibration, use_stored=False
        )
    if args.compare_with:
        rules[f"previous decision ({_revision(args.compare_with)})"] = previous_rule(args.compare_with)
    rows: dict = {}
    listed: dict = {}
    for sim, fl in flights.items():
        rows[sim] = {}
        for r, (name, run) in enumerate(rules.items()):
            alerts = {"healthy": [run(f) for f in fl["healthy"]], "onset": [run(f) for f in fl["onset"]]}
            rows[sim][name] = summarise(alerts, fl["healthy"], fl["onset"])
            if args.list_alerts and r == 0:  # the decision rule's alerts, flight by flight
                listed[sim] = {
                    f.name: {"truth": f.truth, "onset_s": f.onset_s, "thrust_loss": f.thrust_loss, "alerts": al}
                    for k in ("healthy", "onset")
                    for f, al in zip(fl[k], alerts[k])
                    if al
                }
            log(f"{sim} / {name}: {rows[sim][name]}")
    result = {
        "simulators": {
            "ours": (
                "offline.sim, physics drawn per flight from the assumption register (airframe drawn: motor spread, CG, "
                "arm and ESC errors, motor lag, inertia, drag; gusty wind; battery sag; controller gains; gyro noise; "
                "telemetry delay, jitter and drops), random routes, payload 0-0.6 kg; "
                f"{100 * args.pickup_fraction:.0f} % of healthy flights pick up (3 in 4) or drop a payload of 10-40 % "
                "of the mass mid-flight"
                if args.physics == "randomised"
                else "offline.sim: random routes, payload 0-0.6 kg, wind <= 6 m/s, motor spread 6 %, CG 1 cm (per 8 flights)"
            ),
            "evalsim": "offline.evalsim: its 'healthy' set (one nuisance each) and 'onset' set (5-20 % thrust loss)",
        },
        "thresholds": th.as_dict(),
        "healthy_hours": hours,
        "rows": rows,
        "sets": {k: fs.__dict__ for k, fs in sets.items()},
        **({"decision_alerts": listed} if args.list_alerts else {}),
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


def _rest(cal: Calibration) -> tuple:
    return cal.model_sha256, cal.provenance, cal.peaks, cal.bootstrap, cal.bootstrap_failed, cal.confidence


def _revision(checkout: str) -> str:
    import subprocess

    if not (Path(checkout) / ".git").exists():  # an exported tree: its folder names it
        return Path(checkout).name
    try:
        rev = subprocess.run(["git", "-C", checkout, "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True)
        return f"{Path(checkout).name} {rev.stdout.strip()}"
    except (OSError, subprocess.CalledProcessError):
        return Path(checkout).name


def markdown(r: dict) -> str:
    from offline.alerts.card import COLUMNS, hours_line, rows

    lines = [
        f"Decision thresholds (absolute, change: nat-s; physics: nats; null = disabled): suspect {r['thresholds']['suspect']}, fault "
        f"{r['thresholds']['fault']} ({r['thresholds']['source']}). CPU {r['cpu_s']} s.",
        "",
        "| " + " | ".join(COLUMNS) + " |",
        "|" + "---|" * len(COLUMNS),
    ]
    lines += ["| " + " | ".join(cells) + " |" for cells in rows(r)]
    lines += ["", "Simulators: " + "; ".join(f"{k}: {v}" for k, v in r["simulators"].items() if k in r["rows"])]
    if "healthy_hours" in r:
        lines += ["", hours_line(r)]
    return "\n".join(lines)


if __name__ == "__main__":
    if "--calibrate" in sys.argv[1:]:
        print("python -m offline.alerts.evaluate --calibrate is deprecated: use 'propwatch tune alerts'", file=sys.stderr)
    else:
        print("python -m offline.alerts.evaluate is deprecated: use 'propwatch evaluate alerts'", file=sys.stderr)
    sys.exit(main())
