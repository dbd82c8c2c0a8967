"""Every tunable of the character pipeline, in one typed object the controller reads on every step.

The studio builds its grouped sliders from the field metadata::

    for group in Tuning.groups():
        for f in Tuning.fields_in(group):
            f.name, f.type, f.metadata["min"], f.metadata["max"], f.metadata["unit"], f.metadata["doc"]

``min``/``max`` are the slider range and also the accepted range of :meth:`Tuning.from_dict`,
:meth:`Tuning.set` (one field, what a slider calls) and :meth:`Tuning.validate`: validation lives here only. Nothing reads a tunable once and keeps it: a value changed between two steps
acts on the next step.

Every change is announced on ``tuning.events`` as a :class:`TuningChange` (field, channel, old, new),
whatever made it (:meth:`Tuning.set`, a preset, a reset, an attribute or dict entry written directly)::

    tuning.events.connect(callback)     # callback(change: TuningChange); a bound method is held weakly

Controllers, panels, undo and the session log subscribe instead of polling. The runtime only reads a
tuning: a per-name entry it does not name (a database's own channel or tag) counts as the default the
controller knows (the schema's weight, no bias, not excluded).

Defaults follow the reference demo (see ``notes/reference.md``) except where the shipped data asks for
something else: the locomotion set is LAFAN1 at its captured speed, whose root speeds reach about
3.5 m/s forward, 2 m/s sideways and 1 m/s backwards, so the run speeds are lowered to what the data
covers (a query asking for speeds the database does not hold only makes matching worse).
"""
from __future__ import annotations

import dataclasses
import json
import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from lmm.events import Emitter

from lmm.errors import InputError
from lmm.features import DEFAULT_LAYOUT

GROUPS = ("simulation", "speeds", "inertialization", "features", "search", "sync", "ik")


class TuningError(InputError):
    """A bad tuning value or preset; the message names the field (and the preset file, when from one)."""


def _f(default, group, lo, hi, unit, doc):
    return field(default=default, metadata={"group": group, "min": lo, "max": hi, "unit": unit, "doc": doc})


def _default_feature_weights() -> dict[str, float]:
    return {ch.name: float(ch.weight) for ch in DEFAULT_LAYOUT}


# the tags of the shipped data; a controller adds any other tag of its database with bias 0
DEFAULT_TAGS = ("idle", "walk", "jog", "run", "strafe", "turn", "stop", "crouch")
# the shipped data's crouched runs and walks (multipleActions1_subject3) play only when they match clearly
# better: a character asked to run should run upright
DEFAULT_TAG_BIAS = {"crouch": 1.0}
IDLE_TAG = "idle"  # the tag of the idle set (see Tuning.idle_set_enabled)
#: Largest preset file read (bytes): a full preset is about 2 KB; 1 MB leaves room for many channels/tags.
MAX_PRESET_BYTES = 1024 * 1024


def _default_tag_bias() -> dict[str, float]:
    return {t: DEFAULT_TAG_BIAS.get(t, 0.0) for t in DEFAULT_TAGS}


def _default_tag_excluded() -> dict[str, bool]:
    return {t: False for t in DEFAULT_TAGS}


@dataclass(frozen=True)
class TuningChange:
    """One change of a tuning value: ``field`` (a field name), ``channel`` (the entry of a per-name field,
    else None), and the values before and after (None for an entry that did not exist / was removed)."""
    field: str
    channel: str | None
    old: Any
    new: Any


_MISSING = object()


