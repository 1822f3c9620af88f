"""Car-link keys: where a car's 32-byte key comes from, and how a new one is made.

A key is 32 random bytes, written as 64 hexadecimal digits (whitespace ignored) in a key
file of its own (``cars[].link_key_file``; readable by its owner only, never committed) or,
for throw-away runs, inline (``cars[].link_key``). The car's firmware holds the same bytes.
Its file is ``carN.link.key`` (:func:`key_file_name`): a TLS key is ``carN.tls.key``.
``trustfg keys`` makes a fleet's keys (fleet.operator.keys); ``trustfg sim`` makes fresh
keys for every run (fleet.launch.link_keys).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import TYPE_CHECKING

from .frame import KEY_BYTES

if TYPE_CHECKING:
    from ...agent.config import CarConfig


def _config_error(message: str) -> Exception:
    # the typed config loads lazily: trustfg stop reads keys before it (fleet.operator.estop_direct)
    from ...agent.config import ConfigError

    return ConfigError(message)


def parse_key(text: str, where: str) -> bytes:
    """A key from its hexadecimal text; ConfigError naming ``where`` if it is not 32 bytes."""
    digits = "".join(text.split())
    try:
        key = bytes.fromhex(digits)
    except ValueError:
        raise _config_error(f"{where}: a car-link key is {2 * KEY_BYTES} hexadecimal digits") from None
    if len(key) != KEY_BYTES:
        raise _config_error(f"{where}: a car-link key is {KEY_BYTES} bytes ({2 * KEY_BYTES} hex digits), "
                          f"got {len(key)}")
    return key


def link_key(car: "CarConfig") -> bytes | None:
    """The key the car's link uses: None for version 1; for version 2 its key file's (or
    inline) key, or a ConfigError saying what to configure."""
    return key_for(car.id, car.link_version, car.link_key_file, car.link_key)


def key_for(car_id: int, link_version: int, link_key_file: str, link_key: str) -> bytes | None:
    """:func:`link_key` from a car's fields as a config file gives them (``trustfg stop``
    reads them before the typed config loads: fleet.operator.estop_first)."""
    where = f"cars[id={car_id}]"
    if link_version == 1:
        return None
    if link_key_file:
        path = Path(link_key_file).expanduser()
        try:
            text = path.read_text()
            mode = path.stat().st_mode
        except OSError as exc:
            raise _config_error(f"{where}.link_key_file: cannot read {path}: {exc.strerror}") from None
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            import logging  # here: the e-stop's first datagrams go before logging loads

            logging.getLogger(__name__).warning("%s.link_key_file %s is readable by others (chmod 600 it)",
                                                where, path)
        return parse_key(text, f"{where}.link_key_file ({path})")
    if link_key:
        return parse_key(link_key, f"{where}.link_key")
    raise _config_error(f"{where}: the car link (version 2, authenticated) needs the car's key: set "
                      f"link_key_file (or link_version = 1 for old firmware without authentication)")


def key_file_name(car_id: int) -> str:
    """The name of car ``car_id``'s key file: ``car3.link.key``."""
    return f"car{car_id}.link.key"


def new_key() -> bytes:
    return os.urandom(KEY_BYTES)  # what secrets.token_bytes returns, without importing random


def write_key_file(path: Path, key: bytes) -> Path:
    """Write ``key`` as hex to a new file only its owner may read."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(key.hex() + "\n")
    return path
