"""Deadlocks: detected from what a car sees, resolved by a priority rule (decentralised).

Cars that stop for one another can stop for good. Each car watches for it on its own at
every replan, from the poses it observes and the plans it hears: it is deadlocked when
it and every car of its group (peers near it or in its way, not parked, waiting or
stuck) are stalled -- less than ``progress_m`` nearer their goals over ``window_s``. The
car of the group that has been through the most deadlocks, then the lowest id, goes on;
every other drives to a detour for ``yield_s``, clear of the lanes of the cars that go
before it (:func:`lane`). A car parked at its goal that alone walls
a stuck peer in (or, car-like, boxes it in: :func:`boxes_in`) steps aside
(:meth:`DeadlockWatch.step_aside`) until the peer has a way.

A car-like car (VehicleConfig.steering = "car") passes its heading and turning radius:
its way to a detour is the arc that turns it there (agent.steering.departure_arc), not a
turn on the spot, and that arc must keep clear of the walls.

Pure: the caller passes the time and what its car sees. docs/design/safety.md,
"Deadlocks".
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .config import DeadlockConfig
from .fallback import MOVING_MPS  # the fallback's "comes to rest": the same test of a plan's end
from .routes import connected
from .steering import departure_arc, ways_on
from .world import SignedDistanceField

DETOUR_TURNS_DEG = (0.0, 22.5, -22.5, 45.0, -45.0, 67.5, -67.5, 90.0, -90.0, 112.5, -112.5, 135.0, -135.0, 157.5,
                    -157.5)
"""Directions a detour tries, turned from straight away from the cars that go first
(a road's dead end leaves one way out: a step of 22.5 degrees finds it)."""
SEGMENT_SAMPLES = 12
SEEN_S = 0.5
"""Cars seen within this long are what the watch goes by."""
WAITING_S = 0.05
"""A peer whose latest plan starts this much after it was sent has not departed yet."""
WAY_SAMPLES = 20
LANE_STEP_M = 0.05
"""A detour keeps off the straight legs of a way that goes first, checked this often."""
ASIDE_MAX_YIELDS = 4
"""A step aside ends after at most this many ``yield_s``, walled-in peer or not."""


class Sample(NamedTuple):
    """One car at one sample of the watch's window."""

    position: np.ndarray
    goal: np.ndarray | None
    halting: bool
    """Its plan ended at a standstill short of its goal."""
    waiting: bool
    """It had not departed yet (counted in a car-like fleet only: :meth:`DeadlockWatch._record`)."""


@dataclass(frozen=True)
class PeerSeen:
    """What the watch needs of a peer: where it is, and whether it may stand still."""

    position: np.ndarray
    at_goal: bool = False
    waiting: bool = False
    """Not departed yet (its plan starts in the future)."""
    goal: np.ndarray | None = None
    """Its goal, as its plan messages name it (None: not heard yet)."""
    way: np.ndarray | None = None
    """Points (k, 2) of where it means to go (its plan, its goal); a car that gives way to
    it moves away from the nearest of them."""
    halting: bool = False
    """Its plan ends at a standstill short of its goal: it found no way on."""
    stuck: bool = False
    """It says it is told to drive and does not move (agent.messages.PlanMessage.stuck)."""
    deadlocks: int = 0
    """How many deadlocks it says it has been through (agent.messages.PlanMessage.deadlocks)."""
    heading: float | None = None
    """Its yaw as seen (None: not known)."""


@dataclass
class Detour:
    goal: np.ndarray
    until: float
    for_peer: int | None = None
    """A step aside: the walled-in peer it makes way for (held while the peer needs it)."""
    home: np.ndarray | None = None
    """... and the goal we stepped aside from."""
    latest: float = 0.0
    """... and the latest it ends."""
    walls: tuple[int, ...] = ()
    """... and the cars that stood (not parked) and walled it in with us."""


@dataclass
class DeadlockWatch:
    car_id: int
    config: DeadlockConfig
    history: deque = field(default_factory=deque)
    """(t, {car id: Sample}) at the replans of the last window."""
    detour: Detour | None = None
    deadlocked: bool = False
    deadlocks: int = 0
    yields: int = 0
    steps_aside: int = 0
    been_through: int = 0
    """Deadlocks over (our detour driven; or, going first, our group moving again): the
    order's age, told to the peers in our plan messages."""

    def goal(self, now: float, position: np.ndarray, goal: np.ndarray, peers: dict[int, PeerSeen], departed: bool,
             keep_clear: float, sdf: SignedDistanceField, wall_clear: float,
             blockers: frozenset[int] = frozenset(), steering: tuple[float, float] | None = None) -> np.ndarray | None:
        """Record what we see now; the detour goal to plan to while we give way, else None.

        ``blockers``: peers our last plans failed verification against (they belong to
        our group however far away, like a car that stands on our goal);
        ``keep_clear``: how far a detour goal must stay from every car we see (centres);
        ``wall_clear``: from every wall (centre to surface), along the way there too;
        ``steering``: a car-like car's (heading, turning radius), whose way there turns
        on that radius (None: a car that turns in place goes straight)."""
        if self.detour is not None:
            if now < self.detour.until or self._still_needed(now, peers, keep_clear, sdf, wall_clear, steering):
                return self.detour.goal
            if self.detour.for_peer is None:
                self.been_through += 1  # we gave way, and drove our detour
            self.detour = None
            self.history.clear()  # a fresh window before the next detection
        self._record(now, position, goal, peers, steering, waiting=not departed)
        group = self.group(now, peers, blockers) if departed else []
        if not group:
            if self.deadlocked:
                self.been_through += 1  # we went first, and our group moves again
            self.deadlocked = False
            return None
        if not self.deadlocked:
            self.deadlocked = True
            self.deadlocks += 1
        first = [cid for cid in group if goes_first(peers[cid].deadlocks, cid, self.been_through, self.car_id)]
        if not first or not self.config.enabled:
            return None  # we go first (or resolution is off): keep trying for the goal
        goal = detour_goal(position, [_way(peers[cid]) for cid in first], _everyone(peers), self.config.detour_m,
                           keep_clear, sdf, wall_clear, steering)
        if goal is None:
            return None
        self.detour = Detour(goal, now + self.config.yield_s)
        self.deadlocked = False
        self.yields += 1
        return goal

    def step_aside(self, now: float, position: np.ndarray, goal: np.ndarray, peers: dict[int, PeerSeen],
                   keep_clear: float, sdf: SignedDistanceField, wall_clear: float,
                   steering: tuple[float, float] | None = None) -> np.ndarray | None:
        """For a car parked at its goal: record what we see; where to step aside to when we
        wall in a stalled peer (docs/design/safety.md, "Deadlocks"), else None;
        ``steering`` as for :meth:`goal`."""
        if self.detour is not None and self.detour.for_peer is not None and now < self.detour.until:
            return self.detour.goal
        self._record(now, position, goal, peers, steering)
        if not self.config.enabled:
            return None
        position = np.asarray(position, float)
        stuck = {cid for cid in peers if self.stuck(cid, now)}  # once: each reads the whole window
        # The peers that stand where they are, walls to the others: parked at their goals,
        # waiting to depart, stuck (as they say, or as the window saw them).
        standing = [cid for cid, p in sorted(peers.items()) if p.at_goal or p.waiting or p.stuck or cid in stuck]
        for cid, peer in sorted(peers.items()):
            if peer.at_goal or peer.waiting or peer.stuck or peer.goal is None or cid not in stuck:
                continue
            walls = [(tuple(peers[other].position), keep_clear) for other in standing if other != cid]
            pressed = (float(np.linalg.norm(peer.position - position)) < keep_clear
                       or boxes_in(position, peer, walls, keep_clear, sdf, wall_clear, steering))
            if not pressed and connected(sdf, peer.position, peer.goal, wall_clear,
                                         [*walls, (tuple(position), keep_clear)]):
                continue
            if not connected(sdf, peer.position, peer.goal, wall_clear, walls):
                continue  # walled in, but not by us alone
            aside = _aside_goal(position, peer, walls, _everyone(peers), self.config.detour_m, keep_clear, sdf,
                                wall_clear, steering)
            if aside is None:
                continue
            stood = tuple(other for other in standing if other != cid and not peers[other].at_goal)
            self.detour = Detour(aside, now + self.config.yield_s, cid, np.array(position),
                                 now + ASIDE_MAX_YIELDS * self.config.yield_s, stood)
            self.steps_aside += 1
            return aside
        return None

    def _still_needed(self, now: float, peers: dict[int, PeerSeen], keep_clear: float, sdf: SignedDistanceField,
                      wall_clear: float, steering: tuple[float, float] | None = None) -> bool:
        """Whether a step aside holds on: its peer is not at its goal and, were we back
        home, would have no way there past the parked cars and the cars that walled it in
        with us, where they are now, or (car-like cars) would be boxed in by us where it
        stands (up to ``Detour.latest``)."""
        detour = self.detour
        if detour is None or detour.for_peer is None or now >= detour.latest:
            return False
        peer = peers.get(detour.for_peer)
        if peer is None or peer.at_goal or peer.goal is None:
            return False
        walls = [(tuple(p.position), keep_clear) for cid, p in peers.items()
                 if cid != detour.for_peer and (p.at_goal or cid in detour.walls)]
        return (boxes_in(detour.home, peer, walls, keep_clear, sdf, wall_clear, steering)
                or not connected(sdf, peer.position, peer.goal, wall_clear, [*walls, (tuple(detour.home), keep_clear)]))


    def _record(self, now: float, position: np.ndarray, goal: np.ndarray, peers: dict[int, PeerSeen],
                steering: tuple[float, float] | None, waiting: bool = False) -> None:
        """One sample of the window: where we (``waiting``: not departed yet) and every peer
        are, with their goals, whether their plans halt and, in a car-like fleet
        (``steering`` given), whether they wait to depart: a car-like car that gives way just
        after setting off can drive into a neighbour still waiting and have no way on. A
        fleet that turns in place keeps the window its bank was measured with
        (docs/design/safety.md, "Deadlocks")."""
        car_like = steering is not None
        ours = Sample(np.asarray(position, float), np.asarray(goal, float), False, car_like and waiting)
        theirs = {cid: Sample(p.position, p.goal, p.halting, car_like and p.waiting) for cid, p in peers.items()}
        self.history.append((now, {self.car_id: ours} | theirs))
        while self.history and self.history[0][0] < now - self.config.window_s - 1e-9:
            self.history.popleft()

    def group(self, now: float, peers: dict[int, PeerSeen], blockers: frozenset[int] = frozenset()) -> list[int]:
        """The peers near us or in our way (not at their goals, not waiting to depart),
        when we and every one of them are stalled -- if one of them is getting somewhere,
        we are waiting for it, not deadlocked (else empty)."""
        if not self.stalled(self.car_id, now):
            return []
        near = self._out_near(peers, blockers)
        if not all(self.stalled(cid, now) for cid in near):
            return []
        return sorted(near)

    def leaves_lane(self, now: float, peers: dict[int, PeerSeen]) -> bool:
        """Whether we, stalled, plan without our lane (DeadlockConfig.leave_lane): "alone",
        no car within group_radius_m is out and about (parked, waiting and stuck cars
        aside); "nothing-to-wait-for", every such car is stalled too."""
        rule = self.config.leave_lane
        if rule == "never" or not self.stalled(self.car_id, now):
            return False
        near = self._out_near(peers)
        return not near if rule == "alone" else all(self.stalled(cid, now) for cid in near)

    def _out_near(self, peers: dict[int, PeerSeen], blockers: frozenset[int] = frozenset()) -> list[int]:
        """The peers out and about (not at their goals, waiting or stuck) within
        group_radius_m of where we were last recorded, or among ``blockers``."""
        here = self.history[-1][1][self.car_id].position
        return [cid for cid, p in peers.items() if not (p.at_goal or p.waiting or p.stuck)
                and (cid in blockers or np.linalg.norm(p.position - here) <= self.config.group_radius_m)]

    def stalled(self, car_id: int, now: float) -> bool:
        """Came less than progress_m nearer its goal over a whole window (moved less than
        that, for a car whose goal we do not know), seen at every sample of it and, in a
        car-like fleet, driving at every one: one that waited to depart in the window stood
        by its schedule."""
        if not self._window_full(now):
            return False
        track = [seen.get(car_id) for _, seen in self.history]
        if any(entry is None or entry.waiting for entry in track):
            return False
        (first, goal, _, _), (latest, latest_goal, _, _) = track[0], track[-1]
        if goal is not None and latest_goal is not None and np.array_equal(goal, latest_goal):
            progress = float(np.linalg.norm(first - goal) - np.linalg.norm(latest - goal))
            return progress < self.config.progress_m
        return max(float(np.linalg.norm(entry.position - latest)) for entry in track) < self.config.progress_m

    def stuck(self, car_id: int, now: float) -> bool:
        """Stalled, or halting (its plans ending short of its goal) at every sample of a
        whole window."""
        if self.stalled(car_id, now):
            return True
        return self._window_full(now) and all(car_id in seen and seen[car_id].halting for _, seen in self.history)

    def _window_full(self, now: float) -> bool:
        """Whether the history spans a whole window (give or take a replan)."""
        return bool(self.history) and self.history[0][0] <= now - self.config.window_s + 0.25


def peers_seen(tracks: dict, views: dict, own_id: int, now: float, arrival_radius_m: float) -> dict[int, PeerSeen]:
    """What the watch needs of every car we saw lately (``tracks``: agent.sightings.Track by
    id), with what we heard from it (``views``: agent.evidence.PeerView by id)."""
    seen = {}
    for car_id, track in tracks.items():
        motion = track.motion()
        if car_id == own_id or motion is None or now - motion.stamp > SEEN_S:
            continue
        view = views.get(car_id)
        goal = None if view is None or view.goal is None else np.asarray(view.goal, float)
        at_goal = goal is not None and float(np.linalg.norm(motion.position - goal)) <= arrival_radius_m
        waiting = bool(view and view.latest is not None and view.latest.plan.t0 > view.latest.stamp + WAITING_S)
        way, halting = None, False
        if view is not None and view.accepted is not None:
            plan = view.accepted
            way = plan.position_at(np.linspace(now, max(now, plan.t_end), WAY_SAMPLES))
            way = way if goal is None else np.vstack([way, goal])
            halting = (goal is not None and plan.n > 0 and float(np.linalg.norm(plan.velocities[-1])) < MOVING_MPS
                       and float(np.linalg.norm(plan.positions[-1] - goal)) > arrival_radius_m)
        stuck = bool(view and view.latest is not None and view.latest.stuck)
        deadlocks = view.latest.deadlocks if view is not None and view.latest is not None else 0
        seen[car_id] = PeerSeen(motion.position, at_goal, waiting, goal, way, halting, stuck, deadlocks, motion.yaw)
    return seen


def goes_first(been_through: int, car_id: int, other_been_through: int, other_id: int) -> bool:
    """Whether a car goes before another in a deadlock: the one that has been through more
    deadlocks, and of two that have been through as many, the lower id."""
    return (-been_through, car_id) < (-other_been_through, other_id)


def _everyone(peers: dict[int, PeerSeen]) -> list[np.ndarray]:
    """What a detour keeps clear of besides the ways: every car seen, and every peer's
    goal we know -- a car that gives way onto another's goal walls that one out of it (two
    cars that each gave way onto the other's goal would stand there for good)."""
    return [p.position for p in peers.values()] + [p.goal for p in peers.values() if p.goal is not None]


def _way(peer: PeerSeen) -> np.ndarray:
    """Where the peer is and means to go: its position, then its way (k, 2)."""
    return peer.position[None, :] if peer.way is None else np.vstack([peer.position, peer.way])


def detour_goal(position: np.ndarray, ways: list[np.ndarray], everyone: list[np.ndarray], distance: float,
                keep_clear: float, sdf: SignedDistanceField, wall_clear: float,
                steering: tuple[float, float] | None = None) -> np.ndarray | None:
    """A point ``distance`` from ``position`` as directly away from the nearest points of
    ``ways`` (of the cars that go first) as walls and cars allow, and ``keep_clear`` off
    those ways (:func:`lane`) and every car seen; None when every direction tried is blocked."""
    position = np.asarray(position, float)
    nearest = [way[int(np.argmin(np.linalg.norm(way - position, axis=1)))] for way in ways]
    away = sum(((position - p) / max(float(np.linalg.norm(position - p)), 1e-6) for p in nearest), np.zeros(2))
    avoid = np.vstack([*(lane(way, sdf) for way in ways), *everyone]) if ways or everyone else np.zeros((0, 2))
    return _first_clear(position, away, DETOUR_TURNS_DEG, distance, avoid, keep_clear, sdf, wall_clear,
                        steering=steering)


def lane(way: np.ndarray, sdf: SignedDistanceField, step: float = LANE_STEP_M) -> np.ndarray:
    """The points a car whose ``way`` (k, 2) goes first will drive over: the way with each
    leg between two of its points filled in every ``step``, up to where a leg first meets a
    wall (beyond it the car goes round, by a route we do not know). A car that stands
    has a way of its position and its goal: the straight between them is its lane, and a
    car that gives way must not stand on it."""
    way = np.asarray(way, float)
    points = [way[:1]]
    for a, b in zip(way[:-1], way[1:]):
        count = int(math.ceil(float(np.linalg.norm(b - a)) / step))
        if count <= 1:
            points.append(b[None, :])
            continue
        leg = a + np.linspace(0.0, 1.0, count + 1)[1:, None] * (b - a)
        inside = np.flatnonzero(sdf.distance(leg) < 0.0)
        if len(inside):
            points.append(leg[:inside[0]])
            break
        points.append(leg)
    return np.vstack(points)


def boxes_in(position: np.ndarray, peer: PeerSeen, walls: list, keep_clear: float, sdf: SignedDistanceField,
             wall_clear: float, steering: tuple[float, float] | None) -> bool:
    """Whether a car standing at ``position`` alone boxes a car-like ``peer`` in: every
    way the peer can set off on (agent.steering.ways_on, at the fleet's turning radius)
    comes nearer it than ``keep_clear``, a car of ``walls`` ((centre, radius) discs) or a
    wall nearer than ``wall_clear``, and some way would be open were it not there. A car
    that cannot turn in place or reverse, stopped close beside a parked car and facing
    past it, has no way on however open the room is. False for a fleet that turns in
    place (``steering`` None) or a peer whose heading is not known."""
    if steering is None or peer.heading is None:
        return False
    ways = ways_on(peer.position, peer.heading, steering[1])
    ours = [(tuple(np.asarray(position, float)), keep_clear)]
    return not any(_open(way, [*walls, *ours], sdf, wall_clear) for way in ways) and any(
        _open(way, walls, sdf, wall_clear) for way in ways)


def _open(way: np.ndarray, discs: list, sdf: SignedDistanceField, wall_clear: float) -> bool:
    """Whether the points of ``way`` keep ``wall_clear`` from the walls and out of every
    (centre, radius) of ``discs``."""
    if float(np.min(sdf.distance(way))) < wall_clear:
        return False
    return all(float(np.min(np.linalg.norm(way - np.asarray(centre), axis=1))) >= radius for centre, radius in discs)


def _aside_goal(position: np.ndarray, peer: PeerSeen, parked: list, everyone: list[np.ndarray], distance: float,
                keep_clear: float, sdf: SignedDistanceField, wall_clear: float,
                steering: tuple[float, float] | None = None) -> np.ndarray | None:
    """A point ``distance`` from ``position``, reached along a clear segment and
    ``keep_clear`` off every car seen, from where we neither wall ``peer`` in nor (car-like
    cars) box it in (first straight away from it, then turning); None if there is none."""
    others = np.array([p for p in everyone if np.linalg.norm(p - position) > 1e-6]).reshape(-1, 2)
    return _first_clear(position, position - peer.position, DETOUR_TURNS_DEG + (180.0,), distance, others,
                        keep_clear, sdf, wall_clear,
                        lambda goal: not boxes_in(goal, peer, parked, keep_clear, sdf, wall_clear, steering)
                        and connected(sdf, peer.position, peer.goal, wall_clear, [*parked, (tuple(goal), keep_clear)]),
                        steering)


def _first_clear(position: np.ndarray, away: np.ndarray, turns: tuple[float, ...], distance: float,
                 avoid: np.ndarray, keep_clear: float, sdf: SignedDistanceField, wall_clear: float,
                 accept=lambda goal: True, steering: tuple[float, float] | None = None) -> np.ndarray | None:
    """The first point ``distance`` from ``position``, in the direction ``away`` turned by
    each of ``turns`` (degrees) in order, whose way there keeps ``wall_clear`` from the
    walls, that keeps ``keep_clear`` from every point of ``avoid`` and that ``accept``s.
    The way is straight, or for a car-like car (``steering``: heading, turning radius) the
    arc that turns it to face the point, then straight."""
    base = math.atan2(away[1], away[0]) if np.linalg.norm(away) > 1e-6 else 0.0
    for turn in turns:
        angle = base + math.radians(turn)
        goal = position + distance * np.array([math.cos(angle), math.sin(angle)])
        way = _way_to(position, goal, steering)
        if np.min(sdf.distance(way)) < wall_clear:
            continue
        if len(avoid) and np.min(np.linalg.norm(avoid - goal, axis=1)) < keep_clear:
            continue
        if accept(goal):
            return goal
    return None


def _way_to(position: np.ndarray, goal: np.ndarray, steering: tuple[float, float] | None) -> np.ndarray:
    """Points of the way from ``position`` to ``goal``: straight, or with a car-like car's
    ``steering`` (heading, turning radius) its departure arc, then straight, then on as
    far again as the car's turning circle is wide -- a car that cannot turn standing needs
    that room ahead of where it stops to drive anywhere from there."""
    start = position
    arc = np.zeros((0, 2))
    if steering is not None:
        arc = departure_arc(position, steering[0], goal, steering[1])
        if len(arc):
            start = arc[-1]
    way = np.vstack([arc, start + np.linspace(0.0, 1.0, SEGMENT_SAMPLES)[1:, None] * (goal - start)])
    length = float(np.linalg.norm(goal - start))
    if steering is None or length < 1e-9:
        return way
    ahead = goal + np.linspace(0.0, 2.0 * steering[1], SEGMENT_SAMPLES)[1:, None] * (goal - start) / length
    return np.vstack([way, ahead])