class Entries(dict):
    """The entries of a per-name field (``feature_weights``, ``tag_bias``, ``tag_excluded``): a dict whose
    every write is announced, so an entry written in place reaches the subscribers as a slider's does."""

    __slots__ = ("_announce",)

    def __init__(self, *args, announce: Callable[[str, Any, Any], None] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self._announce = announce

    def __setitem__(self, key, value) -> None:
        old = self.get(key, _MISSING)
        super().__setitem__(key, value)
        if self._announce is not None and (old is _MISSING or old != value or type(old) is not type(value)):
            self._announce(key, None if old is _MISSING else old, value)

    def __delitem__(self, key) -> None:
        old = self[key]
        super().__delitem__(key)
        if self._announce is not None:
            self._announce(key, old, None)

    def pop(self, key, *default):
        if key not in self:
            return super().pop(key, *default)
        old = self[key]
        del self[key]
        return old

    def popitem(self):
        key = next(reversed(self))
        return key, self.pop(key)

    def clear(self) -> None:
        for key in list(self):
            del self[key]

    def setdefault(self, key, default=None):
        if key not in self:
            self[key] = default
        return self[key]

    def update(self, *args, **kwargs) -> None:
        for key, value in dict(*args, **kwargs).items():
            self[key] = value

    def __ior__(self, other):
        self.update(other)
        return self

    def __reduce__(self):
        return dict, (dict(self),)


@dataclass
class Tuning:
    # -- simulation object: springs and stick --------------------------------------------------------
    simulation_velocity_halflife_s: float = _f(
        0.27, "simulation", 0.0, 0.5, "s", "Halflife of the velocity spring that moves the simulation object.")
    simulation_rotation_halflife_s: float = _f(
        0.27, "simulation", 0.0, 0.5, "s", "Halflife of the rotation spring that turns the simulation object.")
    stick_deadzone: float = _f(
        0.2, "simulation", 0.0, 0.9, "", "Stick magnitudes below this count as zero; above it the stick is "
        "rescaled so full deflection still gives full speed.")
    # -- speeds ---------------------------------------------------------------------------------------
    run_forward_speed_m_s: float = _f(3.5, "speeds", 0.0, 6.0, "m/s", "Running speed straight ahead.")
    run_sideways_speed_m_s: float = _f(2.0, "speeds", 0.0, 6.0, "m/s", "Running speed to the side (strafing).")
    run_backwards_speed_m_s: float = _f(1.25, "speeds", 0.0, 6.0, "m/s", "Running speed backwards (strafing).")
    walk_forward_speed_m_s: float = _f(1.5, "speeds", 0.0, 4.0, "m/s", "Walking speed straight ahead.")
    walk_sideways_speed_m_s: float = _f(1.25, "speeds", 0.0, 4.0, "m/s", "Walking speed to the side.")
    walk_backwards_speed_m_s: float = _f(1.0, "speeds", 0.0, 4.0, "m/s", "Walking speed backwards.")
    # -- inertialization ------------------------------------------------------------------------------
    inertialization_halflife_s: float = _f(
        0.1, "inertialization", 0.0, 0.3, "s", "Halflife of the offsets that blend out a pose jump (0: no blend).")
    inertialization_slow_halflife_s: float = _f(
        0.2, "inertialization", 0.0, 0.5, "s", "Halflife of the offsets while the simulation object stands still, "
        "blended to the halflife above at 1 m/s: a jump while standing, starting or stopping blends out slowly, "
        "without a jerk (0: the halflife above at every speed).")
    # -- feature weights ------------------------------------------------------------------------------
    feature_weights: dict = field(default_factory=_default_feature_weights, metadata={
        "group": "features", "min": 0.0, "max": 5.0, "unit": "",
        "doc": "Weight of each feature channel (channel name -> weight); 0 ignores the channel."})
    # -- search ---------------------------------------------------------------------------------------
    search_interval_s: float = _f(
        0.1, "search", 0.0, 1.0, "s", "Time between searches (0: search every step).")
    forced_search_threshold: float = _f(
        50.0, "search", 0.0, 500.0, "m/s^2 | rad/s^2", "A search is forced when the rate of change of the "
        "desired velocity or rotation has exceeded this and drops back under it (a sharp input change).")
    transition_cost: float = _f(
        0.0, "search", 0.0, 10.0, "cost", "Added to every candidate except the continuing pose (bias to keep playing).")
    exclude_current_window_frames: int = _f(
        20, "search", 0, 120, "frames", "Frames within this many of the playing frame are not candidates "
        "(the playing frame itself competes as the continuing pose).")
    exclude_range_end_frames: int = _f(
        20, "search", 0, 120, "frames", "The last frames of every clip range are not candidates.")
    top_k: int = _f(8, "search", 1, 64, "", "Number of ranked candidates kept for the debugger.")
    accelerated_search: bool = _f(
        True, "search", False, True, "", "Use the exact accelerated search (else brute force; same answer).")
    tag_bias: dict = field(default_factory=_default_tag_bias, metadata={
        "group": "search", "min": -5.0, "max": 5.0, "unit": "cost",
        "doc": "Cost added to every candidate whose range has the tag (tag -> cost; negative prefers it, "
               "a frame with several tags gets the sum)."})
    tag_excluded: dict = field(default_factory=_default_tag_excluded, metadata={
        "group": "search", "min": False, "max": True, "unit": "", "item": "bool",
        "doc": "Tags whose ranges are never candidates (tag -> true): a filter, where a bias is only a cost. "
               "The frame being played leaves at the next search. Motion matching's search only (the "
               "learned networks learned the unfiltered search). Excluding every candidate frame: an "
               "error and no exclusion."})
    idle_set_enabled: bool = _f(
        True, "search", False, True, "", "When the stick has been released for idle_delay_s, search only frames "
        "tagged 'idle' (as UE's chooser and MxM's idle sets); no such frame: an error and every frame.")
    idle_delay_s: float = _f(
        0.75, "search", 0.0, 5.0, "s", "Time without stick input before the search is restricted to the idle set.")
    idle_follow_take: bool = _f(
        True, "search", False, True, "", "Learned motion matching in the idle set: each search between jumps sets "
        "the state to the idle take's frame that the playing one has reached (the stand follows the take, as motion "
        "matching's does, instead of drifting with the stepper); a continuation, not a projector jump.")
    # -- keeping character and simulation together -----------------------------------------------------
    adjustment_enabled: bool = _f(
        True, "sync", False, True, "", "Pull the character root towards the simulation object every step.")
    adjustment_position_halflife_s: float = _f(
        0.1, "sync", 0.0, 1.0, "s", "Halflife of the position adjustment.")
    adjustment_rotation_halflife_s: float = _f(
        0.2, "sync", 0.0, 1.0, "s", "Halflife of the rotation adjustment.")
    adjustment_by_velocity: bool = _f(
        True, "sync", False, True, "", "Cap the adjustment by the character's own speed, so it never slides in place.")
    adjustment_max_speed_ratio: float = _f(
        0.5, "sync", 0.0, 2.0, "", "Cap: at most this fraction of the character's speed (and angular speed) times dt.")
    clamping_enabled: bool = _f(
        True, "sync", False, True, "", "Never let the character root get further than the limits below "
        "from the simulation object.")
    clamp_max_distance_m: float = _f(
        0.15, "sync", 0.0, 1.0, "m", "Largest distance between character root and simulation object.")
    clamp_max_angle_deg: float = _f(
        90.0, "sync", 0.0, 180.0, "deg", "Largest facing difference between character root and simulation object.")
    # -- foot locking and two-bone IK -----------------------------------------------------------------
    ik_enabled: bool = _f(
        True, "ik", False, True, "", "Foot locking with two-bone leg IK.")
    ik_ground_calibration: bool = _f(
        True, "ik", False, True, "", "Shift each take's poses vertically so its planted toes sit at foot height "
        "(mocap takes differ by a few centimetres in floor calibration: feet in the floor or floating).")
    ik_counter_adjustment: bool = _f(
        True, "ik", False, True, "", "Feet near the ground do not follow the root adjustment and clamping "
        "(the body is pulled towards the simulation object, the legs absorb it), so they are not dragged.")
    ik_swing_clearance_m: float = _f(
        0.03, "ik", 0.0, 0.1, "m", "A swinging (unlocked) toe moving faster than 0.5 m/s is lifted to at least this "
        "above foot height (full at 1.5 m/s) and never below foot height, so it does not skim the ground (0: off).")
    ik_unlock_radius_m: float = _f(
        0.2, "ik", 0.0, 0.5, "m", "A locked foot unlocks once the animation has moved this far from the lock.")
    ik_blend_halflife_s: float = _f(
        0.1, "ik", 0.0, 0.5, "s", "Halflife of the blend back to the animated foot after unlocking.")
    ik_step_halflife_s: float = _f(
        0.2, "ik", 0.0, 0.5, "s", "Halflife of the blend back after a release by the unlock radius (a step: the "
        "foot is far behind its animation and catches up more slowly, 0: the blend halflife above).")
    ik_lock_follow_m_s: float = _f(
        0.0, "ik", 0.0, 1.0, "m/s", "A locked foot creeps after its animated toe at up to this speed (below the 0.3 m/s "
        "that reads as skating), so less is left to catch up when it lets go (0: held still).")
    ik_foot_height_m: float = _f(
        0.02, "ik", 0.0, 0.2, "m", "Toe joint height above the contact point; a locked toe is kept at least "
        "this high above the ground.")
    ik_toe_length_m: float = _f(
        0.15, "ik", 0.0, 0.3, "m", "Length from the toe joint to the tip of the foot; the tip is kept above "
        "the ground by rotating the toe.")
    ik_lift_height_m: float = _f(
        0.01, "ik", 0.0, 0.2, "m", "After its contact ends a locked foot stays locked until the animated toe "
        "has risen this far; an unlocked foot less than this above its last lock is near the ground.")
    ik_ground_blend_speed_m_s: float = _f(
        0.1, "ik", 0.0, 2.0, "m/s", "Fastest horizontal blend of an unlocked foot near the ground back to the "
        "animation; the rest of the blend happens in the air, so the foot does not glide.")
    ik_ground_blend_acceleration_m_s2: float = _f(
        10.0, "ik", 0.0, 100.0, "m/s2", "That speed limit is reached with at most this acceleration, so a foot released "
        "at rest does not take the animation's speed in one tick (0: at once).")
    ik_step_height_m: float = _f(
        0.04, "ik", 0.0, 0.2, "m", "A foot unlocked by the unlock radius (the last resort, during a contact) "
        "steps back to the animation with about this much lift instead of sliding.")
    ik_idle_unlock_radius_m: float = _f(
        0.08, "ik", 0.0, 0.5, "m", "Standing (the stick released longer than the idle delay), a locked foot steps to "
        "the animation once it is this far from it, so a stop ends in the idle's stance, not a frozen stride (0: off).")
    ik_lock_max_speed_m_s: float = _f(
        1.0, "ik", 0.0, 10.0, "m/s", "A foot locks when its contact begins only once its toe moves slower than "
        "this: a transition that brings a contact to a swinging foot would otherwise freeze it mid-swing (a pop).")
    ik_min_knee_deg: float = _f(
        7.0, "ik", 0.0, 45.0, "deg", "The IK never bends a knee straighter than this (the data's straightest "
        "knee is about 6 degrees) unless the animation itself is.")
    ik_knee_max_acceleration_deg_s2: float = _f(
        16500.0, "ik", 0.0, 100000.0, "deg/s2", "The IK's knees never accelerate harder than this (the data's "
        "knees stay under about 19,000 deg/s2): a leg let go by its lock catches up smoothly (0: no limit).")
    ik_soft_reach_m: float = _f(
        0.06, "ik", 0.0, 0.1, "m", "Soft reach: over this last distance before the longest leg, the leg "
        "approaches it smoothly instead of snapping straight (0: a hard limit).")

    # -- change events ------------------------------------------------------------------------------
    def __post_init__(self):
        object.__setattr__(self, "events", Emitter())

    def __setattr__(self, name: str, value) -> None:
        """Store a field's value (a per-name field as :class:`Entries`) and announce what changed."""
        if name not in _FIELD_NAMES:
            object.__setattr__(self, name, value)
            return
        old = self.__dict__.get(name, _MISSING)
        if isinstance(value, dict):
            value = Entries(value, announce=lambda key, o, n, name=name: self._announce(name, key, o, n))
        object.__setattr__(self, name, value)
        if old is _MISSING:
            return
        if isinstance(value, dict):
            old = old if isinstance(old, dict) else {}
            for key in [*old, *(k for k in value if k not in old)]:
                o, n = old.get(key), value.get(key)
                if o != n or type(o) is not type(n):
                    self._announce(name, key, o, n)
        elif old != value or type(old) is not type(value):
            self._announce(name, None, old, value)

    def _announce(self, name: str, channel, old, new) -> None:
        events = self.__dict__.get("events")
        if events is not None:
            events.emit(TuningChange(name, channel, old, new))

    # -- introspection ------------------------------------------------------------------------------
    @staticmethod
    def groups() -> tuple[str, ...]:
        return GROUPS

    @classmethod
    def fields_in(cls, group: str) -> list[dataclasses.Field]:
        if group not in GROUPS:
            raise TuningError(f"unknown tuning group {group!r} (groups: {', '.join(GROUPS)})")
        return [f for f in dataclasses.fields(cls) if f.metadata["group"] == group]

    @classmethod
    def field_info(cls, name: str) -> dataclasses.Field:
        for f in dataclasses.fields(cls):
            if f.name == name:
                return f
        raise TuningError(f"unknown tuning field {name!r}")

    def set(self, name: str, value, channel: str | None = None) -> None:
        """Set one field, checked and converted as a preset value is (an integer field takes ``12.0`` as
        12); for a per-name field (``feature_weights``, ``tag_bias``, ``tag_excluded``) pass ``channel``
        to set one entry. Raises :class:`TuningError` naming the field (``feature_weights.CHANNEL``) and
        its range, and leaves the tuning unchanged, for an unknown field or entry, a wrong type or a value
        out of range."""
        f = self.field_info(name)
        if channel is None:
            setattr(self, name, _check(f, value))
            return
        entries = getattr(self, name)
        if not isinstance(entries, dict):
            raise TuningError(f"tuning field {name!r} has no channels (got channel {channel!r})")
        if channel not in entries:
            what = "channel" if name == "feature_weights" else "tag"
            raise TuningError(f"tuning field {name!r}: unknown {what} {str(channel)[:80]!r} "
                              f"({what}s: {', '.join(entries) or 'none'})")
        entries[channel] = _entry(f, channel, value)

    def name_database_entries(self, channel_weights: dict, tags) -> None:
        """Give a database's feature channels (name -> schema weight) and tags the entries this tuning
        lacks, at the values a controller uses for an unnamed entry (so nothing acts differently), so
        that :meth:`set` and the studio's sliders can set them. The studio calls this; a controller never
        writes into the tuning it reads."""
        for name, weight in channel_weights.items():
            self.feature_weights.setdefault(name, float(weight))
        for tag in tags:
            self.tag_bias.setdefault(tag, self.neutral_entry("tag_bias"))
            self.tag_excluded.setdefault(tag, self.neutral_entry("tag_excluded"))

    def reset_group(self, group: str) -> None:
        """Put every field of ``group`` back to its default."""
        fresh = Tuning()
        for f in self.fields_in(group):
            setattr(self, f.name, self._kept_entries(f, getattr(fresh, f.name)))

    def assign(self, other: "Tuning") -> None:
        """Take every value of ``other`` (a loaded preset) in place, so the controllers sharing this object
        see it at their next step. A per-name entry ``other`` lacks (a database's own feature channel or
        tag, added by the controllers) is kept, reset as :meth:`reset_group` resets it."""
        for f in dataclasses.fields(self):
            setattr(self, f.name, self._kept_entries(f, getattr(other, f.name)))

    def _kept_entries(self, f: dataclasses.Field, value):
        """``value`` for field ``f``; for a per-name field, with this tuning's other entries kept: a custom
        channel keeps its weight, a custom tag goes back to no bias and not excluded."""
        if not isinstance(value, dict):
            return value
        merged = {k: w if f.name == "feature_weights" else self.neutral_entry(f.name)
                  for k, w in getattr(self, f.name).items()}
        merged.update(value)
        return merged

    @classmethod
    def neutral_entry(cls, name: str):
        """The entry of per-name field ``name`` that changes nothing (0.0, or False for true/false
        entries): what a tag or channel the field does not name counts as."""
        return _NEUTRAL[cls.field_info(name).metadata.get("item", "float")]

    def excluded_tags(self, tags) -> tuple[str, ...]:
        """Those of ``tags`` (a database's, in its order) that ``tag_excluded`` excludes."""
        on = self.tag_excluded
        return tuple(t for t in tags if on.get(t, False))

    def copy(self) -> "Tuning":
        return Tuning.from_dict(self.to_dict())

    # -- (de)serialisation with validation ----------------------------------------------------------
    def to_dict(self) -> dict:
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = dict(v) if isinstance(v, dict) else v
        return out

    @classmethod
    def from_dict(cls, d: dict, base: "Tuning | None" = None, channels=None) -> "Tuning":
        """A tuning from a (possibly partial) dict; missing fields keep ``base``'s (or default) values, and
        so do the entries a per-name field (feature weights, tag biases, excluded tags) does not name.
        ``channels``: when given, the feature channel names ``feature_weights`` may name (the database's
        feature schema); a name outside it is an error (a typo would otherwise be silently ignored)."""
        if not isinstance(d, dict):
            raise TuningError(f"a tuning preset must be a JSON object, got {type(d).__name__}")
        t = base.copy() if base is not None else cls()
        names = {f.name: f for f in dataclasses.fields(cls)}
        for key, value in d.items():
            if key not in names:
                raise TuningError(f"unknown tuning field {key[:80]!r}")
            value = _check(names[key], value)
            if isinstance(value, dict):    # a per-name field: the entries named change, the others stay
                value = {**getattr(t, key), **value}
            setattr(t, key, value)
        fw = d.get("feature_weights")
        if fw is not None and not fw:
            raise TuningError("tuning field 'feature_weights': empty; name channels to change (channel -> weight) "
                              "or leave the field out to keep the defaults")
        if fw and channels is not None:
            known = list(channels)
            unknown = [k for k in fw if k not in known]
            if unknown:
                raise TuningError(f"tuning field 'feature_weights.{unknown[0][:80]}': no such feature channel "
                                  f"(channels: {', '.join(known)})")
        return t

    def validate(self) -> None:
        """Raise :class:`TuningError` naming the first field with a bad type or out-of-range value."""
        for f in dataclasses.fields(self):
            _check(f, getattr(self, f.name))

    def save(self, path) -> None:
        from lmm.data.jsonio import write_json

        write_json(path, self.to_dict())

    @staticmethod
    def read_preset(path) -> dict:
        """The JSON object of a preset file, read safely (size, depth, UTF-8; see :mod:`lmm.data.jsonio`)."""
        from lmm.data.jsonio import JsonError, read_json

        try:
            d = read_json(path, "tuning preset", max_bytes=MAX_PRESET_BYTES)
        except JsonError as e:
            raise TuningError(str(e)) from None
        if not isinstance(d, dict):
            raise TuningError(f"{path}: a tuning preset must be a JSON object, got {type(d).__name__}")
        return d

    @classmethod
    def from_preset(cls, d: dict, path, channels=None) -> "Tuning":
        """:meth:`from_dict` with errors naming the preset file ``path``."""
        try:
            return cls.from_dict(d, channels=channels)
        except TuningError as e:
            raise TuningError(f"{path}: {e}") from None

    @classmethod
    def load(cls, path, channels=None) -> "Tuning":
        """A preset file; every problem is a :class:`TuningError` naming the file and the field.
        ``channels``: the feature channel names ``feature_weights`` may name (see :meth:`from_dict`)."""
        return cls.from_preset(cls.read_preset(path), path, channels)


_FIELD_NAMES = frozenset(f.name for f in dataclasses.fields(Tuning))

#: Most entries in a per-name field (feature_weights, tag_bias, tag_excluded): a schema has ~10 channels, a
#: database a handful of tags. Names are channel or tag names, short identifiers.
MAX_DICT_ENTRIES = 1000
MAX_NAME_CHARS = 100


def _check(f: dataclasses.Field, value):
    """The value converted to the field's type, or TuningError naming the field."""
    lo, hi = f.metadata["min"], f.metadata["max"]
    kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
    if kind == "bool":
        if not isinstance(value, bool):
            raise TuningError(f"tuning field {f.name!r}: expected true or false, got {_short(value)}")
        return value
    if kind == "dict":
        if not isinstance(value, dict):
            item = "true or false" if f.metadata.get("item") == "bool" else "number"
            raise TuningError(f"tuning field {f.name!r}: expected an object of name -> {item}, got {_short(value)}")
        if len(value) > MAX_DICT_ENTRIES:
            raise TuningError(f"tuning field {f.name!r}: {len(value)} entries, more than {MAX_DICT_ENTRIES}")
        out = {}
        for k, w in value.items():
            if not isinstance(k, str) or not 0 < len(k) <= MAX_NAME_CHARS:
                raise TuningError(f"tuning field {f.name!r}: names must be strings of 1 to {MAX_NAME_CHARS} "
                                  f"characters, got {str(k)[:40]!r}")
            out[k] = _entry(f, k, w)
        return out
    return _number(f.name, value, lo, hi, integer=(kind == "int"))


#: The value of a per-name field's entry that changes nothing, by the field's item type.
_NEUTRAL = {"float": 0.0, "bool": False}


def _entry(f: dataclasses.Field, name: str, value):
    """One entry of a per-name field (``field.name``), checked and converted, or TuningError naming it."""
    if f.metadata.get("item") == "bool":
        if not isinstance(value, bool):
            raise TuningError(f"tuning field '{f.name}.{name}': expected true or false, got {_short(value)}")
        return value
    return _number(f"{f.name}.{name}", value, f.metadata["min"], f.metadata["max"], integer=False)


def _short(value, limit: int = 40) -> str:
    """``repr(value)`` cut to ``limit`` characters for an error message."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _number(name, value, lo, hi, integer):
    if isinstance(value, bool) or not isinstance(value, numbers.Real):  # numpy scalars are Real too
        raise TuningError(f"tuning field {name!r}: expected a number, got {_short(value)}")
    try:
        float(value)
    except OverflowError:  # an integer beyond float range (JSON allows 4300 digits)
        raise TuningError(f"tuning field {name!r}: a {len(str(abs(int(value))))}-digit number is outside "
                          f"[{lo}, {hi}]") from None
    if integer:
        if not float(value).is_integer():
            raise TuningError(f"tuning field {name!r}: expected an integer, got {_short(value)}")
        value = int(value)
    else:
        value = float(value)
        if not math.isfinite(value):
            raise TuningError(f"tuning field {name!r}: expected a finite number, got {_short(value)}")
    if not lo <= value <= hi:
        raise TuningError(f"tuning field {name!r}: {value!r} is outside [{lo}, {hi}]")
    return value
