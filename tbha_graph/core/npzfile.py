"""Reading an ``.npz`` file from outside the cache safely: the one implementation every reader uses.

Never with pickle (``allow_pickle=False``: an object array is refused, nothing is evaluated) and with
every member's CRC-32 checked: numpy reads only the bytes a member's ``.npy`` header asks for, so a
damaged header declaring a smaller dtype or shape skips the zip's own check and the array would be read
as garbage. Any problem is a :class:`~tbha_graph.core.errors.NodeError` naming the file.
"""
from __future__ import annotations

import zipfile
import zlib
from pathlib import Path
from typing import Iterable

import numpy as np

from .errors import NodeError

#: what reading a damaged .npz raises (zip structure, deflate stream, .npy header, truncation)
DAMAGED_NPZ = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError, RuntimeError)


def read_npz(path: str | Path, what: str = "", hint: str = "", keys: Iterable[str] | None = None) -> dict[str, np.ndarray]:
    """The arrays of the ``.npz`` bundle at ``path`` by name (only those in ``keys`` when given).

    ``what`` names the file's role in messages (``"ground truth"``: "ground truth data/gt.npz is damaged
    ..."); ``hint`` is attached to every error. Raises :class:`NodeError` when the file is missing, is a
    single ``.npy`` array, is not a readable zip, holds an object array, or a member fails its CRC-32.
    """
    path = Path(path)
    name = f"{what} {path}" if what else str(path)
    if not path.is_file():
        raise NodeError(f"{name} does not exist", hint=hint)
    try:
        z = np.load(path, allow_pickle=False)
    except DAMAGED_NPZ as e:
        raise NodeError(f"{name} cannot be read as an .npz without pickle: {e}", hint=hint) from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise NodeError(f"{name} is a single .npy array, not an .npz bundle of named arrays", hint=hint)
    wanted = None if keys is None else set(keys)
    try:
        with z:
            damaged = z.zip.testzip()
            if damaged is not None:
                raise NodeError(f"{name}: {damaged} is damaged (its CRC-32 does not match)", hint=hint)
            return {k: z[k] for k in z.files if wanted is None or k in wanted}
    except DAMAGED_NPZ as e:
        raise NodeError(f"{name}: an array cannot be read without pickle: {e}", hint=hint) from None
