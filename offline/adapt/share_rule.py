"""The older share rule of one airframe: 3 flight-to-flight spreads of its healthy flights' omega^2 shares.

No longer a verdict of any command: ``propwatch diagnose``, the daemon and the fleet judge a flight against the
vehicle's own history with ``monitor.memory`` (docs/VEHICLE_MEMORY.md). What stays here, offline:

- ``propwatch adapt``'s own check that its healthy logs agree (``offline.adapt.checks``: ``flight_shares``,
  ``OUTLIER_SPREADS``, ``SPREAD_FLOOR``), which admits real sessions that drift more than vehicle memory's prior
  (CrazyPAD E9_log03);
- the comparison rule behind the CrazyPAD card's "with the airframe's healthy baseline" figures
  (``bench/crazypad_fusion.py``, ``bench/crazypad_baseline.py``, ``bench/evalsim_hidden.py``): ``HealthyBaseline``,
  ``fuse``, ``cg_or_damage``, measured at the git revisions those figures name.

Shares: each rotor's flight-mean of omega^2 (RPM from the ESC fit, squared) over the mean of the four, over the
airborne samples; the motor command's share where no ESC fit applies (``basis``). Spread: the flight-to-flight std
of each share, floored at ``SPREAD_FLOOR``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from monitor.errors import ConfigError
from monitor.flight import FlightTable
from monitor.labels import LABEL_TABLE

BASELINE_FILE = "baseline.json"
# Floor of the flight-to-flight std of a share. One airframe's shares drift between sessions by more than
# the std within one (CrazyPAD E9: logs 00-02 std <= 0.008, log03 is 0.056 off on M1; E8 std up to 0.026),
# so two or three flights of one session must not make every later healthy flight an outlier.
SPREAD_FLOOR = 0.02
OUTLIER_SPREADS = 3.0  # a share this many spreads from the airframe's healthy mean is not healthy

# Student's t quantiles t_{df}.isf(p) at p = Phi(-3) = 0.0013499, the one-sided tail of the Gaussian 3-sigma rule,
# for df = 1..30 (scipy.stats.t.isf; a test checks them where scipy is installed). A new flight against the mean and
# std of n healthy flights follows t with n - 1 degrees of freedom, scaled by sqrt(1 + 1/n) (prediction interval):
# with 3-4 flights the tails are far heavier than 3 sigma.
T_ISF_3SIGMA = (
    235.8015, 19.2067, 9.2189, 6.6202, 5.5071, 4.9041, 4.5300, 4.2766, 4.0943, 3.9569,
    3.8499, 3.7643, 3.6942, 3.6358, 3.5864, 3.5441, 3.5075, 3.4755, 3.4472, 3.4222,
    3.3997, 3.3796, 3.3613, 3.3448, 3.3296, 3.3158, 3.3030, 3.2913, 3.2804, 3.2703,
)  # fmt: skip


def t_spreads_required(n_flights: int) -> float | None:
    """The spreads a share must be from the healthy mean of ``n_flights`` to be as rare as a Gaussian 3 sigma,
    with the std estimated from those flights: t_{n-1} quantile * sqrt(1 + 1/n). None below 2 flights (no std).
    Beyond 31 flights the first-order Cornish-Fisher term z + (z^3 + z) / (4 df) stands in for the table."""
    if n_flights < 2:
        return None
    df = n_flights - 1
    z = OUTLIER_SPREADS
    q = T_ISF_3SIGMA[df - 1] if df <= len(T_ISF_3SIGMA) else z + (z**3 + z) / (4.0 * df)
    return float(q * np.sqrt(1.0 + 1.0 / n_flights))


def _rows_and_basis(table: FlightTable) -> tuple[np.ndarray, np.ndarray, str]:
    """Airborne rows with all four values known, their per-rotor values, and the basis.

    omega^2 (kRPM^2) where RPM is known (the ESC fit or ESC telemetry), as ``offline.share_baseline``;
    the raw command where no RPM is known for any airborne row.
    """
    rpm = np.asarray(table.motor_rpm, dtype=np.float64)
    rows = table.airborne & np.all(np.isfinite(rpm), axis=1)
    if rows.any():
        return rows, (rpm[rows] / 1000.0) ** 2, "omega2"
    cmd = np.asarray(table.motor_cmd, dtype=np.float64)
    rows = table.airborne & np.all(np.isfinite(cmd), axis=1)
    if not rows.any():
        raise ConfigError(f"{table.source}: no airborne step with all four motor values: no shares")
    return rows, cmd[rows], "command"


def flight_shares(table: FlightTable) -> tuple[np.ndarray, str]:
    """(4,) each rotor's airborne mean omega^2 (or command) over the mean of the four, and the basis."""
    _, x, basis = _rows_and_basis(table)
    mean = np.mean(x, axis=0)
    return mean / np.mean(mean), basis


