"""What each end checks in the handshake, and the one line it gives for each failure; a received
hello read as a :class:`Hello` (:func:`hello_of`).

:class:`link.Session` calls these: :func:`signing_mismatch` on every frame read while waiting
for the peer's hello (the first frame showing the peer signs differently ends the handshake), then
:func:`check_peer_hello` on the hello itself. The runtime adds its own checks of the device's hello
(sample period, link mode, noise, drug, concentration, pump maximum: ``pressor.runtime.session``,
``pressor.runtime.inputs.clinician``); every refusal carries a ``PRESSOR_REFUSAL_REASON`` code that
:meth:`link.Session.refuse` sends the peer (docs/PROTOCOL.md, "Refusals").
"""

from __future__ import annotations

from typing import Any

from pressor.link.counters import HelloRefused
from pressor.link.messages import (
    PROTOCOL_VERSION,
    REFUSAL_CONCENTRATION,
    REFUSAL_DRUG,
    REFUSAL_LINK_MODE,
    REFUSAL_PROTOCOL_VERSION,
    REFUSAL_PUMP_MAXIMUM,
    REFUSAL_ROLE,
    REFUSAL_SAMPLE_PERIOD,
    REFUSAL_SENSOR_NOISE,
    REFUSAL_SYSTEM_ID,
    ROLE_DEVICE,
    ROLE_RUNTIME,
    Hello,
)


def field_text(value: bytes | str) -> str:
    """A ``char[N]`` field as text (pymavlink hands out bytes or str, NUL padding removed)."""
    text = value.decode("ascii", "replace") if isinstance(value, bytes) else value
    return text.rstrip("\0")


def hello_of(msg: Any) -> Hello:
    """A received PRESSOR_HELLO message object as a :class:`Hello`."""
    return Hello(
        field_text(msg.name),
        msg.patient_seed,
        msg.sample_period_s,
        msg.sensor_noise_mmhg,
        msg.n_ticks,
        msg.link_mode,
        msg.role,
        msg.protocol_version,
        field_text(msg.drug),
        msg.concentration_ug_ml,
        msg.pump_max_ml_h,
    )


#: role value -> name, for refusal texts
ROLE_NAMES = {ROLE_RUNTIME: "runtime", ROLE_DEVICE: "device"}


def signing_mismatch(peer: str, refusal: str | None, peer_signed: bool) -> str | None:
    """The cause, as one line, when the peer signs differently from this end; else ``None``.

    Parameters
    ----------
    peer
        The peer's name (``device`` / ``runtime``).
    refusal
        Why the codec refused the last signed frame: ``unsigned``, ``key``, ``stale`` or ``None``.
    peer_signed
        Whether the peer signs although this end has no key.
    """
    why = {
        "unsigned": f"the {peer}'s frames are unsigned but this end signs: give the {peer}"
        " the same key (--signing-key FILE) or run both ends with --no-signing",
        "key": f"the {peer} signs with another key: give both ends the same key file"
        " (pressor keygen; --signing-key FILE)",
        "stale": f"the {peer}'s signing timestamps are replayed or more than a minute old"
        f" (frames of an earlier run, or a wrong clock on the {peer})",
    }.get(refusal or "")
    if why is None and peer_signed:
        why = (
            f"the {peer} signs its frames but this end has no key: give it the same key"
            f" (--signing-key FILE) or start the {peer} with --no-signing"
        )
    return None if why is None else f"signing mismatch: {why}"


def check_peer_hello(peer: Hello, system_id: int | None, name: str, role: int) -> None:
    """Refuse a peer hello of the wrong role, system id or protocol version.

    Parameters
    ----------
    peer
        The peer's hello.
    system_id
        The MAVLink system id its frame came from.
    name, role
        The name (``device`` / ``runtime``) and ``ROLE_*`` value the peer must have; its system
        id must equal its role (runtime 1, device 2).

    Raises
    ------
    HelloRefused
        With ``REFUSAL_ROLE``, ``REFUSAL_SYSTEM_ID`` or ``REFUSAL_PROTOCOL_VERSION`` (checked in
        that order), the text naming both values.
    """
    if peer.role != role:
        raise HelloRefused(
            REFUSAL_ROLE,
            f"{name} hello: peer announced role {peer.role}"
            f" ({ROLE_NAMES.get(peer.role, 'unknown')}), expected {role} ({name})",
        )
    if system_id != role:
        raise HelloRefused(
            REFUSAL_SYSTEM_ID,
            f"{name} hello from MAVLink system id {system_id}, expected {role}"
            " (the system id is the role: runtime 1, device 2)",
        )
    if peer.protocol_version != PROTOCOL_VERSION:
        raise HelloRefused(
            REFUSAL_PROTOCOL_VERSION,
            f"{name} hello: peer protocol_version {peer.protocol_version}, expected"
            f" {PROTOCOL_VERSION}",
        )


#: the fields of a hello that set the terms of a run, each with its refusal reason: a hello in the
#: middle of the run must announce the same (docs/PROTOCOL.md, "A hello in the middle of a run")
RUN_TERMS: tuple[tuple[str, str, int, str], ...] = (
    ("role", "role", REFUSAL_ROLE, ""),
    ("protocol_version", "protocol version", REFUSAL_PROTOCOL_VERSION, ""),
    ("sample_period_s", "sample period", REFUSAL_SAMPLE_PERIOD, " s"),
    ("sensor_noise_mmhg", "noise", REFUSAL_SENSOR_NOISE, " mmHg"),
    ("link_mode", "link mode", REFUSAL_LINK_MODE, ""),
    ("drug", "drug", REFUSAL_DRUG, ""),
    ("concentration_ug_ml", "concentration", REFUSAL_CONCENTRATION, " ug/ml"),
    ("pump_max_ml_h", "pump maximum", REFUSAL_PUMP_MAXIMUM, " ml/h"),
)


def hello_change(first: Hello, later: Hello, name: str) -> HelloRefused | None:
    """The refusal of a hello received in the middle of a run that changes its terms, else
    ``None`` (the same terms again: a device repeating itself or reconnecting).

    Parameters
    ----------
    first
        The hello the run was started on (checked at the handshake).
    later
        A hello received after the handshake.
    name
        The peer's name (``device``) for the text.

    Returns
    -------
    HelloRefused or None
        With the reason of the first field that differs, in the handshake's order
        (:data:`RUN_TERMS`: role, version, sample period, noise, link mode, drug, concentration,
        pump maximum; a NaN differs from everything), the text naming every changed field with
        both values.
    """
    changes = []
    reason = 0
    for field, label, code, unit in RUN_TERMS:
        old, new = getattr(first, field), getattr(later, field)
        if isinstance(old, str):
            same = old.strip().lower() == new.strip().lower()
        else:
            same = old == new  # False for NaN: an announcement of nothing is a change
        if not same:
            reason = reason or code
            changes.append(f"{label} {_value(old)} -> {_value(new)}{unit}")
    if not changes:
        return None
    return HelloRefused(
        reason,
        f"{name} hello in the middle of the run changes {', '.join(changes)}: refused, the run"
        " keeps its first hello",
    )


def _value(v: object) -> str:
    """A hello field's value for a refusal text (numbers short: ``200``, ``0.1``)."""
    return f"{v:g}" if isinstance(v, float) else str(v or "(none)")
