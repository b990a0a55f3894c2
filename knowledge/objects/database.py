"""The objects the robot was taught: a folder of SIFT features, one file per object.

Layout of a database folder (format ``loci.objects/1``)::

    index.json                  {"format": "loci.objects/1", "features": {...},
                                 "objects": [{"name", "kind", "file", "images": [{"width",
                                 "height", "keypoints"}]}]}
    <slug>-<crc32>.npz          one per object (knowledge.npzfile: JSON header + arrays)

Each object's ``.npz`` holds the header ``{"format", "name", "kind", "features"}`` and the
arrays ``keypoints`` ``(n, 4)`` float32 (x, y, size pixels, angle degrees), ``descriptors``
``(n, 128)`` uint8 (SIFT's values are whole numbers, stored exactly), ``image`` ``(n,)``
int32 (which training image each keypoint is from), ``image_sizes`` ``(m, 2)`` int32
(width, height pixels) and ``outlines`` ``(m, 4, 2)`` float32 (each image's corners:
top-left, top-right, bottom-right, bottom-left, pixels).

Every file is written atomically and read with ``allow_pickle=False``. Adding an object
writes its own file and then the index; the other objects' files are never rewritten,
and a broken object file is reported by name when loaded (:class:`ModelError`) without
touching the others. A missing index is rebuilt from the objects' own headers.

Names and kinds: ``name`` is the instance name ("television", "the red couch"); ``kind``
is an ontology class name ("Television", "ChargingStation"). Without an explicit kind the
name's words make it (:func:`class_name`: "charging station" → "ChargingStation").
"""

from __future__ import annotations

import json
import re
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from knowledge.errors import ModelError
from knowledge.fileio import atomic_write_text
from knowledge.npzfile import read_npz, write_npz
from knowledge.objects.features import FeatureParams, Features, extract_features

FORMAT = "loci.objects/1"
INDEX = "index.json"
#: Longest object name accepted, characters.
MAX_NAME = 80
#: A training image needs at least this many SIFT keypoints to be of any use.
MIN_KEYPOINTS = 8


def class_name(words: str) -> str:
    """The ontology class name of some words: ``"charging station"``/``"charging_station"``
    → ``"ChargingStation"``, ``"television"`` → ``"Television"``; ``"LivingRoom"`` stays."""
    parts = [w for w in re.split(r"[\s_\-]+", words.strip()) if w]
    out = "".join(w[:1].upper() + w[1:] for w in parts)
    if not out or not out.isidentifier() or not out[0].isalpha():
        raise ValueError(
            f"{words!r} does not make an ontology class name (letters, digits, starting with a letter, "
            "e.g. 'Television' or 'charging station'); give one with --kind"
        )
    return out


def normalise_name(name: str) -> str:
    """An object name with surrounding and repeated white space removed (ValueError if unusable)."""
    text = " ".join(str(name).split())
    if not text:
        raise ValueError("an object needs a non-empty name, e.g. 'television'")
    if len(text) > MAX_NAME:
        raise ValueError(f"object names are at most {MAX_NAME} characters, got {len(text)}: {text[:20]!r}...")
    if not text.isprintable():
        raise ValueError(f"object name {text!r} contains control characters")
    return text


def file_name(name: str) -> str:
    """The ``.npz`` file name of an object: a readable slug plus a CRC of the name (no collisions
    between names that slug alike, e.g. "tv 1" and "tv_1")."""
    key = name.casefold()
    slug = re.sub(r"[^a-z0-9]+", "_", key).strip("_")[:40] or "object"
    return f"{slug}-{zlib.crc32(key.encode('utf-8')):08x}.npz"


