"""One car's mind, pure: no sockets, threads or processes.

It owns planning (a GTSAM factor graph over the car's GP trajectory, with obstacle and
trust factors), trust in every peer (Beta reputation, testimony fusion), what a car sees
and believes (tracks, peers' plans), the fleet's messages (msgpack codec and inbox), the
typed configuration of everything, the unicycle model of a car, and the metrics of
executed motion. The processes that run it live in ``trustfg.fleet``; links to hardware
in ``trustfg.bridge``.
"""
