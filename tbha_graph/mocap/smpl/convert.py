"""Convert the official SMPL model file (a Python 2 pickle) to the ``.npz`` the pipeline loads.

    python -m tbha_graph.mocap.smpl.convert basicmodel_neutral_lbs_10_207_0_v1.1.0.pkl smpl_neutral.npz

Unpickling can run any code the file's author chose, so this reads the pickle with a *restricted*
unpickler: it resolves only the classes an SMPL file needs and refuses everything else (naming the class):

* numpy arrays and dtypes (``numpy.core.multiarray._reconstruct``, ``numpy.ndarray``, ``numpy.dtype``,
  numpy scalars);
* scipy's ``csc_matrix`` (the joint regressor), rebuilt from its data / indices / indptr arrays by this module;
* chumpy ``Ch`` arrays (``shapedirs``, sometimes ``v_template`` / ``posedirs``), rebuilt as plain arrays from
  their stored value - chumpy itself is never imported;
* plain containers (dict, list, tuple, set), Python 2's ``copy_reg._reconstructor`` for old-style objects and
  ``_codecs.encode`` (bytes in protocol 0-2 pickles written by Python 3).

Only the model arrays are kept (:data:`tbha_graph.mocap.smpl.model.REQUIRED_KEYS`), checked for shape and
the SMPL tree, and written atomically. The pipeline itself never reads a pickle.
"""
from __future__ import annotations

import _compat_pickle
import argparse
import io
import pickle
import sys
from pathlib import Path

import numpy as np

from ...core.errors import NodeError
from .model import REQUIRED_KEYS, check_model_arrays, save_model_npz

WARNING = (
    "warning: reading a pickle. The restricted unpickler only builds numpy arrays, scipy csc matrices and "
    "chumpy arrays (as plain arrays) and refuses any other class, but convert only files from the official "
    "SMPL website. The SMPL model is licensed (https://smpl.is.tue.mpg.de): do not redistribute the .npz."
)


class _Stub:
    """Holds the pickled state of an object whose class we do not import."""

    kind = "object"

    def __init__(self, *args, **kwargs):
        self.args = args
        self.state = None

    def __setstate__(self, state):
        self.state = state

    def value(self) -> np.ndarray:  # pragma: no cover - overridden
        raise NotImplementedError


class _ChumpyArray(_Stub):
    """A chumpy ``Ch``: its value is the ``x`` entry of its state."""

    kind = "chumpy.ch.Ch"

    def value(self) -> np.ndarray:
        state = self.state if isinstance(self.state, dict) else {}
        x = state.get("x")
        if isinstance(x, _Stub):
            x = x.value()
        if not isinstance(x, np.ndarray):
            raise NodeError("a chumpy array in the file holds no plain value 'x' (a computed chumpy expression)",
                            hint="re-export the model with its arrays evaluated (np.array(model[key]))")
        return x


class _CscMatrix(_Stub):
    """A scipy ``csc_matrix``: rebuilt from its arrays (``data``, ``indices``, ``indptr``, shape)."""

    kind = "scipy.sparse.csc_matrix"

    def value(self) -> np.ndarray:
        from scipy.sparse import csc_matrix

        s = self.state if isinstance(self.state, dict) else {}
        shape = s.get("_shape", s.get("shape"))
        try:
            m = csc_matrix((np.asarray(s["data"]), np.asarray(s["indices"]), np.asarray(s["indptr"])), shape=tuple(shape))
            m.check_format(full_check=True)  # indices within the shape: toarray() of a damaged matrix writes out of bounds (segfault)
        except (KeyError, TypeError, ValueError) as e:
            raise NodeError(f"a sparse matrix in the file cannot be rebuilt: {e}") from None
        return m.toarray()


def _numpy_reconstruct():
    try:
        from numpy._core.multiarray import _reconstruct
    except ImportError:  # numpy < 2
        from numpy.core.multiarray import _reconstruct  # type: ignore[no-redef]
    return _reconstruct


def _numpy_scalar():
    try:
        from numpy._core.multiarray import scalar
    except ImportError:  # numpy < 2
        from numpy.core.multiarray import scalar  # type: ignore[no-redef]
    return scalar


