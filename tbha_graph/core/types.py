"""Port types: what flows along an edge of the graph, how it is checked, hashed and stored.

Every port type answers four questions, so the scheduler and cache never special-case data:

* ``accepts(other)``: may an output of type ``other`` feed an input of this type? (checked before running)
* ``validate(value, where)``: is this runtime value of this type? (checked when a node returns)
* ``save(value, path) / load(path)``: how it is stored in the cache and run directory (never pickle)
* ``fingerprint(value)``: a content hash (arrays with dtype and shape, JSON canonicalised, files by content)

Types: :class:`Array`, :class:`Arrays` (a named bundle of arrays, one ``.npz``), :class:`Json`,
:class:`Model` (a pydantic model), :class:`File` (a path; a video is a file, streamed by its consumer),
:class:`AnyOf` (a principled union) and :class:`AnyType`.
"""
from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np
from pydantic import BaseModel

from .errors import PortTypeError

Dim = int | str | None  # fixed size, named symbolic size ("n_frames"), or any


class PortType:
    """Base class of all port types. Subclasses are small, immutable descriptions."""

    #: file suffix used when the value is stored
    suffix: str = ""

    def accepts(self, other: "PortType") -> bool:
        if isinstance(other, AnyOf):
            return all(self.accepts(o) for o in other.options)
        return self._accepts(other)

    def _accepts(self, other: "PortType") -> bool:  # pragma: no cover - overridden
        return type(self) is type(other)

    def validate(self, value: Any, where: str) -> Any:
        return value

    def save(self, value: Any, path: Path) -> None:
        raise NotImplementedError

    def load(self, path: Path) -> Any:
        raise NotImplementedError

    def fingerprint(self, value: Any) -> str:
        raise NotImplementedError

    def describe(self) -> str:
        return type(self).__name__

    def __repr__(self) -> str:
        return self.describe()

    def __or__(self, other: "PortType") -> "AnyOf":
        return AnyOf(self, other)


# ---------------------------------------------------------------------------------------------
# hashing helpers (one place)
# ---------------------------------------------------------------------------------------------
def _canonical_json(value: Any) -> bytes:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=True).encode()


def hash_json(value: Any) -> str:
    """SHA-256 of the canonical JSON form (sorted keys, no whitespace)."""
    return hashlib.sha256(_canonical_json(value)).hexdigest()


def hash_array(a: np.ndarray) -> str:
    """SHA-256 over dtype, shape and the C-contiguous bytes: equal bytes with another dtype/shape differ."""
    a = np.ascontiguousarray(a)
    if a.dtype.hasobject:
        raise PortTypeError("object arrays cannot be hashed or stored (no pickle); use a numeric or str dtype")
    h = hashlib.sha256()
    h.update(a.dtype.str.encode())
    h.update(repr(a.shape).encode())
    h.update(a.view(np.uint8).reshape(-1) if a.size else b"")
    return h.hexdigest()


