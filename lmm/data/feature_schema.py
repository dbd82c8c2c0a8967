"""The feature schema: which channels a matching feature vector has, as plain data.

A manifest, a database cache and a weights file all store the schema (a list of channel tables); this
module reads and checks it (:func:`layout_from_schema`), writes it (:func:`schema_of`) and says what
differs between two (:func:`describe_schema_difference`). It sits in the data layer because those files
do; :mod:`lmm.features` computes the features a schema describes.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

KINDS = ("bone_position", "bone_velocity", "trajectory_position", "trajectory_direction")


@dataclass(frozen=True)
class Channel:
    """One group of feature dimensions.

    kind: ``bone_position`` / ``bone_velocity`` (3 dims: a bone in the simulation bone's space) or
    ``trajectory_position`` / ``trajectory_direction`` (2 dims per future offset: ground-plane x, z).
    bone: a bone name or a role from the database's ``bone_roles`` (e.g. ``left_foot``).
    offsets: frames ahead, at the database rate, for trajectory channels.
    """
    name: str
    kind: str
    bone: str | None = None
    offsets: tuple[int, ...] = ()
    weight: float = 1.0

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"feature channel {self.name!r}: unknown kind {self.kind!r} (expected one of {KINDS})")
        if self.kind.startswith("bone") and not self.bone:
            raise ValueError(f"feature channel {self.name!r}: kind {self.kind} needs a bone")
        if self.kind.startswith("trajectory") and (not self.offsets or any(o <= 0 for o in self.offsets)):
            raise ValueError(f"feature channel {self.name!r}: trajectory channels need positive frame offsets")
        if not (self.weight >= 0.0):
            raise ValueError(f"feature channel {self.name!r}: weight must be >= 0, got {self.weight}")

    @property
    def dims(self) -> int:
        return 3 if self.kind.startswith("bone") else 2 * len(self.offsets)

    def to_dict(self) -> dict:
        d = {"name": self.name, "kind": self.kind, "weight": self.weight}
        if self.bone:
            d["bone"] = self.bone
        if self.offsets:
            d["offsets"] = list(self.offsets)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Channel":
        return cls(name=d["name"], kind=d["kind"], bone=d.get("bone"), offsets=tuple(d.get("offsets", ())),
                   weight=float(d.get("weight", 1.0)))


DEFAULT_LAYOUT: tuple[Channel, ...] = (
    Channel("left_foot_position", "bone_position", "left_foot", weight=0.75),
    Channel("right_foot_position", "bone_position", "right_foot", weight=0.75),
    Channel("left_foot_velocity", "bone_velocity", "left_foot", weight=1.0),
    Channel("right_foot_velocity", "bone_velocity", "right_foot", weight=1.0),
    Channel("hip_velocity", "bone_velocity", "hips", weight=1.0),
    Channel("trajectory_position", "trajectory_position", offsets=(20, 40, 60), weight=1.0),
    Channel("trajectory_direction", "trajectory_direction", offsets=(20, 40, 60), weight=1.5),
)


MAX_TRAJECTORY_OFFSET = 600   # frames ahead (10 s at 60 fps): beyond that a "prediction" means nothing


def schema_of(layout: Sequence[Channel]) -> list[dict]:
    """A feature layout as plain data (what manifests, database caches and weights files store)."""
    return [ch.to_dict() for ch in layout]


def layout_from_schema(schema, where: str = "features") -> tuple[Channel, ...]:
    """Channels from plain data (a list of ``{"name", "kind", "bone", "offsets", "weight"}`` tables).
    Raises :class:`SchemaError` naming the entry and field (``features[2].offsets``)."""
    if not isinstance(schema, list) or not schema:
        raise SchemaError(where, "expected a non-empty list of feature channels")
    out, names = [], set()
    for i, d in enumerate(schema):
        at = f"{where}[{i}]"
        if not isinstance(d, dict):
            raise SchemaError(at, "expected a table with name, kind and bone or offsets")
        unknown = sorted(set(d) - {"name", "kind", "bone", "offsets", "weight"})
        if unknown:
            raise SchemaError(f"{at}.{unknown[0]}", "unknown field (known: name, kind, bone, offsets, weight)")
        name = d.get("name")
        if not isinstance(name, str) or not name or len(name) > 64:
            raise SchemaError(f"{at}.name", f"expected a name of 1-64 characters, got {name!r}")
        if name in names:
            raise SchemaError(f"{at}.name", f"channel {name!r} is declared twice")
        names.add(name)
        kind = d.get("kind")
        if kind not in KINDS:
            raise SchemaError(f"{at}.kind", f"expected one of {', '.join(KINDS)}, got {kind!r}")
        bone = d.get("bone")
        if kind.startswith("bone"):
            if not isinstance(bone, str) or not bone:
                raise SchemaError(f"{at}.bone", f"kind {kind} needs a bone (a joint name or a role such as left_foot)")
        elif bone is not None:
            raise SchemaError(f"{at}.bone", f"kind {kind} takes no bone")
        offsets = d.get("offsets", [])
        if kind.startswith("trajectory"):
            if (not isinstance(offsets, list) or not offsets
                    or not all(isinstance(o, int) and not isinstance(o, bool) for o in offsets)
                    or not all(1 <= o <= MAX_TRAJECTORY_OFFSET for o in offsets)
                    or list(offsets) != sorted(set(offsets))):
                raise SchemaError(f"{at}.offsets", "expected increasing whole numbers of frames ahead, 1 to "
                                  f"{MAX_TRAJECTORY_OFFSET}, e.g. [20, 40, 60]; got {offsets!r}")
        elif offsets not in ([], None):
            raise SchemaError(f"{at}.offsets", f"kind {kind} takes no offsets")
        weight = d.get("weight", 1.0)
        if isinstance(weight, bool) or not isinstance(weight, (int, float)) or not 0.0 <= weight <= 10.0:
            raise SchemaError(f"{at}.weight", f"expected a number from 0 to 10, got {weight!r}")
        out.append(Channel(name, kind, bone if kind.startswith("bone") else None,
                           tuple(offsets) if kind.startswith("trajectory") else (), float(weight)))
    return tuple(out)


class SchemaError(ValueError):
    """A malformed feature schema; ``field`` names the entry (``features[2].offsets``)."""

    def __init__(self, field_name: str, message: str):
        self.field = field_name
        self.message = message
        super().__init__(f"field '{field_name}': {message}")


def describe_schema_difference(theirs: list[dict], ours: list[dict]) -> str:
    """What differs between two feature schemas, in words (weights excepted: they only rescale)."""
    a = {d.get("name"): d for d in theirs}
    b = {d.get("name"): d for d in ours}
    parts = []
    missing = [n for n in a if n not in b]
    extra = [n for n in b if n not in a]
    if missing:
        parts.append("channels only in the networks: " + ", ".join(map(str, missing)))
    if extra:
        parts.append("channels only in the data: " + ", ".join(map(str, extra)))
    for n in a:
        if n in b:
            for key in ("kind", "bone", "offsets"):
                if a[n].get(key) != b[n].get(key):
                    parts.append(f"{n}.{key} {a[n].get(key)!r} in the networks, {b[n].get(key)!r} in the data")
    if not parts and [d.get("name") for d in theirs] != [d.get("name") for d in ours]:
        parts.append("channel order: " + ", ".join(map(str, a)) + " in the networks, " + ", ".join(map(str, b)) + " in the data")
    return "; ".join(parts) or "no difference"
