"""What every renderable shares: the frame state, per-context GL resources (programs and the
unit meshes drawn instanced) and growable instance buffers.

One context holds one set of programs and meshes (cached on ``ctx.extra``), so two skeletons and
all debug geometry cost a handful of instanced draw calls.
"""
from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from ..shaders import FRAME_BINDING, FRAME_FLOATS, frame_block, load_program
from .capsule_mesh import CAPSULE_INFLATE, SHADOW_DEPTH_PULL, capsule_mesh


# ---------------------------------------------------------------------------------------------
# frame state passed to renderables

@dataclass
class Light:
    """A directional light (``direction`` points towards the light) plus ambient and specular."""

    direction: tuple = (0.8, 1.2, 0.25)
    ambient: float = 0.4
    diffuse: float = 0.55
    specular: float = 0.15


@dataclass
class FrameState:
    """Everything a renderable needs to draw one frame."""

    ctx: moderngl.Context
    fbo: moderngl.Framebuffer
    view: np.ndarray
    proj: np.ndarray
    eye: np.ndarray
    target: np.ndarray
    width: int
    height: int
    background: tuple
    light: Light | None = None
    ground_height: float | None = None   # the plane shadows fall on; None: no ground, no shadows

    @property
    def view_proj(self) -> np.ndarray:
        return self.proj @ self.view


# ---------------------------------------------------------------------------------------------
# unit meshes: vertices (in_pos 3f, in_t 1f, in_normal 3f), uint32 triangle indices

