"""The fault lab: Linux network namespaces, nftables rules and a delaying relay
(fleet.faultlab.netem), and the fault matrix that runs ``trustfg sim`` under each fault
(``trustfg faults``, root only).

It sits on top of fleet/: it imports fleet.launch.
"""
