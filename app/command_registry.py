"""Everything a user can do, by id: the one list that the menus, the keyboard shortcuts, the test
scripts and the panels all go through.

A :class:`Command` has an id (what a script's ``"do"`` names and a session log records), a label (what
a menu shows), an optional shortcut key and menu place, the keyword arguments it takes and the callable
that does it. :meth:`CommandRegistry.run` calls it and then announces a :class:`CommandRun` on
``registry.events`` (napari-style ``connect``), so a session log can record what the user did by id.
A panel gets a :class:`CommandView` of the ids it declares and calls ``view.ID(...)``.

The studio's commands are registered in :mod:`app.studio_commands`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

from lmm.events import Emitter

#: ``Command.args`` of a command that takes any keyword arguments (it reads a script action's dict)
ANY_ARGS = ("**",)


@dataclass(frozen=True)
class Command:
    id: str
    label: str
    run: Callable[..., Any]
    args: tuple[str, ...] = ()      # the keyword arguments it takes (a script action's keys); () : none
    shortcut: str = ""              # a key name of :data:`app.input.keyboard.SHORTCUT_KEYS` ("" : none)
    menu: str = ""                  # the menu bar menu that lists it ("" : none)
    section: int = 0                # items of one menu are separated where the section changes
    help: str = ""                  # one line for the keys help (defaults to the label)

    @property
    def takes_arguments(self) -> bool:
        return bool(self.args)


@dataclass(frozen=True)
class CommandRun:
    """A command that ran: its id and the arguments it was given (positional, keyword)."""
    id: str
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)


class CommandRegistry:
    def __init__(self) -> None:
        self._commands: dict[str, Command] = {}
        self.events: Emitter[CommandRun] = Emitter()

    def add(self, id: str, label: str, run: Callable[..., Any], **options) -> Command:
        """Register a command (see :class:`Command` for ``options``); an id is registered once."""
        if id in self._commands:
            raise ValueError(f"command {id!r} is registered twice")
        command = Command(id, label, run, **options)
        self._commands[id] = command
        return command

    def __getitem__(self, id: str) -> Command:
        try:
            return self._commands[id]
        except KeyError:
            raise KeyError(f"unknown command {id!r}") from None

    def __contains__(self, id: str) -> bool:
        return id in self._commands

    def __iter__(self):
        return iter(self._commands.values())

    def ids(self) -> list[str]:
        return list(self._commands)

    def run(self, id: str, *args, **kwargs):
        """Run command ``id`` with these arguments and announce it; returns what the command returns."""
        command = self[id]
        if kwargs and command.args != ANY_ARGS:
            unknown = sorted(set(kwargs) - set(command.args))
            if unknown:
                raise ValueError(f"command {id!r} takes no argument {unknown[0]!r} "
                                 f"(it takes: {', '.join(command.args) or 'none'})")
        result = command.run(*args, **kwargs)
        self.events.emit(CommandRun(id, args, kwargs))
        return result

    def in_menu(self, menu: str) -> list[Command]:
        return [c for c in self._commands.values() if c.menu == menu]

    def shortcuts(self) -> dict[str, Command]:
        """Shortcut key name -> command."""
        return {c.shortcut: c for c in self._commands.values() if c.shortcut}

    def view(self, ids: Iterable[str]) -> "CommandView":
        return CommandView(self, ids)


class CommandView:
    """The commands one panel declared, as methods: ``view.scrub(tick=10)`` runs ``registry.run("scrub",
    tick=10)``. Another id is an error naming the panel's declaration, so what a panel may do is read
    from its ``commands`` line."""

    def __init__(self, registry: CommandRegistry, ids: Iterable[str]):
        self._registry = registry
        self._ids = frozenset(ids)

    def __getattr__(self, id: str):
        if id.startswith("_"):
            raise AttributeError(id)
        if id not in self._ids:
            raise AttributeError(f"command {id!r} is not among the panel's declared commands "
                                 f"({', '.join(sorted(self._ids)) or 'none'})")
        return lambda *args, **kwargs: self._registry.run(id, *args, **kwargs)

    def __contains__(self, id: str) -> bool:
        return id in self._ids
