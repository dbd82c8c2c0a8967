"""A skeleton drawn as a shaded body of capsules (default) or as sticks, with a ground shadow."""
from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from . import body
from .base import (MESH_INSTANCE_FLOATS, FrameState, InstanceBuffer, Renderable, Resources,
                   as_rgba, draw_mesh_instances, draw_transparent)
from .capsule_mesh import CAPSULE_INSTANCE_FLOATS

STYLES = ("capsules", "sticks")
SEAM = 0.05         # relative radius step between caps sharing a joint: more than the mesh's facets (~4 %)
SEAM_EXACT = 0.015  # the same for ray-cast capsules (equal spheres would still z-fight)
BRANCH = 0.1    # branches (arms off the chest, legs off the pelvis) start this much thinner


def radii_for_height(height: float) -> dict:
    """Sizes proportional to a character's height, in the same units, so a skeleton in metres,
    centimetres or inches looks the same: ``Skeleton(ctx, parents, **radii_for_height(h))``.
    ``height`` scales the capsules; the radii are those of the sticks style."""
    return {"joint_radius": 0.016 * height, "bone_radius": 0.011 * height, "height": float(height)}


_UP = np.array([0.0, 1.0, 0.0])   # the direction of a zero-length leaf or neck


@dataclass(frozen=True)
class SkeletonPose:
    """A pose worked out for :meth:`Skeleton.update` away from the GL thread (:meth:`Skeleton.prepare`):
    the positions, and the capsule records' end points made for the body ``layout`` of that moment
    (``records`` None when there was none yet: ``update`` then makes them)."""
    positions: np.ndarray             # (J, 3) float32
    layout: object = None
    records: np.ndarray | None = None  # (R, 6) float32