def share_noise(table: FlightTable) -> np.ndarray:
    """(4,) within-flight std of each rotor's per-sample share (grid rate), airborne samples."""
    _, x, _ = _rows_and_basis(table)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = x / np.mean(x, axis=1, keepdims=True)
    return np.nanstd(s, axis=0)


@dataclass(frozen=True)
class HealthyBaseline:
    basis: str  # "omega2" or "command"
    shares_mean: tuple[float, float, float, float]  # PX4 rotor order
    shares_std: tuple[float, float, float, float]  # flight-to-flight, ddof=1 (0 with one flight)
    noise_std: tuple[float, float, float, float]  # within-flight std of the per-sample share, mean over flights
    activity: tuple[float, float, float, float] | None  # native-rate command activity (>= 50 Hz logs), else None
    rate_hz: float  # grid the shares and noise were measured on
    n_flights: int
    files: tuple[str, ...]
    motor_names: tuple[str, str, str, str]
    # Whether evidence on flights of this kind of airframe tells a CG offset near a rotor (a mass there) from a
    # damaged propeller on it: False where it was measured not to (CrazyPAD: offline/crazypad/README.md), None
    # where nobody measured it. False makes `diagnose --vehicle DIR` word a one-rotor verdict as an imbalance.
    cg_damage_separable: bool | None = None
    cg_damage_evidence: str = ""  # where that was measured

    def spread(self) -> np.ndarray:
        return np.maximum(np.asarray(self.shares_std), SPREAD_FLOOR)

    def deviation(self, shares: np.ndarray) -> np.ndarray:
        """(4,) how many spreads each share is from this airframe's healthy mean."""
        return (np.asarray(shares) - np.asarray(self.shares_mean)) / self.spread()

    def compare(self, table: FlightTable) -> dict:
        """A flight against the baseline: its shares, their deviation, and the rotors beyond 3 spreads."""
        shares, basis = flight_shares(table)
        if basis != self.basis:
            return {"basis": basis, "note": f"baseline measured on {self.basis} shares, this log gives {basis}: not compared"}
        dev = self.deviation(shares)
        out = [int(i) + 1 for i in np.flatnonzero(np.abs(dev) > OUTLIER_SPREADS)]
        k_t = t_spreads_required(self.n_flights)
        res = {
            "basis": basis,
            "shares": [round(float(s), 4) for s in shares],
            "deviation_spreads": [round(float(d), 2) for d in dev],
            "rotors_beyond_3_spreads": out,
            # The same rule with Student's t for a baseline of n_flights (the 3 above assumes a known spread).
            "t_spreads_required": None if k_t is None else round(k_t, 2),
            "rotors_beyond_t_spreads": None if k_t is None else [int(i) + 1 for i in np.flatnonzero(np.abs(dev) > k_t)],
            "verdict": self.verdict(dev),
        }
        if self.cg_damage_separable is not None:
            res["cg_damage_separable"] = self.cg_damage_separable
        return res

    def imbalance_wording(self, rotor: str) -> str | None:
        """How a one-rotor fault verdict on this airframe is worded (``rotor`` as displayed, e.g. "M3 (PX4 rotor
        2)"): "imbalance near M3 (PX4 rotor 2): CG offset or damage" where a CG offset and damage were measured
        not to separate; None (name the fault as the model does) otherwise."""
        if self.cg_damage_separable is not False:
            return None
        return f"imbalance near {rotor}: CG offset or damage"

    def verdict(self, dev: np.ndarray) -> str:
        """What the shares alone can say. A rotor that works harder than this airframe's healthy
        flights is an *imbalance* near it: a damaged propeller and a CG offset toward that rotor
        (a mass near it) move the shares alike, and on the real CrazyPAD flights no share, activity,
        vibration, response-gain or command-coupling evidence told them apart (offline/crazypad/README.md), so
        both are named."""
        k = int(np.argmax(dev))
        if dev[k] <= OUTLIER_SPREADS:
            return f"no rotor beyond {OUTLIER_SPREADS:g} spreads of this airframe's healthy flights"
        return f"imbalance near {self.motor_names[k]}: CG offset or damage"

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict, origin: str = "") -> HealthyBaseline:
        try:
            act = d["activity"]
            return cls(
                basis=str(d["basis"]),
                shares_mean=tuple(map(float, d["shares_mean"])),
                shares_std=tuple(map(float, d["shares_std"])),
                noise_std=tuple(map(float, d["noise_std"])),
                activity=None if act is None else tuple(map(float, act)),
                rate_hz=float(d["rate_hz"]),
                n_flights=int(d["n_flights"]),
                files=tuple(map(str, d["files"])),
                motor_names=tuple(map(str, d["motor_names"])),
                # Absent in baselines written before it existed: not measured.
                cg_damage_separable=None if d.get("cg_damage_separable") is None else bool(d["cg_damage_separable"]),
                cg_damage_evidence=str(d.get("cg_damage_evidence", "")),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"{origin or 'baseline'}: malformed healthy baseline: {exc!r}") from exc

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_text(json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n", encoding="utf-8")
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path) -> HealthyBaseline:
        path = Path(path)
        try:
            return cls.from_dict(json.loads(path.read_text(encoding="utf-8")), str(path))
        except (OSError, json.JSONDecodeError) as exc:
            raise ConfigError(f"{path}: cannot read the healthy baseline: {exc}") from exc


