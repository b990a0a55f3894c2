"""Model files: one ``.npz`` holding a JSON header and named numeric arrays, never pickles.

Shared by every model format of the core (place models, people models). The header is
stored as a 1-D uint8 array ``header_json``; files are written atomically and read with
``allow_pickle=False``. Every problem on reading is a :class:`~knowledge.errors.ModelError`
that names the file and says what to do.
"""

from __future__ import annotations

import io
import json
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from knowledge.errors import ModelError
from knowledge.fileio import atomic_write_bytes

HEADER_KEY = "header_json"


def write_npz(path: str | Path, header: Mapping[str, Any], arrays: Mapping[str, npt.ArrayLike]) -> Path:
    """Write ``header`` (plain JSON) and ``arrays`` (numeric/string, no objects) atomically."""
    try:
        text = json.dumps(header, allow_nan=False, sort_keys=True)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"the model header is not plain JSON: {exc}") from exc
    out: dict[str, npt.NDArray[Any]] = {HEADER_KEY: np.frombuffer(text.encode("utf-8"), dtype=np.uint8)}
    for name, value in arrays.items():
        a = np.asarray(value)
        if a.dtype.hasobject:
            raise ValueError(
                f"array {name!r} holds Python objects; model files hold numeric/string arrays only"
            )
        if name == HEADER_KEY:
            raise ValueError(f"{HEADER_KEY!r} is reserved for the header")
        out[name] = a
    buf = io.BytesIO()
    np.savez_compressed(buf, **out)  # type: ignore[arg-type]
    return atomic_write_bytes(path, buf.getvalue())


def read_npz(
    path: str | Path, *, what: str, retrain: str
) -> tuple[dict[str, Any], dict[str, npt.NDArray[Any]]]:
    """The JSON header and the arrays of a model file.

    ``what`` names the kind of file in messages ("genius-loci place model (loci.place-model/1 .npz)");
    ``retrain`` says how to get a good file ("retrain it with 'loci places train'").
    """
    p = Path(path)
    not_model = f"{p}: not a {what}"
    try:
        loaded = np.load(p, allow_pickle=False)
    except ValueError as exc:  # not .npy/.npz: numpy would have to unpickle it
        raise ModelError(f"{not_model}: unreadable as .npz ({exc}); {retrain}") from exc
    except (OSError, EOFError, zipfile.BadZipFile) as exc:
        raise ModelError(
            f"{not_model}: {exc}; the file may be truncated: copy it again or {retrain}"
        ) from exc
    if not isinstance(loaded, np.lib.npyio.NpzFile):
        raise ModelError(f"{not_model}: it holds a single array, not a model archive")
    arrays: dict[str, npt.NDArray[Any]] = {}
    with loaded as npz:
        if HEADER_KEY not in npz.files:
            raise ModelError(f"{not_model}: it has no {HEADER_KEY!r} entry")
        for key in npz.files:
            try:
                arrays[key] = npz[key]
            except ValueError as exc:
                raise ModelError(
                    f"{p}: entry {key!r} is a pickled object array, which models never contain; "
                    "the file was not written by genius-loci (or was tampered with): do not use it"
                ) from exc
            except (OSError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
                raise ModelError(
                    f"{p}: entry {key!r} is damaged ({exc}); copy it again or {retrain}"
                ) from exc
    raw = arrays.pop(HEADER_KEY)
    try:
        if raw.dtype != np.uint8 or raw.ndim != 1:
            raise ValueError(f"{HEADER_KEY} must be a 1-D uint8 array")
        header = json.loads(raw.tobytes().decode("utf-8"))
        if not isinstance(header, dict):
            raise ValueError("the header is not a JSON object")
    except (ValueError, UnicodeDecodeError) as exc:
        raise ModelError(f"{not_model}: its header is not valid JSON ({exc})") from exc
    return header, arrays
