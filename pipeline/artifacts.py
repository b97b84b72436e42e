"""The artifact store: every stage writes one zarr v3 group (a directory).

Attributes of the root group:
  ``loomlight``: schema id and version, stage, parameters, the inputs (path, identity, stat
                 fingerprint), build key, loomlight version, wall time, peak memory, per-array
                 checksums, content hash, ``complete: true``;
  ``summary``:   the kind-specific numbers ``loomlight info`` shows (counts, bounds, bytes).

Publishing is atomic: an artifact is built in a hidden sibling directory, its attributes are
schema-checked and marked complete, then it is exchanged with the previous one in one
``renameat2(RENAME_EXCHANGE)`` (two renames where the kernel lacks it). A stage killed at any
moment leaves no partial artifact at the output path and the previous artifact untouched; the next
writer of that path (even one that finds the artifact up to date) removes what killed runs left.
Files published together with an artifact (a render's EXR and PNG: ``companions``) go through a
journal: all of them are complete before it is written, and a publication a kill interrupted
after that is finished by the next writer of the artifact or by the next reader of it or of its files
(``settle``, in ``read_meta`` and ``images.read_exr``; a publication in progress is waited for), so a
reader sees either the old set or the new one.

Artifacts are what they claim: at write every array gets a sha256 and a crc32c of its bytes, and
the content hash covers the kind, the summary, the parameters and those checksums. ``Artifact``
refuses one whose content hash does not match its summary, parameters and checksums (an edited
summary or hash), whose arrays differ from the recorded ones, whose summary's counts, shapes or
orders disagree with its arrays' shapes (a forged summary with a recomputed hash:
``pipeline.artifact_checks``), or that has no checksums (written before they were recorded:
rebuild it), and checks an array's crc32c whenever it reads it, so a deleted or truncated chunk is
an error, never zeros.

A stage whose inputs, parameters and code (loomlight's own source files) are unchanged is not
re-run: its build key matches the one recorded in the existing artifact. An input's identity is
recomputed from its bytes (a file's sha256; an artifact's chunk and metadata files hashed), never
taken from what the input says of itself; a stat fingerprint of every file (size, mtime, ctime,
inode: ctime cannot be set back without changing the clock) recorded beside it lets an unchanged
input skip the re-hashing.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import fcntl
import glob
import hashlib
import json
import math
import os
import re
import shutil
import sys
import time
import uuid
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

from . import __version__
from .artifact_checks import check_summary
from .errors import IncompleteArtifact, LoomError
from .memory import peak_rss_bytes
from .schemas import validate

if TYPE_CHECKING:
    import numpy as np

# numpy and zarr are imported where arrays are read or written, not at module level: ``loomlight
# info`` (metadata only) answers without loading them.

SCHEMA_VERSION = 1
FILE = "file"                      # the kind of an input that is a plain file, not an artifact
PAUSE_ENV = "LOOMLIGHT_PAUSE_AT"   # tests: "<point>[,<point>...]" sleeps there (see pause_point)
PUBLISH_WAIT_ENV = "LOOMLIGHT_PUBLISH_WAIT"   # seconds a reader waits for a publication in progress (30)
_HEX64 = re.compile(r"^[0-9a-f]{64}$")


def pause_point(name: str) -> None:
    """A named moment of publication (``built``, ``journal``, ``half-published``); a process whose
    LOOMLIGHT_PAUSE_AT names it announces the moment on stderr and sleeps, so a test can kill it there."""
    points = os.environ.get(PAUSE_ENV)
    if points and name in points.split(","):
        print(f"loomlight: paused at {name}", file=sys.stderr, flush=True)
        time.sleep(3600)


# ------------------------------------------------------------------------------------------------
# hashing
def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _canonical(obj: Any) -> str:
    def default(o):
        import numpy as np

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


def content_digest(kind: str, summary: Mapping, checksums: Mapping, params: Mapping | None) -> str:
    """The content hash: sha256 over the kind, the summary, every array's recorded checksums and the
    parameters (``None``: the hash of artifacts written before the parameters joined it)."""
    doc = {"kind": kind, "summary": summary, "arrays": checksums}
    if params is not None:
        doc["params"] = params
    return hashlib.sha256(_canonical(doc).encode()).hexdigest()


def array_checksums(a, block_bytes: int = 16 << 20) -> dict:
    """{"sha256", "crc32c"} of a (zarr) array's C-order bytes, read in blocks of whole chunk rows."""
    import google_crc32c
    import numpy as np

    h, crc = hashlib.sha256(), 0
    rows = a.shape[0] if a.ndim else 1
    step = max(1, block_bytes // max(1, int(a.nbytes) // max(rows, 1)))
    if a.ndim:
        step = max(a.chunks[0], step // a.chunks[0] * a.chunks[0])
    for i in range(0, max(rows, 1), step):
        raw = np.ascontiguousarray(a[i:i + step] if a.ndim else a[...]).reshape(-1).view(np.uint8)
        h.update(raw)
        crc = google_crc32c.extend(crc, raw.tobytes())
    return {"sha256": h.hexdigest(), "crc32c": int(crc)}


def _crc32c(data: np.ndarray) -> int:
    import google_crc32c
    import numpy as np

    return int(google_crc32c.value(np.ascontiguousarray(data).reshape(-1).view(np.uint8)))


def hash_arrays(group, h) -> None:
    """Feed every array of a zarr group (name, dtype, shape, bytes; sorted, sub-groups too) to hash h."""
    import numpy as np

    for name, a in _walk_arrays(group):
        h.update(f"{name}:{a.dtype}:{a.shape}".encode())
        h.update(np.ascontiguousarray(a[...]).tobytes())


def _walk_arrays(group, prefix=""):
    """(name, zarr array) of a group and its sub-groups, sorted by name at every level."""
    for name, a in sorted(group.arrays(), key=lambda t: t[0]):
        yield prefix + name, a
    for name, sub in sorted(group.groups(), key=lambda t: t[0]):
        yield from _walk_arrays(sub, prefix + name + "/")


# ------------------------------------------------------------------------------------------------
# inputs: identity (recomputed from the bytes) and stat fingerprint
def _root_attrs(path: Path) -> dict:
    try:
        return json.loads((path / "zarr.json").read_text()).get("attributes", {}) or {}
    except (OSError, ValueError, AttributeError) as e:  # ValueError: bad JSON or bytes that are not UTF-8
        raise LoomError(path / "zarr.json", None, f"unreadable artifact metadata: {_short(e)}") from None


def _artifact_files(path: Path) -> list[tuple[str, Path]]:
    """Every file of an artifact directory but its root zarr.json, by relative path."""
    out = []
    for dirpath, dirnames, filenames in os.walk(path):
        dirnames.sort()
        for fn in filenames:
            f = Path(dirpath) / fn
            rel = f.relative_to(path).as_posix()
            if rel != "zarr.json":
                out.append((rel, f))
    return sorted(out)


def _check_kind(path: Path, kind, found: str) -> None:
    if kind is None:
        return
    kinds = (kind,) if isinstance(kind, str) else tuple(kind)
    if found not in kinds:
        want = " or ".join(repr(k) if k != FILE else "a file" for k in kinds)
        what = "a file" if found == FILE else f"a {found!r} artifact"
        raise LoomError(path, None, f"expected {want if FILE in kinds else 'a ' + want + ' artifact'}, found {what}")


def _input_kind(path: Path, kind) -> str:
    """The input's kind (FILE or the artifact's kind), refusing a missing input or one of the wrong kind."""
    if path.is_dir():
        found = read_meta(path).get("kind", "?")
    elif path.exists():
        found = FILE
    else:
        raise LoomError(path, None, "artifact not found" if path.suffix == ".zarr" else "file not found")
    _check_kind(path, kind, found)
    return found


def input_identity(path: str | Path, kind=None) -> str:
    """What an input is, from its bytes: a file's sha256; for an artifact, a sha256 over its kind,
    content hash and summary and every chunk and array-metadata file (names, sizes, bytes)."""
    path = Path(path)
    if _input_kind(path, kind) == FILE:
        return sha256_file(path)
    attrs = _root_attrs(path)
    meta = attrs.get("loomlight", {})
    h = hashlib.sha256(_canonical({"kind": meta.get("kind"), "content_hash": meta.get("content_hash"),
                                   "summary": attrs.get("summary")}).encode())
    for rel, f in _artifact_files(path):
        h.update(f"\0{rel}\0{f.stat().st_size}\0".encode())
        with open(f, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def content_hash(path: str | Path) -> str:
    """Identity of an input file or artifact (``input_identity``)."""
    return input_identity(path)


def stat_fingerprint(path: str | Path, kind=None) -> str:
    """sha256 over (size, mtime, ctime, inode) of an input's files (an artifact's root metadata by its
    bytes): equal fingerprints mean untouched files, since writing a file moves its ctime."""
    path = Path(path)
    _input_kind(path, kind)
    h = hashlib.sha256()
    files = [(path.name, path)] if path.is_file() else _artifact_files(path)
    for rel, f in files:
        st = f.stat()
        h.update(f"{rel}\0{st.st_size}\0{st.st_mtime_ns}\0{st.st_ctime_ns}\0{st.st_ino}\0{st.st_dev}\n".encode())
    if path.is_dir():
        h.update((path / "zarr.json").read_bytes())
    return h.hexdigest()


# ------------------------------------------------------------------------------------------------
# reading
def read_meta(path: str | Path) -> dict:
    """The ``loomlight`` attribute block of an artifact, refusing incomplete ones (a publication of it
    left half done is settled first: ``settle``)."""
    path = Path(path)
    settle(path)
    if not path.exists():
        raise LoomError(path, None, "artifact not found")
    if not (path / "zarr.json").exists():
        raise LoomError(path, None, "not a zarr v3 artifact (no zarr.json)")
    meta = _root_attrs(path).get("loomlight")
    if not isinstance(meta, dict):
        raise LoomError(path, None, "not a loomlight artifact (no 'loomlight' attributes)")
    if meta.get("complete") is not True:
        raise IncompleteArtifact(path, None, "artifact is incomplete (its stage did not finish); re-run the stage")
    return meta


def verify_meta(path: Path, meta: dict, summary: dict) -> dict:
    """The recorded checksums, once the content hash matches them, the summary and the parameters."""
    checksums = meta.get("arrays")
    if not isinstance(checksums, dict):
        raise LoomError(path, None, "artifact has no checksums (written by a loomlight before they were recorded); "
                        "rebuild it with its stage")
    if content_digest(meta.get("kind"), summary, checksums, meta.get("params", {})) != meta.get("content_hash"):
        if content_digest(meta.get("kind"), summary, checksums, None) == meta.get("content_hash"):
            raise LoomError(path, None, "written by a loomlight whose content hash did not cover the parameters; "
                            "rebuild it with its stage")
        raise LoomError(path, None, "the summary or checksums do not match the content hash (edited? it covers "
                        "the parameters too); rebuild it with its stage")
    return checksums


class Artifact:
    """A complete, schema-checked artifact opened for reading; every array read is checked
    against the checksum recorded at write."""

    def __init__(self, path: str | Path, kind: str | None = None):
        self.path = Path(path)
        self.meta = read_meta(self.path)
        if kind is not None and self.meta.get("kind") != kind:
            raise LoomError(self.path, None, f"expected a {kind!r} artifact, found {self.meta.get('kind')!r}")
        self.summary = dict(_root_attrs(self.path).get("summary", {}) or {})
        self._checksums = verify_meta(self.path, self.meta, self.summary)
        self._group = None
        arrays = _array_metadata(self.path)
        if arrays is None:  # a data type the metadata walk does not know: let zarr describe the arrays
            arrays = {name: {"dtype": str(a.dtype), "shape": list(a.shape)} for name, a in _walk_arrays(self.group)}
        manifest = {"summary": self.summary, "arrays": arrays, "params": self.meta.get("params", {})}
        self._check_arrays(manifest["arrays"])
        self._arrays = arrays
        validate(self.meta, "artifact-meta", self.path, prefix="loomlight.")
        validate(manifest, self.meta["kind"], self.path)
        check_summary(self.path, self.meta["kind"], self.summary, arrays)

    @property
    def group(self):
        """The zarr group, opened at the first array access (``info`` reads metadata only)."""
        if self._group is None:
            import zarr

            try:
                self._group = zarr.open_group(str(self.path), mode="r")
            except Exception as e:  # a corrupt zarr.json
                raise LoomError(self.path, None, f"unreadable artifact ({_short(e)})") from None
        return self._group

    def _check_arrays(self, found: dict) -> None:
        for name, rec in sorted(self._checksums.items()):
            a = found.get(name)
            if a is None:
                raise LoomError(self.path, f"array {name}", "recorded at write but missing (deleted?)")
            if a["dtype"] != rec.get("dtype") or a["shape"] != rec.get("shape"):
                raise LoomError(self.path, f"array {name}", f"is {a['dtype']} {a['shape']}, recorded as "
                                f"{rec.get('dtype')} {rec.get('shape')}")
        extra = sorted(set(found) - set(self._checksums))
        if extra:
            raise LoomError(self.path, f"array {extra[0]}", "not recorded at write (added later?)")

    @property
    def kind(self) -> str:
        return self.meta["kind"]

    @property
    def params(self) -> dict:
        return self.meta.get("params", {})

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._checksums:
            raise LoomError(self.path, name, "array missing from artifact")
        place = f"array {name}"
        try:
            data = self.group[name][...]
        except Exception as e:  # zarr / codec errors: a truncated or garbled chunk, a missing array directory
            raise LoomError(self.path, place, f"cannot be read, chunk missing or corrupt ({_short(e)}); "
                            "rebuild it with its stage (--force if it says up to date)") from None
        if _crc32c(data) != self._checksums[name]["crc32c"]:
            raise LoomError(self.path, place, "content does not match its checksum (chunk missing or corrupt); "
                            "rebuild it with its stage (--force if it says up to date)")
        return data

    def __contains__(self, name: str) -> bool:
        return name in self._checksums

    def verify(self) -> int:
        """Read every array, in blocks, and compare its sha256 and crc32c with the ones recorded at write (a
        deleted, truncated or garbled chunk is a LoomError naming the array); returns the bytes read."""
        total = 0
        for name, rec in sorted(self._checksums.items()):
            place = f"array {name}"
            try:
                a = self.group[name]
                got = array_checksums(a)
            except Exception as e:  # zarr / codec errors: a truncated or garbled chunk, a missing array directory
                raise LoomError(self.path, place, f"cannot be read, chunk missing or corrupt ({_short(e)}); "
                                "rebuild it with its stage (--force if it says up to date)") from None
            if got["sha256"] != rec.get("sha256") or got["crc32c"] != rec.get("crc32c"):
                raise LoomError(self.path, place, "content does not match its checksum (chunk missing or corrupt); "
                                "rebuild it with its stage (--force if it says up to date)")
            total += int(a.nbytes)
        return total

    def arrays(self) -> dict[str, Any]:
        return dict(_walk_arrays(self.group))

    def nbytes(self) -> int:
        """Bytes of all arrays, uncompressed."""
        if all(rec["dtype"] in _ITEMSIZE for rec in self._arrays.values()):
            return sum(_ITEMSIZE[rec["dtype"]] * math.prod(rec["shape"]) for rec in self._arrays.values())
        return int(sum(a.nbytes for a in self.arrays().values()))


_ITEMSIZE = {"bool": 1, "int8": 1, "uint8": 1, "int16": 2, "uint16": 2, "int32": 4, "uint32": 4, "int64": 8,
             "uint64": 8, "float16": 2, "float32": 4, "float64": 8, "complex64": 8, "complex128": 16}


def _array_metadata(path: Path, prefix: str = "") -> dict[str, dict] | None:
    """{name: {"dtype", "shape"}} of every array of a zarr v3 group and its sub-groups, read from their
    zarr.json files (no zarr, no numpy); None when an array has a data type other than the plain
    numeric ones (``_ITEMSIZE``), whose name zarr would spell otherwise."""
    out: dict[str, dict] = {}
    try:
        entries = sorted(os.scandir(path), key=lambda e: e.name)
    except OSError as e:
        raise LoomError(path, None, f"unreadable artifact ({_short(e)})") from None
    for e in entries:
        node = Path(e.path) / "zarr.json"
        if not e.is_dir() or not node.is_file():
            continue
        try:
            doc = json.loads(node.read_text())
            kind = doc["node_type"]
            if kind == "array":
                dtype, shape = doc["data_type"], [int(n) for n in doc["shape"]]
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:  # a corrupt array zarr.json
            raise LoomError(path, None, f"unreadable artifact ({node}: {_short(err)})") from None
        if kind == "array":
            if not isinstance(dtype, str) or dtype not in _ITEMSIZE:
                return None
            out[prefix + e.name] = {"dtype": dtype, "shape": shape}
        elif kind == "group":
            sub = _array_metadata(Path(e.path), prefix + e.name + "/")
            if sub is None:
                return None
            out.update(sub)
    return out


def _short(e: BaseException) -> str:
    text = " ".join(str(e).split()) or type(e).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def _manifest(meta: dict, summary: dict, group) -> dict:
    arrays = {name: {"dtype": str(a.dtype), "shape": list(a.shape)} for name, a in _walk_arrays(group)}
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


def temp_sibling(path: Path, tag: str = "tmp") -> Path:
    """A hidden name beside ``path`` owned by this process: ``.<name>.<tag>-<pid>-<random><suffix>``."""
    return path.parent / f".{path.name}.{tag}-{os.getpid()}-{uuid.uuid4().hex[:8]}{path.suffix}"


_OWNED = re.compile(r"\.(tmp|old|publish)-(\d+)-[0-9a-f]{8}")


def _owner_dead(p: Path) -> bool:
    m = _OWNED.search(p.name)
    return m is not None and not _pid_alive(int(m.group(2)))


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        p.unlink(missing_ok=True)


def clean_stale(path: Path) -> None:
    """Finish a publication of ``path`` a killed run left half done (its journal), restore a previous
    artifact a killed fallback publication left aside, then remove the hidden temporaries killed
    runs left beside ``path`` (their process is gone)."""
    parent = path.parent
    if not parent.exists():
        return
    dead = sorted(p for p in parent.glob(f".{path.name}.*") if _owner_dead(p))
    for p in dead:
        if _OWNED.search(p.name).group(1) == "publish" and p.suffix == ".json":
            _roll_forward(p)
    for p in dead:
        if _OWNED.search(p.name).group(1) == "old" and not path.exists() and p.is_dir():
            os.rename(p, path)
    for p in dead:
        if p.exists() or p.is_symlink():
            _remove(p)


class ArtifactWriter:
    """Build an artifact in a hidden sibling directory and publish it atomically.

    ::

        with ArtifactWriter(out, kind="yarns", stage="ingest", params=p, inputs={"source": src}) as w:
            w.write("points", pts, chunks=(65536, 3))
            w.summary.update(curves=n)

    ``inputs`` maps a name to a path, or to ``(path, kind)``: kind ``FILE`` (a plain file), an artifact
    kind or a tuple of kinds; an input of another kind is refused. The output may be neither an
    input nor inside one, nor an existing file or directory that is not an artifact.
    ``companions`` are files published together with the artifact (``companion(dst)`` gives the
    temporary path to write each to). ``started``: the ``time.perf_counter()`` at which the stage's run
    began (default: now); the recorded ``wall_time_s`` runs from it to publication, so it covers the
    whole stage (reading inputs, compilation, compute, writing), not only the writing.
    """

    def __init__(self, path: str | Path, kind: str, stage: str, params: Mapping | None = None,
                 inputs: Mapping[str, Any] | None = None, companions=(), started: float | None = None):
        self._t0 = time.perf_counter() if started is None else float(started)
        self.path = Path(path)
        if self.path.suffix != ".zarr":
            raise LoomError(self.path, None, "artifact paths end in .zarr")
        self.kind = kind
        self.stage = stage
        self.params = jsonable(params or {})
        self.inputs: dict[str, tuple[str, Any]] = {}
        for name, spec in (inputs or {}).items():
            p, k = spec if isinstance(spec, tuple) else (spec, None)
            self.inputs[name] = (str(p), k)
        self.companions = [Path(c) for c in companions]
        self._check_outputs()
        clean_stale(self.path)
        for c in self.companions:
            clean_stale(c)
        self._ids: dict[str, str] | None = None
        self._stats: dict[str, str] = {}
        self._staged: dict[Path, Path] = {}
        self.summary: dict[str, Any] = {}
        self.tmp: Path | None = None
        self.group = None

    # -- checks before any work -------------------------------------------------------------------
    def _check_outputs(self) -> None:
        p = self.path
        if p.is_symlink():
            raise LoomError(p, "-o", "is a symbolic link; give the artifact's real path")
        if p.exists():
            if not p.is_dir():
                raise LoomError(p, "-o", "exists and is not an artifact (a regular file); refusing to replace it")
            if any(p.iterdir()) and not isinstance(_loose_meta(p), dict):
                raise LoomError(p, "-o", "exists and is not a loomlight artifact; refusing to replace it")
        for c in self.companions:
            if c.is_dir():
                raise LoomError(c, "-o", "is a directory")
        for name, (ip, _) in self.inputs.items():
            ir = Path(ip).resolve()
            for o in [p, *self.companions]:
                r = o.resolve()
                if r == ir or ir in r.parents or r in ir.parents:
                    raise LoomError(o, "-o", f"the output would overwrite the {name} input {ip}; choose another path")

    # -- up to date -------------------------------------------------------------------------------
    def input_identities(self, recorded: Mapping | None = None) -> dict[str, str]:
        """Every input's identity, recomputed from its bytes unless its stat fingerprint equals the one
        ``recorded`` beside the identity (by the artifact built from it)."""
        if self._ids is None or recorded is not None:
            ids = {}
            for name, (p, k) in self.inputs.items():
                fp = stat_fingerprint(p, k)
                rec = (recorded or {}).get(name) or {}
                if rec.get("stat") == fp and rec.get("path") == p and _HEX64.match(str(rec.get("sha256", ""))):
                    ids[name] = rec["sha256"]
                else:
                    ids[name] = input_identity(p, k)
                self._stats[name] = fp
            self._ids = ids
        return self._ids

    def up_to_date(self) -> bool:
        """True when the artifact at the output path is complete, intact in its metadata and was built
        with this build key."""
        try:
            meta = read_meta(self.path)
            verify_meta(self.path, meta, _root_attrs(self.path).get("summary", {}) or {})
        except LoomError:
            self.input_identities()
            return False
        ids = self.input_identities(meta.get("inputs"))
        return meta.get("build_key") == build_key(self.kind, self.stage, self.params, ids)

    # -- building ---------------------------------------------------------------------------------
    def __enter__(self) -> "ArtifactWriter":
        if self._ids is None:  # not asked up_to_date: the previous artifact's record may still spare the hashing
            self.input_identities(_recorded_inputs(self.path))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = temp_sibling(self.path)
        import zarr

        self.group = zarr.open_group(str(self.tmp), mode="w", zarr_format=3)
        self.group.attrs["loomlight"] = {"kind": self.kind, "stage": self.stage, "complete": False}
        return self

    def write(self, name: str, data, chunks=None, dimension_names=None, attributes=None):
        import numpy as np

        data = np.asarray(data)
        if chunks is None:
            chunks = _default_chunks(data.shape, data.dtype.itemsize)
        a = self.create(name, data.shape, data.dtype, chunks, dimension_names, attributes)
        if data.size:
            a[...] = data
        return a

    def create(self, name: str, shape, dtype, chunks, dimension_names=None, attributes=None):
        """An empty array whose chunks independent chunk tasks fill (see ``pipeline.chunks``)."""
        import numpy as np

        kw = {}
        if dimension_names is not None:
            kw["dimension_names"] = dimension_names
        dtype = np.dtype(dtype)
        return self.group.create_array(name, shape=tuple(shape), chunks=tuple(chunks), dtype=dtype,
                                       fill_value=_fill(dtype), attributes=attributes or {}, **kw)

    def companion(self, dst: str | Path) -> Path:
        """The temporary path to write companion ``dst`` to; it is published with the artifact."""
        dst = Path(dst)
        if dst not in self.companions:
            raise ValueError(f"{dst} is not a companion of {self.path}")
        self._staged[dst] = self._staged.get(dst) or temp_sibling(dst)
        return self._staged[dst]

    @property
    def store_path(self) -> Path:
        """Where chunk tasks open the array being built (the hidden directory), absolute: tasks may run
        in another process, in another directory."""
        assert self.tmp is not None
        return self.tmp.resolve()

    # -- publishing -------------------------------------------------------------------------------
    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            self._discard()
            return False
        try:
            self._finalize()
        except BaseException:
            self._discard()
            raise
        return False

    def _discard(self) -> None:
        shutil.rmtree(self.tmp, ignore_errors=True)
        for t in self._staged.values():
            _remove(t)

    def _finalize(self) -> None:
        import zarr

        group = zarr.open_group(str(self.tmp), mode="r+")
        summary = jsonable(self.summary)
        checksums = {}
        for name, a in _walk_arrays(group):
            checksums[name] = {"dtype": str(a.dtype), "shape": list(a.shape), **array_checksums(a)}
        companions = {}
        for dst in self.companions:
            tmp = self._staged.get(dst)
            if tmp is None or not tmp.is_file():
                raise RuntimeError(f"companion {dst} of {self.path} was not written")
            companions[dst.name] = {"path": str(dst), "sha256": sha256_file(tmp)}
        ids = self.input_identities()
        meta = {
            "kind": self.kind,
            "schema": f"loomlight/{self.kind}",
            "schema_version": SCHEMA_VERSION,
            "stage": self.stage,
            "params": self.params,
            "inputs": {n: {"path": p, "sha256": ids[n], "stat": self._stats[n]} for n, (p, _) in self.inputs.items()},
            "build_key": build_key(self.kind, self.stage, self.params, ids),
            "loomlight_version": __version__,
            "wall_time_s": time.perf_counter() - self._t0,
            "peak_memory_bytes": peak_rss_bytes(),
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "arrays": checksums,
            "content_hash": content_digest(self.kind, summary, checksums, self.params),
            "complete": True,
        }
        if companions:
            meta["companions"] = companions
        _check_schema(self.tmp, meta, summary, group)
        group.attrs["summary"] = summary
        group.attrs["loomlight"] = meta
        pause_point("built")
        if self._staged:
            _publish_set([(t, d) for d, t in self._staged.items()] + [(self.tmp, self.path)], self.path)
        else:
            _publish(self.tmp, self.path)


def _recorded_inputs(path: Path) -> dict | None:
    try:
        return read_meta(path).get("inputs")
    except LoomError:
        return None


def _loose_meta(path: Path):
    """The 'loomlight' attributes of a directory, complete or not; None when it has none."""
    try:
        return _root_attrs(path).get("loomlight")
    except LoomError:
        return None


def _publish(tmp: Path, path: Path) -> None:
    if path.exists() or path.is_symlink():
        if _exchange(tmp, path):
            shutil.rmtree(tmp, ignore_errors=True)  # tmp now holds the previous artifact
            return
        old = temp_sibling(path, "old")
        os.rename(path, old)
        os.rename(tmp, path)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.rename(tmp, path)


def _move(tmp: Path, dst: Path) -> None:
    """One move of a set (``_publish_set``): a file arrives with its time held at the epoch."""
    if tmp.is_dir():
        _publish(tmp, dst)
    else:
        os.utime(tmp, ns=(0, 0))
        os.replace(tmp, dst)


def _publish_set(moves: list[tuple[Path, Path]], path: Path) -> None:
    """Publish complete temporaries (files first, the artifact directory last) as one set: a journal
    listing the moves is written first (with the new directory's zarr.json digest, to tell it from the
    previous artifact an exchange leaves in its place), so the next writer of ``path``, or a reader
    (``settle``), finishes a publication a kill interrupted. Files are published with their modification
    time held at the epoch until the whole set is there (``_release_files``): Make, which judges a target
    (a render's EXR) by its time, sees a file of an unfinished set as out of date, never as done."""
    entries = [[str(t), str(d), sha256_file(t / "zarr.json") if t.is_dir() else None] for t, d in moves]
    journal = temp_sibling(path, "publish").with_suffix(".json")
    tmp = temp_sibling(path).with_suffix(".json")
    tmp.write_text(json.dumps(entries))
    os.replace(tmp, journal)
    pause_point("journal")
    for i, (t, d) in enumerate(moves):
        _move(t, d)
        if i == 0:
            pause_point("half-published")
    _release_files(entries)
    journal.unlink()


def _release_files(entries) -> None:
    """The published files of a finished set get the time it finished (``_publish_set``)."""
    for _, d, digest in entries:
        if digest is None and os.path.isfile(d):
            os.utime(d)


def _roll_forward(journal: Path) -> None:
    """Finish the moves a killed publication listed (those whose temporary is still the new one). Under
    a lock on the journal: two processes that find it (a writer, readers: ``settle``) finish it once."""
    try:
        fh = open(journal, "rb")
    except OSError:
        return  # finished by another process
    with fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        if not journal.exists():
            return  # another process finished it while this one waited for the lock
        try:
            entries = json.loads(fh.read())
        except (OSError, ValueError):
            entries = []
        for t, d, digest in entries:
            t, d = Path(t), Path(d)
            if t.is_dir() and (not (t / "zarr.json").is_file() or sha256_file(t / "zarr.json") != digest):
                continue  # the previous artifact, exchanged out: clean_stale removes it
            if t.exists():
                _move(t, d)
        _release_files(entries)
        journal.unlink(missing_ok=True)


def settle(path: str | Path) -> None:
    """Before a reader reads the artifact at ``path``, or a file published with it (a render's EXR: pass
    its ``.zarr``): a publication of that set which a killed process left half done (its journal still
    there, ``_publish_set``) is finished here, as its next writer would, and one in progress is waited
    for (``LOOMLIGHT_PUBLISH_WAIT`` seconds, default 30, then refused), so that a reader sees the old set
    or the new one, never the new EXR beside the old PNG and artifact. Without a journal beside ``path``
    (the common case) this is one directory listing."""
    path = Path(path)
    pattern = str(path.parent / (glob.escape(f".{path.name}") + ".publish-*.json"))
    deadline = None
    while True:
        journals = [Path(j) for j in glob.glob(pattern) if _OWNED.search(Path(j).name)]
        if not journals:
            return
        live = []
        for j in journals:
            if _owner_dead(j):
                try:
                    _roll_forward(j)
                except OSError as e:  # a reader without write access to the directory
                    raise LoomError(path, None, f"a publication of it was interrupted and cannot be finished "
                                    f"here ({_short(e)}); run its stage again") from None
            else:
                live.append(j)
        if not live:
            continue
        wait = float(os.environ.get(PUBLISH_WAIT_ENV) or 30)
        deadline = deadline if deadline is not None else time.monotonic() + wait
        if time.monotonic() >= deadline:
            pid = _OWNED.search(live[0].name).group(2)
            raise LoomError(path, None, f"is being published by process {pid} (its files are changing); read it "
                            "when that has finished")
        time.sleep(0.05)


def _fill(dtype: np.dtype):
    import numpy as np

    dtype = np.dtype(dtype)
    if dtype.kind == "b":
        return False
    if dtype.kind in "iu":
        return 0
    return 0.0


def _default_chunks(shape, itemsize: int, target_bytes: int = 4 << 20):
    if len(shape) == 0:
        return ()
    rest = math.prod(int(s) for s in shape[1:])
    rows = max(1, target_bytes // max(1, rest * itemsize))
    return (int(min(max(shape[0], 1), rows)),) + tuple(int(max(s, 1)) for s in shape[1:])
