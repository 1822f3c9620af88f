"""A car's mind: its factor graph and its trust in peers."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .checks import ConfigError, positive

LEAVE_LANE = ("never", "alone", "nothing-to-wait-for")
"""When a stalled car-like car leaves its lane (DeadlockConfig.leave_lane)."""
TRACK_HISTORY_S = 2.0
"""How long a car keeps its observations of every car (agent.sightings.Track.history_s)."""


@dataclass(frozen=True)
class PlannerConfig:
    """The factor graph of one car (docs/design/planner.md). Sigmas are the standard deviations
    of each factor's noise model: smaller means stiffer."""

    support_states: int = 21
    """N, the number of support states x_i = (p_i, v_i) of a plan."""
    interp_checks: int = 4
    """Obstacle/proximity checks per interval in addition to the support state itself."""
    qc: float = 0.5
    """Power spectral density of the white-noise-on-acceleration prior, in m^2/s^3."""
    min_horizon_s: float = 2.0
    """A plan never spans less than this, so the last metres are still smooth."""
    cruise_speed_mps: float = 0.4
    """Nominal speed that sets a plan's arrival time when the start names none (``trustfg go
    --cruise`` names one; the simulations draw each car's from ``sim.cruise_speed_range_mps``)."""
    max_speed_mps: float = 0.6
    """Speeds above this are penalised (soft limit; the vehicle's hard limit is higher)."""
    reach_margin_m: float = 0.5
    """A peer is left out of the graph when even closing at max_speed_mps from both sides
    over the whole horizon, and along its own plan, it stays this much beyond its epsilon
    from where our plan starts (agent.planner.peers_within_reach); covers a plan's small
    excess over the soft speed limit."""
    sigma_start: float = 1e-3
    """Sigma of the prior that pins a plan's first support state to where the car is, in m."""
    sigma_start_velocity: float = 0.05
    """Sigma of the prior that pins a plan's first velocity to the car's, in m/s."""
    sigma_goal: float = 0.01
    """Sigma of the prior that pulls a plan's last support state onto the goal, in m."""
    sigma_goal_velocity: float = 0.01
    """Sigma of the prior that makes a plan end at rest, in m/s."""
    sigma_obstacle: float = 0.003
    """Sigma of the obstacle hinge (walls and obstacles), in m. Walls are certain and do not move; peers' plans are guesses when late, and their
    berth (up to eps_0 * g_max) holds margin. So where both cannot be kept -- a wide berth
    around a predicted peer in a narrow street -- a plan gives way to the peer, by
    (sigma_obstacle / sigma_proximity)^2 ~ 1/11 as much into the wall (the proximity guard
    keeps the cars apart)."""
    sigma_proximity: float = 0.01
    """Sigma of the proximity hinge against peers' shared plans, in m."""
    sigma_consistency: float = 0.2
    """Sigma of the consistency residual, in m/s^2."""
    sigma_speed: float = 0.02
    """Sigma of the soft speed limit's hinge (speed above ``max_speed_mps``), in m/s."""
    sigma_lane: float = 0.15
    """Sigma of the pull towards the lane centre line, in m."""
    sigma_sideways: float = 0.005
    """Car-like cars (VehicleConfig.steering = "car"): sigma of the rows that keep a plan's
    velocity along its heading (no sliding sideways, no reversing), in m/s
    (agent.heading_factors)."""
    sigma_turning: float = 0.005
    """Car-like cars: sigma of the row that keeps a plan's turn within what it moves (no
    curve tighter than the turning radius), and of the prior that starts it at the car's
    yaw, in rad."""
    turn_room: bool = False
    """Car-like cars: rows that keep a plan the room to turn away from a peer that stands
    ahead (agent.turn_room). Off by default: on the car-like bank they move deadlocks
    between seeds rather than remove them (docs/design/planner.md, "Car-like cars")."""
    sigma_turn_room: float = 0.02
    """Car-like cars with ``turn_room``: sigma of its rows, in m: twice the proximity
    sigma, so that where both cannot hold the berth wins."""
    keep_right_m: float = 0.1
    """Car-like cars: a peer a plan closes on ahead is seen this far left of the line of
    sight, so that both turn right and pass instead of closing nose to nose
    (agent.keep_right), in m; 0: off. Cars that turn in place never use it."""
    turn_radius_margin: float = 0.15
    """Car-like cars: a plan turns on at least the vehicle's min_turn_radius_m times (1 +
    this), so that the tracker keeps steering to spare for its corrections."""
    max_iterations: int = 30
    """Levenberg-Marquardt iterations a replan's optimisation takes at most."""
    relative_error_tol: float = 1e-3
    """LM stops when an iteration lowers the error by less than this fraction; replanning
    is receding-horizon, so the next replan carries on from here."""
    absolute_error_tol: float = 0.05
    """LM also stops when an iteration lowers the cost (1/2 sum of squared whitened
    residuals) by less than this."""
    lambda_initial: float = 1e-3
    """Levenberg-Marquardt's damping lambda at the first iteration."""
    lambda_factor: float = 10.0
    """Levenberg-Marquardt multiplies lambda by this after a rejected step and divides it
    by this after an accepted one."""
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
    """The proximity factor: plans keep epsilon from peers' shared plans (paper eqs.
    (7)-(9)). Off (experiments): peers are not planned around."""
    consistency: bool = True
    """The consistency factor: a plan's accelerations are pulled down to its peers' (paper
    Sec. III.D), but for a fleet whose every peer is parked at its goal (no pace to keep).
    Off (experiments): no such pull."""
    transparency: bool = True
    """The transparency factor: a peer's epsilon widens as its transparency trust falls
    (paper Sec. III.D). Off (experiments): every peer is kept at eps_0 times
    ``trust.epsilon_gain_fixed``."""

    def validate(self, path: str) -> None:
        if self.support_states < 3:
            raise ConfigError(f"{path}.support_states: must be at least 3")
        if self.interp_checks < 0:
            raise ConfigError(f"{path}.interp_checks: must be >= 0")
        for name in (
            "qc", "min_horizon_s", "cruise_speed_mps", "max_speed_mps", "sigma_start",
            "sigma_start_velocity", "sigma_goal", "sigma_goal_velocity", "sigma_obstacle",
            "sigma_proximity", "sigma_consistency", "sigma_speed", "sigma_lane", "reach_margin_m", "relative_error_tol", "absolute_error_tol", "lambda_initial",
            "sigma_sideways", "sigma_turning", "sigma_turn_room",
        ):
            positive(getattr(self, name), f"{path}.{name}")
        if self.lambda_factor <= 1.0:
            raise ConfigError(f"{path}.lambda_factor: must be > 1")
        if self.intervals_per_factor < 1:
            raise ConfigError(f"{path}.intervals_per_factor: must be >= 1")
        if self.turn_radius_margin < 0:
            raise ConfigError(f"{path}.turn_radius_margin: must be >= 0")
        if not (self.keep_right_m >= 0 and math.isfinite(self.keep_right_m)):
            raise ConfigError(f"{path}.keep_right_m: must be a finite number >= 0")
        if self.max_iterations < 1:
            raise ConfigError(f"{path}.max_iterations: must be >= 1")
        if self.interpolation not in ("batched", "gtsam"):
            raise ConfigError(f"{path}.interpolation: expected 'batched' or 'gtsam'")


