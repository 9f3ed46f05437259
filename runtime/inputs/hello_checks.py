"""What the runtime refuses in a device's hello, before the first tick.

:func:`check_device_hello` refuses a device whose hello announces another drug, another
concentration or a pump that cannot reach the controller's maximum rate (docs/PROTOCOL.md,
"Clinician's input"), :func:`check_link_hello` one whose sample period, link mode or announced
noise does not fit the run; each raises :class:`link.HelloRefused` with its reason code, which the
runtime sends the device before it closes the link (docs/PROTOCOL.md, "Refusals").
"""

from __future__ import annotations

import math
from typing import Any

from pressor.runtime.inputs.clinician import ClinicianInput


def check_link_hello(peer: Any, period_s: float, rate_hz: float, link_mode: int) -> None:
    """Refuse a device whose hello does not fit the run's timing or announces impossible noise.

    Parameters
    ----------
    peer
        The device's :class:`link.Hello`.
    period_s, rate_hz
        The runtime's loop period (s) and rate (Hz, as given by ``--rate``).
    link_mode
        The runtime's ``LINK_LOCKSTEP`` / ``LINK_REALTIME``.

    Raises
    ------
    link.HelloRefused
        One line naming both values: ``REFUSAL_SAMPLE_PERIOD`` (the periods differ by more than
        1e-9 s), ``REFUSAL_SENSOR_NOISE`` (noise not in [0, 50] mmHg) or ``REFUSAL_LINK_MODE``.
    """
    from pressor.link import (
        LINK_REALTIME,
        REFUSAL_LINK_MODE,
        REFUSAL_SAMPLE_PERIOD,
        REFUSAL_SENSOR_NOISE,
        HelloRefused,
    )

    if not abs(peer.sample_period_s - period_s) <= 1e-9:  # NaN refused too
        raise HelloRefused(
            REFUSAL_SAMPLE_PERIOD,
            f"device sample_period_s {peer.sample_period_s} s differs from --rate"
            f" {rate_hz} Hz (period {period_s} s)",
        )
    if not 0.0 <= peer.sensor_noise_mmhg <= 50.0:  # False for NaN too
        raise HelloRefused(
            REFUSAL_SENSOR_NOISE,
            f"device announces sensor_noise_mmhg {peer.sensor_noise_mmhg}: allowed [0, 50] mmHg",
        )
    if peer.link_mode != link_mode:  # the device's clock and ours would both think they lead
        theirs, ours = (
            "real time" if m == LINK_REALTIME else "lockstep" for m in (peer.link_mode, link_mode)
        )
        raise HelloRefused(
            REFUSAL_LINK_MODE,
            f"device runs {theirs} (hello link_mode {peer.link_mode}) but this runtime"
            f" runs {ours}: {'add' if peer.link_mode == LINK_REALTIME else 'drop'} --realtime",
        )


def check_device_hello(peer: Any, max_rate_ml_h: float, clinician: ClinicianInput) -> None:
    """Refuse a device whose syringe or pump does not fit the loaded controller.

    Parameters
    ----------
    peer
        The device's :class:`link.Hello`.
    max_rate_ml_h
        The controller's largest command (ml/h).
    clinician
        The drug and concentration the loaded design is for (checked against the design by
        :func:`pressor.runtime.inputs.dosing.bind_syringe`).

    Raises
    ------
    link.HelloRefused
        One line naming both values: another drug (``REFUSAL_DRUG``), another concentration
        beyond float32 rounding (``REFUSAL_CONCENTRATION``), or a pump maximum below the
        controller's (``REFUSAL_PUMP_MAXIMUM``: a pump that cannot deliver every rate the
        controller commands; a larger pump maximum is fine: the runtime never commands more than
        the controller's).
    """
    from pressor.link import REFUSAL_CONCENTRATION, REFUSAL_DRUG, REFUSAL_PUMP_MAXIMUM, HelloRefused

    drug = peer.drug.strip().lower()
    if drug != clinician.drug:
        raise HelloRefused(
            REFUSAL_DRUG,
            f"device drug {drug or '(none announced)'} differs from the loaded design's"
            f" {clinician.drug}",
        )
    conc, want = float(peer.concentration_ug_ml), clinician.concentration_ug_ml
    if not math.isclose(conc, want, rel_tol=1e-6):
        raise HelloRefused(
            REFUSAL_CONCENTRATION,
            f"device concentration {conc:g} ug/ml differs from the loaded design's {want:g} ug/ml",
        )
    pump_max = float(peer.pump_max_ml_h)
    if not pump_max >= max_rate_ml_h * (1.0 - 1e-6):  # NaN refused too
        raise HelloRefused(
            REFUSAL_PUMP_MAXIMUM,
            f"device pump maximum {pump_max:g} ml/h differs from the controller's"
            f" {max_rate_ml_h:g} ml/h: the pump cannot deliver every rate the controller commands",
        )
