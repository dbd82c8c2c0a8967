"""Things a Scene draws, one module per kind; each is built from arrays and updated per frame."""
from .arrows import Arrows
from .base import FrameState, Light, Renderable
from .ground import Ground
from .lines import Lines
from .skeleton import Skeleton, radii_for_height
from .spheres import Points, Spheres

__all__ = ["Arrows", "FrameState", "Ground", "Light", "Lines", "Points", "Renderable", "Skeleton",
           "Spheres", "radii_for_height"]
