"""Files written so that a crash leaves the old one or the new one, and read without following a link.

``write_at(dir_fd, name, text)``: a temporary file made with exclusive creation (``O_CREAT | O_EXCL | O_NOFOLLOW``,
mode 0600) beside the target, written, fsynced, renamed over it, and the directory fsynced. A link planted at a
temporary name makes the creation fail; a link at the target is replaced by the file, never written through.
``read_at(dir_fd, name)`` opens with ``O_NOFOLLOW`` and reads a regular file only. Temporary names start with
``.<name>.`` and end in ``.tmp`` (``is_temporary``): what a crash leaves behind, removed at start by the state dir.
"""

from __future__ import annotations

import errno
import os
import secrets
import stat
from pathlib import Path

TMP_SUFFIX = ".tmp"
# Largest baseline read: about 20,000 flights of ~3 kB. Chosen, not measured: a bound on what a corrupt or hostile
# file can make the reader allocate.
MAX_READ_BYTES = 64 * 1024 * 1024


class NotAFileError(OSError):
    """A name that is a link, a directory or another non-regular file where a regular file was expected."""


def temporary_name(name: str) -> str:
    return f".{name}.{os.getpid()}.{secrets.token_hex(4)}{TMP_SUFFIX}"


def is_temporary(entry: str, name: str) -> bool:
    return entry.startswith(f".{name}.") and entry.endswith(TMP_SUFFIX)


def write_at(dir_fd: int, name: str, text: str) -> None:
    """Replace ``name`` in the directory ``dir_fd`` by ``text``, atomically. Raises ``OSError`` (ENOSPC: disk full);
    the temporary file is gone then and the old file untouched."""
    tmp = temporary_name(name)
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600, dir_fd=dir_fd)
    try:
        try:
            data = text.encode("utf-8")
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.rename(tmp, name, src_dir_fd=dir_fd, dst_dir_fd=dir_fd)
    except BaseException:
        try:
            os.unlink(tmp, dir_fd=dir_fd)
        except FileNotFoundError:
            pass
        raise
    os.fsync(dir_fd)


def read_at(dir_fd: int, name: str, max_bytes: int = MAX_READ_BYTES) -> str:
    """The text of the regular file ``name`` in ``dir_fd``, never through a link. ``FileNotFoundError`` where absent,
    ``NotAFileError`` where a link or not a regular file, ``UnicodeDecodeError`` where not UTF-8."""
    try:
        fd = os.open(name, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK, dir_fd=dir_fd)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise NotAFileError(errno.ELOOP, "a symbolic link, not followed", name) from exc
        raise
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise NotAFileError(errno.EINVAL, "not a regular file", name)
        if st.st_size > max_bytes:
            raise NotAFileError(errno.EFBIG, f"{st.st_size} bytes, more than {max_bytes}", name)
        chunks, left = [], max_bytes + 1
        while left > 0:
            b = os.read(fd, min(left, 1 << 20))
            if not b:
                break
            chunks.append(b)
            left -= len(b)
        if left <= 0:
            raise NotAFileError(errno.EFBIG, f"more than {max_bytes} bytes", name)
    finally:
        os.close(fd)
    return b"".join(chunks).decode("utf-8")


def write_atomic(path: str | Path, text: str) -> Path:
    """``write_at`` for a path (``propwatch baseline learn --out``, ``note``): the directory is followed as given,
    the file itself never through a link."""
    path = Path(path)
    dfd = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        write_at(dfd, path.name, text)
    finally:
        os.close(dfd)
    return path
