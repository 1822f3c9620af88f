"""Hardware links of one car process.

It owns the NatNet client that ingests OptiTrack (Motive) poses, the UDP car link that
carries velocity commands to a car, and the trajectory-tracking controller that turns a
plan into those commands.
"""
