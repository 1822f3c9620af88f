"""One car's process: the agent and the bridge together, the 50 Hz velocity-command loop in a
process of its own with the handle that feeds it plans and permits, the car's report of
itself, and laps for long runs.

It imports trustfg.agent, trustfg.bridge, fleet.bus, fleet.program and fleet.cpu; nothing
above it (operator, launch, experiments) is imported here.
"""
