"""The first exchange of a run: the runtime's hello, the device's, and the checks between them.

:func:`handshake` is the first stage of :func:`pressor.runtime.session.run_runtime`: it offers the
run's terms (link mode and rate, drug and syringe, pump maximum) until the device answers, then
holds the device's hello against them, and a device that does not match is told why before the
link closes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from pressor.runtime.inputs.clinician import ClinicianInput
from pressor.runtime.inputs.config import RunConfig
from pressor.runtime.inputs.controller_loader import controller_name
from pressor.runtime.inputs.hello_checks import check_device_hello, check_link_hello
from pressor.runtime.shell.interrupt import Interrupted, stop_requested

if TYPE_CHECKING:
    from pressor.contracts.controller import Controller
    from pressor.link import Hello, RuntimeSession

__all__ = ["handshake"]


def handshake(
    ep: RuntimeSession,
    config: RunConfig,
    controller: Controller,
    clinician: ClinicianInput,
    peer_alive: Callable[[], bool] | None,
    handshake_timeout_s: float,
    on_connected: Callable[[], object] | None,
) -> Hello:
    """Send the runtime's hello until the device answers, call ``on_connected``, check the
    device's hello against the run (link mode and rate, pump, syringe); return it.

    Short attempts, so that a device process that died (``peer_alive`` false) or a stop request
    ends the wait at once; a signing mismatch or a refused hello is raised at once, any other link
    error once ``handshake_timeout_s`` wall seconds have passed. A mismatch is sent to the device
    (so it is told why) before :class:`link.HelloRefused` is raised.
    """
    from pressor.link import (
        LINK_LOCKSTEP,
        LINK_REALTIME,
        Hello,
        HelloRefused,
        LinkError,
        SigningMismatch,
    )

    mode = LINK_REALTIME if config.realtime else LINK_LOCKSTEP
    hello = Hello(
        controller_name(config.controller)[:32],
        sample_period_s=config.period_s,
        link_mode=mode,
        drug=clinician.drug,
        concentration_ug_ml=clinician.concentration_ug_ml,
        pump_max_ml_h=controller.max_rate_ml_h,
    )
    waited = 0.0
    while True:  # short attempts, so a device process that died is noticed at once
        if (stop := stop_requested()) is not None:
            raise Interrupted(stop, "before the device connected")
        try:
            peer = ep.handshake(hello, timeout_s=0.25)
            break
        except (SigningMismatch, HelloRefused):  # a refused device was told why
            raise
        except LinkError:
            waited += 0.25
            if (peer_alive is not None and not peer_alive()) or waited >= handshake_timeout_s:
                raise
    if on_connected is not None:
        on_connected()
    try:
        check_link_hello(peer, config.period_s, config.rate_hz, mode)
        check_device_hello(peer, controller.max_rate_ml_h, clinician)
    except HelloRefused as exc:  # the device is told why before the link closes
        ep.refuse(exc)
        raise
    ep.lock_terms()  # a later hello may not change what was checked here
    return peer
