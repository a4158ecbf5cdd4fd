"""The one registry of node types. Built-in and third-party nodes register the same way: a package
declares an entry point in the group ``tbha_graph.nodes`` naming a module (or package); every
:class:`NodeSpec` defined at module level there (and, for a package, in its submodules) is registered,
attributed to the distribution that provides it.

Lazily: an entry point's module files are *scanned* (read, not imported) for ``@node("type", ...)``
declarations, giving an index type -> module; a module is imported only when a pipeline names one of
its types, so a run imports only its own nodes. Listing every type (``tbha-graph nodes``, the schema)
imports everything. A type the scan missed (declared some other way) is still found: an unknown name
imports every indexed module before it is reported unknown. ``tests/core/test_registry_lazy.py`` checks
that the scan finds exactly what importing registers.

A plugin that fails to import is reported (``IMPORT FAILED``) and the others still load. Two nodes
claiming one type name is an error naming both packages.
"""
from __future__ import annotations

import importlib
import importlib.metadata as md
import importlib.util
import pkgutil
import re
import threading
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from .errors import RegistryError, did_you_mean
from .node import NodeSpec

ENTRY_POINT_GROUP = "tbha_graph.nodes"


@dataclass
class ImportFailure:
    """A plugin module that could not be imported, or a conflict between two plugins."""

    source: str
    module: str
    error: str

    def __str__(self) -> str:
        return f"IMPORT FAILED: {self.module} (from {self.source}): {self.error}"


#: ``@node("stage.name"`` at the start of a line (the declarations :func:`scan_nodes` indexes)
_DECL = re.compile(r"""^@node\(\s*["']([a-z][a-z0-9_]*(?:\.[a-z][a-z0-9_]*)+)["']""", re.M)


def _module_files(module: str) -> list[tuple[str, Path]]:
    """``(module name, file)`` of ``module`` and, for a package, of its submodules (as
    :func:`pkgutil.walk_packages` finds them), located without importing them."""
    spec = importlib.util.find_spec(module)  # imports the parent packages only
    if spec is None:
        raise ImportError(f"no module named {module!r}")
    if spec.submodule_search_locations is None:
        return [(module, Path(spec.origin))] if spec.origin and spec.origin.endswith(".py") else []
    out: list[tuple[str, Path]] = []

    def walk(name: str, folder: Path) -> None:
        init = folder / "__init__.py"
        if init.is_file():
            out.append((name, init))
        for f in sorted(folder.iterdir()):
            if f.suffix == ".py" and f.name != "__init__.py" and f.stem.isidentifier():
                out.append((f"{name}.{f.stem}", f))
            elif f.is_dir() and (f / "__init__.py").is_file() and f.name.isidentifier():
                walk(f"{name}.{f.name}", f)

    for loc in spec.submodule_search_locations:
        walk(module, Path(loc))
    return out


def scan_nodes(module: str) -> dict[str, list[str]]:
    """``{node type: [modules declaring it]}`` for ``module`` and its submodules, from their source text."""
    found: dict[str, list[str]] = {}
    for name, f in _module_files(module):
        try:
            text = f.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            continue
        if "@node(" not in text:
            continue
        for m in _DECL.finditer(text):
            found.setdefault(m.group(1), []).append(name)
    return found


