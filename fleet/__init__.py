"""The fleet's processes and their orchestration, composed from the layers below it.

Its rooms, from the bottom up (each imports only rooms listed before it):

* ``program``      what every trustfg process shares: parser, signals, config or a clear exit
* ``cpu``          what each process of a run costs, from the kernel's accounting
* ``bus``          Zenoh: one session per process, key expressions, TLS, the router
* ``car``          one car's process, its velocity-command loop, its report
* ``sim``          the in-process fleet, run records, ORCA, scenes made from a seed
* ``operator``     the operator's session, ``trustfg go``, the e-stop, the bring-up check
* ``recording``    MCAP recordings and the Foxglove scene
* ``launch``       ``trustfg sim``: a fleet as OS processes, its ports, keys and summary
* ``experiments``  the paper's experiments, attacks, sweeps, the scenario bank
* ``faultlab``     network namespaces and the fault matrix
"""
