"""Fuzzing the SMPL model readers: the restricted pickle reader of the converter
(``tbha_graph.mocap.smpl.convert.read_smpl_pickle``) and the ``.npz`` loader of the pipeline
(``tbha_graph.mocap.smpl.model.load_model``). For the pickle reader: a
damaged pickle must be refused with a ``NodeError`` naming the file, never run anything, never raise
another exception or hang; one that is accepted is a well-formed model (a pickle has no checksum, so
damaged numbers inside an array cannot be told from other numbers by any reader).

Base: a one-vertex model in the official SMPL layout (numpy arrays, a scipy ``csc_matrix`` joint
regressor, extra keys), pickled with protocol 2 like the official Python 2 files. While a case is read,
an audit hook records any attempt to start a process, run code, touch the network or change files.
For the ``.npz`` loader (base: the same model, dense, ``np.savez``): a ``NodeError`` naming the file, or
a model whose arrays are the intact file's (an npz has CRCs: damage must not pass silently).
"""
from __future__ import annotations

import io
import pickle
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzzlib import CASES, assert_names_file, case, fuzz_settings, mutated, time_limit
from tbha_graph.mocap.smpl.convert import read_smpl_pickle
from tbha_graph.mocap.smpl.kintree import N_POSE_FEATURES, N_SMPL_JOINTS, SMPL_PARENTS
from tbha_graph.mocap.smpl.model import load_model

scipy_sparse = pytest.importorskip("scipy.sparse")

# ('compile' is not listed: numpy parses dtype descriptions with ast.literal_eval, which compiles, never runs)
_FORBIDDEN = ("os.system", "os.exec", "os.posix_spawn", "os.spawn", "os.fork", "subprocess.Popen", "exec",
              "socket.", "os.remove", "os.unlink", "os.rename", "os.rmdir", "shutil.", "os.chmod", "ctypes.")
_SEEN: list[str] = []
_WATCH = [False]


def _audit(event: str, args) -> None:
    if _WATCH[0] and event.startswith(_FORBIDDEN):
        code = args[0] if event == "exec" and args else None
        if code is not None and str(getattr(code, "co_filename", "")).endswith(".py"):
            return  # a library module imported lazily (importlib runs its code with exec), not code from the file
        _SEEN.append(f"{event} {getattr(code, 'co_filename', '')}".strip())


sys.addaudithook(_audit)  # cannot be removed; it only records while _WATCH[0] is set


def _model() -> dict:
    rng = np.random.default_rng(3)
    return {
        "v_template": rng.normal(0, 0.5, (1, 3)),
        "shapedirs": rng.normal(0, 0.01, (1, 3, 10)),
        "posedirs": rng.normal(0, 0.01, (1, 3, N_POSE_FEATURES)),
        "J_regressor": scipy_sparse.csc_matrix(np.ones((N_SMPL_JOINTS, 1))),
        "weights": np.full((1, N_SMPL_JOINTS), 1.0 / N_SMPL_JOINTS),
        "kintree_table": np.stack([np.where(SMPL_PARENTS < 0, 2**32 - 1, SMPL_PARENTS), np.arange(N_SMPL_JOINTS)]).astype(np.int64),
        "f": np.zeros((2, 3), dtype=np.uint32),
        "bs_style": "lbs", "vert_sym_idxs": np.arange(3),
    }


MODEL = _model()
BASE = pickle.dumps(MODEL, protocol=2)
DENSE = {k: (v.toarray() if hasattr(v, "toarray") else v) for k, v in MODEL.items()}


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz_smpl")


def check_pickle(raw: bytes, work: Path) -> None:
    path = work / "model.pkl"
    path.write_bytes(raw)
    _SEEN.clear()
    _WATCH[0] = True
    try:
        with time_limit(what="read_smpl_pickle"):
            try:
                arrays = read_smpl_pickle(path)
            except Exception as e:  # noqa: BLE001
                _WATCH[0] = False
                assert_names_file(e, path, need_line=False)
                arrays = None
    finally:
        _WATCH[0] = False
    assert not _SEEN, f"reading the pickle triggered {_SEEN}"
    if arrays is None:
        return
    # a pickle carries no checksum: a damaged number inside an array's bytes is a valid pickle of other
    # numbers, which no reader can tell; what is accepted must still be a well-formed model
    for k, v in arrays.items():
        assert np.shape(v) == np.shape(DENSE[k]) and np.isfinite(v).all(), f"array {k!r}: {np.shape(v)}"


def test_intact_model_reads(work) -> None:
    check_pickle(BASE, work)
    arrays = read_smpl_pickle(work / "model.pkl")
    assert np.array_equal(arrays["J_regressor"], DENSE["J_regressor"])


def _with(**changes) -> bytes:
    return pickle.dumps({**MODEL, **changes}, protocol=2)


def _bad_index_regressor():
    m = scipy_sparse.csc_matrix(np.ones((N_SMPL_JOINTS, 1)))
    m.indices[11] = 655371  # one damaged byte of the pickle did this
    return m