@dataclass(frozen=True)
class TrustConfig:
    """Beta reputation per peer and dimension (docs/design/trust.md)."""

    forgetting: float = 0.85
    """lambda per second: evidence of age s weighs lambda**s (0.85: half-life ~4.3 s)."""
    failure_weight: float = 3.0
    """A failure of transparency or safety counts this many successes: a liar is honest
    most of the time."""
    consistency_failure_weight: float = 1.0
    """A car that did not do what it announced half a second ago counts one failure: cars
    replan, and a changed mind is not a lie."""
    prior_alpha: float = 1.0
    """Successes (alpha) of the Beta prior every peer starts from; with prior_beta 0 a
    stranger's trust is tau = 2/3. Forgetting decays every opinion towards the prior."""
    prior_beta: float = 0.0
    """Failures (beta) of the Beta prior every peer starts from."""
    transparency_tolerance_m: float = 0.15
    """A peer seen within this of where its plan says it is at the plan's stamp: a success;
    beyond it: a failure (agent.audit; the plan's future is graded against a tolerance
    that grows with the lag)."""
    plan_reject_m: float = 0.30
    """A shared plan that misses the peer's observed position by more than this is not
    planned against; the last plan that agreed (or the observed motion) is used."""
    consistency_tolerance_mps2: float = 0.6
    """Observed vs planned acceleration mismatch that still counts as consistent."""
    evidence_period_s: float = 0.1
    """How often a car turns what it observes of its peers into safety and consistency
    evidence. A pass counts for its whole period (agent.witness.EVIDENCE_UNIT_S): trust
    grows and forgets at the same pace at any period, and a longer one costs less CPU."""
    stale_after_s: float = 1.0
    """A peer with no plan for this long is predicted from its observed motion and
    kept at the widest epsilon; silence is never counted as lying."""
    testimony_deviation: float = 0.3
    """A testimony whose mean differs from our own direct estimate by more than this (once
    we hold enough direct evidence) is rejected as a lie and counted."""
    testimony_min_evidence: float = 5.0
    """Direct evidence about a peer (successes plus failures beyond the prior) a car must
    hold before it tests testimonies about that peer against its own estimate."""
    epsilon_gain_max: float = 2.0
    """g(tau) ranges from 1 (tau >= tau_full) to this (tau <= tau_floor)."""
    tau_full: float = 0.9
    """Transparency trust at and above which a peer is kept at eps_0 (g = 1)."""
    tau_floor: float = 0.5
    """Transparency trust at and below which a peer is kept at the widest epsilon, eps_0
    times epsilon_gain_max."""
    epsilon_quantile: float = 0.1
    """Epsilon is set by this lower quantile of the transparency belief, not its mean: a
    peer we know little about is kept as far as its 10 % worst case deserves, and only a
    long record of truth earns eps_0 (0.5: about the mean)."""
    reject_plans: bool = True
    """Refuse what cannot be believed: plans that miss where their sender is seen (now or
    when their time comes), stamps from the future, and plans not yet checked are planned
    against at the widest epsilon. Off: every plan is believed as it comes (the paper's
    baseline); evidence and trust are still gathered."""
    clock_tolerance_s: float = 0.5
    """A plan stamped more than this ahead of our clock when it arrives is refused and
    counted (a transparency failure); a peer's clock offset is estimated and corrected
    within +- this."""
    clock_window_s: float = 10.0
    """A peer's clock offset is estimated from the stamps of its messages of this long."""
    audit_period_s: float = 0.2
    """An accepted plan is compared with where its sender is seen every this many seconds
    of its future, as each time comes (agent.audit)."""
    audit_horizon_s: float = 3.0
    """How far past its stamp an accepted plan's future is audited."""
    audit_notice_s: float = 0.5
    """A plan is audited only until this long after its sender's next plan: a car that
    changes its mind and says so this far ahead is not held to its old plan. A car cannot escape the
    audit by planning often: the newest plan at least this old is always held to."""
    audit_grace_s: float = 0.3
    """A future moment is audited only this long after it has been observed, so that a
    newer plan delayed in the network (TCP under loss) has arrived to excuse it."""
    audit_tolerance_growth_mps: float = 0.15
    """The audit's tolerance at lag h is transparency_tolerance_m + h * this (and the
    rejection threshold plan_reject_m + h * this): honest plans' futures change as their
    cars replan."""
    audit_max_plans: int = 32
    """Plans kept per peer for the audit (bounded memory: 5 plans/s over 3 s is 15)."""
    testimony_max_evidence: float = 60.0
    """A testimony counts at most this much evidence per dimension (about what 10 pieces
    a second saturate at with forgetting 0.85: 10 / -ln 0.85 = 62); more is inflation."""
    blame_closing_mps: float = 0.05
    """Of two cars closer than the breach distance, a car is blamed (a safety failure)
    only if it closes the gap faster than this: a car tailgated or stood still is not."""
    standing_seen_s: float = 1.0
    """A distrusted peer (transparency trust below the prior's) seen standing still this
    long (every observation of it within agent.sightings.STANDING_SEEN_M of the newest; 0: off, at most
    the track's 2 s) is planned against where it stands at no more than eps_0, whatever
    its plans say -- with ``planner.transparency`` on, whose widening this undoes. From
    rest a car closes a gap only slowly (1/2 a t^2), and the next replan sees it move
    (docs/design/trust.md, "Seen standing"). A caught liar parked beside a goal otherwise
    closes it for good."""
    epsilon_gain_fixed: float = 1.0
    """g for every peer when the transparency factor is off (planner.transparency = false):
    1 keeps eps_0 from everyone (the paper's baseline); more keeps a uniformly wider berth
    from everyone."""
    testimonies: bool = True
    """Fuse peers' testimonies into what a car believes (docs/design/trust.md,
    "Testimonies"). Off: a car believes its own eyes alone and ignores every trust report
    it hears (it still publishes its own)."""

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
        if not 0.0 < self.epsilon_quantile < 1.0:
            raise ConfigError(f"{path}.epsilon_quantile: must be within (0, 1)")
        if not 0.0 <= self.standing_seen_s <= TRACK_HISTORY_S:
            raise ConfigError(f"{path}.standing_seen_s: must be within [0, {TRACK_HISTORY_S:g}] s (0: off)")
        if self.audit_max_plans < 1:
            raise ConfigError(f"{path}.audit_max_plans: must be >= 1")
        if self.audit_tolerance_growth_mps < 0 or self.blame_closing_mps < 0 or self.audit_grace_s < 0:
            raise ConfigError(f"{path}.audit_tolerance_growth_mps/blame_closing_mps/audit_grace_s: must be >= 0")
        for name in (
            "transparency_tolerance_m", "plan_reject_m", "consistency_tolerance_mps2",
            "evidence_period_s", "stale_after_s", "testimony_deviation", "clock_tolerance_s",
            "clock_window_s", "audit_period_s", "audit_horizon_s", "audit_notice_s", "testimony_max_evidence",
        ):
            positive(getattr(self, name), f"{path}.{name}")


