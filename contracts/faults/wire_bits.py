"""Bit flags both ends of the link agree on: pump alarms and monitor sample quality.

The wire definition is the dialect's bitmask enums ``PRESSOR_PUMP_ALARM`` and
``PRESSOR_MAP_QUALITY`` in ``link/pressor.xml`` (docs/PROTOCOL.md); these are the same values
for the packages that may not import ``link`` (``tests/link/test_dialect.py`` holds them equal).
The simulator's pump and monitor set them, the runtime's supervisor reads them.
"""

#: pump alarm bit flags carried by PUMP_STATUS (pressor.hil_sim.devices.pump uses these values)
PUMP_ALARM_OCCLUSION = 1
PUMP_ALARM_RESERVOIR_EMPTY = 2
PUMP_ALARM_WATCHDOG = 4
PUMP_ALARM_INVALID_COMMAND = 8
PUMP_ALARM_OUT_OF_RANGE = 16

#: monitor quality bits carried by MAP_SAMPLE.quality (pressor.hil_sim.devices.sensor uses these values)
QUALITY_INVALID = 1
QUALITY_WAVEFORM = 2  # the monitor's waveform check: no pulsatility / over-damped line
QUALITY_HELD = 4  # value repeated, the monitor has no newer one: not a fault (sample-and-hold)
