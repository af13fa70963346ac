"""The state dir: each vehicle's baseline, owned by one writer, never followed through a link.

Layout: ``STATE_DIR/vehicles/<vehicle key>/baseline.json`` (``monitor.memory.baseline``), ``STATE_DIR/daemon.lock``
(held by the daemon for its run; its pid inside) and ``STATE_DIR/write.lock`` (held for each read-modify-write of a
baseline, by the daemon and by ``propwatch baseline learn | note | reset``).

- **Owned, not trusted.** ``StateDir.open`` creates the directory 0700; one owned by another user or writable by
  group or others is refused (``StateDirError``: the daemon turns its memory off for the run and monitoring goes on).
  Below it every directory and file is opened relative to its parent's descriptor with ``O_NOFOLLOW``: a link is
  refused, never followed, and each directory is checked the same way.
- **One writer.** ``hold`` takes ``daemon.lock`` (``fcntl.flock``, released by the kernel when the holder dies, by
  SIGKILL too); a second daemon gets ``StateDirBusy`` naming the holder's pid. ``update`` reads, changes and writes a
  baseline under ``write.lock``, so two writers never lose each other's flights. ``hold`` removes the temporary files
  a crash left (``monitor.memory.atomic``).
- **History is never destroyed.** ``update`` raises (``BaselineError``) where the baseline there cannot be read or is
  of a newer version, and writes nothing; only ``reset`` moves a baseline aside (``baseline.json.reset-<UTC time>``
  beside it) and says where.
"""

from __future__ import annotations

import datetime as _dt
import errno
import fcntl
import os
import re
import stat
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from monitor.errors import PropwatchError
from monitor.memory.atomic import NotAFileError, is_temporary, read_at, write_at
from monitor.memory.baseline import BASELINE_FILE, BaselineError, VehicleBaseline

VEHICLES = "vehicles"
DAEMON_LOCK = "daemon.lock"
WRITE_LOCK = "write.lock"
DIR_MODE = 0o700
# Longest wait for another writer's read-modify-write (one baseline: milliseconds). Chosen, not measured: far past
# one write, short enough for a command-line user.
WRITE_LOCK_WAIT_S = 10.0
_KEY = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9_.-]{0,127}")


class StateDirError(PropwatchError):
    """A state dir (or a directory or file under it) that is not safely ours: memory is off, nothing is written."""


class StateDirBusy(StateDirError):
    """Another process holds the state dir's lock (``pid``: the holder's, where it wrote one)."""

    def __init__(self, text: str, pid: int | None) -> None:
        super().__init__(text)
        self.pid = pid


def safe_key(key: str) -> str:
    """A vehicle key as a directory name: letters, digits, ``_ . -``; never ``.`` or ``..``."""
    key = re.sub(r"[^A-Za-z0-9_.-]", "_", str(key))
    if not _KEY.fullmatch(key):
        raise StateDirError(f"vehicle key {key!r} is not a directory name (letters, digits, _ . -)")
    return key


def baseline_path(root: str | Path, key: str) -> Path:
    """Where a vehicle's baseline lives in the state dir ``root``."""
    return Path(root) / VEHICLES / safe_key(key) / BASELINE_FILE


def _check_owned(st: os.stat_result, where: str) -> None:
    if st.st_uid != os.geteuid():
        raise StateDirError(f"{where} is owned by uid {st.st_uid}, not by this user (uid {os.geteuid()})")
    if st.st_mode & 0o022:
        raise StateDirError(f"{where} is writable by its group or others (mode {stat.S_IMODE(st.st_mode):04o})")


def _open_dir(parent_fd: int, name: str, where: str, create: bool) -> int | None:
    """``name`` under ``parent_fd`` as a directory descriptor, never through a link; created 0700 with ``create``.
    None where it is absent and not created."""
    flags = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC
    try:
        fd = os.open(name, flags, dir_fd=parent_fd)
    except FileNotFoundError:
        if not create:
            return None
        try:
            os.mkdir(name, DIR_MODE, dir_fd=parent_fd)
        except FileExistsError:
            pass
        return _open_dir(parent_fd, name, where, create=False)
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.ENOTDIR):
            raise StateDirError(f"{where} is a symbolic link or not a directory: not followed") from exc
        raise StateDirError(f"{where}: {exc.strerror}") from exc
    try:
        _check_owned(os.fstat(fd), where)
    except BaseException:
        os.close(fd)
        raise
    return fd


