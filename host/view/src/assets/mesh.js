// mesh.js — the binary mesh buffers the server sends, and picking by ray casting.
"use strict";

// /api/material/mesh.bin (layout: host/src/view/material.rs)
function decodeMaterial(buf) {
  const u = new Uint32Array(buf, 0, 2);
  const n = u[0], t = u[1];
  let off = 8;
  const f32 = (count) => { const a = new Float32Array(buf, off, count); off += count * 4; return a; };
  const u32 = (count) => { const a = new Uint32Array(buf, off, count); off += count * 4; return a; };
  return { n, t, pos: f32(3 * n), nrm: f32(3 * n), params: f32(10 * n), std: f32(10 * n), nstd: f32(n), samples: u32(n), status: u32(n), idx: u32(3 * t) };
}

// /api/live/mesh.bin (layout: host/src/view/follow.rs mesh_to_bytes)
function decodePlainMesh(buf) {
  const u = new Uint32Array(buf, 0, 2);
  const n = u[0], t = u[1];
  let off = 8;
  const pos = new Float32Array(buf, off, 3 * n); off += 12 * n;
  const nrm = new Float32Array(buf, off, 3 * n); off += 12 * n;
  const idx = new Uint32Array(buf, off, 3 * t);
  return { n, t, pos, nrm, idx };
}

// Nearest triangle hit by the ray (origin o, direction d); returns the nearest vertex of it.
function pickVertex(mesh, o, d) {
  let best = Infinity, vertex = -1;
  const P = mesh.pos, I = mesh.idx;
  for (let k = 0; k < mesh.t; k++) {
    const a = I[3 * k], b = I[3 * k + 1], c = I[3 * k + 2];
    const p0 = [P[3 * a], P[3 * a + 1], P[3 * a + 2]];
    const e1 = sub([P[3 * b], P[3 * b + 1], P[3 * b + 2]], p0), e2 = sub([P[3 * c], P[3 * c + 1], P[3 * c + 2]], p0);
    const pv = cross(d, e2), det = dot(e1, pv);
    if (Math.abs(det) < 1e-20) continue;
    const inv = 1 / det, tv = sub(o, p0);
    const u = dot(tv, pv) * inv;
    if (u < 0 || u > 1) continue;
    const q = cross(tv, e1), v = dot(d, q) * inv;
    if (v < 0 || u + v > 1) continue;
    const t = dot(e2, q) * inv;
    if (t > 0 && t < best) { best = t; const w = [1 - u - v, u, v]; vertex = [a, b, c][w.indexOf(Math.max(...w))]; }
  }
  return vertex;
}

// The world ray under a canvas pixel for view/projection matrices.
function rayAt(canvas, e, cam) {
  const r = canvas.getBoundingClientRect();
  const x = ((e.clientX - r.left) / r.width) * 2 - 1, y = 1 - ((e.clientY - r.top) / r.height) * 2;
  const eye = cam.eye(), f = norm(sub(cam.centre, eye)), right = norm(cross(f, [0, 0, 1])), up = cross(right, f);
  const h = Math.tan(0.3), aspect = r.width / r.height;
  return { o: eye, d: norm(add(f, add(scale(right, x * h * aspect), scale(up, y * h)))) };
}
