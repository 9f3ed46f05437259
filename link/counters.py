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
        Retransmitted ticks or commands received again (ignored, or answered once more).
    retransmits
        Frames this end re-sent on its own (a command for a retransmitted tick; a tick the device
        sent again after a timeout).
    stale
        Messages for a tick other than the one expected (ignored).
    incomplete_ticks
        Lockstep only: MAP samples dropped because the tick's scheduling or target frame was lost
        (left unanswered, so the device sends the whole tick again).
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
    incomplete_ticks: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain dict (JSON-ready)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}
