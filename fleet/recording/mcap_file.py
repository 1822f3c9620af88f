"""Recorded runs as MCAP files (the robotics log format), written with Foxglove's SDK.

Every fleet message becomes an MCAP message on its own key expression as the topic
(``trustfg/F/N/plan`` ...), JSON-encoded (agent.messages.to_dict) under a JSON Schema
per kind; log time is when it arrived. Next to them, the same run in Foxglove's
well-known schemas, so Foxglove's 3D panel shows it (fleet.recording.foxglove_scene: the map, the
cars, their plans and goals, every car's epsilon circles, frame transforms, a log).
``trustfg sim`` runs also carry mocap-sim's ground truth on ``trustfg/F/truth`` (every
car's x, y, yaw, v, omega at 50 Hz), and the fleet config that ran as metadata
``trustfg.fleet`` (its TOML text).

    trustfg record --config FILE --out RUN.mcap     record a live fleet (e.g. in the lab)
"""

from __future__ import annotations

import csv
import json
import threading
from dataclasses import dataclass
from pathlib import Path

import foxglove
from mcap.reader import make_reader

from ...agent import messages
from ...agent.config import Scenario
from ...agent.scenario_files import dump_scenario, load_scenario, scenario_from_dict
from ..bus.session import FleetBus
from ..program import command_parser, configured, stop_on_signals
from .foxglove_scene import FoxgloveLog

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


class McapRecorder:
    """Writes messages to an MCAP file as they come (Foxglove's SDK: chunked, zstd): the
    fleet messages and their Foxglove scene."""

    def __init__(self, path: Path, scenario: Scenario):
        self._context = foxglove.Context()
        self._writer = foxglove.open_mcap(path, allow_overwrite=True, context=self._context)
        self._writer.write_metadata("trustfg.fleet", {"toml": dump_scenario(scenario)})
        self._log = FoxgloveLog(scenario, self._context)
        self._map_written = False

    @property
    def count(self) -> int:
        return self._log.count

    def write(self, kind: str, sender: int, at: float, data: dict) -> None:
        if not self._map_written:
            self._log.write_map(at)
            self._map_written = True
        self._log.write(kind, sender, at, data, schema(kind))

    def close(self) -> None:
        self._writer.close()


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
            if schema_record is None or not schema_record.name.startswith("trustfg."):
                continue  # Foxglove's scene of the run, not a fleet message
            kind = schema_record.name.removeprefix("trustfg.")
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

