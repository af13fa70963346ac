"""Score ``propwatch diagnose`` on the evaluation-only ``strangers_*`` sets (quad-X airframes of other sizes).

    python -m bench.strangers --set strangers_healthy [--set strangers_onset ...] --seed S --flights N --out DIR
                              [--repo PATH] [--duration-s 80] [--label NAME] [--folder FLIGHTS]

Flights are simulated by THIS checkout's ``offline/evalsim`` into ``DIR/flights/<set>_seed<S>_<D>s`` (reused where
that folder's manifest already holds at least N flights of the same seed and duration: flight i depends only on the
set, the seed and i), then judged by ``propwatch diagnose --json`` of the checkout at ``--repo`` (default: this one),
so the same flights can be scored by another commit (e.g. ``--repo /work/g84``). ``strangers_memory``: per airframe,
``propwatch baseline learn`` on its 3 references, then ``diagnose --baseline`` on its later flights. Outputs (one JSON
per flight, and ``score.json``) go to ``DIR/results/<label>/<set>/``; the label defaults to the --repo commit.

Develop on ``offline.evalsim.names.STRANGERS_DEV_SEED``; ``STRANGERS_EVAL_SEED`` is run once, after the thresholds
are frozen.

What is counted (truth from each flight's JSON; the verdict from ``summary`` and ``verdict``, docs/diagnose-json.md):

- the verdict's named set: ``summary.replace`` where confident, else the first of ``summary.sets`` (empty where
  healthy comes first), else ``summary.inspect``; "exact" when it equals the damaged propellers;
- timed namings: every object anywhere in the JSON with a boot-clock time (``t_boot_s``, ``change_boot_s``, ...) and
  rotors (``propellers``, ``faulty_propellers``, ``motors``, ...): ``decision.alerts[]``, the in-flight verdict, and
  whatever objects of that shape a later version adds. One is an alarm unless its ``level`` is ``suspect``/``none``;
  a motor alarm when its path or text speaks of a motor, ESC, stop or saturation;
- confident-wrong: a confident verdict naming a propeller set other than the truth (on a healthy flight, any), or a
  confident healthy verdict on a damaged flight.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
from collections import Counter, defaultdict
from pathlib import Path

from bench import REPO
from offline.evalsim.names import DEFAULT_DURATION_S, STRANGER_SETS

ONSET_WINDOW_S = 10.0  # in-air damage: named within this of its onset
STOP_WINDOW_S = 1.0  # stopped motor: named within this of the stop
CG_BINS_ARM_FRACTION = (0.0, 0.025, 0.05, 0.1, math.inf)  # take-off damage: CG offset (quirk + payload) / arm
LOGS_PER_CALL = 16  # logs per diagnose process (one start-up for many)
MEMORY_REFERENCES = 3
TIME_KEYS = ("t_boot_s", "change_boot_s", "first_fault_boot_s", "boot_s", "time_boot_s", "stop_boot_s", "onset_boot_s")
ROTOR_KEYS = ("propellers", "faulty_propellers", "motors", "rotors", "motor", "rotor", "px4_rotor")
QUIET_LEVELS = ("suspect", "none", "info", "note", "ok")
MOTOR_WORDS = ("motor", "esc", "stopp", "saturat", "pinned")


# --- flights -------------------------------------------------------------------------------------------------------


def ensure_flights(set_name: str, seed: int, flights: int, duration_s: float, out: Path) -> Path:
    """The folder holding at least ``flights`` flights of ``set_name`` (simulated here when it does not)."""
    from offline.evalsim.catalog import write_set

    d = out / "flights" / f"{set_name}_seed{seed}_{duration_s:g}s"
    m = d / "manifest.json"
    if m.is_file():
        man = json.loads(m.read_text())
        if man["seed"] == seed and man["config"]["flights"] >= flights and man["config"]["duration_s"] == duration_s:
            return d
    write_set(set_name, d, flights=flights, seed=seed, duration_s=duration_s)
    return d


def load_truths(folder: Path, flights: int) -> list[dict]:
    man = json.loads((folder / "manifest.json").read_text())
    rows = []
    for e in man["flights"][:flights]:
        t = json.loads((folder / e["truth"]).read_text())
        t["path"] = str((folder / e["file"]).resolve())
        rows.append(t)
    return rows


# --- running the checkout under test --------------------------------------------------------------------------------


def propwatch(repo: Path, args: list[str]) -> tuple[subprocess.CompletedProcess, float]:
    """Run ``propwatch ARGS`` from the checkout ``repo`` (its code, its models); (the process, its CPU seconds)."""
    env = dict(os.environ, PYTHONPATH=str(repo))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run(
        [sys.executable, "-m", "monitor.cli", *args], cwd=repo, env=env, capture_output=True, text=True, timeout=3600
    )
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return p, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def diagnose(repo: Path, logs: list[str], baseline: str | None = None) -> tuple[list[dict], float]:
    """``diagnose --json`` of each log (in order), and the CPU seconds per log."""
    results, cpu = [], 0.0
    for b in range(0, len(logs), LOGS_PER_CALL):
        chunk = logs[b : b + LOGS_PER_CALL]
        args = ["diagnose", "--json", *chunk] + (["--baseline", baseline] if baseline else [])
        p, c = propwatch(repo, args)
        cpu += c
        try:
            out = json.loads(p.stdout)
        except json.JSONDecodeError:
            out = {"results": [{"log": x, "error": f"exit {p.returncode}: {p.stderr.strip()[-300:]}"} for x in chunk]}
        results.extend(out["results"] if "results" in out else [out])
    return results, cpu / max(len(logs), 1)


def judge(repo: Path, set_name: str, truths: list[dict], res_dir: Path) -> tuple[list[dict], float, list[str]]:
    """Each flight's diagnose JSON (memory: against its airframe's baseline); CPU s per log; problems met."""
    problems: list[str] = []
    if set_name != "strangers_memory":
        js, cpu = diagnose(repo, [t["path"] for t in truths])
    else:
        by_af: dict[str, list[dict]] = defaultdict(list)
        for t in truths:
            by_af[t["airframe_id"]].append(t)
        js_by_name, cpu_total, n = {}, 0.0, 0
        for aid, rows in by_af.items():
            rows.sort(key=lambda t: t["index"])
            refs, later = rows[:MEMORY_REFERENCES], rows[MEMORY_REFERENCES:]
            if len(refs) < MEMORY_REFERENCES or not later:
                continue
            b = res_dir / f"baseline-{aid}.json"
            p, c = propwatch(repo, ["baseline", "learn", *[t["path"] for t in refs], "--out", str(b)])
            cpu_total += c
            if p.returncode != 0 or not b.is_file():
                problems.append(f"{aid}: baseline learn failed (exit {p.returncode}): {p.stderr.strip()[-200:]}")
                base = None
            else:
                base = str(b)
            out, c = diagnose(repo, [t["path"] for t in later], base)
            cpu_total += c * len(later)
            n += len(later)
            js_by_name.update({t["name"]: j for t, j in zip(later, out, strict=True)})
        truths[:] = [t for t in truths if t["name"] in js_by_name]
        js, cpu = [js_by_name[t["name"]] for t in truths], cpu_total / max(n, 1)
    for t, j in zip(truths, js, strict=True):
        (res_dir / f"{t['name']}.json").write_text(json.dumps(j, indent=1) + "\n")
    return js, cpu, problems


# --- reading a verdict ----------------------------------------------------------------------------------------------


def summary(j: dict) -> dict:
    return j.get("summary") or {}


def state(j: dict) -> str:
    if "error" in j:
        return "error"
    if j.get("verdict") is None and not summary(j):
        return "no verdict"
    return str(summary(j).get("state", "no verdict"))


def confident(j: dict) -> bool:
    return summary(j).get("confidence") == "confident"


def named_set(j: dict) -> tuple[int, ...]:
    """The propellers the verdict names first (see the module docstring)."""
    s = summary(j)
    if s.get("replace"):
        return tuple(sorted(s["replace"]))
    sets = s.get("sets") or []
    if sets:
        return tuple(sorted(sets[0]))
    return tuple(sorted(s.get("inspect") or []))


def faulty_marked(j: dict) -> bool:
    """A FAULTY verdict: confident damage, or any propeller marked faulty."""
    return state(j) == "damaged" or any(p.get("faulty") for p in j.get("propellers") or [] if isinstance(p, dict))


def _rotors(x) -> tuple[int, ...] | None:
    if isinstance(x, bool):
        return None
    if isinstance(x, int):
        return (x,)
    if isinstance(x, list) and all(isinstance(r, int) and not isinstance(r, bool) for r in x):
        return tuple(sorted(x))
    return None


def timed_events(j: dict) -> list[dict]:
    """Every object with a boot-clock time and rotors, anywhere in ``j``: {t, rotors, level, alarm, motor, path}."""
    out: list[dict] = []

    def walk(x, path: str) -> None:
        if isinstance(x, dict):
            t = next((x[k] for k in TIME_KEYS if isinstance(x.get(k), int | float) and not isinstance(x.get(k), bool)), None)
            r = next((_rotors(x[k]) for k in ROTOR_KEYS if _rotors(x.get(k)) is not None), None)
            if t is not None and r:
                words = " ".join([path, *(str(v) for v in x.values() if isinstance(v, str))]).lower()
                level = x.get("level")
                out.append(
                    {
                        "t": float(t),
                        "rotors": r,
                        "level": level,
                        "alarm": level not in QUIET_LEVELS,
                        "motor": any(w in words for w in MOTOR_WORDS),
                        "path": path,
                    }
                )
            for k, v in x.items():
                walk(v, f"{path}.{k}" if path else k)
        elif isinstance(x, list):
            for v in x:
                walk(v, f"{path}[]")

    walk(j, "")
    return out


def propeller_alarms(j: dict) -> list[dict]:
    return [e for e in timed_events(j) if e["alarm"] and not e["motor"]]


def motor_alarms(j: dict) -> list[dict]:
    return [e for e in timed_events(j) if e["alarm"] and e["motor"]]


def confident_wrong(j: dict, truth_set: tuple[int, ...]) -> bool:
    if not confident(j):
        return False
    replace = tuple(sorted(summary(j).get("replace") or []))
    if replace and replace != truth_set:
        return True
    return bool(truth_set) and state(j) == "healthy"


# --- tallies --------------------------------------------------------------------------------------------------------


def _pct(k: int, n: int) -> str:
    return f"{k}/{n} ({100.0 * k / n:.0f} %)" if n else "0/0"


def _named_within(j: dict, rotors: tuple[int, ...], t0: float, window_s: float, motor: bool | None = None) -> bool:
    evs = timed_events(j)
    return any(
        e["alarm"] and e["rotors"] == rotors and t0 <= e["t"] <= t0 + window_s and (motor is None or e["motor"] == motor)
        for e in evs
    )


def _common(rows: list[tuple[dict, dict]]) -> dict:
    truth_sets = [tuple(t["faulty_propellers"]) for t, _ in rows]
    return {
        "flights": len(rows),
        "states": dict(Counter(state(j) for _, j in rows)),
        "confident_wrong": sum(confident_wrong(j, ts) for (_, j), ts in zip(rows, truth_sets, strict=True)),
    }


def score_healthy(rows: list[tuple[dict, dict]]) -> dict:
    def block(sel):
        return {
            "flights": len(sel),
            "faulty": sum(faulty_marked(j) for _, j in sel),
            "in_flight_fault": sum(bool(propeller_alarms(j)) for _, j in sel),
            "motor_alarms": sum(bool(motor_alarms(j)) for _, j in sel),
            "no_damage": sum(state(j) == "healthy" for _, j in sel),
            "inspect": sum(state(j) == "inspect" for _, j in sel),
            "no_verdict": sum(state(j) in ("no verdict", "error") for _, j in sel),
        }

    hard = [r for r in rows if r[0].get("hard_manoeuvre")]
    return {
        **_common(rows),
        **block(rows),
        "hard": block(hard),
        "hard_saturating": sum(r[0]["saturated_fraction"] > 0.01 for r in hard),
    }


def score_onset(rows: list[tuple[dict, dict]]) -> dict:
    exact = within = wrong = 0
    for t, j in rows:
        ts = tuple(t["faulty_propellers"])
        exact += named_set(j) == ts
        within += _named_within(j, ts, t["fault_onset_boot_s"], ONSET_WINDOW_S)
        wrong += any(e["rotors"] != ts for e in propeller_alarms(j))
    return {**_common(rows), "exact": exact, "named_within_10s": within, "wrong_in_flight_alarm": wrong}


def cg_bin(frac: float) -> str:
    edges = CG_BINS_ARM_FRACTION
    i = next(k for k in range(len(edges) - 1) if edges[k] <= frac < edges[k + 1])
    return f"{edges[i]:.3f}-{edges[i + 1]:.3f}" if math.isfinite(edges[i + 1]) else f">={edges[i]:.3f}"


def score_takeoff(rows: list[tuple[dict, dict]]) -> dict:
    bins: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    exact = conf_exact = conf_healthy = in_inspect = 0
    for t, j in rows:
        ts = tuple(t["faulty_propellers"])
        hit = named_set(j) == ts
        exact += hit
        conf_exact += hit and confident(j) and state(j) == "damaged"
        conf_healthy += state(j) == "healthy" and confident(j)
        in_inspect += set(ts) <= set(summary(j).get("propellers") or [])
        b = bins[cg_bin(t["cg_offset_arm_fraction"])]
        b[0] += hit
        b[1] += 1
    return {
        **_common(rows),
        "exact": exact,
        "exact_confident": conf_exact,
        "confident_healthy": conf_healthy,
        "truth_in_replace_or_inspect": in_inspect,
        "by_cg_arm_fraction": {k: {"named": v[0], "flights": v[1]} for k, v in sorted(bins.items())},
    }


def score_stopped(rows: list[tuple[dict, dict]]) -> dict:
    motor_1s = any_1s = ever = called_propeller = 0
    for t, j in rows:
        r, t0 = (int(t["stopped_motor"]),), float(t["stop_boot_s"])
        motor_1s += _named_within(j, r, t0, STOP_WINDOW_S, motor=True)
        any_1s += _named_within(j, r, t0, STOP_WINDOW_S)
        ever += any(e["alarm"] and r[0] in e["rotors"] and e["t"] >= t0 for e in timed_events(j))
        called_propeller += tuple(sorted(summary(j).get("replace") or [])) == r
    return {
        **_common(rows),
        "motor_named_within_1s": motor_1s,
        "named_within_1s_any_kind": any_1s,
        "named_after_stop": ever,
        "replace_propeller_of_stopped_motor": called_propeller,
    }


def score_memory(rows: list[tuple[dict, dict]]) -> dict:
    healthy = [r for r in rows if not r[0]["faulty_propellers"]]
    takeoff = [r for r in rows if r[0]["faulty_propellers"] and r[0]["fault_onset_boot_s"] is None]
    onset = [r for r in rows if r[0]["fault_onset_boot_s"] is not None]
    h = score_healthy(healthy) if healthy else {}
    return {
        **_common(rows),
        "healthy_later": {
            k: h.get(k) for k in ("flights", "faulty", "in_flight_fault", "motor_alarms", "no_damage", "inspect", "no_verdict")
        },
        "takeoff_later": {
            "flights": len(takeoff),
            "exact": sum(named_set(j) == tuple(t["faulty_propellers"]) for t, j in takeoff),
        },
        "onset_later": score_onset(onset) if onset else {"flights": 0},
    }


SCORERS = {
    "strangers_healthy": score_healthy,
    "strangers_onset": score_onset,
    "strangers_takeoff": score_takeoff,
    "strangers_stopped": score_stopped,
    "strangers_memory": score_memory,
}


def format_score(set_name: str, s: dict) -> str:
    n = s["flights"]
    lines = [f"{set_name}: {n} flights, states {s['states']}, CONFIDENT-WRONG {s['confident_wrong']}"]
    if set_name == "strangers_healthy":
        lines += [
            f"  FAULTY {s['faulty']}; in-flight FAULT {s['in_flight_fault']}; motor/saturation alarms {s['motor_alarms']}",
            f"  headline 'no damage' {_pct(s['no_damage'], n)}; inspect {s['inspect']}; no verdict {s['no_verdict']}",
            f"  hard manoeuvres {s['hard']['flights']} ({s['hard_saturating']} with outputs at a limit > 1 % of samples): "
            f"FAULTY {s['hard']['faulty']}, in-flight FAULT {s['hard']['in_flight_fault']}, "
            f"motor alarms {s['hard']['motor_alarms']}, 'no damage' {_pct(s['hard']['no_damage'], s['hard']['flights'])}",
        ]
    elif set_name == "strangers_onset":
        lines += [
            f"  exact-named {_pct(s['exact'], n)}; named within {ONSET_WINDOW_S:g} s of onset {_pct(s['named_within_10s'], n)}; "
            f"flights with an in-flight alarm naming another set {s['wrong_in_flight_alarm']}"
        ]
    elif set_name == "strangers_takeoff":
        lines += [
            f"  damaged rotor named {_pct(s['exact'], n)} (confident {s['exact_confident']}); in replace/inspect "
            f"{_pct(s['truth_in_replace_or_inspect'], n)}; confident healthy {s['confident_healthy']}",
            "  by CG offset / arm: "
            + ", ".join(f"{k}: {_pct(v['named'], v['flights'])}" for k, v in s["by_cg_arm_fraction"].items()),
        ]
    elif set_name == "strangers_stopped":
        lines += [
            f"  motor/ESC failure named within {STOP_WINDOW_S:g} s {_pct(s['motor_named_within_1s'], n)}; that rotor named "
            f"within {STOP_WINDOW_S:g} s (any kind) {_pct(s['named_within_1s_any_kind'], n)}; after the stop "
            f"{_pct(s['named_after_stop'], n)}; its propeller to replace {s['replace_propeller_of_stopped_motor']}"
        ]
    elif set_name == "strangers_memory":
        h, tk, on = s["healthy_later"], s["takeoff_later"], s["onset_later"]
        lines += [
            f"  later healthy {h['flights']}: FAULTY {h['faulty']}, in-flight FAULT {h['in_flight_fault']}, "
            f"'no damage' {_pct(h['no_damage'] or 0, h['flights'] or 0)}, inspect {h['inspect']}, no verdict {h['no_verdict']}",
            f"  later damaged from take-off: exact {_pct(tk['exact'], tk['flights'])}",
        ]
        if on.get("flights"):
            lines.append(
                f"  later damaged in the air: exact {_pct(on['exact'], on['flights'])}, named within "
                f"{ONSET_WINDOW_S:g} s {_pct(on['named_within_10s'], on['flights'])}"
            )
    return "\n".join(lines)


def repo_label(repo: Path) -> str:
    def git(*a):
        return subprocess.run(["git", "-C", str(repo), *a], capture_output=True, text=True).stdout.strip()

    dirty = "-dirty" if git("status", "--porcelain", "--untracked-files=no") else ""
    return (git("rev-parse", "--short", "HEAD") or repo.name) + dirty


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.strangers", description=__doc__.split("\n")[0])
    p.add_argument("--set", dest="sets", action="append", required=True, choices=STRANGER_SETS)
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--flights", type=int, required=True, help="flights per set (strangers_memory: 12 per airframe)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--repo", type=Path, default=REPO, help="the checkout whose propwatch judges (default: this one)")
    p.add_argument("--duration-s", type=float, default=DEFAULT_DURATION_S)
    p.add_argument("--label", help="results folder name (default: the --repo commit)")
    p.add_argument(
        "--folder",
        type=Path,
        help="judge the flights already in this folder (e.g. offline.vehicles.ours.write_fleet's, for development on "
        "our own simulator) instead of the set's; one --set names how they are scored",
    )
    a = p.parse_args(argv)
    if a.folder and len(a.sets) != 1:
        p.error("--folder takes exactly one --set")
    repo = a.repo.resolve()
    label = a.label or repo_label(repo)
    report = {"repo": str(repo), "label": label, "seed": a.seed, "flights": a.flights, "duration_s": a.duration_s, "sets": {}}
    for set_name in a.sets:
        folder = a.folder.resolve() if a.folder else ensure_flights(set_name, a.seed, a.flights, a.duration_s, a.out.resolve())
        truths = load_truths(folder, a.flights)
        res_dir = a.out.resolve() / "results" / label / set_name
        res_dir.mkdir(parents=True, exist_ok=True)
        js, cpu, problems = judge(repo, set_name, truths, res_dir)
        s = SCORERS[set_name](list(zip(truths, js, strict=True)))
        s["diagnose_cpu_s_per_flight"] = cpu
        s["problems"] = problems
        report["sets"][set_name] = s
        (res_dir / "score.json").write_text(json.dumps(s, indent=1) + "\n")
        print(format_score(set_name, s))
        print(f"  diagnose CPU {cpu:.2f} s per flight ({label}); seed {a.seed}, {a.duration_s:g} s flights")
        for pr in problems:
            print(f"  problem: {pr}")
    (a.out.resolve() / "results" / label / f"score_seed{a.seed}.json").write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