def hash_file(path: Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while True:
            b = f.read(chunk)
            if not b:
                break
            h.update(b)
    return h.hexdigest()


# ---------------------------------------------------------------------------------------------
# arrays
# ---------------------------------------------------------------------------------------------
#: dtype *kinds* a port may declare instead of an exact dtype, with the numpy kind codes each admits
_KINDS = {"float": "f", "int": "iu", "uint": "u", "bool": "b", "str": "U"}


def _kinds_of(spec: str) -> set[str]:
    """numpy kind codes a declared dtype (exact, e.g. "float32", or a kind, e.g. "float") stands for."""
    return set(_KINDS[spec]) if spec in _KINDS else {np.dtype(spec).kind}


def _dtype_ok(want: str | None, got: np.dtype) -> bool:
    if want is None:
        return True
    if want in _KINDS:
        return got.kind in _KINDS[want]
    return np.dtype(want) == got


def _shape_desc(shape: Sequence[Dim] | None) -> str:
    if shape is None:
        return "any shape"
    return "(" + ", ".join("*" if d is None else str(d) for d in shape) + ("," if len(shape) == 1 else "") + ")"


class Array(PortType):
    """A numpy array with a dtype (``"float64"``, or a kind: ``"float"``, ``"int"``, ``"bool"``, ``"str"``)
    and a shape spec: ints are fixed sizes, strings name symbolic sizes (``"n_frames"``), ``None`` is any.

    ``Array("float", ("n_frames", 16, 3))`` is a joint-position array.
    """

    suffix = ".npz"

    def __init__(self, dtype: str | None = None, shape: Sequence[Dim] | None = None, doc: str = ""):
        self.dtype = dtype
        self.shape = tuple(shape) if shape is not None else None
        self.doc = doc

    def describe(self) -> str:
        return f"Array[{self.dtype or 'any'}, {_shape_desc(self.shape)}]"

    def _accepts(self, other: PortType) -> bool:
        if not isinstance(other, Array):
            return False
        a, b = self.dtype, other.dtype
        if a is not None and b is not None and a != b:
            # an exact dtype accepts only itself; a kind accepts any dtype (or kind) inside it
            if a not in _KINDS or not _kinds_of(b) <= _kinds_of(a):
                return False
        if self.shape is not None and other.shape is not None:
            if len(self.shape) != len(other.shape):
                return False
            for x, y in zip(self.shape, other.shape):
                if isinstance(x, int) and isinstance(y, int) and x != y:
                    return False
        return True

    def check(self, value: Any, where: str) -> np.ndarray:
        if not isinstance(value, np.ndarray):
            raise PortTypeError(f"{where}: expected a numpy array {self.describe()}, got {type(value).__name__}")
        if not _dtype_ok(self.dtype, value.dtype):
            raise PortTypeError(f"{where}: expected dtype {self.dtype}, got {value.dtype}")
        if value.dtype.hasobject:
            raise PortTypeError(f"{where}: object arrays are not allowed (they would need pickle)")
        if self.shape is not None:
            if value.ndim != len(self.shape) or any(
                isinstance(d, int) and d != s for d, s in zip(self.shape, value.shape)
            ):
                raise PortTypeError(f"{where}: expected shape {_shape_desc(self.shape)}, got {value.shape}")
        return value

    def validate(self, value: Any, where: str) -> np.ndarray:
        return self.check(value, where)

    def save(self, value: np.ndarray, path: Path) -> None:
        with open(path, "wb") as f:
            np.savez(f, value=value)

    def load(self, path: Path) -> np.ndarray:
        with np.load(path, allow_pickle=False) as z:
            return z["value"]

    def fingerprint(self, value: np.ndarray) -> str:
        return hash_array(value)


class Arrays(PortType):
    """A bundle of named arrays stored as one ``.npz`` (``dict[str, np.ndarray]``).

    ``keys`` declares arrays that must be present (name -> :class:`Array`); other keys may be present
    too. Strings and scalars are stored as 0-d arrays. A consumer declaring keys accepts a producer
    that declares at least those keys (or declares none, which is checked when it runs).
    """

    suffix = ".npz"

    def __init__(self, keys: dict[str, Array] | None = None, doc: str = ""):
        self.keys = dict(keys or {})
        self.doc = doc

    def describe(self) -> str:
        if not self.keys:
            return "Arrays"
        return "Arrays{" + ", ".join(f"{k}: {v.describe()}" for k, v in self.keys.items()) + "}"

    def _accepts(self, other: PortType) -> bool:
        if not isinstance(other, Arrays):
            return False
        if not other.keys:
            return True
        return all(k in other.keys and v.accepts(other.keys[k]) for k, v in self.keys.items())

    def validate(self, value: Any, where: str) -> dict[str, np.ndarray]:
        if not isinstance(value, dict):
            raise PortTypeError(f"{where}: expected a dict of arrays, got {type(value).__name__}")
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise PortTypeError(f"{where}: array names must be strings, got {k!r}")
            out[k] = v if isinstance(v, np.ndarray) else np.asarray(v)
            if out[k].dtype.hasobject:
                raise PortTypeError(f"{where}: key {k!r} is an object array (would need pickle)")
        missing = [k for k in self.keys if k not in out]
        if missing:
            raise PortTypeError(f"{where}: missing array(s) {missing}; present: {sorted(out)}")
        for k, spec in self.keys.items():
            spec.check(out[k], f"{where}[{k!r}]")
        return out

    def save(self, value: dict, path: Path) -> None:
        with open(path, "wb") as f:
            np.savez(f, **value)

    def load(self, path: Path) -> dict[str, np.ndarray]:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}

    def fingerprint(self, value: dict) -> str:
        return hash_json({k: hash_array(np.asarray(v)) for k, v in sorted(value.items())})


# ---------------------------------------------------------------------------------------------
# JSON and pydantic models
# ---------------------------------------------------------------------------------------------
def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"{type(o).__name__} is not JSON-serialisable")


class Json(PortType):
    """Any JSON-able value (dict, list, str, number, bool, None); numpy scalars/arrays become JSON."""

    suffix = ".json"

    def __init__(self, doc: str = ""):
        self.doc = doc

    def _accepts(self, other: PortType) -> bool:
        return isinstance(other, (Json, Model))

    def validate(self, value: Any, where: str) -> Any:
        if isinstance(value, BaseModel):
            value = value.model_dump(mode="json")
        try:
            return json.loads(json.dumps(value, default=_json_default))
        except (TypeError, ValueError) as e:
            raise PortTypeError(f"{where}: value is not JSON-serialisable: {e}") from None

    def save(self, value: Any, path: Path) -> None:
        path.write_text(json.dumps(value, indent=2, default=_json_default))  # key order kept (hashing is canonical)

    def load(self, path: Path) -> Any:
        return json.loads(path.read_text())

    def fingerprint(self, value: Any) -> str:
        return hash_json(value)


