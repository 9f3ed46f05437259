"""Framing of the pressor link: pack frames, scan a byte stream for them, check and decode them.

A :class:`FrameCodec` owns one end's generated ``MAVLink`` object (``pressor.link.dialect.pressor``: system
and component ids, sequence number, signing state), its receive buffer and its per-stream sequence
tracking, and counts into the session's :class:`~pressor.link.counters.LinkCounters`.

Framing. The codec frames the byte stream itself and hands each complete candidate frame to the
generated ``MAVLink.decode`` (what ``parse_buffer`` does internally, minus its weaknesses):

- a candidate must start with 0xFD, carry a message id of this dialect, a payload length no longer
  than that message's and no unknown incompatibility flag; otherwise the byte is junk and the
  scanner moves on by one byte;
- a frame that fails its CRC is counted (``bad_crc``) and the scanner resumes one byte after its
  start, not after its claimed length - so a corrupted length byte loses that frame only, instead
  of swallowing the following ones as pymavlink's ``robust_parsing`` does;
- a corrupted length that claims *more* bytes than will ever come stalls the frame at the end of a
  burst; :meth:`FrameCodec.drop_stalled` (called when a wait times out) drops its first byte, then
  the session rescans
  (``resyncs``).

Sequence numbers are tracked per (system, component); a jump counts one ``seq_gaps`` event and
``frames_lost`` missing frames.

Signing (MAVLink 2). With a :class:`~pressor.link.signing.Signing`, every outgoing frame is signed, and
incoming frames are checked against the same key; unsigned frames (``require=True``) and frames
with a wrong signature or a replayed timestamp are refused and counted (``refused_unsigned``,
``refused_bad_signature``; :attr:`FrameCodec.refusal` says why the last one was). The signing
timestamp (10 µs units, then +1 per frame as the protocol requires) comes from the wall clock for
keys with ``wall_clock`` (key files, random per-run keys: frames of an earlier run are refused),
else from the session's run clock (seeded keys: signed runs are byte-identical).

Hot path. Messages without arrays or strings (all but the hello) are packed by
:meth:`FrameCodec.pack_fields` and decoded into plain field tuples: byte-identical to pymavlink's
``pack``/``decode`` (a test compares them) but without its per-frame header and message objects,
at about half pymavlink's cost (docs/notes/benchmarks.md, "Design measurements").
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Callable
from typing import Any

from pressor.link.counters import LinkCounters
from pressor.link.dialect import pressor as mavlink
from pressor.link.signing import Signing

_MARKER = 0xFD
_HEADER = 10
_SIG = 13
_HDR = struct.Struct("<BBBBBBBHB")
_CRC = struct.Struct("<H")
_SIGN_STAMP = struct.Struct("<BQ")
_sha256 = hashlib.sha256
#: the generated module's C CRC-16/MCRF4XX (``fastcrc``), or None (then no fast codec)
_mcrf4xx = getattr(mavlink, "mcrf4xx", None)

_Perm = tuple[int, ...] | None

#: ``accept(msgid, payload, fast, frame)``: an accepted frame's field tuple (``fast``) or message
#: object, and its bytes.
Accept = Callable[[int, Any, bool, bytearray], None]


def _fast_codecs() -> dict[int, tuple[Any, struct.Struct, bytes, _Perm, _Perm]]:
    """Per message id without arrays or strings: (class, struct, crc_extra byte, XML→wire
    permutation, wire→XML order; each permutation None when it is the identity, as for every
    pressor message). Those messages are packed and decoded here, byte-identical to
    pymavlink's ``pack``/``decode`` but without its per-frame objects (tests compare both)."""
    out = {}
    if _mcrf4xx is None:
        return out

    def perm(order: tuple[int, ...]) -> _Perm:
        return None if order == tuple(range(len(order))) else order

    for mid, cls in mavlink.mavlink_map.items():
        if any(n != 1 for n in cls.lengths) or any(t.startswith("char") for t in cls.fieldtypes):
            continue
        to_wire = tuple(cls.fieldnames.index(n) for n in cls.ordered_fieldnames)
        out[mid] = (
            cls,
            cls.unpacker,
            bytes([cls.crc_extra]),
            perm(to_wire),
            perm(tuple(cls.orders)),
        )
    return out


_FAST = _fast_codecs()
#: longest payload (bytes) of each message id: a candidate frame claiming more is junk
_ID_HELLO = mavlink.MAVLINK_MSG_ID_PRESSOR_HELLO
_MAXLEN = {mid: cls.unpacker.size for mid, cls in mavlink.mavlink_map.items()}


def message_object(msgid: int, values: tuple) -> Any:
    """The generated message object for field ``values`` (XML order) of message ``msgid``."""
    return mavlink.mavlink_map[msgid](*values)


