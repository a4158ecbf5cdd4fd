from __future__ import annotations

import contextlib
import warnings

import pytest


@pytest.fixture
def no_hidden_warnings(monkeypatch):
    """A context manager: inside it every warning is an error and ``warnings.catch_warnings`` may not be
    entered, so the code run there must emit no warning rather than hide one. ``catch_warnings`` swaps the
    process-wide filter list (not thread-safe before Python 3.14), and nodes run in threads under
    ``tbha-run --jobs``."""

    def refuse(*args, **kwargs):
        raise AssertionError("warnings.catch_warnings entered: process-wide state, not thread-safe")

    @contextlib.contextmanager
    def strict():
        with warnings.catch_warnings(), monkeypatch.context() as mp:
            warnings.simplefilter("error")
            mp.setattr(warnings, "catch_warnings", refuse)
            yield

    return strict
