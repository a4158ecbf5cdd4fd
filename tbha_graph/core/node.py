"""Declaring a node: a typed contract (ports, params, version) around a plain Python function.

A node is declared once, with the :func:`node` decorator::

    class Params(BaseModel):
        sigma: float = Field(1.5, gt=0, description="Gaussian blur", json_schema_extra={"unit": "px"})

    @node("filter.blur", version=1, inputs={"x": Array("float", ("n", 3))},
          outputs={"y": Array("float", ("n", 3))}, params=Params)
    def blur(ctx, x):
        "Blur a signal."
        return {"y": ...}

The function receives a :class:`Context` (``ctx.params`` is the validated params model) and one keyword
argument per input port, and returns a dict with one entry per output port (or the bare value when the
node has exactly one output). The contract is plain data on the returned :class:`NodeSpec`, readable
without running anything (``tbha-graph nodes TYPE`` prints it).

The cache key uses the params as validated. A node whose result depends on more than those values (a
preset filled in unless a param is set explicitly, read from ``model_fields_set``) gives its params model
a method ``effective(self) -> dict`` returning exactly what the result depends on (JSON values); the key
uses that instead, so equivalent settings share a key and different results never do (see
``export.bvh``).
"""
from __future__ import annotations

import builtins
import contextvars
import inspect
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Callable, Iterable, Iterator, Mapping, TypeVar, get_args

from pydantic import BaseModel, ConfigDict

from .errors import RegistryError
from .scratch import remove_at_exit, scratch_folder
from .types import PortType

T = TypeVar("T")

#: Set by the concurrent executor (:func:`.scheduler._run_concurrent`) to an Event it sets on Ctrl-C: a node
#: running in a worker thread then stops at its next :meth:`Context.progress` step (threads cannot be interrupted)
CANCEL: contextvars.ContextVar = contextvars.ContextVar("tbha_cancel", default=None)


class Cancelled(KeyboardInterrupt):
    """The run was interrupted (Ctrl-C) while this node ran in a worker thread: raised at its next progress step."""


def checkpoint() -> None:
    """Raise :class:`Cancelled` if the run this code belongs to was interrupted (Ctrl-C while nodes run in worker
    threads, ``--jobs`` above 1); else nothing (a few hundred nanoseconds). For long computations with no
    ``ctx.progress`` step, such as an optimiser's iterations: call it once per iteration."""
    _raise_if_set(CANCEL.get())


def _raise_if_set(cancel) -> None:
    """Raise :class:`Cancelled` if ``cancel`` (a ``threading.Event`` or None) is set."""
    if cancel is not None and cancel.is_set():
        raise Cancelled("interrupted")


def _cancellable(it: Iterator[T], cancel) -> Iterator[T]:
    """``it``'s items until ``cancel`` (a ``threading.Event``) is set, then :class:`Cancelled`; ``it`` closed either way."""
    try:
        for item in it:
            _raise_if_set(cancel)
            yield item
    finally:
        close = getattr(it, "close", None)
        if close is not None:
            close()


_TYPE_NAME = re.compile(r"^[a-z][a-z0-9_]*(\.[a-z][a-z0-9_]*)+$")


class _FileContent:
    """Marker: a params field whose file *content* is part of the cache key."""

    def __repr__(self) -> str:
        return "FileContent"


FILE_CONTENT = _FileContent()

#: A params field holding the path of an input file (a video, a suit spec, a BVH). Its content hash,
#: not just its path, enters the node's cache key, so editing the file re-runs the node.
InputPath = Annotated[Path, FILE_CONTENT]


def is_input_path_field(annotation: Any, metadata: Iterable[Any] = ()) -> bool:
    """True when a params field is declared with :data:`InputPath` (also inside ``Optional``/unions)."""
    if any(m is FILE_CONTENT for m in metadata):
        return True
    return any(a is FILE_CONTENT or is_input_path_field(a) for a in get_args(annotation))


_path_fields: dict[type, tuple[str, ...]] = {}


def input_path_fields(model: type[BaseModel]) -> tuple[str, ...]:
    """Names of the :data:`InputPath` fields of a params model (memoised per class)."""
    names = _path_fields.get(model)
    if names is None:
        names = tuple(n for n, f in model.model_fields.items() if is_input_path_field(f.annotation, f.metadata))
        _path_fields[model] = names
    return names


class NoParams(BaseModel):
    """A node without parameters."""

    model_config = ConfigDict(extra="forbid")


@dataclass(frozen=True)
class Input:
    """An input port: its type, whether it must be connected, and a description."""

    type: PortType
    required: bool = True
    doc: str = ""


def optional(t: PortType, doc: str = "") -> Input:
    """Declare an input port that may be left unconnected (the function then receives ``None``)."""
    return Input(t, required=False, doc=doc)