# The classifier's own bar for a confident label (DecisionConfig.faulty_probability, docs/diagnose-json.md): the
# fusion adds no constant of its own beyond OUTLIER_SPREADS.
CLASSIFIER_CONFIDENT = 0.9


def fuse(deviation_spreads, label_probability, classifier_label: int, classifier_confident: bool) -> dict:
    """The verdict of an adapted airframe from its healthy baseline and the classifier together.

    ``deviation_spreads`` (4,) is ``HealthyBaseline.deviation`` of the flight; ``label_probability`` the
    classifier's 16 mean label probabilities. The baseline is a likelihood that is (nearly) zero or flat:
    a damaged propeller (or a CG offset toward it) makes its rotor work harder, so

    - rotors more than ``OUTLIER_SPREADS`` above this airframe's healthy share form the set B; when B is
      not empty the verdict is the non-empty subset of B the classifier finds most probable (for one rotor
      in B: that rotor, whatever the classifier said). ``confident`` when that subset holds at least
      ``CLASSIFIER_CONFIDENT`` of the probability of all subsets of B, else ``ambiguous``;
    - when no rotor is beyond it (a rotor far *below* its share is no single damaged propeller's signature
      on its own), the flight looks like this airframe's healthy flights: healthy, unless the classifier
      alone is confident (its label probability >= ``CLASSIFIER_CONFIDENT``), whose verdict then stands.

    Constants, none fitted on a fault flight: ``OUTLIER_SPREADS`` = 3, the Gaussian 3-sigma of the healthy
    flight-to-flight spread, fixed before any scoring (``propwatch adapt``'s own outlier rule). Checked on the
    CrazyPAD healthy calibration flights only, each against the baseline of the other 2-3 of its airframe
    (``bench/crazypad_fusion.py`` prints it): their largest deviation is 3.7 spreads on motor logs (5.2 on
    controller logs, baselines of 1-2 flights), so no lower k is supported by healthy data. On simulated flights
    only (``bench/crazypad_fusion_sim.py``, 4-flight baselines) k = 3 flags 6.5 % of healthy flights and names
    one-rotor cuts alike on all four rotors. ``CLASSIFIER_CONFIDENT`` is the classifier's own bar.
    Returns {"label", "faulty_propellers", "confidence", "rule"}.
    """
    dev = np.asarray(deviation_spreads, dtype=np.float64)
    p = np.asarray(label_probability, dtype=np.float64)
    if dev.shape != (4,) or p.shape != (16,):
        raise ValueError(f"fuse: need 4 deviations and 16 label probabilities, got {dev.shape} and {p.shape}")
    above = {int(i) + 1 for i in np.flatnonzero(dev > OUTLIER_SPREADS)}
    if above:
        cands = [lab for lab, rotors in LABEL_TABLE.items() if rotors and set(rotors) <= above]
        best = max(cands, key=lambda lab: p[lab - 1])
        mass = float(sum(p[lab - 1] for lab in cands))
        share = p[best - 1] / mass if mass > 0 else 1.0 / len(cands)
        conf = "confident" if len(cands) == 1 or share >= CLASSIFIER_CONFIDENT else "ambiguous"
        rule = f"baseline: PX4 rotor(s) {sorted(above)} beyond {OUTLIER_SPREADS:g} spreads" + (
            "" if len(cands) == 1 else f"; the classifier's most probable of their {len(cands)} sets"
        )
        return {"label": int(best), "faulty_propellers": list(LABEL_TABLE[best]), "confidence": conf, "rule": rule}
    if classifier_confident and classifier_label != 1:
        return {
            "label": int(classifier_label),
            "faulty_propellers": list(LABEL_TABLE[classifier_label]),
            "confidence": "confident",
            "rule": f"no rotor beyond {OUTLIER_SPREADS:g} spreads; the classifier is confident",
        }
    return {
        "label": 1,
        "faulty_propellers": [],
        "confidence": "confident",
        "rule": f"no rotor beyond {OUTLIER_SPREADS:g} spreads and the classifier is not confident of a fault: healthy",
    }


