"""Recorded runs: every fleet message of a live run into an MCAP file (``trustfg record``),
read back for reports and replays, and the fleet drawn in Foxglove's well-known schemas.

It imports fleet.bus and fleet.program.
"""
