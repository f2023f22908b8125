// common.js — shared by every page: token-carrying fetches, error capture, WebGL helpers,
// 4×4 matrices, colour maps. No third-party code.
"use strict";
const E = (window.__ellipso = { ready: false, errors: [], frames: 0 });
const TOKEN = document.body.dataset.token;
const MODE = document.body.dataset.mode;

function reportError(msg) {
  E.errors.push(String(msg));
  const box = document.getElementById("errors");
  box.hidden = false;
  box.textContent = E.errors.join("\n");
}
window.addEventListener("error", (e) => reportError(e.message || e));
window.addEventListener("unhandledrejection", (e) => reportError(e.reason && e.reason.stack ? e.reason.stack : e.reason));

function url(path, params) {
  const u = new URL(path, location.origin);
  u.searchParams.set("token", TOKEN);
  for (const [k, v] of Object.entries(params || {})) u.searchParams.set(k, v);
  return u.toString();
}
async function api(path, kind) {
  const r = await fetch(url(path));
  if (!r.ok) throw new Error(path + ": HTTP " + r.status + " " + (await r.text()));
  return kind === "bin" ? r.arrayBuffer() : kind === "text" ? r.text() : r.json();
}
function el(tag, attrs, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "class") e.className = v; else if (k.startsWith("on")) e.addEventListener(k.slice(2), v); else e.setAttribute(k, v);
  }
  for (const c of children) e.append(c);
  return e;
}
function setStatus(text) { document.getElementById("status").textContent = text; }
function markReady() { E.ready = true; document.body.dataset.ready = "1"; }
function fmt(v, d) { return v === null || v === undefined ? "–" : !isFinite(v) ? String(v) : Number(v).toFixed(d === undefined ? 3 : d); }

// ---- WebGL ----
function compile(gl, type, src) {
  const s = gl.createShader(type);
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(s));
  return s;
}
function program(gl, vs, fs) {
  const p = gl.createProgram();
  gl.attachShader(p, compile(gl, gl.VERTEX_SHADER, vs));
  gl.attachShader(p, compile(gl, gl.FRAGMENT_SHADER, fs));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error("link: " + gl.getProgramInfoLog(p));
  return p;
}
function webgl(canvas) {
  const gl = canvas.getContext("webgl2", { antialias: true, preserveDrawingBuffer: true });
  if (!gl) throw new Error("WebGL2 is not available in this browser");
  return gl;
}

// ---- matrices (column-major Float32Array, as GL wants) ----
const M4 = {
  perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0]);
  },
  lookAt(eye, at, up) {
    const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
    return new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
  },
  mul(a, b) {
    const o = new Float32Array(16);
    for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      o[c * 4 + r] = s;
    }
    return o;
  },
};
function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
function add(a, b) { return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]; }
function scale(a, k) { return [a[0] * k, a[1] * k, a[2] * k]; }
function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
function norm(a) { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; }
function sph(az, el, r) { const a = az * Math.PI / 180, e = el * Math.PI / 180; return [r * Math.cos(e) * Math.cos(a), r * Math.cos(e) * Math.sin(a), r * Math.sin(e)]; }

// ---- colour maps (viridis polynomial fit; diverging blue–white–red) ----
const GLSL_COLOUR = `
vec3 viridis(float t) {
  t = clamp(t, 0.0, 1.0);
  const vec3 c0 = vec3(0.2777, 0.0054, 0.3340), c1 = vec3(0.1050, 1.4046, 1.3846), c2 = vec3(-0.3308, 0.2148, 0.0950);
  const vec3 c3 = vec3(-4.6342, -5.7991, -19.3324), c4 = vec3(6.2283, 14.1799, 56.6906), c5 = vec3(4.7764, -13.7451, -65.3530);
  const vec3 c6 = vec3(-5.4355, 4.6459, 26.3124);
  return c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6)))));
}
vec3 diverging(float v) {
  v = clamp(v, -1.0, 1.0);
  return v < 0.0 ? mix(vec3(1.0), vec3(0.19, 0.36, 0.75), -v) : mix(vec3(1.0), vec3(0.75, 0.16, 0.16), v);
}
vec3 hsv2rgb(vec3 c) {
  vec3 p = abs(fract(c.xxx + vec3(1.0, 2.0 / 3.0, 1.0 / 3.0)) * 6.0 - 3.0);
  return c.z * mix(vec3(1.0), clamp(p - 1.0, 0.0, 1.0), c.y);
}
vec3 to_srgb(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}`;
function viridisJs(t) {
  t = Math.min(1, Math.max(0, t));
  const c = [[0.2777, 0.0054, 0.334], [0.105, 1.4046, 1.3846], [-0.3308, 0.2148, 0.095], [-4.6342, -5.7991, -19.3324], [6.2283, 14.1799, 56.6906], [4.7764, -13.7451, -65.353], [-5.4355, 4.6459, 26.3124]];
  return [0, 1, 2].map((k) => { let v = 0; for (let i = 6; i >= 0; i--) v = v * t + c[i][k]; return Math.round(255 * Math.min(1, Math.max(0, v))); });
}
function legendBar(canvas, fn) {
  const ctx = canvas.getContext("2d");
  for (let x = 0; x < canvas.width; x++) {
    const [r, g, b] = fn(x / (canvas.width - 1));
    ctx.fillStyle = `rgb(${r},${g},${b})`;
    ctx.fillRect(x, 0, 1, canvas.height);
  }
}

// ---- orbit camera: drag to rotate, wheel to zoom, shift-drag (or right-drag) to move the light ----
function orbit(canvas, centre, radius, onChange, onLightDrag, onClick) {
  const o = { az: -60, el: 25, dist: 4.6 * radius, centre, radius };
  let drag = null;
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY, light: e.shiftKey || e.button === 2, moved: 0 }; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY; drag.moved += Math.abs(dx) + Math.abs(dy);
    if (drag.light) onLightDrag(dx, dy);
    else { o.az -= dx * 0.4; o.el = Math.max(-89, Math.min(89, o.el + dy * 0.4)); onChange(); }
  });
  canvas.addEventListener("pointerup", (e) => { if (drag && drag.moved < 3 && onClick) onClick(e); drag = null; });
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); o.dist = Math.max(1.2 * radius, Math.min(20 * radius, o.dist * Math.exp(e.deltaY * 0.001))); onChange(); }, { passive: false });
  o.eye = () => add(centre, sph(o.az, o.el, o.dist));
  o.up = () => { const f = norm(sub(centre, o.eye())); const r = norm(cross(f, [0, 0, 1])); return cross(r, f); };
  o.matrices = (aspect) => {
    const view = M4.lookAt(o.eye(), centre, [0, 0, 1]);
    const proj = M4.perspective(0.6, aspect, o.dist * 0.05, o.dist * 4);
    return { view, proj, viewProj: M4.mul(proj, view) };
  };
  return o;
}

window.addEventListener("DOMContentLoaded", () => {
  const run = { material: window.runMaterial, live: window.runLive, check: window.runCheck }[MODE];
  if (!run) { reportError("unknown mode " + MODE); return; }
  run().catch((e) => reportError(e && e.stack ? e.stack : e));
});
