"""Write layers into ONE self-contained HTML page with a small embedded WebGL viewer.

No network access and no extra package: the geometry is embedded as base64 little-endian
arrays (triangle soups with per-vertex normals and RGBA colours, line segments, points) in a
JSON block, drawn by about 200 lines of plain WebGL 1 JavaScript. Mouse: drag to rotate about
the vertical axis and the screen's horizontal axis, right-drag or shift-drag to pan, wheel to
zoom. After the first frame the page sets ``<body data-status="rendered">``; a script error sets
``data-status="error: ..."`` and logs it with ``console.error`` (what the headless-browser test
checks).
"""

from __future__ import annotations

import base64
import html
import json
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.viz.cameras import CameraPreset
from acoustisim.viz.layers import RGBA_ARRAY, Layer


def _b64(array: NDArray[Any], dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


def _cell_rgba(layer: Layer, n_cells: int) -> NDArray[np.uint8]:
    """RGBA (n_cells, 4) uint8 of each cell: the layer's array, or its uniform colour."""
    if layer.has_rgba:
        return np.asarray(layer.mesh.cell_data[RGBA_ARRAY], dtype=np.uint8).reshape(-1, 4)
    rgba = np.empty((n_cells, 4), dtype=np.uint8)
    rgba[:, :3] = np.round(np.clip(layer.color, 0.0, 1.0) * 255.0).astype(np.uint8)
    rgba[:, 3] = int(round(float(np.clip(layer.opacity, 0.0, 1.0)) * 255.0))
    return rgba


def _line_segments(mesh: Any) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Segments (k, 2) of every line cell and the cell index of each (k,)."""
    from vtkmodules.util.numpy_support import vtk_to_numpy

    cells = mesh.GetLines()
    if cells.GetNumberOfCells() == 0:
        return np.empty((0, 2), dtype=np.int64), np.empty(0, dtype=np.int64)
    offsets = vtk_to_numpy(cells.GetOffsetsArray()).astype(np.int64)
    connectivity = vtk_to_numpy(cells.GetConnectivityArray()).astype(np.int64)
    sizes = np.diff(offsets)
    cell_of_vertex = np.repeat(np.arange(sizes.size), sizes)
    same = cell_of_vertex[1:] == cell_of_vertex[:-1]
    start = np.flatnonzero(same)
    segments = np.column_stack([connectivity[start], connectivity[start + 1]])
    # Line cells come after the vertex cells in a PolyData's cell numbering.
    return segments, cell_of_vertex[start] + mesh.GetNumberOfVerts()


def layer_payload(layer: Layer) -> dict[str, Any] | None:
    """The JSON-ready drawing item of one layer (None when it has no geometry).

    Surfaces become triangle soups (3 vertices per triangle, smooth normals split at 40 degree
    creases), line layers segment soups, point layers points.
    """
    mesh = layer.mesh
    if mesh.n_points == 0:
        return None
    item: dict[str, Any] = {"name": layer.name, "size": float(layer.point_size), "flat": bool(layer.flat_points)}
    if layer.style == "points":
        points = np.asarray(mesh.points, dtype=float)
        rgba = np.empty((len(points), 4), dtype=np.uint8)
        rgba[:] = _cell_rgba(layer, 1)[0]
        positions, normals, colours, mode = points, None, rgba, "points"
    elif layer.style in ("lines", "wireframe"):
        if layer.style == "wireframe" or mesh.n_lines == 0:
            mesh = mesh.extract_all_edges()
        segments, cell = _line_segments(mesh)
        if segments.size == 0:
            return None
        cell_rgba = _cell_rgba(layer, mesh.n_cells) if layer.has_rgba else _cell_rgba(layer, 1)
        rgba = cell_rgba[cell] if layer.has_rgba else np.broadcast_to(cell_rgba[0], (len(cell), 4))
        positions = np.asarray(mesh.points, dtype=float)[segments].reshape(-1, 3)
        colours = np.repeat(rgba, 2, axis=0)
        normals, mode = None, "lines"
    else:
        surface = mesh.triangulate()
        if surface.GetNumberOfPolys() == 0:
            return None
        surface = surface.compute_normals(cell_normals=False, point_normals=True, split_vertices=True,
                                          feature_angle=40.0, auto_orient_normals=False, consistent_normals=False)
        faces = np.asarray(surface.faces).reshape(-1, 4)[:, 1:]
        n_other = surface.GetNumberOfVerts() + surface.GetNumberOfLines()
        if layer.has_rgba:
            rgba = np.asarray(surface.cell_data[RGBA_ARRAY], dtype=np.uint8).reshape(-1, 4)[n_other:]
        else:
            rgba = np.broadcast_to(_cell_rgba(layer, 1)[0], (len(faces), 4))
        positions = np.asarray(surface.points, dtype=float)[faces].reshape(-1, 3)
        normals = np.asarray(surface.point_data["Normals"], dtype=float)[faces].reshape(-1, 3)
        colours = np.repeat(np.asarray(rgba), 3, axis=0)
        mode = "triangles"
    item.update(
        mode=mode,
        count=int(len(positions)),
        transparent=bool(np.any(colours[:, 3] < 255)),
        pos=_b64(positions, "<f4"),
        nrm=None if normals is None else _b64(normals, "<f4"),
        col=_b64(colours, "u1"),
    )
    return item


def _hex(color: Sequence[float]) -> str:
    r, g, b = (int(round(255 * min(max(float(c), 0.0), 1.0))) for c in color)
    return f"#{r:02x}{g:02x}{b:02x}"


def page_data(layers: Sequence[Layer], camera: CameraPreset, title: str) -> dict[str, Any]:
    """Everything the page draws, as a JSON-ready dictionary."""
    items = [item for item in (layer_payload(layer) for layer in layers) if item is not None]
    return {
        "title": title,
        "camera": {
            "eye": list(camera.position_m),
            "target": list(camera.focal_point_m),
            "up": list(camera.view_up),
            "parallel": camera.parallel,
            "scale": camera.parallel_scale_m,
            "fov": camera.view_angle_deg,
        },
        "legend": [{"label": layer.label, "color": _hex(layer.color)} for layer in layers if layer.label],
        "items": items,
    }


_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>__TITLE__</title>
<style>
html,body{margin:0;height:100%;overflow:hidden;background:#fff;font:13px sans-serif}
canvas{display:block;width:100vw;height:100vh}
#title{position:absolute;left:10px;top:8px;font-size:16px}
#legend{position:absolute;right:10px;bottom:10px;background:rgba(255,255,255,.85);border:1px solid #999;padding:6px 8px}
#legend div{white-space:nowrap;line-height:18px}
#legend span{display:inline-block;width:12px;height:12px;margin-right:6px;vertical-align:-1px}
#help{position:absolute;left:10px;bottom:8px;color:#555}
</style></head>
<body data-status="loading"><canvas id="view"></canvas><div id="title"></div><div id="legend"></div>
<div id="help">drag: rotate &middot; right-drag or shift-drag: pan &middot; wheel: zoom</div>
<script type="application/json" id="scene-data">__DATA__</script>
<script>
"use strict";
window.addEventListener("error", function (e) {
  document.body.setAttribute("data-status", "error: " + e.message);
});
(function () {
  const data = JSON.parse(document.getElementById("scene-data").textContent);
  document.getElementById("title").textContent = data.title;
  const legend = document.getElementById("legend");
  if (!data.legend.length) legend.style.display = "none";
  data.legend.forEach(function (e) {
    const row = document.createElement("div"), sw = document.createElement("span");
    sw.style.background = e.color; row.appendChild(sw); row.appendChild(document.createTextNode(e.label));
    legend.appendChild(row);
  });
  const canvas = document.getElementById("view");
  const gl = canvas.getContext("webgl", {antialias: true, preserveDrawingBuffer: true, alpha: false});
  if (!gl) { console.error("WebGL is not available"); document.body.setAttribute("data-status", "error: no WebGL"); return; }
  function decode(b64, Type) {
    const s = atob(b64), bytes = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) bytes[i] = s.charCodeAt(i);
    return new Type(bytes.buffer);
  }
  const vsrc = "attribute vec3 p;attribute vec3 n;attribute vec4 c;uniform mat4 mvp;uniform float ps;" +
    "varying vec4 vc;varying vec3 vn;void main(){gl_Position=mvp*vec4(p,1.0);gl_PointSize=ps;vc=c;vn=n;}";
  const fsrc = "precision mediump float;varying vec4 vc;varying vec3 vn;uniform vec3 ld;uniform float lit;" +
    "uniform float pt;void main(){if(pt>0.5){vec2 q=gl_PointCoord-vec2(0.5);if(dot(q,q)>0.25)discard;}" +
    "float k=1.0;if(lit>0.5){k=0.45+0.55*abs(dot(normalize(vn),ld));}gl_FragColor=vec4(vc.rgb*k,vc.a);}";
  function shader(type, src) {
    const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  }
  const prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER, vsrc)); gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, fsrc));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
  gl.useProgram(prog);
  const loc = {p: gl.getAttribLocation(prog, "p"), n: gl.getAttribLocation(prog, "n"), c: gl.getAttribLocation(prog, "c"),
    mvp: gl.getUniformLocation(prog, "mvp"), ps: gl.getUniformLocation(prog, "ps"), ld: gl.getUniformLocation(prog, "ld"),
    lit: gl.getUniformLocation(prog, "lit"), pt: gl.getUniformLocation(prog, "pt")};
  function buffer(array) { const b = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.bufferData(gl.ARRAY_BUFFER, array, gl.STATIC_DRAW); return b; }
  const items = data.items.map(function (it) {
    return {mode: it.mode, count: it.count, transparent: it.transparent, size: it.size, flat: it.flat,
      pos: buffer(decode(it.pos, Float32Array)), nrm: it.nrm ? buffer(decode(it.nrm, Float32Array)) : null,
      col: buffer(decode(it.col, Uint8Array))};
  });
  // ---- camera
  const cam = {eye: data.camera.eye.slice(), target: data.camera.target.slice(), up: data.camera.up.slice(),
    parallel: data.camera.parallel, scale: data.camera.scale, fov: data.camera.fov};
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]], add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const mul = (a, s) => [a[0] * s, a[1] * s, a[2] * s], dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = a => mul(a, 1 / Math.hypot(a[0], a[1], a[2]));
  function rotate(v, axis, ang) {  // Rodrigues
    const k = norm(axis), c = Math.cos(ang), s = Math.sin(ang);
    return add(add(mul(v, c), mul(cross(k, v), s)), mul(k, dot(k, v) * (1 - c)));
  }
  function matrix() {
    const w = canvas.width, h = canvas.height, aspect = w / h;
    const f = norm(sub(cam.target, cam.eye)), r = norm(cross(f, cam.up)), u = cross(r, f);
    const dist = Math.hypot(...sub(cam.target, cam.eye));
    const view = [r[0], u[0], -f[0], 0, r[1], u[1], -f[1], 0, r[2], u[2], -f[2], 0,
      -dot(r, cam.eye), -dot(u, cam.eye), dot(f, cam.eye), 1];
    const near = Math.max(dist * 1e-3, 1e-4), far = dist * 20 + 100;
    let proj;
    if (cam.parallel) {
      const t = cam.scale, rr = t * aspect;
      proj = [1 / rr, 0, 0, 0, 0, 1 / t, 0, 0, 0, 0, -2 / (far - near), 0, 0, 0, -(far + near) / (far - near), 1];
    } else {
      const t = 1 / Math.tan(cam.fov * Math.PI / 360);
      proj = [t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, 2 * far * near / (near - far), 0];
    }
    const m = new Float32Array(16);
    for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) {
      let s = 0; for (let k = 0; k < 4; k++) s += proj[k * 4 + j] * view[i * 4 + k]; m[i * 4 + j] = s;
    }
    return {m: m, ld: mul(f, -1)};
  }
  function draw() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr)), h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, w, h); gl.clearColor(1, 1, 1, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    const mv = matrix();
    gl.uniformMatrix4fv(loc.mvp, false, mv.m); gl.uniform3fv(loc.ld, mv.ld);
    [false, true].forEach(function (pass) {
      if (pass) { gl.enable(gl.BLEND); gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA); gl.depthMask(false); }
      else { gl.disable(gl.BLEND); gl.depthMask(true); }
      items.forEach(function (it) {
        if (it.transparent !== pass) return;
        gl.bindBuffer(gl.ARRAY_BUFFER, it.pos); gl.enableVertexAttribArray(loc.p); gl.vertexAttribPointer(loc.p, 3, gl.FLOAT, false, 0, 0);
        if (it.nrm) { gl.bindBuffer(gl.ARRAY_BUFFER, it.nrm); gl.enableVertexAttribArray(loc.n); gl.vertexAttribPointer(loc.n, 3, gl.FLOAT, false, 0, 0); }
        else { gl.disableVertexAttribArray(loc.n); gl.vertexAttrib3f(loc.n, 0, 0, 1); }
        gl.bindBuffer(gl.ARRAY_BUFFER, it.col); gl.enableVertexAttribArray(loc.c); gl.vertexAttribPointer(loc.c, 4, gl.UNSIGNED_BYTE, true, 0, 0);
        gl.uniform1f(loc.lit, it.mode === "triangles" ? 1 : 0); gl.uniform1f(loc.pt, it.mode === "points" && !it.flat ? 1 : 0);
        gl.uniform1f(loc.ps, it.size * dpr);
        gl.drawArrays(it.mode === "triangles" ? gl.TRIANGLES : it.mode === "lines" ? gl.LINES : gl.POINTS, 0, it.count);
      });
    });
    gl.depthMask(true);
    const err = gl.getError();
    if (err !== gl.NO_ERROR) throw new Error("WebGL error " + err);
  }
  let pending = false;
  function redraw() { if (!pending) { pending = true; requestAnimationFrame(function () { pending = false; draw(); }); } }
  // ---- mouse
  let drag = null;
  canvas.addEventListener("contextmenu", e => e.preventDefault());
  canvas.addEventListener("mousedown", e => { drag = {x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey}; });
  window.addEventListener("mouseup", () => { drag = null; });
  window.addEventListener("mousemove", function (e) {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y; drag.x = e.clientX; drag.y = e.clientY;
    const f = sub(cam.target, cam.eye), dist = Math.hypot(...f), r = norm(cross(f, cam.up)), u = norm(cross(r, f));
    if (drag.pan) {
      const k = (cam.parallel ? 2 * cam.scale : 2 * dist * Math.tan(cam.fov * Math.PI / 360)) / canvas.clientHeight;
      const shift = add(mul(r, -dx * k), mul(u, dy * k));
      cam.eye = add(cam.eye, shift); cam.target = add(cam.target, shift);
    } else {
      let v = sub(cam.eye, cam.target), up = cam.up;
      v = rotate(v, [0, 0, 1], -dx * 0.01); up = rotate(up, [0, 0, 1], -dx * 0.01);
      const right = norm(cross(mul(v, -1), up));
      v = rotate(v, right, -dy * 0.01); up = rotate(up, right, -dy * 0.01);
      cam.eye = add(cam.target, v); cam.up = norm(up);
    }
    redraw();
  });
  canvas.addEventListener("wheel", function (e) {
    e.preventDefault();
    const k = Math.exp(e.deltaY * 0.001);
    if (cam.parallel) cam.scale *= k; else cam.eye = add(cam.target, mul(sub(cam.eye, cam.target), k));
    redraw();
  }, {passive: false});
  window.addEventListener("resize", redraw);
  draw();
  document.body.setAttribute("data-status", "rendered");
})();
</script></body></html>
"""


def render_page(layers: Sequence[Layer], camera: CameraPreset, title: str = "") -> str:
    """The HTML text of the page."""
    data = json.dumps(page_data(layers, camera, title), separators=(",", ":"))
    # Keep the JSON from closing its <script> element.
    data = data.replace("</", "<\\/")
    return _PAGE.replace("__TITLE__", html.escape(title)).replace("__DATA__", data)
