"""One replan made safe: optimise, verify, try other starting guesses, else brake.

Every plan the optimiser returns is verified (agent.verify) before the car uses or
publishes it. A plan that fails is not executed; the planner tries again from other
starting guesses, cheapest first -- ``tighten``, ``around``, ``other side``, ``retimed``,
``slower``, ``off lane``, ``cold`` (:func:`_next_attempt` picks the order from what the
plan broke) -- until one verifies, ``VerifyConfig.max_attempts`` plans have been tried,
or (in the car process) ``budget_ms`` of CPU time or ``wall_limit_s`` of wall time has
gone. When nothing verifies, the car commits to the fallback (agent.fallback). Counting
the outcomes per car is the caller's job (agent.car_agent).

Pure: the budget's clock is passed in (None in the in-process fleet, which counts
attempts only, so a run stays exactly repeatable from its seed). docs/design/safety.md,
"Verified plans".
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .config import PlannerConfig, VerifyConfig
from .fallback import fallback
from .gp import Plan
from .planner import PlanningError, PlanRequest, PlanResult, plan_trajectory
from .retime import retime
from .routes import NoRoute, path_length, plan_route
from .verify import Bounds, Conflict, Verdict, verify
from .world import SignedDistanceField

FIRST, RETRY, FALLBACK, UNVERIFIED, KEPT = "first", "retry", "fallback", "unverified", "kept"
"""Outcomes of a replan (counted per car as ``plans_<outcome>``); KEPT: the previous plan,
verified again and not optimised (agent.car_agent, VerifyConfig.keep_s)."""
SLOWER_HORIZON = 1.5
"""The ``slower`` alternative's horizon, as a multiple of the failed one."""
BUMP_WIDTH_S = 1.0
"""Standard deviation in time of the ``other side`` displacement."""
SIDE_CLEAR_M = 0.02
"""A plan this close to a peer's track goes round it on the left."""
OBSTACLE_PUSH_M = 0.05
"""``other side`` of a wall pushes this much further out than the plan lacks."""
TIGHTEN_PAD = 1.25
"""``tighten`` raises a broken epsilon by this times how far it was broken."""
TIGHTEN_RADIUS = 1.25
"""... and a car-like car's turning radius by this factor when its plan turned too tight."""
STANDING_M = 0.05
"""A peer whose plan moves it less than this over its span stands (``around``)."""
AROUND_MARGIN_M = 0.05
"""``around`` keeps this beyond a standing peer's epsilon (the hinges settle a little
inside it)."""
AROUND_COMFORT_M = 0.1
"""... and this beyond every clearance where the way is wide enough."""
BACK_S = 1.0
"""A plan backs away when, this long after now, it is BACK_M further from its goal than
the car is now."""
BACK_M = 0.05
HEAD_ON_LATERAL_M = 0.3
"""A peer comes head on when it is within its epsilon and this of our straight way to the
goal, ahead of us, and closing in on us."""
PASS_MARGIN_M = 0.1
"""``pass`` puts its via point this beyond the peer's epsilon from the peer's way."""


@dataclass(frozen=True)
class Outcome:
    plan: Plan
    outcome: str
    """FIRST, RETRY, FALLBACK or UNVERIFIED (verification switched off)."""
    result: PlanResult
    """The optimiser's result behind ``plan`` (for a fallback: the last one tried, with
    the braking plan in it); ``time_ms`` is the whole replan's, checks included."""
    verdict: Verdict | None
    """The check of ``plan`` (a fallback is checked too, for the record)."""
    tried: tuple[str, ...]
    """The starting guesses tried, in order."""
    blocked_by: tuple[int, ...] = ()
    """Peers (indices of ``request.peers``; ids once the agent has them) that a plan of
    this replan failed verification against."""
    first_broke: tuple[str, ...] = ()
    """What the first plan tried broke, when it failed verification: the kinds of its
    conflicts ('limits', 'obstacle', 'peer'), sorted; empty when it passed (or raised)."""


