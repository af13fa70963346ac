"""``propwatch keygen PATH``: a new MAVLink 2 signing key for ``link.signing_key_path``.

Writes 32 random bytes (``secrets.token_bytes``) as 64 hex digits and a newline, readable by its owner only
(mode 0600), and never over an existing file unless ``--force``. The same key goes to the autopilot (PX4:
the ground station's SETUP_SIGNING, or ``MAV_x_SIGN`` with the key in its storage); docs/SECURITY.md.
"""

from __future__ import annotations

import argparse
import os
import secrets
from pathlib import Path

from monitor.daemon.link import SIGNING_KEY_BYTES
from monitor.errors import ConfigError


def write_key(path: str | Path, force: bool = False) -> Path:
    path = Path(path)
    flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if force else os.O_EXCL)
    try:
        fd = os.open(path, flags, 0o600)
    except FileExistsError:
        raise ConfigError(f"{path}: exists; a new key would lock out whatever holds the old one (--force replaces it)") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot write the signing key: {exc.strerror or exc}") from None
    with os.fdopen(fd, "w", encoding="ascii") as f:
        os.fchmod(f.fileno(), 0o600)
        f.write(secrets.token_bytes(SIGNING_KEY_BYTES).hex() + "\n")
    return path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="propwatch keygen", description="Write a new MAVLink 2 signing key (mode 0600).")
    p.add_argument("path", help="key file to create, e.g. /etc/propwatch/signing.key (link.signing_key_path)")
    p.add_argument("--force", action="store_true", help="replace an existing key file")
    args = p.parse_args(argv)
    path = write_key(args.path, args.force)
    print(f"{path}: new 32-byte signing key (mode 0600); give the autopilot the same key (docs/SECURITY.md)")
    return 0
