"""A stand-in for the lab's hardware: simulated cars and a simulated OptiTrack.

It owns the vehicle model (unicycle kinematics with limits and noise), simulated cars
that obey the same UDP commands as real ones (watchdog included), and a NatNet server
that streams genuine NatNet frames of their poses.
"""
