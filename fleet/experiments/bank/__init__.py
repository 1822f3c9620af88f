"""The scenario bank: every scene, many seeds, our pipeline and the baselines a user would
pick; its journals (one JSON line per run), the report with confidence intervals, and the
rerun that checks a journal entry comes out the same.

It imports fleet.experiments' shared parts and fleet.sim.
"""
