"""The car's mind: one agent per car.

It owns planning (a GTSAM factor graph over the car's GP trajectory, with obstacle and
trust factors), trust estimation in every peer (Beta reputation, testimony fusion), the
fleet messages and the Zenoh bus they travel on, the in-process fleet simulation and
the paper's experiments. Hardware I/O lives in ``bridge``; the simulated hardware in
``mocap_sim``.
"""
