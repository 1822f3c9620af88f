"""The fleet in one process: fast, deterministic per seed, with the real parts inside.

Every car is a :class:`CarAgent` (the same planner and trust code the car process runs)
driving a simulated unicycle (agent.vehicle) with the tracking controller of the
bridge (bridge.trajectory_controller). Cars see each other through noisy pose observations and talk
through the fleet message codec (agent.messages: msgpack bytes, decoded and filtered by
an Inbox per receiver), over a :class:`Network` with latency, jitter and loss
(``[sim]``). Time is simulated: a replan takes no simulated time, so a run is exactly
repeatable from its seed. A car with ``clock_offset_s`` reads every time off its own
clock, that much ahead of the fleet's: its observations, stamps, departure and plan
tracking, as a car computer with a wrong clock would.

The cars stand ``sim.settle_s`` at their starts before the go, as ``trustfg sim``'s do
(standing plans published, poses seen, evidence gathered); the record of motion starts
at the go (t = 0), the trust record with the wait.

Per seed, each car draws a start delay in [0, start_delay_max_s], a cruise speed in
cruise_speed_range_mps (:func:`draw_departures`, which ``trustfg sim`` uses too) and a
replanning phase, so that starts are desynchronised and, with avoidance off, conflicting
routes really collide. Physics and control step at ``control.command_rate_hz``.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from ...agent import messages
from ...agent.car_agent import CarAgent
from ...agent.config import Scenario, SimConfig
from ...agent.gp import standing
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
    cost O(n^2) trust fusions every RECORD_TRUST_PERIOD_S: a third of a 16-car run)."""
    sim = scenario.sim
    sdf = sdf or build_sdf(scenario.world)
    rng = np.random.default_rng(seed)
    cars = list(scenario.cars)
    n = len(cars)
    ids = [c.id for c in cars]
    depart, cruise = draw_departures(scenario, rng)
    control = scenario.control
    step_s = 1.0 / control.command_rate_hz
    spread = control.replan_period_s if sim.replan_phase_max_s is None else sim.replan_phase_max_s
    phase = rng.uniform(0.0, spread, n)
    noise_rng = np.random.default_rng([seed, 7])

    def minds(departures) -> list[CarAgent]:
        return [CarAgent(car=c, scenario=scenario, sdf=sdf, depart_at=float(departures[i]),
                         cruise_speed_mps=float(cruise[i]), rng=np.random.default_rng([seed, c.id]))
                for i, c in enumerate(cars)]

    # The cars stand sim.settle_s before the go, as trustfg sim's do: minds that wait
    # (depart_at = inf), each replaced at the go by one that drives and carries over what
    # its predecessor learnt (CarAgent.carry_over, as the car process does at a start).
    settle_steps = int(round(sim.settle_s / step_s))
    agents = minds(np.full(n, math.inf) if settle_steps else depart)
    waited: list[CarAgent] = []  # the minds that stood the wait (their liars' lies are the run's too)
    inboxes = [messages.Inbox() for _ in cars]
    vehicles = [VehicleState(c.start[0], c.start[1], c.start_heading) for c in cars]

    clock = np.array([c.clock_offset_s for c in cars])  # each car's clock minus the fleet's
    network = Network(sim, n, np.random.default_rng([seed, 11]))

    steps = int(math.ceil(sim.timeout_s / step_s)) + 1
    times, states = [], []
    trust_times, trust_rows, transparency_rows, epsilon_rows = [], [], [], []
    arrived: list[float | None] = [None] * n
    guard_limited = [0] * n
    plan_log: list = []
    # Replans and reports keep their phase to the go through the wait.
    next_replan = phase - math.ceil(sim.settle_s / control.replan_period_s) * control.replan_period_s
    next_report = rng.uniform(0.0, control.trust_report_period_s, n)
    next_report -= math.ceil(sim.settle_s / control.trust_report_period_s) * control.trust_report_period_s
    next_trust_record = -math.floor(sim.settle_s / RECORD_TRUST_PERIOD_S + 1e-9) * RECORD_TRUST_PERIOD_S

    for k in range(-settle_steps, steps):
        t = k * step_s
        going = t >= -1e-9
        if k == 0 and settle_steps:  # the go
            waited, agents = agents, minds(depart)
            for i, agent in enumerate(agents):
                agent.carry_over(waited[i])
        # 1. Deliver due messages through each receiver's inbox (decode + order/replay filter).
        own = t + clock  # every car's own reading of the time
        for sender, receiver, payload in network.due(t):
            message = inboxes[receiver].accept(payload, key_sender=ids[sender])
            if message is not None:
                agents[receiver].receive(message, own[receiver])
        # 2. Everyone sees everyone (mocap), with noise.
        seen = np.empty((n, n, 3))  # seen[j, i]: car i as car j sees it
        for i, state in enumerate(vehicles):
            noisy = noise_rng.normal(0.0, sim.observation_noise_m, (n, 2))
            seen[:, i] = np.column_stack([state.x + noisy[:, 0], state.y + noisy[:, 1], np.full(n, state.yaw)])
            for j, agent in enumerate(agents):
                agent.observe(own[j], ids[i], *seen[j, i])
        # 3. Evidence, replanning, reports.
        for i, agent in enumerate(agents):
            agent.gather_evidence(own[i])
            if t + 1e-9 >= next_replan[i]:
                next_replan[i] += control.replan_period_s
                if going:
                    agent.replan(own[i])
                elif (motion := agent.tracks[ids[i]].motion()) is not None:
                    agent.plan = standing(motion.position, own[i])  # waiting: as fleet.car.process
                if keep_plans and agent.plan is not None:
                    plan_log.append((t, i, agent.plan))
                outgoing = agent.plan_message(own[i])
                if outgoing is not None:
                    network.publish(i, messages.encode(outgoing), t)
            if t + 1e-9 >= next_report[i]:
                next_report[i] += control.trust_report_period_s
                network.publish(i, messages.encode(agent.trust_message(own[i])), t)
        if record_trust and t + 1e-9 >= next_trust_record:  # trust from the start of the wait
            next_trust_record += RECORD_TRUST_PERIOD_S
            trust_times.append(t)
            tr, tp, ep = _trust_snapshot(agents, ids, own)
            trust_rows.append(tr)
            transparency_rows.append(tp)
            epsilon_rows.append(ep)
        if not going:
            continue  # the cars stand; their motion's record starts at the go
        # 4. Record, then control and move.
        times.append(t)
        states.append([[s.x, s.y, s.yaw, s.v, s.omega] for s in vehicles])
        for i, agent in enumerate(agents):
            state = vehicles[i]
            if arrived[i] is None and math.hypot(state.x - cars[i].goal[0], state.y - cars[i].goal[1]) <= scenario.arrival_radius_m:
                arrived[i] = t
            me = agent.tracks[ids[i]].motion()
            others = [(*seen[i, j], cars[j].radius_m) for j in range(n) if j != i]
            command = drive(agent.plan, own[i], (me.position[0], me.position[1], me.yaw),
                            own[i] >= depart[i] and not agent.at_goal, lambda: others, cars[i].radius_m, scenario, sdf)
            guard_limited[i] += command.guard_limited
            vehicles[i] = vehicle_step(state, command.v, command.omega, step_s, scenario.vehicle)
        if all(a is not None for a in arrived) and all(abs(s.v) < 1e-3 for s in vehicles):
            break

    def minds_of(i: int) -> list[CarAgent]:
        """Car i's minds that lie, in order: the one that waited, the one that drove."""
        return [mind for mind in (*waited[i:i + 1], agents[i]) if mind.liar is not None]

    return RunRecord(
        seed=seed,
        car_ids=ids,
        radii=[c.radius_m for c in cars],
        times=np.array(times),
        states=np.array(states),
        arrived_at=arrived,
        depart_at=[float(d) for d in depart],
        trust_times=np.array(trust_times),
        trust=np.array(trust_rows),
        transparency=np.array(transparency_rows),
        epsilon=np.array(epsilon_rows),
        replan_ms=[list(a.replan_ms) for a in agents],
        counters=[dict(a.counters) | {f"trust_{k}": v for k, v in a.trust.counters.items()}
                  | ({f"attack_{k}": v for k, v in a.liar.counters.items()} if a.liar else {})
                  | {"guard_limited": guard_limited[i]} | network.counters(i) for i, a in enumerate(agents)],
        inbox=[dict(box.dropped) | {f"accepted_{k}": v for k, v in box.accepted.items()} for box in inboxes],
        final_plans=[(a.plan.positions.copy(), a.plan.velocities.copy()) if a.plan is not None else
                     (np.zeros((0, 2)), np.zeros((0, 2))) for a in agents],
        plan_log=plan_log,
        first_lie_s=[_first_lie(minds_of(i)) for i in range(n)],
        told=[[told for mind in minds_of(i) for told in mind.liar.told] for i in range(n)],
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
    their own generator, so a run without faults is the same run it always was."""

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
