"""Running an example as a researcher would: its own process, from the repository root."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 180.0
"""An example takes seconds; a busy 2-core machine may stretch that several times over."""


def png(path: Path) -> bool:
    """Whether ``path`` holds a PNG image (its eight-byte signature)."""
    return path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def run_example(tmp_path):
    """``run_example(NAME, *args)``: run examples/NAME.py with ``--out tmp_path``; its stdout."""

    def run(name: str, *args: str) -> str:
        done = subprocess.run([sys.executable, str(ROOT / "examples" / f"{name}.py"), *args, "--out", str(tmp_path)],
                              cwd=ROOT, capture_output=True, text=True, timeout=TIMEOUT_S)
        assert done.returncode == 0, done.stderr
        return done.stdout

    return run
