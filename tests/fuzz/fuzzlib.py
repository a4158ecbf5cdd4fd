"""Shared pieces of the fuzz tests: text mutations (a hypothesis strategy), a hang guard, the
user-error property and a count of the cases run (printed at the end of the pytest run).

A mutation turns valid file bytes into a damaged file, the way files are damaged in practice or by
hand-editing: byte and bit flips, deleted/duplicated/swapped lines, truncation, swapped/deleted/
inserted tokens, numbers replaced by odd ones (NaN, inf, huge, empty, hex, underscores), wrong
indentation, junk lines. One to three mutations are applied per case; hypothesis shrinks a failing
case to the fewest, smallest mutations.
"""
from __future__ import annotations

import os
import re
import signal
from collections import Counter
from contextlib import contextmanager
from pathlib import Path

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from tbha_graph.core.errors import TbhaError

#: cases run per fuzz test name (printed by conftest.py at the end of the session)
CASES: Counter[str] = Counter()

#: ``TBHA_FUZZ_SCALE=10`` runs ten times more cases; ``TBHA_FUZZ_RANDOM=1`` draws new cases each run
#: (the default is a fixed, reproducible set so the suite never flakes).
SCALE = float(os.environ.get("TBHA_FUZZ_SCALE", "1"))
RANDOM = os.environ.get("TBHA_FUZZ_RANDOM", "") not in ("", "0")

#: seconds one case may take before it counts as a hang
CASE_TIMEOUT_S = 10.0


def fuzz_settings(max_examples: int) -> settings:
    return settings(
        max_examples=max(1, int(max_examples * SCALE)),
        deadline=None,  # wall-clock deadlines flake on a loaded machine; hangs are caught by time_limit
        database=None,  # no .hypothesis/ folder in the work tree
        derandomize=not RANDOM,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
        print_blob=True,
    )


class Hang(BaseException):
    """A case ran longer than CASE_TIMEOUT_S (BaseException: code under test cannot swallow it)."""


@contextmanager
def time_limit(seconds: float = CASE_TIMEOUT_S, what: str = "case"):
    """Raise :class:`Hang` in the main thread if the block runs longer than ``seconds``."""

    def on_alarm(signum, frame):
        raise Hang(f"{what} still running after {seconds} s: a hang")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    except Hang as e:  # reported as an assertion so hypothesis shrinks and prints the case
        raise AssertionError(str(e)) from None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def assert_names_file(err: BaseException, path: Path, need_line: bool) -> None:
    """The property every rejected input must satisfy: the project's own error type, a message that
    names the file, and (``need_line``) a 1-based line number in its location."""
    assert isinstance(err, TbhaError), f"{type(err).__name__} is not a TbhaError: {err!r}"
    text = str(err)
    assert str(path) in text or path.name in text, f"the message does not name the file {path.name}: {text}"
    if need_line:
        assert err.location is not None and err.location.line > 0, f"no line number in: {text}"


# ---------------------------------------------------------------------------------------------
# mutations
# ---------------------------------------------------------------------------------------------
_NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_TOKEN = re.compile(rb"\S+")
ODD_NUMBERS = [b"nan", b"NaN", b"inf", b"-inf", b"1e309", b"-1e309", b"9" * 40, b"-0", b"0", b"", b"0x1F",
               b"1_000", b"1,5", b"1e", b".", b"-", b"+.5e-3", b"3.4028235e38", b"1e-320", b"\xc2\xb3", b"\xb3",
               b"\xd9\xa1", b"true", b"null", b"~", b"[]", b"{}", b"'1'", b'"1"']
INDENTS = [b"", b" ", b"  ", b"   ", b"\t", b"\t\t", b" \t", b"        "]
JUNK_LINES = [b"", b"   ", b"\t", b"#", b"---", b"...", b"- x", b"? a", b": b", b"{", b"}", b"[", b"&a *a", b"!!python/object:os.system", b"%YAML 1.1",
              b"\x00", b"\xff\xfe", b"\xef\xbb\xbf", b"\r", b"a: b: c", b"<<: *x", b"key: [1, 2", b"'unterminated"]


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True) or [b""]