def _fix_winding(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Orient every triangle counter-clockwise seen from outside (along the vertex normals)."""
    p = verts[:, :3].copy()
    p[:, 1] += verts[:, 3]  # unit-length configuration: axial offset = y + t
    n = verts[:, 4:7]
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    face = np.cross(b - a, c - a)
    flip = (face * (n[tris[:, 0]] + n[tris[:, 1]] + n[tris[:, 2]])).sum(axis=1) < 0
    tris = tris.copy()
    tris[flip] = tris[flip][:, ::-1]
    return tris


def sphere_mesh(slices: int = 16, stacks: int = 10):
    theta = np.linspace(0.0, np.pi, stacks + 1)           # from +Y to -Y
    phi = np.linspace(0.0, 2.0 * np.pi, slices + 1)
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    xyz = np.stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)], axis=-1).reshape(-1, 3)
    verts = np.c_[xyz, np.zeros(len(xyz)), xyz]
    tris = []
    row = slices + 1
    for i in range(stacks):
        for j in range(slices):
            a, b = i * row + j, i * row + j + 1
            c, d = a + row, b + row
            if i > 0:
                tris.append((a, b, c))
            if i < stacks - 1:
                tris.append((b, d, c))
    tris = np.array(tris, dtype=np.int64)
    return verts.astype(np.float32), _fix_winding(verts, tris).astype(np.uint32)


def _ring(segments: int):
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    return np.cos(phi), np.sin(phi)


def cylinder_mesh(segments: int = 16):
    """Radius 1 along the segment (t from 0 to 1), with flat caps."""
    c, s = _ring(segments)
    z0 = np.zeros(segments)
    side0 = np.c_[c, z0, s, z0, c, z0, s]
    side1 = np.c_[c, z0, s, z0 + 1, c, z0, s]
    cap0 = np.c_[c, z0, s, z0, z0, z0 - 1, z0]
    cap1 = np.c_[c, z0, s, z0 + 1, z0, z0 + 1, z0]
    centers = np.array([[0, 0, 0, 0, 0, -1, 0], [0, 0, 0, 1, 0, 1, 0]], dtype=np.float64)
    verts = np.r_[side0, side1, cap0, cap1, centers]
    k = np.arange(segments)
    k1 = (k + 1) % segments
    n = segments
    tris = np.r_[
        np.c_[k, k1, n + k], np.c_[k1, n + k1, n + k],          # side quads
        np.c_[2 * n + k, 2 * n + k1, np.full(n, 4 * n)],         # cap at t=0
        np.c_[3 * n + k, 3 * n + k1, np.full(n, 4 * n + 1)],     # cap at t=1
    ]
    return verts.astype(np.float32), _fix_winding(verts, tris).astype(np.uint32)


def cone_mesh(segments: int = 16):
    """Base radius 1 at t=0, apex at t=1, closed base. Draw with ``u_cone = 1``."""
    c, s = _ring(segments)
    z0 = np.zeros(segments)
    # one apex vertex per side so each face keeps its own normal
    mid = np.pi / segments
    cm, sm = np.cos(np.arange(segments) * 2 * mid + mid), np.sin(np.arange(segments) * 2 * mid + mid)
    side = np.c_[c, z0, s, z0, c, z0 + 1, s]
    apex = np.c_[z0, z0, z0, z0 + 1, cm, z0 + 1, sm]
    base = np.c_[c, z0, s, z0, z0, z0 - 1, z0]
    center = np.array([[0, 0, 0, 0, 0, -1, 0]], dtype=np.float64)
    verts = np.r_[side, apex, base, center]
    k = np.arange(segments)
    k1 = (k + 1) % segments
    n = segments
    tris = np.r_[np.c_[k, k1, n + k], np.c_[2 * n + k, 2 * n + k1, np.full(n, 3 * n)]]
    # winding from the geometry itself: the apex normals are only approximate for _fix_winding
    return verts.astype(np.float32), _fix_winding(verts, tris).astype(np.uint32)


# ---------------------------------------------------------------------------------------------
# per-context resources

MESH_INSTANCE_FLOATS = 11   # a(3) b(3) radius(1) color(4)
LINE_INSTANCE_FLOATS = 14   # p0(3) p1(3) c0(4) c1(4)


SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "swiftshader", "software")


def is_software_renderer(ctx: moderngl.Context) -> bool:
    """Whether the context rasterizes on the CPU (Mesa llvmpipe and friends)."""
    name = str(ctx.info.get("GL_RENDERER", "")).lower()
    return any(s in name for s in SOFTWARE_RENDERERS)


class Resources:
    """Programs and unit meshes of one context; get it with ``Resources.of(ctx)``.

    ``exact_capsules``: draw capsule bodies ray-cast per pixel (exact surfaces, smooth seams) or
    as the plain mesh (slightly faceted, where bones meet at a shallow angle the facets show).
    Defaults to exact on a GPU and the mesh on software GL, where exact costs ~1.5x the frame;
    set it before creating skeletons to choose."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.exact_capsules = not is_software_renderer(ctx)
        self.frame_uniforms = ctx.buffer(reserve=4 * FRAME_FLOATS, dynamic=True)
        self.mesh_program = load_program(ctx, "mesh.vert", "mesh.frag")
        self.line_program = load_program(ctx, "line.vert", "line.frag")
        self.meshes = {}
        for name, (verts, tris) in {"sphere": sphere_mesh(), "cylinder": cylinder_mesh(),
                                    "cone": cone_mesh()}.items():
            self.meshes[name] = (ctx.buffer(verts.tobytes()), ctx.buffer(tris.tobytes()))
        corners = np.array([[0, -1], [0, 1], [1, -1], [1, 1]], dtype=np.float32)
        self.line_corners = ctx.buffer(corners.tobytes())
        self.capsule_program = load_program(ctx, "capsule.vert", "capsule.frag")
        self.capsule_exact_program = load_program(ctx, "capsule.vert", "capsule_exact.frag")
        self.shadow_program = load_program(ctx, "capsule.vert", "shadow.frag")
        for prog in (self.capsule_program, self.capsule_exact_program, self.shadow_program):
            prog["u_shadow"].value = 1.0 if prog is self.shadow_program else 0.0
            prog["u_inflate"].value = CAPSULE_INFLATE if prog is self.capsule_exact_program else 1.0
        verts, tris = capsule_mesh()
        self.capsule_mesh = (ctx.buffer(verts.tobytes()), ctx.buffer(tris.tobytes()))
        # shadows only need the outline: a coarse mesh keeps them cheap on software GL, where
        # their cost is mostly per triangle
        verts, tris = capsule_mesh(segments=12, cap_rings=3)
        self.shadow_mesh = (ctx.buffer(verts.tobytes()), ctx.buffer(tris.tobytes()))
        self.shadow_resolve_program = load_program(ctx, "shadow_resolve.vert", "shadow_resolve.frag")
        self.shadow_resolve_program["u_depth_pull"].value = SHADOW_DEPTH_PULL
        self._resolve_corners = ctx.buffer(np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float32).tobytes())
        self.shadow_resolve_vao = ctx.vertex_array(self.shadow_resolve_program,
                                                   [(self._resolve_corners, "2f", "in_corner")])

    @classmethod
    def of(cls, ctx: moderngl.Context) -> "Resources":
        if ctx.extra is None:
            ctx.extra = {}
        store = ctx.extra if isinstance(ctx.extra, dict) else _fallback_store.setdefault(id(ctx), {})
        res = store.get("viewer.resources")
        if res is None:
            res = store["viewer.resources"] = cls(ctx)
        return res

    def mesh_vao(self, mesh: str, instances: moderngl.Buffer) -> moderngl.VertexArray:
        vbo, ibo = self.meshes[mesh]
        return self.ctx.vertex_array(
            self.mesh_program,
            [(vbo, "3f 1f 3f", "in_pos", "in_t", "in_normal"),
             (instances, "3f 3f 1f 4f/i", "i_a", "i_b", "i_radius", "i_color")],
            index_buffer=ibo, index_element_size=4)

    def capsule_vao(self, instances: moderngl.Buffer, shadow: bool = False,
                    exact: bool | None = None) -> moderngl.VertexArray:
        """Rounded cones from ``instances`` (a, b, ra, rb, rgba): lit (``exact`` or the mesh,
        None: ``exact_capsules``) or as their ground shadow."""
        exact = self.exact_capsules if exact is None else exact
        vbo, ibo = self.shadow_mesh if shadow else self.capsule_mesh
        program = self.shadow_program if shadow else self.capsule_exact_program if exact else self.capsule_program
        return self.ctx.vertex_array(
            program,
            [(vbo, "2f 1f 1f", "in_ring", "in_lat", "in_end"),
             (instances, "3f 3f 1f 1f 4f/i", "i_a", "i_b", "i_ra", "i_rb", "i_color")],
            index_buffer=ibo, index_element_size=4)

    def line_vao(self, instances: moderngl.Buffer) -> moderngl.VertexArray:
        return self.ctx.vertex_array(
            self.line_program,
            [(self.line_corners, "2f", "in_corner"),
             (instances, "3f 3f 4f 4f/i", "i_p0", "i_p1", "i_c0", "i_c1")])

    def begin_frame(self, frame: FrameState, light: Light) -> None:
        """Write the per-frame uniforms shared by all programs (frame.glsl's block) and bind them."""
        direction = np.asarray(light.direction, dtype=np.float64)
        self.frame_uniforms.write(frame_block(
            frame.view, frame.proj, frame.view_proj, frame.eye, direction / np.linalg.norm(direction),
            light.ambient, light.diffuse, light.specular, (frame.width, frame.height)))
        self.frame_uniforms.bind_to_uniform_block(FRAME_BINDING)


