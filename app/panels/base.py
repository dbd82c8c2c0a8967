"""What a panel is and what it may touch.

A panel declares what it uses: ``commands``, the ids of :mod:`app.studio_commands` it runs (it gets
them, and only them, as ``self.ctx.actions.ID(...)``), and ``reads``, the :class:`View` fields its
update reads. It gets a :class:`PanelContext` once (dearpygui for its own items, the tuning it may
write, its commands, the theme and read-only :class:`EngineFacts`) and a :class:`View` of the displayed
tick every frame. It never sees the studio, the session or another panel.

A panel subclasses :class:`Panel` and implements ``build(window_kwargs)`` (create every item once, in
``self.window(window_kwargs)``), ``update(view)`` (only ``set_value``/``configure_item`` on its own items)
and, when it has something to report, fills ``self.last`` (what it shows, as plain data, for the test
dump that ``state()`` returns).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

from app.command_registry import CommandRegistry, CommandView
from app.frame_times import FrameTimes
from app.history import History, Tick
from lmm.tuning import Tuning

from .common import WINDOWS, TextCache, window_tag

if TYPE_CHECKING:
    from app.theme import Theme
    from lmm.data.database import Database
    from lmm.data.manifest import Manifest
    from lmm.features import Features


@dataclass(frozen=True)
class EngineFacts:
    """Read-only facts about the engine that panels label and lay out with."""
    db: "Database"                                      # frame labels, skeleton
    features: "Features"                                # the database's features
    dt: float                                           # seconds per tick
    latent_dims: int                                    # a running controller's latent size (32 without one)
    controller_names: Callable[[], list[str]]           # running controllers (LMM may appear later)
    features_of: Callable[[str], "Features"]            # the features a controller searches
    memory: Callable[[], dict]                          # controller -> part -> bytes kept at run time
    manifest: "Manifest | None" = None                  # the manifest the database was built from
    quality_text: Callable[[], str] = lambda: ""        # the live motion quality rows (app.quality_live)

    @property
    def channel_names(self) -> list[str]:
        return list(self.features.names)


@dataclass(frozen=True)
class PreviewPose:
    """A pose a panel asks the 3D view to show as a preview ghost (the ``set_preview`` command).

    Everything is in the ghost's own frame: its root (simulation bone) at the origin facing +Z, metres.
    The 3D view places each ghost beside the inspected character of the displayed tick, facing the same
    way, so it follows the picked tick while scrubbing."""
    label: str
    positions: Any                                      # (J, 3) global joint positions
    parents: Any                                        # (J,) int, -1 for roots
    names: tuple[str, ...] | None = None                # joint names (size the body parts), or None
    trajectory: Any = None                              # (T, 3) future root positions on the ground, or None
    directions: Any = None                              # (T, 3) facing at those positions, or None
    points: Any = None                                  # (P, 3) feature points (e.g. feet), or None
    color: tuple[float, float, float] = (0.55, 0.95, 0.55)


@dataclass
class PanelContext:
    dpg: Any                                            # dearpygui.dearpygui (for the panel's own items)
    tuning: Tuning                                      # the one object panels write (its events say what changed)
    commands: CommandRegistry | None                    # every command; a panel gets its declared ones as ``actions``
    theme: "Theme"
    engine: EngineFacts
    actions: CommandView | None = None                  # the panel's declared commands (set by Panel.__init__)

    def for_commands(self, ids) -> "PanelContext":
        """This context with ``actions`` limited to the command ids ``ids``."""
        view = self.commands.view(ids) if self.commands is not None else None
        return dataclasses.replace(self, actions=view)


@dataclass(frozen=True)
class RecordingStatus:
    seconds: float
    files: tuple[str, ...]                              # file names being written


@dataclass
class View:
    """What the panels show this frame: the displayed tick (live or scrubbed) and its context."""
    tick: Tick | None                                   # None before the first tick
    history: History
    live: bool
    paused: bool
    inspected: str                                      # controller the single-controller panels inspect
    frame: int = 0                                      # studio frame counter
    problems: dict[str, str] = field(default_factory=dict)   # controller -> why it is off ("" or absent: ok)
    latent_status: str = ""                             # why MM's matched latents are missing ("" when shown)
    frame_times: FrameTimes | None = None
    render_info: str = ""                               # the 3D view's size, MSAA and GL renderer
    camera_azimuth: float = 0.0                         # radians, input convention (0: looking along +Z)
    recording: RecordingStatus | None = None
    last_recording: str = ""                            # what the last finished recording wrote (or why not)
    input_name: str = ""                                # replayed log's name ("" for live input)
    replay_line: str = ""                               # replay progress
    devices: tuple[str, ...] = ()                       # connected gamepads
    reference: str = ""                                 # reference BVH shown beside the characters
    following: str = ""                                 # the reference the characters follow ("" = none)
    layout: str = ""
    hidden_windows: tuple[str, ...] = ()                # window keys the layout hides
    physics_status: str = ""                            # why there are no ragdolls ("" when they run)
    ragdoll: dict = field(default_factory=dict)         # "enabled", "residual", "drawn" as the session has them

    @property
    def mode(self) -> str:
        if getattr(self.history, "is_session", False):      # a reopened session (app.review.SessionHistory)
            return "SESSION"
        return "LIVE" if self.live else ("PAUSED" if self.paused else "REWIND")

    @property
    def tick_number(self) -> int:
        return -1 if self.tick is None else int(self.tick.tick)

    def snap(self, name: str | None = None):
        """The displayed snapshot of ``name`` (default: the inspected controller, else any), or None."""
        if self.tick is None:
            return None
        snaps = self.tick.snapshots
        name = name or self.inspected
        if name in snaps:
            return snaps[name]
        return next(iter(snaps.values()), None)

    def snap_of(self, name: str):
        """The displayed snapshot of exactly ``name``, or None when that controller is not running."""
        return None if self.tick is None else self.tick.snapshots.get(name)


class Panel:
    """A dockable window of the studio. Subclasses set ``key`` (see :data:`app.panels.common.WINDOWS`)
    and declare the ``commands`` they run and the :class:`View` fields their update ``reads``."""
    key = ""
    commands: tuple[str, ...] = ()
    reads: tuple[str, ...] = ()

    def __init__(self, ctx: PanelContext):
        # a test may hand a plain namespace with only the fields the panel uses: it is taken as it is
        self.ctx = ctx.for_commands(self.commands) if isinstance(ctx, PanelContext) else ctx
        self.dpg = ctx.dpg
        self.tag = window_tag(self.key)
        self.title = WINDOWS[self.key][1]
        self.text = TextCache(ctx.dpg)
        self.last: dict = {}

    def window(self, window_kwargs: dict, **options):
        """The panel's window (a context manager), with its fixed id so layout files find it."""
        return self.dpg.window(tag=self.tag, label=self.title, **options, **window_kwargs)

    def build(self, window_kwargs: dict) -> None:
        raise NotImplementedError

    def update(self, view: View) -> None:
        pass

    # a panel whose update does numeric work (history windows, images, markers) can split it off:
    # ``prepare`` does it, ``update(view, prepared)`` shows a result (None: prepare it now). The studio
    # calls ``prepare`` on the tick worker for the next frame (see app.prepared).
    #: ``prepare`` reads ``view.frame`` (a result is then never kept from one frame to the next)
    prepare_uses_frame = False

    def prepare_key(self, view: View) -> tuple:
        """The panel's own settings that ``prepare`` reads (a result made with others is not used)."""
        return ()

    def prepare(self, view: View) -> Any:
        """What ``update`` shows of ``view``, worked out from the view, the history and the panel's
        settings only: no dearpygui call, no change to the panel (it may run on another thread)."""
        return None

    def state(self) -> dict:
        return dict(self.last)
