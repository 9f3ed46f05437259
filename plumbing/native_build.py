"""Compile a C source into a cached shared library, for optional compiled kernels of simulations.

The in-process simulator can run some of its pure arithmetic as compiled C instead of Python (the
LPV controller's C twin, the estimator, the paper patient: :mod:`pressor.hil_sim.native`). Such a kernel must
give the same IEEE double results as the Python it stands in for, so the flags are fixed:
``-O2 -ffp-contract=off -fno-fast-math -fexcess-precision=standard`` (no fused multiply-add, no
reassociation; every intermediate rounded to double), ``-std=c99``. Nothing here is needed: when
no C compiler works, :func:`shared_library` says why and the caller keeps its Python path.

Libraries are cached per user, keyed by the sha256 of the source (and its header), the flags and
the compiler's version line, under ``$PRESSOR_CACHE_DIR`` or ``$XDG_CACHE_HOME/pressor/native``
(default ``~/.cache/pressor/native``). A library is written to a temporary sibling and moved into
place, so concurrent processes (a Dask cluster, ``--jobs``) and interrupted builds never leave a half-written
library under a final name.

``PRESSOR_NATIVE``: ``auto`` (default) uses a compiled kernel where a compiler works; ``off`` never
compiles (every simulation runs its Python path: the same bytes, more slowly).
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TypeVar

from pressor.plumbing.files import AtomicFile

T = TypeVar("T")

#: the compiler flags; a change here is a new cache key
FLAGS = (
    "-std=c99",
    "-O2",
    "-ffp-contract=off",
    "-fno-fast-math",
    "-fexcess-precision=standard",
    "-fPIC",
    "-shared",
)
NATIVE_ENV = "PRESSOR_NATIVE"
NATIVE_MODES = ("auto", "off")
CACHE_ENV = "PRESSOR_CACHE_DIR"


@dataclass(frozen=True)
class Build:
    """The outcome of :func:`shared_library`: the library's path, or ``None`` and why not."""

    path: Path | None
    reason: str


def native_mode() -> str:
    """``PRESSOR_NATIVE`` (``auto`` when unset).

    Raises
    ------
    ValueError
        A value other than ``auto`` or ``off`` (naming the variable, the value and the choices).
    """
    mode = os.environ.get(NATIVE_ENV, "auto").strip().lower() or "auto"
    if mode not in NATIVE_MODES:
        raise ValueError(
            f"environment variable {NATIVE_ENV}={mode!r}: expected one of {', '.join(NATIVE_MODES)}"
        )
    return mode


def cache_dir() -> Path:
    """Where compiled libraries are kept (see the module docstring)."""
    explicit = os.environ.get(CACHE_ENV)
    if explicit:
        return Path(explicit)
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "pressor" / "native"


