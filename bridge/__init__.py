"""One car's links and control: from OptiTrack poses to the car's velocity commands.

It owns the NatNet codec and client that ingest Motive's poses, the UDP car link that
carries velocity commands (codec, the car's receiving rules, sockets), the trajectory
tracking controller that turns a plan into a command, and the proximity guard that caps
the speed under any plan.
"""
