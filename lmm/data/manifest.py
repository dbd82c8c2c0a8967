"""Dataset manifests: which BVH files, which frame ranges, and how to turn them into a database.

A manifest is a JSON (or TOML) file. Paths inside it are relative to the manifest's folder, or to its
``root`` when it names one: a folder (itself relative to the manifest's folder) in which ``$NAME`` and
``${NAME}`` are taken from the environment, so one manifest serves a download kept anywhere
(``"root": "${LAFAN1_DIR}"``; an unset variable is an error naming it). The root is not part of the
database key: only the files' contents are.
A clip's ``ranges`` are ``[start, stop]`` pairs or ``{"range": [start, stop], "tags": ["walk", "run"]}``
tables; a clip-level ``"tags"`` list applies to every range of the clip. Tags are words: lowercase
letters, digits, ``_`` and ``-``.
``features`` declares the feature schema: the channels matched (kind, bone or role, trajectory sample
times in frames ahead, default weight), as a list of tables or the name of a JSON file holding one
(relative to the manifest). Without it the shipped schema is used (:data:`lmm.data.feature_schema.DEFAULT_LAYOUT`).
Every problem raises :class:`ManifestError` naming the file and the field (paths, never the contents
of the files they point at). Every number has an accepted range and every list a length limit (the
``MAX_``/``MIN_`` constants below, each with what it is derived from), all checked before any work.
"""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from lmm.errors import InputError
from lmm.data.reading import NotRegularFileError, open_regular, read_limited, resolved
from lmm.skeleton import MANIFEST_ROLES, default_bones
from lmm.data.feature_schema import DEFAULT_LAYOUT, SchemaError, layout_from_schema, schema_of

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

# --- accepted ranges and sizes (what the build can actually do) ----------------------------------------
#: Largest manifest file: the shipped one is 5 KB; 1 MiB holds thousands of ranges.
MAX_MANIFEST_BYTES = 1 << 20
#: Deepest nesting of lists and tables: a manifest needs 6 (clips > clip > ranges > range > tags); the
#: limit keeps every later walk over the data far from Python's recursion limit.
MAX_NESTING = 8
#: Longest ``name`` (shown in the studio and stored in the database; never a file name) and ``description``.
MAX_NAME_CHARS = 80
MAX_DESCRIPTION_CHARS = 4096
#: Most clip entries and ranges (all clips together): each clip is one BVH read (0.1-0.5 s for a shipped
#: take) and each range one resampling pass; the shipped set has 6 clips and 40 ranges.
MAX_CLIPS = 256
MAX_RANGES = 4096
#: Most tags on a range, longest tag, most bone roles, mirror name pairs, longest joint or mark name.
MAX_TAGS = 32
MAX_TAG_CHARS = 32
MAX_BONES = 64
MAX_MIRROR_PAIRS = 16
MAX_JOINT_NAME_CHARS = 256
MAX_PATH_CHARS = 4096
#: Largest frame index in a range: the BVH reader accepts at most this many frames.
MAX_RANGE_FRAME = 5_000_000
#: ``unit_scale``: file units to metres, from 0.1 mm (1e-4) to 100 m per unit (mm 0.001, inch 0.0254, cm 0.01).
UNIT_SCALE_RANGE = (1e-4, 100.0)
#: ``target_fps``: the database's frame rate, also the controllers' tick: below 10 fps trajectory samples
#: and inertialization have too few frames to work with, above 240 fps the database grows with no gain
#: (capture is 30-120 fps); 1e5 built for a minute and 5.5 GB before this limit.
TARGET_FPS_RANGE = (10.0, 240.0)
#: ``speed_scale``: playback speed of every clip; 0.1..10 keeps the resampled frame count within 10x of
#: the source's (1e-9 would ask for a billion frames per source frame).
SPEED_SCALE_RANGE = (0.1, 10.0)
#: Savitzky-Golay smoothing of the simulation bone: odd windows up to 601 frames (10 s at 60 fps; the
#: cost is window x frames), polynomial order 0..7 (a higher order fits noise and is ill-conditioned).
MAX_SMOOTHING_WINDOW = 601
MAX_SMOOTHING_ORDER = 7
#: Contacts: the median window is odd, at most 61 frames (1 s at 60 fps; a median wider than a step
#: erases the contact, and its memory is window x frames); the speed threshold is at most 10 m/s.
MAX_MEDIAN_WINDOW = 61
MAX_CONTACT_SPEED_M_S = 10.0
#: Components of ``hips_forward_axis`` (a direction; its length does not matter).
MAX_AXIS_COMPONENT = 1e3


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
    bones: dict[str, str] = field(default_factory=default_bones)   # role -> joint name (LAFAN1's by default)
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


