"""Hostile input, property-based: nothing crashes, hangs or grows without bound.

(The NatNet parser and the car-link decoder have their own property tests in
tests/bridge; the message decoder in tests/agent/test_messages.py.)
"""

import string
import time
import tracemalloc

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trustfg.agent import messages
from trustfg.agent.config import ConfigError
from trustfg.agent.scenario_files import load_scenario, scenario_from_dict

pytestmark = pytest.mark.realtime

SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(allow_nan=True),
                    st.text(max_size=20))
TOML_VALUES = st.recursive(
    st.one_of(st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
              st.text(max_size=10)),
    lambda inner: st.one_of(st.lists(inner, max_size=5), st.dictionaries(st.text(string.ascii_lowercase + "_", max_size=12), inner, max_size=5)),
    max_leaves=20)
KEYS = ["name", "fleet", "cars", "world", "planner", "trust", "vehicle", "tracking", "sim", "control", "bus", "natnet",
        "id", "start", "goal", "route", "bounds_m", "obstacles", "support_states", "qc", "kind", "min", "max"]


@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.dictionaries(st.sampled_from(KEYS), TOML_VALUES, max_size=8))
def test_config_loader_refuses_anything_malformed_with_config_error_only(data):
    try:
        scenario_from_dict(data)
    except ConfigError:
        pass


@settings(max_examples=600, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["planner", "world", "sim", "trust"]),
                          st.sampled_from(["qc", "support_states", "bounds_m", "forgetting", "timeout_s", "x"]),
                          TOML_VALUES), max_size=4))
def test_mutated_valid_scenarios_only_raise_config_error(changes):
    data = {"name": "t", "cars": [{"id": 1, "start": [0.0, 0.0], "goal": [1.0, 0.0]}]}
    for section, key, value in changes:
        data.setdefault(section, {})[key] = value
    try:
        scenario_from_dict(data)
    except ConfigError:
        pass


@settings(max_examples=500, deadline=None)
@given(st.text(max_size=300))
def test_any_file_text_is_a_config_error_or_a_scenario(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("cfg") / "x.toml"
    path.write_text(text)
    try:
        load_scenario(path)
    except ConfigError:
        pass


def test_a_msgpack_bomb_is_refused_fast_and_small():
    """Headers that claim 2**32 elements must not make the decoder allocate them."""
    bombs = [b"\xdd\xff\xff\xff\xff", b"\xdf\xff\xff\xff\xff", b"\xc6\xff\xff\xff\xff" + b"x" * 10,
             b"\x81\xa1k\xdd\x7f\xff\xff\xff"]
    tracemalloc.start()
    started = time.perf_counter()
    for bomb in bombs:
        with pytest.raises(messages.MessageError):
            messages.decode(bomb)
    elapsed = time.perf_counter() - started
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 5_000_000 and elapsed < 1.0


def test_inbox_counts_every_kind_of_drop():
    inbox = messages.Inbox()
    good = messages.encode(messages.PoseMessage(3, 1, 10.0, 0.0, 0.0, 0.0, True))
    assert inbox.accept(good, key_sender=3) is not None
    assert inbox.accept(good, key_sender=3) is None  # replayed
    assert inbox.accept(messages.encode(messages.PoseMessage(3, 2, 10.0, 0, 0, 0, True)), key_sender=4) is None
    assert inbox.accept(b"\x00" * (messages.MAX_MESSAGE_BYTES + 1), key_sender=3) is None
    assert inbox.accept(msgpack.packb({"v": 1}), key_sender=3) is None
    assert inbox.dropped == {"replayed": 1, "spoofed_sender": 1, "oversized": 1, "invalid": 1}


@settings(max_examples=2000, deadline=None)
@given(st.lists(st.binary(max_size=200), max_size=30))
def test_an_inbox_fed_garbage_stays_bounded(payloads):
    """State grows with senders and kinds (at most 256 x 5), never with the garbage."""
    inbox = messages.Inbox()
    for payload in payloads:
        inbox.accept(payload, key_sender=1)
    assert len(inbox._last) <= 256 * 5
    assert sum(inbox.dropped.values()) + sum(inbox.accepted.values()) == len(payloads)
