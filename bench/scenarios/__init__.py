"""Closed-loop robot scenarios: the control loop that times each step, and its figures."""
