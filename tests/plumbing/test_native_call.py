"""pressor.plumbing.native_call: a C function bound to its state, through the compiled callers or
ctypes, with the same bits either way."""

from __future__ import annotations

import ctypes
import functools
import math
import random
import struct

import pytest

from pressor.plumbing import native_build as nb
from pressor.plumbing import native_call as nc

needs_callers = pytest.mark.skipif(
    nb.compiler() is None or bool(nc.reason()), reason=f"no compiled callers: {nc.reason()}"
)

#: one C function per caller signature, each mixing its arguments into its state and its result
#: (divisions and products round, so a changed argument bit changes the output)
KERNELS = r"""
#include <stdint.h>
typedef struct { double acc; int64_t n; } st_t;
int32_t f_i_pd(st_t *s, double x) { s->acc = s->acc / 3.0 + x; s->n += 1; return (int32_t)(s->acc > 1.0); }
void f_v_pd(st_t *s, double x) { s->acc = s->acc * 0.7 - x / 7.0; s->n += 2; }
double f_d_pddddd(st_t *s, double a, double b, double c, double d, double e) {
    s->acc = s->acc / 1.1 + a * b - c / (d + 3.0) + e; return s->acc * 1.0000001;
}
double f_d_pdddp(st_t *s, double a, double b, double c, double *out) {
    *out = a / 3.0 + b * c; s->acc += *out; return s->acc - a;
}
int32_t f_i_pdqd(st_t *s, double a, int64_t k, double b) { s->acc = a / 9.0 + (double)k * b; s->n = k; return (int32_t)(k % 5); }
"""


class _State(ctypes.Structure):
    _fields_ = [("acc", ctypes.c_double), ("n", ctypes.c_int64)]


_p, _d = ctypes.c_void_p, ctypes.c_double
DECLARED = {
    "i_pd": (ctypes.c_int32, [_p, _d]),
    "v_pd": (None, [_p, _d]),
    "d_pddddd": (_d, [_p, _d, _d, _d, _d, _d]),
    "d_pdddp": (_d, [_p, _d, _d, _d, _p]),
    "i_pdqd": (ctypes.c_int32, [_p, _d, ctypes.c_int64, _d]),
}


@pytest.fixture(scope="module")
def kernels(tmp_path_factory):
    if nb.compiler() is None:
        pytest.skip("no C compiler")
    src = tmp_path_factory.mktemp("kernels") / "kernels.c"
    src.write_text(KERNELS)
    lib = nb.load_library(src, "native_call_kernels")
    assert not isinstance(lib, str), lib
    for name, (restype, argtypes) in DECLARED.items():
        fn = getattr(lib, f"f_{name}")
        fn.restype, fn.argtypes = restype, argtypes
    return lib


def _bits(v: object) -> object:
    return struct.pack("<d", v) if isinstance(v, float) else v


def _arguments(name: str, rng: random.Random, out: ctypes.c_double) -> list[object]:
    pool = [0.0, -0.0, 1e-310, -1e308, math.inf, math.nan, 1.0 / 3.0]
    draw = [rng.choice(pool) if rng.random() < 0.2 else rng.uniform(-50, 50) for _ in range(5)]
    if name == "i_pdqd":
        return [draw[0], rng.randrange(-(2**40), 2**40), draw[1]]
    if name == "d_pdddp":
        return [*draw[:3], ctypes.addressof(out)]
    return draw[: len(DECLARED[name][1]) - 1]


@needs_callers
@pytest.mark.parametrize("name", list(nc.SIGNATURES.values()))
def test_each_caller_gives_the_ctypes_calls_bits_and_state(kernels, name):
    fn = getattr(kernels, f"f_{name}")
    runs = []
    for fast in (True, False):
        state, out = _State(0.5, 0), ctypes.c_double(0.0)
        bound = nc.bind(fn, state, fast=fast)
        assert (bound.func is fn) is not fast  # the compiled caller, or ctypes itself
        rng = random.Random(41)
        trace = []
        for _ in range(300):
            result = bound(*_arguments(name, rng, out))
            trace.append((_bits(result), _bits(state.acc), state.n, _bits(out.value)))
        runs.append(trace)
    assert runs[0] == runs[1]


@needs_callers
def test_a_caller_given_the_wrong_arguments_raises_instead_of_calling(kernels):
    state = _State(0.0, 0)
    bound = nc.bind(kernels.f_d_pddddd, state)
    with pytest.raises(TypeError, match="d_pddddd takes 7 arguments"):
        bound(1.0, 2.0)
    with pytest.raises(TypeError):
        bound(1.0, 2.0, "three", 4.0, 5.0)
    assert (state.acc, state.n) == (0.0, 0)


def test_without_the_callers_bind_is_the_ctypes_call_and_says_why(kernels, monkeypatch):
    monkeypatch.setattr(nc, "callers", lambda: "no Python.h in /nowhere")
    state = _State(0.0, 0)
    bound = nc.bind(kernels.f_i_pd, state)
    assert isinstance(bound, functools.partial) and bound.func is kernels.f_i_pd
    assert bound(2.0) == 1 and state.n == 1
    assert nc.reason() == "no Python.h in /nowhere"


def test_a_signature_without_a_caller_is_called_through_ctypes(kernels):
    fn = kernels.f_i_pdqd
    state = _State(0.0, 0)
    saved = fn.argtypes
    try:
        fn.argtypes = [_p, _d, ctypes.c_int32, _d]  # not one of SIGNATURES
        assert nc.bind(fn, state).func is fn
    finally:
        fn.argtypes = saved


def test_an_extension_without_python_headers_is_not_built_and_says_where_it_looked(
    tmp_path, monkeypatch
):
    monkeypatch.setenv(nb.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.delenv(nb.NATIVE_ENV, raising=False)
    monkeypatch.setattr(nb.sysconfig, "get_paths", lambda: {"include": str(tmp_path)})
    if nb.compiler() is None:
        pytest.skip("no C compiler")
    ext = nb.load_extension(nc.SOURCE, nc.MODULE)
    assert ext == f"no Python.h in {tmp_path} (the interpreter's development headers)"
    assert not (tmp_path / "cache").exists()
