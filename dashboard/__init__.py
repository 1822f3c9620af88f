"""What people look at: the live page of the fleet and reports of recorded runs.

It owns the fleet as the page sees it (state: poses, plans, trust, distances, alerts),
the web server that serves it live from the bus or replays a recording, and the HTML
report with figures drawn from a recording.
"""