def plan_safely(request: PlanRequest, bounds: Bounds, planner: PlannerConfig, config: VerifyConfig,
                sdf: SignedDistanceField, last_verified: Plan | None,
                clock: Callable[[], float] | None = None, wall_limit_s: float | None = None) -> Outcome:
    """Plan, verify, retry, else brake along ``last_verified``; raise PlanningError only
    for a car state that is not finite. ``clock``: CPU time for ``config.budget_ms``;
    ``wall_limit_s``: no new attempt after this much wall time (None: no limit)."""
    started = time.perf_counter()
    if not (np.all(np.isfinite(request.position)) and np.all(np.isfinite(request.velocity))
            and math.isfinite(request.t_now)):
        raise PlanningError("the car's state must be finite")
    if not config.enabled:
        result = plan_trajectory(request, planner, sdf)
        return Outcome(result.plan, UNVERIFIED, result, None, ("warm" if request.warm_start else "cold",))
    tried: list[str] = []
    blocked: set[int] = set()
    first_broke: tuple[str, ...] = ()
    last: PlanResult | None = None
    name = "warm" if request.warm_start is not None else "cold"
    attempt: PlanRequest | None = request
    budget_start = clock() if clock else 0.0
    retry_planner = dataclasses.replace(planner, max_iterations=min(planner.max_iterations, config.retry_iterations))
    while attempt is not None:
        tried.append(name)
        try:
            if name == "retimed":  # a guess to check as it is, not to optimise (it would undo the pace)
                result = PlanResult(attempt.warm_start, 0, math.nan, math.nan, 0.0, True)
            else:
                result = plan_trajectory(attempt, planner if len(tried) == 1 else retry_planner, sdf)
        except PlanningError:
            result = None
        if result is not None:
            last = result
            verdict = verify(result.plan, request.peers, bounds, sdf, config,
                             start_speed=float(np.linalg.norm(request.velocity)), start_heading=request.heading)
            if verdict.ok:
                outcome = FIRST if len(tried) == 1 else RETRY
                if outcome == FIRST and config.pass_head_on:
                    passed = _pass_head_on(request, result, bounds, retry_planner, sdf, config)
                    if passed is not None:
                        tried.append("pass")
                        return Outcome(passed[0].plan, RETRY, _timed(passed[0], started), passed[1], tuple(tried))
                return Outcome(result.plan, outcome, _timed(result, started), verdict, tuple(tried),
                               tuple(sorted(blocked)), first_broke)
            blocked.update(c.peer for c in verdict.conflicts if c.kind == "peer")
            if len(tried) == 1:
                first_broke = tuple(sorted({c.kind for c in verdict.conflicts}))
        else:
            verdict = None
        if (len(tried) >= config.max_attempts or (clock and (clock() - budget_start) * 1e3 > config.budget_ms)
                or (wall_limit_s is not None and time.perf_counter() - started > wall_limit_s)):
            break
        name, attempt = _next_attempt(request, tried, last, verdict, sdf, bounds)
    plan, verdict = fallback(last_verified, request, bounds, sdf, config)
    base = last or PlanResult(plan, 0, math.nan, math.nan, 0.0, request.warm_start is not None)
    return Outcome(plan, FALLBACK, _timed(dataclasses.replace(base, plan=plan), started), verdict, tuple(tried),
                   tuple(sorted(blocked)), first_broke)


def backs_away(plan: Plan, request: PlanRequest) -> bool:
    """Whether ``plan`` is BACK_M further from the goal BACK_S from now than the car is."""
    here = float(np.linalg.norm(request.position - request.goal))
    (later,) = plan.position_at(np.array([request.t_now + BACK_S]))
    return float(np.linalg.norm(later - request.goal)) > here + BACK_M


def head_on(request: PlanRequest) -> int | None:
    """The nearest peer ahead of us on our straight way to the goal (within its epsilon +
    HEAD_ON_LATERAL_M of it) that closes in on us, as its plan has it now; else None."""
    way = request.goal - request.position
    length = float(np.linalg.norm(way))
    if length < 1e-6:
        return None
    along = way / length
    best = None
    for i, peer in enumerate(request.peers):
        (q,), (w,) = peer.plan.state_at(np.array([request.t_now]))
        offset = q - request.position
        ahead = float(along @ offset)
        lateral = abs(float(along[0] * offset[1] - along[1] * offset[0]))
        closing = float(w @ offset) < 0.0
        if 0.0 < ahead < length and lateral < peer.epsilon + HEAD_ON_LATERAL_M and closing:
            if best is None or ahead < best[0]:
                best = (ahead, i)
    return None if best is None else best[1]


