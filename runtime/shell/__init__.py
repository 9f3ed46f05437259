"""The shell around the core: fixed-rate loop, clocks, timing, CPU placement, stop signals, the
live view's viewer process (``--view``).

On the shipped path: :class:`pressor.runtime.shell.loop.Loop` runs the core once per period against the
link and hands each tick to the recorder.
"""