class Model(PortType):
    """An instance of a pydantic model class, stored as JSON and re-validated when loaded."""

    suffix = ".json"

    def __init__(self, model: type[BaseModel], doc: str = ""):
        self.model = model
        self.doc = doc

    def describe(self) -> str:
        return f"Model[{self.model.__name__}]"

    def _accepts(self, other: PortType) -> bool:
        return isinstance(other, Model) and issubclass(other.model, self.model)

    def validate(self, value: Any, where: str) -> BaseModel:
        if isinstance(value, self.model):
            return value
        try:
            return self.model.model_validate(value)
        except Exception as e:  # pydantic.ValidationError and friends
            raise PortTypeError(f"{where}: not a valid {self.model.__name__}: {e}") from None

    def save(self, value: BaseModel, path: Path) -> None:
        path.write_text(value.model_dump_json(indent=2))

    def load(self, path: Path) -> BaseModel:
        return self.model.model_validate_json(path.read_text())

    def fingerprint(self, value: BaseModel) -> str:
        return hash_json(value.model_dump(mode="json"))


# ---------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------
class File(PortType):
    """A file on disk, passed as a :class:`pathlib.Path`. Its consumer streams it (a video is never
    loaded whole). ``kind`` is a free label checked for compatibility (``"video"``, ``"bvh"``; ``None``
    accepts any kind); ``suffix`` is the extension used when it is stored (``".mp4"``)."""

    def __init__(self, kind: str | None = None, suffix: str = "", doc: str = ""):
        self.kind = kind
        self.suffix = suffix
        self.doc = doc

    def describe(self) -> str:
        return f"File[{self.kind or 'any'}{', ' + self.suffix if self.suffix else ''}]"

    def _accepts(self, other: PortType) -> bool:
        return isinstance(other, File) and (self.kind is None or other.kind is None or self.kind == other.kind)

    def validate(self, value: Any, where: str) -> Path:
        p = Path(value)
        if not p.is_file():
            raise PortTypeError(f"{where}: expected an existing file, {p} does not exist")
        return p

    def save(self, value: Path, path: Path) -> None:
        shutil.copyfile(value, path)

    def load(self, path: Path) -> Path:
        return path

    def fingerprint(self, value: Path) -> str:
        return hash_file(Path(value))  # the content (the cache memoises it by path, size and mtime)


# ---------------------------------------------------------------------------------------------
# unions
# ---------------------------------------------------------------------------------------------
class AnyOf(PortType):
    """An input that accepts any of several types (the principled alternative to a ``*`` wildcard).
    At run time the value is validated against the options in order; the first that fits wins."""

    def __init__(self, *options: PortType):
        flat: list[PortType] = []
        for o in options:
            flat.extend(o.options if isinstance(o, AnyOf) else [o])
        self.options = tuple(flat)

    def describe(self) -> str:
        return " | ".join(o.describe() for o in self.options)

    def accepts(self, other: PortType) -> bool:
        others: Iterable[PortType] = other.options if isinstance(other, AnyOf) else (other,)
        return all(any(o.accepts(x) for o in self.options) for x in others)

    def _pick(self, value: Any) -> PortType:
        errors = []
        for o in self.options:
            try:
                o.validate(value, "value")
                return o
            except PortTypeError as e:
                errors.append(str(e))
        raise PortTypeError("; ".join(errors))

    def validate(self, value: Any, where: str) -> Any:
        try:
            return self._pick(value).validate(value, where)
        except PortTypeError as e:
            raise PortTypeError(f"{where}: matches none of {self.describe()}: {e}") from None


class AnyType(PortType):
    """Accepts every type. Useful for generic nodes (e.g. a writer); prefer a precise type."""

    def accepts(self, other: PortType) -> bool:
        return True

    def describe(self) -> str:
        return "Any"


def concrete_type_of(declared: PortType, value: Any) -> PortType:
    """The concrete port type used to store/hash ``value`` declared as ``declared`` (resolves unions)."""
    if isinstance(declared, AnyOf):
        return declared._pick(value)
    if isinstance(declared, AnyType):
        if isinstance(value, np.ndarray):
            return Array()
        if isinstance(value, dict) and value and all(isinstance(v, np.ndarray) for v in value.values()):
            return Arrays()
        if isinstance(value, BaseModel):
            return Model(type(value))
        if isinstance(value, Path):
            return File()
        return Json()
    return declared


_TYPE_BY_NAME = {"Array": Array, "Arrays": Arrays, "Json": Json, "File": File}


def storage_type(name: str) -> PortType:
    """A port type from its stored class name (used when loading cache entries of unions / Any)."""
    return _TYPE_BY_NAME[name]()
