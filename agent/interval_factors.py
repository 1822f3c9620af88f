"""The checks of every interval as GTSAM factors: chunks of intervals, one evaluation.

Two constructions of the same residuals (``PlannerConfig.interpolation``):

* ``batched`` (default): the intervals are cut into chunks of
  ``PlannerConfig.intervals_per_factor``; each chunk is one CustomFactor on the support
  states it spans, whose residual is its intervals' rows (agent.factors) stacked. All
  chunks are evaluated together in one compiled call (agent.interval_kernel), cached in a
  :class:`BatchedIntervals` keyed by the whole Values, and each factor returns its slice:
  fewer calls from C++ into Python, each factor still a pure function of its keys.
* ``gtsam``: GTSAM's own ``WnoaInterpFactorPoint2`` wraps a per-check CustomFactor on an
  interpolated state; one Python call per check, kept as the reference.

docs/design/planner.md, "Checks between support states".
"""

from __future__ import annotations

import functools
import threading

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, V, X

from . import factors
from .config import PlannerConfig


def chunk_bounds(n_intervals: int, per_factor: int) -> list[tuple[int, int]]:
    """[first, end) interval ranges of the chunks, in order; the last may be shorter."""
    return [(start, min(start + per_factor, n_intervals)) for start in range(0, n_intervals, per_factor)]


def chunk_keys(first: int, end: int) -> list[int]:
    """Keys of a chunk of intervals [first, end): p_s, v_s for s = first..end."""
    return [key for s in range(first, end + 1) for key in (X(s), V(s))]


