"""The pressor MAVLink dialect: XML and committed module agree, ids stay free, every message
round-trips through real frames."""

from __future__ import annotations

import math
import struct
import time
import xml.etree.ElementTree as ET
from typing import Any

import pytest

from pressor.link import (
    ROLE_DEVICE,
    ROLE_RUNTIME,
    DeviceSession,
    RuntimeSession,
    Signing,
    generate,
    open_port,
)
from pressor.link.dialect import pressor as mavlink
from tests.support.link_doubles import tick_inputs


def test_committed_module_matches_what_mavgen_generates_from_the_xml(tmp_path):
    fresh = generate.generate(generate.XML_PATH, tmp_path / "pressor.py")
    assert fresh.read_text() == generate.MODULE_PATH.read_text(), (
        "link/dialect/pressor.py is stale: run `python -m pressor.link.generate`"
    )


def test_generation_uses_mavlink2_so_no_message_is_dropped():
    # mavgen's default wire protocol 1.0 silently drops every id > 255: all of ours
    assert mavlink.WIRE_PROTOCOL_VERSION == "2.0"
    names = {cls.name for cls in mavlink.mavlink_map.values()}
    assert {
        "PRESSOR_HEARTBEAT",
        "PRESSOR_HELLO",
        "MAP_SAMPLE",
        "SCHEDULING_PARAMS",
        "MAP_TARGET",
        "INFUSION_COMMAND",
        "PUMP_STATUS",
        "PRESSOR_REFUSAL",
    } <= names


def _ids_defined_in_our_xml() -> set[int]:
    root = ET.parse(generate.XML_PATH).getroot()
    return {int(m.get("id")) for m in root.iter("message")}


def test_message_ids_are_in_our_block_and_unused_by_pymavlink_all_dialect():
    from pymavlink.dialects.v20 import all as all_dialect

    ours = _ids_defined_in_our_xml()
    assert len(ours) == 8 and all(45000 <= mid < 45100 for mid in ours)
    assert not ours & set(all_dialect.mavlink_map), "id collision with pymavlink's all dialect"


def test_included_standard_messages_are_identical_to_pymavlink_s():
    from pymavlink.dialects.v20 import all as all_dialect

    included = set(mavlink.mavlink_map) - _ids_defined_in_our_xml()
    assert 0 in included  # the standard HEARTBEAT, for generic MAVLink tools
    for mid in included:
        assert mavlink.mavlink_map[mid].crc_extra == all_dialect.mavlink_map[mid].crc_extra


