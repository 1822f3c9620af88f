"""A car's mind: its factor graph and its trust in peers."""

from __future__ import annotations

from dataclasses import dataclass

from .checks import ConfigError, positive


@dataclass(frozen=True)
class PlannerConfig:
    """The factor graph of one car (docs/architecture.md, "The planner"). Sigmas are the standard
    deviations of each factor's noise model: smaller means stiffer."""

    support_states: int = 21
    """N, the number of support states x_i = (p_i, v_i) of a plan."""
    interp_checks: int = 4
    """Obstacle/proximity checks per interval in addition to the support state itself."""
    qc: float = 0.5
    """Power spectral density of the white-noise-on-acceleration prior, m^2/s^3."""
    min_horizon_s: float = 2.0
    """A plan never spans less than this, so the last metres are still smooth."""
    cruise_speed_mps: float = 0.4
    """Nominal speed used to set the planned arrival time (a car may override it)."""
    max_speed_mps: float = 0.6
    """Speeds above this are penalised (soft limit; the vehicle's hard limit is higher)."""
    reach_margin_m: float = 0.5
    """A peer is left out of the graph when even closing at max_speed_mps from both sides
    over the whole horizon, and along its own plan, it stays this much beyond its epsilon
    from where our plan starts (agent.planner.peers_within_reach); covers a plan's small
    excess over the soft speed limit."""
    sigma_start: float = 1e-3
    sigma_start_velocity: float = 0.05
    sigma_goal: float = 0.01
    sigma_goal_velocity: float = 0.01
    sigma_obstacle: float = 0.003
    """Walls are certain and do not move; peers' plans are guesses when late, and their
    berth (up to eps_0 * g_max) holds margin. So where both cannot be kept -- a wide berth
    around a predicted peer in a narrow street -- a plan gives way to the peer, by
    (sigma_obstacle / sigma_proximity)^2 ~ 1/11 as much into the wall (the proximity guard
    keeps the cars apart)."""
    sigma_proximity: float = 0.01
    sigma_consistency: float = 0.2
    """Sigma of the consistency residual, in m/s^2."""
    sigma_speed: float = 0.02
    sigma_lane: float = 0.15
    """Sigma of the pull towards the lane centre line, m."""
    max_iterations: int = 30
    relative_error_tol: float = 1e-3
    """LM stops when an iteration lowers the error by less than this fraction; replanning
    is receding-horizon, so the next replan carries on from here."""
    absolute_error_tol: float = 0.05
    """... or by less than this much cost (1/2 sum of squared whitened residuals)."""
    lambda_initial: float = 1e-3
    lambda_factor: float = 10.0
    diagonal_damping: bool = True
    """Damp with lambda * diag(J^T J) (scale-invariant; the hinges are far stiffer than
    the GP prior)."""
    intervals_per_factor: int = 4
    """'batched': consecutive intervals checked by one GTSAM factor. Each factor is a call
    from C++ into Python per linearisation and per error evaluation; larger chunks make
    fewer calls but denser linear systems (agent.interval_factors)."""
    interpolation: str = "batched"
    """'batched': one factor per chunk of intervals, every check evaluated in one numpy
    call; 'gtsam': one WnoaInterpFactorPoint2 per interpolated check (slower, for reference)."""
    lane_keeping: bool = True
    """Pull plans towards the car's route (start, via points, goal): its lane."""
    proximity: bool = True
    consistency: bool = True
    transparency: bool = True
    """The three trust factors, switchable for the experiments."""

    def validate(self, path: str) -> None:
        if self.support_states < 3:
            raise ConfigError(f"{path}.support_states: must be at least 3")
        if self.interp_checks < 0:
            raise ConfigError(f"{path}.interp_checks: must be >= 0")
        for name in (
            "qc", "min_horizon_s", "cruise_speed_mps", "max_speed_mps", "sigma_start",
            "sigma_start_velocity", "sigma_goal", "sigma_goal_velocity", "sigma_obstacle",
            "sigma_proximity", "sigma_consistency", "sigma_speed", "sigma_lane", "reach_margin_m", "relative_error_tol", "absolute_error_tol", "lambda_initial",
        ):
            positive(getattr(self, name), f"{path}.{name}")
        if self.lambda_factor <= 1.0:
            raise ConfigError(f"{path}.lambda_factor: must be > 1")
        if self.intervals_per_factor < 1:
            raise ConfigError(f"{path}.intervals_per_factor: must be >= 1")
        if self.max_iterations < 1:
            raise ConfigError(f"{path}.max_iterations: must be >= 1")
        if self.interpolation not in ("batched", "gtsam"):
            raise ConfigError(f"{path}.interpolation: expected 'batched' or 'gtsam'")