REQUIRED_BONES = MANIFEST_ROLES


def _short(value, limit: int = 40) -> str:
    """A value for an error message, cut to ``limit`` characters."""
    s = repr(value)
    return s if len(s) <= limit else s[:limit] + "..."


def _num(path, name, value, *, positive=False, integer=False, odd=False, lo=None, hi=None):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ManifestError(path, name, f"expected a number, got {_short(value)}")
    if isinstance(value, float) and not math.isfinite(value):
        raise ManifestError(path, name, f"expected a finite number, got {value!r}")
    if integer and int(value) != value:
        raise ManifestError(path, name, f"expected an integer, got {value!r}")
    if positive and value <= 0:
        raise ManifestError(path, name, f"expected a positive number, got {_short(value)}")
    if odd and int(value) % 2 != 1:
        raise ManifestError(path, name, f"expected an odd integer, got {_short(value)}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ManifestError(path, name, f"expected {'an integer' if integer else 'a number'} from {lo:g} to "
                                        f"{hi:g}, got {_short(value)}")
    return int(value) if integer else float(value)


def _text(path, name, value, limit: int, *, allow_empty: bool = False) -> str:
    if not isinstance(value, str):
        raise ManifestError(path, name, f"expected a string, got {_short(value)}")
    if len(value) > limit:
        raise ManifestError(path, name, f"expected at most {limit} characters, got {len(value)}")
    if not value and not allow_empty:
        raise ManifestError(path, name, "expected a non-empty string")
    if "\x00" in value:
        raise ManifestError(path, name, "expected text without NUL characters")
    return value


def _dataset_name(path, value) -> str:
    """``name``: printable text without path separators (it never becomes a file name, but it is shown)."""
    name = _text(path, "name", value, MAX_NAME_CHARS)
    if not name.isprintable() or "/" in name or "\\" in name or name.strip() in ("", ".", ".."):
        raise ManifestError(path, "name", "expected printable text without '/', '\\' or control "
                                          f"characters, got {_short(name)}")
    return name


def _check_table(path, name, table, known) -> None:
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise ManifestError(path, f"{name}.{unknown[0]}", f"unknown field (known: {', '.join(sorted(known))})")


