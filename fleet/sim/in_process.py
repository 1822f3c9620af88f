"""The fleet in one process: fast, deterministic per seed, with the real parts inside.

Every car is a :class:`CarAgent` (the planner and trust code the car process runs) driving
a simulated unicycle (agent.vehicle) through the control step of bridge.drive. Cars see
each other through noisy pose observations and talk through the fleet message codec, each
receiver's Inbox, over a :class:`Network` with latency, jitter and loss (``[sim]``). Time
is simulated: a replan takes none, so a run repeats exactly from its seed. A car with
``clock_offset_s`` reads every time off its own clock, as a car computer with a wrong
clock would. The cars stand ``sim.settle_s`` at their starts before the go, as ``trustfg
sim``'s do; per seed each draws a start delay, a cruise speed (:func:`draw_departures`,
which ``trustfg sim`` uses too) and a replanning phase. docs/design/experiments.md, "The
in-process fleet".
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from ...agent import messages
from ...agent.car_agent import CarAgent
from ...agent.config import Scenario, SimConfig
from ...agent.gp import standing
from ...agent.sight import sight_matrix
from ...agent.vehicle import VehicleState
from ...agent.vehicle import step as vehicle_step
from ...agent.world import SignedDistanceField, build_sdf
from ...bridge.drive import drive
from .run_record import RunRecord

RECORD_TRUST_PERIOD_S = 0.1


def draw_departures(scenario: Scenario, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Per car, a start delay U(0, start_delay_max_s) and a cruise speed
    U(cruise_speed_range_mps), drawn in that order from ``rng``."""
    n = len(scenario.cars)
    delay = rng.uniform(0.0, scenario.sim.start_delay_max_s, n)
    cruise = rng.uniform(*scenario.sim.cruise_speed_range_mps, n)
    return delay, cruise


def simulate(scenario: Scenario, seed: int, sdf: SignedDistanceField | None = None,
             keep_plans: bool = False, record_trust: bool = True) -> RunRecord:
    """Run the scenario to completion (every car at its goal) or to sim.timeout_s.
    ``record_trust=False`` leaves the trust matrices over time out of the record (they
    cost O(n^2) trust fusions every RECORD_TRUST_PERIOD_S, much of a large fleet's run)."""
    fleet = _Fleet(scenario, seed, sdf, keep_plans, record_trust)
    for k in range(-fleet.settle_steps, fleet.steps):
        if fleet.step(k):
            break
    return fleet.record()


