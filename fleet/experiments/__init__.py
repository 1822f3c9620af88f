"""The experiments run on the in-process fleet: the paper's experiments, the attack suite,
the transparency sweep, the scenario bank with its journals, reports and reruns, their
statistics, figures, and the worker pool that runs independent runs in parallel.

It imports fleet.sim and fleet.program (and trustfg.agent); never a bus or a car process.
"""
