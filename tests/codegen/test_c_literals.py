"""The emitted C writes its floating constants in decimal, each the exact double the Python module
uses; a named constant (``#define``) carries the exact hexadecimal value in a comment where the
decimal is not the binary value (the tables' coefficients are checked bit for bit instead).

Checked on C emitted from the hand-built design (every literal compared with the plan it was
written from) and on every committed generated C file.
"""

from __future__ import annotations

import re
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

from pressor.codegen import pipeline as pl
from pressor.codegen.emit_spec import nonzero_entries
from pressor.codegen.tables import TabulationGrid, TabulationProof, build_tables, check_grid
from tests.support.codegen_helpers import (
    BOX,
    HAND_GRID_REL_TOL,
    TS,
    example_controller,
    hand_design,
)

GENERATED = Path(pl.REPO_ROOT) / "runtime" / "generated"
COMMITTED = sorted(GENERATED.glob("*.c")) + sorted(GENERATED.glob("*.h"))
HEX_FLOAT = re.compile(r"[-+]?0[xX][0-9a-fA-F]*\.?[0-9a-fA-F]*[pP][-+]?\d+")
COMMENT = re.compile(r"/\*.*?\*/", re.S)
# a decimal floating constant (has a point or an exponent), not part of a name or a hex literal
DECIMAL = re.compile(r"(?<![\w.])-?(?:\d+\.\d*|\.\d+|\d+(?=[eE]))(?:[eE][-+]?\d+)?(?![\w.])")
NOTED = re.compile(r"(-?[\d.]+(?:e[-+]?\d+)?),?\s+/\* (-?0x[0-9a-f.]+p[-+]\d+) \*/")


def _code(text: str) -> str:
    return COMMENT.sub(" ", text)


def _check_literals(text: str) -> int:
    """Assert every floating constant outside comments is decimal, the shortest that round-trips,
    every hex note equals its decimal and is there only where the decimal is inexact, and every
    inexact named constant has one; return how many decimals were checked."""
    code = _code(text)
    assert not HEX_FLOAT.findall(code)
    lits = DECIMAL.findall(code)
    for lit in lits:
        assert repr(float(lit)) == lit.lstrip("+"), lit
    for lit, hexval in NOTED.findall(text):
        assert float(lit) == float.fromhex(hexval), (lit, hexval)
        assert Decimal(lit) != Decimal(float.fromhex(hexval)), lit  # a note only where needed
    for line in text.splitlines():
        if line.startswith("#define"):
            for lit in DECIMAL.findall(_code(line)):
                if Decimal(lit) != Decimal(float(lit)):
                    assert NOTED.search(line), f"{line!r}: {lit} is not exact and has no hex note"
    return len(lits)


@pytest.fixture(scope="module")
def emitted():
    design = hand_design()
    grid = TabulationGrid.uniform(BOX[:, 0], BOX[:, 1], (5, 3, 3))
    tables = build_tables(example_controller, grid, 0.1, 0.1, TS)
    check = check_grid(example_controller, grid, tables, grid.cell_midpoints(), 0.1, 0.1, TS)
    proof = TabulationProof(grid, tables, check, HAND_GRID_REL_TOL)
    plan = pl.quantise(design, proof, "q31")
    return {
        "plan": plan,
        "float": pl.emit(design, proof, plan, "c", c_float=True).files,
        "int": pl.emit(design, proof, plan, "c").files,
    }


@pytest.mark.parametrize("mode", ["float", "int"])
def test_emitted_c_has_decimal_literals_and_hex_notes_on_inexact_constants(emitted, mode):
    checked = sum(_check_literals(text) for text in emitted[mode].values())
    assert checked >= (700 if mode == "float" else 20)


def test_float_table_literals_are_the_plans_doubles_bit_for_bit(emitted):
    plan = emitted["plan"]
    src = emitted["float"]["lpv_map_controller.c"]
    body = _code(src.split("lpvmap_tab[")[1].split("};")[0].split("= {", 1)[1])
    values = [float(x) for x in DECIMAL.findall(body)]
    entries = nonzero_entries(plan)
    flat = plan.scaled_tables.reshape(-1, *plan.scaled_tables.shape[3:])
    expected = [float(node[i, j]) for node in flat for i, j in entries]
    assert len(values) == len(expected)
    assert np.array_equal(np.array(values).view(np.int64), np.array(expected).view(np.int64))


def test_constants_read_as_their_decimal_value(emitted):
    h = emitted["float"]["lpv_map_controller.h"]
    assert "#define LPVMAP_MAX_RATE_ML_H 120.0\n" in h
    assert "#define LPVMAP_SAMPLE_PERIOD_S 0.1  /* 0x1.999999999999ap-4 */" in h


@pytest.mark.parametrize("path", COMMITTED, ids=lambda p: p.name)
def test_committed_c_has_decimal_literals_and_hex_notes_on_inexact_constants(path):
    # a header: the sample period, the pump limit and the concentration; a source: the tables too
    assert _check_literals(path.read_text(encoding="utf-8")) >= (3 if path.suffix == ".h" else 1000)
