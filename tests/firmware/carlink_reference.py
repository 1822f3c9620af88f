"""The C reference of the car link (firmware/carlink/) built for the tests: the system C
compiler, a ctypes wrapper of the core, the POSIX car as a process, and variants of the
source made by named text substitutions."""

from __future__ import annotations

import contextlib
import ctypes
import os
import re
import shutil
import signal
import subprocess
from pathlib import Path
from typing import Iterator

import pytest

ROOT = Path(__file__).resolve().parent.parent.parent
FIRMWARE = ROOT / "firmware" / "carlink"
HERE = Path(__file__).resolve().parent
SOURCES = ("carlink.h", "carlink.c", "carlink_posix.c", "mcu_example.c")
STRICT = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wconversion", "-Wshadow", "-Wstrict-prototypes")
"""The README's flags (-std=c99 -Wall -Wextra) and more, every warning an error."""
SANITIZE = ("-O1", "-g", "-fno-omit-frame-pointer", "-fsanitize=address,undefined", "-fno-sanitize-recover=all")

VERDICTS = ("accepted", "e_stop", "ping", "wrong_car", "repeated_seq", "stale_seq", "old_session", "length",
            "magic", "version", "crc", "mac", "reserved", "car_id", "flags", "non_finite")
"""carlink_verdict's names, in the enum's order (carlink.h)."""
DECODE_REASONS = VERDICTS[VERDICTS.index("length"):]


def compiler() -> str:
    """The system C compiler ($CC, cc or gcc); the test fails, saying so, without one."""
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and shutil.which(name):
            return shutil.which(name)  # type: ignore[return-value]
    pytest.fail("no C compiler on this machine (tried $CC, cc, gcc): the firmware reference cannot be built; "
                "install gcc (tests/setup-system.sh does on Debian)", pytrace=False)


def build(out: Path, sources: list[Path], *flags: str) -> Path:
    done = subprocess.run([compiler(), *STRICT, *flags, "-I", str(sources[0].parent), "-I", str(FIRMWARE),
                           *map(str, sources), "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, f"the build of {out.name} failed:\n{done.stderr}"
    assert not done.stderr.strip(), done.stderr  # not even a note
    return out


def variant(folder: Path, substitutions: list[tuple[str, str, str]]) -> Path:
    """A copy of firmware/carlink/ in ``folder`` with (file, old, new) applied; each old
    text must occur exactly once."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in SOURCES:
        shutil.copy(FIRMWARE / name, folder / name)
    for name, old, new in substitutions:
        text = (folder / name).read_text()
        assert text.count(old) == 1, f"{name}: {old!r} occurs {text.count(old)} times, not once"
        (folder / name).write_text(text.replace(old, new))
    return folder


def build_posix(out: Path, folder: Path = FIRMWARE) -> Path:
    return build(out, [folder / "carlink_posix.c", folder / "carlink.c"], "-O2")


@contextlib.contextmanager
def posix_car(binary: Path, car_id: int, key_file: Path | None, *extra: str) -> Iterator[tuple[tuple[str, int], list]]:
    """The POSIX car on a free loopback port: yields its address and a list that gets its
    output (stdout lines) once it has stopped; stopped with SIGTERM, which must end it with 0."""
    argv = [str(binary), "--car", str(car_id), "--bind", "127.0.0.1:0", *extra]
    if key_file is not None:
        argv += ["--key", str(key_file)]
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    output: list[str] = []
    try:
        first = process.stdout.readline()
        found = re.search(r"listening on 127\.0\.0\.1:(\d+)$", first.strip())
        assert found, first + process.stderr.read()
        yield ("127.0.0.1", int(found.group(1))), output
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
        try:
            code = process.wait(timeout=5)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
        output[:] = [first, *process.stdout.read().splitlines(keepends=True)]
        process.stdout.close()
        process.stderr.close()
        assert code == 0, output


class CCar:
    """The core (carlink.c) through the ctypes harness: one car's state in a buffer."""

    def __init__(self, library: ctypes.CDLL, car_id: int, key: bytes | None = None, watchdog_ms: int = 250,
                 resync_ms: int = 1000):
        self._lib = library
        self._state = ctypes.create_string_buffer(library.harness_state_size())
        self._key = key
        self.init_result = library.harness_init(self._state, car_id, key, watchdog_ms, resync_ms)

    def receive(self, data: bytes, now_ms: int) -> dict:
        out = (ctypes.c_uint64 * 12)()
        answer = (ctypes.c_uint8 * 44)()
        length = self._lib.harness_receive(self._state, data, len(data), now_ms & 0xFFFFFFFF, out, answer)
        fields = ("verdict", "version", "car_id", "source", "flags", "session", "seq", "stamp_bits", "v_bits",
                  "omega_bits", "resynced", "new_session")
        got = dict(zip(fields, out))
        got["verdict"] = VERDICTS[got["verdict"]]
        got["answer"] = bytes(answer[:length])
        return got

    def motors(self, now_ms: int) -> tuple[float, float, bool]:
        out = (ctypes.c_float * 2)()
        stopped = self._lib.harness_motors(self._state, now_ms & 0xFFFFFFFF, out)
        return out[0], out[1], bool(stopped)

    def counters(self) -> dict:
        n = self._lib.harness_decode_errors()
        out = (ctypes.c_uint32 * (9 + n))()
        self._lib.harness_counters(self._state, out)
        names = ("accepted", "resynced", "e_stops", "pings", "wrong_car", "stale_seq", "repeated_seq",
                 "new_session", "old_session")
        counts = dict(zip(names, out[:9]))
        counts["decode_errors"] = {reason: out[9 + i] for i, reason in enumerate(DECODE_REASONS) if out[9 + i]}
        return counts


def load_harness(out: Path) -> ctypes.CDLL:
    path = build(out, [HERE / "carlink_harness.c", FIRMWARE / "carlink.c"], "-O2", "-fPIC", "-shared")
    lib = ctypes.CDLL(str(path))
    lib.harness_state_size.restype = ctypes.c_size_t
    lib.harness_init.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_char_p, ctypes.c_uint32, ctypes.c_uint32]
    lib.harness_receive.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint32,
                                    ctypes.POINTER(ctypes.c_uint64), ctypes.POINTER(ctypes.c_uint8)]
    lib.harness_motors.argtypes = [ctypes.c_void_p, ctypes.c_uint32, ctypes.POINTER(ctypes.c_float)]
    lib.harness_counters.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint32)]
    lib.harness_decode_errors.restype = ctypes.c_uint
    for name in ("carlink_sha256", "carlink_hmac_sha256"):
        getattr(lib, name).restype = None
    lib.carlink_sha256.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p]
    lib.carlink_hmac_sha256.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p, ctypes.c_size_t,
                                        ctypes.c_char_p]
    lib.carlink_crc32.argtypes = [ctypes.c_char_p, ctypes.c_size_t]
    lib.carlink_crc32.restype = ctypes.c_uint32
    return lib
