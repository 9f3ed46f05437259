"""The pure per-tick closed loop: supervisor, dose guard, scheduling protocol, controller step.

On the shipped path (``pressor run`` and every simulated run step the same core). No I/O, no
clock, no recording: the bottom of ``runtime``; it imports nothing else from ``runtime``.
"""
