"""Controller-state checkpoints: seeking in a session without replaying it from its start.

A checkpoint holds what a controller changes as it steps, so that restoring it into the same controller
(the one a :class:`lmm.session.seek.SessionSeeker` built) and stepping on gives the recorded poses bit for
bit (tested against the fingerprints). It is taken attribute by attribute, not with a plain deep copy:

* arrays and small objects are copied, arrays that are views of one buffer staying views of one buffer
  (the LMM state is a view of the buffer its bound network calls read; inertialization offsets are views
  of their decay's stacked array, see :meth:`lmm.inertialize.Offsets.__deepcopy__`); on restore the
  controller's own buffers get the values in place, so its bound calls (not copied) still read them;
* the tuning, database, features, networks and anything of :data:`SHARED_BYTES` or more are kept by
  reference with their attributes as they were: what changes in them is rebound, not written in place (new
  feature weights make a new normalised array and the search index rebuilds on it; a search result is
  replaced), and so are the arrays these hold (an object that refers to one, such as MM's lazily ranked
  candidates, is small: it is kept by reference, not copied with a 6 MB feature array). Only references
  are kept, so a checkpoint of the default database's MM or LMM controller is 40-70 KB
  (``bench/session_seek.py``); objects and slots are walked alike.
"""
from __future__ import annotations

import copy
import functools
import types

import numpy as np

_CALLS = (types.FunctionType, types.MethodType, types.BuiltinFunctionType, functools.partial)

#: attributes holding this many bytes or more are kept by reference (read-only while a session plays)
SHARED_BYTES = 64 * 1024
#: attributes a checkpoint does not keep: MM's last full search result (6 MB on the default database),
#: replaced at every search and read by no later step; kept by reference it would pin one per checkpoint
NOT_KEPT = frozenset({"last_search"})


def _nbytes(value, seen: set, limit: int) -> int:
    """Bytes of the arrays ``value`` holds (stops counting past ``limit``)."""
    if id(value) in seen:
        return 0
    seen.add(id(value))
    if isinstance(value, np.ndarray):
        return value.nbytes
    items = ()
    if isinstance(value, dict):
        items = value.values()
    elif isinstance(value, (list, tuple)):
        items = value
    elif not isinstance(value, (_CALLS, str, bytes, int, float, bool, type(None))):
        items = _fields(value)
    total = 0
    for v in items:
        total += _nbytes(v, seen, limit)
        if total >= limit:
            break
    return total


def _fields(value):
    """An object's attribute values: its ``__dict__`` and its ``__slots__``."""
    if hasattr(value, "__dict__"):
        yield from vars(value).values()
    for cls in type(value).__mro__:
        for name in getattr(cls, "__slots__", ()):
            if hasattr(value, name):
                yield getattr(value, name)


def _base(a: np.ndarray) -> np.ndarray:
    while isinstance(a.base, np.ndarray):
        a = a.base
    return a


def _arrays(value, skip: set, out: dict) -> None:
    """Every array reachable from ``value`` (through dicts, lists, tuples and objects' attributes), by id."""
    if id(value) in skip or id(value) in out:
        return
    if isinstance(value, np.ndarray):
        out[id(value)] = value
        return
    skip.add(id(value))
    if isinstance(value, dict):
        items = value.values()
    elif isinstance(value, (list, tuple)):
        items = value
    elif isinstance(value, functools.partial):
        items = (*value.args, *value.keywords.values())
    elif not isinstance(value, (_CALLS, str, bytes, int, float, bool, type(None))):
        items = _fields(value)
    else:
        return
    for v in items:
        _arrays(v, skip, out)


def _copy_keeping_views(value, memo: dict, bases: dict):
    """``copy.deepcopy(value, memo)`` where arrays that are views of one buffer stay views of one buffer:
    ``bases`` maps a buffer's id to the buffer its copy uses (a new copy unless given)."""
    arrays: dict = {}
    _arrays(value, set(memo), arrays)
    for a in arrays.values():
        b = _base(a)
        target = bases.get(id(b))
        if target is None:
            target = bases[id(b)] = b.copy()
        if a is b:
            memo[id(a)] = target
        else:
            offset = a.__array_interface__["data"][0] - b.__array_interface__["data"][0]
            memo[id(a)] = np.ndarray(a.shape, a.dtype, buffer=target, offset=offset, strides=a.strides)
    return copy.deepcopy(value, memo)


