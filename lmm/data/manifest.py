"""Dataset manifests: which BVH files, which frame ranges, and how to turn them into a database.

A manifest is a JSON (or TOML) file. Paths inside it are relative to the manifest's folder.
A clip's ``ranges`` are ``[start, stop]`` pairs or ``{"range": [start, stop], "tags": ["walk", "run"]}``
tables; a clip-level ``"tags"`` list applies to every range of the clip. Tags are words: lowercase
letters, digits, ``_`` and ``-``.
``features`` declares the feature schema: the channels matched (kind, bone or role, trajectory sample
times in frames ahead, default weight), as a list of tables or the name of a JSON file holding one
(relative to the manifest). Without it the shipped schema is used (:data:`lmm.features.DEFAULT_LAYOUT`).
Every problem raises :class:`ManifestError` naming the file and the field.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

from lmm.errors import InputError
from lmm.features import DEFAULT_LAYOUT, SchemaError, layout_from_schema, schema_of

try:  # Python 3.11+
    import tomllib
except ImportError:  # pragma: no cover
    tomllib = None


class ManifestError(InputError):
    def __init__(self, path, field_name: str, message: str):
        self.path = str(path) if path is not None else None
        self.field = field_name
        self.message = message
        where = f"{self.path}: " if self.path else ""
        super().__init__(f"{where}field '{field_name}': {message}")


TAG_PATTERN = re.compile(r"^[a-z0-9_-]+$")


@dataclass
class ClipSpec:
    file: Path
    ranges: list[tuple[int, int]] | None  # None: the whole take; [start, stop) in source frames
    source: str = ""                      # the file as written in the manifest
    tags: tuple[str, ...] = ()            # clip-level tags (every range has them)
    range_tags: list[tuple[str, ...]] | None = None  # per range (clip tags included); None: whole take

    def tags_of(self, k: int) -> tuple[str, ...]:
        """Tags of range ``k`` (or of the whole take when ``ranges`` is None), clip tags included."""
        return self.range_tags[k] if self.range_tags is not None else self.tags


@dataclass
class Manifest:
    path: Path | None
    name: str = "dataset"
    description: str = ""
    unit_scale: float = 0.01
    target_fps: float = 60.0
    speed_scale: float = 1.0
    mirror: bool = True
    mirror_name_pairs: list[tuple[str, str]] = field(default_factory=lambda: [("Left", "Right")])
    bones: dict[str, str] = field(default_factory=lambda: {
        "hips": "Hips", "spine": "Spine2", "left_foot": "LeftFoot", "right_foot": "RightFoot",
        "left_toe": "LeftToe", "right_toe": "RightToe"})
    hips_forward_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    simulation_position_window: int = 31
    simulation_direction_window: int = 61
    simulation_order: int = 3
    contact_speed_threshold_m_s: float = 0.15
    contact_median_window: int = 5
    clips: list[ClipSpec] = field(default_factory=list)
    features: list[dict] = field(default_factory=lambda: schema_of(DEFAULT_LAYOUT))  # the feature schema
    features_file: Path | None = None     # where ``features`` came from when the manifest names a file

    def settings(self) -> dict:
        """Everything that changes the built database, except the file contents (hashed separately)."""
        return {
            "unit_scale": self.unit_scale, "target_fps": self.target_fps, "speed_scale": self.speed_scale,
            "mirror": self.mirror, "mirror_name_pairs": [list(p) for p in self.mirror_name_pairs],
            "bones": dict(sorted(self.bones.items())), "hips_forward_axis": list(self.hips_forward_axis),
            "simulation": [self.simulation_position_window, self.simulation_direction_window, self.simulation_order],
            "contacts": [self.contact_speed_threshold_m_s, self.contact_median_window],
            "clips": [{"file": c.file.name, "ranges": c.ranges} for c in self.clips],
        }

    def tag_names(self) -> list[str]:
        """Every tag used by any range, sorted."""
        return sorted({t for c in self.clips for k in range(len(c.ranges or [None])) for t in c.tags_of(k)})

    def tag_settings(self) -> list:
        """The tags of every range in clip order (what a database's tag masks are built from)."""
        return [[list(c.tags_of(k)) for k in range(len(c.ranges or [None]))] for c in self.clips]


REQUIRED_BONES = ("hips", "spine", "left_foot", "right_foot", "left_toe", "right_toe")


def _num(path, name, value, *, positive=False, integer=False, odd=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ManifestError(path, name, f"expected a number, got {value!r}")
    if value != value or value in (float("inf"), float("-inf")):
        raise ManifestError(path, name, f"expected a finite number, got {value!r}")
    if integer and int(value) != value:
        raise ManifestError(path, name, f"expected an integer, got {value!r}")
    if positive and value <= 0:
        raise ManifestError(path, name, f"expected a positive number, got {value!r}")
    if odd and int(value) % 2 != 1:
        raise ManifestError(path, name, f"expected an odd integer, got {value!r}")
    return int(value) if integer else float(value)


def _tags(path, name, value) -> tuple[str, ...]:
    if not isinstance(value, list):
        raise ManifestError(path, name, f"expected a list of tag words, got {value!r}")
    for k, t in enumerate(value):
        if not isinstance(t, str) or not TAG_PATTERN.match(t):
            raise ManifestError(path, f"{name}[{k}]", f"bad tag {t!r}: a tag is lowercase letters, digits, '_' or '-'")
    return tuple(dict.fromkeys(value))  # in order, without repeats


def parse_manifest(data: dict, path: Path | None = None, base_dir: Path | None = None) -> Manifest:
    if not isinstance(data, dict):
        raise ManifestError(path, "<top>", "expected a JSON object / TOML table")
    base_dir = base_dir or (path.parent if path else Path.cwd())
    m = Manifest(path=path)
    known = {"format", "version", "name", "description", "unit_scale", "target_fps", "speed_scale", "mirror",
             "mirror_name_pairs", "bones", "hips_forward_axis", "simulation", "contacts", "clips", "features"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ManifestError(path, unknown[0], f"unknown field (known: {', '.join(sorted(known))})")
    m.name = str(data.get("name", path.stem if path else "dataset"))
    m.description = str(data.get("description", ""))
    if "unit_scale" in data:
        m.unit_scale = _num(path, "unit_scale", data["unit_scale"], positive=True)
    if "target_fps" in data:
        m.target_fps = _num(path, "target_fps", data["target_fps"], positive=True)
    if "speed_scale" in data:
        m.speed_scale = _num(path, "speed_scale", data["speed_scale"], positive=True)
    if "mirror" in data:
        if not isinstance(data["mirror"], bool):
            raise ManifestError(path, "mirror", f"expected true or false, got {data['mirror']!r}")
        m.mirror = data["mirror"]
    if "mirror_name_pairs" in data:
        pairs = data["mirror_name_pairs"]
        if not isinstance(pairs, list) or not all(
                isinstance(p, list) and len(p) == 2 and all(isinstance(s, str) and s for s in p) for p in pairs):
            raise ManifestError(path, "mirror_name_pairs", 'expected a list of ["LeftMark", "RightMark"] pairs')
        m.mirror_name_pairs = [tuple(p) for p in pairs]
    if "bones" in data:
        bones = data["bones"]
        if not isinstance(bones, dict) or not all(isinstance(v, str) for v in bones.values()):
            raise ManifestError(path, "bones", "expected a table of role -> joint name")
        m.bones = {**m.bones, **bones}
    if "hips_forward_axis" in data:
        axis = data["hips_forward_axis"]
        if not isinstance(axis, list) or len(axis) != 3:
            raise ManifestError(path, "hips_forward_axis", "expected three numbers")
        m.hips_forward_axis = tuple(_num(path, f"hips_forward_axis[{i}]", a) for i, a in enumerate(axis))
        if sum(a * a for a in m.hips_forward_axis) == 0:
            raise ManifestError(path, "hips_forward_axis", "must not be zero")
    sim = data.get("simulation", {})
    if not isinstance(sim, dict):
        raise ManifestError(path, "simulation", "expected a table")
    m.simulation_position_window = _num(path, "simulation.position_window", sim.get("position_window", 31), integer=True, odd=True)
    m.simulation_direction_window = _num(path, "simulation.direction_window", sim.get("direction_window", 61), integer=True, odd=True)
    m.simulation_order = _num(path, "simulation.order", sim.get("order", 3), integer=True)
    contacts = data.get("contacts", {})
    if not isinstance(contacts, dict):
        raise ManifestError(path, "contacts", "expected a table")
    m.contact_speed_threshold_m_s = _num(path, "contacts.speed_threshold_m_s", contacts.get("speed_threshold_m_s", 0.15), positive=True)
    m.contact_median_window = _num(path, "contacts.median_window", contacts.get("median_window", 5), integer=True, odd=True)

    clips = data.get("clips")
    if not isinstance(clips, list) or not clips:
        raise ManifestError(path, "clips", "expected a non-empty list of {file, ranges}")
    for i, clip in enumerate(clips):
        where = f"clips[{i}]"
        if not isinstance(clip, dict) or "file" not in clip:
            raise ManifestError(path, where, "expected a table with a 'file'")
        if not isinstance(clip["file"], str):
            raise ManifestError(path, f"{where}.file", "expected a path string")
        file = (base_dir / clip["file"]).resolve()
        if not file.is_file():
            raise ManifestError(path, f"{where}.file", f"no such file: {file}")
        unknown = sorted(set(clip) - {"file", "ranges", "tags"})
        if unknown:
            raise ManifestError(path, f"{where}.{unknown[0]}", "unknown field (known: file, ranges, tags)")
        clip_tags = _tags(path, f"{where}.tags", clip["tags"]) if "tags" in clip else ()
        ranges = clip.get("ranges")
        range_tags = None
        if ranges is not None:
            if not isinstance(ranges, list) or not ranges:
                raise ManifestError(path, f"{where}.ranges", "expected a non-empty list of [start, stop] pairs")
            parsed, range_tags = [], []
            for k, r in enumerate(ranges):
                tags = clip_tags
                if isinstance(r, dict):
                    extra = sorted(set(r) - {"range", "tags"})
                    if extra or "range" not in r:
                        raise ManifestError(path, f"{where}.ranges[{k}]" + (f".{extra[0]}" if extra else ""),
                                            'expected {"range": [start, stop], "tags": [...]}')
                    if "tags" in r:
                        tags = tuple(dict.fromkeys(clip_tags + _tags(path, f"{where}.ranges[{k}].tags", r["tags"])))
                    r = r["range"]
                if (not isinstance(r, list) or len(r) != 2
                        or not all(isinstance(v, int) and not isinstance(v, bool) for v in r)):
                    raise ManifestError(path, f"{where}.ranges[{k}]", f"expected [start, stop] integers, got {r!r}")
                if r[0] < 0 or r[1] <= r[0]:
                    raise ManifestError(path, f"{where}.ranges[{k}]", f"expected 0 <= start < stop, got {r!r}")
                parsed.append((r[0], r[1]))
                range_tags.append(tags)
            ranges = parsed
        m.clips.append(ClipSpec(file=file, ranges=ranges, source=clip["file"], tags=clip_tags, range_tags=range_tags))
    for role in REQUIRED_BONES:
        if role not in m.bones:
            raise ManifestError(path, f"bones.{role}", "missing")
    if "features" in data:
        m.features, m.features_file = _feature_schema(path, base_dir, data["features"])
    return m


MAX_SCHEMA_BYTES = 1 << 20


def _feature_schema(path, base_dir: Path, value) -> tuple[list[dict], Path | None]:
    """The manifest's ``features``: a list of channel tables, or a JSON file (relative path) holding one
    (a list, or a table with a ``features`` list). Errors name the file and field."""
    source, file = path, None
    if isinstance(value, str):
        file = (base_dir / value).resolve()
        try:
            if file.stat().st_size > MAX_SCHEMA_BYTES:
                raise ManifestError(path, "features", f"{value}: larger than {MAX_SCHEMA_BYTES} bytes")
            text = file.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise ManifestError(path, "features", f"cannot read the feature schema {value!r} "
                                f"({getattr(e, 'strerror', None) or e})") from None
        try:
            value = json.loads(text)
        except (json.JSONDecodeError, RecursionError) as e:
            where = f"line {e.lineno} column {e.colno}: {e.msg}" if isinstance(e, json.JSONDecodeError) else "nested too deep"
            raise ManifestError(file, "<file>", f"invalid JSON at {where}") from None
        if isinstance(value, dict) and set(value) <= {"features", "format", "version", "description"}:
            value = value.get("features")
        source = file
    try:
        layout = layout_from_schema(value, "features")
    except SchemaError as e:
        raise ManifestError(source, e.field, e.message) from None
    return schema_of(layout), file


def load_manifest(path) -> Manifest:
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ManifestError(path, "<file>", f"cannot read: {e.strerror or e}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ManifestError(path, "<file>", "not UTF-8 text") from None
    if path.suffix.lower() == ".toml":
        if tomllib is None:  # pragma: no cover
            raise ManifestError(path, "<file>", "TOML manifests need Python 3.11+")
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as e:
            raise ManifestError(path, "<file>", f"invalid TOML: {e}") from None
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as e:
            raise ManifestError(path, "<file>", f"invalid JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    return parse_manifest(data, path=path.resolve())