class BatchedIntervals:
    """Evaluates every interval of a trajectory in one call, for many factors.

    GTSAM linearises (or evaluates) factors one after another on the same Values; the
    first chunk factor to ask computes all intervals, the others read their slice.
    """

    def __init__(self, problem: factors.IntervalProblem, n: int, per_factor: int):
        self.problem = problem
        self.n = n
        self.chunks = chunk_bounds(n - 1, per_factor)
        self._per_factor = per_factor
        whole = (n - 1) // per_factor * per_factor  # the full chunks, then the shorter last one
        self._runs = [run for run in ((0, whole), (whole, n - 1)) if run[1] > run[0]]
        self._lock = threading.Lock()
        self._values: gtsam.Values | None = None
        self._residuals: list[np.ndarray] = []
        self._jacobian = np.zeros(0)
        self._blocks: list[np.ndarray] = []
        self._jacobians: list[gtsam.JacobianVector | None] = []
        self.evaluations = 0

    def chunk(self, f: int, values: gtsam.Values, want_jacobian: bool
              ) -> tuple[np.ndarray, gtsam.JacobianVector | None]:
        """Residual rows of chunk f and, if wanted, its Jacobian blocks (one per key)."""
        with self._lock:
            if self._values is None or not values.equals(self._values, 0.0):
                self._evaluate(values)
            jacobian = None
            if want_jacobian:
                jacobian = self._jacobians[f]
                if jacobian is None:  # converted to Eigen once per point, on first use
                    if not self._blocks:
                        self._lay_out_blocks()
                    jacobian = self._jacobians[f] = gtsam.JacobianVector(list(self._blocks[f]))
            return self._residuals[f], jacobian

    def _evaluate(self, values: gtsam.Values) -> None:
        positions = gtsam.utilities.extractVectors(values, "x")
        velocities = gtsam.utilities.extractVectors(values, "v")
        residual, self._jacobian = factors.evaluate_intervals(self.problem, positions, velocities)
        self._residuals = []
        for first, end in self._runs:
            c = min(self._per_factor, end - first)
            self._residuals.extend(residual[first:end].reshape((end - first) // c, c * residual.shape[1]))
        self._blocks = []  # laid out when a Jacobian is first asked for at this point: LM
        # evaluates every trial point, and linearises only those it accepts
        self._jacobians = [None] * len(self.chunks)
        self._values = gtsam.Values(values)
        self.evaluations += 1

    def _lay_out_blocks(self) -> None:
        """Each chunk's Jacobian blocks (one per key) from the intervals' Jacobian."""
        # (I, 4, R, 2) as a view of the (I, R, 4, 2) Jacobian: block j of interval i,
        # states ordered (p_i, v_i, p_i+1, v_i+1).
        blocks = self._jacobian.transpose(0, 2, 1, 3)
        rows = blocks.shape[2]
        for first, end in self._runs:
            # Chunks of c intervals over [first, end), at once. Keys of a chunk: 2 per state,
            # c + 1 states; interval l of the chunk fills its own rows of the blocks of
            # states l and l + 1 (keys 2l .. 2l + 3).
            c = min(self._per_factor, end - first)
            count = (end - first) // c
            own = blocks[first:end].reshape(count, c, 4, rows, 2).transpose(0, 1, 2, 4, 3)
            # Laid out axis before row, so that each block, (c * rows, 2), is in column-major
            # order: Eigen's, which GTSAM then takes without reordering it.
            dense = np.zeros((count, 2 * (c + 1), 2, c, rows))
            for local in range(c):
                dense[:, 2 * local:2 * local + 4, :, local] = own[:, local]
            self._blocks.extend(dense.reshape(count, 2 * (c + 1), 2, c * rows).transpose(0, 1, 3, 2))


def _chunk_error(batch: BatchedIntervals, f: int, this: gtsam.CustomFactor,
                 values: gtsam.Values, H: gtsam.JacobianVector | None) -> np.ndarray:
    residual, jacobian = batch.chunk(f, values, H is not None)
    if H is not None:
        H[:] = jacobian
    return residual


def add_batched_checks(graph: gtsam.NonlinearFactorGraph, problem: factors.IntervalProblem,
                       config: PlannerConfig) -> BatchedIntervals:
    batch = BatchedIntervals(problem, config.support_states, config.intervals_per_factor)
    sigmas = factors.interval_sigmas(problem, config.sigma_obstacle, config.sigma_proximity,
                                     config.sigma_speed, config.sigma_lane, config.sigma_consistency)
    models = {}  # one noise model per chunk length: all but the last chunk share one
    for f, (first, end) in enumerate(batch.chunks):
        if end - first not in models:
            models[end - first] = gtsam.noiseModel.Diagonal.Sigmas(np.tile(sigmas, end - first))
        graph.add(gtsam.CustomFactor(models[end - first], chunk_keys(first, end),
                                     functools.partial(_chunk_error, batch, f)))
    return batch


# --- the reference construction with GTSAM's own interpolation factor ----------------------


def _check_error(problem: factors.IntervalProblem, i: int, k: int, this: gtsam.CustomFactor,
                 values: gtsam.Values, H: list[np.ndarray] | None) -> np.ndarray:
    """Rows of one check on (p, v) at check time k of interval i (keys: p, v)."""
    keys = this.keys()
    p = values.atPoint2(keys[0])
    v = values.atPoint2(keys[1])  # interpolated velocities are stored as Vector2
    residual, d_dp, d_dv = factors.check_residuals(
        p, v, problem.peer_positions[i, k], problem.epsilons, problem.sdf,
        problem.epsilon_obstacle, problem.max_speed, problem.lane)
    if H is not None:
        H[0] = d_dp
        H[1] = d_dv
    return residual


def _consistency_error(problem: factors.IntervalProblem, i: int, this: gtsam.CustomFactor,
                       values: gtsam.Values, H: list[np.ndarray] | None) -> np.ndarray:
    keys = this.keys()
    v0, v1 = values.atVector(keys[0]), values.atVector(keys[1])
    a = (v1 - v0) / problem.dt
    root = np.sqrt(a @ a + factors.SMOOTH_ACCEL_DELTA**2)
    excess = root - factors.SMOOTH_ACCEL_DELTA - problem.consistency_targets[i]
    if H is not None:
        da = (a / root / problem.dt)[None, :] if excess > 0.0 else np.zeros((1, 2))
        H[0] = -da
        H[1] = da
    return np.array([max(excess, 0.0)])


def add_gtsam_interp_checks(graph: gtsam.NonlinearFactorGraph, problem: factors.IntervalProblem,
                            config: PlannerConfig, states: list, qc: np.ndarray) -> None:
    sigmas = factors.check_sigmas(problem, config.sigma_obstacle, config.sigma_proximity,
                                  config.sigma_speed, config.sigma_lane)
    model = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
    fractions = factors.check_fractions(config.interp_checks)
    index = 0
    for i in range(len(states) - 1):
        left, right = states[i], states[i + 1]
        graph.add(gtsam.CustomFactor(model, [X(i), V(i)], functools.partial(_check_error, problem, i, 0)))
        for k in range(1, len(fractions)):
            t = left.time + fractions[k] * (right.time - left.time)
            inner = gtsam.CustomFactor(model, [A(index), B(index)],
                                       functools.partial(_check_error, problem, i, k))
            interp = gtsam.StateData(A(index), B(index), t)
            graph.add(gtsam.WnoaInterpFactorPoint2(inner, {left, right}, {interp}, qc, True))
            index += 1
        if problem.consistency_targets is not None:
            graph.add(gtsam.CustomFactor(
                gtsam.noiseModel.Isotropic.Sigma(1, config.sigma_consistency), [V(i), V(i + 1)],
                functools.partial(_consistency_error, problem, i)))
