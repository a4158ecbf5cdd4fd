"""Small nodes for testing the framework core (no mocap knowledge). Importable by Dask workers."""
from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from tbha_graph.core import AnyOf, Array, File, InputPath, Json, NodeError, node, optional


class SourceParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    n: int = Field(4, ge=1, description="number of samples")
    value: float = Field(1.0, description="value of every sample", json_schema_extra={"unit": "m"})


@node("test.source", version=1, outputs={"x": Array("float64", ("n",))}, params=SourceParams)
def source(ctx):
    """A constant array of n samples."""
    return np.full(ctx.params.n, ctx.params.value)


class ScaleParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    factor: float = Field(2.0, description="multiplier")
    sleep: float = Field(0.0, ge=0, description="seconds to sleep (to test parallelism)")


@node("test.scale", inputs={"x": Array("float", ("n",))}, outputs={"y": Array("float64", ("n",))}, params=ScaleParams)
def scale(ctx, x):
    """Multiply by a factor."""
    if ctx.params.sleep:
        time.sleep(ctx.params.sleep)
    return {"y": x * ctx.params.factor}


@node("test.add", inputs={"a": Array("float", ("n",)), "b": optional(Array("float", ("n",)))}, outputs={"y": Array("float64", ("n",))})
def add(ctx, a, b):
    """a + b (b optional)."""
    return a + (b if b is not None else 0.0)


@node("test.metrics", inputs={"x": AnyOf(Array("float"), Json())}, outputs={"metrics": Json()})
def metrics(ctx, x):
    """Figures of an array (mean, n)."""
    x = np.asarray(x, dtype=float)
    return {"mean": float(x.mean()), "n": int(x.size), "frames": int(x.size)}


@node("test.to_text", inputs={"x": Array("float")}, outputs={"text": File(kind="text", suffix=".txt")})
def to_text(ctx, x):
    """Write the array as text to a file."""
    p = ctx.output_path("x.txt")
    p.write_text(" ".join(f"{v:g}" for v in x))
    return p


class ReadParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    path: InputPath = Field(description="a text file of numbers")


@node("test.read_numbers", outputs={"x": Array("float64", ("n",))}, params=ReadParams)
def read_numbers(ctx):
    """Read whitespace-separated numbers from a file."""
    text = Path(ctx.params.path).read_text().split()
    if not text:
        raise NodeError(f"{ctx.params.path} holds no numbers", hint="write some numbers into it")
    return np.array([float(t) for t in text])


class FailParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    bug: bool = False


@node("test.fail", inputs={"x": Array("float")}, outputs={"y": Array("float")}, params=FailParams)
def fail(ctx, x):
    """Always fails: with a NodeError, or with a bug (ZeroDivisionError)."""
    if ctx.params.bug:
        return 1 / 0
    raise NodeError("input frame 3 is unreadable", hint="re-export the file")


@node("test.bad_output", outputs={"y": Array("float", (None, 3))})
def bad_output(ctx):
    """Returns an array of the wrong shape."""
    return np.zeros((4, 2))


class CountParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    counter: str = Field(description="file whose line count records invocations")
    factor: float = 1.0


@node("test.counted", inputs={"x": Array("float")}, outputs={"y": Array("float64")}, params=CountParams)
def counted(ctx, x):
    """Scale and append a line to a counter file (to count real invocations across processes)."""
    with open(ctx.params.counter, "a") as f:
        f.write(f"{os.getpid()}\n")
    return x * ctx.params.factor


@node("test.frames", inputs={"x": Array("float")}, outputs={"y": Array("float64")})
def frames(ctx, x):
    """Iterates over samples with progress reporting."""
    out = [v + 1 for v in ctx.progress(list(x), total=len(x), desc="samples")]
    return np.array(out, dtype=np.float64)


class IntervalParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    log: str = Field(description="file to append 'start end pid' to")
    sleep: float = 0.5
    factor: float = 1.0


@node("test.interval", inputs={"x": Array("float")}, outputs={"y": Array("float64")}, params=IntervalParams)
def interval(ctx, x):
    """Sleep, recording when it ran and in which process (to observe parallelism)."""
    t0 = time.time()
    time.sleep(ctx.params.sleep)
    with open(ctx.params.log, "a") as f:
        f.write(f"{t0} {time.time()} {os.getpid()}\n")
    return x * ctx.params.factor


class MeetParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    group: str = Field(description="nodes of one group wait for each other")
    parties: int = Field(2, ge=1, description="nodes in the group")
    timeout: float = Field(5.0, gt=0, description="seconds to wait for the others")
    warn: str = Field("", description="a warning to give (empty: none)")
    after: float = Field(0.0, ge=0, description="seconds to sleep after the meeting (to end after the others)")
    factor: float = 1.0


_MEETINGS: dict[str, "threading.Barrier"] = {}
_MEETINGS_LOCK = threading.Lock()


@node("test.meet", inputs={"x": Array("float")}, outputs={"y": Array("float64")}, params=MeetParams)
def meet(ctx, x):
    """Wait until every node of its group has started (a threading.Barrier): the run passes only when those nodes
    run at the same time; one after another, the first waits ``timeout`` and fails."""
    p = ctx.params
    with _MEETINGS_LOCK:
        barrier = _MEETINGS.setdefault(p.group, threading.Barrier(p.parties))
    try:
        barrier.wait(timeout=p.timeout)
    except threading.BrokenBarrierError:
        raise NodeError(f"the other nodes of group '{p.group}' did not start within {p.timeout} s") from None
    time.sleep(p.after)
    if p.warn:
        ctx.warn(p.warn)
    return x * p.factor


class StepsParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    log: str = Field(description="file to append each finished step's number to")
    steps: int = 200
    sleep: float = 0.02


@node("test.steps", inputs={"x": Array("float")}, outputs={"y": Array("float64")}, params=StepsParams)
def steps(ctx, x):
    """Many slow steps through ``ctx.progress``, each logged as it ends (to see where an interrupted run stopped)."""
    p = ctx.params
    with open(p.log, "a") as f:
        for k in ctx.progress(range(p.steps), total=p.steps, desc="steps"):
            time.sleep(p.sleep)
            f.write(f"{k}\n")
            f.flush()
    return x * 1.0


#: a small pipeline of these nodes (src -> double, triple -> sum -> stats), shared by the framework's tests
CHAIN = """
description: a small chain
nodes:
  src:
    type: test.source
    params: {n: 5, value: 2.0}
  double:
    type: test.scale
    inputs: {x: src.x}
    params: {factor: 2}
  triple:
    type: test.scale
    inputs: {x: src.x}
    params: {factor: 3}
  sum:
    type: test.add
    inputs: {a: double.y, b: triple.y}
  stats:
    type: test.metrics
    inputs: {x: sum.y}
outputs:
  sum.npz: sum.y
  metrics.json: stats.metrics
"""
