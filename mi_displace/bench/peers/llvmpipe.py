"""Mesa's llvmpipe (OpenGL 4.5 on the CPU, headless EGL) through ``moderngl``: the peer of
``bench raster`` (:func:`mesh_frame`) and ``bench slicing`` (:class:`GLSlices`, the slicing
paper's algorithm as real OpenGL: slice polygons per base polygon drawn with the depth test
on, the α-test as a fragment ``discard`` against the height texture, §3.1).

Needs ``moderngl`` (the ``peers`` extra) and Mesa's EGL (``scripts/setup_peers.sh``);
:func:`context` raises :class:`~mi_displace.bench.peers.PeerUnavailable` without them.
"""
from __future__ import annotations

import os

import numpy as np

from mi_displace.bench._timing import median_time
from mi_displace.bench.peers import SYSTEM, PeerUnavailable, require

SLICE_VERTEX = """
#version 330
uniform mat4 mvp;
in vec3 pos; in vec2 uv; in float ramp; in vec3 normal;
out vec2 v_uv; out float v_ramp; out vec3 v_n;
void main() { gl_Position = mvp * vec4(pos, 1.0); v_uv = uv; v_ramp = ramp; v_n = normal; }
"""
SLICE_FRAGMENT = """
#version 330
uniform sampler2D height; uniform vec3 light; uniform vec3 albedo; uniform float ambient;
in vec2 v_uv; in float v_ramp; in vec3 v_n;
out vec4 colour;
void main() {
    if (texture(height, v_uv).r < v_ramp) discard;   // the alpha test (D >= h_alpha)
    colour = vec4(albedo * (ambient + max(dot(normalize(v_n), light), 0.0)), 1.0);
}
"""
MESH_VERTEX = """
#version 330
uniform mat4 mvp;
uniform vec3 to_light;
uniform vec3 albedo;
in vec3 in_pos;
in vec3 in_nrm;
out vec3 color;
void main() {
    color = albedo / 3.14159265 * max(dot(normalize(in_nrm), to_light), 0.0) + albedo * 0.1;
    gl_Position = mvp * vec4(in_pos, 1.0);
}
"""
MESH_FRAGMENT = """
#version 330
in vec3 color;
out vec4 frag;
void main() { frag = vec4(color, 1.0); }
"""


def context():
    """A standalone ``moderngl`` context on llvmpipe (EGL, headless); the caller releases it.

    Raises:
        PeerUnavailable: ``moderngl`` missing, no EGL context, or a renderer other than llvmpipe.
    """
    moderngl = require("moderngl")
    try:
        ctx = moderngl.create_standalone_context(backend="egl")
    except Exception as error:  # moderngl raises a bare Exception when EGL / Mesa is missing
        raise PeerUnavailable(f"no EGL context ({' '.join(str(error).split())}); "
                              f"install {SYSTEM}") from error
    renderer = ctx.info["GL_RENDERER"]
    if "llvmpipe" not in renderer:
        ctx.release()
        raise PeerUnavailable(f"the EGL renderer is {renderer!r}, not llvmpipe")
    return ctx


def renderer() -> str:
    """The GL renderer string of an llvmpipe context (e.g. ``llvmpipe (LLVM 15.0.7, 256 bits)``)."""
    ctx = context()
    try:
        return ctx.info["GL_RENDERER"]
    finally:
        ctx.release()


def look_at_mvp(origin, target, up, fov_x_deg: float, aspect: float, near=0.05, far=50.0) -> np.ndarray:
    """(4, 4) OpenGL projection x view matrix (column vectors) of a pinhole camera at
    ``origin`` looking at ``target`` (world units), horizontal field of view in degrees."""
    o, t, u = (np.asarray(x, np.float64) for x in (origin, target, up))
    f = t - o
    f /= np.linalg.norm(f)
    s = np.cross(f, u)
    s /= np.linalg.norm(s)
    v = np.cross(s, f)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = s, v, -f
    view[:3, 3] = -view[:3, :3] @ o
    tx = np.tan(np.radians(fov_x_deg) / 2)
    ty = tx / aspect
    proj = np.zeros((4, 4))
    proj[0, 0], proj[1, 1] = 1 / tx, 1 / ty
    proj[2, 2], proj[2, 3] = -(far + near) / (far - near), -2 * far * near / (far - near)
    proj[3, 2] = -1
    return proj @ view


