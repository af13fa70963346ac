"""What a pilot reads: one verdict object built from the ``diagnose --json`` result, rendered everywhere.

``verdict_of(result)`` turns one diagnosis (``Diagnosis.to_json()`` or the fleet's stored ``diagnosis`` column)
into a ``Verdict``: which propellers to replace or inspect, how sure, the next step, and the evidence behind it in
plain words. The text output (``monitor.diagnose.cli.format_text``), the JSON's ``summary`` key, the HTML page and
PNG (``monitor.diagnose.report``) and the fleet site's rows (``fleet.report``) all render this one object, so they
state the same propellers, confidence and next step (tests/test_verdict_agreement.py replays every demo and real
log through all five).

Wording rules:

* "is damaged: replace it" only for a ``confident`` verdict that names propellers.
* Otherwise every hypothesis set is named ("Propeller 3 or propellers 1+2+3") and every propeller in any of them is
  to be inspected, with one sentence on why the evidence cannot tell them apart.
* The fault classifier's own probability is evidence, named as such; a propeller it flags at or above the
  verdict's FAULTY level (``verdict.faulty_probability_required``, 0.9) is always in the next step, so no
  headline clears a propeller the numbers below it flag.
* Label numbers, windows and the conformal rule stay in ``--json`` and docs/diagnose-json.md.

Times are seconds after take-off (the first airborne sample), never the autopilot's boot clock.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field

from monitor.decision.network_gate import UNDECLARED_START

# PX4 quad-X: where each rotor sits and which way it spins (monitor/vehicle.py's rotor positions).
POSITION = {1: "front-right", 2: "rear-left", 3: "front-left", 4: "rear-right"}
SAME_SPIN_PAIRS = ((1, 2), (3, 4))  # diagonal pairs spinning the same way (1, 2 CCW; 3, 4 CW)
FLAG_PROBABILITY = 0.9  # the classifier's P(faulty) that puts a propeller in the next step (DecisionConfig's FAULTY)
MAX_SETS_NAMED = 4  # beyond this many hypothesis sets the headline counts them instead of naming each

STATES = ("damaged", "motor", "inspect", "healthy", "imbalance", "no verdict", "unreadable")


@dataclass(frozen=True)
class Verdict:
    """One flight's verdict as every rendering states it (``to_json`` is the ``summary`` key of ``diagnose --json``)."""

    state: str  # one of STATES
    confidence: str  # the diagnosis' verdict.confidence ("confident", "ambiguous", "suspect", "uncertain"), "none"
    replace: tuple[int, ...]  # PX4 rotors to replace (a confident fault)
    inspect: tuple[int, ...]  # PX4 rotors to inspect (any hypothesis set, or flagged by the classifier)
    sets: tuple[tuple[int, ...], ...]  # the hypothesis sets the verdict cannot tell apart, most probable first
    names: tuple[str, ...]  # the vehicle's own rotor names, PX4 order
    headline: str
    next_step: str
    why: str | None = None  # why the evidence cannot tell the sets apart (not confident only)
    evidence: tuple[str, ...] = ()
    change_s: float | None = None  # s after take-off when the in-flight evidence changed (an in-flight fault)
    compared_with: str | None = None  # "against 3 healthy flights of this vehicle, 2026-05-01 to 05-03"
    takeoff_boot_s: float | None = None  # the boot-clock time that is 0 s in every rendering
    warnings: tuple[str, ...] = field(default=())

    @property
    def propellers(self) -> tuple[int, ...]:
        """Every propeller the next step touches (replace or inspect), PX4 order."""
        return tuple(sorted(set(self.replace) | set(self.inspect)))

    def status(self, px4_rotor: int) -> str:
        """``replace``, ``inspect``, ``ok``, or ``not judged`` (no verdict): what the verdict asks of one propeller."""
        if self.state in ("no verdict", "unreadable"):
            return "not judged"
        return "replace" if px4_rotor in self.replace else "inspect" if px4_rotor in self.inspect else "ok"

    def to_json(self) -> dict:
        out = asdict(self)
        out["sets"] = [list(s) for s in self.sets]
        del out["warnings"]  # the diagnosis' own ``warnings`` key
        for k in ("replace", "inspect", "names", "evidence"):
            out[k] = list(out[k])
        out["propellers"] = list(self.propellers)
        out["status"] = [self.status(i) for i in range(1, 5)]
        return out


def rotor_words(i: int, names) -> str:
    """``propeller 3 (front-left)``; a vehicle with its own names: ``propeller M3 (rear-left)``."""
    return f"propeller {names[i - 1] if names else i} ({POSITION[i]})"


