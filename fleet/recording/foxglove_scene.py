"""The fleet in Foxglove's well-known schemas, written with the official SDK (foxglove-sdk).

One :class:`FoxgloveLog` per Foxglove sink -- an MCAP file (fleet.recording.mcap_file) or
the live WebSocket server (dashboard.foxglove_live) -- logs every fleet message twice: as
itself (JSON with its JSON Schema, on its key expression) and as what Foxglove's 3D panel
draws, in Foxglove's protobuf schemas: ``trustfg/F/scene`` (SceneUpdate: the map, every
car as a disc and an arrow at its last pose, its plan and goal), ``trustfg/F/N/epsilon``
(SceneUpdate: the distance car N keeps from each peer, a circle around that peer),
``trustfg/F/tf`` (FrameTransforms: world -> carN) and ``trustfg/F/log`` (Log: the start
and every change of a car's state). Everything lies on the ground plane (z = 0) of frame
``world``, in metres; entities have no lifetime: each update replaces the one of its id.
"""

from __future__ import annotations

import json
import math

import foxglove
from foxglove.channels import FrameTransformsChannel, LogChannel, SceneUpdateChannel
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    LinePrimitive,
    LinePrimitiveLineType,
    Log,
    LogLevel,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)
from matplotlib.colors import to_rgb

from ...agent.config import Scenario
from ..bus import key_exprs

WORLD = "world"
_GREY = Color(r=0.45, g=0.45, b=0.5, a=1.0)
_CIRCLE_POINTS = 36


def frame_of(car_id: int) -> str:
    return f"car{car_id}"


def _pose(x: float, y: float, z: float = 0.0, yaw: float = 0.0) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=_yaw(yaw))


def _yaw(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def _circle(x: float, y: float, radius: float, color: Color, thickness: float = 0.01) -> LinePrimitive:
    points = [Point3(x=x + radius * math.cos(a), y=y + radius * math.sin(a), z=0.005)
              for a in (2.0 * math.pi * i / _CIRCLE_POINTS for i in range(_CIRCLE_POINTS))]
    return LinePrimitive(type=LinePrimitiveLineType.LineLoop, points=points, color=color, thickness=thickness)


def map_entities(scenario: Scenario, stamp: Timestamp) -> list[SceneEntity]:
    """The arena's walls and its obstacles (rectangles as blocks, polygons as outlines)."""
    x0, y0, x1, y1 = scenario.world.bounds_m
    walls = LinePrimitive(type=LinePrimitiveLineType.LineLoop, thickness=0.03, color=_GREY,
                          points=[Point3(x=x, y=y, z=0.0) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))])
    cubes, lines = [], [walls]
    for o in scenario.world.obstacles:
        if o.kind == "rect":
            (ax, ay), (bx, by) = o.min, o.max
            cubes.append(CubePrimitive(pose=_pose((ax + bx) / 2, (ay + by) / 2, 0.1),
                                       size=Vector3(x=bx - ax, y=by - ay, z=0.2), color=_GREY))
        else:
            lines.append(LinePrimitive(type=LinePrimitiveLineType.LineLoop, thickness=0.03, color=_GREY,
                                       points=[Point3(x=px, y=py, z=0.0) for px, py in o.points]))
    return [SceneEntity(timestamp=stamp, frame_id=WORLD, id="map", cubes=cubes, lines=lines)]


