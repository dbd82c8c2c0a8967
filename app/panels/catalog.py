"""The dockable panels the studio builds besides the 3D view, in the order it builds them."""
from __future__ import annotations


def dock_panels() -> tuple[type, ...]:
    """The panel classes (imported when the window is built: each pulls in its own helpers)."""
    from .candidates import CandidatesPanel
    from .coverage import CoveragePanel
    from .database import DatabasePanel
    from .features import FeaturesPanel
    from .latent import LatentPanel
    from .motion_search import MotionSearchPanel
    from .physics import PhysicsPanel
    from .recording import RecordingPanel
    from .search import SearchPanel
    from .stats import StatsPanel
    from .timeline import TimelinePanel
    from .tuning import TuningPanel

    return (FeaturesPanel, LatentPanel, SearchPanel, CandidatesPanel, TuningPanel, StatsPanel, TimelinePanel,
            RecordingPanel, DatabasePanel, CoveragePanel, MotionSearchPanel, PhysicsPanel)