class Skeleton(Renderable):
    """``Skeleton(ctx, parents, color, alpha, joint_radius, bone_radius, names=None,
    style="capsules", shadow=True, height=None, thickness=1.0, body_radii=None)``;
    ``update(positions)`` with global joint positions (J, 3).

    - ``style="capsules"``: a body of rounded cones, one per bone, between joint spheres whose
      radii are ``body_radii`` (J,) (fractions of the height, e.g. from the joint names by
      ``lmm.skeleton.body_radii``) or, where it is NaN or not given, from the joint's place in the
      tree; leaf joints are extended (hands, toes, by their ``names``) and a leaf ``Head`` is a sphere. Sizes are fractions of ``height`` (the character's
      height in scene units), estimated from the bone lengths of the first pose when None;
      ``thickness`` scales every radius. ``radii`` (J,) can be set to override the joint radii.
    - ``style="sticks"``: thin cylinders of ``bone_radius`` and joint spheres of ``joint_radius``.
    - ``shadow``: cast a planar shadow from the scene's key light on the scene's ground (drawn by
      the Renderer, darkening the ground once however many bones overlap).
    - ``alpha < 1`` draws a ghost: a single-layer blend of its front surface; its shadow is
      ``alpha`` times as dark.
    - A joint named ``Simulation`` (the database's ground projection of the root) is not drawn.
    - ``exact`` (fixed when created, from ``Resources.of(ctx).exact_capsules``): capsules ray-cast
      per pixel (a GPU's default) or drawn as their mesh (software GL's default).

    Every attribute (``color``, ``alpha``, ``style``, ``shadow``, ``thickness``, ``height``,
    ``radii``, ``joint_radius``, ``bone_radius``) can be changed at any time; it applies on the
    next draw. Capsules style costs one instanced draw call per skeleton, its shadow one more
    (plus one per scene for all shadows together).
    """

    def __init__(self, ctx: moderngl.Context, parents, color=(0.95, 0.55, 0.15), alpha: float = 1.0,
                 joint_radius: float = 0.028, bone_radius: float = 0.019, names=None,
                 style: str = "capsules", shadow: bool = True, height: float | None = None,
                 thickness: float = 1.0, body_radii=None):
        self.ctx = ctx
        self.parents = np.asarray(parents, dtype=np.int64).ravel()
        if names is not None and len(names) != len(self.parents):
            raise ValueError(f"{len(names)} joint names for {len(self.parents)} joints")
        self.names = None if names is None else [str(n) for n in names]
        if body_radii is not None and len(body_radii) != len(self.parents):
            raise ValueError(f"{len(body_radii)} body radii for {len(self.parents)} joints")
        self.body_radii = None if body_radii is None else np.asarray(body_radii, dtype=np.float64).copy()
        self.color = tuple(float(c) for c in color[:3])
        self.alpha = float(alpha)
        self.joint_radius = float(joint_radius)
        self.bone_radius = float(bone_radius)
        self._style_name = "capsules"
        self.style = style
        self.shadow = bool(shadow)
        self.height = None if height is None else float(height)
        self.thickness = float(thickness)
        self.radii = None
        self.visible = True
        n = len(self.parents)
        shown = np.ones(n, dtype=bool)
        if self.names is not None:
            shown = np.array([n.lower() != body.SIMULATION_NAME for n in self.names])
        self._shown = shown
        children = np.nonzero(self.parents >= 0)[0]
        children = children[shown[children] & shown[self.parents[children]]]
        self._children = children
        self._bone_parents = self.parents[children]
        res = Resources.of(ctx)
        self.exact = res.exact_capsules
        # exact surfaces only need caps a hair apart; the mesh needs more than its facet depth
        self._seam = SEAM_EXACT if self.exact else SEAM
        # caps meeting at a joint get distinct radii (see SEAM): the bone that continues the trunk
        # through a joint (the child carrying most joints) starts at its radius r, the bone arriving
        # ends at (1 - SEAM) r, branches start thinner, each one SEAM apart, inside the others
        self._start_scale = np.ones(len(children))
        subtree = body.subtree_sizes(self.parents)
        for p in np.unique(self._bone_parents):
            bones = np.nonzero(self._bone_parents == p)[0]
            order = bones[np.argsort(-subtree[children[bones]], kind="stable")]
            for rank, k in enumerate(order[1:]):
                self._start_scale[k] = 1.0 - BRANCH - self._seam * (rank + 1)
        self._heads = body.head_joints(self.parents, self.names)
        self._joints = InstanceBuffer(ctx, MESH_INSTANCE_FLOATS, max(n, 1))
        self._bones = InstanceBuffer(ctx, MESH_INSTANCE_FLOATS, max(len(children), 1))
        self._capsules = InstanceBuffer(ctx, CAPSULE_INSTANCE_FLOATS, max(2 * n, 1))
        self._joint_vao = res.mesh_vao("sphere", self._joints.buffer)
        self._bone_vao = res.mesh_vao("cylinder", self._bones.buffer)
        self._capsule_vao = res.capsule_vao(self._capsules.buffer, exact=self.exact)
        self._shadow_vao = res.capsule_vao(self._capsules.buffer, shadow=True)
        self._positions = None
        self._capsule_data = None  # what the capsule buffer holds (shadow bounds are computed from it)
        self._lengths = None
        self._body = None          # (joint radii, bone end radii, leaf extensions, end factors, height)
        self._body_key = None
        self._layout = None        # (body sizes it was made for, capsule records' fixed part)
        self._uploaded_style = None
        self._rgba = (None, None)  # ((colour, alpha), float32 RGBA) of the last upload
        self._fixed = None         # (layout, RGBA array, staging array) whose fixed capsule columns are written

    @property
    def n_joints(self) -> int:
        return len(self.parents)

    @property
    def transparent(self) -> bool:
        return self.alpha < 1.0

    @property
    def casts_shadow(self) -> bool:
        return self.shadow and self._positions is not None and self._capsules.count > 0

    @property
    def style(self) -> str:
        """``"capsules"`` or ``"sticks"``; applies on the next draw."""
        return self._style_name

    @style.setter
    def style(self, value: str) -> None:
        if value not in STYLES:
            raise ValueError(f"unknown skeleton style {value!r}: use one of {', '.join(STYLES)}")
        self._style_name = value

    def _style(self):
        radii = None if self.radii is None else np.asarray(self.radii, dtype=np.float64).tobytes()
        return (self.style, self.color, self.alpha, self.joint_radius, self.bone_radius, self.thickness,
                self.height, radii)

    def update(self, global_positions) -> None:
        """Set the pose: global joint positions (J, 3) in scene units, or a :class:`SkeletonPose` from
        :meth:`prepare` (its records are used when the body has not changed since)."""
        prepared = global_positions if isinstance(global_positions, SkeletonPose) else None
        if prepared is not None:
            p = prepared.positions
        else:
            p = np.asarray(global_positions, dtype=np.float32).reshape(-1, 3)
        if len(p) != self.n_joints:
            raise ValueError(f"Skeleton has {self.n_joints} joints, got positions for {len(p)}")
        self._positions = p
        if self._lengths is None:   # bones touching a hidden joint do not count for the body's size
            shown_bone = self._shown & self._shown[np.maximum(self.parents, 0)]
            self._lengths = body.bone_lengths(self.parents, p) * shown_bone
        self._upload(prepared)

    def prepare(self, global_positions) -> SkeletonPose:
        """What :meth:`update` works out of a pose, without touching GL or this skeleton: safe on another
        thread while the GL thread draws. The capsule records are made for the body layout of the last
        update (none before the first, or in sticks style); ``update`` checks that it is still the
        same layout."""
        p = np.asarray(global_positions, dtype=np.float32).reshape(-1, 3)
        layout = self._layout
        if len(p) != self.n_joints or layout is None or self.style != "capsules" or layout[0] is not self._body:
            return SkeletonPose(p)
        L = layout[1]
        return SkeletonPose(p, L, self._capsule_ends(p, L, np.empty_like(L["ends"])).astype(np.float32))

    # -- body proportions -------------------------------------------------------------------------
    def body_height(self) -> float:
        """The height the capsule sizes are fractions of: ``height``, or estimated from the bones."""
        if self.height is not None:
            return self.height
        if self._lengths is None:   # no pose yet
            return 1.0
        return body.estimate_height(self.parents, self._lengths)

    def joint_radii(self) -> np.ndarray:
        """(J,) radius of each joint sphere in capsules style (after ``thickness``)."""
        return self._body_sizes()[0]

    def _body_sizes(self):
        key = (self.height, self.thickness, None if self.radii is None else
               np.asarray(self.radii, dtype=np.float64).tobytes())
        if self._body is None or self._body_key != key:
            h = self.body_height()
            if self.radii is not None:
                radii = np.broadcast_to(np.asarray(self.radii, dtype=np.float64), (self.n_joints,)).copy()
            else:
                radii = body.joint_radii(self.parents, self.body_radii, self._lengths, h)
            radii = radii * self.thickness * self._shown
            ext, end = body.leaf_extensions(self.parents, self.names, self._lengths, h, self.body_radii)
            bone_end = radii.copy()
            for j in self._heads:   # the neck keeps its own radius up to the head sphere
                bone_end[j] = min(radii[j], radii[self.parents[j]])
            self._body = (radii, bone_end, ext, end, h)
            self._body_key = key
        return self._body

    # -- instances --------------------------------------------------------------------------------
    def _upload(self, prepared: SkeletonPose | None = None) -> None:
        p = self._positions
        key = (self.color, self.alpha)
        if self._rgba[0] != key:
            self._rgba = (key, as_rgba(self.color, alpha=self.alpha))
        rgba = self._rgba[1]
        if self.style == "sticks":
            self._upload_sticks(p, rgba)
            self._upload_capsules_of_sticks(p, rgba)
        else:
            self._upload_capsules(p, rgba, prepared)
        self._uploaded_style = self._style()

    def _upload_sticks(self, p, rgba) -> None:
        shown = np.nonzero(self._shown)[0]
        j = self._joints.staging(len(shown))
        j[:, 0:3] = p[shown]
        j[:, 3:6] = p[shown]
        j[:, 6] = self.joint_radius
        j[:, 7:11] = rgba
        self._joints.upload(j)
        b = self._bones.staging(len(self._children))
        b[:, 0:3] = p[self._bone_parents]
        b[:, 3:6] = p[self._children]
        b[:, 6] = self.bone_radius
        b[:, 7:10] = rgba[:3] * 0.85   # bones a little darker than joints, same hue
        b[:, 10] = rgba[3]
        self._bones.upload(b)

    def _upload_capsules_of_sticks(self, p, rgba) -> None:
        """The sticks as capsules: only their shadow is drawn from these."""
        shown = np.nonzero(self._shown)[0]
        nb, nj = len(self._children), len(shown)
        c = self._capsules.staging(nb + nj)
        c[:nb, 0:3] = p[self._bone_parents]
        c[:nb, 3:6] = p[self._children]
        c[:nb, 6:8] = self.bone_radius
        c[nb:, 0:3] = p[shown]
        c[nb:, 3:6] = p[shown]
        c[nb:, 6:8] = self.joint_radius
        c[:, 8:12] = rgba
        self._capsules.upload(c)
        self._capsule_data = c
        self._fixed = None    # the capsule records now hold the sticks' radii

    def _capsule_layout(self):
        """What of the capsule records does not depend on the pose, cached with the body sizes: which
        joints each record joins, and its radius columns. Rebuilt when the sizes change."""
        body_sizes = self._body_sizes()
        if self._layout is not None and self._layout[0] is body_sizes:
            return self._layout[1]
        radii, bone_end, ext, end, _ = body_sizes
        parents, kids = self._bone_parents, self._children
        keep = (radii[parents] > 0) & (radii[kids] > 0)
        parents, kids = parents[keep], kids[keep]
        # leaf extensions continue the parent bone past the leaf
        leaves = np.nonzero(ext > 0)[0]
        leaves = leaves[self._shown[leaves] & (radii[leaves] > 0)]
        # heads: a sphere centred past the head joint, along the neck
        heads = self._heads[radii[self._heads] > 0]
        # joints no bone reaches (a lone root, a skeleton of one joint) are spheres of their own
        lonely = np.ones(self.n_joints, dtype=bool)
        lonely[parents] = False
        lonely[kids] = False
        lonely &= radii > 0
        lonely = np.nonzero(lonely)[0]
        nb, nl, nh, nj = len(kids), len(leaves), len(heads), len(lonely)
        r = np.empty((nb + nl + nh + nj, 2), np.float32)
        # no two caps on one joint may be the same sphere: their facets would poke through each
        # other in jagged stripes
        r[:nb, 0] = radii[parents] * self._start_scale[keep]
        r[:nb, 1] = bone_end[kids] * (1.0 - self._seam)
        r[nb:nb + nl, 0] = radii[leaves]
        r[nb:nb + nl, 1] = radii[leaves] * end[leaves]
        r[nb + nl:nb + nl + nh] = radii[heads, None]
        r[nb + nl + nh:] = radii[lonely, None]
        # every record's two ends as indices into the pose extended by the leaf ends and head centres
        # (computed per pose from the directions below): one gather fills both end columns
        J = self.n_joints
        ext_rows = J + np.arange(nl + nh)
        pairs = np.concatenate([np.stack([parents, kids], 1), np.stack([leaves, ext_rows[:nl]], 1),
                                np.stack([ext_rows[nl:], ext_rows[nl:]], 1), np.stack([lonely, lonely], 1)])
        layout = {"pairs": pairs.astype(np.intp),
                  "dir_both": np.concatenate([leaves, heads, self.parents[leaves], self.parents[heads]]),
                  "ends": np.empty((J + nl + nh, 3)),    # filled per pose (float64, as the sums are)
                  "dir_scale": np.concatenate([ext[leaves], body.HEAD_CENTER_OFFSET * radii[heads]])[:, None],
                  "radii": r}
        self._layout = (body_sizes, layout)
        return layout

    def _upload_capsules(self, p, rgba, prepared: SkeletonPose | None = None) -> None:
        L = self._capsule_layout()
        c = self._capsules.staging(len(L["radii"]))
        if prepared is not None and prepared.layout is L and prepared.records is not None:
            c[:, 0:6] = prepared.records
        else:
            c[:, 0:6] = self._capsule_ends(p, L, L["ends"])
        # the radius and colour columns stay in the staging array from pose to pose: rewritten only
        # when the layout, the colour or the array itself changed
        fixed = self._fixed
        if fixed is None or fixed[0] is not L or fixed[1] is not rgba or fixed[2] is not c.base:
            c[:, 6:8] = L["radii"]
            c[:, 8:12] = rgba
            self._fixed = (L, rgba, c.base)
        self._capsules.upload(c)
        self._capsule_data = c

    @staticmethod
    def _capsule_ends(p, L: dict, ends: np.ndarray) -> np.ndarray:
        """(R, 6) float64 end points of the capsule records of pose ``p`` (``ends``: scratch rows)."""
        # leaf ends continue the parent bone past the leaf; head centres sit along the neck
        # (each numpy call costs a microsecond or two here, about what its arithmetic on a few rows
        # costs: the steps below are as few calls as give the same numbers)
        both = p[L["dir_both"]]                 # the leaves and heads, then their parents, in one gather
        k = len(L["dir_scale"])
        start = both[:k]
        d = start - both[k:]
        norm = np.sqrt(np.add.reduce(d * d, axis=1, keepdims=True))   # np.linalg.norm's sum, without its overhead
        if k and norm.min() > 1e-9:
            d /= norm                           # what the line below gives when no bone has zero length
        else:
            d = np.where(norm > 1e-9, d / np.maximum(norm, 1e-12), _UP)
        ends[:len(p)] = p                       # the pose, then the leaf ends and head centres
        np.multiply(d, L["dir_scale"], out=ends[len(p):])
        ends[len(p):] += start
        return ends[L["pairs"]].reshape(-1, 6)

    # -- drawing ----------------------------------------------------------------------------------
    def draw(self, frame: FrameState) -> None:
        if self._positions is None:
            return
        if self._uploaded_style != self._style():
            self._upload()
        if self.style == "sticks":
            draws = [lambda: draw_mesh_instances(frame, self._bone_vao, self._bones.count),
                     lambda: draw_mesh_instances(frame, self._joint_vao, self._joints.count)]
        else:
            draws = [lambda: self._draw_capsules()]
        if self.transparent:
            draw_transparent(frame, draws)
        else:
            for d in draws:
                d()

    def _draw_capsules(self) -> None:
        if self._capsules.count:
            self._capsule_vao.render(moderngl.TRIANGLES, instances=self._capsules.count)

    def draw_shadow(self, frame: FrameState) -> None:
        if self._uploaded_style != self._style():
            self._upload()
        if self._capsules.count:
            self._shadow_vao.program["u_fade_height"].value = float(max(self._body_sizes()[4], 1e-9))
            self._shadow_vao.render(moderngl.TRIANGLES, instances=self._capsules.count)

    def shadow_bounds(self, direction: np.ndarray, ground: float):
        """(x0, z0, x1, z1): the capsules flattened onto the ground along ``direction``."""
        if self._uploaded_style != self._style():
            self._upload()
        c = self._capsule_data
        if c is None or len(c) == 0:
            return None
        ends = np.concatenate([c[:, 0:3], c[:, 3:6]]).astype(np.float64)
        flat = ends - direction * (np.maximum(ends[:, 1:2] - ground, 0.0) / direction[1])
        margin = float(c[:, 6:8].max()) * (1.0 + 1.0 / direction[1])
        x, z = flat[:, 0], flat[:, 2]
        return x.min() - margin, z.min() - margin, x.max() + margin, z.max() + margin

    def release(self) -> None:
        for obj in (self._joint_vao, self._bone_vao, self._capsule_vao, self._shadow_vao,
                    self._joints, self._bones, self._capsules):
            obj.release()
