"""Which evidence tells a CG offset near M3 from a damaged M3 propeller on real CrazyPAD flights?

    nice python -m bench.crazypad_separation [--root ../shared/data/crazypad] [--json out.json]

Reads every CrazyPAD flight at 100 Hz (motor logs with logged commands; controller logs
with commands rebuilt by the firmware mixer), prints the effect size of each condition
against its airframe's healthy flights, then, per metric, how well one threshold separates
CG-offset flights (masses taped or hung near M3) from damage (cuts >= 3 mm, tape).
About 1-2 minutes on one core.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from offline.crazypad.data import DEFAULT_ROOT, load_manifest  # noqa: E402
from offline.crazypad.evidence import effect_sizes, flight_evidence, separation  # noqa: E402

SHOWN = (
    "share_M1",
    "share_M2",
    "share_M3",
    "share_M4",
    "activity_M3_over_others",
    "activity_mean",
    "vibration_log10",
    "response_gain_M3",
    "response_gain_M1",
    "coupling_YT",
    "coupling_RP",
)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=DEFAULT_ROOT)
    ap.add_argument("--json", type=Path, default=None, help="write every figure here")
    args = ap.parse_args(argv)
    evidence = [flight_evidence(f, args.root) for f in load_manifest(args.root)]
    rows, sep = effect_sizes(evidence), separation(evidence)
    print("effect size vs healthy of the same airframe and log config, (mean - healthy) / healthy std")
    print(f"{'config':10s} {'af':3s} {'group':22s} {'n':>3s} " + " ".join(f"{s[:14]:>14s}" for s in SHOWN))
    for r in rows:
        print(
            f"{r['config']:10s} {r['airframe']:3s} {r['group']:22s} {r['n']:3d} "
            + " ".join(f"{r['effect'][s]:14.1f}" for s in SHOWN)
        )
    print("\nCG offset (masses) vs damage (cuts >= 3 mm, tape), relative to healthy; overlap = misplaced by the best threshold")
    for s in sep:
        print(
            f"{s['config']:10s} {s['airframe']:3s} {s['metric']:24s} cg {s['cg_offset_mean']:+9.4f} (n={s['n_cg_offset']:2d})"
            f"  damage {s['damage_mean']:+9.4f} (n={s['n_damage']:2d})  d={s['d']:+6.2f}  overlap={s['overlap']}"
        )
    if args.json:
        args.json.write_text(json.dumps({"effects": rows, "separation": sep}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
