"""What a simulated run depends on besides the code, the configuration and the seed.

The in-process fleet is deterministic: the same code, scene, seed and environment give the
same run to the last bit. A run of many cars is also chaotic: a difference in the last bit
of one floating-point result grows, over thousands of replans, into another run (another
makespan, sometimes another outcome). Such differences come from the packages (a numpy,
scipy or GTSAM release with another summation order or another ``sin``), from the BLAS
kernels OpenBLAS picks for the CPU, from the vector instruction sets numpy dispatches its
loops to, and from the CPU numba compiles for. So a journal entry names its environment
(:func:`digest` of :func:`environment`) beside its commit: two runs of one seed are the
same run only when both match (``trustfg experiment bank --recheck K`` reruns K of a
journal's runs here and says which came out the same; docs/results/scenario-bank.md,
"Repeating a run", how often they did on another machine). :func:`code_version` names the
commit.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path

PACKAGES = ("numpy", "scipy", "gtsam", "numba", "llvmlite", "msgpack", "pyrvo")
"""The packages whose arithmetic a run goes through (pyrvo: ORCA's runs)."""

DISPATCH_PREFIXES = ("OPENBLAS_", "NPY_", "NUMBA_")
"""Environment variables that can change which kernels run (recorded when set): OpenBLAS's
(OPENBLAS_CORETYPE picks its kernels: some machines set it for every process), numpy's
dispatch (NPY_DISABLE_CPU_FEATURES ...) and numba's target (NUMBA_CPU_NAME ...)."""


def environment() -> dict:
    """The packages' versions, the CPU, the instruction sets numpy dispatches to, the BLAS
    and the CPU numba compiles for, and the variables that override them."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpu": cpu_model(),
        "packages": versions,
        "numpy_dispatch": _numpy_dispatch(),
        "blas": _blas(),
        "numba_cpu": _numba_cpu(),
        "variables": {name: value for name, value in sorted(os.environ.items()) if name.startswith(DISPATCH_PREFIXES)},
    }


def code_version() -> str:
    """The commit this package runs from (``git describe --always --dirty``: ``-dirty``
    when the tree has changes), else the installed version: what a journal entry was
    run on, so runs of several commits can be told apart."""
    here = Path(__file__).resolve().parent
    try:
        done = subprocess.run(["git", "-C", str(here), "describe", "--always", "--dirty", "--abbrev=7"],
                              capture_output=True, text=True, timeout=5.0)
        if done.returncode == 0 and done.stdout.strip():
            return done.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    try:
        return "trustfg " + metadata.version("trustfg")
    except metadata.PackageNotFoundError:
        return "unknown"


def digest(env: dict) -> str:
    """A short name for an environment: equal environments, equal digests."""
    return hashlib.sha256(json.dumps(env, sort_keys=True).encode()).hexdigest()[:12]


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo; elsewhere what the platform says)."""
    try:
        return next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                    if line.startswith("model name"))
    except (OSError, StopIteration):
        return platform.processor()


def _numpy_dispatch() -> list[str]:
    """The dispatch targets numpy was built with that this CPU runs (its loops take the
    best of them)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # numpy < 2
        try:
            from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
        except ImportError:
            return []
    return [target for target in __cpu_dispatch__ if __cpu_features__.get(target)]


def _blas() -> str | None:
    import numpy as np
    try:
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
    except (TypeError, KeyError):  # numpy < 1.26 prints only
        return None
    return f"{blas.get('name')} {blas.get('version')}"


def _numba_cpu() -> str | None:
    try:
        import llvmlite.binding as llvm
    except ImportError:
        return None
    return llvm.get_host_cpu_name()
