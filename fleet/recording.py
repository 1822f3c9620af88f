"""Recorded runs as MCAP files (the robotics log format; they open in Foxglove).

Every fleet message becomes an MCAP message on its own key expression as the topic
(``trustfg/F/N/plan`` ...), JSON-encoded (agent.messages.to_dict) under a JSON Schema
per kind; log time is when it arrived. ``trustfg sim`` runs also carry mocap-sim's
ground truth on ``trustfg/F/truth`` (every car's x, y, yaw, v, omega at 50 Hz), and the
fleet config that ran as metadata ``trustfg.fleet`` (its TOML text).

    trustfg record --config FILE --out RUN.mcap     record a live fleet (e.g. in the lab)
"""

from __future__ import annotations

import csv
import json
import threading
from dataclasses import dataclass
from pathlib import Path

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from ..agent import messages
from ..agent.config import Scenario
from ..agent.scenario_files import dump_scenario, load_scenario, scenario_from_dict
from . import keys
from .bus import FleetBus
from .command import command_parser, configured, stop_on_signals

NUMBER = {"type": "number"}
INTEGER = {"type": "integer"}
XY = {"type": "array", "items": NUMBER, "minItems": 2, "maxItems": 2}
COMMON = {"kind": {"type": "string"}, "id": INTEGER, "seq": INTEGER, "stamp": NUMBER}
SCHEMAS = {
    "plan": {"t0": NUMBER, "dt": NUMBER, "goal": XY, "positions": {"type": "array", "items": XY},
             "velocities": {"type": "array", "items": XY}},
    "trust": {"peers": {"type": "object", "additionalProperties": {"type": "object", "properties": {
        "alpha": {"type": "array", "items": NUMBER}, "beta": {"type": "array", "items": NUMBER},
        "tau": {"type": "array", "items": NUMBER}, "trust": NUMBER, "epsilon": NUMBER}}}},
    "pose": {"x": NUMBER, "y": NUMBER, "yaw": NUMBER, "valid": {"type": "boolean"}},
    "status": {"state": {"type": "string"}, "replan_ms": NUMBER, "iterations": INTEGER,
               "at_goal": {"type": "boolean"}, "counters": {"type": "object", "additionalProperties": INTEGER},
               "trial": INTEGER},
    "start": {"trial": INTEGER, "cars": {"type": "object", "additionalProperties": {"type": "object", "properties": {
        "depart": NUMBER, "cruise": NUMBER}}}},
    "stop": {"action": {"type": "string"}, "cars": {"type": "array", "items": INTEGER}, "trial": INTEGER},
    "heartbeat": {},
    "clock": {},
    "truth": {"t": NUMBER, "cars": {"type": "object", "additionalProperties": {"type": "object", "properties": {
        "x": NUMBER, "y": NUMBER, "yaw": NUMBER, "v": NUMBER, "omega": NUMBER}}}},
}


def schema(kind: str) -> bytes:
    properties = SCHEMAS[kind] if kind == "truth" else COMMON | SCHEMAS[kind]
    return json.dumps({"title": f"trustfg.{kind}", "type": "object", "properties": properties,
                       "required": sorted(properties)}).encode()


def topic(fleet: str, kind: str, sender: int) -> str:
    return keys.fleet_key(fleet, kind) if kind in (*keys.OPERATOR, keys.TRUTH) else keys.key(fleet, sender, kind)


