"""``trustfg sim``: a whole fleet as OS processes on one machine (car processes, mocap-sim,
the operator's session), the child processes and their ports, fresh car-link keys for a
run, the run's summary, and a loopback testbed for tests and benchmarks.

It imports the rooms below it: fleet.bus, fleet.car, fleet.operator, fleet.sim,
fleet.recording, fleet.program and fleet.cpu.
"""