class _Fleet:
    """One run of :func:`simulate`: the cars set up from the seed, stepped through the
    world one command period at a time (:meth:`step`), and what was recorded (:meth:`record`)."""

    def __init__(self, scenario: Scenario, seed: int, sdf: SignedDistanceField | None,
                 keep_plans: bool, record_trust: bool):
        """Set up the cars: departures, speeds and phases drawn from ``seed``, minds, bodies
        and the network, and the empty record."""
        self.scenario, self.seed, self.keep_plans, self.record_trust = scenario, seed, keep_plans, record_trust
        sim = scenario.sim
        self.sdf = sdf or build_sdf(scenario.world)
        rng = np.random.default_rng(seed)
        self.cars = cars = list(scenario.cars)
        self.n = n = len(cars)
        self.ids = [c.id for c in cars]
        self.depart, self.cruise = draw_departures(scenario, rng)
        self.control = control = scenario.control
        self.step_s = step_s = 1.0 / control.command_rate_hz
        spread = control.replan_period_s if sim.replan_phase_max_s is None else sim.replan_phase_max_s
        phase = rng.uniform(0.0, spread, n)
        self.noise_rng = np.random.default_rng([seed, 7])

        # The cars stand sim.settle_s before the go, as trustfg sim's do: minds that wait
        # (depart_at = inf), each replaced at the go by one that drives and carries over what
        # its predecessor learnt (CarAgent.carry_over, as the car process does at a start).
        self.settle_steps = int(round(sim.settle_s / step_s))
        self.agents = self._minds(np.full(n, math.inf) if self.settle_steps else self.depart)
        self.waited: list[CarAgent] = []  # the minds that stood the wait (their liars' lies are the run's too)
        self.inboxes = [messages.Inbox() for _ in cars]
        self.vehicles = [VehicleState(c.start[0], c.start[1], c.start_heading) for c in cars]

        self.clock = np.array([c.clock_offset_s for c in cars])  # each car's clock minus the fleet's
        self.ranges = [scenario.sensing_range(c) for c in cars]
        self.limited = not all(math.isinf(r) for r in self.ranges)
        """Some car sees only the peers near it (SensingConfig): its mind and guard get theirs alone."""
        self.sight = np.ones((n, n), dtype=bool)
        """sight[j, i]: car j sees car i now."""
        self.network = Network(sim, n, np.random.default_rng([seed, 11]))

        self.steps = int(math.ceil(sim.timeout_s / step_s)) + 1
        self.times, self.states = [], []
        self.trust_times, self.trust_rows, self.transparency_rows, self.epsilon_rows = [], [], [], []
        self.arrived: list[float | None] = [None] * n
        self.guard_limited = [0] * n
        self.tracking_error: list[list[float]] = [[] for _ in range(n)]
        self.plan_log: list = []
        # Replans and reports keep their phase to the go through the wait.
        self.next_replan = phase - math.ceil(sim.settle_s / control.replan_period_s) * control.replan_period_s
        self.next_report = rng.uniform(0.0, control.trust_report_period_s, n)
        self.next_report -= math.ceil(sim.settle_s / control.trust_report_period_s) * control.trust_report_period_s
        self.next_trust_record = -math.floor(sim.settle_s / RECORD_TRUST_PERIOD_S + 1e-9) * RECORD_TRUST_PERIOD_S

    def _minds(self, departures) -> list[CarAgent]:
        return [CarAgent(car=c, scenario=self.scenario, sdf=self.sdf, depart_at=float(departures[i]),
                         cruise_speed_mps=float(self.cruise[i]), rng=np.random.default_rng([self.seed, c.id]))
                for i, c in enumerate(self.cars)]

    def step(self, k: int) -> bool:
        """Step k of the world (k < 0: the wait before the go); whether every car is at its
        goal and still."""
        t = k * self.step_s
        going = t >= -1e-9
        if k == 0 and self.settle_steps:  # the go
            self.waited, self.agents = self.agents, self._minds(self.depart)
            for i, agent in enumerate(self.agents):
                agent.carry_over(self.waited[i])
        own = t + self.clock  # every car's own reading of the time
        self._deliver(t, own)
        seen = self._observe(own)
        self._think(t, own, going)
        if self.record_trust and t + 1e-9 >= self.next_trust_record:  # trust from the start of the wait
            self.next_trust_record += RECORD_TRUST_PERIOD_S
            self.trust_times.append(t)
            tr, tp, ep = _trust_snapshot(self.agents, self.ids, own)
            self.trust_rows.append(tr)
            self.transparency_rows.append(tp)
            self.epsilon_rows.append(ep)
        if not going:
            return False  # the cars stand; their motion's record starts at the go
        return self._move(t, own, seen)

    def _deliver(self, t: float, own: np.ndarray) -> None:
        """1. Deliver due messages through each receiver's inbox (decode + order/replay filter)."""
        for sender, receiver, payload in self.network.due(t):
            message = self.inboxes[receiver].accept(payload, key_sender=self.ids[sender])
            if message is not None:
                self.agents[receiver].receive(message, own[receiver])

    def _observe(self, own: np.ndarray) -> np.ndarray:
        """2. Everyone sees everyone (mocap), with noise, or with a sensing range the peers
        within it (``sight``, from where the cars truly are); seen[j, i]: car i as car j sees it."""
        n, ids = self.n, self.ids
        if self.limited:
            sdf = self.sdf if self.scenario.sensing.line_of_sight else None
            self.sight = sight_matrix([(s.x, s.y) for s in self.vehicles], self.ranges, sdf)
        seen = np.empty((n, n, 3))
        for i, state in enumerate(self.vehicles):
            noisy = self.noise_rng.normal(0.0, self.scenario.sim.observation_noise_m, (n, 2))
            seen[:, i] = np.column_stack([state.x + noisy[:, 0], state.y + noisy[:, 1], np.full(n, state.yaw)])
            for j, agent in enumerate(self.agents):
                if self.sight[j, i]:
                    agent.observe(own[j], ids[i], *seen[j, i])
        return seen

    def _think(self, t: float, own: np.ndarray, going: bool) -> None:
        """3. Evidence, replanning, reports."""
        control, network, ids = self.control, self.network, self.ids
        for i, agent in enumerate(self.agents):
            agent.gather_evidence(own[i])
            if t + 1e-9 >= self.next_replan[i]:
                self.next_replan[i] += control.replan_period_s
                if going:
                    agent.replan(own[i])
                elif (motion := agent.tracks[ids[i]].motion()) is not None:
                    agent.plan = standing(motion.position, own[i])  # waiting: as fleet.car.process
                if self.keep_plans and agent.plan is not None:
                    self.plan_log.append((t, i, agent.plan))
                outgoing = agent.plan_message(own[i])
                if outgoing is not None:
                    network.publish(i, messages.encode(outgoing), t)
            if t + 1e-9 >= self.next_report[i]:
                self.next_report[i] += control.trust_report_period_s
                network.publish(i, messages.encode(agent.trust_message(own[i])), t)

    def _move(self, t: float, own: np.ndarray, seen: np.ndarray) -> bool:
        """4. Record, then control and move; whether every car is at its goal and still."""
        scenario, cars, vehicles, ids, n = self.scenario, self.cars, self.vehicles, self.ids, self.n
        self.times.append(t)
        self.states.append([[s.x, s.y, s.yaw, s.v, s.omega] for s in vehicles])
        for i, agent in enumerate(self.agents):
            state = vehicles[i]
            if self.arrived[i] is None and \
                    math.hypot(state.x - cars[i].goal[0], state.y - cars[i].goal[1]) <= scenario.arrival_radius_m:
                self.arrived[i] = t
            me = agent.tracks[ids[i]].motion()
            others = [(*seen[i, j], cars[j].radius_m) for j in range(n) if j != i and self.sight[i, j]]
            command = drive(agent.plan, own[i], (me.position[0], me.position[1], me.yaw),
                            own[i] >= self.depart[i] and not agent.at_goal, lambda: others, cars[i].radius_m,
                            scenario, self.sdf)
            self.guard_limited[i] += command.guard_limited
            if not (command.stop or command.guard_limited):  # how closely the car follows its plan
                (p,) = agent.plan.position_at(np.array([own[i]]))
                self.tracking_error[i].append(math.hypot(state.x - p[0], state.y - p[1]))
            vehicles[i] = vehicle_step(state, command.v, command.omega, self.step_s, scenario.vehicle)
        return all(a is not None for a in self.arrived) and all(abs(s.v) < 1e-3 for s in vehicles)

    def _lying_minds(self, i: int) -> list[CarAgent]:
        """Car i's minds that lie, in order: the one that waited, the one that drove."""
        return [mind for mind in (*self.waited[i:i + 1], self.agents[i]) if mind.liar is not None]

    def record(self) -> RunRecord:
        """What the run recorded, with every car's counters and its last plan."""
        agents, network, n = self.agents, self.network, self.n
        return RunRecord(
            seed=self.seed,
            car_ids=self.ids,
            radii=[c.radius_m for c in self.cars],
            times=np.array(self.times),
            states=np.array(self.states),
            arrived_at=self.arrived,
            depart_at=[float(d) for d in self.depart],
            trust_times=np.array(self.trust_times),
            trust=np.array(self.trust_rows),
            transparency=np.array(self.transparency_rows),
            epsilon=np.array(self.epsilon_rows),
            replan_ms=[list(a.replan_ms) for a in agents],
            counters=[dict(a.counters) | {f"trust_{k}": v for k, v in a.trust.counters.items()}
                      | ({f"attack_{k}": v for k, v in a.liar.counters.items()} if a.liar else {})
                      | {"guard_limited": self.guard_limited[i]} | network.counters(i) for i, a in enumerate(agents)],
            inbox=[dict(box.dropped) | {f"accepted_{k}": v for k, v in box.accepted.items()} for box in self.inboxes],
            final_plans=[(a.plan.positions.copy(), a.plan.velocities.copy()) if a.plan is not None else
                         (np.zeros((0, 2)), np.zeros((0, 2))) for a in agents],
            plan_log=self.plan_log,
            first_lie_s=[_first_lie(self._lying_minds(i)) for i in range(n)],
            told=[[told for mind in self._lying_minds(i) for told in mind.liar.told] for i in range(n)],
            tracking_error=[np.array(errors) for errors in self.tracking_error],
        )


