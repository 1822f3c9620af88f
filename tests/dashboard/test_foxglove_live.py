"""Foxglove: a recorded run read back with the mcap reader and Foxglove's protobuf schemas
(as the SDK declares them), and the live server spoken to over Foxglove's WebSocket
protocol by a plain client."""

from __future__ import annotations

import base64
import dataclasses
import json
import struct
import time

import numpy as np
import pytest
from foxglove.messages import FrameTransforms, Log, SceneUpdate
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from websockets.sync.client import connect

from tests.conftest import wait_for
from trustfg.agent import messages
from trustfg.agent.config import BusConfig
from trustfg.agent.gp import Plan
from trustfg.dashboard.foxglove_live import FoxgloveLive
from trustfg.fleet.bus.session import FleetBus
from trustfg.fleet.launch.ports import free_port
from trustfg.fleet.recording.mcap_file import McapRecorder, read_recording

pytestmark = pytest.mark.realtime

T0 = 1_700_000_000.0


def fleet_messages():
    """What a run of two cars says, as real fleet messages (decoded form)."""
    plan = Plan(T0, 0.5, np.array([[0.4, -2.0], [0.4, -1.5], [0.4, -1.0]]), np.zeros((3, 2)))
    out = [("start", 0, messages.StartMessage(1, T0, {1: (T0 + 1, 0.4), 2: (T0 + 1.5, 0.4)}))]
    for i in range(5):
        t = T0 + 0.1 * i
        out.append(("pose", 1, messages.PoseMessage(1, i + 1, t, 0.4, -2.0 + 0.05 * i, 1.5708, True)))
        out.append(("pose", 2, messages.PoseMessage(2, i + 1, t, -2.0, -0.4, 0.0, True)))
    out.append(("plan", 1, messages.PlanMessage(1, 1, T0 + 0.5, plan, (0.4, 2.15))))
    out.append(("status", 1, messages.StatusMessage(1, 1, T0 + 0.6, "driving", 5.0, 3, False, {})))
    return [(kind, sender, messages.to_dict(m), T0 + 0.01 * n) for n, (kind, sender, m) in enumerate(out)]


def test_a_recording_shows_cars_plans_and_the_map_in_foxglove_schemas(intersection, tmp_path):
    path = tmp_path / "run.mcap"
    recorder = McapRecorder(path, intersection)
    for kind, sender, data, at in fleet_messages():
        recorder.write(kind, sender, at, data)
    recorder.close()

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
        summary = reader.get_summary()
        schemas = {s.name: s for s in summary.schemas.values()}
        # the channels carry the SDK's own schemas, byte for byte
        for sdk in (SceneUpdate, FrameTransforms, Log):
            assert schemas[sdk.get_schema().name].data == sdk.get_schema().data
            assert schemas[sdk.get_schema().name].encoding == "protobuf"
        topics = [c.topic for c in summary.channels.values() if summary.schemas[c.schema_id].encoding == "protobuf"]
        entities, transforms, logs = {}, [], []
        for schema, channel, _, proto in reader.iter_decoded_messages(topics=topics):
            if schema.name == "foxglove.SceneUpdate":
                entities.update({e.id: e for e in proto.entities})
            elif schema.name == "foxglove.FrameTransforms":
                transforms += list(proto.transforms)
            elif schema.name == "foxglove.Log":
                logs.append(proto.message)
    car1 = entities["car/1"]
    assert car1.frame_id == "world"
    assert car1.cylinders[0].pose.position.x == pytest.approx(0.4)
    assert car1.cylinders[0].pose.position.y == pytest.approx(-1.8)
    assert car1.cylinders[0].size.x == pytest.approx(0.2)  # a disc of the car's diameter
    assert "car/2" in entities
    plan = entities["plan/1"].lines[0]
    assert [c for p in plan.points for c in (p.x, p.y)] == pytest.approx([0.4, -2.0, 0.4, -1.5, 0.4, -1.0])
    assert entities["goal/1"].spheres[0].pose.position.y == pytest.approx(2.15)
    assert len(entities["map"].cubes) == len(intersection.world.obstacles)
    assert {t.child_frame_id for t in transforms} == {"car1", "car2"}
    assert any("start" in m for m in logs) and any("driving" in m for m in logs)
    # the fleet's own messages are still there, and only they come back as fleet messages
    scenario, events = read_recording(path)
    assert scenario.name == intersection.name
    assert [e.kind for e in events] == [kind for kind, *_ in fleet_messages()]


def protobuf_class(channel: dict):
    """A message class from a channel's advertised schema (a base64 FileDescriptorSet)."""
    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


def test_a_foxglove_websocket_client_receives_a_cars_pose(intersection):
    car_endpoint = f"tcp/127.0.0.1:{free_port()}"
    fleet = dataclasses.replace(intersection, bus=BusConfig(connect=(car_endpoint,)))
    with FleetBus(BusConfig(listen=(car_endpoint,)), fleet.fleet, 3) as car, \
            FoxgloveLive(fleet, port=0, listen=(f"tcp/127.0.0.1:{free_port()}",)) as live:
        with connect(f"ws://127.0.0.1:{live.port}", subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"],
                     open_timeout=5) as ws:
            assert ws.subprotocol == "foxglove.sdk.v1"  # the SDK's name for foxglove.websocket.v1
            channels: dict[str, dict] = {}
            deadline = time.monotonic() + 20
            seq = 0
            tf = None
            while tf is None and time.monotonic() < deadline:  # the car talks, the server forwards
                seq += 1
                car.publish("pose", messages.encode(messages.PoseMessage(3, seq, time.time(), 1.25, -0.5, 0.3, True)))
                live.step(0.05)
                try:
                    while True:
                        frame = ws.recv(timeout=0.05)
                        if isinstance(frame, str) and json.loads(frame)["op"] == "advertise":
                            channels.update({c["topic"]: c for c in json.loads(frame)["channels"]})
                except TimeoutError:
                    pass
                tf = channels.get(f"trustfg/{fleet.fleet}/tf")
            assert tf is not None, f"no transforms advertised: {list(channels)}"
            assert tf["encoding"] == "protobuf" and tf["schemaName"] == "foxglove.FrameTransforms"
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": tf["id"]}]}))
            decoded = None

            def receive_pose():
                nonlocal decoded, seq
                seq += 1
                car.publish("pose", messages.encode(messages.PoseMessage(3, seq, time.time(), 1.25, -0.5, 0.3, True)))
                live.step(0.05)
                try:
                    frame = ws.recv(timeout=0.1)
                except TimeoutError:
                    return False
                if isinstance(frame, bytes) and frame[0] == 0x01:  # message data
                    subscription, _log_time = struct.unpack_from("<IQ", frame, 1)
                    assert subscription == 1
                    decoded = protobuf_class(tf).FromString(frame[13:])
                return decoded is not None

            assert wait_for(receive_pose, 20.0, interval=0.0)
    (transform,) = decoded.transforms
    assert (transform.parent_frame_id, transform.child_frame_id) == ("world", "car3")
    assert (transform.translation.x, transform.translation.y) == pytest.approx((1.25, -0.5))
    assert 2 * np.arctan2(transform.rotation.z, transform.rotation.w) == pytest.approx(0.3, abs=1e-6)