class GLSlices:
    """Slice polygons drawn by OpenGL into an offscreen ``width`` x ``height_px`` target
    (the slicing paper's §3.1 algorithm).

    Args:
        sm: :class:`mi_displace.slicing.geometry.SliceMesh` (positions, uvs, rw[:, 0] = h_α, bn).
        height: (R, R) float32 α texture (rows along v), sampled bilinear + repeat.
        mvp: (4, 4) from :func:`look_at_mvp`; light: direction towards the light.

    Raises:
        PeerUnavailable: no llvmpipe context (:func:`context`).
    """

    def __init__(self, sm, height: np.ndarray, mvp: np.ndarray, width: int, height_px: int,
                 light=(0.6, -0.4, 0.7), albedo=(0.72, 0.42, 0.3), ambient=0.15):
        moderngl = require("moderngl")

        self.ctx = ctx = context()
        self.prog = ctx.program(vertex_shader=SLICE_VERTEX, fragment_shader=SLICE_FRAGMENT)
        data = np.concatenate([sm.positions, sm.uvs, sm.rw[:, :1], sm.bn], 1).astype("f4")
        self.vbo = ctx.buffer(data.tobytes())
        self.ibo = ctx.buffer(sm.faces.astype("u4").tobytes())
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "3f 2f 1f 3f", "pos", "uv", "ramp", "normal")],
                                    self.ibo)
        self.tex = ctx.texture(height.shape[::-1], 1, np.ascontiguousarray(height, "f4").tobytes(), dtype="f4")
        self.tex.repeat_x = self.tex.repeat_y = True
        self.tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.fbo = ctx.framebuffer(color_attachments=[ctx.texture((width, height_px), 4)],
                                   depth_attachment=ctx.depth_texture((width, height_px)))
        self.prog["mvp"].write(np.ascontiguousarray(mvp.T, "f4").tobytes())
        light = np.asarray(light, np.float64)
        self.prog["light"].value = tuple(light / np.linalg.norm(light))
        self.prog["albedo"].value = tuple(albedo)
        self.prog["ambient"].value = ambient
        self.size = (width, height_px)

    def frame(self) -> None:
        """Draw one frame: clear, all slices, finish (``ctx.finish``: the work is done)."""
        moderngl = require("moderngl")

        self.fbo.use()
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.fbo.clear(0.12, 0.13, 0.15, 1.0, depth=1.0)
        self.tex.use(0)
        self.vao.render(moderngl.TRIANGLES)
        self.ctx.finish()

    def image(self) -> np.ndarray:
        """(H, W, 3) float32 of the last frame (row 0 at the top)."""
        w, h = self.size
        data = np.frombuffer(self.fbo.read(components=3), np.uint8).reshape(h, w, 3)
        return data[::-1].astype(np.float32) / 255

    def release(self) -> None:
        self.ctx.release()


def mesh_frame(positions: np.ndarray, normals: np.ndarray, faces: np.ndarray,
               to_camera: np.ndarray, fov_deg: float, res: int, to_light, albedo) -> dict:
    """Draw a triangle mesh with per-vertex Lambert shading (one directional light + 0.1
    ambient) and depth test at ``res`` x ``res``, as Mitsuba's perspective camera sees it.

    Args:
        positions, normals: (V, 3) float32 (world units); faces: (F, 3) uint32.
        to_camera: (4, 4) world-to-camera matrix (Mitsuba's: +z forward, x to the left).
        fov_deg: the camera's field of view (degrees); to_light: unit direction to the light.

    Returns:
        ``llvmpipe_s`` (warm median frame: clear, draw, read-back), ``llvmpipe_upload_s``
        (the same with the vertex upload), the renderer, its thread count and ``image``
        ((res, res, 3) float32, row 0 at the top).
    """
    moderngl = require("moderngl")

    near, far = 0.1, 100.0
    f = 1 / np.tan(np.radians(fov_deg) / 2)
    # Mitsuba's camera looks along +z with x to the left: mirror x so the image matches
    projection = np.array([[-f, 0, 0, 0], [0, f, 0, 0],
                           [0, 0, (far + near) / (far - near), -2 * far * near / (far - near)],
                           [0, 0, 1, 0]])
    mvp = (projection @ to_camera).astype(np.float32)
    ctx = context()
    try:
        program = ctx.program(vertex_shader=MESH_VERTEX, fragment_shader=MESH_FRAGMENT)
        program["mvp"].write(mvp.T.tobytes())
        program["to_light"].value = tuple(to_light)
        program["albedo"].value = tuple(albedo)
        vertices = np.hstack([positions, normals]).astype(np.float32)
        vbo = ctx.buffer(vertices.tobytes())
        ibo = ctx.buffer(np.ascontiguousarray(faces, np.uint32).tobytes())
        vao = ctx.vertex_array(program, [(vbo, "3f 3f", "in_pos", "in_nrm")], ibo)
        fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((res, res), 4, dtype="f4")],
                              depth_attachment=ctx.depth_renderbuffer((res, res)))
        ctx.enable(moderngl.DEPTH_TEST)

        def frame():
            fbo.use()
            fbo.clear(0.1, 0.1, 0.1, 1.0)
            vao.render(moderngl.TRIANGLES)
            return np.frombuffer(fbo.read(components=3, dtype="f4"), np.float32)

        def upload_frame():
            vbo.write(vertices.tobytes())
            return frame()

        frame_s = median_time(frame, 5)
        upload_s = median_time(upload_frame, 3)
        image = frame().reshape(res, res, 3)[::-1]
        return {"llvmpipe_s": frame_s, "llvmpipe_upload_s": upload_s,
                "llvmpipe_renderer": ctx.info["GL_RENDERER"],
                "llvmpipe_threads": os.environ.get("LP_NUM_THREADS", "default (all cores)"),
                "image": image}
    finally:
        ctx.release()
