"""The CrazyPAD copy in ../shared/data/crazypad: its manifest, conditions and our split.

Only the manifest is parsed here; flight logs are read by the project's one
CrazyPAD reader (``monitor.logs``, ``--format crazypad``).

Two Crazyflies flew the data set: the radio addresses E7E7E7E7E8 and ..E9 in
the upstream flight script (``src/log_to_flash/collect_data.py``) are the
``E8_``/``E9_`` file prefixes. Their healthy flights differ (README table and
``propwatch crazypad analyse``), so each airframe is calibrated on its own.

The split, fixed by rule so nothing is chosen by looking at results:
- ``calibration``: healthy motor logs with an even log number (per airframe);
- ``holdout``: the other healthy motor logs (odd numbers), never fitted;
- ``evaluation``: every non-healthy log. Fault magnitudes in the simulation come
  from physics ranges, not from these flights, so none of them is tuned on.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

from monitor.errors import LogFormatError
from monitor.vehicle import REPO_ROOT

DEFAULT_ROOT = REPO_ROOT.parent / "shared" / "data" / "crazypad"
INTACT_SPAN_MM = 47.0  # tip-to-tip span of an intact Crazyflie propeller (data set README)
AIRFRAMES = ("E8", "E9")

# Depth bins for the report, by total span removed (both blades), mm.
DEPTH_BINS: tuple[tuple[str, float, float], ...] = (
    ("cut <=1 mm", 0.0, 1.0),
    ("cut 1.5-2.5 mm", 1.5, 2.5),
    ("cut 3-4.5 mm", 3.0, 4.5),
    ("cut 5-8 mm", 5.0, 8.0),
)


@dataclass(frozen=True)
class CrazypadFlight:
    file: str  # relative to the data root
    log_type: str  # "motor" or "controller": the folder, i.e. the flight's group
    log_config: str  # what the file really holds: "motor", "motor_no_yaw" or "controller"
    condition: str
    fault_kind: str
    faulty: tuple[bool, bool, bool, bool]  # Bitcraze M1..M4
    airframe: str  # "E8" or "E9"
    log_number: int

    @property
    def cut_total_mm(self) -> float | None:
        return cut_total_mm(self.condition) if self.fault_kind == "propeller_cut" else None

    @property
    def has_motor_commands(self) -> bool:
        return self.log_config.startswith("motor")

    @property
    def role(self) -> str:
        if self.fault_kind != "healthy":
            return "evaluation"
        return "calibration" if self.log_number % 2 == 0 else "holdout"

    @property
    def group(self) -> str:
        """The row of the report this flight belongs to."""
        if self.fault_kind == "propeller_cut":
            mm = self.cut_total_mm
            for name, lo, hi in DEPTH_BINS:
                if lo - 1e-9 <= mm <= hi + 1e-9:
                    return name
            raise LogFormatError(f"{self.file}: cut of {mm} mm is outside the report's bins")
        if self.fault_kind == "tape_on_propeller":
            return "tape M3+M4" if self.faulty[3] else "tape M3"
        if self.fault_kind == "added_mass_near_motor":
            return "mass " + self.condition.split("add_weight_")[1].replace("_near_", " near ").replace("_", "+")
        if self.fault_kind == "hanging_mass_on_string":
            return "string " + self.condition.split("weight_on_string_")[1].replace("_near_", " near ")
        return "healthy"


_MM = r"(\d+(?:\.\d+)?)mm"


def cut_total_mm(condition: str) -> float:
    """Span removed from an M3 propeller (both blades, mm) from CrazyPAD's folder name.

    ``cut_propeller_M3_Xmm`` (older names): total length reduction X.
    ``cut_propeller_M3_a_b_span`` / ``..._a_span``: 47 - span.
    ``cut_m3_a_b``: a + b from each blade.
    """
    name = condition.replace("мм", "mm")
    nums = [float(x) for x in re.findall(_MM, name)]
    if not nums:
        raise LogFormatError(f"condition {condition!r}: no cut length in the name")
    if name.startswith("cut_m3_"):
        return sum(nums)
    if len(nums) == 1:
        return nums[0]
    return round(INTACT_SPAN_MM - nums[-1], 3)


def load_manifest(root: str | Path = DEFAULT_ROOT) -> list[CrazypadFlight]:
    """Every flight the manifest lists, in manifest order."""
    path = Path(root) / "manifest.csv"
    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read the CrazyPAD manifest: {exc.strerror or exc}") from exc
    flights = []
    for i, r in enumerate(rows):
        try:
            stem = Path(r["file"]).name.split(".")[0]  # E8_log03
            airframe, num = stem.split("_log")
            flights.append(
                CrazypadFlight(
                    file=r["file"],
                    log_type=r["log_type"],
                    log_config=r["log_config"],
                    condition=r["condition"],
                    fault_kind=r["fault_kind"],
                    faulty=tuple(r[f"M{k}_faulty"] == "1" for k in range(1, 5)),
                    airframe=airframe,
                    log_number=int(num),
                )
            )
        except (KeyError, ValueError) as exc:
            raise LogFormatError(f"{path}: row {i + 2}: {exc}") from exc
    return flights


def select(
    flights: list[CrazypadFlight], *, role: str | None = None, airframe: str | None = None, motor_only: bool = True
) -> list[CrazypadFlight]:
    out = [f for f in flights if (role is None or f.role == role) and (airframe is None or f.airframe == airframe)]
    return [f for f in out if f.has_motor_commands] if motor_only else out