def _allowed() -> dict[tuple[str, str], object]:
    import codecs
    import copyreg

    allowed: dict[tuple[str, str], object] = {
        ("numpy", "ndarray"): np.ndarray,
        ("numpy", "dtype"): np.dtype,
        ("copyreg", "_reconstructor"): copyreg._reconstructor,
        ("builtins", "object"): object,
        ("builtins", "set"): set,
        ("builtins", "frozenset"): frozenset,
        ("builtins", "list"): list,
        ("builtins", "dict"): dict,
        ("builtins", "tuple"): tuple,
        ("_codecs", "encode"): codecs.encode,  # how protocol <= 2 pickles written by Python 3 store bytes
        ("chumpy.ch", "Ch"): _ChumpyArray,
        ("scipy.sparse.csc", "csc_matrix"): _CscMatrix,
        ("scipy.sparse._csc", "csc_matrix"): _CscMatrix,
        ("scipy.sparse", "csc_matrix"): _CscMatrix,
    }
    for mod in ("numpy.core.multiarray", "numpy._core.multiarray"):
        allowed[(mod, "_reconstruct")] = _numpy_reconstruct()
        allowed[(mod, "scalar")] = _numpy_scalar()
    return allowed


class RestrictedUnpickler(pickle._Unpickler):
    """An unpickler that resolves only the classes listed in the module docstring.

    The pure-Python unpickler: its memo is a dict, where the C one grows an array to the largest memo
    index in the file (a damaged 4-byte LONG_BINPUT index made a 10 kB file allocate gigabytes)."""

    def __init__(self, file, source: str = "the file"):
        super().__init__(file, encoding="latin1", fix_imports=True)
        self._allowed = _allowed()
        self._source = source

    def find_class(self, module: str, name: str):
        if (module, name) in _compat_pickle.NAME_MAPPING:  # Python 2 names (protocol <= 2 pickles)
            module, name = _compat_pickle.NAME_MAPPING[(module, name)]
        module = _compat_pickle.IMPORT_MAPPING.get(module, module)
        obj = self._allowed.get((module, name))
        if obj is None:
            raise NodeError(f"{self._source}: refused to load {module}.{name}: an SMPL model file needs only numpy "
                            "arrays, scipy csc matrices and chumpy arrays",
                            hint="this is not an SMPL model pickle, or a variant this converter does not know; "
                                 "never load pickles from unknown sources")
        return obj

    def persistent_load(self, pid):
        raise NodeError(f"{self._source}: refused a persistent object reference in the pickle")


def _plain(value) -> np.ndarray | None:
    if isinstance(value, _Stub):
        return value.value()
    if isinstance(value, np.ndarray):
        return value
    return None


def read_smpl_pickle(path: str | Path) -> dict[str, np.ndarray]:
    """The model arrays of an official SMPL ``.pkl`` (restricted unpickling), checked; NodeError on any problem."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise NodeError(f"cannot read {path}: {e}") from None
    try:
        obj = RestrictedUnpickler(io.BytesIO(data), str(path)).load()
    except NodeError:
        raise
    except Exception as e:  # noqa: BLE001 - any malformed pickle is a user error here
        raise NodeError(f"{path}: not a readable pickle: {type(e).__name__}: {e}") from None
    if not isinstance(obj, dict):
        raise NodeError(f"{path}: expected a dict of model arrays, found {type(obj).__name__}")
    arrays = {}
    for key in REQUIRED_KEYS:
        if key in obj:
            try:
                v = _plain(obj[key])
                v = np.asarray(obj[key] if v is None else v)
            except NodeError as e:
                raise NodeError(f"{path}: {key}: {e.message}", hint=e.hint) from None
            except (TypeError, ValueError) as e:  # e.g. ragged nested lists
                raise NodeError(f"{path}: {key} is not an array: {e}") from None
            if v.dtype.kind not in "biuf":
                raise NodeError(f"{path}: {key} holds {v.dtype} values, not numbers")
            arrays[key] = v
    return check_model_arrays(arrays, str(path))


def convert(src: str | Path, dst: str | Path) -> dict[str, tuple[int, ...]]:
    """Convert ``src`` (.pkl) to ``dst`` (.npz); returns the written arrays' shapes."""
    arrays = read_smpl_pickle(src)
    save_model_npz(arrays, dst)
    return {k: v.shape for k, v in arrays.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="python -m tbha_graph.mocap.smpl.convert",
                                 description="Convert the official SMPL model .pkl to the .npz the pipeline loads.")
    ap.add_argument("src", help="official SMPL model file (.pkl)")
    ap.add_argument("dst", help="output .npz")
    a = ap.parse_args(argv)
    print(WARNING, file=sys.stderr)
    try:
        shapes = convert(a.src, a.dst)
    except NodeError as e:
        print(f"error: {e.format()}", file=sys.stderr)
        return 1
    for k, s in shapes.items():
        print(f"{k}={s}")
    print(f"wrote {a.dst}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
