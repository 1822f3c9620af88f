"""The repository speaks of the project only: no words of how its work was organised, no
files named by iteration, no commit hashes outside a results page's provenance line, and
module docstrings short enough to read where they stand."""

from __future__ import annotations

import ast
import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

INTERNAL = re.compile(r"s[t]op [0-9]+|s[i]tting|quick h[o]ur|i[s]sue [0-9]+|x f[r]ozen", re.IGNORECASE)
"""Words that mean something only to the people who organised the work. One letter of each
stands in brackets, so that this file does not match its own patterns."""

ITERATION_NAME = re.compile(r"(s[t]op|s[i]tting|round|iteration|take)[-_]?[0-9]+|[a-z][-_][0-9]{2}\b",
                            re.IGNORECASE)
"""A file name that counts iterations (bank-round-3.md, results-v-18.md)."""

COMMIT = re.compile(r"(?<![0-9a-zA-Z_/#.-])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,12}(?![0-9a-zA-Z_-])")
"""A short commit hash: 7-12 hex digits with letters and digits, standing alone."""

PROVENANCE = re.compile(r"\bprovenance\b", re.IGNORECASE)
"""The line of a results page that names the commit it was measured on says so."""

MAX_DOCSTRING_LINES = 20
"""A module docstring of about 15 lines at most: its essay belongs in docs/design/."""

REFERENCE_DOCSTRINGS = {"bridge/carlink/codec.py", "bridge/carlink/answer.py", "bridge/carlink/receiver.py",
                        "bridge/natnet/frame.py", "bridge/natnet/model.py", "bridge/natnet/handshake.py",
                        "fleet/bus/key_exprs.py", "agent/messages.py", "fleet/faultlab/matrix.py"}
"""Modules whose docstring is a reference table a reader needs beside the code (a wire
format's bytes, the key-expression table, the fault cases the command's help prints)."""


def tracked() -> list[str]:
    out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout.split("\n")
    return [name for name in out if name and (ROOT / name).is_file()]


def text_of(name: str) -> str | None:
    try:
        return (ROOT / name).read_text(encoding="utf-8")
    except (UnicodeDecodeError, OSError):
        return None


def test_no_internal_vocabulary_anywhere():
    found = []
    for name in tracked():
        text = text_of(name)
        for number, line in enumerate((text or "").splitlines(), 1):
            if INTERNAL.search(line):
                found.append(f"{name}:{number}: {line.strip()[:100]}")
    assert found == []


def test_no_file_is_named_by_iteration():
    assert [name for name in tracked() if name.startswith("docs/") and ITERATION_NAME.search(Path(name).stem)] == []


def test_commit_hashes_only_on_a_results_page_provenance_line():
    found = []
    for name in tracked():
        if not name.endswith((".py", ".md", ".toml", ".sh", ".c", ".h", ".service", ".json5")) \
                or name == "tests/repo/test_vocabulary.py" or name.startswith("tests/data/"):
            continue
        for number, line in enumerate((text_of(name) or "").splitlines(), 1):
            if not COMMIT.search(line):
                continue
            if name.startswith("docs/results/") and PROVENANCE.search(line):
                continue
            found.append(f"{name}:{number}: {line.strip()[:100]}")
    assert found == []


def test_module_docstrings_are_short():
    long = []
    for name in tracked():
        if not name.endswith(".py") or name in REFERENCE_DOCSTRINGS:
            continue
        doc = ast.get_docstring(ast.parse((ROOT / name).read_text()), clean=False)
        if doc and doc.count("\n") + 1 > MAX_DOCSTRING_LINES:
            long.append(f"{name}: {doc.count(chr(10)) + 1} lines")
    assert long == []
