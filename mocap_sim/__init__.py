"""A stand-in for the lab's hardware: simulated cars and a simulated OptiTrack.

It owns simulated cars that obey the same UDP commands as real ones (through the car
link's own receiving rules, watchdog included) and a NatNet server that streams genuine
NatNet frames of their poses, encoded with the codec the bridge decodes with.
"""