def _num(i: int, names) -> str:
    return names[i - 1] if names else str(i)


def _and(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def set_words(s, names, capital: bool = False) -> str:
    """One hypothesis set: ``no damage``, ``propeller 3 (front-left)``, ``propellers 1+2+3``."""
    if not s:
        text = "no damage"
    elif len(s) == 1:
        text = rotor_words(s[0], names)
    else:
        text = "propellers " + "+".join(_num(i, names) for i in s)
    return text[0].upper() + text[1:] if capital else text


def why_alike(sets, physics: bool) -> str:
    """One sentence: why the evidence cannot tell these propeller sets apart."""
    if not physics:
        return (
            "This log gave no usable balance of forces (see the warnings), and the fault classifier alone "
            "does not single out one of them."
        )
    diffs = {tuple(sorted(set(a) ^ set(b))) for a in sets for b in sets if a != b}
    pair = next((p for p in SAME_SPIN_PAIRS if p in diffs), None)
    if pair is not None:
        a, b = pair
        return (
            f"Propellers {a} and {b} sit diagonally opposite and spin the same way, so thrust lost on both alike "
            "leaves the vehicle level and asks the motors for almost the same outputs: only the yaw torque, "
            "which the log does not measure, could tell these apart."
        )
    return "Each of these damages asks the motors for nearly the same outputs to hold the vehicle level, so the log cannot tell them apart."


def flight_seconds(boot_s: float, takeoff_boot_s: float | None) -> float:
    return boot_s - (takeoff_boot_s or 0.0)


def compared_with_words(flights: int | None, first: str | None, last: str | None) -> str | None:
    """``against 3 healthy flights of this vehicle, 2026-05-01 to 05-03`` from the vehicle memory's comparison."""
    if not flights:
        return None
    what = f"against {flights} healthy flight{'s' if flights != 1 else ''} of this vehicle"
    if first and last and first != last:
        return f"{what}, {first} to {last[5:] if first[:5] == last[:5] else last}"  # the year once
    return f"{what}, {first or last}" if (first or last) else what


def _compared(result: dict) -> str | None:
    """What the flight was compared with, and what does not tie the log to it (the baseline's ``caveats``)."""
    b = result.get("baseline") or {}
    c = b.get("compared_with")
    if not isinstance(c, dict):
        return None
    words = compared_with_words(c.get("flights"), c.get("first"), c.get("last"))
    caveats = b.get("caveats") or []
    return f"{words} (but {'; '.join(caveats)})" if words and caveats else words


def _classifier_probability(v: dict) -> list[float] | None:
    """The fault classifier's own mean P(faulty) per propeller (with a set rule ``fault_probability`` is the rule's)."""
    p = v.get("network_fault_probability") or v.get("fault_probability")
    if v.get("source") == "in-flight change" and not v.get("network_fault_probability"):
        p = v.get("fault_probability")  # the whole flight's, which is what the classifier said
    return list(p) if p else None


def _verdict_sets(result: dict) -> list[tuple[int, ...]]:
    """The sets the verdict names: the rule's or the in-flight rule's hypotheses, else the verdict's one set."""
    v = result["verdict"]
    own = tuple(v.get("faulty_propellers") or ())
    hyps = result.get("hypotheses") or []
    if v.get("imbalance_rotors"):
        return [tuple(v["imbalance_rotors"])]
    if result.get("hypothesis_rule") is not None or v.get("source") in ("in-flight change", "first flight", "motor output"):
        sets = [tuple(h["faulty_propellers"]) for h in hyps if "faulty_propellers" in h]
        if sets:
            return sets
    return [own]


def _evidence(result: dict, names, takeoff: float | None) -> list[str]:
    v = result["verdict"]
    out = []
    p = _classifier_probability(v)
    if p:
        flagged = [i + 1 for i, x in enumerate(p) if x >= 0.5]
        if flagged:
            out.append(
                "Fault classifier (a neural network reading the motor outputs and attitude): probability of damage "
                + _and([f"{100 * p[i - 1]:.0f} % on {_num(i, names)}" for i in flagged])
                + (
                    ", " + f"at most {100 * max(p[i] for i in range(4) if i + 1 not in flagged):.0f} % on the others"
                    if len(flagged) < 4
                    else ""
                )
                + "."
            )
        else:
            top = max(range(4), key=lambda i: p[i])
            out.append(
                "Fault classifier (a neural network reading the motor outputs and attitude): no propeller above 50 % "
                f"probability of damage (highest {100 * p[top]:.0f} %, on {_num(top + 1, names)})."
            )
    eff, std = result.get("rotor_effectiveness"), result.get("rotor_effectiveness_std")
    if eff:
        out.append(
            "Balance of forces (physics): "
            + ", ".join(f"{_num(i + 1, names)} gives {100 * e:.0f} %" for i, e in enumerate(eff))
            + " of its normal thrust"
            + (f" (each to within {100 * max(std):.0f} %)" if std else "")
            + "."
        )
    sh = result.get("shares")
    if sh and sh.get("level_shares"):
        what = "omega^2" if sh.get("basis") == "omega2" else "motor output"
        out.append(
            f"Shares ({what}, physics): "
            + ", ".join(f"{_num(i + 1, names)} {100 * x:.0f} %" for i, x in enumerate(sh["level_shares"]))
            + " of the mean of the four in level flight"
            + (
                f"; {_num(sh['top_rotor'], names)} stands {100 * sh['standout']:.1f} points above the next "
                f"(healthy airframes reach {100 * sh['standout_threshold']:.0f})"
                if sh.get("top_rotor")
                else ""
            )
            + "."
        )
    net = result.get("network") or {}
    if net and not net.get("used"):
        out.append(
            "Fault classifier: silent (physics only: "
            + (
                "nothing declares this airframe to be the one it was trained on)."
                if undeclared(result)
                else "this airframe is not the one the network was trained on)."
            )
        )
    dec = result.get("decision")
    if dec:
        faults = [a for a in dec.get("alerts", []) if a.get("level") == "fault"]
        tested = (dec.get("final") or {}).get("tested_s", 0.0)
        if faults:
            a = faults[0]
            which = "+".join(_num(i, names) for i in a.get("propellers") or []) or "unlocalised"
            unused = v.get("source") != "in-flight change"
            out.append(
                f"In-flight monitor: fault on {which} at {flight_seconds(a['t_boot_s'], takeoff):.0f} s after take-off"
                + (
                    " (not used: this log is unlike the flights the monitor was calibrated on; see the warnings)."
                    if unused
                    else "."
                )
            )
        elif dec.get("alerts"):
            a = dec["alerts"][0]
            which = "+".join(_num(i, names) for i in a.get("propellers") or []) or "unlocalised"
            out.append(
                f"In-flight monitor: suspected {which} at {flight_seconds(a['t_boot_s'], takeoff):.0f} s after take-off, never a fault."
            )
        elif tested > 0:
            out.append(f"In-flight monitor: no alert over {tested:.0f} s of flight compared with its own start.")
        else:
            out.append("In-flight monitor: no opinion: the flight was too short to learn its own normal (10 s) first.")
    return out


def _flagged_extra(result: dict, named: set[int]) -> list[int]:
    """Propellers the classifier flags at the FAULTY level that the verdict's sets do not name."""
    v = result["verdict"]
    p = _classifier_probability(v) or []
    level = v.get("faulty_probability_required", FLAG_PROBABILITY)
    return [i + 1 for i, x in enumerate(p) if x >= level and i + 1 not in named]


def undeclared(result: dict) -> bool:
    """The network was silent because nothing declared the log's airframe (``monitor.diagnose.engine.undeclared``)."""
    return ((result.get("network") or {}).get("why_not") or "").startswith(UNDECLARED_START)


def verdict_of(result: dict) -> Verdict:
    """The ``Verdict`` of one ``diagnose --json`` object (or a fleet row's stored diagnosis)."""
    names = tuple(p["name"] for p in result.get("propellers") or []) or ("1", "2", "3", "4")
    if result.get("error"):
        return Verdict(
            "unreadable",
            "none",
            (),
            (),
            (),
            names,
            "Log not readable: " + result["error"],
            "Nothing was judged: fix or replace the log (the message names what is wrong) and diagnose it again.",
        )
    segs = result.get("airborne_segments") or []
    takeoff = segs[0]["start_boot_s"] if segs else None
    warnings = tuple(result.get("warnings") or ())
    compared = _compared(result)
    v = result.get("verdict")
    if v is None:
        reason = result.get("reason") or ""
        other_vehicle = re.search(r"try (--vehicle \S+?(?: or --vehicle \S+?)*)\)?$", reason)
        return Verdict(
            "no verdict",
            "none",
            (),
            (),
            (),
            names,
            "No verdict: " + plain_reason(reason),
            f"Nothing was judged: diagnose this log again with {other_vehicle.group(1)}."
            if other_vehicle
            else "Nothing was judged: check the propellers as before any flight; to have them judged, diagnose a log "
            "of a minute of steady flight with motor outputs and attitude.",
            takeoff_boot_s=takeoff,
            compared_with=compared,
            warnings=warnings,
        )
    conf = v.get("confidence", "confident")
    sets = _verdict_sets(result)
    silent = (result.get("network") or {}).get("why_not") or ""
    other_vehicle = re.search(r"try (--vehicle \S+?(?: or --vehicle \S+?)*)\)?$", silent)
    # where the log is another class of vehicle than the model's, the vehicle's own model may judge it too
    own_model = (
        (
            f" If this is the airframe of {other_vehicle.group(1).removeprefix('--vehicle ')}, diagnose it again with "
            f"{other_vehicle.group(1)} to have its classifier judge it too."
            if undeclared(result)
            else f" Diagnose this log again with {other_vehicle.group(1)} to have its own model judge it too."
        )
        if other_vehicle
        else ""
    )
    evidence = _evidence(result, names, takeoff)
    change = flight_seconds(v["change_boot_s"], takeoff) if v.get("source") == "in-flight change" else None
    when = f" (from {change:.0f} s after take-off)" if change is not None else ""
    named = {i for s in sets for i in s}
    flagged = _flagged_extra(result, named)
    if flagged and not v.get("network"):  # the network alone: a note, never a propeller to inspect
        evidence.append(
            f"Note: the fault classifier alone flags {_and([_num(i, names) for i in flagged])}; physics does not "
            f"name {'it' if len(flagged) == 1 else 'them'}, so {'it is' if len(flagged) == 1 else 'they are'} not "
            "asked for."
        )
    extra: list[int] = []
    also = ""
    common = dict(
        names=names,
        evidence=tuple(evidence),
        change_s=change,
        compared_with=compared,
        takeoff_boot_s=takeoff,
        warnings=warnings,
    )
    if v.get("source") == "motor output":
        k = v["faulty_propellers"][0]
        kinds = {a["rotor"]: a["kind"] for a in v.get("motor_output") or []}
        since = flight_seconds(v["change_boot_s"], takeoff)
        n = _num(k, names)
        if kinds.get(k, "stopped") == "stopped":
            return Verdict(  # a motor, not a propeller: nothing to replace until the motor is checked
                "motor",
                conf,
                (),
                (k,),
                ((k,),),
                headline=f"Motor {n} ({POSITION[k]}) stopped from {since:.0f} s after take-off: its output sat at the "
                "bottom of its range while the others flew; a motor or ESC failure, not a propeller.",
                next_step=f"Check motor {n}, its ESC and wiring before the next flight; then its propeller.",
                **common,
            )
        return Verdict(
            "inspect",
            conf,
            (),
            (k,),
            ((k,),),
            headline=f"Motor {n} ({POSITION[k]}) at full output from {since:.0f} s after take-off while the others were "
            f"not: that corner is at its limit.",
            next_step=f"Check motor {n} and its ESC, inspect propeller {n}, and check that the load sits centred "
            "before the next flight.",
            why="A failing motor or ESC, a damaged propeller and a load off centre towards it all ask that motor for "
            "everything it has.",
            **common,
        )
    if v.get("source") == "first flight":
        if sets and sets[0]:
            k = sets[0][0]
            sh = result.get("shares") or {}
            lvl = sh.get("level_shares") or [1.0] * 4
            harder = 100 * (lvl[k - 1] - 1.0)
            n = _num(k, names)
            return Verdict(
                "inspect",
                conf,
                (),
                (k,),
                ((k,), ()),
                headline=f"Rotor {n} works {harder:.0f} % harder than the mean of the four: a damaged propeller {n}, or "
                "this airframe's balance; 3 healthy flights of this vehicle will tell.",
                next_step=f"Inspect propeller {n} before the next flight; replace it if it is chipped, cracked or bent. "
                "If it is intact, learn this vehicle's normal (propwatch baseline learn) from 3 healthy flights." + own_model,
                why="Without the vehicle's history, a CG off towards this rotor or a weaker motor moves its share as "
                "a damaged propeller does.",
                **common,
            )
        return Verdict(
            "healthy",
            conf,
            (),
            (),
            ((),),
            headline="No damage seen.",
            next_step="Fly as usual. A first flight cannot see a propeller damaged before take-off that moves its "
            "rotor's share no more than this airframe's own balance does: 3 healthy flights of this vehicle "
            "(propwatch baseline learn) will." + own_model,
            why="No rotor's share stands out beyond what healthy airframes show; without the vehicle's history, "
            "damage present from take-off smaller than its own balance cannot be seen.",
            **common,
        )
    if v.get("imbalance_rotors"):
        rotors = tuple(v["imbalance_rotors"])
        where = _and([rotor_words(i, names) for i in rotors])
        return Verdict(
            "imbalance",
            conf,
            (),
            tuple(sorted(set(rotors) | set(extra))),
            (rotors,),
            headline=f"Imbalance near {where}{when}: a shifted load or battery, or a damaged propeller{also}.",
            next_step=f"Check that the load and battery sit centred, and inspect {_and([_num(i, names) for i in rotors])}"
            + (f" and {_and([_num(i, names) for i in extra])}" if extra else "")
            + ".",
            why=v.get("imbalance_why")
            or "On this airframe's healthy flights a mass off centre and a damaged propeller were measured to look alike.",
            **common,
        )
    if conf == "confident" and sets[0]:
        s = sets[0]
        it = "it" if len(s) == 1 else "them"
        who = _and([rotor_words(i, names) for i in s])
        verb = "is" if len(s) == 1 else "are"
        return Verdict(
            "damaged",
            conf,
            tuple(s),
            tuple(extra),
            (tuple(s),),
            headline=f"{who[0].upper() + who[1:]} {verb} damaged{when}: replace {it}{also}.",
            next_step=f"Replace {_and([_num(i, names) for i in s])}"
            + (f", inspect {_and([_num(i, names) for i in extra])}" if extra else "")
            + ", then fly a short check flight and diagnose it.",
            **common,
        )
    if conf == "confident":
        if extra:
            nums = _and([_num(i, names) for i in extra])
            return Verdict(
                "inspect",
                conf,
                (),
                tuple(extra),
                ((),),
                headline=f"No damage measured, but the fault classifier alone flags {nums}: inspect "
                + ("it." if len(extra) == 1 else "them."),
                next_step=f"Inspect {nums} before the next flight.",
                **common,
            )
        return Verdict(
            "healthy",
            conf,
            (),
            (),
            ((),),
            headline="No damaged propeller found.",
            next_step="Fly as usual.",
            **common,
        )
    inspect = tuple(sorted(named | set(extra)))
    physics = bool(result.get("rotor_effectiveness"))
    if len(sets) > MAX_SETS_NAMED:
        top = " or ".join(set_words(s, names) for s in sets[:2])
        headline = f"Not sure: {len(sets)} possible damage patterns, most likely {top}"
    elif len(sets) > 1:
        headline = " or ".join(set_words(s, names, capital=k == 0) for k, s in enumerate(sets))
    elif sets[0]:
        headline = f"{set_words(sets[0], names, capital=True)} may be damaged (not sure)"
    else:
        headline = "Probably no damage (not sure)"
    if inspect:
        what = "all four" if len(inspect) == 4 else _and([_num(i, names) for i in inspect])
        headline += f"{when}: inspect {what}" + (
            f" ({_and([_num(i, names) for i in extra])} flagged by the fault classifier alone)" if extra else ""
        )
        whom = "all four propellers" if len(inspect) == 4 else ("propeller " if len(inspect) == 1 else "propellers ") + what
        step = f"Inspect {whom} before the next flight; replace any that is chipped, cracked or bent."
    else:
        step = "No propeller to single out: check all four as before any flight, and diagnose the next flight."
    why = why_alike(sets, physics) if len(sets) > 1 else "The evidence points this way but not strongly enough to be sure."
    return Verdict("inspect", conf, (), inspect, tuple(sets), headline=headline + ".", next_step=step, why=why, **common)


def plain_reason(reason: str) -> str:
    """The engine's reason for no verdict, in a pilot's words where it has a technical one."""
    if reason.startswith("no usable window"):
        return "the log holds no 5 s of continuous flight with every signal logged."
    if reason.startswith("no airborne flight"):
        return "the log holds no flight (the vehicle never left the ground with its motors running)."
    if reason.startswith("not a quad-X"):
        return (
            "this is not a four-rotor (quad-X) vehicle, the only kind propwatch knows ("
            + reason.split(": ")[1].split(";")[0]
            + ")."
        )
    if reason.startswith("vehicle outside the model's envelope"):
        return "this vehicle flies unlike the ones propwatch's model knows (" + reason.split(": ", 1)[-1] + ")."
    return reason
