// check.js — the shader port's check page (/check): evaluates pbrdf.glsl on the server's grid
// of geometries into a float framebuffer, and compares with the Rust model's matrices.
"use strict";

window.runCheck = async function () {
  const data = await api("/api/check/cases");
  const pbrdf = await api("/assets/pbrdf.glsl", "text");
  document.getElementById("title").textContent = "shader port check";
  const cases = data.cases, N = cases.length;
  const canvas = el("canvas", { width: 12, height: N });
  const gl = webgl(canvas);
  if (!gl.getExtension("EXT_color_buffer_float")) throw new Error("EXT_color_buffer_float is not available: cannot read float results");
  // inputs: 8 RGBA32F texels per case
  const input = new Float32Array(8 * 4 * N);
  cases.forEach((c, k) => {
    const p = c.params, o = 32 * k;
    input.set([...c.normal, 0, ...c.to_light, 0, ...c.to_camera, 0, ...c.light_up, 0, ...c.camera_up, 0, p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8], p[9], 0, 0], o);
  });
  const tex = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, tex);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, 8, N, 0, gl.RGBA, gl.FLOAT, input);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  const fs = `#version 300 es
precision highp float;
precision highp sampler2D;
${pbrdf}
uniform sampler2D u_cases;
out vec4 o;
void main() {
  int k = int(gl_FragCoord.x), row = int(gl_FragCoord.y);
  vec4 t[8];
  for (int i = 0; i < 8; i++) t[i] = texelFetch(u_cases, ivec2(i, row), 0);
  Geometry g = make_geometry(t[0].xyz, t[1].xyz, t[2].xyz, t[3].xyz, t[4].xyz);
  Lobes l = evaluate_lobes(g, t[5].x, t[5].y, t[5].z);
  int c = k / 4, r = k - 4 * c;
  float rho_d = c == 0 ? t[6].w : (c == 1 ? t[7].x : t[7].y);
  float rho_ss = c == 0 ? t[6].x : (c == 1 ? t[6].y : t[6].z);
  mat4 M = total_channel(l, rho_d, t[5].w, rho_ss);
  o = vec4(M[0][r], M[1][r], M[2][r], M[3][r]);
}`;
  const vs = `#version 300 es
void main() { vec2 p = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0); gl_Position = vec4(p, 0.0, 1.0); }`;
  const prog = program(gl, vs, fs);
  const rt = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, rt);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, 12, N, 0, gl.RGBA, gl.FLOAT, null);
  const fb = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, rt, 0);
  if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) throw new Error("float framebuffer incomplete");
  gl.viewport(0, 0, 12, N);
  gl.useProgram(prog);
  gl.activeTexture(gl.TEXTURE0);
  gl.bindTexture(gl.TEXTURE_2D, tex);
  gl.uniform1i(gl.getUniformLocation(prog, "u_cases"), 0);
  gl.drawArrays(gl.TRIANGLES, 0, 3);
  const out = new Float32Array(12 * 4 * N);
  gl.readPixels(0, 0, 12, N, gl.RGBA, gl.FLOAT, out);
  // per case: 3 channels × 16 row-major elements
  const results = cases.map((_, k) => [0, 1, 2].map((c) => Array.from(out.subarray(48 * k + 16 * c, 48 * k + 16 * c + 16))));
  let worst = 0, worstCase = -1;
  results.forEach((r, k) => r.forEach((m, c) => {
    const ref = data.reference[k][c];
    const s = Math.max(...ref.map(Math.abs));
    const d = Math.max(...m.map((v, i) => Math.abs(v - ref[i])));
    const e = s > 0 ? d / s : d;
    if (!(e <= worst)) { worst = e; worstCase = k; }
  }));
  E.check = { results, worst, worstCase, tolerance: data.tolerance, cases: N, renderer: gl.getParameter(gl.RENDERER) };
  const pass = worst <= data.tolerance;
  document.getElementById("app").append(el("div", { class: "panel" },
    el("h3", {}, "pbrdf.glsl against ellipso_sim::optics (f64)"),
    el("div", {}, `${N} geometries × 3 channels × 16 elements on ${E.check.renderer}`),
    el("div", { class: pass ? "ok" : "bad", id: "verdict" }, `largest |ΔM|/max|M| = ${worst.toExponential(2)} (case ${worstCase}); tolerance ${data.tolerance}: ${pass ? "pass" : "FAIL"}`)));
  setStatus(pass ? "port agrees" : "port disagrees");
  markReady();
};