def compiler() -> str | None:
    """The C compiler builds use: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on ``PATH`` (None)."""
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def _version_line(cc: str) -> str:
    try:
        out = subprocess.run(
            [cc, "--version"], capture_output=True, text=True, timeout=30, check=False
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.splitlines()[0] if out else ""


def shared_library(source: Path, name: str, python_extension: bool = False) -> Build:
    """The shared library compiled from the C file ``source`` (and its header ``source.h``, if any).

    ``name`` (letters, digits, ``_``) prefixes the cached file. Compiles once per source and header
    text, flags and compiler; later calls return the cached library. A ``python_extension`` is
    compiled against this interpreter's headers (``Python.h``) and named with its extension suffix;
    the interpreter's version is then part of the cache key.

    Returns
    -------
    Build
        ``path`` the library, or ``None`` with ``reason``: ``PRESSOR_NATIVE=off``, no compiler on
        ``PATH``, an unwritable cache directory, or the compiler's error (its last line).
    """
    if native_mode() == "off":
        return Build(None, f"{NATIVE_ENV}=off")
    cc = compiler()
    if cc is None:
        return Build(None, "no C compiler (cc, gcc or clang) on PATH")
    flags, suffix, python = FLAGS, ".so", ""
    if python_extension:
        include = sysconfig.get_paths()["include"]
        if not (Path(include) / "Python.h").is_file():
            return Build(None, f"no Python.h in {include} (the interpreter's development headers)")
        flags = (*FLAGS, f"-I{include}")
        suffix = sysconfig.get_config_var("EXT_SUFFIX") or ".so"
        python = sys.version
    header = Path(source).with_suffix(".h")  # a twin's own header is part of what it compiles
    parts = [Path(source).read_bytes(), header.read_bytes() if header.is_file() else b""]
    key = hashlib.sha256(
        b"\0".join((*parts, " ".join(flags).encode(), _version_line(cc).encode(), python.encode()))
    ).hexdigest()[:20]
    target = cache_dir() / f"{name}-{key}{suffix}"
    if target.is_file():
        return Build(target, "cached")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with AtomicFile(target) as out:
            proc = subprocess.run(
                [cc, *flags, "-o", str(out.tmp), str(source)],
                capture_output=True,
                text=True,
                timeout=300,
                check=False,
            )
            if proc.returncode != 0:
                last = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
                raise _CompileError(f"{Path(cc).name} failed on {source}: {last}")
    except _CompileError as exc:
        return Build(None, str(exc))
    except (OSError, subprocess.SubprocessError) as exc:
        return Build(None, f"cannot build in {target.parent}: {exc}")
    return Build(target, "compiled")


class _CompileError(Exception):
    pass


def load_library(source: Path, name: str) -> ctypes.CDLL | str:
    """:func:`shared_library` loaded with ctypes, or the reason (a ``str``) why there is none.

    A cached library that does not load (damaged outside pressor: pressor itself only ever moves
    complete files into the cache) is removed and built again once.
    """
    return _load_built(source, name, False, lambda path: ctypes.CDLL(str(path)))


def load_extension(source: Path, module: str) -> ModuleType | str:
    """The Python extension module ``module`` compiled from ``source`` (:func:`shared_library` with
    ``python_extension``), imported, or the reason (a ``str``) why there is none; a damaged cached
    one is built again, as in :func:`load_library`."""

    def load(path: Path) -> ModuleType:
        spec = importlib.util.spec_from_file_location(module, path)
        if spec is None or spec.loader is None:
            raise ImportError(f"not an extension module: {path}")
        ext = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(ext)
        return ext

    return _load_built(source, module, True, load)


def _load_built(
    source: Path, name: str, python_extension: bool, load: Callable[[Path], T]
) -> T | str:
    """``load`` of :func:`shared_library`'s file, or why not; a cached file that ``load`` refuses
    (``OSError``, ``ImportError``) is removed and built again once."""
    build = shared_library(source, name, python_extension)
    if build.path is None:
        return build.reason
    try:
        return load(build.path)
    except (OSError, ImportError) as exc:
        if build.reason != "cached":  # just compiled: building again would not help
            return f"cannot load {build.path}: {exc}"
    build.path.unlink(missing_ok=True)
    return _load_built(source, name, python_extension, load)  # compiles afresh: this ends


def load_twin(
    source: Path, name: str, state_size_symbol: str, state: type[ctypes.Structure]
) -> ctypes.CDLL | str:
    """:func:`load_library`, refused unless the library's ``state_size_symbol()`` (a C function
    returning ``sizeof`` of its state, ``uint32_t``) equals ``ctypes.sizeof(state)``: the wrapper's
    mirror of the C state must have the C's layout."""
    lib = load_library(source, name)
    if isinstance(lib, str):
        return lib
    size = getattr(lib, state_size_symbol)
    size.restype = ctypes.c_uint32
    if size() != ctypes.sizeof(state):
        return f"{Path(source).name}: state layout differs from the one this wrapper knows"
    return lib
