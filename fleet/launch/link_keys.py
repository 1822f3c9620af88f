"""Fresh car-link keys for a run on this machine (``trustfg sim``, the fault lab, tests).

Every car that speaks the authenticated link (version 2) and has no key of its own gets a
new random key in ``FOLDER/carN.link.key`` (readable by its owner only); the config then names
that file, so the run's fleet.toml -- and the recording that embeds it -- holds no key.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from ...agent.config import Scenario
from ...bridge.carlink import new_key, write_key_file
from ...bridge.carlink.keys import key_file_name


def with_link_keys(scenario: Scenario, folder: Path) -> Scenario:
    cars = []
    for car in scenario.cars:
        if car.link_version == 2 and not (car.link_key_file or car.link_key):
            path = write_key_file(folder / key_file_name(car.id), new_key())
            car = dataclasses.replace(car, link_key_file=str(path.resolve()))
        cars.append(car)
    return dataclasses.replace(scenario, cars=tuple(cars))