@dataclass(frozen=True)
class ObjectEntry:
    """One object of the index.

    Attributes:
        name: instance name (unique in the database, compared case-insensitively).
        kind: ontology class name.
        file: the object's ``.npz``, relative to the database folder.
        image_sizes: ``(width, height)`` of each training image, pixels.
        keypoints: number of SIFT keypoints of each training image.
    """

    name: str
    kind: str
    file: str
    image_sizes: tuple[tuple[int, int], ...]
    keypoints: tuple[int, ...]

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "kind": self.kind,
            "file": self.file,
            "images": [
                {"width": w, "height": h, "keypoints": n}
                for (w, h), n in zip(self.image_sizes, self.keypoints, strict=True)
            ],
        }

    @classmethod
    def from_json(cls, doc: Any) -> ObjectEntry:
        if not isinstance(doc, dict):
            raise ValueError(f"an index entry must be a JSON object, got {type(doc).__name__}")
        try:
            images = doc["images"]
            if not isinstance(images, list) or not images:
                raise ValueError("'images' must be a non-empty list")
            sizes = tuple((int(i["width"]), int(i["height"])) for i in images)
            counts = tuple(int(i["keypoints"]) for i in images)
            name, kind, file = normalise_name(str(doc["name"])), str(doc["kind"]), str(doc["file"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"index entry {doc!r} lacks or mistypes a field ({exc})") from exc
        if Path(file).name != file or not file.endswith(".npz"):
            raise ValueError(f"index entry {name!r} names a file outside the folder: {file!r}")
        return cls(name, class_name(kind), file, sizes, counts)


@dataclass(frozen=True, eq=False)
class TrainingView:
    """One training image of an object, ready for matching.

    Attributes:
        name, kind: the object's.
        features: SIFT features of the training image.
        image_index: which of the object's training images this is (0-based).
    """

    name: str
    kind: str
    features: Features
    image_index: int = 0


class ObjectDatabase:
    """A folder of taught objects (see the module docstring for the format).

    Open one with :meth:`open`; a folder that does not exist yet is an empty database, made
    on the first :meth:`add`. Not safe for two processes adding at the same time.
    """

    def __init__(
        self, folder: Path, entries: Iterable[ObjectEntry] = (), feature_params: FeatureParams | None = None
    ) -> None:
        self.folder = Path(folder)
        self.feature_params = feature_params or FeatureParams()
        self._entries: dict[str, ObjectEntry] = {}
        for e in entries:
            if e.name.casefold() in self._entries:
                raise ModelError(f"{self.index_path}: object {e.name!r} is listed twice")
            self._entries[e.name.casefold()] = e

    # ------------------------------------------------------------------ reading
    @property
    def index_path(self) -> Path:
        return self.folder / INDEX

    @classmethod
    def open(cls, folder: str | Path) -> ObjectDatabase:
        """The database in ``folder``: its index is read (object files are read on demand)."""
        folder = Path(folder)
        if folder.exists() and not folder.is_dir():
            raise ValueError(f"{folder} is a file, not an object database folder; pick another --db")
        index = folder / INDEX
        if not index.exists():
            return cls._rebuilt(folder)
        try:
            doc = json.loads(index.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ModelError(
                f"{index}: not a readable {FORMAT} index ({exc}); the objects' .npz files are untouched: "
                f"move {index.name} away and the index is rebuilt from them"
            ) from exc
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
            raise ModelError(
                f"{index}: not a {FORMAT} index (format {found!r}); "
                "use a folder written by 'loci objects add' or another --db"
            )
        try:
            params = FeatureParams(**{k: v for k, v in doc.get("features", {}).items() if k != "version"})
            entries = [ObjectEntry.from_json(e) for e in doc.get("objects", [])]
        except (TypeError, ValueError, AttributeError) as exc:
            raise ModelError(f"{index}: damaged {FORMAT} index: {exc}") from exc
        return cls(folder, entries, params)

    @classmethod
    def _rebuilt(cls, folder: Path) -> ObjectDatabase:
        """A database whose index is missing: the entries come from the object files' headers."""
        entries = []
        for path in sorted(folder.glob("*.npz")) if folder.is_dir() else []:
            header, arrays = _read_object_file(path)
            sizes = arrays["image_sizes"]
            counts = np.bincount(arrays["image"], minlength=len(sizes))
            entries.append(
                ObjectEntry(
                    normalise_name(str(header["name"])),
                    class_name(str(header["kind"])),
                    path.name,
                    tuple((int(w), int(h)) for w, h in sizes),
                    tuple(int(n) for n in counts),
                )
            )
        return cls(folder, entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and " ".join(name.split()).casefold() in self._entries

    def names(self) -> list[str]:
        """The objects' names, sorted."""
        return sorted(e.name for e in self._entries.values())

    def entries(self) -> list[ObjectEntry]:
        """The index entries, sorted by name."""
        return sorted(self._entries.values(), key=lambda e: e.name)

    def entry(self, name: str) -> ObjectEntry:
        """The entry called ``name`` (case-insensitive); ValueError naming the known ones if absent."""
        key = normalise_name(name).casefold()
        if key not in self._entries:
            known = ", ".join(self.names()) or "none yet"
            raise ValueError(
                f"unknown object {name!r} in {self.folder} (known: {known}); "
                "teach it with 'loci objects add NAME IMAGE...'"
            )
        return self._entries[key]

    def views(self, names: Sequence[str] | None = None) -> list[TrainingView]:
        """The training views of the objects called ``names`` (default: all), loaded from their
        files; a missing or damaged file is a :class:`ModelError` naming it and the object."""
        entries = self.entries() if names is None else [self.entry(n) for n in names]
        out: list[TrainingView] = []
        for e in entries:
            out.extend(self._load(e))
        return out

    def _load(self, e: ObjectEntry) -> list[TrainingView]:
        path = self.folder / e.file
        fix = (
            f"teach {e.name!r} again with 'loci objects add --replace {e.name!r} IMAGE...' "
            f"or forget it with 'loci objects remove {e.name!r}'"
        )
        if not path.is_file():
            raise ModelError(f"{path}: the features of object {e.name!r} are missing; {fix}")
        header, arrays = _read_object_file(path, fix=fix)
        if normalise_name(str(header.get("name", ""))).casefold() != e.name.casefold():
            raise ModelError(f"{path}: holds object {header.get('name')!r}, the index says {e.name!r}; {fix}")
        kp, desc, img, sizes = (arrays[k] for k in ("keypoints", "descriptors", "image", "image_sizes"))
        return [
            TrainingView(
                e.name,
                e.kind,
                Features(kp[img == i], desc[img == i].astype(np.float32), (int(w), int(h))),
                i,
            )
            for i, (w, h) in enumerate(sizes)
        ]

    # ------------------------------------------------------------------ writing
    def add(
        self,
        name: str,
        images: Sequence[npt.ArrayLike],
        *,
        kind: str | None = None,
        replace: bool = False,
    ) -> ObjectEntry:
        """Teach an object from one or more pictures of it (uint8 grey/BGR, cropped to the object).

        ``kind`` is an ontology class name or words for one ("Television", "coffee machine");
        without it the name makes it. Adding to a known name adds training images (the kind
        must agree); ``replace=True`` starts the object afresh. Writes the object's file, then
        the index, both atomically.
        """
        name = normalise_name(name)
        if not images:
            raise ValueError(f"teaching {name!r} needs at least one image of it")
        cls_name = class_name(kind) if kind is not None else class_name(name)
        feats = []
        for i, image in enumerate(images):
            f = extract_features(image, self.feature_params)
            if len(f) < MIN_KEYPOINTS:
                raise ValueError(
                    f"image {i + 1} of {name!r} has {len(f)} SIFT keypoints (need at least {MIN_KEYPOINTS}): "
                    "use a sharper, larger, more textured picture of the object"
                )
            feats.append(f)
        old = self._entries.get(name.casefold())
        if old is not None and not replace:
            if kind is not None and cls_name != old.kind:
                raise ValueError(
                    f"{name!r} is already known as a {old.kind}, not a {cls_name}; "
                    "use replace (--replace) to teach it afresh"
                )
            cls_name = old.kind
            feats = [v.features for v in self._load(old)] + feats
        entry = ObjectEntry(
            old.name if old is not None and not replace else name,
            cls_name,
            file_name(name),
            tuple(f.image_size for f in feats),
            tuple(len(f) for f in feats),
        )
        self._write_object(entry, feats)
        if old is not None and old.file != entry.file:
            (self.folder / old.file).unlink(missing_ok=True)
        self._entries[name.casefold()] = entry
        self._write_index()
        return entry

    def remove(self, name: str) -> ObjectEntry:
        """Forget an object: the index first (so a crash leaves at most a stray file), then its file."""
        e = self.entry(name)
        del self._entries[e.name.casefold()]
        self._write_index()
        (self.folder / e.file).unlink(missing_ok=True)
        return e

    def _write_object(self, e: ObjectEntry, feats: Sequence[Features]) -> None:
        header = {"format": FORMAT, "name": e.name, "kind": e.kind, "features": self.feature_params.key()}
        outlines = np.array(
            [[[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]] for w, h in e.image_sizes],
            dtype=np.float32,
        )
        write_npz(
            self.folder / e.file,
            header,
            {
                "keypoints": np.concatenate([f.keypoints for f in feats]).astype(np.float32),
                "descriptors": np.clip(
                    np.rint(np.concatenate([f.descriptors for f in feats])), 0, 255
                ).astype(np.uint8),
                "image": np.repeat(np.arange(len(feats), dtype=np.int32), [len(f) for f in feats]),
                "image_sizes": np.array(e.image_sizes, dtype=np.int32).reshape(-1, 2),
                "outlines": outlines,
            },
        )

    def _write_index(self) -> None:
        doc = {
            "format": FORMAT,
            "features": self.feature_params.key(),
            "objects": [e.to_json() for e in self.entries()],
        }
        atomic_write_text(self.index_path, json.dumps(doc, indent=2, ensure_ascii=False) + "\n")


def _read_object_file(path: Path, *, fix: str = "") -> tuple[dict[str, Any], dict[str, npt.NDArray[Any]]]:
    """Header and checked arrays of one object file (ModelError naming the file otherwise)."""
    fix = fix or "teach the object again with 'loci objects add --replace NAME IMAGE...'"
    header, arrays = read_npz(path, what=f"{FORMAT} object file", retrain=fix)
    try:
        if header.get("format") != FORMAT:
            raise ValueError(f"format {header.get('format')!r}, expected {FORMAT!r}")
        for key in ("name", "kind"):
            if not isinstance(header.get(key), str):
                raise ValueError(f"the header lacks {key!r}")
        kp, desc = arrays["keypoints"], arrays["descriptors"]
        img, sizes = arrays["image"], arrays["image_sizes"]
        n = kp.shape[0] if kp.ndim == 2 else -1
        if kp.shape != (n, 4) or kp.dtype != np.float32 or not np.all(np.isfinite(kp)):
            raise ValueError(f"keypoints must be finite (n, 4) float32, got {kp.dtype} {kp.shape}")
        if desc.shape != (n, 128) or desc.dtype != np.uint8:
            raise ValueError(f"descriptors must be ({n}, 128) uint8, got {desc.dtype} {desc.shape}")
        if sizes.ndim != 2 or sizes.shape[1:] != (2,) or len(sizes) < 1 or np.any(sizes < 1):
            raise ValueError(f"image_sizes must be (m, 2) positive, got {sizes.shape}")
        if img.shape != (n,) or not np.issubdtype(img.dtype, np.integer):
            raise ValueError(f"image must be ({n},) integers, got {img.dtype} {img.shape}")
        if n and (img.min() < 0 or img.max() >= len(sizes)):
            raise ValueError("image indices out of range")
    except KeyError as exc:
        raise ModelError(f"{path}: not a {FORMAT} object file: array {exc} is missing; {fix}") from exc
    except ValueError as exc:
        raise ModelError(f"{path}: not a {FORMAT} object file: {exc}; {fix}") from exc
    return header, arrays
