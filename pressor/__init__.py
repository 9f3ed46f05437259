"""pressor's front door: the ``pressor`` console script dispatcher (see :mod:`pressor.cli`)."""