def _pass_head_on(request: PlanRequest, backing: PlanResult, bounds: Bounds, planner: PlannerConfig,
                  sdf: SignedDistanceField, config: VerifyConfig) -> tuple[PlanResult, Verdict] | None:
    """A plan that passes the peer coming head on, on our right, when ``backing`` backs
    away in front of it; None when it does not, or no such plan verifies and goes on."""
    if not backs_away(backing.plan, request):
        return None
    index = head_on(request)
    if index is None:
        return None
    peer = request.peers[index]
    (q,) = peer.plan.position_at(np.array([request.t_now]))
    along = (request.goal - request.position) / np.linalg.norm(request.goal - request.position)
    right = np.array([along[1], -along[0]])
    meet = request.position + along * float(along @ (q - request.position)) * 0.5
    via = meet + right * (peer.epsilon + PASS_MARGIN_M)
    if sdf.distance_and_gradient(via)[0] < request.epsilon_obstacle:
        return None
    attempt = dataclasses.replace(request, warm_start=None, route=((float(via[0]), float(via[1])),), lane=())
    try:
        result = plan_trajectory(attempt, planner, sdf)
    except PlanningError:
        return None
    verdict = verify(result.plan, request.peers, bounds, sdf, config,
                     start_speed=float(np.linalg.norm(request.velocity)), start_heading=request.heading)
    if not verdict.ok or backs_away(result.plan, request):
        return None
    return result, verdict


def _timed(result: PlanResult, started: float) -> PlanResult:
    return dataclasses.replace(result, time_ms=(time.perf_counter() - started) * 1e3)


def _next_attempt(request: PlanRequest, tried: list[str], failed: PlanResult | None,
                  verdict: Verdict | None, sdf: SignedDistanceField, bounds: Bounds) -> tuple[str, PlanRequest | None]:
    """The next starting guess not tried yet, cheapest first (None: none left). A car-like
    car's plan that only turns too tight is tightened (a wider radius) and then made anew:
    keeping its path (``retimed``) keeps the turn."""
    conflicts = verdict.conflicts if verdict else ()
    distance = [c for c in conflicts if c.kind in ("obstacle", "peer")]
    turning = any(c.kind == "turning" for c in conflicts)
    limits_only = bool(conflicts) and not distance and not turning
    order = (["retimed", "slower", "off lane", "cold"] if limits_only
             else ["tighten", "cold", "off lane", "slower"] if turning and not distance
             else ["tighten", "around", "other side", "slower", "cold"])
    for name in order:
        if name in tried:
            continue
        if name == "retimed" and failed is not None:
            speed = float(np.linalg.norm(request.velocity))
            return name, dataclasses.replace(request, warm_start=retime(failed.plan, speed, bounds.max_speed_mps,
                                                                        bounds.max_accel_mps2))
        if name == "tighten" and failed is not None and (distance or turning):
            return name, tightened(request, failed.plan, list(conflicts))
        if name == "around" and distance:
            way = around_standing(request, distance, sdf)
            if way is not None:
                return name, way
        if name == "other side" and failed is not None and distance:
            return name, dataclasses.replace(request, warm_start=other_side(failed.plan, distance[0], request, sdf))
        if name == "off lane" and request.lane:
            return name, dataclasses.replace(request, warm_start=None, lane=())
        if name == "cold":
            return name, dataclasses.replace(request, warm_start=None)
        if name == "slower":
            horizon = max(request.t_arrive - request.t_now, 0.0)
            return name, dataclasses.replace(request, warm_start=None,
                                             t_arrive=request.t_now + SLOWER_HORIZON * horizon)
    return "", None


