"""Test-only plugin (``tbha-run --plugin fault_nodes``) for the SIGKILL fault test: places where a run
announces that it has got somewhere, so the test can kill it there instead of at a guessed moment.

With ``$TBHA_FAULT_MARKERS`` set to a folder:

* ``fault.pause_motion`` / ``fault.pause_rotations`` write ``<label>.started`` there when they start
  running, then pause ``$TBHA_FAULT_PAUSE`` seconds (default 0.5) and pass their bundle on unchanged;
* every cache store writes ``store-<i>.started`` (i = 0, 1, ... in store order) after the entry's
  payload files are written and before its ``meta.json`` and rename, then pauses as long.

Without ``$TBHA_FAULT_MARKERS`` the nodes only pass their input on (the reference run).
"""
from __future__ import annotations

import itertools
import os
import time
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from tbha_graph.core.cache import Cache
from tbha_graph.core.node import node
from tbha_graph.mocap.ports import MOTION, ROTATIONS

MARKERS = os.environ.get("TBHA_FAULT_MARKERS")
PAUSE = float(os.environ.get("TBHA_FAULT_PAUSE", "0.5"))


def mark(name: str) -> None:
    """Announce ``name`` (a file in the markers folder) and pause, when markers are on."""
    if MARKERS:
        Path(MARKERS, name).write_text(f"{os.getpid()}\n")
        time.sleep(PAUSE)


class PauseParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    label: str = Field(description="marker name: <label>.started")


@node("fault.pause_motion", version=1, inputs={"motion": MOTION}, outputs={"motion": MOTION}, params=PauseParams)
def pause_motion(ctx, motion):
    """Mark that the node started, pause, and pass the motion on unchanged."""
    mark(f"{ctx.params.label}.started")
    return {"motion": motion}


@node("fault.pause_rotations", version=1, inputs={"rotations": ROTATIONS}, outputs={"rotations": ROTATIONS}, params=PauseParams)
def pause_rotations(ctx, rotations):
    """Mark that the node started, pause, and pass the rotations on unchanged."""
    mark(f"{ctx.params.label}.started")
    return {"rotations": rotations}


if MARKERS:
    _stores = itertools.count()

    def _store_started(work: Path) -> None:
        mark(f"store-{next(_stores)}.started")

    Cache.after_payload_hook = staticmethod(_store_started)
