"""What a link session counts, and the errors that end a session."""

from __future__ import annotations

from dataclasses import dataclass, fields


class LinkError(RuntimeError):
    """The link cannot go on (handshake failed, peer mismatch)."""


class SigningMismatch(LinkError):
    """The peer signs differently: unsigned, another key, stale timestamps, or signed while this
    end is not (raised by the handshake at the first such frame)."""


class LinkClosedError(LinkError):
    """The peer closed the link (or the port vanished)."""


class Refusal(LinkError):
    """A hello refused, by this end (:class:`HelloRefused`) or by the peer
    (:class:`PeerRefused`); the commands exit 2 on it."""


class HelloRefused(Refusal):
    """This end refuses the peer's hello (docs/PROTOCOL.md, "Refusals").

    Parameters
    ----------
    reason
        The ``PRESSOR_REFUSAL_REASON`` value (``link.REFUSAL_*``).
    text
        One line naming both values; the message of the exception, and what
        :meth:`link.Session.refuse` sends the peer.
    """

    def __init__(self, reason: int, text: str) -> None:
        super().__init__(text)
        self.reason = reason
        self.text = text


class PeerRefused(Refusal):
    """The peer refused this end's hello: its PRESSOR_REFUSAL arrived.

    Parameters
    ----------
    reason
        The ``PRESSOR_REFUSAL_REASON`` value the peer sent.
    text
        The peer's one line.
    peer
        The peer's name, for the message (``refused by the runtime: TEXT``).
    """

    def __init__(self, reason: int, text: str, peer: str = "peer") -> None:
        super().__init__(f"refused by the {peer}: {text}")
        self.reason = reason
        self.text = text


@dataclass(slots=True)
class LinkCounters:
    """What the session saw and did; all counts since the session was made.

    Attributes
    ----------
    frames_sent, bytes_sent
        Frames (bytes) written.
    frames_received, bytes_received
        Frames accepted (bytes read, accepted or not).
    bad_crc
        Complete candidate frames that failed the CRC or decoding.
    junk_bytes
        Bytes skipped while hunting for a frame start.
    resyncs
        Partial frames abandoned after a wait timed out.
    seq_gaps, frames_lost
        Sequence jumps (events) and the frames they imply were lost.
    timeouts
        Waits (sample, command, handshake) that ended without what they waited for.
    refused_unsigned, refused_bad_signature
        Frames refused by signing: unsigned, or signed with a wrong key / replayed timestamp.
    duplicates
        MAP samples of a tick already held or answered (a resent tick, a duplicated frame; the
        runtime answers a resent tick it already answered once more), or commands for a tick
        already applied (device); ignored.
    old_ticks
        MAP samples of an earlier tick than one already held or answered (ignored).
    retransmits
        Frames this end re-sent on its own (a command for a retransmitted tick; a tick the device
        sent again after a timeout).
    stale
        MAP samples superseded by a newer one before the loop took them (real time), or commands
        for a later tick than the one expected (device); ignored.
    incomplete_sched, incomplete_target, incomplete_status
        Lockstep only: ticks the device had to resend because their first transmission lacked
        the SCHEDULING_PARAMS (when required), the MAP_TARGET (when required) or the PUMP_STATUS
        (once the device sent one) of the tick; a tick lacking several counts in each. A lost
        pump status is not resent: the tick then goes to the loop without it.
    misnumbered_status
        Lockstep only: PUMP_STATUS frames numbered for a tick already answered (a device that
        numbers the status of tick k's command k instead of k+1). The runtime cannot use them,
        so its pump checks (alarms, delivered versus commanded) do not run; counted and raised
        as the advisory ``LINK_ERRORS`` instead of passing silently.
    wrong_system
        Frames (hellos excepted) from another MAVLink system id than the peer's role: this end's
        own frames echoed back by the line (a tty in cooked mode), or a third node. Dropped
        before they count as received, so they never pass for the peer's liveness.
    """

    frames_sent: int = 0
    bytes_sent: int = 0
    frames_received: int = 0
    bytes_received: int = 0
    bad_crc: int = 0
    junk_bytes: int = 0
    resyncs: int = 0
    seq_gaps: int = 0
    frames_lost: int = 0
    timeouts: int = 0
    refused_unsigned: int = 0
    refused_bad_signature: int = 0
    duplicates: int = 0
    retransmits: int = 0
    stale: int = 0
    old_ticks: int = 0
    incomplete_sched: int = 0
    incomplete_target: int = 0
    incomplete_status: int = 0
    misnumbered_status: int = 0
    wrong_system: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain dict (JSON-ready)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def incomplete(self) -> int:
        """Lockstep ticks resent because they were incomplete (each cause counted)."""
        return self.incomplete_sched + self.incomplete_target + self.incomplete_status

    def discarded(self) -> int:
        """What the link layer discarded or could not use, all causes that raise the runtime's
        advisory ``LINK_ERRORS``: bad frames, junk, abandoned partial frames, sequence gaps,
        incomplete ticks, misnumbered pump statuses, frames of another system id, refused
        signatures."""
        return (
            self.bad_crc
            + self.junk_bytes
            + self.resyncs
            + self.seq_gaps
            + self.incomplete()
            + self.misnumbered_status
            + self.wrong_system
            + self.refused_unsigned
            + self.refused_bad_signature
        )


#: What the runtime's session drops, by cause: the counters above that count discarded frames
#: or samples (the run summary's ``link_dropped``, docs/PROTOCOL.md).
DROP_CAUSES: tuple[str, ...] = (
    "bad_crc",
    "resyncs",
    "refused_unsigned",
    "refused_bad_signature",
    "duplicates",
    "old_ticks",
    "stale",
    "incomplete_sched",
    "incomplete_target",
    "incomplete_status",
    "misnumbered_status",
    "wrong_system",
)
