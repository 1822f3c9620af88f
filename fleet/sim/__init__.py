"""The fleet in one process: deterministic, simulated time, every car a real CarAgent;
the record of a run and its summary, the trust a run's reports show over time, the ORCA
baseline on the same simulated cars, and scenes made from a seed.

It imports trustfg.agent, trustfg.bridge and fleet.program; no bus, no process, no socket.
"""
