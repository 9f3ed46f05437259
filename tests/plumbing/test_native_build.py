"""pressor.plumbing.native_build: a C file compiled once into the per-user cache, or a reason why not."""

from __future__ import annotations

import ctypes

import pytest

from pressor.plumbing import native_build as nb

needs_cc = pytest.mark.skipif(nb.compiler() is None, reason="no C compiler")
SOURCE = "double twice(double x) { return 2.0 * x; }\n"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(nb.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.delenv(nb.NATIVE_ENV, raising=False)
    return tmp_path / "cache"


@needs_cc
def test_library_compiles_once_then_comes_from_the_cache(cache, tmp_path):
    src = tmp_path / "k.c"
    src.write_text(SOURCE)
    first = nb.shared_library(src, "k")
    assert first.reason == "compiled" and first.path.parent == cache
    lib = ctypes.CDLL(str(first.path))
    lib.twice.restype, lib.twice.argtypes = ctypes.c_double, [ctypes.c_double]
    assert lib.twice(1.25) == 2.5
    mtime = first.path.stat().st_mtime_ns
    again = nb.shared_library(src, "k")
    assert (again.path, again.reason) == (first.path, "cached")
    assert again.path.stat().st_mtime_ns == mtime
    assert not [p for p in cache.iterdir() if p.name.endswith(".tmp")]


@needs_cc
def test_an_edited_source_gets_its_own_library(cache, tmp_path):
    src = tmp_path / "k.c"
    src.write_text(SOURCE)
    a = nb.shared_library(src, "k").path
    src.write_text(SOURCE.replace("2.0", "3.0"))
    b = nb.shared_library(src, "k").path
    assert a != b and a.is_file() and b.is_file()


@needs_cc
def test_compile_error_gives_the_compilers_message_and_leaves_no_file(cache, tmp_path):
    src = tmp_path / "bad.c"
    src.write_text("double f(double x) { return x +; }\n")
    build = nb.shared_library(src, "bad")
    assert build.path is None
    assert "bad.c" in build.reason and "failed" in build.reason
    assert not cache.exists() or not list(cache.iterdir())


def test_off_and_no_compiler_give_a_reason_and_no_library(cache, tmp_path, monkeypatch):
    src = tmp_path / "k.c"
    src.write_text(SOURCE)
    monkeypatch.setenv(nb.NATIVE_ENV, "off")
    assert nb.shared_library(src, "k") == nb.Build(None, "PRESSOR_NATIVE=off")
    monkeypatch.setenv(nb.NATIVE_ENV, "auto")
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    monkeypatch.delenv("CC", raising=False)
    build = nb.shared_library(src, "k")
    assert build.path is None and "no C compiler" in build.reason


def test_unknown_mode_is_refused_naming_the_variable_value_and_choices(monkeypatch):
    monkeypatch.setenv(nb.NATIVE_ENV, "fast")
    with pytest.raises(ValueError, match=r"PRESSOR_NATIVE='fast'.*auto, off"):
        nb.native_mode()


def test_cache_dir_follows_the_variables(monkeypatch, tmp_path):
    monkeypatch.delenv(nb.CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert nb.cache_dir() == tmp_path / "pressor" / "native"
    monkeypatch.setenv(nb.CACHE_ENV, str(tmp_path / "x"))
    assert nb.cache_dir() == tmp_path / "x"


@needs_cc
def test_a_damaged_cached_library_is_built_again_and_loads(cache, tmp_path):
    src = tmp_path / "k.c"
    src.write_text(SOURCE)
    path = nb.shared_library(src, "k").path
    path.write_bytes(b"not a shared object")
    lib = nb.load_library(src, "k")
    assert not isinstance(lib, str), lib
    lib.twice.restype, lib.twice.argtypes = ctypes.c_double, [ctypes.c_double]
    assert lib.twice(4.0) == 8.0 and path.read_bytes() != b"not a shared object"


def test_load_library_gives_the_reason_when_there_is_no_library(cache, tmp_path, monkeypatch):
    src = tmp_path / "k.c"
    src.write_text(SOURCE)
    monkeypatch.setenv(nb.NATIVE_ENV, "off")
    assert nb.load_library(src, "k") == "PRESSOR_NATIVE=off"