def tightened(request: PlanRequest, failed: Plan, conflicts: list[Conflict]) -> PlanRequest:
    """The request with every broken epsilon raised by TIGHTEN_PAD times how far it was
    broken (and a car-like car's turning radius by TIGHTEN_RADIUS when it turned too
    tight), warm-started from the failed plan."""
    extra = {c.peer: c.excess for c in conflicts if c.kind == "peer"}
    peers = tuple(dataclasses.replace(p, epsilon=p.epsilon + TIGHTEN_PAD * extra[i]) if i in extra else p
                  for i, p in enumerate(request.peers))
    wall = max((c.excess for c in conflicts if c.kind == "obstacle"), default=0.0)
    steering = request.steering
    if steering is not None and any(c.kind == "turning" for c in conflicts):
        steering = (steering[0], steering[1] * TIGHTEN_RADIUS)
    return dataclasses.replace(request, peers=peers, warm_start=failed, steering=steering,
                               epsilon_obstacle=request.epsilon_obstacle + TIGHTEN_PAD * wall)


def stands_still(plan: Plan, since: float) -> bool:
    """Whether ``plan`` moves its car less than STANDING_M from ``since`` on."""
    times = np.linspace(max(since, plan.t0), max(since, plan.t_end), 12)
    positions = plan.position_at(times)
    return float(np.max(np.linalg.norm(positions - positions[0], axis=1))) < STANDING_M


def around_standing(request: PlanRequest, conflicts: list[Conflict], sdf: SignedDistanceField) -> PlanRequest | None:
    """The request cold along a route round every standing peer, when one of them is among
    ``conflicts``; None when none is, or no route keeps the clearances."""
    still = [i for i, peer in enumerate(request.peers) if stands_still(peer.plan, request.t_now)]
    if not any(c.kind == "peer" and c.peer in still for c in conflicts):
        return None
    keep_out = [(tuple(np.ravel(request.peers[i].plan.position_at(request.t_now))),
                 request.peers[i].epsilon + AROUND_MARGIN_M) for i in still]
    clearance = request.epsilon_obstacle
    try:
        route = plan_route(sdf, None, request.position, request.goal, clearance, clearance + AROUND_COMFORT_M, keep_out)
    except NoRoute:
        return None
    before = path_length(np.array([request.position, *request.route, request.goal], dtype=float))
    after = path_length(np.array([request.position, *route, request.goal], dtype=float))
    horizon = max(request.t_arrive - request.t_now, 0.0) * max(1.0, after / max(before, 1e-6))
    return dataclasses.replace(request, warm_start=None, route=route, lane=(), t_arrive=request.t_now + horizon)


def other_side(plan: Plan, conflict: Conflict, request: PlanRequest, sdf: SignedDistanceField) -> Plan:
    """``plan`` displaced sideways around the time of ``conflict`` so that it passes on the
    other side: of a peer, mirrored across the peer's track to the peer's epsilon (sideways
    to the motion relative to it); of a wall, pushed out by what it lacks, to the side the
    distance field rises (to the left where that is not clear, as in the middle of a
    pillar a straight route crosses). Faded in and out with a Gaussian bump in time; the
    start stays where the car is."""
    p = np.array(conflict.position)
    (v,) = plan.state_at(conflict.t)[1]
    if conflict.kind == "peer":
        q = np.array(conflict.other)
        peer = request.peers[conflict.peer]
        (w,) = peer.plan.state_at(conflict.t)[1]
        relative = v - w
    else:
        relative = v
    left = np.array([-relative[1], relative[0]])
    left = left / np.linalg.norm(left) if np.linalg.norm(left) > 1e-6 else np.array([0.0, 1.0])
    if conflict.kind == "peer":
        offset = float(left @ (p - q))  # which side of the peer we pass, and how far
        side = 1.0 if offset >= 0.0 else -1.0
        if abs(offset) < SIDE_CLEAR_M:
            side = -1.0  # straight through it: the mirror of a pass to its right is to its left
        shift = left * (-side * peer.epsilon - offset)
    else:
        _, gradient = sdf.distance_and_gradient(p)
        lateral = float(left @ gradient)
        side = np.sign(lateral) if abs(lateral) > 0.3 else 1.0
        shift = left * side * (conflict.excess + OBSTACLE_PUSH_M)
    t = plan.times()
    weight = np.exp(-0.5 * ((t - conflict.t) / BUMP_WIDTH_S) ** 2)
    weight[0] = 0.0
    rate = -(t - conflict.t) / BUMP_WIDTH_S**2 * weight
    rate[0] = 0.0
    return Plan(plan.t0, plan.dt, plan.positions + weight[:, None] * shift,
                plan.velocities + rate[:, None] * shift)