def cg_or_damage(label: int, motor_names) -> dict:
    """The verdict of an imbalance on an airframe whose flights do not tell a CG offset from damage.

    ``label`` is the fused verdict's (a set of rotors working harder than healthy). Measured on the CrazyPAD
    flights (``offline/crazypad/README.md``): masses near M3 and cut M3 propellers move shares, command
    activity, vibration and the response gain alike, so neither cause is named: no propeller is called
    faulty (label 1, ``faulty_propellers`` empty, confidence ``ambiguous``), the rotors are an imbalance, and
    ``hypotheses`` holds both explanations (damaged propellers on them; intact propellers with the CG moved
    toward them). Returns the verdict's new fields and the hypotheses.
    """
    rotors = list(LABEL_TABLE[label])
    if not rotors:
        raise ValueError("cg_or_damage: a healthy label is no imbalance")
    names = [str(motor_names[i - 1]) for i in rotors]
    where = " + ".join(names)
    return {
        "label": 1,
        "faulty_propellers": [],
        "faulty_names": [],
        "confidence": "ambiguous",
        "imbalance_rotors": rotors,
        "imbalance_names": names,
        "hypotheses": [
            {"faulty_propellers": rotors, "cause": f"damaged propeller on {where}"},
            {"faulty_propellers": [], "cause": f"CG offset toward {where} (a mass near it), propellers intact"},
        ],
    }


def baseline_from_tables(
    tables: list[FlightTable],
    files: list[str],
    activity: np.ndarray | None = None,
    cg_damage_separable: bool | None = None,
    cg_damage_evidence: str = "",
) -> HealthyBaseline:
    """The baseline of flights already checked as healthy (``offline.adapt.checks``)."""
    per = [flight_shares(t) for t in tables]
    bases = {b for _, b in per}
    if len(bases) != 1:
        raise ConfigError(f"healthy logs mix share bases {sorted(bases)}: give logs of one kind")
    basis = bases.pop()
    sh = np.array([s for s, _ in per])
    std = sh.std(axis=0, ddof=1) if len(sh) > 1 else np.zeros(4)
    noise = np.mean([share_noise(t) for t in tables], axis=0)
    return HealthyBaseline(
        basis=basis,
        shares_mean=tuple(map(float, sh.mean(axis=0))),
        shares_std=tuple(map(float, std)),
        noise_std=tuple(map(float, noise)),
        activity=None if activity is None else tuple(map(float, activity)),
        rate_hz=float(tables[0].rate_hz),
        n_flights=len(tables),
        files=tuple(files),
        motor_names=tuple(tables[0].motor_names),
        cg_damage_separable=cg_damage_separable,
        cg_damage_evidence=cg_damage_evidence,
    )
