"""The fleet bus: one Zenoh session per process, the table of key expressions and their
QoS, mutual TLS and access control, and a router for members that cannot reach each other.

It owns every Zenoh call of trustfg. It imports trustfg.agent (messages) and fleet.program,
and nothing else of fleet/: every other room of fleet/ talks to the fleet through it.
"""