@dataclass
class NodeSpec:
    """The declared contract of a node type. ``fn(ctx, **inputs) -> dict[port, value]``."""

    type: str
    fn: Callable[..., Any]
    inputs: dict[str, Input]
    outputs: dict[str, PortType]
    params: type[BaseModel]
    version: int | str
    doc: str
    #: filled in by the registry: the distribution (package) that provided the node
    source: str = field(default="")

    @property
    def summary(self) -> str:
        """First line of the docstring."""
        return (self.doc.strip().splitlines() or [""])[0]

    @property
    def module(self) -> str:
        return getattr(self.fn, "__module__", "")

    def __call__(self, ctx: "Context", **inputs: Any) -> Any:
        return self.fn(ctx, **inputs)

    def __deepcopy__(self, memo: dict) -> "NodeSpec":
        return self  # a declaration is immutable; copying a pipeline never copies its node types


def node(
    type: str,
    *,
    version: int | str = 1,
    inputs: Mapping[str, PortType | Input] | None = None,
    outputs: Mapping[str, PortType] | None = None,
    params: type[BaseModel] = NoParams,
) -> Callable[[Callable[..., Any]], NodeSpec]:
    """Decorator declaring a node type (see module docstring). Returns a :class:`NodeSpec`.

    ``type`` is a dotted lowercase name, ``stage.name`` (e.g. ``"segment.hierarchical"``); ``version``
    must be bumped when the algorithm's results change (it is part of the cache key, together with a
    fingerprint of the code).
    """
    if not _TYPE_NAME.match(type):
        raise RegistryError(
            f"node type {type!r} is not a dotted lowercase name",
            hint="use 'stage.name', e.g. 'segment.hierarchical'",
        )
    if not (isinstance(params, builtins.type) and issubclass(params, BaseModel)):
        raise RegistryError(f"node {type!r}: params must be a pydantic BaseModel class, got {params!r}")
    ins = {k: (v if isinstance(v, Input) else Input(v)) for k, v in (inputs or {}).items()}
    outs = dict(outputs or {})
    for name, p in list(ins.items()) + [(k, v) for k, v in outs.items()]:
        t = p.type if isinstance(p, Input) else p
        if not isinstance(t, PortType):
            raise RegistryError(f"node {type!r}: port {name!r} must be a port type (Array, Json, File, ...), got {t!r}")

    def wrap(fn: Callable[..., Any]) -> NodeSpec:
        sig = inspect.signature(fn)
        names = [p for p in sig.parameters][1:]
        if set(names) != set(ins) and not any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values()):
            raise RegistryError(
                f"node {type!r}: function {fn.__name__}(ctx, {', '.join(names)}) does not take exactly its input ports {sorted(ins)}"
            )
        return NodeSpec(
            type=type,
            fn=fn,
            inputs=ins,
            outputs=outs,
            params=params,
            version=version,
            doc=inspect.getdoc(fn) or "",
        )

    return wrap


class Context:
    """What a running node sees besides its inputs.

    * ``params``: the validated params model instance.
    * ``node_id``: the id of this node in the pipeline.
    * ``work_dir``: a private, empty folder for files the node produces (returned ``File`` outputs
      are moved into the cache from here).
    * ``progress(iterable, total=None, desc="")``: wrap a long loop (e.g. over frames) to report progress
      (and, running beside other nodes, to stop at the next step when the user presses Ctrl-C).
    * ``log(msg)``: a message shown under the node's progress line.
    * ``warn(msg)``: something the user must know about the result (a doubtful calibration, ...). Kept
      with the node's cache entry (a cached run reports it again), listed in ``manifest.json`` and the
      run summary, and added to the run's report output (see :mod:`tbha_graph.core.rundir`).
    """

    def __init__(self, node_id: str, params: BaseModel, work_dir: Path | str | None = None, reporter: Any = None,
                 work_root: Path | str | None = None):
        self.node_id = node_id
        self.params = params
        self._work_dir = work_dir
        self._work_root = work_root  # without work_dir: a fresh folder under it, named when first used
        self._reporter = reporter
        self.warnings: list[str] = []

    @property
    def work_dir(self) -> Path:
        if self._work_dir is None and self._work_root is not None:
            self._work_dir = Path(self._work_root) / f"{self.node_id}-{time.monotonic_ns()}"
        if self._work_dir is None:
            self._work_dir = scratch_folder(f"tbha-{self.node_id}-")  # nothing takes its files: gone at exit
            remove_at_exit(self._work_dir)
        self._work_dir = Path(self._work_dir)
        self._work_dir.mkdir(parents=True, exist_ok=True)
        return self._work_dir

    def output_path(self, name: str) -> Path:
        """A path inside :attr:`work_dir` for a file output called ``name``."""
        return self.work_dir / name

    def progress(self, iterable: Iterable[T], total: int | None = None, desc: str = "") -> Iterator[T]:
        it = iter(iterable) if self._reporter is None else self._reporter.progress(self.node_id, iterable, total=total, desc=desc)
        cancel = CANCEL.get()
        return it if cancel is None else _cancellable(it, cancel)

    def log(self, msg: str) -> None:
        if self._reporter is not None:
            self._reporter.log(self.node_id, msg)

    def warn(self, msg: str) -> None:
        msg = str(msg)
        if msg not in self.warnings:
            self.warnings.append(msg)