@dataclass(frozen=True)
class VerifyConfig:
    """Every plan is checked before a car uses or publishes it (agent.verify); a plan that
    fails is retried from other starting guesses, and without a verified plan the car
    brakes along its last verified one (agent.safe_plan). docs/design/safety.md, "Verified
    plans"."""

    enabled: bool = True
    """Off (ablations only): plans are used as the optimiser returns them."""
    tolerance: float = 0.25
    """Share of each safety margin a plan may eat: against a peer the margin is
    eps_ab - d_ab (what epsilon keeps beyond the breach distance; 0.15 m for two trusted
    cars of 0.1 m radius, so 0.0375 m may be eaten), against walls it is
    SafetyConfig.obstacle_margin_m (0.0125 m). The soft hinges leave an optimised plan a
    few millimetres inside epsilon where it is pressed; the breach distance itself is
    never eaten (the tolerance is below 1)."""
    sample_m: float = 0.02
    """Check times are spaced so that neither the car nor any peer relative to it moves
    more than about this between two of them; the half step actually travelled is added
    to every distance a sample must keep, so the check holds between samples too."""
    limit_lag_m: float = 0.02
    """How far along its track the car may fall behind (or run ahead of) its plan over
    ``limits_horizon_s`` because the plan asks for more speed or acceleration than the
    vehicle has (VehicleConfig): the lag of a follower held to those limits. Less than
    what the tolerance leaves of any margin (3/4 of 5 cm against walls)."""
    turning_slack_rad: float = 0.15
    """Car-like cars (VehicleConfig.steering = "car"): how much further a plan's heading may
    turn, over any stretch of it, than the turning radius allows over that stretch's
    length, from the car's own heading at its start (agent.steering.turning_excess), in
    rad. A kink of this size costs a car that cuts it on its tightest circle about
    R slack^2 / 8 of the path (under a millimetre at R = 0.3 m), and a start this far off
    its heading about R slack^2 / 2 (3.4 mm): room for sampling and the pose's noise,
    none for a turn the car cannot make."""
    limits_horizon_s: float = 1.0
    """Speed and acceleration are checked over this first part of a plan: what the car
    executes before it has replanned five times. Further on a plan is a promise of path
    and timing that later replans revise (its far end brakes hard into the goal on
    sparse support states); its distances are checked over its whole length."""
    max_attempts: int = 4
    """Plans tried per replan: the warm-started one, then alternatives (agent.safe_plan:
    tightened, the other side of a conflict, slower, cold); then the fallback."""
    retry_iterations: int = 10
    """Levenberg-Marquardt iterations an alternative may take (the first plan takes the
    planner's own ``max_iterations``): retries must fit in a replan's budget."""
    budget_ms: float = 80.0
    """CPU time of the planning thread after which no further alternative is started in a
    replan (the car process; the in-process fleet runs on simulated time and counts
    attempts only). CPU time, not wall time: a process that waits for a core (eight car
    processes on two) still gets its alternatives instead of falling back for lack of
    time, as the in-process fleet does."""
    fallback_decel_mps2: float = 1.0
    """Deceleration of the fallback's braking trajectory (below VehicleConfig's limit, so
    the car can follow it)."""
    swap_first: bool = True
    """Verification holds a peer where its plan ends for good (a parked car stays parked,
    a car waiting on our goal is waited for), but the peer we swap places with -- it
    stands on our goal and its goal is our start (agent.car_agent) -- only ``peer_hold_s``
    past the end of its plan, when we go first (the deadlock watch's order,
    agent.deadlock.goes_first): two such cars, each waiting for the other to leave, would
    stand for good. The hold is for that one peer only: held short, any car standing on
    our goal would be driven at before it has left. Off: every peer is held for good."""
    peer_hold_s: float = 3.0
    """How long past the end of its plan the peer we swap places with is held (swap_first):
    a car that replans five times a second and stops in 0.6 s from top speed needs far
    less; the peer's next plans say where it is."""
    pass_head_on: bool = True
    """A verified plan that backs away from the goal (agent.safe_plan, BACK_M over BACK_S)
    in front of a peer coming head on along our way is tried once more, cold along a via
    point beside the peer's way, on our right; the plan that passes is taken when it
    verifies and does not back away (``pass``, counted as ``head_on_passes``), and the car
    plans without lane keeping for agent.car_agent.PASS_HOLD_S after it. Off: the first
    verified plan is taken as it is, and two cars meeting head on along one line may back
    away from each other for seconds before they pass."""
    keep_s: float = 0.0
    """Keep the plan instead of optimising anew, for up to this long after it was
    optimised, while it still verifies from now against what the car knows now (peers'
    newest plans and epsilons, the walls, the limits) and the car tracks it (docs/design/planner.md,
    "Kept plans"); counted as ``plans_kept``. 0: optimise at every replan. A kept plan is
    checked as strictly as a new one but not improved; what it saves is CPU: most replans
    of a car with a clear way."""

    keep_changed_m: float = 0.0
    """A kept plan goes on only while what its optimisation planned against stands: the
    same peers, each at an epsilon and with a believed plan within this many metres of
    then (over the kept plan's remaining horizon), and the same planned arrival; anything
    else optimises anew (docs/design/planner.md, "Kept plans"). 0: no such check, the plan
    is kept while it verifies."""

    def validate(self, path: str) -> None:
        if self.keep_s < 0:
            raise ConfigError(f"{path}.keep_s: must be >= 0")
        if self.keep_changed_m < 0:
            raise ConfigError(f"{path}.keep_changed_m: must be >= 0")
        if not 0.0 <= self.tolerance < 1.0:
            raise ConfigError(f"{path}.tolerance: must be within [0, 1): the breach distance is never eaten")
        if self.limit_lag_m < 0:
            raise ConfigError(f"{path}.limit_lag_m: must be >= 0")
        if self.max_attempts < 1 or self.retry_iterations < 1:
            raise ConfigError(f"{path}.max_attempts/retry_iterations: must be >= 1")
        for name in ("sample_m", "limits_horizon_s", "budget_ms", "fallback_decel_mps2", "peer_hold_s",
                     "turning_slack_rad"):
            positive(getattr(self, name), f"{path}.{name}")


