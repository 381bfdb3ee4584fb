"""The paper's algorithm as real OpenGL (benchmark baseline): slice polygons per base
polygon drawn with the depth test on, the α-test as a fragment ``discard`` against the
height texture (§3.1).  Runs on Mesa's llvmpipe through moderngl + EGL (headless).

:func:`setup` installs what it needs where it can (``pip install moderngl``; Debian
``libegl1 libgl1-mesa-dri libegl-mesa0`` through apt-get as root) and returns ``None`` or
the reason it cannot run.  These are bench-only dependencies, not package dependencies.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time

import numpy as np

MODERNGL = "moderngl==5.13.0"
DEBIAN = ("libegl1", "libgl1-mesa-dri", "libegl-mesa0")

VERTEX = """
#version 330
uniform mat4 mvp;
in vec3 pos; in vec2 uv; in float ramp; in vec3 normal;
out vec2 v_uv; out float v_ramp; out vec3 v_n;
void main() { gl_Position = mvp * vec4(pos, 1.0); v_uv = uv; v_ramp = ramp; v_n = normal; }
"""
FRAGMENT = """
#version 330
uniform sampler2D height; uniform vec3 light; uniform vec3 albedo; uniform float ambient;
in vec2 v_uv; in float v_ramp; in vec3 v_n;
out vec4 colour;
void main() {
    if (texture(height, v_uv).r < v_ramp) discard;   // the alpha test (D >= h_alpha)
    colour = vec4(albedo * (ambient + max(dot(normalize(v_n), light), 0.0)), 1.0);
}
"""


def setup() -> str | None:
    """Make moderngl + an EGL llvmpipe context available; ``None`` or why not."""
    try:
        import moderngl  # noqa: F401
    except ImportError:
        r = subprocess.run([sys.executable, "-m", "pip", "install", "-q", MODERNGL],
                           capture_output=True, text=True)
        if r.returncode != 0:
            return f"pip install {MODERNGL} failed: {r.stderr.strip()[-200:]}"
    try:
        import moderngl

        moderngl.create_standalone_context(backend="egl").release()
        return None
    except Exception as first:  # no EGL / GL driver: try the Debian packages
        if shutil.which("apt-get") is None or os.geteuid() != 0:
            return f"no EGL context ({first}); install {' '.join(DEBIAN)}"
        r = subprocess.run(["apt-get", "install", "-y", "-q", *DEBIAN], capture_output=True, text=True)
        if r.returncode != 0:
            return f"apt-get install {' '.join(DEBIAN)} failed: {r.stderr.strip()[-200:]}"
        try:
            import moderngl

            moderngl.create_standalone_context(backend="egl").release()
            return None
        except Exception as e:
            return f"no EGL context after installing {' '.join(DEBIAN)}: {e}"


def look_at_mvp(origin, target, up, fov_x_deg: float, aspect: float, near=0.05, far=50.0) -> np.ndarray:
    """OpenGL projection x view matrix (column vectors) of a pinhole camera."""
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
    """Slice polygons drawn by OpenGL into an offscreen ``width`` x ``height`` target.

    Args:
        sm: :class:`mi_displace.slicing.geometry.SliceMesh` (positions, uvs, rw[:, 0] = h_α, bn).
        height: (R, R) float32 α texture (rows along v), sampled bilinear + repeat.
        mvp: (4, 4) from :func:`look_at_mvp`; light: unit direction towards the light.
    """

    def __init__(self, sm, height: np.ndarray, mvp: np.ndarray, width: int, height_px: int,
                 light=(0.6, -0.4, 0.7), albedo=(0.72, 0.42, 0.3), ambient=0.15):
        import moderngl

        self.ctx = moderngl.create_standalone_context(backend="egl")
        ctx = self.ctx
        self.prog = ctx.program(vertex_shader=VERTEX, fragment_shader=FRAGMENT)
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

    def frame(self) -> float:
        """Draw one frame (clear, all slices, finish); wall seconds."""
        import moderngl

        start = time.perf_counter()
        self.fbo.use()
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.fbo.clear(0.12, 0.13, 0.15, 1.0, depth=1.0)
        self.tex.use(0)
        self.vao.render(moderngl.TRIANGLES)
        self.ctx.finish()
        return time.perf_counter() - start

    def image(self) -> np.ndarray:
        """(H, W, 3) float32 of the last frame (row 0 at the top)."""
        w, h = self.size
        data = np.frombuffer(self.fbo.read(components=3), np.uint8).reshape(h, w, 3)
        return data[::-1].astype(np.float32) / 255

    def release(self) -> None:
        self.ctx.release()
