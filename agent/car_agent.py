"""One car's mind: what it sees, what it believes of its peers, what it plans and what it shares.

Pure logic, no I/O: the in-process fleet and the car process hand it observations and
messages, and ask it for plans and reports (times: seconds, fleet clock). Four steps:

* see: :meth:`CarAgent.observe` keeps every car's sightings (agent.sightings);
* believe: :meth:`CarAgent.receive` takes peers' plans and testimonies (agent.evidence),
  and :meth:`CarAgent.gather_evidence` audits and judges them (agent.witness);
* plan: :meth:`CarAgent.replan` plans against the believed peers at the epsilon their
  trust earns, verified, with its fallback (agent.safe_plan, agent.deadlock);
* share: :meth:`CarAgent.plan_message` and :meth:`CarAgent.trust_message`.

docs/design/trust.md, "Which plan is believed" and "Seen standing"; docs/design/planner.md,
"Replanning and consensus" and "Kept plans".
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .attacks import Liar
from .config import CarConfig, Scenario
from .deadlock import DeadlockWatch, goes_first, peers_seen
from .evidence import PeerView, belief, take_plan
from .gp import Plan, standing
from .messages import PlanMessage, TrustReport
from .planner import PeerConstraint, PlanningError, PlanRequest, PlanResult
from .safe_plan import FALLBACK, FIRST, KEPT, RETRY, Outcome, plan_safely
from .sight import out_of_sight, unseen_epsilon
from .sightings import Track, predicted_plan, standing_at
from .steering import MOVING_MPS, held_to, turn_then
from .trust import TrustBook
from .verify import Bounds, verify
from .witness import Witness, recorder
from .world import SignedDistanceField

log = logging.getLogger(__name__)

PASS_HOLD_S = 3.0
"""How long after a pass of a peer head on (agent.safe_plan) the car plans without lane
keeping, so that the next replans keep to the side it passes on."""
ARRIVAL_SLACK_S = 1.0
"""Added to path length / cruise speed: time to speed up and slow down."""
WARM_GOAL_M = 0.25
"""A plan that ends further than this from the goal does not warm-start a replan."""
START_FROM_PLAN_M = 0.05
START_FROM_PLAN_MPS = 0.15
"""A replan starts from the previous plan while the car is this close to it."""


@dataclass
class CarAgent:
    car: CarConfig
    scenario: Scenario
    sdf: SignedDistanceField
    depart_at: float = 0.0
    """When the car may start moving (fleet clock)."""
    cruise_speed_mps: float | None = None
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    """Drives this car's attack only (seeded by the caller)."""
    clock: Callable[[], float] | None = None
    """Clock of the replan budget (VerifyConfig.budget_ms) in the car process: the
    planning thread's CPU time; None in the in-process fleet, whose replans take no
    simulated time (attempts only)."""

    def __post_init__(self) -> None:
        self.tracks: dict[int, Track] = {}
        self.peers: dict[int, PeerView] = {}
        self.sight_range = self.scenario.sensing_range(self.car)
        """How far this car sees its peers, m (inf: everywhere; agent.sight)."""
        self.trust = TrustBook(owner=self.car.id, config=self.scenario.trust,
                               limited_sight=math.isfinite(self.sight_range))
        self.plan: Plan | None = None
        self.last_result: PlanResult | None = None
        self.verified: Plan | None = None
        """The last plan that passed verification: a fallback brakes along it."""
        self.last_outcome: Outcome | None = None
        self._optimised_at: float | None = None
        """When the current plan was optimised and verified (None: it was not, or the car
        has given way since): a plan is kept at most ``verify.keep_s`` after that."""
        self._optimised_against: dict[int, PeerConstraint] = {}
        """What the current plan was optimised against, by peer (for kept plans)."""
        self._optimised_arrival = math.nan
        self._lane_off_until = -math.inf
        """Until when lane keeping is off: we pass a peer head on (agent.safe_plan, ``pass``), or
        a stalled car-like car (DeadlockConfig.leave_lane; off by default)."""
        self.deadlock = DeadlockWatch(self.car.id, self.scenario.deadlock)
        self.replan_ms: deque = deque(maxlen=100_000)  # bounded: a lab run may last hours
        self.counters: Counter = Counter()
        self.at_goal = False
        self._seq = Counter()
        self.witness = Witness(self.car.id, self.scenario, self.sdf, self.radius)
        self.radii = {c.id: c.radius_m for c in self.scenario.cars}
        self.liar = None
        if self.car.attack is not None:
            partners = frozenset(c.id for c in self.scenario.cars if c.id != self.car.id and c.attack is not None
                                 and "collude" in c.attack.names)
            self.liar = Liar(self.car.id, self.car.attack, self.rng, partners,
                             tolerance_m=self.scenario.trust.plan_reject_m,
                             horizon_s=self.scenario.trust.audit_notice_s + self.scenario.control.replan_period_s)
        self.set_departure(self.depart_at, self.cruise_speed_mps or self.scenario.planner.cruise_speed_mps)

    def set_departure(self, depart_at: float, cruise_speed_mps: float) -> None:
        """When the car may set off and how fast it cruises (the operator's start)."""
        self.depart_at = depart_at
        self.cruise = cruise_speed_mps
        points = np.array([self.car.start, *self.car.route, self.car.goal])
        length = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
        self.t_arrive = depart_at + length / cruise_speed_mps + ARRIVAL_SLACK_S

    # --- inputs -----------------------------------------------------------------------------

    def observe(self, t: float, car_id: int, x: float, y: float, yaw: float) -> None:
        """A pose of any car (ourselves included), e.g. from NatNet."""
        self.tracks.setdefault(car_id, Track()).add(t, x, y, yaw)

    def receive(self, message: PlanMessage | TrustReport, now: float) -> None:
        """A decoded, validated message from a peer (``now``: when it arrived)."""
        if message.sender == self.car.id:
            return
        view = self.view(message.sender)
        if isinstance(message, TrustReport):
            view.clock.add(message.stamp, now)
            self.trust.receive(message, now)
            return
        take_plan(view, message, now, self.tracks.get(message.sender), recorder(self.trust, message.sender, now),
                  self.counters)

    def view(self, peer: int) -> PeerView:
        if peer not in self.peers:
            self.peers[peer] = PeerView(self.scenario.trust, self.scenario.control.replan_period_s)
        return self.peers[peer]

    def clock_offsets(self) -> dict[int, float]:
        """Every peer's estimated clock offset (its clock minus ours), seconds."""
        return {peer: view.clock.offset for peer, view in self.peers.items() if view.clock.samples}

    def peer_gone(self, peer: int) -> None:
        """The peer's process left the bus (liveliness lost): stop believing its last plan
        now rather than after stale_after_s; it is predicted from what we see of it."""
        view = self.peers.get(peer)
        if view is not None:
            view.accepted_received = -np.inf
            self.counters["peers_gone"] += 1

    # --- evidence ---------------------------------------------------------------------------

    def next_evidence_at(self) -> float:
        """When gather_evidence will next gather (it is rate-limited)."""
        return self.witness.next_at()

    def gather_evidence(self, now: float) -> None:
        """Safety and consistency evidence about every seen peer, and the audits of their
        plans (rate-limited: agent.witness.Witness)."""
        self.witness.gather(now, self.tracks, self.peers, self.trust, self.counters)

    def _look(self, now: float) -> frozenset[int]:
        """The peers out of sight now (limited sight; none with unlimited sight): planned
        against never as if fully trusted (docs/design/trust.md, "Limited sight")."""
        if not self.trust.limited_sight:
            return frozenset()
        return out_of_sight(self.tracks, (c.id for c in self.scenario.cars), self.car.id, now)

    # --- planning ---------------------------------------------------------------------------

    def radius(self, car_id: int) -> float:
        """A car's radius (a car the scenario does not know is taken to be our size)."""
        return self.radii.get(car_id, self.car.radius_m)

    def epsilon_0(self, peer: int) -> float:
        """The distance we keep from a fully trusted ``peer`` (SafetyConfig)."""
        return self.scenario.safety.epsilon_0(self.car.radius_m, self.radius(peer))

    def peer_constraints(self, now: float) -> list[tuple[int, PeerConstraint]]:
        """Every peer we plan around, with the plan we believe and the distance to keep."""
        planner, trust = self.scenario.planner, self.scenario.trust
        constraints = []
        unseen = self._look(now)
        for peer in sorted(set(self.peers) | set(self.tracks)):
            if peer == self.car.id:
                continue
            view = self.peers.get(peer)
            believed = belief(view, now) if view else None
            widest = self.epsilon_0(peer) * max(trust.epsilon_gain_max, trust.epsilon_gain_fixed)
            if believed is not None:
                plan, verified = believed
                if peer in unseen:  # its plan cannot be checked by us: as its witnesses trust it, never fully
                    self.counters["peers_out_of_sight"] += 1
                    epsilon = max(self.trust.epsilon(peer, now, self.epsilon_0(peer), planner.transparency),
                                  unseen_epsilon(self.epsilon_0(peer), trust))
                elif verified or not trust.reject_plans:
                    epsilon = self.trust.epsilon(peer, now, self.epsilon_0(peer), planner.transparency)
                else:
                    self.counters["peers_unverified"] += 1  # not checked yet: not as if trusted
                    epsilon = widest
            else:
                plan, epsilon = predicted_plan(self.tracks.get(peer), now, trust.stale_after_s), widest
                if plan is None:
                    continue
                self.counters["peers_predicted"] += 1
            if (trust.standing_seen_s > 0 and planner.transparency and epsilon > self.epsilon_0(peer)
                    and self.trust.distrusted(peer, now)):
                stands_at = standing_at(self.tracks.get(peer), now, trust.standing_seen_s, trust.stale_after_s)
                if stands_at is not None:  # where it is seen, at eps_0 (docs/design/trust.md, "Seen standing")
                    self.counters["peers_seen_standing"] += 1
                    plan, epsilon = standing(stands_at, now), self.epsilon_0(peer)
            done = parked(view, self.tracks.get(peer), plan, now,
                          self.scenario.arrival_radius_m + self.scenario.deadlock.detour_m)
            constraints.append((peer, PeerConstraint(plan, epsilon, self._hold(peer), done)))
        return constraints

    def _hold(self, peer: int) -> float | None:
        """How long verification holds ``peer`` where its plan ends (None: for good). For
        good, but for a peer we swap places with -- it stands on our goal, and its goal is
        our start, each within eps_0 -- when we go first (the deadlock watch's order:
        agent.deadlock.goes_first): then for VerifyConfig.peer_hold_s
        (VerifyConfig.swap_first). Each waiting for the other to leave, the two would wait
        for ever; the one that goes first sets off, and the other, whose plan now meets a
        moving one, follows."""
        if not self.scenario.verify.swap_first:
            return None
        view, track = self.peers.get(peer), self.tracks.get(peer)
        seen = track.motion() if track else None
        if view is None or view.goal is None or seen is None:
            return None
        heard = view.latest.deadlocks if view.latest is not None else 0
        if not goes_first(self.deadlock.been_through, self.car.id, heard, peer):
            return None
        reach = self.epsilon_0(peer)
        on_our_goal = float(np.linalg.norm(seen.position - np.asarray(self.car.goal, float))) <= reach
        to_our_start = float(np.linalg.norm(np.asarray(view.goal, float) - np.asarray(self.car.start, float))) <= reach
        return self.scenario.verify.peer_hold_s if on_our_goal and to_our_start else None

    def replan(self, now: float) -> PlanResult | None:
        """Plan from our observed state; None if we cannot (no pose yet, or at the goal)."""
        own = self.tracks.get(self.car.id)
        motion = own.motion() if own else None
        if motion is None:
            self.counters["replan_no_pose"] += 1
            return None
        goal = np.asarray(self.car.goal, dtype=float)
        if self.at_goal or (np.linalg.norm(motion.position - goal) <= self.scenario.tracking.goal_tolerance_m
                            and now >= self.depart_at):
            self.at_goal = True
            if self._step_aside(now, motion.position, held_to(self.scenario.vehicle, motion.yaw)) is None:
                self.plan = standing(motion.position, now)
                return None
            self.at_goal = False  # parked across a peer's only way: the detour below, then back
        t0 = max(now, self.depart_at)
        position, velocity, on_plan = self._start_state(motion, t0, now)
        steering = held_to(self.scenario.vehicle, motion.yaw)
        remaining = remaining_length(self.plan, self.car, motion.position, t0, steering)
        # A car that yielded is behind schedule: its arrival slips so that it goes on at
        # its cruise speed instead of racing to catch up (a car-like car's by the turn it
        # has to make first, too).
        self.t_arrive = max(self.t_arrive, t0 + remaining / self.cruise + 0.5 * ARRIVAL_SLACK_S)
        t_arrive = self.t_arrive
        constraints = self.peer_constraints(now)
        request = PlanRequest(
            t_now=t0, position=position, velocity=velocity, goal=goal, t_arrive=t_arrive,
            epsilon_obstacle=self.scenario.safety.epsilon_obstacle(self.car.radius_m),
            peers=tuple(c for _, c in constraints), warm_start=self.plan, route=self.car.route,
            lane=(self.car.start, *self.car.route), steering=steering,
        )
        detour = self._give_way(now, motion.position, request.steering)
        if detour is not None:  # giving way in a deadlock (agent.deadlock): to the detour instead
            request = dataclasses.replace(request, goal=detour, route=(), lane=(), t_arrive=t0 + ARRIVAL_SLACK_S
                                          + float(np.linalg.norm(detour - motion.position)) / self.cruise)
        elif now < self._lane_off_until:  # passing a peer head on, or stalled (car-like)
            request = dataclasses.replace(request, lane=())
        if self.liar is not None and now >= self.depart_at:  # a framer drives where it means harm
            request, constraints = self.liar.steer(request, constraints, now, self._seen(now))
            request = dataclasses.replace(request, peers=tuple(c for _, c in constraints))
        kept = self._keep(now, t0, on_plan, request, constraints, detour)
        if kept is not None:
            self._use(kept)
            return kept.result
        # Warm-start from the previous plan, or, when that one went elsewhere (a fallback
        # stops short, a detour), from the last verified plan if that one goes to the goal.
        warm = next((plan for plan in (self.plan, self.verified) if plan is not None
                     and np.linalg.norm(plan.positions[-1] - request.goal) <= WARM_GOAL_M), None)
        request = dataclasses.replace(request, warm_start=warm)
        try:
            outcome = plan_safely(request, self._bounds([peer for peer, _ in constraints]), self.scenario.planner,
                                  self.scenario.verify, self.sdf, self.verified, self.clock,
                                  self.scenario.control.lease_s / 2 if self.clock else None)
        except PlanningError as exc:
            self.counters["replan_failed"] += 1
            log.warning("car %d: replanning failed, keeping the previous plan: %s", self.car.id, exc)
            return None
        self._use(dataclasses.replace(outcome, blocked_by=tuple(constraints[i][0] for i in outcome.blocked_by)))
        self._optimised_at = now if outcome.outcome in (FIRST, RETRY) and detour is None else None
        self._optimised_against = {peer: c for peer, c in constraints}
        self._optimised_arrival = self.t_arrive
        if outcome.tried and outcome.tried[-1] == "pass":  # hold the pass: no lane to pull us back in front of the peer
            self._lane_off_until = now + PASS_HOLD_S
            self.counters["head_on_passes"] += 1  # a retry (plans_retry) that passes a peer met head on
        return outcome.result

    def _keep(self, now: float, t0: float, on_plan: bool, request: PlanRequest, constraints: list,
              detour: np.ndarray | None) -> Outcome | None:
        """The current plan, verified again from ``t0``, if it may be kept (docs/design/planner.md,
        "Kept plans"); else None: optimise. ``on_plan``: the car tracks it
        (:meth:`_start_state` starts from it; never before the departure)."""
        config = self.scenario.verify
        plan = self.plan
        if (config.keep_s <= 0 or not config.enabled or not on_plan or plan is not self.verified
                or self._optimised_at is None or now - self._optimised_at > config.keep_s
                or detour is not None or self.liar is not None
                or np.linalg.norm(plan.positions[-1] - request.goal) > WARM_GOAL_M
                or self._changed_since_optimised(t0, constraints)):
            return None
        started = time.perf_counter()
        verdict = verify(plan, request.peers, self._bounds([peer for peer, _ in constraints]), self.sdf, config,
                         t_from=t0, start_heading=request.heading)
        if not verdict.ok:
            return None
        result = PlanResult(plan, 0, math.nan, math.nan, (time.perf_counter() - started) * 1e3, True)
        return Outcome(plan, KEPT, result, verdict, ("kept",))

    def _changed_since_optimised(self, t0: float, constraints: list) -> bool:
        """Has what the current plan was optimised against changed by more than
        ``verify.keep_changed_m`` (a peer in or out of reach, an epsilon, a believed plan
        over the rest of our plan's horizon) or has the planned arrival slipped?"""
        tolerance = self.scenario.verify.keep_changed_m
        if tolerance <= 0:
            return False
        then = self._optimised_against
        if self.t_arrive != self._optimised_arrival or {peer for peer, _ in constraints} != set(then):
            return True
        times = self.plan.times()
        times = times[times >= t0]
        for peer, current in constraints:
            was = then[peer]
            if abs(current.epsilon - was.epsilon) > tolerance or current.hold_s != was.hold_s:
                return True
            if current.plan is not was.plan and len(times) and float(np.max(np.linalg.norm(
                    current.plan.position_at(times) - was.plan.position_at(times), axis=1))) > tolerance:
                return True
        return False

    def _give_way(self, now: float, position: np.ndarray, steering: tuple[float, float] | None) -> np.ndarray | None:
        """The deadlock watch (agent.deadlock) on what we see: a detour goal while we give
        way, else None (``steering``: a car-like car's, agent.steering.held_to); a stalled
        car-like car's lane off for PASS_HOLD_S when DeadlockConfig.leave_lane says so.
        Counts ``deadlocks`` and ``deadlock_yields``."""
        seen = peers_seen(self.tracks, self.peers, self.car.id, now, self.scenario.arrival_radius_m)
        safety, r = self.scenario.safety, self.car.radius_m
        blockers = frozenset(self.last_outcome.blocked_by) if self.last_outcome else frozenset()
        detour = self.deadlock.goal(now, position, np.asarray(self.car.goal, float), seen, now >= self.depart_at,
                                    safety.epsilon_0(r, r), self.sdf, safety.epsilon_obstacle(r), blockers, steering)
        if steering is not None and now >= self.depart_at and self.deadlock.leaves_lane(now, seen):
            self._lane_off_until = now + PASS_HOLD_S  # stalled (deadlock.leave_lane): the lane gives way
        for name, count in (("deadlocks", self.deadlock.deadlocks), ("deadlock_yields", self.deadlock.yields)):
            if count:
                self.counters[name] = count
        return detour

    def _step_aside(self, now: float, position: np.ndarray, steering: tuple[float, float] | None) -> np.ndarray | None:
        """Parked at our goal: where to step aside to when we wall a stalled peer in
        (agent.deadlock), else None. Counts ``deadlock_steps_aside``."""
        seen = peers_seen(self.tracks, self.peers, self.car.id, now, self.scenario.arrival_radius_m)
        safety, r = self.scenario.safety, self.car.radius_m
        aside = self.deadlock.step_aside(now, position, np.asarray(self.car.goal, float), seen,
                                         safety.epsilon_0(r, r), self.sdf, safety.epsilon_obstacle(r), steering)
        if self.deadlock.steps_aside:
            self.counters["deadlock_steps_aside"] = self.deadlock.steps_aside
        return aside

    def _bounds(self, peers: list[int]) -> Bounds:
        """What our plans must keep from the walls and from each of ``peers`` (SafetyConfig)."""
        safety, r = self.scenario.safety, self.car.radius_m
        return Bounds.of(safety.epsilon_obstacle(r), safety.obstacle_breach(r),
                         [safety.breach_distance(r, self.radius(p)) for p in peers], self.scenario.vehicle)

    def _use(self, outcome: Outcome) -> None:
        """Adopt a replan's outcome and count it (``plans_first``, ``plans_retry``,
        ``plans_fallback``, ``plans_unverified``; ``peers_out_of_reach`` of the plan adopted)."""
        self.counters[f"plans_{outcome.outcome}"] += 1
        if outcome.outcome != FALLBACK:
            self.verified = outcome.plan
        self.plan = outcome.plan
        self.last_outcome = outcome
        self.last_result = outcome.result
        self.counters["peers_out_of_reach"] += outcome.result.peers_out_of_reach
        self.replan_ms.append(outcome.result.time_ms)

    def _start_state(self, motion, t0: float, now: float) -> tuple[np.ndarray, np.ndarray, bool]:
        """Where the new plan starts, and whether that is on our plan: our previous plan's
        state at t0 while we track it closely (the reference stays continuous across
        replans, so the car does not jerk at every replan), else the measured state."""
        if now < self.depart_at:
            return motion.position, np.zeros(2), False
        if self.plan is not None:
            (p,), (v,) = self.plan.state_at(t0)
            if (np.linalg.norm(p - motion.position) <= START_FROM_PLAN_M
                    and np.linalg.norm(v - motion.velocity) <= START_FROM_PLAN_MPS):
                return p, v, True
        self.counters["replan_from_measured"] += 1
        return motion.position, motion.velocity, False

    # --- outputs ----------------------------------------------------------------------------

    def carry_over(self, before: "CarAgent") -> None:
        """Take over what ``before`` -- this car's mind in the last trial, or while it
        waited for the go -- knows of the fleet: the poses it saw, its views of the peers
        (their plans, clocks and audits) and its trust in them. A new trial gives the car a
        new plan, not a new memory: the evidence gathered while the fleet waited for the
        go counts (cars that start inside one another's widest epsilon, strangers still,
        plan away from each other at the go), and a liar caught in one trial is no
        stranger in the next. Our messages are numbered on from ``before``'s: the peers'
        inboxes take a sequence that starts over only as a restarted sender's, after 2 s
        of its messages dropped as replays."""
        self._seq = Counter(before._seq)
        self.tracks, self.peers, self.trust = before.tracks, before.peers, before.trust

    def next_seq(self, kind: str) -> int:
        self._seq[kind] += 1
        return self._seq[kind]

    def plan_message(self, now: float) -> PlanMessage | None:
        """Our plan as we share it (falsified if this car is set to misinform)."""
        if self.plan is None:
            return None
        shared, stamp = self.plan, now
        if self.liar is not None:
            shared, stamp = self.liar.plan(self.plan, now, self._motion(self.car.id, now), self._seen(now))
        return PlanMessage(self.car.id, self.next_seq("plan"), stamp, shared,
                           (float(self.car.goal[0]), float(self.car.goal[1])), deadlocks=self.deadlock.been_through)

    def _motion(self, car_id: int, now: float):
        track = self.tracks.get(car_id)
        motion = track.motion() if track else None
        return motion if motion is not None and now - motion.stamp <= self.scenario.trust.stale_after_s else None

    def _seen(self, now: float) -> dict:
        """The fresh observed motion of every other car."""
        seen = {car_id: self._motion(car_id, now) for car_id in self.tracks if car_id != self.car.id}
        return {car_id: m for car_id, m in seen.items() if m is not None}

    def trust_message(self, now: float) -> TrustReport:
        report = self.trust.report(self.car.id, self.next_seq("trust"), now, self.epsilon_0, self.scenario.planner.transparency)
        return self.liar.testimony(report) if self.liar is not None else report

    def trust_in(self, peer: int, now: float) -> float:
        return self.trust.trust(peer, now)


