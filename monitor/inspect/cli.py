"""propwatch inspect LOG [--json] [--csv DIR]: what propwatch read from a log.

Per message (tlog, DataFlash) or topic (ULog): count, mean rate, time span,
the longest gap and the number of gaps (an interval over 5x the median and
0.2 s). The parameters that decide how motors are read (PWM min/max, output
functions = motor mapping, frame / vehicle type), the motor command range per
rotor (vehicle's name beside its PX4 number), and the 20 Hz grid diagnose uses.

--csv DIR writes LOG.signals.csv (the resampled signals) and
LOG.features.csv (exactly the features diagnose feeds the model, with
window_end = 1 at the last step of every window it classifies). Times are
seconds on the autopilot's boot clock (tlog: the ground station's receive clock).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from monitor.diagnose.engine import round_floats


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="propwatch inspect", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("log", metavar="LOG", help=".tlog, .ulg, DataFlash .bin, or CSV (with --format)")
    p.add_argument("--format", dest="fmt", default=None, help="log format or CSV mapping name, as for diagnose")
    p.add_argument("--model", default=None, help="classifier whose features --csv writes (default: as diagnose)")
    p.add_argument("--vehicle", default=None, help="vehicle YAML for the ESC curve (default: as diagnose)")
    p.add_argument("--hop", type=int, default=20, help="window hop marked in --csv, as diagnose's --hop (default 20)")
    p.add_argument("--json", action="store_true", help="print JSON to stdout")
    p.add_argument("--csv", metavar="DIR", default=None, help="write the resampled signals and model features as CSV into DIR")
    return p.parse_args(argv)


def format_text(info: dict) -> str:
    lines = [f"== {info['log']} ({info['format']})", f"vehicle type: {info['vehicle_type'] or 'not logged'}"]
    m = info["motors"]
    lines.append(f"motors ({m['cmd_unit']}), vehicle name beside PX4 rotor number:")
    for i, name in enumerate(m["names"]):
        rng = f"{m['cmd_min'][i]:g}..{m['cmd_max'][i]:g}" if m["cmd_min"] else "not logged"
        air = f", airborne mean {m['airborne_cmd_mean'][i]:.0f}" if m["airborne_cmd_mean"] else ""
        lines.append(f"  {name} (PX4 rotor {i + 1}): command {rng}{air}")
    if info["parameters"]:
        lines.append("parameters: " + ", ".join(f"{k}={v:g}" for k, v in info["parameters"].items()))
    g = info["grid"]
    lines.append(
        f"grid: {g['steps']} steps at {g['rate_hz']:g} Hz ({g['start_boot_s']:.1f}-{g['stop_boot_s']:.1f} s), "
        f"{g['airborne_steps']} airborne"
    )
    w = max([len(s["name"]) for s in info["messages"]] + [7])
    lines.append(f"{'message':<{w}} {'count':>8} {'rate Hz':>8} {'first s':>10} {'last s':>10} {'max gap s':>9} {'gaps':>5}")
    for s in info["messages"]:
        first = f"{s['first_s']:.1f}" if s["first_s"] is not None else "-"
        last = f"{s['last_s']:.1f}" if s["last_s"] is not None else "-"
        lines.append(
            f"{s['name']:<{w}} {s['count']:>8} {s['rate_hz']:>8.1f} {first:>10} {last:>10} {s['max_gap_s']:>9.2f} {s['gaps']:>5}"
        )
    lines += [f"warning: {w}" for w in info["warnings"]]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from monitor.diagnose.engine import default_model
    from monitor.inspect.log import inspect_log, write_csv
    from monitor.logs import read_log
    from monitor.model import Classifier, choose_esc

    clf = Classifier(args.model or default_model(args.vehicle))
    esc = choose_esc(clf, args.vehicle or "")
    table = read_log(args.log, fmt=args.fmt, esc=esc, rate_hz=clf.info.sample_rate_hz, extras=False)
    info = inspect_log(args.log, args.fmt, table)
    if args.csv:
        for path in write_csv(Path(args.csv), table, clf.info.features, clf.info.window, args.hop):
            print(f"wrote {path}", file=sys.stderr)
    if args.json:
        json.dump(round_floats(info), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(format_text(info))
    return 0


if __name__ == "__main__":
    sys.exit(main())
