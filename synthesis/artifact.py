"""The controller artifact: one self-describing ``.npz`` file (docs/ARCHITECTURE.md).

Layout (``numpy.savez``, no pickled objects):

* ``metadata`` — uint8 bytes of a UTF-8 JSON document: ``format_version``, ``box`` (3×2: K
  [mmHg/(ml/h)], T [s], τ [s]), ``rate_bounds``, ``grid`` (3 lists, physical units), ``basis``,
  ``model`` (Ω, Λ, φ, ξ, η, box, rates, pump max, frequency ``shaping`` if set), ``design`` (full
  config), ``scaling``, ``lambda2``, ``lambda3``, ``gamma``, ``solver`` (name, status, times,
  iterations), ``verification`` (``null`` until :func:`with_verification` fills it), ``created_by``,
  and optionally ``reference`` (``enabled``, ``lambda_s``, ``pump_fraction``, ``k_min``: the 2-DOF
  prefilter of :mod:`pressor.synthesis.problem.reference`; absent in older artifacts, read as disabled), and
  optionally ``controller`` (``structure``, ``loop_gain``: the family of
  :mod:`pressor.synthesis.families.registry`; absent in older artifacts and in every artifact of the default
  family; a family without a synthesis LMI stores null ``lambda2``/``lambda3`` and its analysis'
  bound on the design grid as ``gamma``), and optionally ``design.drug`` (``name``,
  ``concentration_ug_ml``: the drug and syringe the gains are for,
  :class:`pressor.contracts.drug.DrugBinding`; absent in artifacts made before designs named their drug,
  read as :data:`pressor.contracts.drug.DEFAULT_BINDING`, phenylephrine at 100 µg/ml).
* ``coef_<name>`` — the family's coefficients
  (:meth:`pressor.synthesis.families.registry.Family.coefficient_shapes`): the decision variables of a
  synthesised family (scaled coordinates), the certificate of an analysed one.
* ``node_<name>`` — the controller at the grid nodes, physical units (time in s), shape
  ``(nK, nT, ntau, rows, cols)`` for Ak, Adk, Bk, Ck, Cdk, Dk (controller order:
  :meth:`pressor.synthesis.families.registry.Family.controller_order`).
* ``sha256`` — uint8 bytes of the hex digest of everything above (canonical order).

Loading checks the format version, every expected field's presence, dtype, shape and finiteness and
the hash; any failure raises :class:`ArtifactError` naming the file and the field. Saving writes a
temporary file in the target directory and renames it (atomic on POSIX).
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pressor.contracts.drug import DEFAULT_BINDING, DrugBinding
from pressor.plumbing.files import AtomicFile
from pressor.synthesis.artifact_path import default_artifact_path  # noqa: F401 (re-exported)
from pressor.synthesis.families.registry import ControllerFamily
from pressor.synthesis.problem.config import ModelConfig
from pressor.synthesis.problem.model import dims
from pressor.synthesis.problem.reference import ReferenceConfig

FORMAT_VERSION = 1


def node_shapes(n: int, ny: int = 2) -> dict[str, tuple[int, int]]:
    """Controller of order ``n`` at the grid nodes: name -> (rows, cols).

    The order is the family's (:meth:`pressor.synthesis.families.registry.Family.controller_order`).
    """
    return {
        "Ak": (n, n),
        "Adk": (n, n),
        "Bk": (n, ny),
        "Ck": (1, n),
        "Cdk": (1, n),
        "Dk": (1, ny),
    }


_REQUIRED_META = (
    "format_version",
    "box",
    "rate_bounds",
    "grid",
    "basis",
    "model",
    "scaling",
    "lambda2",
    "lambda3",
    "gamma",
    "solver",
    "verification",
)


class ArtifactError(ValueError):
    """An artifact file is missing, corrupted, truncated, tampered with or of another version."""


@dataclass(frozen=True)
class ControllerArtifact:
    """A synthesized controller and everything needed to rebuild, verify and generate it.

    Attributes
    ----------
    metadata
        The JSON metadata (see module docstring).
    coefficients
        The family's coefficients, name -> array
        (:meth:`pressor.synthesis.families.registry.Family.coefficient_shapes`).
    nodes
        Reconstructed controller at the grid nodes, name -> (nK, nT, ntau, rows, cols) (physical).
    """

    metadata: dict[str, Any]
    coefficients: dict[str, np.ndarray]
    nodes: dict[str, np.ndarray]
    _sha: str = field(default="", compare=False, repr=False)

    @property
    def sha256(self) -> str:
        """Hex sha256 of the artifact content (metadata + arrays, canonical order)."""
        return self._sha or content_hash(self.metadata, self.coefficients, self.nodes)

    @property
    def box(self) -> np.ndarray:
        """(3, 2) parameter box: K [mmHg/(ml/h)], T [s], τ [s]; lower, upper."""
        return np.asarray(self.metadata["box"], dtype=float)

    @property
    def rate_bounds(self) -> np.ndarray:
        """(3,) bounds |K̇| [mmHg/(ml/h)/s], |Ṫ| [s/s], |τ̇| [s/s]."""
        return np.asarray(self.metadata["rate_bounds"], dtype=float)

    @property
    def grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Synthesis grid nodes per parameter (physical units)."""
        g = self.metadata["grid"]
        return (np.asarray(g[0], float), np.asarray(g[1], float), np.asarray(g[2], float))

    @property
    def omega(self) -> float:
        """Input filter gain Ω (1/s) of u = Ω/(s + Λ) u_a."""
        return float(self.metadata["model"]["omega"])

    @property
    def lambda_(self) -> float:
        """Input filter pole Λ (1/s)."""
        return float(self.metadata["model"]["lambda"])

    @property
    def max_rate_ml_h(self) -> float:
        """Pump limit (ml/h)."""
        return float(self.metadata["model"]["max_rate_ml_h"])

    @property
    def gamma(self) -> float:
        """Guaranteed L2 gain bound γ on the synthesis grid."""
        return float(self.metadata["gamma"])

    @property
    def reference(self) -> ReferenceConfig:
        """The design's prefilter (:class:`~pressor.synthesis.problem.reference.ReferenceConfig`); disabled
        when the artifact carries none."""
        ref = self.metadata.get("reference")
        return ReferenceConfig() if ref is None else ReferenceConfig.from_dict(ref)

    @property
    def family(self) -> ControllerFamily:
        """The controller family (:mod:`pressor.synthesis.families.registry`); the default one when the
        artifact has none."""
        return ControllerFamily.from_metadata(self.metadata)

    @property
    def drug(self) -> DrugBinding:
        """The drug and syringe concentration the gains are for (``design.drug``); phenylephrine at
        100 µg/ml (:data:`pressor.contracts.drug.DEFAULT_BINDING`) when the artifact names none."""
        return drug_of(self.metadata)

    @property
    def population(self) -> tuple[float, float] | None:
        """The design's patient sensitivity range (mmHg per µg/kg/min, ``design.population``), or
        None when it names none."""
        design = self.metadata.get("design")
        pop = design.get("population") if isinstance(design, dict) else None
        if pop is None:
            return None
        lo, hi = (float(v) for v in pop["K_ug_kg_min"])
        return (lo, hi)

    @property
    def model_config(self) -> ModelConfig:
        """The design's :class:`~pressor.synthesis.problem.config.ModelConfig`."""
        return ModelConfig.from_dict(self.metadata["model"])


