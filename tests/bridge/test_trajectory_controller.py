
import numpy as np
import pytest

from trustfg.agent.config import TrackingConfig, VehicleConfig
from trustfg.agent.gp import Plan
from trustfg.agent.vehicle import VehicleState, step
from trustfg.bridge.trajectory_controller import track


def circle_plan(radius=1.0, speed=0.4, seconds=12.0, n=61):
    t = np.linspace(0, seconds, n)
    w = speed / radius
    positions = np.stack([radius * np.sin(w * t), radius * (1 - np.cos(w * t))], axis=1)
    velocities = np.stack([speed * np.cos(w * t), speed * np.sin(w * t)], axis=1)
    return Plan(0.0, t[1] - t[0], positions, velocities)


def follow(plan, state, seconds, dt=0.02):
    gains, limits = TrackingConfig(), VehicleConfig()
    errors = []
    for k in range(int(seconds / dt)):
        t = k * dt
        v, w = track(plan, t, state.x, state.y, state.yaw, gains, limits)
        assert 0.0 <= v <= limits.max_speed_mps and abs(w) <= limits.max_turn_rate_radps
        state = step(state, v, w, dt, limits)
        errors.append(np.linalg.norm(plan.position_at(t + dt)[0] - state.position))
    return state, np.array(errors)


@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.1, -0.05), (-0.08, 0.1)])
@pytest.mark.parametrize("heading_error", [0.0, 0.3, -0.4])
def test_tracking_converges_onto_a_curved_plan(offset, heading_error):
    plan = circle_plan()
    start = VehicleState(offset[0], offset[1], heading_error)
    _, errors = follow(plan, start, 10.0)
    assert errors[-100:].max() < 0.03  # settled within 3 cm
    assert errors[-1] < errors[0] + 1e-9 or errors[0] < 0.01


def test_tracking_stops_at_the_end_of_a_plan():
    plan = Plan(0.0, 1.0, np.array([[0.0, 0.0], [0.2, 0.0], [0.5, 0.0], [0.6, 0.0]]),
                np.array([[0.0, 0.0], [0.25, 0.0], [0.2, 0.0], [0.0, 0.0]]))
    state, _ = follow(plan, VehicleState(0.0, 0.0, 0.0), 8.0)
    assert abs(state.x - 0.6) < TrackingConfig().goal_tolerance_m
    assert state.v == pytest.approx(0.0, abs=1e-9)


def test_a_car_standing_on_its_plan_point_stays_put():
    plan = Plan(0.0, 1.0, np.zeros((3, 2)), np.zeros((3, 2)))
    assert track(plan, 0.5, 0.001, -0.002, 1.0, TrackingConfig(), VehicleConfig()) == (0.0, 0.0)