class FoxgloveLog:
    """Logs fleet messages and their scene to one Foxglove ``context`` (see the module)."""

    def __init__(self, scenario: Scenario, context: foxglove.Context) -> None:
        self.scenario = scenario
        self.fleet = scenario.fleet
        self._context = context
        self._colors = {car.id: Color(**dict(zip("rgb", to_rgb(c))), a=1.0)
                        for car, c in zip(scenario.cars, scenario.car_colors())}
        self._radii = {car.id: car.radius_m for car in scenario.cars}
        self._json: dict[str, foxglove.Channel] = {}
        self._epsilon: dict[int, SceneUpdateChannel] = {}
        self._scene = SceneUpdateChannel(key_exprs.fleet_key(self.fleet, "scene"), context=context)
        self._tf = FrameTransformsChannel(key_exprs.fleet_key(self.fleet, "tf"), context=context)
        self._log = LogChannel(key_exprs.fleet_key(self.fleet, "log"), context=context)
        self._poses: dict[int, tuple[float, float, float]] = {}
        self._states: dict[int, str] = {}
        self.count = 0

    def write_map(self, at: float) -> None:
        """The walls and obstacles (once per recording; every few seconds on a live server,
        for clients that join late)."""
        self._scene.log(SceneUpdate(entities=map_entities(self.scenario, Timestamp.from_epoch_secs(at))),
                        log_time=_ns(at))

    def write(self, kind: str, sender: int, at: float, data: dict, schema: bytes) -> None:
        """One fleet message (``agent.messages.to_dict`` form) that arrived at ``at``."""
        topic = self.topic(kind, sender)
        channel = self._json.get(topic)
        if channel is None:
            channel = self._json[topic] = foxglove.Channel(
                topic, schema=foxglove.Schema(name=f"trustfg.{kind}", encoding="jsonschema", data=schema),
                message_encoding="json", context=self._context)
        channel.log(json.dumps(data).encode(), log_time=_ns(at))
        self.count += 1
        drawn = getattr(self, f"_draw_{kind}", None)
        if drawn is not None:
            drawn(sender, at, data)

    def topic(self, kind: str, sender: int) -> str:
        if kind in (*key_exprs.OPERATOR, key_exprs.TRUTH):
            return key_exprs.fleet_key(self.fleet, kind)
        return key_exprs.key(self.fleet, sender, kind)

    # --- what each kind draws -------------------------------------------------------------

    def _draw_pose(self, car: int, at: float, data: dict) -> None:
        if not data.get("valid", True):
            return
        x, y, yaw = float(data["x"]), float(data["y"]), float(data["yaw"])
        self._poses[car] = (x, y, yaw)
        stamp, color, r = Timestamp.from_epoch_secs(at), self._color(car), self._radii.get(car, 0.1)
        body = SceneEntity(
            timestamp=stamp, frame_id=WORLD, id=f"car/{car}",
            cylinders=[CylinderPrimitive(pose=_pose(x, y, 0.04, yaw), size=Vector3(x=2 * r, y=2 * r, z=0.08),
                                         bottom_scale=1.0, top_scale=1.0, color=color)],
            arrows=[ArrowPrimitive(pose=_pose(x, y, 0.09, yaw), shaft_length=1.2 * r, shaft_diameter=0.02,
                                   head_length=0.6 * r, head_diameter=0.05, color=Color(r=1, g=1, b=1, a=1))],
            texts=[TextPrimitive(pose=_pose(x, y, 0.25), billboard=True, font_size=14, scale_invariant=True,
                                 color=color, text=f"car {car}")])
        self._scene.log(SceneUpdate(entities=[body]), log_time=_ns(at))
        self._tf.log(FrameTransforms(transforms=[FrameTransform(
            timestamp=stamp, parent_frame_id=WORLD, child_frame_id=frame_of(car),
            translation=Vector3(x=x, y=y, z=0.0), rotation=_yaw(yaw))]), log_time=_ns(at))

    def _draw_plan(self, car: int, at: float, data: dict) -> None:
        stamp, color = Timestamp.from_epoch_secs(at), self._color(car)
        points = [Point3(x=float(px), y=float(py), z=0.01) for px, py in data["positions"]]
        gx, gy = data["goal"]
        plan = SceneEntity(timestamp=stamp, frame_id=WORLD, id=f"plan/{car}",
                           lines=[LinePrimitive(type=LinePrimitiveLineType.LineStrip, points=points,
                                                thickness=0.02, color=color)])
        goal = SceneEntity(timestamp=stamp, frame_id=WORLD, id=f"goal/{car}",
                           spheres=[SpherePrimitive(pose=_pose(float(gx), float(gy), 0.02),
                                                    size=Vector3(x=0.08, y=0.08, z=0.04), color=color)])
        self._scene.log(SceneUpdate(entities=[plan, goal]), log_time=_ns(at))

    def _draw_trust(self, truster: int, at: float, data: dict) -> None:
        stamp, color = Timestamp.from_epoch_secs(at), self._color(truster)
        entities = []
        for peer, view in data["peers"].items():
            pose = self._poses.get(int(peer))
            if pose is None or not math.isfinite(view.get("epsilon", math.nan)):
                continue
            entities.append(SceneEntity(timestamp=stamp, frame_id=WORLD, id=f"epsilon/{truster}/{peer}",
                                        lines=[_circle(pose[0], pose[1], float(view["epsilon"]), color)]))
        if entities:
            channel = self._epsilon.get(truster)
            if channel is None:
                channel = self._epsilon[truster] = SceneUpdateChannel(
                    key_exprs.key(self.fleet, truster, "epsilon"), context=self._context)
            channel.log(SceneUpdate(entities=entities), log_time=_ns(at))

    def _draw_status(self, car: int, at: float, data: dict) -> None:
        state = str(data["state"])
        if self._states.get(car) == state:
            return
        self._states[car] = state
        level = LogLevel.Warning if state in ("stuck", "stopped") else LogLevel.Info
        self._log.log(Log(timestamp=Timestamp.from_epoch_secs(at), level=level, name=frame_of(car),
                          message=f"car {car}: {state}"), log_time=_ns(at))

    def _draw_start(self, _sender: int, at: float, data: dict) -> None:
        cars = ", ".join(f"{c} at {v['depart'] - at:+.1f} s" for c, v in sorted(data["cars"].items()))
        self._log.log(Log(timestamp=Timestamp.from_epoch_secs(at), level=LogLevel.Info, name="operator",
                          message=f"start: {cars}"), log_time=_ns(at))

    def _color(self, car: int) -> Color:
        return self._colors.get(car, _GREY)


def _ns(at: float) -> int:
    return int(round(at * 1e9))
