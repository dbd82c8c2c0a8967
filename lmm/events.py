"""A minimal change-event emitter (napari's ``events`` in a few lines, no Qt): a model owns an
:class:`Emitter`, views and controllers ``connect`` a callback and are called with each event.

A bound method is held through a weak reference, so a controller or panel that is dropped (a
replaced LMM controller, a closed panel) stops being called and is not kept alive by the model it
listened to; a plain function or lambda is held strongly until :meth:`Emitter.disconnect`.
"""
from __future__ import annotations

import types
import weakref
from typing import Callable, Generic, TypeVar

E = TypeVar("E")


class Emitter(Generic[E]):
    """Calls every connected callback with each emitted event, in the order they were connected."""

    def __init__(self) -> None:
        self._callbacks: list = []       # weakref.WeakMethod or a callable

    def connect(self, callback: Callable[[E], None]) -> Callable[[E], None]:
        """Call ``callback(event)`` on every :meth:`emit` from now on; returns ``callback`` (a decorator)."""
        self.disconnect(callback)
        ref = weakref.WeakMethod(callback) if isinstance(callback, types.MethodType) else callback
        self._callbacks.append(ref)
        return callback

    def disconnect(self, callback: Callable[[E], None]) -> None:
        """Stop calling ``callback`` (nothing happens when it is not connected)."""
        self._callbacks = [c for c in self._callbacks if self._resolve(c) not in (None, callback)]

    def emit(self, event: E) -> None:
        dead = False
        for ref in list(self._callbacks):
            callback = self._resolve(ref)
            if callback is None:
                dead = True
            else:
                callback(event)
        if dead:
            self._callbacks = [c for c in self._callbacks if self._resolve(c) is not None]

    def __len__(self) -> int:
        return sum(self._resolve(c) is not None for c in self._callbacks)

    @staticmethod
    def _resolve(ref):
        return ref() if isinstance(ref, weakref.WeakMethod) else ref
