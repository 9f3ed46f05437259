"""What each end checks in the handshake, and the one line it gives for each failure.

:class:`link.Session` calls these: :func:`signing_mismatch` on every frame read while waiting
for the peer's hello (the first frame showing the peer signs differently ends the handshake), then
:func:`check_peer_hello` on the hello itself. The runtime adds its own checks of the device's hello
(sample period, link mode, noise, drug, concentration, pump maximum: ``pressor.runtime.session``,
``pressor.runtime.inputs.clinician``); every refusal carries a ``PRESSOR_REFUSAL_REASON`` code that
:meth:`link.Session.refuse` sends the peer (docs/PROTOCOL.md, "Refusals").
"""

from __future__ import annotations

from pressor.link.counters import HelloRefused
from pressor.link.messages import (
    PROTOCOL_VERSION,
    REFUSAL_PROTOCOL_VERSION,
    REFUSAL_ROLE,
    REFUSAL_SYSTEM_ID,
    ROLE_DEVICE,
    ROLE_RUNTIME,
    Hello,
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
