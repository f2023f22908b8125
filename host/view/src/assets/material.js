// material.js — fitted-material mode: fit.ply with the per-vertex pBRDF evaluated per pixel in
// the shader port (pbrdf.glsl), an orbit camera, a movable point light, polarised or unpolarised
// light, any Mueller element, DoLP/AoLP, parameter maps and a vertex picker.
"use strict";

const MAT_VS = `#version 300 es
in vec3 a_pos; in vec3 a_nrm; in vec4 a_p0; in vec3 a_ss; in vec3 a_d; in float a_grey; in float a_map; in float a_cat;
uniform mat4 u_viewProj;
out vec3 v_pos; out vec3 v_nrm; out vec4 v_p0; out vec3 v_ss; out vec3 v_d; out float v_grey; out float v_map; flat out float v_cat;
void main() {
  v_pos = a_pos; v_nrm = a_nrm; v_p0 = a_p0; v_ss = a_ss; v_d = a_d; v_grey = a_grey; v_map = a_map; v_cat = a_cat;
  gl_Position = u_viewProj * vec4(a_pos, 1.0);
}`;

function matFs(pbrdf) {
  return `#version 300 es
precision highp float;
${pbrdf}
${GLSL_COLOUR}
in vec3 v_pos; in vec3 v_nrm; in vec4 v_p0; in vec3 v_ss; in vec3 v_d; in float v_grey; in float v_map; flat in float v_cat;
uniform vec3 u_eye; uniform vec3 u_light; uniform vec3 u_camUp; uniform float u_polarised; uniform float u_psi;
uniform float u_exposure; uniform float u_d0; uniform int u_display; uniform ivec2 u_elem; uniform vec2 u_range;
uniform vec3 u_palette[18]; uniform vec3 u_pick; uniform float u_pickR;
out vec4 o;
void main() {
  vec3 n = normalize(v_nrm);
  vec3 wo = normalize(u_eye - v_pos);
  vec3 col;
  if (v_grey > 0.5 && u_display != 6) {
    col = vec3(0.30 + 0.25 * abs(dot(normalize(v_nrm), wo)));
  } else if (u_display == 4) {
    col = viridis((v_map - u_range.x) / max(u_range.y - u_range.x, 1e-12));
  } else if (u_display == 5) {
    col = n * 0.5 + 0.5;
  } else if (u_display == 6) {
    col = u_palette[int(v_cat + 0.5)];
  } else {
    vec3 to_light = u_light - v_pos;
    float d2 = dot(to_light, to_light);
    Geometry g = make_geometry(n, to_light, wo, u_camUp, u_camUp);
    Lobes l = evaluate_lobes(g, v_p0.x, v_p0.y, v_p0.z);
    vec4 s_in = vec4(1.0, u_polarised * cos(2.0 * u_psi), u_polarised * sin(2.0 * u_psi), 0.0);
    mat4 P[3];
    vec4 s[3];
    for (int c = 0; c < 3; c++) {
      P[c] = total_channel(l, v_d[c], v_p0.w, v_ss[c]);
      s[c] = P[c] * s_in * (u_d0 * u_d0 / d2);
    }
    if (u_display == 0) {
      col = to_srgb(vec3(s[0].x, s[1].x, s[2].x) * u_exposure);
    } else if (u_display == 1) {
      mat4 M = (P[0] + P[1] + P[2]) / 3.0;
      float m00 = M[0][0];
      if (u_elem == ivec2(0, 0)) {
        col = m00 > 0.0 ? viridis((log(m00) / log(10.0) - u_range.x) / (u_range.y - u_range.x)) : vec3(0.0);
      } else {
        col = m00 > 0.0 ? diverging(M[u_elem.y][u_elem.x] / m00) : vec3(0.0);
      }
    } else {
      vec4 m = (s[0] + s[1] + s[2]) / 3.0;
      float dolp = m.x > 0.0 ? length(m.yz) / m.x : 0.0;
      // no light reaching the camera: black (as the Mueller and AoLP displays), not DoLP 0
      if (u_display == 2) col = m.x > 0.0 ? viridis(dolp) : vec3(0.0);
      else {
        float aolp = 0.5 * atan(m.z, m.y);
        if (aolp < 0.0) aolp += PI;
        col = m.x > 0.0 ? hsv2rgb(vec3(aolp / PI, clamp(dolp, 0.0, 1.0), 1.0)) : vec3(0.0);
      }
    }
  }
  if (u_pickR > 0.0 && distance(v_pos, u_pick) < u_pickR) col = mix(col, vec3(1.0, 0.2, 1.0), 0.7);
  o = vec4(col, 1.0);
}`;
}