# Cases the fuzzer found (kept as explicit examples). A csc_matrix whose stored row index is out of range
# was built unchecked and toarray() wrote out of bounds: the Python process died (segfault).
FOUND = [
    case(BASE.replace(b"csc_matrix", b"csc_matrij", 1), "an unknown class name"),
    case(_with(weights=[[1.0, 2.0], [3.0]]), "a ragged list as an array"),
    case(_with(f=np.array(["a", "b"])), "strings as an array"),
]


def test_found_huge_memo_index_does_not_allocate_gigabytes(tmp_path) -> None:
    """A damaged LONG_BINPUT index (4 bytes) made the C unpickler grow its memo array to that index:
    this 10-byte pickle took 3.1 GB of memory and seconds. Peak memory of a child process, not time."""
    import subprocess

    path = tmp_path / "model.pkl"
    path.write_bytes(b"\x80\x02}r\xaf\x92G\x0c.")  # PROTO 2, EMPTY_DICT, LONG_BINPUT 205,000,111, STOP
    code = ("import resource, sys\nfrom tbha_graph.mocap.smpl.convert import read_smpl_pickle\n"
            "from tbha_graph.core.errors import NodeError\nbefore = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
            "try:\n    read_smpl_pickle(sys.argv[1])\nexcept NodeError as e:\n    print(e.format())\n"
            "print('grew_kb', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before)\n")
    proc = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert str(path) in proc.stdout and "missing array" in proc.stdout
    grew_mb = int(proc.stdout.rsplit("grew_kb", 1)[1]) / 1024
    assert grew_mb < 200, f"reading a 10-byte pickle grew the process by {grew_mb:.0f} MB"


def test_found_out_of_range_sparse_index_does_not_crash(tmp_path) -> None:
    """Run in a child process: before the fix it died with SIGSEGV, which would take pytest with it."""
    import subprocess

    path = tmp_path / "model.pkl"
    path.write_bytes(_with(J_regressor=_bad_index_regressor()))
    code = ("import sys\nfrom tbha_graph.mocap.smpl.convert import read_smpl_pickle\nfrom tbha_graph.core.errors import NodeError\n"
            "try:\n    read_smpl_pickle(sys.argv[1])\nexcept NodeError as e:\n    print(e.format())\n    sys.exit(3)\n")
    proc = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 3, f"exit {proc.returncode}: {proc.stderr[-1500:]}"
    assert str(path) in proc.stdout and "J_regressor" in proc.stdout


@pytest.mark.parametrize("raw", FOUND, ids=lambda c: c.what[0])
def test_found_cases(raw, work) -> None:
    check_pickle(raw, work)


@given(data=st.data())
@fuzz_settings(max_examples=120)
def test_fuzz_smpl_pickle(work, data) -> None:
    CASES["smpl pickle"] += 1
    raw = data.draw(st.one_of(
        mutated(BASE, (b"cos\nsystem\n", b"c__builtin__\neval\n", b"R", b"b", b"(", b"t")),
        st.tuples(st.integers(0, len(BASE) - 1), st.binary(min_size=1, max_size=16)).map(
            lambda t: BASE[: t[0]] + t[1] + BASE[t[0] + len(t[1]):]),
    ), label="damaged pickle")
    check_pickle(raw, work)


# --- the .npz model loader ------------------------------------------------------------------------------
def _npz(arrays: dict) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **{k: v for k, v in arrays.items() if isinstance(v, np.ndarray) and k != "vert_sym_idxs"})
    return buf.getvalue()


NPZ = _npz(DENSE)


def check_npz(raw: bytes, work: Path) -> None:
    path = work / "model.npz"
    path.write_bytes(raw)
    with time_limit(what="load_model"):
        try:
            model = load_model(path)
        except Exception as e:  # noqa: BLE001
            assert_names_file(e, path, need_line=False)
            return
    for name, key in (("v_template", "v_template"), ("shapedirs", "shapedirs"), ("posedirs", "posedirs"),
                      ("J_regressor", "J_regressor"), ("weights", "weights")):
        assert np.array_equal(getattr(model, name), DENSE[key]), f"{name} is not the intact file's"


def test_found_npz_header_declaring_a_smaller_dtype(work) -> None:
    """posedirs (5 kB, more than zipfile's 4 kB read chunk) with '<f4' in its header: numpy read half the
    member, the CRC was never checked, and the model loaded with garbage pose blend shapes."""
    i = NPZ.index(b"<f8", NPZ.index(b"posedirs.npy"))
    check_npz(NPZ[:i] + b"<f4" + NPZ[i + 3:], work)


@given(data=st.data())
@fuzz_settings(max_examples=60)
def test_fuzz_smpl_npz(work, data) -> None:
    CASES["smpl model npz"] += 1
    raw = data.draw(st.one_of(
        mutated(NPZ),
        st.tuples(st.integers(0, len(NPZ) - 1), st.binary(min_size=1, max_size=16)).map(
            lambda t: NPZ[: t[0]] + t[1] + NPZ[t[0] + len(t[1]):]),
    ), label="damaged npz")
    check_npz(raw, work)