def drug_of(metadata: dict[str, Any]) -> DrugBinding:
    """The drug binding of artifact ``metadata`` (``design.drug``, else the default binding)."""
    design = metadata.get("design")
    d = design.get("drug") if isinstance(design, dict) else None
    return DEFAULT_BINDING if d is None else DrugBinding.from_dict(d)


def _canonical_json(meta: dict[str, Any]) -> bytes:
    return json.dumps(meta, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def content_hash(
    metadata: dict[str, Any], coefficients: dict[str, np.ndarray], nodes: dict[str, np.ndarray]
) -> str:
    """sha256 over the canonical JSON metadata and every array (name, dtype, shape, bytes)."""
    h = hashlib.sha256()
    h.update(_canonical_json(metadata))
    for prefix, arrays in (("coef_", coefficients), ("node_", nodes)):
        for name in sorted(arrays):
            a = np.ascontiguousarray(arrays[name], dtype="<f8")
            h.update(f"{prefix}{name}|{a.dtype.str}|{a.shape}".encode())
            h.update(a.tobytes())
    return h.hexdigest()


def make_artifact(
    metadata: dict[str, Any], coefficients: dict[str, np.ndarray], nodes: dict[str, np.ndarray]
) -> ControllerArtifact:
    """Build an artifact (arrays copied to float64, hash computed)."""
    coefs = {k: np.array(v, dtype=float) for k, v in coefficients.items()}
    nd = {k: np.array(v, dtype=float) for k, v in nodes.items()}
    meta = json.loads(_canonical_json(metadata))  # normalise to plain JSON types
    _validate(meta, coefs, nd, "<memory>")
    return ControllerArtifact(meta, coefs, nd, content_hash(meta, coefs, nd))


def with_verification(artifact: ControllerArtifact, results: dict[str, Any]) -> ControllerArtifact:
    """Copy of ``artifact`` with ``metadata['verification'] = results`` (JSON-ready) and a new hash."""
    meta = dict(artifact.metadata)
    meta["verification"] = results
    return make_artifact(meta, artifact.coefficients, artifact.nodes)


def save_artifact(artifact: ControllerArtifact, path: str | Path) -> Path:
    """Write ``artifact`` to exactly ``path`` atomically (temporary file + rename).

    Returns
    -------
    pathlib.Path
        The written path.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {
        "metadata": np.frombuffer(_canonical_json(artifact.metadata), dtype=np.uint8),
        "sha256": np.frombuffer(artifact.sha256.encode(), dtype=np.uint8),
    }
    for k, v in artifact.coefficients.items():
        arrays[f"coef_{k}"] = np.ascontiguousarray(v, dtype="<f8")
    for k, v in artifact.nodes.items():
        arrays[f"node_{k}"] = np.ascontiguousarray(v, dtype="<f8")
    with AtomicFile(p) as target, open(target.tmp, "wb") as fh:
        np.savez(fh, **arrays)
        fh.flush()
        os.fsync(fh.fileno())
    return p


def _err(path: str, fieldname: str, why: str) -> ArtifactError:
    return ArtifactError(f"{path}: field '{fieldname}': {why}")


def _check_array(path: str, name: str, a: np.ndarray, shape: tuple[int, ...]) -> None:
    if a.dtype != np.float64:
        raise _err(path, name, f"dtype {a.dtype}, expected float64")
    if a.shape != shape:
        raise _err(path, name, f"shape {a.shape}, expected {shape}")
    if not np.all(np.isfinite(a)):
        raise _err(path, name, "contains NaN or Inf")


def _validate(
    meta: dict[str, Any], coefs: dict[str, np.ndarray], nodes: dict[str, np.ndarray], path: str
) -> None:
    if not isinstance(meta, dict):
        raise _err(path, "metadata", "not a JSON object")
    for key in _REQUIRED_META:
        if key not in meta:
            raise _err(path, f"metadata.{key}", "missing")
    if meta["format_version"] != FORMAT_VERSION:
        raise _err(
            path,
            "metadata.format_version",
            f"{meta['format_version']!r}, this reader understands {FORMAT_VERSION}",
        )
    try:
        box = np.asarray(meta["box"], dtype=float)
        rates = np.asarray(meta["rate_bounds"], dtype=float)
        grid = [np.asarray(g, dtype=float) for g in meta["grid"]]
        gamma = float(meta["gamma"])
        pd = dims(ModelConfig.from_dict(meta["model"]))
    except (TypeError, ValueError, KeyError) as exc:
        raise _err(path, "metadata", f"malformed ({exc})") from None
    if meta.get("reference") is not None:
        ref = meta["reference"]
        keys = {"enabled", "lambda_s", "pump_fraction", "k_min"}
        if not isinstance(ref, dict) or not keys <= set(ref) <= keys | {"lag_s"}:
            raise _err(path, "metadata.reference", f"must have the keys {sorted(keys)} (and lag_s)")
        try:
            ReferenceConfig.from_dict(ref)
        except (TypeError, ValueError) as exc:
            raise _err(path, "metadata.reference", str(exc)) from None
    try:
        drug_of(meta)
    except ValueError as exc:
        raise _err(path, "metadata.design.drug", str(exc)) from None
    if box.shape != (3, 2) or not np.all(np.isfinite(box)) or not np.all(box[:, 0] < box[:, 1]):
        raise _err(path, "metadata.box", "must be a finite 3x2 array with lower < upper")
    if rates.shape != (3,) or not np.all(np.isfinite(rates)) or np.any(rates < 0):
        raise _err(path, "metadata.rate_bounds", "must be 3 finite non-negative numbers")
    if len(grid) != 3 or any(g.ndim != 1 or g.size < 2 or not np.all(np.isfinite(g)) for g in grid):
        raise _err(path, "metadata.grid", "must be 3 finite 1-D lists with >= 2 nodes")
    for i, g in enumerate(grid):
        if np.any(np.diff(g) <= 0) or g[0] < box[i, 0] - 1e-9 or g[-1] > box[i, 1] + 1e-9:
            raise _err(path, "metadata.grid", f"axis {i} not increasing inside the box")
    if not np.isfinite(gamma) or gamma <= 0:
        raise _err(path, "metadata.gamma", f"{gamma!r} is not a positive finite number")
    try:
        family = ControllerFamily.from_metadata(meta)
    except (TypeError, ValueError) as exc:
        raise _err(path, "metadata.controller", str(exc)) from None
    impl = family.impl
    shapes = impl.coefficient_shapes(pd.n, pd.ny)
    extra = sorted(set(coefs) - set(shapes))
    if extra:
        raise _err(
            path, f"coef_{extra[0]}", f"not a coefficient of a {family.structure!r} artifact"
        )
    for name, allowed in shapes.items():
        if name not in coefs:
            raise _err(path, f"coef_{name}", "missing")
        shape = coefs[name].shape
        if shape not in allowed:
            want = " or ".join(str(a) for a in allowed)
            raise _err(path, f"coef_{name}", f"shape {shape}, expected {want}")
        _check_array(path, f"coef_{name}", coefs[name], shape)
    gshape = tuple(g.size for g in grid)
    for name, (r, c) in node_shapes(impl.controller_order(pd.n), pd.ny).items():
        if name not in nodes:
            raise _err(path, f"node_{name}", "missing")
        _check_array(path, f"node_{name}", nodes[name], (*gshape, r, c))


def load_artifact(path: str | Path) -> ControllerArtifact:
    """Load and fully check an artifact.

    Raises
    ------
    ArtifactError
        Naming the file and the field, if the file is missing, unreadable, truncated, of another
        format version, malformed, non-finite, or its content does not match its sha256.
    """
    p = str(path)
    if not os.path.isfile(p):
        raise _err(p, "<file>", "no such file")
    try:
        with np.load(p, allow_pickle=False) as z:
            files = set(z.files)
            for key in ("metadata", "sha256"):
                if key not in files:
                    raise _err(p, key, "missing")
            raw = {k: z[k] for k in files}
    except ArtifactError:
        raise
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as exc:
        raise _err(p, "<file>", f"not a readable artifact ({type(exc).__name__}: {exc})") from None
    try:
        meta = json.loads(bytes(raw["metadata"].astype(np.uint8)).decode())
    except (UnicodeDecodeError, json.JSONDecodeError, ValueError) as exc:
        raise _err(p, "metadata", f"not valid JSON ({exc})") from None
    try:
        stored_sha = bytes(raw["sha256"].astype(np.uint8)).decode("ascii")
    except (UnicodeDecodeError, ValueError):
        raise _err(p, "sha256", "not an ASCII hex digest") from None
    coefs = {k[5:]: raw[k] for k in raw if k.startswith("coef_")}
    nodes = {k[5:]: raw[k] for k in raw if k.startswith("node_")}
    _validate(meta, coefs, nodes, p)
    actual = content_hash(meta, coefs, nodes)
    if actual != stored_sha:
        raise _err(
            p, "sha256", f"content hash {actual[:16]}… does not match stored {stored_sha[:16]}…"
        )
    return ControllerArtifact(meta, coefs, nodes, actual)