class McapRecorder:
    """Writes messages to an MCAP file as they come (chunked, zstd)."""

    def __init__(self, path: Path, scenario: Scenario):
        self.fleet = scenario.fleet
        self._file = open(path, "wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library="trustfg")
        self._writer.add_metadata("trustfg.fleet", {"toml": dump_scenario(scenario)})
        self._schemas = {kind: self._writer.register_schema(f"trustfg.{kind}", "jsonschema", schema(kind))
                         for kind in SCHEMAS}
        self._channels: dict[str, int] = {}
        self._sequence = 0
        self.count = 0

    def write(self, kind: str, sender: int, at: float, data: dict) -> None:
        name = topic(self.fleet, kind, sender)
        channel = self._channels.get(name)
        if channel is None:
            channel = self._channels[name] = self._writer.register_channel(name, "json", self._schemas[kind])
        self._sequence += 1
        stamp = int(round(at * 1e9))
        self._writer.add_message(channel, log_time=stamp, data=json.dumps(data).encode(),
                                 publish_time=stamp, sequence=self._sequence)
        self.count += 1

    def close(self) -> None:
        self._writer.finish()
        self._file.close()


def convert_run(folder: Path, scenario: Scenario) -> Path:
    """messages.jsonl and ground_truth.csv of a ``trustfg sim`` run -> run.mcap, in time order."""
    events: list[tuple[float, str, int, dict]] = []
    with open(folder / "messages.jsonl") as f:
        for line in f:
            record = json.loads(line)
            if "message" in record:
                events.append((record["t"], record["kind"], record["sender"], record["message"]))
    truth_path = folder / "ground_truth.csv"
    if truth_path.exists():
        rows: dict[float, dict] = {}
        with open(truth_path, newline="") as f:
            for row in csv.DictReader(f):
                t = float(row["t"])
                rows.setdefault(t, {})[row["car_id"]] = {k: float(row[k]) for k in ("x", "y", "yaw", "v", "omega")}
        ids = {str(c.id) for c in scenario.cars}
        events.extend((t, "truth", 0, {"t": t, "cars": cars}) for t, cars in rows.items() if ids <= set(cars))
    events.sort(key=lambda e: e[0])
    path = folder / "run.mcap"
    recorder = McapRecorder(path, scenario)
    for at, kind, sender, data in events:
        recorder.write(kind, sender, at, data)
    recorder.close()
    return path


@dataclass(frozen=True)
class Recorded:
    at: float
    kind: str
    sender: int
    data: dict


def read_recording(path: Path) -> tuple[Scenario, list[Recorded]]:
    """The fleet config and every message of an MCAP run, in log-time order. The file's
    CRCs are checked; a message that is not valid JSON of a known kind is an error."""
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        fleet_toml = None
        for metadata in reader.iter_metadata():
            if metadata.name == "trustfg.fleet":
                fleet_toml = metadata.metadata["toml"]
        if fleet_toml is None:
            raise ValueError(f"{path}: no trustfg.fleet metadata: not a trustfg recording")
        import tomllib
        scenario = scenario_from_dict(tomllib.loads(fleet_toml))
        events = []
        for schema_record, channel, message in reader.iter_messages(log_time_order=True):
            kind = schema_record.name.removeprefix("trustfg.") if schema_record else "?"
            data = json.loads(message.data)
            sender = data.get("id", 0) if kind != "truth" else 0
            events.append(Recorded(message.log_time / 1e9, kind, sender, data))
    return scenario, events


def resolve_run(run: Path) -> Path:
    """A run folder (with run.mcap) or an .mcap file."""
    if run.is_dir():
        run = run / "run.mcap"
    if not run.exists():
        raise FileNotFoundError(f"no recording at {run}")
    return run


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg record", "Record a live fleet to an MCAP file.")
    parser.add_argument("--config", required=True, help="fleet config: a TOML file or a shipped name (lab/fleet)")
    parser.add_argument("--out", type=Path, required=True, help="MCAP file to write")
    parser.add_argument("--listen", action="append", default=[], help="Zenoh endpoint to listen on (repeatable)")
    args = parser.parse_args(argv)
    scenario = configured("trustfg record", lambda: load_scenario(args.config))
    stop = stop_on_signals(threading.Event())
    inbox = messages.Inbox()
    recorder = McapRecorder(args.out, scenario)
    try:
        with FleetBus(scenario.bus, scenario.fleet, None, listen=tuple(args.listen),
                      operator_kinds=("start", "stop")) as bus:
            print(f"recording fleet {scenario.fleet!r} to {args.out} (Ctrl-C to stop)", flush=True)
            while True:
                done = stop.is_set()  # one more drain after the stop, so nothing received is lost
                bus.wait(0.2)
                for received in bus.drain():
                    message = inbox.accept(received.payload, key_sender=received.sender)
                    if message is not None:
                        recorder.write(message.kind, message.sender, received.at, messages.to_dict(message))
                        if recorder.count == 1:
                            print(f"first message: {message.kind} from car {message.sender}", flush=True)
                if done:
                    break
    finally:
        recorder.close()
    print(f"{recorder.count} messages, {dict(inbox.dropped) or 'none'} dropped")
    return 0

