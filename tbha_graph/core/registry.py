"""The one registry of node types. Built-in and third-party nodes register the same way: a package
declares an entry point in the group ``tbha_graph.nodes`` naming a module (or package); every
:class:`NodeSpec` defined at module level there (and, for a package, in its submodules) is registered,
attributed to the distribution that provides it.

A plugin that fails to import is reported (``IMPORT FAILED``) and the others still load. Two nodes
claiming one type name is an error naming both packages.
"""
from __future__ import annotations

import importlib
import importlib.metadata as md
import pkgutil
import threading
from dataclasses import dataclass
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


class Registry:
    """Node types by name."""

    def __init__(self) -> None:
        self._specs: dict[str, NodeSpec] = {}
        self._conflicts: dict[str, str] = {}
        self.failures: list[ImportFailure] = []

    # --- registration -----------------------------------------------------------------------
    def add(self, spec: NodeSpec, source: str = "<python>") -> NodeSpec:
        """Register one node type; ``source`` names the package providing it."""
        if not isinstance(spec, NodeSpec):
            raise RegistryError(f"{spec!r} is not a node (declare it with @node)")
        if not spec.source:
            spec.source = source
        old = self._specs.get(spec.type)
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

    def load_entry_points(self, group: str = ENTRY_POINT_GROUP) -> None:
        """Import every plugin of the entry-point group; failures are recorded, never raised."""
        for ep in md.entry_points(group=group):
            source = ep.dist.name if ep.dist is not None else ep.name
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
        try:
            return self._specs[type_name]
        except KeyError:
            raise RegistryError(
                f"unknown node type '{type_name}'{did_you_mean(type_name, self._specs)}",
                hint="`tbha-graph nodes` lists the installed node types",
            ) from None

    def __contains__(self, type_name: str) -> bool:
        return type_name in self._specs

    def types(self) -> list[str]:
        return sorted(self._specs)

    def specs(self) -> list[NodeSpec]:
        return [self._specs[t] for t in self.types()]


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