def parked(view: PeerView | None, track: Track | None, plan: Plan, now: float, reach: float) -> bool:
    """Whether a peer is done driving: what is left of its plan from ``now`` stands, and it
    is seen within ``reach`` of the goal it told us (the arrival radius plus
    DeadlockConfig.detour_m, so a car that stepped aside from its goal for another counts
    as parked too)."""
    motion = track.motion() if track else None
    if view is None or view.goal is None or motion is None:
        return False
    ahead = plan.velocities[plan.times() >= now - plan.dt]
    if len(ahead) and float(np.max(np.linalg.norm(ahead, axis=1))) >= MOVING_MPS:
        return False
    return float(np.linalg.norm(motion.position - np.asarray(view.goal, float))) <= reach


def remaining_length(plan: Plan | None, car: CarConfig, position: np.ndarray, t0: float,
                     steering: tuple[float, float] | None = None) -> float:
    """How far ``car`` still drives from ``position``: along ``plan`` from t0 (one that
    stops short leaves the rest straight to the goal), or with no plan along the route; a
    car-like car's (``steering``) turn first (agent.steering.turn_then)."""
    if plan is None:
        points = np.array([position, *car.route, car.goal])
    else:
        times = np.linspace(t0, max(plan.t_end, t0), 30)
        points = np.vstack([position, plan.position_at(times), car.goal])
    if steering is not None:
        points = turn_then(points, *steering)
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