def _keep_arrays_of(obj, keep: dict) -> None:
    """Keep the arrays ``obj`` holds by reference too (e.g. the features' normalised array, which a ranked
    candidate list refers to as well)."""
    if isinstance(obj, np.ndarray):
        return
    for value in _fields(obj):
        if isinstance(value, np.ndarray):
            keep.setdefault(id(value), value)


class ControllerState:
    """What ``controller`` holds that stepping changes, taken now (:meth:`restore` puts it back)."""

    def __init__(self, controller):
        # the controller itself too: what refers back to it (MM's lazily ranked candidates) keeps referring to it
        keep = {id(o): o for o in (controller, controller.tuning, controller.db, controller.features)}
        _keep_arrays_of(controller.db, keep)
        _keep_arrays_of(controller.features, keep)
        for value in vars(controller).values():
            # (the bytes of what is kept already are not counted: an object that only refers to them is small)
            if id(value) not in keep and _nbytes(value, set(keep), SHARED_BYTES) >= SHARED_BYTES:
                keep[id(value)] = value
                _keep_arrays_of(value, keep)
        self._shared = keep                 # a deep copy's memo: these are not copied
        self._source = id(controller)
        attributes = {n: v for n, v in vars(controller).items() if n not in NOT_KEPT}
        own = {n: v for n, v in attributes.items() if id(v) not in keep and not isinstance(v, _CALLS)}
        self.shared = {n: v for n, v in attributes.items() if id(v) in keep and v is not controller}
        # their attributes as they are now (references): what changes in them is rebound, not written in
        # place (new feature weights make a new normalised array; a search index rebuilds on it)
        self.shared_attributes = {n: dict(vars(v)) for n, v in self.shared.items()
                                  if hasattr(v, "__dict__") and v is not controller.tuning}
        self.values = _copy_keeping_views(own, dict(keep), {})
        found: dict = {}
        _arrays(self.values, set(keep), found)
        self.nbytes = sum(b.nbytes for b in {id(_base(a)): _base(a) for a in found.values()}.values())

    def restore(self, controller) -> None:
        """Put the state back into ``controller`` (the one it was taken from): its buffers (the arrays its
        bound network calls write) get the values in place, and views of them stay views."""
        self._put_values(controller, self._shared)
        current = vars(controller)
        current.update(self.shared)
        for name, attributes in self.shared_attributes.items():
            vars(current[name]).update(attributes)

    def transplant(self, controller) -> None:
        """Put the state into another controller of the same kind, built on the same database and networks
        file (a branch's own: :meth:`lmm.session.seek.SessionSeeker.branched`). The objects of its own that
        have attributes (its tuning, features, search index, networks) stay its own, and what the copied
        values refer to among them is mapped to them by attribute name; give it the state's tuning next, so
        that it re-derives them (as :meth:`restore`'s caller does). The other values kept by reference
        (arrays, tuples, a search's ranked list: never written once made) are shared."""
        current = vars(controller)
        memo = dict(self._shared)
        memo[self._source] = controller
        own_objects = {n: v for n, v in self.shared.items()
                       if hasattr(v, "__dict__") and type(current.get(n)) is type(v)}
        for name, value in own_objects.items():
            memo[id(value)] = current[name]
            target = vars(current[name])
            for attribute, old in self.shared_attributes.get(name, {}).items():
                if id(old) in memo and attribute in target:
                    memo[id(old)] = target[attribute]
        self._put_values(controller, memo)
        current.update({n: v for n, v in self.shared.items() if n not in own_objects})

    def _put_values(self, controller, memo: dict) -> None:
        """The copied values into ``controller``; the arrays it has already get them in place."""
        current = vars(controller)
        bases = {}
        for name, value in self.values.items():
            live = current.get(name)
            if isinstance(value, np.ndarray) and isinstance(live, np.ndarray):
                src, dst = _base(value), _base(live)
                if src.shape == dst.shape and src.dtype == dst.dtype:
                    bases[id(src)] = dst
        for src_id, dst in bases.items():
            src = next(_base(v) for v in self.values.values() if isinstance(v, np.ndarray) and id(_base(v)) == src_id)
            np.copyto(dst, src)
        current.update(_copy_keeping_views(self.values, dict(memo), bases))
