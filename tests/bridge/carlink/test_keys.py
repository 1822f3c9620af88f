"""Where a car's link key comes from (config, key file) and senders that pick the version
from the car's config, over real UDP sockets."""

import dataclasses

import pytest

from tests.conftest import wait_for
from trustfg.agent.config import CarConfig, ConfigError
from trustfg.bridge.carlink import CommandReceiver, CommandSender, link_key, new_key, write_key_file

pytestmark = pytest.mark.realtime


def car(**fields):
    return CarConfig(**{"id": 3, "start": (0.0, 0.0), "goal": (1.0, 0.0), "link": "udp://127.0.0.1:9"} | fields)


def test_version_2_needs_a_key_and_says_where_to_put_it():
    with pytest.raises(ConfigError, match="link_key_file"):
        link_key(car())
    assert link_key(car(link_version=1)) is None


def test_keys_from_a_file_or_inline_and_bad_ones_refused(tmp_path):
    key = new_key()
    path = write_key_file(tmp_path / "car3.key", key)
    assert path.stat().st_mode & 0o077 == 0
    assert link_key(car(link_key_file=str(path))) == key
    assert link_key(car(link_key=key.hex())) == key
    (tmp_path / "short.key").write_text("abcd\n")
    with pytest.raises(ConfigError, match="32 bytes"):
        link_key(car(link_key_file=str(tmp_path / "short.key")))
    with pytest.raises(ConfigError, match="cannot read"):
        link_key(car(link_key_file=str(tmp_path / "missing.key")))
    with pytest.raises(ConfigError, match="64 hexadecimal"):
        car(link_key="zz" * 32).validate("cars[0]")
    with pytest.raises(ConfigError, match="does not use a key"):
        car(link_version=1, link_key=key.hex()).validate("cars[0]")


def test_senders_from_the_config_drive_a_car_with_the_key_and_a_restart_is_taken_at_once(tmp_path):
    key = new_key()
    with CommandReceiver(3, ("127.0.0.1", 0), key=key) as rx:
        config = car(link=f"udp://127.0.0.1:{rx.address[1]}", link_key=key.hex())
        with CommandSender.for_car(config, stop_repeats=0) as tx:
            assert tx.version == 2
            tx.send(0.3, 0.0)
            assert wait_for(lambda: rx.counters.accepted == 1, 2.0)
        with CommandSender.for_car(config, stop_repeats=0) as restarted:  # a new session, no waiting
            restarted.send(0.2, 0.0)
            assert wait_for(lambda: rx.counters.accepted == 2, 2.0)
            assert rx.counters.new_session == 2 and rx.last_command.v_mps == pytest.approx(0.2)
        old_firmware = dataclasses.replace(config, link_version=1, link_key="")
        with CommandSender.for_car(old_firmware, stop_repeats=0) as v1:
            assert v1.version == 1
            v1.send(0.1, 0.0)
            assert wait_for(lambda: rx.counters.decode_errors.get("length") == 1, 2.0)
        assert rx.counters.accepted == 2