def _nesting(value) -> int:
    """Deepest nesting of lists and tables in ``value``, without recursion."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, (dict, list)):
            deepest = max(deepest, depth)
            if depth <= MAX_NESTING:
                stack.extend((c, depth + 1) for c in (v.values() if isinstance(v, dict) else v))
    return deepest


def _tags(path, name, value) -> tuple[str, ...]:
    if not isinstance(value, list):
        raise ManifestError(path, name, f"expected a list of tag words, got {_short(value)}")
    if len(value) > MAX_TAGS:
        raise ManifestError(path, name, f"expected at most {MAX_TAGS} tags, got {len(value)}")
    for k, t in enumerate(value):
        if not isinstance(t, str) or not TAG_PATTERN.match(t) or len(t) > MAX_TAG_CHARS:
            raise ManifestError(path, f"{name}[{k}]", f"bad tag {_short(t)}: a tag is up to {MAX_TAG_CHARS} "
                                                      "lowercase letters, digits, '_' or '-'")
    return tuple(dict.fromkeys(value))  # in order, without repeats


def parse_manifest(data: dict, path: Path | None = None, base_dir: Path | None = None) -> Manifest:
    if not isinstance(data, dict):
        raise ManifestError(path, "<top>", "expected a JSON object / TOML table")
    if _nesting(data) > MAX_NESTING:
        raise ManifestError(path, "<top>", f"lists and tables nested deeper than {MAX_NESTING} levels")
    base_dir = manifest_dir = base_dir or (path.parent if path else Path.cwd())
    if "root" in data:  # the takes' folder; the feature schema file stays beside the manifest
        base_dir = _root_dir(path, manifest_dir, data["root"])
    m = Manifest(path=path)
    known = {"format", "version", "root", "name", "description", "unit_scale", "target_fps", "speed_scale", "mirror",
             "mirror_name_pairs", "bones", "hips_forward_axis", "simulation", "contacts", "clips", "features"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ManifestError(path, unknown[0], f"unknown field (known: {', '.join(sorted(known))})")
    if "name" in data:
        m.name = _dataset_name(path, data["name"])
    elif path is not None:
        m.name = path.stem[:MAX_NAME_CHARS]
    if "description" in data:
        m.description = _text(path, "description", data["description"], MAX_DESCRIPTION_CHARS, allow_empty=True)
    if "unit_scale" in data:
        m.unit_scale = _num(path, "unit_scale", data["unit_scale"], positive=True,
                            lo=UNIT_SCALE_RANGE[0], hi=UNIT_SCALE_RANGE[1])
    if "target_fps" in data:
        m.target_fps = _num(path, "target_fps", data["target_fps"], positive=True,
                            lo=TARGET_FPS_RANGE[0], hi=TARGET_FPS_RANGE[1])
    if "speed_scale" in data:
        m.speed_scale = _num(path, "speed_scale", data["speed_scale"], positive=True,
                             lo=SPEED_SCALE_RANGE[0], hi=SPEED_SCALE_RANGE[1])
    if "mirror" in data:
        if not isinstance(data["mirror"], bool):
            raise ManifestError(path, "mirror", f"expected true or false, got {data['mirror']!r}")
        m.mirror = data["mirror"]
    if "mirror_name_pairs" in data:
        pairs = data["mirror_name_pairs"]
        if not isinstance(pairs, list) or len(pairs) > MAX_MIRROR_PAIRS or not all(
                isinstance(p, list) and len(p) == 2
                and all(isinstance(s, str) and s and len(s) <= MAX_JOINT_NAME_CHARS for s in p) for p in pairs):
            raise ManifestError(path, "mirror_name_pairs", f'expected a list of at most {MAX_MIRROR_PAIRS} '
                                                           '["LeftMark", "RightMark"] pairs')
        m.mirror_name_pairs = [tuple(p) for p in pairs]
    if "bones" in data:
        bones = data["bones"]
        if (not isinstance(bones, dict) or len(bones) > MAX_BONES
                or not all(isinstance(v, str) and 0 < len(v) <= MAX_JOINT_NAME_CHARS for v in bones.values())
                or not all(0 < len(k) <= MAX_JOINT_NAME_CHARS for k in bones)):
            raise ManifestError(path, "bones", f"expected a table of at most {MAX_BONES} role -> joint name")
        m.bones = {**m.bones, **bones}
    if "hips_forward_axis" in data:
        axis = data["hips_forward_axis"]
        if not isinstance(axis, list) or len(axis) != 3:
            raise ManifestError(path, "hips_forward_axis", "expected three numbers")
        m.hips_forward_axis = tuple(_num(path, f"hips_forward_axis[{i}]", a, lo=-MAX_AXIS_COMPONENT,
                                         hi=MAX_AXIS_COMPONENT) for i, a in enumerate(axis))
        if sum(a * a for a in m.hips_forward_axis) == 0:
            raise ManifestError(path, "hips_forward_axis", "must not be zero")
    sim = data.get("simulation", {})
    if not isinstance(sim, dict):
        raise ManifestError(path, "simulation", "expected a table")
    _check_table(path, "simulation", sim, ("position_window", "direction_window", "order"))
    m.simulation_position_window = _num(path, "simulation.position_window", sim.get("position_window", 31),
                                        integer=True, odd=True, lo=1, hi=MAX_SMOOTHING_WINDOW)
    m.simulation_direction_window = _num(path, "simulation.direction_window", sim.get("direction_window", 61),
                                         integer=True, odd=True, lo=1, hi=MAX_SMOOTHING_WINDOW)
    m.simulation_order = _num(path, "simulation.order", sim.get("order", 3), integer=True,
                              lo=0, hi=MAX_SMOOTHING_ORDER)
    contacts = data.get("contacts", {})
    if not isinstance(contacts, dict):
        raise ManifestError(path, "contacts", "expected a table")
    _check_table(path, "contacts", contacts, ("speed_threshold_m_s", "median_window"))
    m.contact_speed_threshold_m_s = _num(path, "contacts.speed_threshold_m_s",
                                         contacts.get("speed_threshold_m_s", 0.15), positive=True,
                                         lo=0.0, hi=MAX_CONTACT_SPEED_M_S)
    m.contact_median_window = _num(path, "contacts.median_window", contacts.get("median_window", 5),
                                   integer=True, odd=True, lo=1, hi=MAX_MEDIAN_WINDOW)

    clips = data.get("clips")
    if not isinstance(clips, list) or not clips:
        raise ManifestError(path, "clips", "expected a non-empty list of {file, ranges}")
    if len(clips) > MAX_CLIPS:
        raise ManifestError(path, "clips", f"expected at most {MAX_CLIPS} clips, got {len(clips)}")
    n_ranges = sum(len(c["ranges"]) if isinstance(c, dict) and isinstance(c.get("ranges"), list) else 1
                   for c in clips)
    if n_ranges > MAX_RANGES:
        raise ManifestError(path, "clips", f"expected at most {MAX_RANGES} ranges in all, got {n_ranges}")
    for i, clip in enumerate(clips):
        where = f"clips[{i}]"
        if not isinstance(clip, dict) or "file" not in clip:
            raise ManifestError(path, where, "expected a table with a 'file'")
        if not isinstance(clip["file"], str):
            raise ManifestError(path, f"{where}.file", "expected a path string")
        _text(path, f"{where}.file", clip["file"], MAX_PATH_CHARS)
        try:
            file = resolved(base_dir / clip["file"])
            found = file.is_file()
        except (OSError, ValueError) as e:  # a name too long for the file system, a loop of links...
            raise ManifestError(path, f"{where}.file", f"cannot use the path ({getattr(e, 'strerror', None) or e})") from None
        if not found:
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
                    raise ManifestError(path, f"{where}.ranges[{k}]", f"expected [start, stop] integers, got {_short(r)}")
                if r[0] < 0 or r[1] <= r[0] or r[1] > MAX_RANGE_FRAME:
                    raise ManifestError(path, f"{where}.ranges[{k}]",
                                        f"expected 0 <= start < stop <= {MAX_RANGE_FRAME}, got {_short(r)}")
                parsed.append((r[0], r[1]))
                range_tags.append(tags)
            ranges = parsed
        m.clips.append(ClipSpec(file=file, ranges=ranges, source=clip["file"], tags=clip_tags, range_tags=range_tags))
    for role in REQUIRED_BONES:
        if role not in m.bones:
            raise ManifestError(path, f"bones.{role}", "missing")
    if "features" in data:
        m.features, m.features_file = _feature_schema(path, manifest_dir, data["features"])
    return m


_ENV_REFERENCE = re.compile(r"\$(?:\{([A-Za-z_][A-Za-z0-9_]*)\}|([A-Za-z_][A-Za-z0-9_]*))")


def _root_dir(path, base_dir: Path, value) -> Path:
    """The manifest's ``root``: environment references expanded, relative to the manifest's folder."""
    text = _text(path, "root", value, MAX_PATH_CHARS)

    def expand(match) -> str:
        name = match.group(1) or match.group(2)
        if name not in os.environ or not os.environ[name]:
            raise ManifestError(path, "root", f"environment variable {name} is not set: set it to the folder "
                                              "that holds the takes")
        return os.environ[name]

    root = base_dir / Path(_ENV_REFERENCE.sub(expand, text)).expanduser()
    try:
        found = root.is_dir()
    except (OSError, ValueError) as e:
        raise ManifestError(path, "root", f"cannot use the path ({getattr(e, 'strerror', None) or e})") from None
    if not found:
        raise ManifestError(path, "root", f"no such folder: {root}")
    return root


MAX_SCHEMA_BYTES = 1 << 20


def _feature_schema(path, base_dir: Path, value) -> tuple[list[dict], Path | None]:
    """The manifest's ``features``: a list of channel tables, or a JSON file (relative path) holding one
    (a list, or a table with a ``features`` list). Errors name the file and field."""
    source, file = path, None
    if isinstance(value, str):
        _text(path, "features", value, MAX_PATH_CHARS)
        try:
            file = resolved(base_dir / value)
            # a regular file of at most MAX_SCHEMA_BYTES (a FIFO or /dev/zero is refused before reading)
            text = read_limited(file, MAX_SCHEMA_BYTES, "feature schema").decode("utf-8")
        except (OSError, UnicodeDecodeError, ValueError) as e:
            raise ManifestError(path, "features", f"cannot read the feature schema {value!r} "
                                f"({getattr(e, 'strerror', None) or e})") from None
        value = _parse_json(file, text)
        if _nesting(value) > MAX_NESTING:
            raise ManifestError(file, "<top>", f"lists and tables nested deeper than {MAX_NESTING} levels")
        if isinstance(value, dict) and set(value) <= {"features", "format", "version", "description"}:
            value = value.get("features")
        source = file
    try:
        layout = layout_from_schema(value, "features")
    except SchemaError as e:
        raise ManifestError(source, e.field, e.message) from None
    return schema_of(layout), file


def _parse_json(path, text: str):
    """JSON text -> data; every failure (syntax, nesting past the recursion limit, a number past
    Python's digit limit) is a ManifestError naming the file and line, never the text itself."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise ManifestError(path, "<file>", f"invalid JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    except RecursionError:
        raise ManifestError(path, "<file>", f"lists and tables nested deeper than {MAX_NESTING} levels") from None
    except ValueError:  # e.g. an integer of more than 4300 digits
        raise ManifestError(path, "<file>", "invalid JSON: a number too long to read") from None


def load_manifest(path) -> Manifest:
    path = Path(path)
    try:
        with open_regular(path, "manifest") as f:   # a FIFO or a device is refused, never waited on
            raw = f.read(MAX_MANIFEST_BYTES + 1)
    except NotRegularFileError as e:
        raise ManifestError(path, "<file>", str(e).split(": ", 1)[-1]) from None
    except (OSError, ValueError) as e:  # ValueError: a NUL in the path
        raise ManifestError(path, "<file>", f"cannot read: {getattr(e, 'strerror', None) or e}") from None
    if len(raw) > MAX_MANIFEST_BYTES:
        raise ManifestError(path, "<file>", f"larger than {MAX_MANIFEST_BYTES} bytes: expected a manifest")
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
            raise ManifestError(path, "<file>", f"invalid TOML: {str(e)[:200]}") from None
        except RecursionError:
            raise ManifestError(path, "<file>", f"lists and tables nested deeper than {MAX_NESTING} levels") from None
        except ValueError:
            raise ManifestError(path, "<file>", "invalid TOML: a number too long to read") from None
    else:
        data = _parse_json(path, text)
    return parse_manifest(data, path=path.resolve())
