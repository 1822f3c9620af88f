"""What people look at: the live fleet web page, recorded runs and report figures."""
