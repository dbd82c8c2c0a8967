"""A Scene: the renderables to draw, a light and a background colour."""
from __future__ import annotations

from .renderables.base import Light, Renderable


class Scene:
    """Holds renderables in draw order. Opaque ones are drawn first (in order), then the shadows
    of those that cast one on the ground, then transparent ones (in order), so ghosts blend over
    everything else. ``shadow_strength`` (0..1) is how much a shadow darkens the ground."""

    def __init__(self, background=(0.17, 0.18, 0.21), light: Light | None = None,
                 shadow_strength: float = 0.55):
        self.background = tuple(background)
        self.light = light or Light()
        self.shadow_strength = float(shadow_strength)
        self.renderables: list[Renderable] = []

    def add(self, *renderables: Renderable):
        """Add renderables; returns the single one given, or the tuple."""
        self.renderables.extend(renderables)
        return renderables[0] if len(renderables) == 1 else renderables

    def remove(self, renderable: Renderable) -> None:
        self.renderables.remove(renderable)

    def draw_order(self) -> list[Renderable]:
        visible = [r for r in self.renderables if r.visible]
        return [r for r in visible if not r.transparent] + [r for r in visible if r.transparent]

    def ground_height(self) -> float | None:
        """Height of the first visible ground (where shadows fall), or None without one."""
        for r in self.renderables:
            if r.visible and r.receiver_height is not None:
                return float(r.receiver_height)
        return None

    def release(self) -> None:
        for r in self.renderables:
            r.release()
        self.renderables.clear()
