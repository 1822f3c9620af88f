"""trustfg: trust-aware, decentralized motion planning for robot fleets.

The repository keeps one top-level folder per layer; ``pyproject.toml`` installs each of
them under this package, so everything imports as ``trustfg.<layer>``:

* ``trustfg.agent``     one car's mind, pure: planner, trust, plans, messages, config
* ``trustfg.bridge``    one car's links and control: NatNet, car link, tracking, guard
* ``trustfg.fleet``     processes: bus, car process, launcher, experiments, fault lab
* ``trustfg.mocap_sim`` the stand-in hardware: simulated cars and OptiTrack
* ``trustfg.dashboard`` what people look at: the live page and reports
* ``trustfg.deploy``    configs that ship: scenarios, lab fleets, Zenoh variants

A layer imports only layers listed above it here (agent at the bottom); ``trustfg.cli``,
the command, sits on top of all. docs/design/architecture.md tells the whole story.
"""

__version__ = "0.3.0"
"""The release (CHANGELOG.md); pyproject.toml reads it from here."""
