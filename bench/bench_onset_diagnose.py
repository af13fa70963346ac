"""`propwatch diagnose` on logs of flights whose propeller was damaged mid-flight, on both simulators.

A propeller damaged half-way through a flight (a branch, a hard landing and a second take-off) is the case a
whole-flight verdict handles worst: every window weighs alike, so the healthy part outvotes the damaged one,
and on an airframe unlike its vehicle file the static imbalance looks like damage anywhere. Diagnose now
answers with the in-flight rule where it raised a fault (``monitor.diagnose.engine.apply_in_flight_fault``);
this bench scores both answers on the same logs, beside two ω²-share baselines:

- ``whole flight``: the verdict diagnose gave before (classifier x moment balance over every window);
- ``diagnose``: what it gives now;
- ``ω²-share``: the issue's baseline, the rotor with the largest flight-mean share of ω² (singles only);
- ``ω²-share change (told the onset)``: the rotor whose share rose most from before the onset to after it;
  it is told the true onset time, which no monitor knows (an upper reference, singles only).

Flights: ``--ours N`` singles and N pairs of our simulator (physics drawn from the assumption register, as
``make evaluate-alerts``; seeds 211 / 212, flights no calibration or evaluation set uses), written as .tlog
without the register's telemetry degradation; ``--evalsim N`` flights of the evaluation-only simulator's
``onset`` set (singles and pairs, 5-20 % thrust loss, its own telemetry), which nothing trains or selects on.
Each log goes through the log reader and ``diagnose_table`` as the CLI runs it.

    python -m bench.bench_onset_diagnose --ours 20 --evalsim 40 --card   # ~2 min on 2 cores (evalsim set written once)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from monitor.diagnose.engine import diagnose_table
from monitor.diagnose.physics import physics_evidence
from monitor.logs import read_log
from monitor.model import Classifier, choose_esc
from monitor.resample import US_PER_S
from monitor.vehicle import DEFAULT_VEHICLE, REPO_ROOT, load_vehicle
from offline.share_baseline import omega2_shares, share_baseline
from offline.sim.log import BOOT_OFFSET_US

OURS_SEEDS = {"single": 211, "pair": 212}
CARD_ONSET_S = (25.0, 50.0)  # the card table's flights: damaged 25-50 s into an 80 s flight


def ours_flights(n: int, out: Path, duration_s: float, onset_s: tuple[float, float] = CARD_ONSET_S) -> list[dict]:
    """``n`` singles and ``n`` pairs of our simulator as .tlog files, damaged at a time drawn in ``onset_s``; their
    truth."""
    from offline.alerts.flights import FlightSet, randomised_chunks
    from offline.sim.io_tlog import write_tlog

    vehicle = load_vehicle(DEFAULT_VEHICLE)
    truths = []
    for kind, seed in OURS_SEEDS.items():
        fs = FlightSet(kind, n_flights=n, duration_s=duration_s, physics="randomised", seed=seed, onset_s=onset_s)
        for ch in randomised_chunks(vehicle, fs):
            for b, name in enumerate(ch.names):
                path = write_tlog(out / f"{name}.tlog", ch.flog, b)
                onset = float(np.ceil(ch.onset_s[b] * ch.flog.log_rate_hz) / ch.flog.log_rate_hz)
                faulty = [int(i) + 1 for i in np.flatnonzero(ch.cond[b])]
                # each rotor's thrust factor at its own hover speed, as make evaluate-alerts
                factor = ch.hover_thrust_factors(b, ch.flog.signals()["motor_rpm"][b], vehicle, duration_s).tolist()
                truths.append(
                    {
                        "file": str(path),
                        "faulty_propellers": faulty,
                        "onset_boot_s": BOOT_OFFSET_US / US_PER_S + onset,
                        "thrust_factor_at_hover": factor,
                    }
                )
    return truths


def evalsim_flights(n: int, out: Path, seed: int) -> list[dict]:
    from offline.evalsim.score import load_set
    from offline.evalsim.sets import write_set

    truths = load_set(out)[1] if (out / "manifest.json").is_file() else []
    if len(truths) < n:  # flight i depends on (seed, i) only: a larger set extends a smaller one
        _, truths = load_set(write_set("onset", out, flights=n, seed=seed))
    return [
        {
            "file": str(out / t["file"]),
            "faulty_propellers": sorted(t["faulty_propellers"]),
            "onset_boot_s": BOOT_OFFSET_US / US_PER_S + t["fault_onset_s"],
            "thrust_factor_at_hover": t["thrust_factor_at_hover"],
        }
        for t in truths[:n]
    ]


def score_flight(t: dict, clf: Classifier, esc, vehicle) -> dict:
    table = read_log(t["file"], esc=esc, rate_hz=clf.info.sample_rate_hz, extras=True)
    d = diagnose_table(table, clf, hop=1, esc=esc, vehicle=vehicle)
    whole_eff, _ = physics_evidence(table, vehicle, window=clf.info.window)  # what diagnose read before
    if d.verdict is None:
        return {**t, "error": d.reason}
    v, res = d.verdict, d.to_json()
    whole = v.get("whole_flight", v)
    t_s = np.asarray(table.timestamp_us, dtype=np.float64) / US_PER_S
    air = np.asarray(table.airborne, dtype=bool)
    before, after = air & (t_s < t["onset_boot_s"]), air & (t_s >= t["onset_boot_s"] + 5.0)
    change = None
    if before.sum() > 100 and after.sum() > 100:
        change = omega2_shares(table.motor_cmd, after, esc) - omega2_shares(table.motor_cmd, before, esc)
    return {
        **t,
        "whole_flight": sorted(whole["faulty_propellers"]),
        "diagnose": sorted(v["faulty_propellers"]),
        "confidence": v["confidence"],
        "source": v.get("source", "whole flight"),
        "in_flight_alerts": [a["text"] for a in (d.decision or {}).get("alerts", [])],
        "change_boot_s": v.get("change_boot_s"),
        "hypotheses": [sorted(h["faulty_propellers"]) for h in (res["hypotheses"] or [])],
        "rotor_effectiveness": res["rotor_effectiveness"],
        "whole_flight_effectiveness": whole_eff.rotor_effectiveness if whole_eff is not None else None,
        "rotor_effectiveness_std": res["rotor_effectiveness_std"],
        "share_rotor": share_baseline(omega2_shares(table.motor_cmd, air, esc)),
        "share_change_rotor": None if change is None else share_baseline(change),
    }


def summary(rows: list[dict]) -> dict:
    ok = [r for r in rows if "error" not in r]
    single = [r for r in ok if len(r["faulty_propellers"]) == 1]
    pair = [r for r in ok if len(r["faulty_propellers"]) == 2]

    def frac(xs, f):
        return round(float(np.mean([f(r) for r in xs])), 4) if xs else None

    def wrong(key):
        return lambda r: bool(set(r[key]) - set(r["faulty_propellers"]))

    # The moment balance's reading of each damaged rotor against its true thrust factor at hover (singles, where
    # diagnose gave one): what a person checks by hand.
    def eff(key):
        err = [
            r[key][r["faulty_propellers"][0] - 1] - r["thrust_factor_at_hover"][r["faulty_propellers"][0] - 1]
            for r in single
            if r.get(key) is not None
        ]
        a = np.abs(np.asarray(err))
        return {
            f"{key}_singles_given": len(err),
            f"{key}_singles_abs_error_median": round(float(np.median(a)), 4) if err else None,
            # of every single flight: a withheld reading is not within 2 points
            f"{key}_singles_within_2_points": round(float(np.sum(a <= 0.02) / len(single)), 4) if single else None,
        }

    return {
        "flights": len(rows),
        **eff("rotor_effectiveness"),
        **eff("whole_flight_effectiveness"),
        "no_verdict": len(rows) - len(ok),
        "singles": len(single),
        "pairs": len(pair),
        "whole_flight_exact": frac(ok, lambda r: r["whole_flight"] == r["faulty_propellers"]),
        "whole_flight_single_exact": frac(single, lambda r: r["whole_flight"] == r["faulty_propellers"]),
        "whole_flight_names_a_healthy_propeller": frac(ok, wrong("whole_flight")),
        "diagnose_exact": frac(ok, lambda r: r["diagnose"] == r["faulty_propellers"]),
        "diagnose_single_exact": frac(single, lambda r: r["diagnose"] == r["faulty_propellers"]),
        "diagnose_pair_exact": frac(pair, lambda r: r["diagnose"] == r["faulty_propellers"]),
        "diagnose_truth_in_hypotheses": frac(ok, lambda r: r["faulty_propellers"] in r["hypotheses"]),
        "diagnose_mean_hypotheses": frac(ok, lambda r: len(r["hypotheses"])),
        "diagnose_names_a_healthy_propeller": frac(ok, wrong("diagnose")),
        "diagnose_from_in_flight_change": frac(ok, lambda r: r["source"] == "in-flight change"),
        "in_flight_alerted": frac(ok, lambda r: bool(r["in_flight_alerts"])),  # any level
        "change_before_onset": sum(1 for r in ok if r["change_boot_s"] is not None and r["change_boot_s"] < r["onset_boot_s"]),
        "change_latency_median_s": (
            round(float(np.median([r["change_boot_s"] - r["onset_boot_s"] for r in ok if r["change_boot_s"] is not None])), 2)
            if any(r["change_boot_s"] is not None for r in ok)
            else None
        ),
        "share_single_exact": frac(single, lambda r: [r["share_rotor"]] == r["faulty_propellers"]),
        # None where no flight had 100 airborne samples before its onset (damaged from take-off)
        "share_change_single_exact": frac(
            [r for r in single if r["share_change_rotor"] is not None],
            lambda r: [r["share_change_rotor"]] == r["faulty_propellers"],
        ),
    }


def pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f} %"


def effect(s: dict, key: str) -> str:
    med = s[f"{key}_singles_abs_error_median"]
    given = s[f"{key}_singles_given"]
    return f"{pct(s[f'{key}_singles_within_2_points'])} ({'-' if med is None else f'{100 * med:.1f}'}; given {given})"


COLUMNS = (
    "simulator",
    "verdict",
    "exact",
    "singles",
    "pairs",
    "truth in hypotheses (mean sets)",
    "names a healthy propeller",
    "single's effectiveness within ±2 points (median error, points; readings given)",
    "flights",
)


def table_rows(res: dict) -> list[tuple[str, ...]]:
    rows = []
    for sim, s in res.items():
        n = f"{s['singles']} + {s['pairs']}"
        rows.append(
            (
                sim,
                "whole flight (diagnose before)",
                pct(s["whole_flight_exact"]),
                pct(s["whole_flight_single_exact"]),
                "-",
                "-",
                pct(s["whole_flight_names_a_healthy_propeller"]),
                effect(s, "whole_flight_effectiveness"),
                n,
            )
        )
        rows.append(
            (
                sim,
                "**diagnose now**",
                pct(s["diagnose_exact"]),
                pct(s["diagnose_single_exact"]),
                pct(s["diagnose_pair_exact"]),
                f"{pct(s['diagnose_truth_in_hypotheses'])} ({s['diagnose_mean_hypotheses']:.2f})",
                pct(s["diagnose_names_a_healthy_propeller"]),
                effect(s, "rotor_effectiveness"),
                n,
            )
        )
        rows.append((sim, "ω²-share", "-", pct(s["share_single_exact"]), "-", "-", "-", "-", str(s["singles"])))
        rows.append(
            (
                sim,
                "ω²-share change (told the onset)",
                "-",
                pct(s["share_change_single_exact"]),
                "-",
                "-",
                "-",
                "-",
                str(s["singles"]),
            )
        )
    return rows


def table_md(res: dict) -> str:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in table_rows(res)])


def write_card_table(res: dict, argv_text: str) -> None:
    from offline.classifier.card_tables import TABLES_FILE, CardTable, upsert_table

    table = CardTable(
        key="onset-diagnose",
        title="Diagnose on flights damaged mid-flight, both simulators",
        note=(
            "One propeller (singles) or two (pairs) damaged 25-50 s into an 80 s flight. *whole flight*: the verdict "
            "over every window, what diagnose answered before; *diagnose now*: the in-flight rule's answer where it "
            "reached fault level (the flight against its own first 10 s of evidence), else the whole-flight verdict. "
            "Exact: the verdict's set is the truth; names a healthy propeller: the verdict's set holds a propeller "
            "that is not damaged. *ours*: physics drawn from the assumption register (airframe terms included), "
            "written as .tlog without the register's telemetry degradation; *evalsim*: the evaluation-only "
            "simulator's `onset` set (its own damage model, controller and telemetry), never used for training or "
            "selection. The ω²-share change is told the true onset time, which no monitor knows. Effectiveness: "
            "`rotor_effectiveness` of the damaged rotor of each single against its true thrust factor at hover, "
            "within ±2 points as a share of all singles (a withheld reading counts as a miss); before, diagnose read "
            "the whole flight's balance; now, with an in-flight change, the windows after it against the flight's own "
            "balance before it."
        ),
        columns=COLUMNS,
        rows=tuple(table_rows(res)),
        produced_by=f"python -m bench.bench_onset_diagnose {argv_text}".strip(),
    )
    upsert_table(REPO_ROOT / "models" / TABLES_FILE, table)
    print(f"card table 'onset-diagnose' written to models/{TABLES_FILE}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--ours", type=int, default=20, help="singles and as many pairs of our simulator")
    p.add_argument("--evalsim", type=int, default=40, help="flights of the evaluation simulator's onset set")
    p.add_argument("--seed", type=int, default=0, help="evalsim set seed")
    p.add_argument("--duration", type=float, default=80.0)
    p.add_argument("--model", default=str(REPO_ROOT / "models" / "classifier.onnx"))
    p.add_argument("--out", default="out/onset-diagnose")
    p.add_argument(
        "--onset-s",
        type=float,
        nargs=2,
        default=CARD_ONSET_S,
        metavar=("LO", "HI"),
        help="our flights' damage time, drawn in [LO, HI] s (0 0.5: damaged from take-off, which no in-flight change shows)",
    )
    p.add_argument("--card", action="store_true", help="upsert the table into models/classifier.card-tables.json")
    args = p.parse_args(argv)
    if args.card and tuple(args.onset_s) != CARD_ONSET_S:
        p.error("--card: the card's table is of flights damaged 25-50 s in (the default --onset-s)")
    out = Path(args.out)
    t0 = time.process_time()
    clf = Classifier(args.model)
    esc = choose_esc(clf, "")
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    sets = {}
    if args.ours:
        (out / "ours").mkdir(parents=True, exist_ok=True)
        sets["ours"] = ours_flights(args.ours, out / "ours", args.duration, tuple(args.onset_s))
    if args.evalsim:
        sets["evalsim"] = evalsim_flights(args.evalsim, out / "evalsim", args.seed)
    rows = {sim: [score_flight(t, clf, esc, vehicle) for t in ts] for sim, ts in sets.items()}
    res = {sim: summary(r) for sim, r in rows.items()}
    for sim, r in rows.items():
        for x in r:
            if x.get("diagnose") != x["faulty_propellers"]:
                print(
                    f"{sim} {Path(x['file']).name}: truth {x['faulty_propellers']} diagnose {x.get('diagnose')} "
                    f"({x.get('source')}, sets {x.get('hypotheses')}) whole flight {x.get('whole_flight')}"
                )
    md = table_md(res)
    print(md)
    cpu = time.process_time() - t0
    print(f"CPU {cpu:.0f} s")
    (out / "onset-diagnose.json").write_text(json.dumps({"summary": res, "flights": rows, "cpu_s": round(cpu, 1)}, indent=1))
    (out / "onset-diagnose.md").write_text(md + "\n")
    if args.card:
        write_card_table(res, f"--ours {args.ours} --evalsim {args.evalsim} --seed {args.seed} --card")
    return 0


if __name__ == "__main__":
    sys.exit(main())