const DISPLAYS = [
  ["rendered", "rendered (s0, RGB)"], ["mueller", "Mueller element (pick below)"], ["dolp", "DoLP"], ["aolp", "AoLP (hue) × DoLP (saturation)"],
  ["eta", "η"], ["sigma_s", "σs"], ["sigma_ss", "σss"], ["rho_s", "ρs"], ["rho_ss", "ρss (mean RGB)"], ["rho_d", "ρd (mean RGB)"],
  ["std_eta", "σ(η) standard error"], ["std_rho_d", "σ(ρd) standard error"], ["normal_std", "normal σ (deg)"], ["samples", "samples used"],
  ["normal", "normal"], ["flags", "flags"],
];
// one colour per fit flag (info.flags order, the last one "Invalid"), then "no flag"
const FLAG_COLOURS = [[0.85, 0.2, 0.2], [0.9, 0.5, 0.1], [0.25, 0.25, 0.3], [1, 0.95, 0.3], [0.3, 0.6, 1], [0.6, 0.3, 0.9], [0.2, 0.8, 0.8], [0.95, 0.5, 0.7], [0.55, 0.35, 0.2], [0.7, 0.7, 0.95], [0.9, 0.9, 0.6], [0.4, 0.55, 0.4], [0.6, 0.6, 0.6], [0.2, 0.4, 0.6], [0.8, 0.4, 0.4], [0.5, 0.3, 0.5], [1, 0, 1]];
const NO_FLAG_COLOUR = [0.35, 0.75, 0.35];
// the display's colour range: the fit's shared ranges (the PNG maps'), mean RGB over channels
const PARAM_INDEX = { eta: [0], sigma_s: [1], sigma_ss: [2], rho_s: [3], rho_ss: [4, 5, 6], rho_d: [7, 8, 9] };
const STD_INDEX = { std_eta: [0], std_rho_d: [7, 8, 9] };