_fallback_store: dict = {}


class InstanceBuffer:
    """A GPU buffer of per-instance float32 records that grows by orphaning, never shrinks, and
    keeps its identity so vertex arrays built on it stay valid."""

    def __init__(self, ctx: moderngl.Context, floats_per_instance: int, capacity: int = 32):
        self.floats = floats_per_instance
        self.buffer = ctx.buffer(reserve=capacity * floats_per_instance * 4, dynamic=True)
        self.count = 0
        self._staging = np.zeros((capacity, floats_per_instance), dtype=np.float32)

    def staging(self, n: int) -> np.ndarray:
        """A reusable (n, floats) float32 array to fill before ``upload``."""
        if len(self._staging) < n:
            self._staging = np.zeros((max(n, 2 * len(self._staging)), self.floats), dtype=np.float32)
        return self._staging[:n]

    def upload(self, data: np.ndarray) -> None:
        data = np.ascontiguousarray(data, dtype=np.float32)
        if data.nbytes > self.buffer.size:
            self.buffer.orphan(max(data.nbytes, 2 * self.buffer.size))
        if data.nbytes:
            self.buffer.write(data)
        self.count = len(data)

    def release(self) -> None:
        self.buffer.release()


def same_fixed_inputs(old: tuple | None, new: tuple) -> bool:
    """Whether an update's per-item inputs are those its staging arrays already hold the columns of.
    ``old``/``new``: ``(staging arrays, inputs)``; the staging arrays must be the same objects, input
    arrays the same read-only objects (a caller handing the same frozen array again means the same
    values: MarkerBatch's sizes and colours), other inputs equal. A writable input array never counts
    as the same: its owner may have changed it in place."""
    if old is None or len(old[0]) != len(new[0]) or len(old[1]) != len(new[1]):
        return False
    if any(a is not b for a, b in zip(old[0], new[0])):
        return False
    for a, b in zip(old[1], new[1]):
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            if a is not b or b.flags.writeable:
                return False
        elif a != b:
            return False
    return True


def as_rgba(color, n: int | None = None, alpha: float = 1.0) -> np.ndarray:
    """Colours as float32 RGBA: one colour (3|4,) -> (4,), or per item (n, 3|4) -> (n, 4)."""
    c = np.asarray(color, dtype=np.float32)
    if c.ndim == 1:
        out = np.empty(4, dtype=np.float32)
        out[:3] = c[:3]
        out[3] = c[3] if len(c) > 3 else alpha
        if n is not None:
            out = np.broadcast_to(out, (n, 4))
        return out
    out = np.empty((len(c), 4), dtype=np.float32)
    out[:, :3] = c[:, :3]
    out[:, 3] = c[:, 3] if c.shape[1] > 3 else alpha
    return out


