"""One source of truth for the protocol: docs/PROTOCOL.md and link/pressor.xml say the same.

Every message of the XML has a section in the document (``### NAME (id), ...``) whose quoted line
is the XML's description and whose field table lists the XML's fields in order, with their types
and units; the protocol version and the refusal reasons are the same in both.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pressor.link import PROTOCOL_VERSION
from pressor.link.generate import XML_PATH

DOC = Path(__file__).resolve().parents[2] / "docs" / "PROTOCOL.md"
#: what the unit column says for a field without a unit or an enum in the XML
UNITLESS = {"-", "tick", "ticks", "ASCII", "0/1"}


def _words(text: str) -> str:
    return " ".join(text.split())


def _xml() -> ET.Element:
    return ET.parse(XML_PATH).getroot()


def _doc_sections() -> dict[str, tuple[int, str, list[list[str]]]]:
    """Each message section: name -> (id, quoted description, field table rows)."""
    sections = {}
    parts = re.split(r"^### ", DOC.read_text(), flags=re.MULTILINE)
    for part in parts[1:]:
        head = re.match(r"([A-Z_]+) \((\d+)\)", part)
        if head is None:
            continue
        quote = [line[2:] for line in part.splitlines() if line.startswith("> ")]
        rows = [
            [cell.strip() for cell in line.strip("|").split("|")]
            for line in part.splitlines()
            if line.startswith("| `")
        ]
        sections[head[1]] = (int(head[2]), _words(" ".join(quote)), rows)
    return sections


def _unit_cell(field: ET.Element) -> str | None:
    """What the document's unit column must say for ``field`` (None: any unitless word)."""
    if field.get("units"):
        return field.get("units")
    if field.get("enum"):
        kind = "bitmask" if field.get("display") == "bitmask" else "enum"
        return f"{kind} `{field.get('enum')}`"
    return None


MESSAGES = {m.get("name"): m for m in _xml().iter("message")}


def test_the_document_has_a_section_for_every_message_and_no_other():
    assert set(_doc_sections()) == set(MESSAGES)


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_each_message_s_id_description_fields_types_and_units_match_the_xml(name: str):
    msg_id, description, rows = _doc_sections()[name]
    message = MESSAGES[name]
    assert msg_id == int(message.get("id"))
    assert description == _words(message.findtext("description")), "description differs"
    fields = list(message.iter("field"))
    assert [row[0] for row in rows] == [f"`{f.get('name')}`" for f in fields], "field names"
    for row, field in zip(rows, fields, strict=True):
        assert row[1] == field.get("type").replace("_t", ""), f"{field.get('name')}: type"
        want = _unit_cell(field)
        if want is None:
            assert row[2] in UNITLESS, f"{field.get('name')}: {row[2]!r} is a unit the XML lacks"
        else:
            assert row[2] == want, f"{field.get('name')}: unit"


def test_the_protocol_version_is_the_same_in_the_xml_the_document_and_the_code():
    text = DOC.read_text()
    [doc_version] = re.findall(r"Protocol version: \*\*(\d+)\*\*", text)
    sections = _doc_sections()
    [hello_row] = [row for row in sections["PRESSOR_HELLO"][2] if row[0] == "`protocol_version`"]
    assert f"must be {PROTOCOL_VERSION} on both ends" in hello_row[3]
    [refusal_row] = [r for r in sections["PRESSOR_REFUSAL"][2] if r[0] == "`protocol_version`"]
    assert f"({PROTOCOL_VERSION})" in refusal_row[3]
    assert int(_xml().findtext("version")) == int(doc_version) == PROTOCOL_VERSION


def test_the_document_lists_every_refusal_reason_of_the_xml():
    [enum] = [e for e in _xml().iter("enum") if e.get("name") == "PRESSOR_REFUSAL_REASON"]
    xml_reasons = {e.get("name"): int(e.get("value")) for e in enum.iter("entry")}
    section = DOC.read_text().split("## Refusals", 1)[1].split("\n## ", 1)[0]
    doc_reasons = {
        m[2]: int(m[1])
        for m in re.finditer(r"^\| (\d+) \| `(PRESSOR_REFUSAL_REASON_\w+)`", section, re.M)
    }
    assert doc_reasons == xml_reasons