def test_invalid_xml_is_reported_not_exited(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text(
        "<mavlink><messages><message id='45000' name='X'><field type='nonsense' name='a'>a"
        "</field></message></messages></mavlink>"
    )
    with pytest.raises(RuntimeError, match="bad.xml"):
        generate.generate(bad, tmp_path / "bad.py")


_TYPE_VALUES = {
    "float": [1.5, -123.25, math.inf],
    "double": [1234.0625, -0.1, 1e-300],
    "uint8_t": [0, 1, 255],
    "uint16_t": [0, 513, 65535],
    "uint32_t": [0, 70000, 4294967295],
    "int32_t": [0, -70000, 2147483647],
    "int16_t": [0, -513, 32767],
    "int8_t": [0, -1, 127],
    "uint64_t": [0, 1 << 40, (1 << 64) - 1],
}


def _sample_args(cls, variant: int) -> list:
    args = []
    for name, ftype in zip(cls.fieldnames, cls.fieldtypes, strict=True):
        if ftype == "char":
            args.append(f"v{variant}-{name}".encode()[:32])
        else:
            args.append(_TYPE_VALUES[ftype][variant])
    return args


def poll_until(ep: Any, got: list, n: int, timeout_s: float = 5.0) -> None:
    """Read the port until ``n`` messages arrived or ``timeout_s`` (s) passed: one fixed read
    window missed frames on a loaded host."""
    deadline = time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < deadline:
        ep.poll(0.1)


@pytest.mark.parametrize("variant", [0, 1, 2])
@pytest.mark.parametrize("signed", [False, True])
@pytest.mark.parametrize("msg_id", sorted(mavlink.mavlink_map))
def test_every_message_round_trips_through_a_real_frame(msg_id, signed, variant):
    cls = mavlink.mavlink_map[msg_id]
    port = open_port("loop://")
    sign = Signing.generate(seed=7) if signed else None
    # loop:// reads back what it writes: the frames come from the peer's system id, or the
    # session drops them as its own echo (wrong_system)
    ep = RuntimeSession(port, signing=sign, system_id=ROLE_DEVICE)
    got = []
    ep.on_message = got.append
    args = _sample_args(cls, variant)
    frame = ep.send(cls(*args))
    assert frame[0] == 0xFD and bool(frame[2] & 1) == signed
    poll_until(ep, got, 1)
    assert len(got) == 1 and got[0].id == msg_id
    for name, ftype, sent in zip(cls.fieldnames, cls.fieldtypes, args, strict=True):
        value = getattr(got[0], name)
        if ftype == "float":  # float32 on the wire
            sent = struct.unpack("<f", struct.pack("<f", sent))[0]
        if ftype == "char":  # decoded as str
            sent = sent.decode()
        assert value == sent, name
    assert ep.counters.bad_crc == 0 and ep.counters.junk_bytes == 0
    port.close()


def test_nan_map_sample_survives_the_wire():
    port = open_port("loop://")
    ep = DeviceSession(port, system_id=ROLE_RUNTIME)  # read back as the runtime's frames
    got = []
    ep.on_message = got.append
    ep.send_tick(tick_inputs(5, 0.5, math.nan, 3, 90.0, 0.5, 150.0, 30.0, False))
    poll_until(ep, got, 3)
    sample = [m for m in got if m.id == mavlink.MAVLINK_MSG_ID_MAP_SAMPLE][0]
    assert math.isnan(sample.map_mmhg) and sample.quality == 3 and sample.tick == 5
    assert [m.id for m in got] == [45003, 45004, 45002]  # DeviceSession sends the sample last
    port.close()


def _xml_enum(name: str) -> dict[str, int]:
    root = ET.parse(generate.XML_PATH).getroot()
    (enum,) = [e for e in root.iter("enum") if e.get("name") == name]
    return {e.get("name"): int(e.get("value")) for e in enum.iter("entry")}


def test_quality_and_pump_alarm_bits_on_both_ends_are_the_xml_enums():
    # contracts may not import link: the bits both ends use are held equal to the XML here
    from pressor.contracts.faults import wire_bits

    quality = _xml_enum("PRESSOR_MAP_QUALITY")
    alarms = _xml_enum("PRESSOR_PUMP_ALARM")
    ours = {n: v for n, v in vars(wire_bits).items() if n.startswith(("QUALITY_", "PUMP_ALARM_"))}
    expected = {n.removeprefix("PRESSOR_MAP_"): v for n, v in quality.items()}
    expected |= {n.removeprefix("PRESSOR_"): v for n, v in alarms.items()}
    assert ours == expected
    assert all(v & (v - 1) == 0 for v in expected.values())  # one bit each
    assert mavlink.PRESSOR_PUMP_ALARM_WATCHDOG == wire_bits.PUMP_ALARM_WATCHDOG


def test_quality_and_alarm_fields_name_their_bitmask_enums():
    root = ET.parse(generate.XML_PATH).getroot()
    fields = {
        (m.get("name"), f.get("name")): f for m in root.iter("message") for f in m.iter("field")
    }
    for key, enum in (
        (("MAP_SAMPLE", "quality"), "PRESSOR_MAP_QUALITY"),
        (("PUMP_STATUS", "alarms"), "PRESSOR_PUMP_ALARM"),
    ):
        assert fields[key].get("enum") == enum and fields[key].get("display") == "bitmask"
        assert "defined by the device model" not in (fields[key].text or "")