@dataclass(frozen=True)
class DeadlockConfig:
    """Deadlocks (agent.deadlock): a car that has not come ``progress_m`` nearer its goal
    for ``window_s`` while a peer within ``group_radius_m`` is stuck too, is in a deadlock;
    the car of lower priority gives way."""

    enabled: bool = True
    """Off (ablations only): deadlocks are still detected and counted, not resolved."""
    window_s: float = 3.0
    """How long a car must have come less than progress_m nearer its goal to count as
    stalled: short enough that cars standing in a door for several seconds are seen as
    deadlocked; a car taken for deadlocked while it waits its turn gives way for a moment
    and carries on."""
    progress_m: float = 0.1
    """A car that has come less than this nearer its goal over window_s is stalled."""
    group_radius_m: float = 1.0
    """Peers nearer than this (centres) that are stuck too belong to our group."""
    yield_s: float = 3.0
    """How long a car that gives way keeps its detour before it heads for its goal again."""
    detour_m: float = 0.6
    """How far the detour goal lies from where the car gave way."""
    leave_lane: str = "never"
    """Car-like cars: when a stalled car plans without lane keeping, 3 s at a time:
    "never"; "alone" (no car within group_radius_m is out and about -- parked, waiting and
    stuck cars aside); "nothing-to-wait-for" (no such car is getting somewhere). Off by
    default: measured on the car-like bank, either rule loses about as many runs as it
    gains (docs/design/planner.md, "Leaving the lane when stalled")."""

    def validate(self, path: str) -> None:
        for name in ("window_s", "progress_m", "group_radius_m", "yield_s", "detour_m"):
            positive(getattr(self, name), f"{path}.{name}")
        if self.leave_lane not in LEAVE_LANE:
            raise ConfigError(f"{path}.leave_lane: expected one of {', '.join(map(repr, LEAVE_LANE))}, "
                              f"got {self.leave_lane!r}")
