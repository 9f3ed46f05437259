"""A refused hello reaches the peer: PRESSOR_REFUSAL with the reason code and the one line, then a
heartbeat FAULT (docs/PROTOCOL.md, "Refusals"); the peer's next wait raises :class:`PeerRefused`."""

from __future__ import annotations

import pytest

from pressor.link import (
    REFUSAL_DRUG,
    REFUSAL_PROTOCOL_VERSION,
    REFUSAL_SYSTEM_ID,
    STATE_FAULT,
    DeviceSession,
    Hello,
    HelloRefused,
    PeerRefused,
    RuntimeSession,
)
from tests.support.link_doubles import collect, drain, loop_pair


@pytest.mark.parametrize(
    ("device_kw", "hello_kw", "reason", "text"),
    [
        ({"system_id": 42}, {}, REFUSAL_SYSTEM_ID, "device hello from MAVLink system id 42"),
        (
            {},
            {"protocol_version": 1},
            REFUSAL_PROTOCOL_VERSION,
            "device hello: peer protocol_version 1",
        ),
    ],
    ids=["system-id", "protocol-version"],
)
def test_the_runtime_refuses_a_bad_device_hello_and_the_device_learns_why(
    device_kw: dict, hello_kw: dict, reason: int, text: str
) -> None:
    a, b = loop_pair()
    dev = DeviceSession(b, **device_kw)
    dev.send_hello(Hello("bedside", **hello_kw))
    with pytest.raises(HelloRefused, match=text) as refused:
        RuntimeSession(a).handshake(Hello("pi"), timeout_s=2.0)
    assert refused.value.reason == reason
    with pytest.raises(PeerRefused, match=f"refused by the runtime: {text}") as told:
        dev.wait_for_command(0, 2.0)
    assert (told.value.reason, told.value.text) == (reason, refused.value.text)
    assert dev.peer_heartbeat is not None and dev.peer_heartbeat.state == STATE_FAULT


def test_a_refusal_frame_carries_reason_version_and_text_cut_to_200_characters() -> None:
    a, b = loop_pair()
    rt, dev = RuntimeSession(a), DeviceSession(b)
    got = collect(dev)
    rt.refuse(HelloRefused(REFUSAL_DRUG, "device drug " + "x" * 300))
    drain(dev)
    refusal, std_heartbeat, heartbeat = got
    assert refusal.get_type() == "PRESSOR_REFUSAL" and refusal.reason == REFUSAL_DRUG
    assert refusal.protocol_version == 2 and len(refusal.text) == 200
    assert refusal.text.startswith("device drug xxx")
    assert std_heartbeat.get_type() == "HEARTBEAT"
    assert heartbeat.get_type() == "PRESSOR_HEARTBEAT" and heartbeat.state == STATE_FAULT
    assert dev.peer_refusal == (REFUSAL_DRUG, refusal.text)
