"""The shell around the core: fixed-rate loop, clocks, timing, CPU placement, stop signals.

On the shipped path: :class:`pressor.runtime.shell.loop.Loop` runs the core once per period against the
link and hands each tick to the recorder.
"""