class Registry:
    """Node types by name."""

    def __init__(self) -> None:
        self._specs: dict[str, NodeSpec] = {}
        self._conflicts: dict[str, str] = {}
        self.failures: list[ImportFailure] = []
        self._index: dict[str, tuple[str, str]] = {}  # type -> (module, source) not imported yet
        self._lazy: list[tuple[str, str]] = []  # (module or package, source) indexed lazily

    # --- registration -----------------------------------------------------------------------
    def add(self, spec: NodeSpec, source: str = "<python>") -> NodeSpec:
        """Register one node type; ``source`` names the package providing it."""
        if not isinstance(spec, NodeSpec):
            raise RegistryError(f"{spec!r} is not a node (declare it with @node)")
        if not spec.source:
            spec.source = source
        old = self._specs.get(spec.type)
        pending = self._index.get(spec.type)
        if pending is not None and pending[0] != spec.module and old is None:
            msg = (
                f"node type '{spec.type}' is declared twice: by package '{pending[1]}' ({pending[0]}) "
                f"and by package '{spec.source}' ({spec.module})"
            )
            self._conflicts[spec.type] = msg
            raise RegistryError(msg, hint="uninstall one of the two packages or rename one node type")
        if old is not None and old is not spec:
            msg = (
                f"node type '{spec.type}' is declared twice: by package '{old.source}' ({old.module}) "
                f"and by package '{spec.source}' ({spec.module})"
            )
            self._conflicts[spec.type] = msg
            raise RegistryError(msg, hint="uninstall one of the two packages or rename one node type")
        self._specs[spec.type] = spec
        return spec

    def add_module(self, module: ModuleType | str, source: str = "<python>") -> list[NodeSpec]:
        """Register every NodeSpec defined in ``module`` (and in all submodules if it is a package).

        Submodules that fail to import are recorded in :attr:`failures`; the rest still register."""
        if isinstance(module, str):
            module = importlib.import_module(module)
        found: list[NodeSpec] = []
        modules = [module]
        if hasattr(module, "__path__"):
            for info in pkgutil.walk_packages(module.__path__, module.__name__ + "."):
                try:
                    modules.append(importlib.import_module(info.name))
                except Exception as e:  # noqa: BLE001 - a broken module must not block the others
                    self.failures.append(ImportFailure(source, info.name, f"{type(e).__name__}: {e}"))
        for mod in modules:
            for value in list(vars(mod).values()):
                if isinstance(value, NodeSpec) and value.module == mod.__name__:
                    try:
                        found.append(self.add(value, source))
                    except RegistryError as e:
                        self.failures.append(ImportFailure(source, mod.__name__, e.message))
        return found

    def add_lazy(self, module: str, source: str = "<python>") -> list[str]:
        """Index the node types declared in ``module`` (and its submodules) without importing them; each
        module is imported when one of its types is first looked up. Returns the indexed types."""
        found = scan_nodes(module)
        for t, mods in found.items():
            owners = {(m, source) for m in mods}
            if t in self._index:
                owners.add(self._index[t])
            if t in self._specs:
                owners.add((self._specs[t].module, self._specs[t].source))
            if len({m for m, _ in owners}) > 1:  # two modules (the same one indexed twice is no conflict)
                (m1, s1), (m2, s2) = sorted(dict(owners).items())[:2]
                self._conflicts[t] = (f"node type '{t}' is declared twice: by package '{s1}' ({m1}) "
                                      f"and by package '{s2}' ({m2})")
                self.failures.append(ImportFailure(source, module, self._conflicts[t]))
                continue
            if t not in self._specs:
                self._index[t] = (mods[0], source)
        self._lazy.append((module, source))
        return sorted(found)

    def _import_indexed(self, module: str, source: str) -> None:
        """Import one indexed module and register its nodes (an import failure is recorded)."""
        for t in [t for t, (m, _) in self._index.items() if m == module]:
            del self._index[t]
        try:
            mod = importlib.import_module(module)
        except Exception as e:  # noqa: BLE001 - a broken module must not block the others
            self.failures.append(ImportFailure(source, module, f"{type(e).__name__}: {e}"))
            return
        for value in list(vars(mod).values()):
            if isinstance(value, NodeSpec) and value.module == mod.__name__ and value.type not in self._conflicts:
                try:
                    self.add(value, source)
                except RegistryError as e:
                    self.failures.append(ImportFailure(source, mod.__name__, e.message))

    def load_all(self) -> None:
        """Import every lazily indexed module (listing all types needs them; so does an unknown name)."""
        lazy, self._lazy = self._lazy, []
        for module, source in lazy:
            self._index = {t: v for t, v in self._index.items() if v[0] != module and not v[0].startswith(module + ".")}
            self.add_module(module, source)

    def load_entry_points(self, group: str = ENTRY_POINT_GROUP, lazy: bool = True) -> None:
        """Register every plugin of the entry-point group (``lazy``: index its modules, import them when
        used); failures are recorded, never raised."""
        for ep in md.entry_points(group=group):
            source = ep.dist.name if ep.dist is not None else ep.name
            if lazy and not ep.attr:
                try:
                    self.add_lazy(ep.module, source)
                    continue
                except Exception:  # noqa: BLE001 - cannot be scanned (no source files): import it now
                    pass
            try:
                target = ep.load()
            except Exception as e:  # noqa: BLE001
                self.failures.append(ImportFailure(source, ep.value, f"{type(e).__name__}: {e}"))
                continue
            if isinstance(target, ModuleType):
                self.add_module(target, source)
            elif isinstance(target, NodeSpec):
                try:
                    self.add(target, source)
                except RegistryError as e:
                    self.failures.append(ImportFailure(source, ep.value, e.message))
            else:
                self.failures.append(ImportFailure(source, ep.value, "entry point is neither a module nor a node"))

    # --- lookup -------------------------------------------------------------------------------
    def get(self, type_name: str) -> NodeSpec:
        if type_name in self._conflicts:
            raise RegistryError(self._conflicts[type_name])
        spec = self._specs.get(type_name)
        if spec is not None:
            return spec
        pending = self._index.get(type_name)
        if pending is not None:
            self._import_indexed(*pending)
            if type_name in self._conflicts:
                raise RegistryError(self._conflicts[type_name])
            spec = self._specs.get(type_name)
            if spec is not None:
                return spec
        if self._lazy:  # not (or wrongly) indexed: import everything before calling it unknown
            self.load_all()
            return self.get(type_name)
        raise RegistryError(
            f"unknown node type '{type_name}'{did_you_mean(type_name, self._specs)}",
            hint="`tbha-graph nodes` lists the installed node types",
        )

    def __contains__(self, type_name: str) -> bool:
        return type_name in self._specs or type_name in self._index

    def types(self) -> list[str]:
        self.load_all()
        return sorted(self._specs)

    def specs(self) -> list[NodeSpec]:
        return [self._specs[t] for t in self.types()]

    def loaded_modules(self) -> list[str]:
        """Modules whose nodes are registered so far (lazily indexed ones only once used)."""
        return sorted({s.module for s in self._specs.values()})


_default: Registry | None = None
_lock = threading.Lock()


def default_registry() -> Registry:
    """The process-wide registry, loaded from the installed entry points on first use."""
    global _default
    with _lock:
        if _default is None:
            reg = Registry()
            reg.load_entry_points()
            _default = reg
        return _default


def load_plugin_modules(names: list[str], registry: Registry | None = None) -> None:
    """Register nodes from extra importable modules (``--plugin mymodule`` on the command line)."""
    reg = registry or default_registry()
    for name in names:
        try:
            reg.add_module(name, source=name)
        except ImportError as e:
            raise RegistryError(f"cannot import plugin module '{name}': {e}", hint="is it installed / on PYTHONPATH?") from None
