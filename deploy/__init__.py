"""Configs that ship with trustfg (package data, found with importlib.resources).

scenarios/  scenes for the simulations (``--scenario NAME``)
lab/        lab fleet configs (one car process per car computer)
zenoh/      Zenoh session variants (listed endpoints, multicast, a router)
systemd/    the car process as a service
tls/        the script that makes a fleet's certificates (never commit its output)
"""