class FrameCodec:
    """Pack and unpack the frames of one end of the link.

    Parameters
    ----------
    system_id, component_id
        MAVLink ids of this end.
    signing
        Sign outgoing frames and check incoming ones; ``None`` = no signing (signed incoming frames
        are then accepted unchecked, as pymavlink does).
    clock
        The run clock (callable returning s): the signing timestamps.
    counters
        Where receive-side events are counted.
    """

    def __init__(
        self,
        system_id: int,
        component_id: int,
        signing: Signing | None,
        clock: Callable[[], float],
        counters: LinkCounters,
    ) -> None:
        mav = mavlink.MAVLink(None, system_id, component_id)
        if signing is not None and signing.wall_clock:
            from pressor.link.signing import wall_clock_s

            clock = wall_clock_s
            # a receiver starts at its own wall-clock stamp: a new stream more than a minute
            # behind it (frames recorded in an earlier run) is refused
            mav.signing.timestamp = int(clock() * 100_000.0)
        if signing is not None:
            mav.signing.secret_key = signing.key
            mav.signing.link_id = signing.link_id
            mav.signing.sign_outgoing = True
            if not signing.require:
                mav.signing.allow_unsigned_callback = lambda _mav, _msgid: True
        #: the generated ``MAVLink`` object (ids, sequence number, signing state)
        self.mav = mav
        self.signed = signing is not None
        self.clock = clock
        self.counters = counters
        self.rx = bytearray()
        self._last_seq: dict[tuple[int, int], int] = {}
        #: why the last signed-link frame was refused: ``unsigned``, ``key`` (another key) or
        #: ``stale`` (timestamp replayed or more than a minute old); None if none was
        self.refusal: str | None = None
        #: an unsigned end accepted a signed frame (the peer has a key this end lacks)
        self.peer_signed = False
        #: the MAVLink system id the peer's frames must come from (its role); ``None``: any
        self.peer_system: int | None = None

    # ------------------------------------------------------------------ packing
    def _stamp(self) -> None:
        """Move the signing timestamp up to the run clock (10 µs units; never backwards)."""
        ts = int(self.clock() * 100_000.0)
        sg = self.mav.signing
        if ts > sg.timestamp:
            sg.timestamp = ts

    def pack(self, msg: Any) -> bytes:
        """Pack (and sign) a generated message object as the next frame."""
        if self.signed:
            self._stamp()
        mav = self.mav
        frame = msg.pack(mav)
        mav.seq = (mav.seq + 1) & 0xFF
        return frame

    def pack_fields(self, msgid: int, values: tuple) -> bytes:
        """Pack (and sign) message ``msgid`` from its field values in XML order as the next frame;
        byte-identical to :meth:`pack` of the generated message.

        The hot path of every tick: no message object, one struct pack, the C CRC, one sha256.
        Messages with arrays or strings (the hello) go through :meth:`pack`.
        """
        codec = _FAST.get(msgid)
        if codec is None:
            return self.pack(message_object(msgid, values))
        _cls, st, extra, to_wire, _ = codec
        payload = st.pack(*(values if to_wire is None else [values[j] for j in to_wire]))
        payload = payload.rstrip(b"\x00") or payload[:1]  # MAVLink 2 trailing-zero truncation
        mav = self.mav
        head = _HDR.pack(
            _MARKER,
            len(payload),
            1 if self.signed else 0,
            0,
            mav.seq,
            mav.srcSystem,
            mav.srcComponent,
            msgid & 0xFFFF,
            msgid >> 16,
        )
        body = head[1:] + payload
        frame = head + payload + _CRC.pack(_mcrf4xx(body + extra, 0xFFFF))
        if self.signed:
            sg = mav.signing
            ts = int(self.clock() * 100_000.0)  # run-clock timestamp, see _stamp()
            if ts > sg.timestamp:
                sg.timestamp = ts
            frame += _SIGN_STAMP.pack(sg.link_id, sg.timestamp)[:7]
            frame += _sha256(sg.secret_key + frame).digest()[:6]
            sg.timestamp += 1
        mav.seq = (mav.seq + 1) & 0xFF
        return frame

    def restart(self) -> None:
        """Forget received bytes and number frames from 0 again (a new session on the wire)."""
        self.rx.clear()
        self.mav.seq = 0

    # ---------------------------------------------------------------- receiving
    def drop_stalled(self) -> bool:
        """Abandon a partial frame that stalled (e.g. a corrupted length claiming more bytes):
        drop its first byte (counted in ``resyncs``); True if there was one (then rescan)."""
        if not self.rx:
            return False
        self.counters.resyncs += 1
        self.counters.junk_bytes += 1
        del self.rx[:1]
        return True

    def scan(self, data: bytes, accept: Accept) -> None:
        """Add received bytes; frame, decode, check and count them, and call ``accept`` with each
        accepted frame (in order). A partial frame at the end stays buffered."""
        c = self.counters
        c.bytes_received += len(data)
        rx = self.rx
        rx += data
        n = len(rx)
        i = 0
        maxlen = _MAXLEN
        fast = _FAST
        peer = self.peer_system
        while True:
            j = rx.find(_MARKER, i)
            if j < 0:
                c.junk_bytes += n - i
                i = n
                break
            if j > i:
                c.junk_bytes += j - i
                i = j
            if n - i < _HEADER:
                break
            plen = rx[i + 1]
            incompat = rx[i + 2]
            mid = rx[i + 7] | (rx[i + 8] << 8) | (rx[i + 9] << 16)
            limit = maxlen.get(mid)
            if limit is None or plen == 0 or plen > limit or incompat & 0xFE:
                c.junk_bytes += 1
                i += 1
                continue
            flen = _HEADER + plen + 2 + (_SIG if incompat & 1 else 0)
            if n - i < flen:
                break
            frame = rx[i : i + flen]
            codec = fast.get(mid)
            try:
                if codec is not None:
                    payload = self._decode_fields(frame, codec)
                else:
                    payload = self._decode_object(frame, incompat & 1)
            except mavlink.MAVError as exc:
                if "signature" in exc.message:
                    # CRC was good, so the framing is right: skip the whole frame
                    if incompat & 1:
                        c.refused_bad_signature += 1
                        key = self.mav.signing.secret_key
                        genuine = _sha256(key + frame[:-6]).digest()[:6] == frame[-6:]
                        self.refusal = "stale" if genuine else "key"
                    else:
                        c.refused_unsigned += 1
                        self.refusal = "unsigned"
                    i += flen
                else:
                    c.bad_crc += 1
                    c.junk_bytes += 1
                    i += 1
                continue
            i += flen
            if peer is not None and frame[5] != peer and mid != _ID_HELLO:
                # this end's own frames echoed back, or a third node: never the peer's liveness
                # (a hello passes, so that a wrong role or system id is refused by name)
                c.wrong_system += 1
                continue
            c.frames_received += 1
            if incompat & 1 and not self.signed:
                self.peer_signed = True
            key = (frame[5], frame[6])
            seq = frame[4]
            last = self._last_seq.get(key)
            if last is not None:
                gap = (seq - last - 1) & 0xFF
                if gap:
                    c.seq_gaps += 1
                    c.frames_lost += gap
            self._last_seq[key] = seq
            accept(mid, payload, codec is not None, frame)
        if i:
            del rx[:i]

    def _decode_fields(self, frame: bytearray, codec: tuple) -> tuple:
        """``MAVLink.decode`` for a framed message without arrays or strings, returning its field
        values in XML order: the same checks (CRC with crc_extra; with a key, the signature and
        its timestamp, unsigned frames refused unless allowed), no objects.

        Raises
        ------
        mavlink.MAVError
            Bad CRC, or "Invalid signature" (the caller tells the two apart by the message).
        """
        cls, st, extra, _, orders = codec
        plen = frame[1]
        end = _HEADER + plen
        if _mcrf4xx(frame[1:end] + extra, 0xFFFF) != frame[end] | (frame[end + 1] << 8):
            raise mavlink.MAVError("invalid MAVLink CRC")
        sg = self.mav.signing
        if sg.secret_key is not None and not (frame[2] & 1 and self._check_signature(frame)):
            cb = sg.allow_unsigned_callback
            if cb is None or not cb(self.mav, cls.id):
                raise mavlink.MAVError("Invalid signature")
        size = st.size
        if plen < size:  # MAVLink 2 trailing-zero truncation
            t = st.unpack(frame[_HEADER:end] + bytes(size - plen))
        else:
            t = st.unpack_from(frame, _HEADER)
        return t if orders is None else tuple([t[j] for j in orders])

    def _check_signature(self, frame: bytearray) -> bool:
        """pymavlink's ``check_signature`` rules, the hash checked first: a frame signed with
        this key whose timestamp is newer than the last one of its stream (link, system,
        component) - or, for a new stream, at most one minute behind this end's own. Only an
        accepted frame moves the stream's timestamp (pymavlink records it before checking the
        hash, so one corrupted timestamp would make every later genuine frame look replayed).
        """
        sg = self.mav.signing
        if _sha256(sg.secret_key + frame[:-6]).digest()[:6] != frame[-6:]:
            return False
        stamp = int.from_bytes(frame[-12:-6], "little")
        stream = (frame[-13], frame[5], frame[6])
        stamps = sg.stream_timestamps
        last = stamps.get(stream)
        if stamp <= last if last is not None else stamp + 6_000_000 < sg.timestamp:
            return False
        stamps[stream] = stamp
        if stamp > sg.timestamp:
            sg.timestamp = stamp  # what this end signs with next never goes below what it saw
        return True

    def _decode_object(self, frame: bytearray, signed: int) -> Any:
        """pymavlink's ``decode`` (messages with arrays or strings), with its timestamp
        bookkeeping undone when the signature fails (see :meth:`_check_signature`)."""
        stamps = self.mav.signing.stream_timestamps
        stream = (frame[-13], frame[5], frame[6]) if signed else None
        prev = stamps.get(stream) if stream is not None else None
        try:
            return self.mav.decode(frame)
        except mavlink.MAVError as exc:
            if stream is not None and "signature" in exc.message:
                if prev is None:
                    stamps.pop(stream, None)
                else:
                    stamps[stream] = prev
            raise