def _first_lie(minds: list[CarAgent]) -> float | None:
    """When the first of a car's lying minds first lied (None: never)."""
    return next((mind.liar.first_lie_at for mind in minds if mind.liar.first_lie_at is not None), None)


def _trust_snapshot(agents: list[CarAgent], ids: list[int], own: np.ndarray):
    n = len(agents)
    trust = np.ones((n, n))
    transparency = np.ones((n, n))
    epsilon = np.zeros((n, n))
    for a, agent in enumerate(agents):
        t = float(own[a])
        for b, peer in enumerate(ids):
            if a == b:
                continue
            tau = agent.trust.tau(peer, t)
            trust[a, b] = float(np.min(tau))
            transparency[a, b] = float(tau[2])
            epsilon[a, b] = agent.trust.epsilon(peer, t, agent.epsilon_0(peer), agent.scenario.planner.transparency)
    return trust, transparency, epsilon




class Network:
    """The fleet's messages in simulated time: per receiver, a message is lost with
    probability ``sim.message_loss`` and otherwise arrives ``message_latency_s`` plus
    U(0, ``message_jitter_s``) after it was sent, in the order it was sent on each
    sender-receiver link (as over one Zenoh session's reliable link). Draws come from
    their own generator, so the faults change nothing else a run draws."""

    def __init__(self, sim: SimConfig, n: int, rng: np.random.Generator):
        self.sim, self.n, self.rng = sim, n, rng
        self.queue: list[tuple[float, int, int, int, bytes]] = []  # (at, order, sender, receiver, payload)
        self.order = 0
        self.last = np.full((n, n), -np.inf)  # latest delivery time per link
        self.lost = [0] * n
        self.sent = [0] * n

    def publish(self, sender: int, payload: bytes, now: float) -> None:
        self.sent[sender] += 1
        for receiver in range(self.n):
            if receiver == sender:
                continue
            if self.sim.message_loss > 0.0 and self.rng.random() < self.sim.message_loss:
                self.lost[receiver] += 1
                continue
            delay = self.sim.message_latency_s
            if self.sim.message_jitter_s > 0.0:
                delay += self.rng.uniform(0.0, self.sim.message_jitter_s)
            at = max(now + delay, self.last[sender, receiver])
            self.last[sender, receiver] = at
            heapq.heappush(self.queue, (at, self.order, sender, receiver, payload))
            self.order += 1

    def due(self, now: float):
        """(sender, receiver, payload) of every message due by ``now``, in order."""
        while self.queue and self.queue[0][0] <= now + 1e-9:
            _, _, sender, receiver, payload = heapq.heappop(self.queue)
            yield sender, receiver, payload

    def counters(self, car: int) -> dict[str, int]:
        return {"messages_lost": self.lost[car]} if self.sim.message_loss > 0.0 else {}
