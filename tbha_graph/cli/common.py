"""Shared pieces of the command-line tools: error printing without tracebacks, exit codes."""
from __future__ import annotations

import os
import sys
from typing import Any, Callable

EXIT_OK, EXIT_FAILED, EXIT_USER = 0, 1, 2


def guarded(fn: Callable[[], int]) -> int:
    """Run a CLI body; user errors print as messages (exit 2), node failures exit 1, ^C exits 130. A reader
    that stops early (``tbha-graph schema | head``) ends the output quietly, as for any Unix tool."""
    from ..core.errors import NodeFailed, PipelineErrors, TbhaError  # here: `--help` never gets this far

    try:
        return _quiet_on_broken_pipe(fn)
    except PipelineErrors as e:
        print(f"error: {e.format()}", file=sys.stderr)
        return EXIT_USER
    except NodeFailed as e:
        print(f"error: {e.format()}", file=sys.stderr)
        return EXIT_FAILED
    except TbhaError as e:
        print(f"error: {e.format()}", file=sys.stderr)
        return EXIT_USER
    except RecursionError:
        print("error: the input is nested too deeply to process (a pipeline, suit or body file, or a --set value)", file=sys.stderr)
        return EXIT_USER
    except KeyboardInterrupt:
        print("interrupted; what finished is in the cache, run the same command to resume", file=sys.stderr)
        return 130


def _quiet_on_broken_pipe(fn: Callable[[], int]) -> int:
    try:
        code = fn()
        sys.stdout.flush()
        return code
    except BrokenPipeError:
        # the reader closed the pipe: stop writing; point stdout at /dev/null so the interpreter's final
        # flush does not raise again
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return EXIT_OK


def parse_assignments(items: list[str] | None, what: str) -> dict[str, Any]:
    from ..core.spec import parse_assignment

    out: dict[str, Any] = {}
    for item in items or []:
        k, v = parse_assignment(item, what)
        out[k] = v
    return out


def positive_int(text: str) -> int:
    """argparse type: a whole number of at least 1."""
    import argparse

    try:
        v = int(text)
    except ValueError:
        v = 0
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number of at least 1, not {text!r}")
    return v


JOBS_HELP = "nodes the local executor runs at once (independent branches; default: the pipeline's 'jobs', else 1)"


def add_run_arguments(p) -> None:
    p.add_argument("pipeline", help="pipeline YAML file")
    p.add_argument("--out", "-o", help="run directory (default: runs/<pipeline name>)")
    p.add_argument("--set", "-s", action="append", metavar="NODE.PARAM=VALUE", help="override a param (repeatable)")
    p.add_argument("--var", "-v", action="append", metavar="NAME=VALUE", help="set a pipeline variable (repeatable)")
    p.add_argument("--output", action="append", metavar="NAME", help="produce only these outputs (default: all)")
    p.add_argument("--executor", choices=["local", "dask"], default="local", help="where nodes run (dask: a LocalCluster unless --scheduler)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="address of an existing Dask scheduler (implies --executor dask)")
    p.add_argument("--workers", type=int, help="workers of the LocalCluster (dask executor)")
    p.add_argument("--jobs", "-j", type=positive_int, metavar="N", help=JOBS_HELP)
    p.add_argument("--no-cache", action="store_true", help="run everything, read and write no cache")
    p.add_argument("--cache-dir", help="cache folder (default: $TBHA_CACHE_DIR or the user cache folder)")
    p.add_argument("--plugin", action="append", metavar="MODULE", help="also register the nodes of this importable module")
    p.add_argument("--quiet", "-q", action="store_true", help="print only errors and the summary")
    p.add_argument("--verbose", action="store_true", help="print every figure of metrics.json in the summary (docs/metrics.md explains them)")