@st.composite
def _one_mutation(draw, data: bytes, vocab: tuple[bytes, ...]) -> tuple[bytes, str]:
    kind = draw(st.sampled_from(
        ["flip_byte", "flip_bit", "delete_line", "duplicate_line", "swap_lines", "truncate", "swap_tokens",
         "delete_token", "insert_token", "odd_number", "random_number", "reindent", "junk_line"]))
    n = len(data)
    if kind in ("flip_byte", "flip_bit", "truncate") and n == 0:
        kind = "junk_line"
    if kind == "flip_byte":
        i = draw(st.integers(0, n - 1))
        b = draw(st.integers(0, 255))
        return data[:i] + bytes([b]) + data[i + 1:], f"byte {i} -> {b:#04x}"
    if kind == "flip_bit":
        i, bit = draw(st.integers(0, n - 1)), draw(st.integers(0, 7))
        return data[:i] + bytes([data[i] ^ (1 << bit)]) + data[i + 1:], f"bit {bit} of byte {i}"
    if kind == "truncate":
        i = draw(st.integers(0, n - 1))
        return data[:i], f"truncated at byte {i}"
    lines = _lines(data)
    if kind in ("delete_line", "duplicate_line", "reindent", "junk_line", "swap_lines"):
        k = draw(st.integers(0, len(lines) - 1))
        if kind == "delete_line":
            return b"".join(lines[:k] + lines[k + 1:]), f"deleted line {k + 1}"
        if kind == "duplicate_line":
            return b"".join(lines[:k + 1] + lines[k:]), f"duplicated line {k + 1}"
        if kind == "swap_lines":
            j = min(k + 1, len(lines) - 1)
            lines[k], lines[j] = lines[j], lines[k]
            return b"".join(lines), f"swapped lines {k + 1} and {j + 1}"
        if kind == "reindent":
            ind = draw(st.sampled_from(INDENTS))
            lines[k] = ind + lines[k].lstrip(b" \t")
            return b"".join(lines), f"line {k + 1} indented {ind!r}"
        junk = draw(st.one_of(st.sampled_from(JUNK_LINES), st.binary(max_size=12)))
        return b"".join(lines[:k] + [junk + b"\n"] + lines[k:]), f"junk line {junk!r} before line {k + 1}"
    toks = list(_TOKEN.finditer(data))
    nums = list(_NUMBER.finditer(data))
    if kind in ("odd_number", "random_number") and nums:
        m = draw(st.sampled_from(nums))
        if kind == "odd_number":
            new = draw(st.sampled_from(ODD_NUMBERS))
        else:
            x = draw(st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True)))
            new = repr(x).encode()
        return data[:m.start()] + new + data[m.end():], f"number {m.group()!r} at {m.start()} -> {new!r}"
    if not toks:
        return data + b"\n", "newline appended"
    if kind == "swap_tokens":
        a, b = sorted(draw(st.lists(st.sampled_from(toks), min_size=2, max_size=2)), key=lambda m: m.start())
        if a.start() == b.start():
            return data, "no-op swap"
        out = data[:a.start()] + b.group() + data[a.end():b.start()] + a.group() + data[b.end():]
        return out, f"swapped {a.group()!r}@{a.start()} and {b.group()!r}@{b.start()}"
    m = draw(st.sampled_from(toks))
    if kind == "delete_token":
        return data[:m.start()] + data[m.end():], f"deleted {m.group()!r}@{m.start()}"
    word = draw(st.sampled_from(vocab)) if vocab else m.group()
    return data[:m.start()] + word + b" " + data[m.start():], f"inserted {word!r}@{m.start()}"


class Mutated(bytes):
    """Mutated file bytes that print as the list of mutations (a failing case stays readable)."""

    what: list[str]

    def __repr__(self) -> str:
        return f"Mutated({'; '.join(self.what)}; {len(self)} bytes)"


def case(data: bytes, what: str) -> Mutated:
    """A hand-written case (for ``@example``)."""
    m = Mutated(data)
    m.what = [what]
    return m


@st.composite
def mutated(draw, data: bytes, vocab: tuple[bytes, ...] = (), max_mutations: int = 3) -> Mutated:
    """Strategy: ``data`` after 1..``max_mutations`` random mutations (``.what`` describes each)."""
    done = []
    for _ in range(draw(st.integers(1, max_mutations))):
        data, what = draw(_one_mutation(data, vocab))
        done.append(what)
    out = Mutated(data)
    out.what = done
    return out


def vocabulary(data: bytes) -> tuple[bytes, ...]:
    """The distinct words of a file (inserted elsewhere by ``insert_token``)."""
    return tuple(sorted({m.group() for m in _TOKEN.finditer(data) if not _NUMBER.fullmatch(m.group())}))