def _read_pid(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _holder_pid(fd: int) -> int | None:
    """The pid in a lock file whose lock another process holds. The holder writes it just after taking the lock: a
    reader in between sees none or the previous holder's (gone), so it reads again for up to half a second."""
    pid = None
    for _ in range(20):
        pid = _read_pid(fd)
        if pid is not None and _alive(pid):
            break
        time.sleep(0.025)
    return pid


class StateDir:
    """An opened state dir (``StateDir.open``); ``close`` releases its descriptors and locks."""

    def __init__(self, root: Path, fd: int) -> None:
        self.root = root
        self._fd = fd
        self._held: int | None = None

    @classmethod
    def open(cls, root: str | Path, create: bool = True) -> StateDir:
        """Open (with ``create``, make 0700) the state dir ``root``. ``root`` itself may be reached through a link
        (a systemd ``StateDirectory`` can be one); what it resolves to must be this user's and not writable by
        others. Raises ``StateDirError``."""
        root = Path(root)
        if create and not root.exists():
            try:
                root.parent.mkdir(parents=True, exist_ok=True)
                os.mkdir(root, DIR_MODE)
            except FileExistsError:
                pass
            except OSError as exc:
                raise StateDirError(f"state dir {root} cannot be created: {exc.strerror}") from exc
        try:
            fd = os.open(root, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        except OSError as exc:
            raise StateDirError(f"state dir {root}: {exc.strerror}") from exc
        try:
            _check_owned(os.fstat(fd), f"state dir {root}")
        except BaseException:
            os.close(fd)
            raise
        return cls(root, fd)

    def close(self) -> None:
        for fd in (self._held, self._fd):
            if fd is not None and fd >= 0:
                os.close(fd)
        self._held, self._fd = None, -1

    def __enter__(self) -> StateDir:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def path(self, key: str) -> Path:
        return baseline_path(self.root, key)

    # -- locks
    def _lock_fd(self, name: str) -> int:
        try:
            fd = os.open(name, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600, dir_fd=self._fd)
        except OSError as exc:
            why = "a symbolic link: not followed" if exc.errno == errno.ELOOP else exc.strerror
            raise StateDirError(f"{self.root / name}: {why}") from exc
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_uid != os.geteuid():
            os.close(fd)
            raise StateDirError(f"{self.root / name} is not a regular file of this user")
        return fd

    @staticmethod
    def _mark(fd: int) -> None:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)

    def hold(self) -> list[str]:
        """Take the daemon's lock for the life of this object, then remove the temporary files a crash left.
        Raises ``StateDirBusy`` naming the holder where another process has it. Returns the files removed."""
        if self._held is not None:
            return []
        fd = self._lock_fd(DAEMON_LOCK)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = _holder_pid(fd)
            os.close(fd)
            who = f"pid {pid}" if pid is not None else "a process that wrote no pid"
            raise StateDirBusy(f"state dir {self.root} is in use by another propwatch monitor ({who})", pid) from None
        self._mark(fd)
        self._held = fd
        return self.remove_stale()

    @contextmanager
    def writing(self, wait_s: float | None = None) -> Iterator[None]:
        """Hold ``write.lock`` (waiting up to ``wait_s``, default ``WRITE_LOCK_WAIT_S``) for one read-modify-write."""
        wait_s = WRITE_LOCK_WAIT_S if wait_s is None else wait_s
        fd = self._lock_fd(WRITE_LOCK)
        try:
            deadline = time.monotonic() + wait_s
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if time.monotonic() >= deadline:
                        pid = _holder_pid(fd)
                        raise StateDirBusy(
                            f"state dir {self.root}: another writer (pid {pid}) held it for more than {wait_s:g} s", pid
                        ) from None
                    time.sleep(0.02)
            self._mark(fd)
            yield
        finally:
            os.close(fd)  # releases the lock

    # -- the vehicles
    @contextmanager
    def _vehicle_dir(self, key: str, create: bool) -> Iterator[int | None]:
        key = safe_key(key)
        vfd = _open_dir(self._fd, VEHICLES, f"{self.root / VEHICLES}", create)
        if vfd is None:
            yield None
            return
        try:
            kfd = _open_dir(vfd, key, f"{self.root / VEHICLES / key}", create)
        finally:
            os.close(vfd)
        try:
            yield kfd
        finally:
            if kfd is not None:
                os.close(kfd)

    def vehicles(self) -> list[str]:
        """The vehicle keys that have a directory here."""
        vfd = _open_dir(self._fd, VEHICLES, f"{self.root / VEHICLES}", create=False)
        if vfd is None:
            return []
        try:
            return sorted(e for e in os.listdir(vfd) if _KEY.fullmatch(e))
        finally:
            os.close(vfd)

    def remove_stale(self) -> list[str]:
        """Remove the temporary files left beside the baselines (a crash mid-write), under the write lock."""
        removed = []
        with self.writing():
            for key in self.vehicles():
                try:
                    with self._vehicle_dir(key, create=False) as kfd:
                        if kfd is None:
                            continue
                        for e in os.listdir(kfd):
                            if is_temporary(e, BASELINE_FILE):
                                os.unlink(e, dir_fd=kfd)  # a link is removed, not followed
                                removed.append(f"{VEHICLES}/{key}/{e}")
                except StateDirError:
                    continue  # said when that vehicle is read
        return removed

    def _load_at(self, kfd: int | None, key: str) -> VehicleBaseline | None:
        where = self.path(key)
        if kfd is None:
            return None
        try:
            text = read_at(kfd, BASELINE_FILE)
        except FileNotFoundError:
            return None
        except NotAFileError as exc:
            raise StateDirError(f"{where}: {exc.strerror}") from exc
        except (OSError, UnicodeDecodeError) as exc:
            raise BaselineError(f"{where}: cannot read the vehicle baseline: {exc}") from exc
        return VehicleBaseline.from_text(text, str(where))

    def load(self, key: str) -> VehicleBaseline | None:
        """This vehicle's baseline, None where it has none. Raises ``BaselineError`` where the file cannot be used
        (unreadable, corrupt, newer: ``BaselineNewerError``) and ``StateDirError`` where it or a directory above it
        is a link or not this user's."""
        with self._vehicle_dir(key, create=False) as kfd:
            return self._load_at(kfd, key)

    def update(
        self,
        key: str,
        change: Callable[[VehicleBaseline | None], VehicleBaseline | None],
        wait_s: float | None = None,
    ) -> VehicleBaseline | None:
        """Read this vehicle's baseline, ``change`` it (None: write nothing) and write the result, all under the
        write lock (waiting up to ``wait_s`` for it: ``writing``). A baseline that cannot be read is never replaced:
        ``load``'s errors pass through and nothing is written. ``OSError`` of the write (ENOSPC: disk full) passes
        through with the old file untouched."""
        with self.writing(wait_s), self._vehicle_dir(key, create=True) as kfd:
            new = change(self._load_at(kfd, key))
            if new is not None:
                write_at(kfd, BASELINE_FILE, new.to_text())
            return new

    def reset(self, key: str, now: _dt.datetime | None = None) -> Path:
        """Move this vehicle's baseline aside (``baseline.json.reset-<UTC time>`` beside it, whatever it holds, a
        link included) so the next flight starts a new history. Returns where it went; ``StateDirError`` where none."""
        stamp = (now or _dt.datetime.now(_dt.timezone.utc)).strftime("%Y%m%dT%H%M%SZ")
        with self.writing(), self._vehicle_dir(key, create=False) as kfd:
            if kfd is None or not _exists(kfd, BASELINE_FILE):
                known = ", ".join(self.vehicles()) or "none"
                raise StateDirError(f"no baseline of vehicle {key} in {self.root} (vehicles there: {known})")
            name, k = f"{BASELINE_FILE}.reset-{stamp}", 1
            while _exists(kfd, name):
                k += 1
                name = f"{BASELINE_FILE}.reset-{stamp}-{k}"
            os.rename(BASELINE_FILE, name, src_dir_fd=kfd, dst_dir_fd=kfd)
            os.fsync(kfd)
        return self.path(key).with_name(name)


def _exists(dir_fd: int, name: str) -> bool:
    try:
        os.lstat(name, dir_fd=dir_fd)
    except FileNotFoundError:
        return False
    return True


def state_dir_of(path: str | Path) -> tuple[Path, str] | None:
    """(state dir, vehicle key) where ``path`` is a baseline in a state dir's layout
    (``DIR/vehicles/<key>/baseline.json``), else None."""
    p = Path(path).absolute()
    if p.name == BASELINE_FILE and p.parent.parent.name == VEHICLES:
        return p.parent.parent.parent, p.parent.name
    return None
