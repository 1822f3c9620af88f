"""The fleet's processes and their orchestration, composed from the layers below.

It owns the Zenoh bus (one session per process, the key table, mutual TLS and access
control), the car process (agent + bridge on real threads and sockets), the launcher of a
whole simulated fleet (``trustfg sim``), the operator's start (``trustfg go``), the
deterministic in-process fleet and the experiments run on it, recordings (MCAP) and the
figures drawn from runs, and the fault lab (network namespaces, the fault matrix).
"""
