"""A vehicle's history that cannot be lost, forked or poisoned (monitor.memory.store, baseline, atomic, cli).

Each case as an attacker or a fault would try it: docs/SECURITY.md's table names these tests.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from monitor.memory import atomic, store
from monitor.memory.baseline import BaselineError, BaselineNewerError, VehicleBaseline
from monitor.memory.cli import main as baseline_main
from monitor.memory.store import StateDir, StateDirBusy, StateDirError
from monitor.memory.summary import FlightSummary, ShareAccumulator

RATE_HZ = 20.0
KEY = "sysid-1"
ROOT = Path(__file__).resolve().parents[1]


def summary(k: int, seconds: float = 40.0) -> FlightSummary:
    rng = np.random.default_rng(k)
    n = int(seconds * RATE_HZ)
    share = np.array([1.03, 0.97, 0.95, 1.05]) * (1 + 0.003 * rng.standard_normal(4))
    x = 36.0 * share * (1 + 0.01 * rng.standard_normal((n, 4)))
    acc = ShareAccumulator("omega2", RATE_HZ)
    acc.table(x, 0.01 * rng.standard_normal(n), 0.01 * rng.standard_normal(n), np.ones(n, dtype=bool))
    return acc.summary


def baseline(flights: int = 3) -> VehicleBaseline:
    b = VehicleBaseline(KEY, "daemon", ("1", "2", "3", "4"), "omega2")
    for k in range(flights):
        b.add(f"flight {k + 1}", "2026-05-01", summary(k), "no fault")
    return b


def add_flight(b: VehicleBaseline | None) -> VehicleBaseline:
    b = b or VehicleBaseline(KEY, "daemon", ("1", "2", "3", "4"), "omega2")
    b.add(f"flight {len(b.flights) + 1}", None, summary(len(b.flights)), "no fault")
    return b


@pytest.fixture
def state(tmp_path):
    sd = StateDir.open(tmp_path / "state")
    sd.update(KEY, lambda _: baseline())
    yield sd
    sd.close()


# -- 1. history is never destroyed --------------------------------------------------------------------------------


def _truncated(p: Path):
    p.write_bytes(p.read_bytes()[:300])


def _garbage(p: Path):
    p.write_bytes(os.urandom(2000))


def _newer(p: Path):
    d = json.loads(p.read_text())
    d["version"] = 99
    p.write_text(json.dumps(d))


def _no_steps(p: Path):
    d = json.loads(p.read_text())
    for f in d["flights"]:
        f["summary"]["n"] = 0
    p.write_text(json.dumps(d))


@pytest.mark.parametrize("damage", [_truncated, _garbage, _newer, _no_steps])
def test_a_baseline_that_cannot_be_read_is_kept_as_it_is_and_never_replaced(state, damage):
    p = state.path(KEY)
    damage(p)
    before = p.read_bytes()
    with pytest.raises(BaselineError) as err:
        state.update(KEY, add_flight)
    assert "\n" not in str(err.value) and str(p) in str(err.value)
    if damage is _newer:
        assert isinstance(err.value, BaselineNewerError) and "version 99 is newer" in str(err.value)
    assert p.read_bytes() == before
    assert sorted(os.listdir(p.parent)) == ["baseline.json"]


def test_reset_moves_the_baseline_aside_dated_and_says_where(state, capsys):
    p = state.path(KEY)
    _newer(p)
    before = p.read_bytes()
    assert baseline_main(["reset", "--state-dir", str(state.root), "--vehicle", KEY]) == 0
    out = capsys.readouterr().out
    moved = [q for q in p.parent.iterdir() if q.name.startswith("baseline.json.reset-")]
    assert len(moved) == 1 and moved[0].read_bytes() == before and str(moved[0]) in out
    assert not p.exists()
    assert len(state.update(KEY, add_flight).flights) == 1  # the history starts again
    # a second reset the same second keeps both
    moved2 = state.reset(KEY)
    assert moved2.exists() and moved2 != moved[0]
    assert baseline_main(["reset", "--state-dir", str(state.root), "--vehicle", "sysid-9"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no baseline of vehicle sysid-9" in err and KEY in err


def test_the_daemon_survives_a_baseline_whose_flights_have_no_steps(tmp_path):
    from monitor.daemon.memory_adapter import VehicleMemory

    sd = StateDir.open(tmp_path)
    sd.update(KEY, lambda _: baseline())
    _no_steps(sd.path(KEY))
    mem = VehicleMemory(tmp_path, RATE_HZ)
    mem.identify(sysid=1)  # a ValueError traceback here was a crash loop under Restart=on-failure
    assert "flights[0].summary.n" in mem.status() and "\n" not in mem.status()


# -- 2. every loaded value is validated ---------------------------------------------------------------------------


def _set(path: str, value):
    def change(d):
        *head, last = path.split(".")
        for k in head:
            d = d[int(k)] if k.isdigit() else d[k]
        if last.isdigit():
            d[int(last)] = value
        else:
            d[last] = value

    return change


IMPOSSIBLE = [
    ("flights.0.summary.n", 0, "flights[0].summary.n"),
    ("flights.0.summary.n", 10**30, "field n"),
    ("flights.0.summary.n", True, "flights[0].summary.n"),
    ("flights.0.summary.sum_share.1", 1e300, "sum_share"),
    ("flights.0.summary.sum_share.1", -5.0, "sum_share"),
    ("flights.0.summary.rate_hz", 0, "rate_hz"),
    ("flights.0.summary.n_blocks", 10**6, "n_blocks"),
    ("flights.0.summary.ftf.1.1", -1.0, "ftf"),
    ("flights.0.summary.ftf.0.1", 1e6, "ftf"),
    ("flights.0.summary.ftf.1.2", 1e4, "ftf"),
    ("flights.0.summary.fts.1.2", 1e9, "fts"),
    ("flights.0.summary.sum_collective", -1.0, "sum_collective"),
    ("flights.0.summary.sum_block.0", 1e300, "sum_block"),
    ("flights.0.summary.sum_block_outer.0.0", 1e6, "sum_block_outer"),
    ("flights.0.summary.basis", "command", "flights[0].summary.basis"),
    ("flights.0.epoch", 5, "flights[0].epoch"),
    ("flights.0.date", "yesterday", "flights[0].date"),
    ("flights.0.source", "trust me", "flights[0].source"),
    ("flights.1", "x", "flights[1]"),
    ("epoch", -1, "field epoch"),
    ("vehicle.motor_names", ["1", "2", "3"], "vehicle.motor_names"),
    ("vehicle.cg_damage_separable", "no", "vehicle.cg_damage_separable"),
    ("events", [{"event": "washed", "date": None, "epoch": 0}], "events[0].event"),
    ("version", "1", "field version"),
]


@pytest.mark.parametrize("where,value,named", IMPOSSIBLE, ids=[f"{w}={v!r}"[:40] for w, v, _ in IMPOSSIBLE])
def test_an_impossible_value_is_refused_in_one_line_naming_the_field(tmp_path, capsys, where, value, named):
    d = baseline().to_dict()
    _set(where, value)(d)
    p = tmp_path / "B.json"
    p.write_text(json.dumps(d))
    with pytest.raises(BaselineError) as err:
        VehicleBaseline.load(p)
    assert named in str(err.value) and "\n" not in str(err.value), str(err.value)
    assert baseline_main(["show", str(p)]) == 2
    e = capsys.readouterr().err
    assert e.count("\n") == 1 and named in e and "Traceback" not in e


@pytest.mark.parametrize("field", ["ftf", "sum_block_outer"])
def test_sums_that_are_not_scatters_are_refused(tmp_path, field):
    # symmetric, every entry within its bounds, yet no set of steps or blocks sums to it (not positive semi-definite)
    d = baseline().to_dict()
    m = np.asarray(d["flights"][0]["summary"][field])
    a, b = (1, 2) if field == "ftf" else (0, 1)
    m[a, b] = m[b, a] = -1.5 * np.sqrt(m[a, a] * m[b, b]) - 1e-3
    d["flights"][0]["summary"][field] = m.tolist()
    (tmp_path / "B.json").write_text(json.dumps(d))
    with pytest.raises(BaselineError, match=rf"field {field}:"):
        VehicleBaseline.load(tmp_path / "B.json")


def test_non_numbers_and_nesting_bombs_are_refused_in_one_line(tmp_path):
    text = baseline().to_text().replace('"sum_share": [', '"sum_share": [NaN, ', 1)
    for name, body in (("nan.json", text), ("deep.json", "[" * 200_000), ("inf.json", text.replace("NaN", "1e999"))):
        (tmp_path / name).write_text(body)
        with pytest.raises(BaselineError) as err:
            VehicleBaseline.load(tmp_path / name)
        assert "\n" not in str(err.value) and name in str(err.value)


def test_every_summary_a_flight_can_produce_passes_the_check():
    # The bounds are what the accumulator can produce: random flights at the edges (zero rotors, tilts at +-pi,
    # landings, non-finite steps) always pass, and survive a round trip through JSON.
    rng = np.random.default_rng(7)
    for k in range(40):
        n = int(rng.integers(1, 2000))
        x = rng.uniform(0, 100, (n, 4)) * (rng.uniform(size=(n, 4)) > 0.1)
        x[rng.uniform(size=n) < 0.02] = np.nan
        tilt = rng.uniform(-np.pi, np.pi, (2, n)) * (rng.uniform(size=(2, n)) < 0.5)
        air = rng.uniform(size=n) > 0.05
        acc = ShareAccumulator("omega2" if k % 2 else "command", float(rng.choice([10.0, 20.0, 50.0, 400.0])))
        acc.table(x, tilt[0], tilt[1], air)
        s = acc.summary
        s.check(f"random flight {k}")
        FlightSummary.from_dict(json.loads(json.dumps(s.to_dict())), f"random flight {k}")


def test_a_sum_share_of_1e300_is_never_evidence(state):
    p = state.path(KEY)
    d = json.loads(p.read_text())
    d["flights"][0]["summary"]["sum_share"][0] = 1e300
    p.write_text(json.dumps(d))
    with pytest.raises(BaselineError, match=r"flights\[0\].*sum_share"):
        state.load(KEY)


# -- 3. the state dir is owned, not trusted -----------------------------------------------------------------------


def test_the_state_dir_and_what_is_under_it_are_made_private(tmp_path):
    sd = StateDir.open(tmp_path / "var" / "state")
    sd.update(KEY, lambda _: baseline())
    mode = lambda p: os.stat(p).st_mode & 0o777  # noqa: E731
    assert mode(sd.root) == 0o700
    assert mode(sd.root / "vehicles") == 0o700 and mode(sd.path(KEY).parent) == 0o700
    assert mode(sd.path(KEY)) == 0o600
    unit = (ROOT / "deploy" / "propwatch-monitor.service").read_text()
    assert "\nStateDirectoryMode=0700\n" in unit


@pytest.mark.parametrize("bits", [0o020, 0o002])
def test_a_state_dir_others_can_write_is_refused(tmp_path, bits):
    root = tmp_path / "state"
    root.mkdir(mode=0o700)
    os.chmod(root, 0o700 | bits)
    with pytest.raises(StateDirError, match="writable by its group or others"):
        StateDir.open(root)
    os.chmod(root, 0o700)
    sd = StateDir.open(root)
    os.chmod(sd.root, 0o700)
    sd.update(KEY, lambda _: baseline())
    os.chmod(sd.path(KEY).parent, 0o700 | bits)  # a vehicle's directory too
    with pytest.raises(StateDirError, match="writable by its group or others"):
        sd.load(KEY)


def test_a_state_dir_of_another_user_is_refused(tmp_path, monkeypatch):
    root = tmp_path / "state"
    root.mkdir(mode=0o700)
    monkeypatch.setattr(os, "geteuid", lambda: os.stat(root).st_uid + 1)
    with pytest.raises(StateDirError, match=r"owned by uid \d+, not by this user"):
        StateDir.open(root)


def test_a_vehicle_directory_that_is_a_link_is_not_followed(tmp_path):
    sd = StateDir.open(tmp_path / "state")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir(mode=0o700)
    (sd.root / "vehicles").mkdir(mode=0o700)
    (sd.root / "vehicles" / KEY).symlink_to(elsewhere)
    with pytest.raises(StateDirError, match="symbolic link"):
        sd.update(KEY, add_flight)
    assert list(elsewhere.iterdir()) == []
    (sd.root / "vehicles" / KEY).unlink()
    (sd.root / "vehicles").rmdir()
    (sd.root / "vehicles").symlink_to(elsewhere)
    with pytest.raises(StateDirError, match="symbolic link"):
        sd.update(KEY, add_flight)
    assert list(elsewhere.iterdir()) == []


def test_a_baseline_that_is_a_link_is_not_read_or_written_through(state, tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("precious\n")
    p = state.path(KEY)
    p.unlink()
    p.symlink_to(victim)
    with pytest.raises(StateDirError, match="symbolic link"):
        state.load(KEY)
    with pytest.raises(StateDirError, match="symbolic link"):
        state.update(KEY, add_flight)
    assert victim.read_text() == "precious\n" and p.is_symlink()


def test_links_planted_at_temporary_names_are_never_written_through(state, tmp_path, monkeypatch):
    victim = tmp_path / "victim"
    victim.write_text("precious\n")
    p = state.path(KEY)
    planted = [f".baseline.json.{pid}.tmp" for pid in range(os.getpid() - 2, os.getpid() + 3)]
    for name in planted:
        (p.parent / name).symlink_to(victim)
    state.update(KEY, add_flight)  # fresh random names: not caught by a planted link
    assert victim.read_text() == "precious\n" and not p.is_symlink() and len(VehicleBaseline.load(p).flights) == 4
    # even a name guessed right: exclusive creation fails rather than follow the link
    monkeypatch.setattr(atomic, "temporary_name", lambda name: planted[0])
    with pytest.raises(FileExistsError):
        state.update(KEY, add_flight)
    assert victim.read_text() == "precious\n" and len(VehicleBaseline.load(p).flights) == 4
    monkeypatch.undo()
    # stale temporary files (and links) are removed when the daemon takes the state dir; their targets stay
    (p.parent / ".baseline.json.999999.tmp").write_text("half a file")
    removed = state.hold()
    assert sorted(removed) == sorted(f"vehicles/{KEY}/{n}" for n in [*planted, ".baseline.json.999999.tmp"])
    assert sorted(os.listdir(p.parent)) == ["baseline.json"] and victim.read_text() == "precious\n"


def test_a_disk_full_mid_write_leaves_the_old_file_and_no_temporary(state, monkeypatch):
    p = state.path(KEY)
    before = p.read_bytes()
    real_write = os.write

    def full(fd, data):
        real_write(fd, bytes(data[:100]))
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(atomic.os, "write", full)
    with pytest.raises(OSError) as err:
        state.update(KEY, add_flight)
    assert err.value.errno == errno.ENOSPC
    assert p.read_bytes() == before and sorted(os.listdir(p.parent)) == ["baseline.json"]


# -- 4. one writer ------------------------------------------------------------------------------------------------


def _python(code: str, **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], env=env, text=True, **kw)


def _holder(code: str) -> subprocess.Popen:
    """A process that runs ``code`` (taking the state dir's lock), prints 'held' and waits; the line is read here."""
    p = _python(code + '\nprint("held", flush=True)\nsys.stdin.read()\n', stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    assert p.stdout.readline().strip() == "held"
    return p


def _refused_by(root: Path) -> StateDirBusy:
    with StateDir.open(root) as sd, pytest.raises(StateDirBusy) as err:
        sd.hold()
    return err.value


def test_a_second_holder_is_refused_naming_the_first_and_a_killed_holder_frees_it(tmp_path):
    root = tmp_path / "state"
    holder = _holder(f"import sys\nfrom monitor.memory.store import StateDir\nStateDir.open({str(root)!r}).hold()")
    try:
        err = _refused_by(root)
        assert err.pid == holder.pid and f"pid {holder.pid}" in str(err)
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait(timeout=30)
    with StateDir.open(root) as sd:  # the kernel released the lock of the killed holder
        assert sd.hold() == []


def test_a_holder_that_has_not_yet_written_its_pid_is_still_named(tmp_path):
    # Two daemons started at once: the loser can read the lock file between the winner's lock and its pid, and find
    # the previous holder's pid there (gone) or none. It reads again until the pid is a live process.
    root = tmp_path / "state"
    StateDir.open(root).close()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (root / "daemon.lock").write_text(f"{dead.pid}\n")
    lock = str(root / "daemon.lock")
    late = _holder(
        f"import fcntl, os, sys, threading, time\nfd = os.open({lock!r}, os.O_RDWR)\nfcntl.flock(fd, fcntl.LOCK_EX)\n"
        "threading.Timer(0.2, lambda: (os.ftruncate(fd, 0), os.pwrite(fd, f'{os.getpid()}\\n'.encode(), 0))).start()"  # the pid 0.2 s late
    )
    try:
        assert _refused_by(root).pid == late.pid
    finally:
        late.kill()
        late.wait(timeout=30)


def test_two_writers_at_once_lose_no_flight(tmp_path):
    root = tmp_path / "state"
    StateDir.open(root).close()
    each = 12
    code = f"""
        import sys
        sys.path.insert(0, {str(ROOT / "tests")!r})
        from test_security_memory import add_flight
        from monitor.memory.store import StateDir
        sd = StateDir.open({str(root)!r})
        print("ready", flush=True)
        sys.stdin.readline()
        for _ in range({each}):
            sd.update("{KEY}", add_flight)
        """
    procs = [_python(code, stdin=subprocess.PIPE, stdout=subprocess.PIPE) for _ in range(2)]
    for p in procs:
        assert p.stdout.readline().strip() == "ready"
    for p in procs:
        p.stdin.write("go\n")
        p.stdin.flush()
    for p in procs:
        assert p.wait(timeout=120) == 0
    with StateDir.open(root) as sd:
        assert len(sd.load(KEY).flights) == 2 * each


def test_baseline_note_and_learn_into_a_state_dir_take_the_write_lock(state, capsys, monkeypatch):
    p = state.path(KEY)
    monkeypatch.setattr(store, "WRITE_LOCK_WAIT_S", 0.2)
    with state.writing():
        assert baseline_main(["note", str(p), "--event", "inspected"]) == 2
    err = capsys.readouterr().err
    assert f"pid {os.getpid()}" in err and err.count("\n") == 1
    assert VehicleBaseline.load(p).events == []
    assert baseline_main(["note", str(p), "--event", "props-replaced", "--date", "2026-05-09"]) == 0
    assert "restarts" in capsys.readouterr().out
    assert VehicleBaseline.load(p).events == [{"event": "props-replaced", "date": "2026-05-09", "epoch": 1}]
    # learn never replaces a state dir's history: reset it first
    from monitor.memory.cli import _learnt, _write

    with pytest.raises(BaselineError, match="already holds this vehicle's history.*baseline reset"):
        _write(p, _learnt(baseline(), p), plain_old=False)
    assert len(VehicleBaseline.load(p).flights) == 3 and VehicleBaseline.load(p).epoch == 1


def _normal_one_summary_at_a_time(summaries):
    """The normal as docs/VEHICLE_MEMORY.md states it, each flight's terms from its own summary (the reference)."""
    from monitor.memory import thresholds as th
    from monitor.memory.normal import TILT_RIDGE_RAD2

    w = sum(s.ftf[1:, 1:] - np.outer(s.ftf[0, 1:], s.ftf[0, 1:]) / s.n for s in summaries)
    v = sum(s.fts[1:] - np.outer(s.ftf[0, 1:], s.fts[0]) / s.n for s in summaries)
    slopes = np.linalg.solve(w + TILT_RIDGE_RAD2 * sum(s.n for s in summaries) * np.eye(2), v)
    c = np.array([s.mean_share() - s.mean_regime()[1:] @ slopes for s in summaries])
    m = len(c)
    cov = (th.PRIOR_FLIGHTS * np.asarray(th.PRIOR_COV) + (m - 1) * np.cov(c.T, ddof=1)) / (th.PRIOR_FLIGHTS + m - 1)
    within = np.mean([s.within_cov() for s in summaries if s.within_cov() is not None], axis=0)
    return c.mean(axis=0), slopes, cov, within


def test_leave_one_out_normals_are_the_normals_of_the_other_flights():
    # set_aside_outliers judges every flight against the others at each landing: from one stack (linear in flights;
    # a normal per flight from its summaries was quadratic: 7.9 s of CPU at 400 flights, past the unit's watchdog
    # near 500), and the same normals.
    from monitor.memory.normal import FlightStack

    flights = [summary(k, seconds=5.0 + 3 * k) for k in range(12)]
    stack = FlightStack.of(flights)
    for i in (0, 5, 11):
        keep = np.arange(len(flights)) != i
        got = stack.normal(keep)
        want = _normal_one_summary_at_a_time([f for j, f in enumerate(flights) if j != i])
        for a, b in zip((got.intercept, got.slopes, got.cov, got.within_block_cov), want):
            np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-15)
        assert got.n_flights == 11
