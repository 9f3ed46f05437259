"""The bedside devices as the runtime meets them: the infusion pump and the MAP monitor (the
bottom layer), and ``pressor device``, the process that plays pump, monitor and patient on the far
side of the serial link (:mod:`pressor.hil_sim.devices.device`, :mod:`pressor.hil_sim.devices.device_options`; above the
world it runs).
"""