@dataclass(frozen=True)
class TrustConfig:
    """Beta reputation per peer and dimension (docs/architecture.md, "Trust")."""

    forgetting: float = 0.85
    """lambda per second: evidence of age s weighs lambda**s (0.85: half-life ~4.3 s)."""
    failure_weight: float = 3.0
    """A failure of transparency or safety counts this many successes: a liar is honest
    most of the time."""
    consistency_failure_weight: float = 1.0
    """A car that did not do what it announced half a second ago counts one failure: cars
    replan, and a changed mind is not a lie."""
    prior_alpha: float = 1.0
    prior_beta: float = 0.0
    """The Beta prior every peer starts from (tau = 2/3); forgetting decays towards it."""
    transparency_tolerance_m: float = 0.15
    """A peer seen within this of where its latest plan says it is now: full success;
    beyond twice this: full failure; linear in between."""
    plan_reject_m: float = 0.30
    """A shared plan that misses the peer's observed position by more than this is not
    planned against; the last plan that agreed (or the observed motion) is used."""
    consistency_tolerance_mps2: float = 0.6
    """Observed vs planned acceleration mismatch that still counts as consistent."""
    evidence_period_s: float = 0.1
    stale_after_s: float = 1.0
    """A peer with no plan for this long is predicted from its observed motion and
    kept at the widest epsilon; silence is never counted as lying."""
    testimony_deviation: float = 0.3
    """A testimony whose mean differs from our own direct estimate by more than this (once
    we hold enough direct evidence) is rejected as a lie and counted."""
    testimony_min_evidence: float = 5.0
    epsilon_gain_max: float = 2.0
    """g(tau) ranges from 1 (tau >= tau_full) to this (tau <= tau_floor)."""
    tau_full: float = 0.9
    tau_floor: float = 0.5
    epsilon_gain_fixed: float = 1.0
    """g for every peer when the transparency factor is off (planner.transparency = false):
    1 keeps eps_0 from everyone; the bank's "wide" baseline keeps 2 eps_0."""

    def validate(self, path: str) -> None:
        if not 0.0 < self.forgetting <= 1.0:
            raise ConfigError(f"{path}.forgetting: must be within (0, 1]")
        if self.prior_alpha < 0 or self.prior_beta < 0:
            raise ConfigError(f"{path}.prior_alpha/prior_beta: must be >= 0")
        if not 0.0 <= self.tau_floor < self.tau_full <= 1.0:
            raise ConfigError(f"{path}.tau_floor/tau_full: need 0 <= tau_floor < tau_full <= 1")
        if self.failure_weight <= 0 or self.consistency_failure_weight <= 0:
            raise ConfigError(f"{path}.failure_weight/consistency_failure_weight: must be > 0")
        if self.epsilon_gain_max < 1.0 or self.epsilon_gain_fixed < 1.0:
            raise ConfigError(f"{path}.epsilon_gain_max/epsilon_gain_fixed: must be >= 1")
        for name in (
            "transparency_tolerance_m", "plan_reject_m", "consistency_tolerance_mps2",
            "evidence_period_s", "stale_after_s", "testimony_deviation",
        ):
            positive(getattr(self, name), f"{path}.{name}")
