"""The artifact store: every stage writes one zarr v3 group (a directory).

Attributes of the root group:
  ``loomlight``: schema id and version, stage, parameters, content hashes of inputs, build key,
                 loomlight version, wall time, peak memory, ``complete: true``, content hash;
  ``summary``:   the kind-specific numbers ``loomlight info`` shows (counts, bounds, bytes).

Publishing is atomic: an artifact is built in a hidden sibling directory, its attributes are
schema-checked and marked complete, then it is exchanged with the previous one in one
``renameat2(RENAME_EXCHANGE)`` (two renames where the kernel lacks it). A stage killed at any
moment leaves no partial artifact at the output path and the previous artifact untouched.
A stage whose inputs, parameters and code (loomlight's own source files) are unchanged is not re-run:
its build key matches the one recorded in the existing artifact.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import hashlib
import json
import os
import resource
import shutil
import time
import uuid
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import zarr

from . import __version__
from .errors import IncompleteArtifact, LoomError
from .schemas import validate

SCHEMA_VERSION = 1


# ------------------------------------------------------------------------------------------------
# hashing
def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def content_hash(path: str | Path) -> str:
    """Content hash of an input: a file's sha256, or an artifact's recorded content hash."""
    path = Path(path)
    if path.is_dir():
        meta = read_meta(path)
        return meta["content_hash"]
    if not path.exists():
        raise LoomError(path, None, "file not found")
    return _sha256_file(path)


def _canonical(obj: Any) -> str:
    def default(o):
        if isinstance(o, (np.integer,)):
            return int(o)
        if isinstance(o, (np.floating,)):
            return float(o)
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, Path):
            return str(o)
        raise TypeError(f"not JSON-serialisable: {type(o)}")

    return json.dumps(obj, sort_keys=True, default=default, separators=(",", ":"))


def jsonable(obj: Any) -> Any:
    return json.loads(_canonical(obj))


_CODE_HASH: str | None = None


def code_hash() -> str:
    """sha256 over loomlight's own source (pipeline/, stages/, schemas/): an artifact built by other code
    (a changed kernel or layout) is never taken as up to date."""
    global _CODE_HASH
    if _CODE_HASH is None:
        root = Path(__file__).resolve().parents[1]
        h = hashlib.sha256()
        for sub, pattern in (("pipeline", "*.py"), ("stages", "*.py"), ("schemas", "*.json")):
            for f in sorted((root / sub).rglob(pattern)):
                h.update(str(f.relative_to(root)).encode())
                h.update(f.read_bytes())
        _CODE_HASH = h.hexdigest()
    return _CODE_HASH


def build_key(kind: str, stage: str, params: Mapping, input_hashes: Mapping[str, str]) -> str:
    doc = {"kind": kind, "stage": stage, "params": params, "inputs": dict(input_hashes), "version": __version__,
           "code": code_hash()}
    return hashlib.sha256(_canonical(doc).encode()).hexdigest()


# ------------------------------------------------------------------------------------------------
# reading
def read_meta(path: str | Path) -> dict:
    """The ``loomlight`` attribute block of an artifact, refusing incomplete ones."""
    path = Path(path)
    if not path.exists():
        raise LoomError(path, None, "artifact not found")
    if not (path / "zarr.json").exists():
        raise LoomError(path, None, "not a zarr v3 artifact (no zarr.json)")
    try:
        attrs = json.loads((path / "zarr.json").read_text()).get("attributes", {})
    except (OSError, json.JSONDecodeError) as e:
        raise LoomError(path / "zarr.json", None, f"unreadable artifact metadata: {e}") from None
    meta = attrs.get("loomlight")
    if not isinstance(meta, dict):
        raise LoomError(path, None, "not a loomlight artifact (no 'loomlight' attributes)")
    if meta.get("complete") is not True:
        raise IncompleteArtifact(path, None, "artifact is incomplete (its stage did not finish); re-run the stage")
    return meta


class Artifact:
    """A complete, schema-checked artifact opened for reading."""

    def __init__(self, path: str | Path, kind: str | None = None):
        self.path = Path(path)
        self.meta = read_meta(self.path)
        if kind is not None and self.meta.get("kind") != kind:
            raise LoomError(self.path, None, f"expected a {kind!r} artifact, found {self.meta.get('kind')!r}")
        self.group = zarr.open_group(str(self.path), mode="r")
        self.summary = dict(self.group.attrs.get("summary", {}))
        _check_schema(self.path, self.meta, self.summary, self.group)

    @property
    def kind(self) -> str:
        return self.meta["kind"]

    @property
    def params(self) -> dict:
        return self.meta.get("params", {})

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.group[name][...]
        except KeyError:
            raise LoomError(self.path, name, "array missing from artifact") from None

    def __contains__(self, name: str) -> bool:
        return name in self.group

    def arrays(self) -> dict[str, Any]:
        out = {}
        def walk(g, prefix=""):
            for name, a in g.arrays():
                out[prefix + name] = a
            for name, sub in g.groups():
                walk(sub, prefix + name + "/")
        walk(self.group)
        return out

    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self.arrays().values()))


def _manifest(meta: dict, summary: dict, group) -> dict:
    arrays = {}
    def walk(g, prefix=""):
        for name, a in g.arrays():
            arrays[prefix + name] = {"dtype": str(a.dtype), "shape": list(a.shape)}
        for name, sub in g.groups():
            walk(sub, prefix + name + "/")
    walk(group)
    return {"summary": summary, "arrays": arrays, "params": meta.get("params", {})}


def _check_schema(path: Path, meta: dict, summary: dict, group) -> None:
    validate(meta, "artifact-meta", path, prefix="loomlight.")
    validate(_manifest(meta, summary, group), meta["kind"], path)


# ------------------------------------------------------------------------------------------------
# writing
_libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> bool:
    """Atomically exchange two existing paths; False where the kernel cannot."""
    fn = getattr(_libc, "renameat2", None)
    if fn is None:
        return False
    rc = fn(_AT_FDCWD, os.fsencode(str(a)), _AT_FDCWD, os.fsencode(str(b)), _RENAME_EXCHANGE)
    return rc == 0


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _clean_stale_siblings(path: Path) -> None:
    """Remove hidden build directories left by killed stages (their process is gone)."""
    parent = path.parent
    if not parent.exists():
        return
    for p in parent.glob(f".{path.name}.tmp-*"):
        try:
            pid = int(p.name.rsplit("-", 2)[-2])
        except (ValueError, IndexError):
            continue
        if not _pid_alive(pid):
            shutil.rmtree(p, ignore_errors=True)
    for p in parent.glob(f".{path.name}.old-*"):
        shutil.rmtree(p, ignore_errors=True)


def is_up_to_date(path: str | Path, key: str) -> bool:
    """True when a complete artifact at ``path`` was built with build key ``key``."""
    try:
        meta = read_meta(path)
    except LoomError:
        return False
    return meta.get("build_key") == key


class ArtifactWriter:
    """Build an artifact in a hidden sibling directory and publish it atomically.

    ::

        with ArtifactWriter(out, kind="yarns", stage="ingest", params=p, inputs={"source": src}) as w:
            w.write("points", pts, chunks=(65536, 3))
            w.summary.update(curves=n)
    """

    def __init__(self, path: str | Path, kind: str, stage: str, params: Mapping | None = None,
                 inputs: Mapping[str, str | Path] | None = None):
        self.path = Path(path)
        if self.path.suffix != ".zarr":
            raise LoomError(self.path, None, "artifact paths end in .zarr")
        self.kind = kind
        self.stage = stage
        self.params = jsonable(params or {})
        self.inputs = {name: str(p) for name, p in (inputs or {}).items()}
        self.input_hashes = {name: content_hash(p) for name, p in self.inputs.items()}
        self.key = build_key(kind, stage, self.params, self.input_hashes)
        self.summary: dict[str, Any] = {}
        self.tmp: Path | None = None
        self.group = None
        self._t0 = 0.0

    def up_to_date(self) -> bool:
        return is_up_to_date(self.path, self.key)

    def __enter__(self) -> "ArtifactWriter":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        _clean_stale_siblings(self.path)
        self.tmp = self.path.parent / f".{self.path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        self.group = zarr.open_group(str(self.tmp), mode="w", zarr_format=3)
        self.group.attrs["loomlight"] = {"kind": self.kind, "stage": self.stage, "complete": False}
        self._t0 = time.perf_counter()
        return self

    # -- arrays ---------------------------------------------------------------------------------
    def write(self, name: str, data, chunks=None, dimension_names=None, attributes=None):
        data = np.asarray(data)
        if chunks is None:
            chunks = _default_chunks(data.shape, data.dtype.itemsize)
        kw = {}
        if dimension_names is not None:
            kw["dimension_names"] = dimension_names
        a = self.group.create_array(name, shape=data.shape, chunks=chunks, dtype=data.dtype,
                                    fill_value=_fill(data.dtype), attributes=attributes or {}, **kw)
        if data.size:
            a[...] = data
        return a

    def create(self, name: str, shape, dtype, chunks, dimension_names=None, attributes=None):
        """An empty array whose chunks independent chunk tasks fill (see ``pipeline.chunks``)."""
        kw = {}
        if dimension_names is not None:
            kw["dimension_names"] = dimension_names
        dtype = np.dtype(dtype)
        return self.group.create_array(name, shape=tuple(shape), chunks=tuple(chunks), dtype=dtype,
                                       fill_value=_fill(dtype), attributes=attributes or {}, **kw)

    @property
    def store_path(self) -> Path:
        """Where chunk tasks open the array being built (the hidden directory)."""
        assert self.tmp is not None
        return self.tmp

    # -- publishing -----------------------------------------------------------------------------
    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            return False
        try:
            self._finalize()
        except BaseException:
            shutil.rmtree(self.tmp, ignore_errors=True)
            raise
        return False

    def _finalize(self) -> None:
        group = zarr.open_group(str(self.tmp), mode="r+")
        meta = {
            "kind": self.kind,
            "schema": f"loomlight/{self.kind}",
            "schema_version": SCHEMA_VERSION,
            "stage": self.stage,
            "params": self.params,
            "inputs": {n: {"path": p, "sha256": self.input_hashes[n]} for n, p in self.inputs.items()},
            "build_key": self.key,
            "loomlight_version": __version__,
            "wall_time_s": time.perf_counter() - self._t0,
            "peak_memory_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "content_hash": self._content_hash(group),
            "complete": True,
        }
        summary = jsonable(self.summary)
        _check_schema(self.tmp, meta, summary, group)
        group.attrs["summary"] = summary
        group.attrs["loomlight"] = meta
        _publish(self.tmp, self.path)

    def _content_hash(self, group) -> str:
        h = hashlib.sha256()
        h.update(self.kind.encode())
        h.update(_canonical(jsonable(self.summary)).encode())
        hash_arrays(group, h)
        return h.hexdigest()


def hash_arrays(group, h) -> None:
    """Feed every array of a zarr group (name, dtype, shape, bytes; sorted, sub-groups too) to hash h."""
    def walk(g, prefix=""):
        for name, a in sorted(g.arrays(), key=lambda t: t[0]):
            h.update(f"{prefix}{name}:{a.dtype}:{a.shape}".encode())
            h.update(np.ascontiguousarray(a[...]).tobytes())
        for name, sub in sorted(g.groups(), key=lambda t: t[0]):
            walk(sub, prefix + name + "/")
    walk(group)


def _publish(tmp: Path, path: Path) -> None:
    if path.exists() or path.is_symlink():
        if _exchange(tmp, path):
            shutil.rmtree(tmp, ignore_errors=True)  # tmp now holds the previous artifact
            return
        old = path.parent / f".{path.name}.old-{uuid.uuid4().hex[:8]}"
        os.rename(path, old)
        os.rename(tmp, path)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.rename(tmp, path)


def _fill(dtype: np.dtype):
    dtype = np.dtype(dtype)
    if dtype.kind == "b":
        return False
    if dtype.kind in "iu":
        return 0
    return 0.0


def _default_chunks(shape, itemsize: int, target_bytes: int = 4 << 20):
    if len(shape) == 0:
        return ()
    rest = int(np.prod(shape[1:])) if len(shape) > 1 else 1
    rows = max(1, target_bytes // max(1, rest * itemsize))
    return (int(min(max(shape[0], 1), rows)),) + tuple(int(max(s, 1)) for s in shape[1:])
