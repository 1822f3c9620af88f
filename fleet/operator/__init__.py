"""The operator's tools: the operator's session (heartbeat, trials), ``trustfg go``, the
emergency stop on its two independent paths (over the bus, and E_STOP datagrams straight to
each car's link, the first of them sent before the program loads), and the bring-up check.

It imports trustfg.agent, trustfg.bridge, fleet.bus, fleet.program and fleet.sim (scene checks).
"""
