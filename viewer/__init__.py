"""viewer: moderngl drawing of skeletons and debug geometry from arrays (no dearpygui).

Build renderables from arrays, put them in a Scene, and draw the scene with a Renderer seen by an
OrbitCamera; ``create_headless_context()`` gives a context with no display (tests, screenshots),
``attach_current_context()`` wraps dearpygui's or a glfw window's.
"""
from .camera import OrbitCamera, apply_drag, apply_scroll, look_at, perspective, project_points
from .context import ContextError, attach_current_context, create_headless_context
from .renderables import Arrows, Ground, Light, Lines, Points, Skeleton, Spheres, radii_for_height
from .renderer import Renderer
from .scene import Scene

__all__ = [
    "Arrows", "ContextError", "Ground", "Light", "Lines", "OrbitCamera", "Points", "Renderer", "Scene",
    "Skeleton", "Spheres", "apply_drag", "apply_scroll", "attach_current_context",
    "create_headless_context", "look_at", "perspective", "project_points", "radii_for_height",
]