window.runMaterial = async function () {
  const info = await api("/api/material/info");
  const mesh = decodeMaterial(await api("/api/material/mesh.bin", "bin"));
  const pbrdf = await api("/assets/pbrdf.glsl", "text");
  document.getElementById("title").textContent = `fitted material · ${info.file} · ${info.vertices} vertices, ${info.triangles} triangles`;
  const app = document.getElementById("app");
  const canvas = el("canvas", { class: "gl", width: 760, height: 600, id: "view" });
  const side = el("div", { class: "side" });
  app.append(canvas, side);
  const gl = webgl(canvas);
  const prog = program(gl, MAT_VS, matFs(pbrdf));
  const n = mesh.n;
  const centre = info.centre, radius = info.radius;
  const INVALID = 1 << info.invalid_bit, WITHHELD = 1 << info.withheld_bit, ETA_WITHHELD = 1 << info.eta_withheld_bit;
  // grey by default: what the fit's identifiability rule withholds (as the PNG maps) and invalid values
  const state = { display: "rendered", elem: [0, 0], polarised: false, psi: 0, exposure: 1.0, lightAz: -25, lightEl: 40, lightDist: 4 * radius, greyMask: WITHHELD | INVALID, pick: -1 };

  // attributes
  const p0 = new Float32Array(4 * n), ss = new Float32Array(3 * n), dd = new Float32Array(3 * n);
  for (let i = 0; i < n; i++) {
    const q = mesh.params.subarray(10 * i, 10 * i + 10);
    p0.set([q[0], q[1], q[2], q[3]], 4 * i); ss.set([q[4], q[5], q[6]], 3 * i); dd.set([q[7], q[8], q[9]], 3 * i);
  }
  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  const buffers = {};
  function attrib(name, data, size) {
    const loc = gl.getAttribLocation(prog, name);
    const b = buffers[name] || (buffers[name] = gl.createBuffer());
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    if (loc >= 0) { gl.enableVertexAttribArray(loc); gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0); }
  }
  attrib("a_pos", mesh.pos, 3); attrib("a_nrm", mesh.nrm, 3); attrib("a_p0", p0, 4); attrib("a_ss", ss, 3); attrib("a_d", dd, 3);
  const ib = gl.createBuffer();
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, mesh.idx, gl.STATIC_DRAW);

  function scalarOf(i, key) {
    const P = mesh.params, S = mesh.std, k = 10 * i;
    const mean3 = (a, o) => (a[k + o] + a[k + o + 1] + a[k + o + 2]) / 3;
    switch (key) {
      case "eta": return P[k]; case "sigma_s": return P[k + 1]; case "sigma_ss": return P[k + 2]; case "rho_s": return P[k + 3];
      case "rho_ss": return mean3(P, 4); case "rho_d": return mean3(P, 7);
      case "std_eta": return S[k]; case "std_rho_d": return mean3(S, 7);
      case "normal_std": return mesh.nstd[i]; case "samples": return mesh.samples[i];
    }
    return 0;
  }
  const nFlags = info.flags.length;  // the fit's flags, then "Invalid"
  function category(st) {
    for (let b = 0; b < nFlags; b++) if (st & info.flag_bits[b]) return b;
    return nFlags;
  }
  function sharedRange(table, idx) {
    const r = idx.map((k) => table[k]);
    return [Math.min(...r.map((x) => x[0])), Math.max(...r.map((x) => x[1]))];
  }
  let range = [0, 1];
  function upload() {
    const grey = new Float32Array(n), map = new Float32Array(n), cat = new Float32Array(n);
    const vals = [];
    const etaDisplay = state.display === "eta" || state.display === "std_eta";
    for (let i = 0; i < n; i++) {
      const st = mesh.status[i];
      grey[i] = st & (state.greyMask | (etaDisplay ? ETA_WITHHELD : 0)) ? 1 : 0;
      cat[i] = category(st);
      const v = scalarOf(i, state.display);
      map[i] = isFinite(v) ? v : 1e30;
      if (!(st & (WITHHELD | INVALID)) && isFinite(v)) vals.push(v);
    }
    if (PARAM_INDEX[state.display]) range = sharedRange(info.ranges, PARAM_INDEX[state.display]);
    else if (STD_INDEX[state.display]) range = sharedRange(info.std_ranges, STD_INDEX[state.display]);
    else {
      vals.sort((a, b) => a - b);
      range = vals.length ? [vals[Math.floor(0.01 * (vals.length - 1))], vals[Math.ceil(0.99 * (vals.length - 1))]] : [0, 1];
      if (!(range[1] > range[0])) range = [range[0] - 0.5 * Math.abs(range[0] || 1) * 0.1, range[0] + Math.abs(range[0] || 1) * 0.05];
    }
    attrib("a_grey", grey, 1); attrib("a_map", map, 1); attrib("a_cat", cat, 1);
    legend();
  }

  const cam = orbit(canvas, centre, radius, draw, (dx, dy) => { state.lightAz -= dx * 0.5; state.lightEl = Math.max(-80, Math.min(89, state.lightEl + dy * 0.5)); syncControls(); draw(); }, (e) => {
    const r = rayAt(canvas, e, cam);
    state.pick = pickVertex(mesh, r.o, r.d);
    showPick(); draw();
  });
  const lightPos = () => add(centre, sph(state.lightAz, state.lightEl, state.lightDist));

  function draw() {
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(0.063, 0.067, 0.078, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(prog);
    const m = cam.matrices(canvas.width / canvas.height);
    const U = (name) => gl.getUniformLocation(prog, name);
    gl.uniformMatrix4fv(U("u_viewProj"), false, m.viewProj);
    gl.uniform3fv(U("u_eye"), cam.eye());
    gl.uniform3fv(U("u_camUp"), cam.up());
    gl.uniform3fv(U("u_light"), lightPos());
    gl.uniform1f(U("u_polarised"), state.polarised ? 1 : 0);
    gl.uniform1f(U("u_psi"), (state.psi * Math.PI) / 180);
    gl.uniform1f(U("u_exposure"), state.exposure);
    gl.uniform1f(U("u_d0"), 4 * radius);
    const code = { rendered: 0, mueller: 1, dolp: 2, aolp: 3, normal: 5, flags: 6 }[state.display];
    gl.uniform1i(U("u_display"), code === undefined ? 4 : code);
    gl.uniform2i(U("u_elem"), state.elem[0], state.elem[1]);
    gl.uniform2fv(U("u_range"), state.display === "mueller" ? [-3, 0.5] : range);
    gl.uniform3fv(U("u_palette"), new Float32Array(FLAG_COLOURS.slice(0, nFlags).concat([NO_FLAG_COLOUR]).flat()));
    const pk = state.pick >= 0 ? [mesh.pos[3 * state.pick], mesh.pos[3 * state.pick + 1], mesh.pos[3 * state.pick + 2]] : [0, 0, 0];
    gl.uniform3fv(U("u_pick"), pk);
    gl.uniform1f(U("u_pickR"), state.pick >= 0 ? 0.025 * radius : 0);
    gl.bindVertexArray(vao);
    gl.drawElements(gl.TRIANGLES, 3 * mesh.t, gl.UNSIGNED_INT, 0);
    E.frames++;
  }

  // ---- controls ----
  const displaySel = el("select", { id: "display" });
  for (const [k, label] of DISPLAYS) displaySel.append(el("option", { value: k }, label));
  const grid = el("div", { class: "grid4" });
  const elemButtons = [];
  for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) {
    const b = el("button", { onclick: () => { state.elem = [i, j]; state.display = "mueller"; displaySel.value = "mueller"; syncControls(); upload(); draw(); } }, `M${i}${j}`);
    elemButtons.push([i, j, b]); grid.append(b);
  }
  const pol = el("input", { type: "checkbox", id: "polarised" });
  const psi = el("input", { type: "range", min: 0, max: 180, step: 1, value: 0 });
  const exposure = el("input", { type: "range", min: -4, max: 4, step: 0.05, value: 0 });
  const laz = el("input", { type: "range", min: -180, max: 180, step: 1, value: state.lightAz });
  const lel = el("input", { type: "range", min: -80, max: 89, step: 1, value: state.lightEl });
  const legendCanvas = el("canvas", { width: 200, height: 12 });
  const legendText = el("span", { class: "muted", id: "legend-text" });
  const pickBox = el("div", { class: "muted" }, "click the object to pick a vertex");
  displaySel.addEventListener("change", () => { state.display = displaySel.value; upload(); draw(); });
  pol.addEventListener("change", () => { state.polarised = pol.checked; draw(); });
  psi.addEventListener("input", () => { state.psi = +psi.value; draw(); });
  exposure.addEventListener("input", () => { state.exposure = Math.pow(2, +exposure.value); draw(); });
  laz.addEventListener("input", () => { state.lightAz = +laz.value; draw(); });
  lel.addEventListener("input", () => { state.lightEl = +lel.value; draw(); });
  function syncControls() {
    laz.value = ((state.lightAz + 540) % 360) - 180; lel.value = state.lightEl;
    for (const [i, j, b] of elemButtons) b.className = state.display === "mueller" && state.elem[0] === i && state.elem[1] === j ? "on" : "";
  }
  function legend() {
    const ctx = legendCanvas.getContext("2d");
    ctx.clearRect(0, 0, 200, 12);
    const d = state.display;
    if (d === "mueller" && !(state.elem[0] === 0 && state.elem[1] === 0)) {
      legendBar(legendCanvas, (t) => { const v = 2 * t - 1, w = 1 - Math.abs(v); return v < 0 ? [255 * (w + (1 - w) * 0.19), 255 * (w + (1 - w) * 0.36), 255 * (w + (1 - w) * 0.75)] : [255 * (w + (1 - w) * 0.75), 255 * (w + (1 - w) * 0.16), 255 * (w + (1 - w) * 0.16)]; });
      legendText.textContent = `M${state.elem[0]}${state.elem[1]}/M00: −1 … +1`;
    } else if (d === "mueller") { legendBar(legendCanvas, viridisJs); legendText.textContent = "log10 M00: −3 … 0.5"; }
    else if (d === "dolp") { legendBar(legendCanvas, viridisJs); legendText.textContent = "DoLP 0 … 1"; }
    else if (d === "aolp") { legendBar(legendCanvas, (t) => hsvJs(t)); legendText.textContent = "AoLP 0° … 180° (camera frame)"; }
    else if (d === "rendered") legendText.textContent = "s0 per channel × exposure, sRGB";
    else if (d === "normal") legendText.textContent = "n·½+½ (world)";
    else if (d === "flags") legendText.textContent = "first flag of each vertex (swatches below; green: no flag)";
    else { legendBar(legendCanvas, viridisJs); legendText.textContent = `${fmt(range[0])} … ${fmt(range[1])} (1st–99th pct)`; }
    legendCanvas.hidden = d === "rendered" || d === "normal" || d === "flags";
  }
  function hsvJs(t) { const h = t * 6, c = 1, x = 1 - Math.abs((h % 2) - 1); const [r, g, b] = h < 1 ? [c, x, 0] : h < 2 ? [x, c, 0] : h < 3 ? [0, c, x] : h < 4 ? [0, x, c] : h < 5 ? [x, 0, c] : [c, 0, x]; return [r * 255, g * 255, b * 255]; }
  const flagBoxes = el("div");
  {
    const box = el("input", { type: "checkbox" });
    box.checked = true;
    box.addEventListener("change", () => { state.greyMask = box.checked ? state.greyMask | WITHHELD : state.greyMask & ~WITHHELD; upload(); draw(); });
    flagBoxes.append(el("label", {}, box, " not identifiable (the fit's rule, as the PNG maps)"));
  }
  info.flags.forEach((name, b) => {
    const bit = info.flag_bits[b];
    const box = el("input", { type: "checkbox" });
    box.checked = !!(state.greyMask & bit);
    box.addEventListener("change", () => { state.greyMask = box.checked ? state.greyMask | bit : state.greyMask & ~bit; upload(); draw(); });
    const c = FLAG_COLOURS[b].map((v) => Math.round(255 * v));
    flagBoxes.append(el("label", {}, box, el("span", { class: "swatch", style: `background:rgb(${c})` }), ` ${name} (${info.flag_counts[b]})`));
  });
  {
    const c = NO_FLAG_COLOUR.map((v) => Math.round(255 * v));
    flagBoxes.append(el("label", {}, el("span", { class: "swatch", style: `background:rgb(${c})` }), ` no flag (${info.unflagged})`));
  }
  function showPick() {
    const i = state.pick;
    if (i < 0) { pickBox.textContent = "no vertex under the cursor"; return; }
    const P = mesh.params.subarray(10 * i, 10 * i + 10), S = mesh.std.subarray(10 * i, 10 * i + 10);
    const st = mesh.status[i];
    const std = (k) => (isFinite(S[k]) ? "± " + fmt(S[k], 4) : "not identifiable");
    const value = (k) => (st & WITHHELD || (k === 0 && st & ETA_WITHHELD) ? `(${fmt(P[k], 4)}, not a measurement)` : fmt(P[k], 4));
    const rows = info.params.map((name, k) => el("tr", {}, el("td", {}, name), el("td", {}, value(k)), el("td", {}, std(k))));
    const flags = info.flags.filter((_, b) => st & info.flag_bits[b]);
    pickBox.replaceChildren(el("div", {}, `vertex ${i} · ${mesh.samples[i]} samples · normal ± ${fmt(mesh.nstd[i], 2)}°`),
      el("table", {}, el("tr", {}, el("th", {}, "param"), el("th", {}, "value"), el("th", {}, "std error")), ...rows),
      el("div", { class: flags.length ? "warn" : "ok" }, flags.length ? "flags: " + flags.join(", ") : "no flags"));
  }
  side.append(
    el("div", { class: "panel" }, el("h3", {}, "Display"), displaySel, grid, el("div", { class: "legend" }, legendCanvas, legendText)),
    el("div", { class: "panel" }, el("h3", {}, "Light (shift-drag or right-drag on the view)"),
      el("label", {}, "azimuth", laz), el("label", {}, "elevation", lel), el("label", {}, "exposure (log2)", exposure),
      el("label", {}, pol, " polarised light"), el("label", {}, "polariser angle ψ (light frame, deg)", psi)),
    el("div", { class: "panel" }, el("h3", {}, "Grey out vertices flagged"), flagBoxes),
    el("div", { class: "panel", id: "pick" }, el("h3", {}, "Vertex"), pickBox),
  );

  // test and scripting hooks
  E.setLight = (az, el_) => { state.lightAz = az; state.lightEl = el_; syncControls(); draw(); };
  E.setDisplay = (d, i, j) => { state.display = d; if (i !== undefined) state.elem = [i, j]; displaySel.value = d; syncControls(); upload(); draw(); };
  E.setPolarised = (on, psiDeg) => { state.polarised = on; state.psi = psiDeg || 0; pol.checked = on; draw(); };
  E.pick = (i) => { state.pick = i; showPick(); draw(); return pickBox.textContent; };
  E.info = info;
  upload(); syncControls(); draw();
  setStatus("drag to rotate, wheel to zoom, shift-drag to move the light, click to pick");
  markReady();
};
