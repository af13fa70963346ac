"""Run the onboard monitor on a recorded .tlog, as fast as it reads, and collect what it would have announced.

    python examples/monitor_tlog.py FLIGHT.tlog

The daemon of ``propwatch monitor`` in its file mode (``--connect FILE.tlog``): the same loop that runs beside
PX4, fed from the log instead of a link. Alerts go to an events file (one JSON line each) and its counters to a
report; vehicle memory is off (``--state-dir ''``), so nothing is written outside ``out_dir``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from monitor.cli import main as propwatch


def run(tlog: str | Path, out_dir: str | Path = "out/example-monitor") -> dict:
    """``{"report": the daemon's counters, "events": its alert lines}`` for one replayed flight."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    events, report = out / "events.jsonl", out / "report.json"
    events.unlink(missing_ok=True)
    argv = ["monitor", "--connect", str(tlog), "--tlog-speed", "0", "--state-dir", ""]
    argv += ["--events", str(events), "--report", str(report), "--log-level", "WARNING"]
    code = propwatch(argv)
    if code != 0:
        raise RuntimeError(f"propwatch monitor exited {code} on {tlog}")
    result = {
        "report": json.loads(report.read_text()),
        "events": [json.loads(line) for line in events.read_text().splitlines()] if events.exists() else [],
    }
    print(f"{tlog}: {result['report']['messages']} messages, {result['report']['alerts']} alerts")
    for e in result["events"]:
        print(f"  {e}")
    return result


if __name__ == "__main__":
    run(sys.argv[1])