class Renderable:
    """Base of everything a Scene draws. Subclasses fill their buffers in ``update(...)`` and
    issue their draws in ``draw(frame)``; ``transparent`` ones are drawn after opaque ones.

    A renderable that ``casts_shadow`` also has ``draw_shadow(frame)`` (its shadow geometry with
    the shadow program, see ``draw_shadows``); one that has a ``receiver_height`` (the ground) is
    the plane shadows fall on."""

    visible: bool = True
    receiver_height: float | None = None

    @property
    def transparent(self) -> bool:
        return False

    @property
    def casts_shadow(self) -> bool:
        return False

    def draw_shadow(self, frame: FrameState) -> None:  # pragma: no cover - interface
        pass

    def shadow_bounds(self, direction: np.ndarray, ground: float):  # pragma: no cover - interface
        """(x0, z0, x1, z1) on the ground containing this renderable's shadow, or None."""
        return None

    def draw(self, frame: FrameState) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def release(self) -> None:
        pass


def draw_mesh_instances(frame: FrameState, vao: moderngl.VertexArray, count: int,
                        cone: bool = False) -> None:
    if count <= 0:
        return
    vao.program["u_cone"].value = 1.0 if cone else 0.0
    vao.render(moderngl.TRIANGLES, instances=count)


def set_depth_write(fbo: moderngl.Framebuffer, enabled: bool) -> None:
    fbo.depth_mask = enabled
    fbo.use()  # moderngl applies a framebuffer's masks when it is bound


def draw_transparent(frame: FrameState, draws) -> None:
    """Single-layer transparency: a depth-only pass, then colour where depth matches, so a ghost
    shows its front surface blended over the scene without its own insides."""
    ctx, fbo = frame.ctx, frame.fbo
    fbo.color_mask = (False, False, False, False)
    fbo.use()  # moderngl applies a framebuffer's masks when it is bound
    for draw in draws:
        draw()
    fbo.color_mask = (True, True, True, True)
    fbo.use()
    ctx.depth_func = "<="
    for draw in draws:
        draw()
    ctx.depth_func = "<"


def shadow_direction(light: Light) -> np.ndarray:
    """Unit vector towards the key light, raised to at least ~11 degrees above the horizon so a
    grazing light does not stretch shadows to the horizon."""
    direction = np.asarray(light.direction, dtype=np.float64)
    direction = direction / np.linalg.norm(direction)
    if direction[1] < 0.2:
        direction[1] = 0.2
        direction /= np.linalg.norm(direction)
    return direction


def draw_shadows(frame: FrameState, casters, strength: float = 0.45) -> None:
    """Planar shadows of ``casters`` on the ground plane ``frame.ground_height``, from the key
    light, darkening the ground at most once however many parts overlap.

    Pass 1 draws the casters' light-facing triangles flattened onto the ground and writes
    ``1 - darkness`` into the destination alpha only, with MIN blending; depth is tested (bodies
    hide their shadows) but not written. Pass 2 draws one ground rectangle over the union of the
    casters' ``shadow_bounds`` that multiplies the colour by the destination alpha and sets it
    back to 1 (so each pixel is darkened once, and the image stays opaque). Lines and anything
    transparent are drawn afterwards, over the shadow, and keep their colour."""
    if not casters or frame.ground_height is None or frame.light is None:
        return
    ctx, fbo = frame.ctx, frame.fbo
    res = Resources.of(ctx)
    direction = shadow_direction(frame.light)
    ground = float(frame.ground_height)
    bounds = [b for b in (c.shadow_bounds(direction, ground) for c in casters) if b is not None]
    if not bounds:
        return
    bounds = np.asarray(bounds, dtype=np.float64)
    rect = (bounds[:, 0].min(), bounds[:, 1].min(), bounds[:, 2].max(), bounds[:, 3].max())
    prog = res.shadow_program
    prog["u_shadow_dir"].value = tuple(direction)
    prog["u_ground"].value = ground
    prog["u_depth_pull"].value = SHADOW_DEPTH_PULL
    prog["u_strength"].value = float(strength)
    # pass 1: seen from a camera above the ground, exactly the light-facing triangles of a closed
    # mesh keep their winding once flattened, so back-face culling halves the overdraw
    fbo.depth_mask = False
    fbo.color_mask = (False, False, False, True)
    fbo.use()  # moderngl applies a framebuffer's masks when it is bound
    ctx.blend_equation = moderngl.MIN
    for caster in casters:
        caster.draw_shadow(frame)
    # pass 2: resolve over the rectangle, whatever the depth there
    fbo.color_mask = (True, True, True, True)
    fbo.use()
    ctx.blend_equation = moderngl.FUNC_ADD
    ctx.blend_func = (moderngl.ZERO, moderngl.DST_ALPHA, moderngl.ONE, moderngl.ZERO)
    ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
    rp = res.shadow_resolve_program
    rp["u_rect"].value = tuple(float(x) for x in rect)
    rp["u_ground"].value = ground
    res.shadow_resolve_vao.render(moderngl.TRIANGLE_STRIP)
    ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
    fbo.depth_mask = True
    fbo.use()
    ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
