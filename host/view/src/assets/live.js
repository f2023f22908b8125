// live.js — live-capture mode: the latest frame's s0 / DoLP / AoLP, counters, the camera path on
// a dome with each frame's pose status, and coverage (on the mesh, or on the dome) with hints.
// Updates arrive as server-sent events (at most a few per second).
"use strict";

const CAT_COLOURS = ["#7a1f2b", "#e04848", "#f08c30", "#f0d040", "#a8d860", "#3cb371"];
const STATUS_COLOURS = { posed: "#3cb371", rejected: "#e04848", pending: "#8a9099", flagged: "#f08c30" };

const COV_VS = `#version 300 es
in vec3 a_pos; in vec3 a_nrm; in float a_cat;
uniform mat4 u_viewProj;
out vec3 v_nrm; flat out float v_cat;
void main() { v_nrm = a_nrm; v_cat = a_cat; gl_Position = u_viewProj * vec4(a_pos, 1.0); }`;
const COV_FS = `#version 300 es
precision highp float;
in vec3 v_nrm; flat in float v_cat;
uniform vec3 u_palette[6]; uniform vec3 u_eyeDir;
out vec4 o;
void main() { float s = 0.45 + 0.55 * abs(dot(normalize(v_nrm), u_eyeDir)); o = vec4(u_palette[int(v_cat + 0.5)] * s, 1.0); }`;

function hexRgb(h) { return [1, 3, 5].map((i) => parseInt(h.slice(i, i + 2), 16) / 255); }

window.runLive = async function () {
  const app = document.getElementById("app");
  const imgs = {};
  const figs = ["s0", "dolp", "aolp"].map((k) => {
    imgs[k] = el("img", { alt: k });
    return el("figure", {}, imgs[k], el("figcaption", {}, { s0: "s0 (red: saturated)", dolp: "DoLP (0 … 1)", aolp: "AoLP = hue, DoLP = saturation" }[k]));
  });
  const frameStats = el("div", { class: "muted" }, "waiting for the first frame…");
  const counters = el("table", { id: "counters" });
  const dome = el("canvas", { width: 420, height: 436, id: "dome" });
  const tick = (status, word) => el("span", { style: `color:${STATUS_COLOURS[status]}` }, word);
  const domeKey = el("div", { class: "muted", style: "width:420px;font-size:12px" },
    "○ camera position of each posed frame (the latest ringed); strip: one tick per frame, ",
    tick("posed", "posed"), ", ", tick("rejected", "rejected"), ", ", tick("pending", "pending"), ", ", tick("flagged", "flagged"));
  const hints = el("ul", { class: "hints", id: "hints" });
  const legend = el("div");
  const rejections = el("table");
  const left = el("div", { style: "display:flex;flex-direction:column;gap:8px" },
    el("div", { class: "panel" }, el("h3", {}, "Latest frame"), el("div", { class: "imgs" }, ...figs), frameStats),
    el("div", { class: "panel", style: "display:flex;gap:10px" },
      el("div", {}, el("h3", {}, "Camera path and coverage (dome, seen from above)"), dome, domeKey),
      el("div", { style: "width:300px" }, el("h3", {}, "Coverage"), legend, el("h3", { style: "margin-top:8px" }, "Where to take photos next"), hints)));
  const side = el("div", { class: "side" },
    el("div", { class: "panel" }, el("h3", {}, "Capture"), counters),
    el("div", { class: "panel" }, el("h3", {}, "Pose rejections"), rejections));
  app.append(left, side);

  // optional mesh coverage view
  let meshView = null;
  const meshBuf = await api("/api/live/mesh.bin", "bin");
  if (meshBuf.byteLength > 0) meshView = makeMeshView(decodePlainMesh(meshBuf), left);

  let last = null, lastImage = -1, lastCoverage = -1, firstDone = false;
  async function update(s) {
    last = E.live = s;
    (E.history = E.history || []).push({ state: s.state, frames: s.counters.frames });
    document.getElementById("title").textContent = `live · ${s.session}`;
    setStatus(s.state === "waiting" ? "waiting for the capture to start…" : s.state === "ended" ? `ended: ${s.end_reason}` : "capturing");
    const c = s.counters;
    const rows = [
      ["frames", c.frames], ["frame rate", fmt(c.fps, 1) + " fps"], ["pulses", c.pulses], ["paired", c.paired],
      ["dropped", c.dropped, c.dropped > 0], ["flagged", c.flagged, c.flagged > 0],
      ["pairing errors", Object.entries(c.pairing_errors).map(([k, v]) => `${k} ${v}`).join(", ") || "0", Object.keys(c.pairing_errors).length > 0],
      ["link errors", c.link_errors + " (" + c.link_frames_ok + " ok)", c.link_errors > 0],
      ["clock residual", c.clock_rms_us === null ? "–" : fmt(c.clock_rms_us, 1) + " µs"],
      ["clock drift", c.clock_drift_ppm === null ? "–" : fmt(c.clock_drift_ppm, 1) + " ppm"],
      ["posed", `${s.tracking.posed} (${s.tracking.pending} pending${s.tracking.deferred && s.tracking.pending > 0 ? "; the newest frame is tracked live, the rest when the capture ends or pauses" : ""})`],
      ["faults", c.faults.length ? c.faults.join("; ") : "0", c.faults.length > 0],
    ];
    if (c.disconnected) rows.push(["link", "disconnected: " + c.disconnected, true]);
    if (s.tracking.error) rows.push(["tracking", s.tracking.error, true]);
    counters.replaceChildren(...rows.map(([k, v, bad]) => el("tr", {}, el("td", {}, k), el("td", { class: bad ? "bad" : "" }, String(v)))));
    rejections.replaceChildren(...(Object.keys(s.tracking.rejections).length ? Object.entries(s.tracking.rejections).map(([r, n]) => el("tr", {}, el("td", {}, r), el("td", {}, String(n)))) : [el("tr", {}, el("td", { class: "muted" }, "none"))]));
    if (s.latest) {
      const l = s.latest;
      frameStats.textContent = `frame ${l.frame_id} · ${l.width}×${l.height} superpixels · saturated ${fmt(100 * l.saturated_fraction, 2)} % · dark ${fmt(100 * l.dark_fraction, 1)} % · mean DoLP ${fmt(l.mean_dolp_valid, 3)}`;
      frameStats.className = l.saturated_fraction > 0.01 ? "warn" : "muted";
      if (l.frame_id !== lastImage) {
        lastImage = l.frame_id;
        for (const k of ["s0", "dolp", "aolp"]) imgs[k].src = url("/api/live/image/" + k, { v: l.frame_id });
      }
    } else if (s.latest_error) frameStats.textContent = s.latest_error;
    const cov = s.coverage;
    if (cov) {
      legend.replaceChildren(...cov.labels.map((label, i) => el("div", {}, el("span", { class: "swatch", style: `background:${CAT_COLOURS[i]}` }), `${label}: ${cov.counts[i]}`)),
        el("div", { class: "muted" }, cov.proxy ? `coverage on a dome of ${cov.elements} directions around the object (no mesh given)` : `coverage on the mesh's ${cov.elements} vertices`));
      hints.replaceChildren(...cov.hints.map((h) => el("li", {}, h)));
      if (cov.views !== lastCoverage || s.version === 1) {
        lastCoverage = cov.views;
        const cats = new Uint8Array(await api("/api/live/coverage.bin", "bin"));
        E.coverage = cats;
        drawDome(cats);
        if (meshView) meshView.setCategories(cats);
      } else drawDome(E.coverage);
    } else drawDome(null);
    if (!firstDone) { firstDone = true; markReady(); }
  }

  function drawDome(cats) {
    const ctx = dome.getContext("2d"), W = dome.width, H = dome.height;
    // elevation 90° at the centre, 0° on the circle; azimuth 0 (+x) to the right, +y up; the
    // proxy reaches 10° below the horizon and the side labels sit at −14°: both inside the canvas
    const R = (W / 2 - 14) * 90 / 104, cx = W / 2, cy = W / 2;
    ctx.fillStyle = "#101114"; ctx.fillRect(0, 0, W, H);
    const at = (az, elv) => { const r = R * (90 - Math.max(-10, elv)) / 90, a = az * Math.PI / 180; return [cx + r * Math.cos(a), cy - r * Math.sin(a)]; };
    const label = (t, x, y) => { ctx.strokeText(t, x, y); ctx.fillText(t, x, y); };
    const s = last, cov = s && s.coverage;
    if (cov && cov.proxy && cats) {
      ctx.globalAlpha = 0.8;
      cov.dome.forEach(([az, elv], i) => { const [x, y] = at(az, elv); ctx.fillStyle = CAT_COLOURS[cats[i]]; ctx.beginPath(); ctx.arc(x, y, 6.5, 0, 7); ctx.fill(); });
      ctx.globalAlpha = 1;
    }
    ctx.font = "11px system-ui"; ctx.lineJoin = "round";
    for (const e of [0, 30, 60]) { ctx.strokeStyle = "#5a616c"; ctx.lineWidth = 1; ctx.beginPath(); ctx.arc(cx, cy, R * (90 - e) / 90, 0, 7); ctx.stroke(); }
    ctx.strokeStyle = "#101114"; ctx.lineWidth = 3; ctx.fillStyle = "#c8ccd3";
    for (const e of [0, 30, 60]) label(e + "°", cx + 3, cy - R * (90 - e) / 90 + 12);
    for (const [az, t] of [[0, "+x"], [90, "+y"], [180, "−x"], [270, "−y"]]) { const [x, y] = at(az, -14); label(t, x - 6, y + 4); }
    ctx.lineWidth = 1;
    if (!s) return;
    const posed = s.frames.filter((f) => f.status === "posed" && f.az !== null);
    ctx.strokeStyle = "rgba(255,255,255,0.6)"; ctx.beginPath();
    posed.forEach((f, i) => { const [x, y] = at(f.az, f.el); if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
    ctx.stroke();
    for (const f of posed) { const [x, y] = at(f.az, f.el); ctx.fillStyle = "#fff"; ctx.strokeStyle = "#000"; ctx.beginPath(); ctx.arc(x, y, 3, 0, 7); ctx.fill(); ctx.stroke(); }
    const latest = s.frames[s.frames.length - 1];
    if (latest && latest.az !== null) { const [x, y] = at(latest.az, latest.el); ctx.strokeStyle = "#fff"; ctx.lineWidth = 2; ctx.beginPath(); ctx.arc(x, y, 7, 0, 7); ctx.stroke(); ctx.lineWidth = 1; }
    // status strip: one tick per frame (posed / rejected / pending / flagged)
    const n = s.frames.length, w = Math.max(1, Math.min(4, (W - 8) / Math.max(n, 1)));
    s.frames.forEach((f, i) => { ctx.fillStyle = STATUS_COLOURS[f.status]; ctx.fillRect(4 + i * w, H - 9, Math.max(1, w - 0.5), 6); });
  }

  const es = new EventSource(url("/api/live/events"));
  es.addEventListener("state", (ev) => { update(JSON.parse(ev.data)).catch((e) => reportError(e.stack || e)); });
  es.onerror = () => { if (last && last.state === "ended") return; setStatus("connection to ellipso lost; retrying…"); };
  E.closeEvents = () => es.close();
};

function makeMeshView(mesh, parent) {
  const canvas = el("canvas", { class: "gl", width: 420, height: 360, id: "coverage-mesh" });
  parent.append(el("div", { class: "panel" }, el("h3", {}, "Coverage on the mesh (drag to rotate)"), canvas));
  const gl = webgl(canvas);
  const prog = program(gl, COV_VS, COV_FS);
  let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < mesh.n; i++) for (let k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], mesh.pos[3 * i + k]); hi[k] = Math.max(hi[k], mesh.pos[3 * i + k]); }
  const centre = [0, 1, 2].map((k) => (lo[k] + hi[k]) / 2), radius = 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  const buf = (name, data, size) => { const b = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW); const loc = gl.getAttribLocation(prog, name); gl.enableVertexAttribArray(loc); gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0); return b; };
  buf("a_pos", mesh.pos, 3); buf("a_nrm", mesh.nrm, 3);
  const catBuf = buf("a_cat", new Float32Array(mesh.n), 1);
  const ib = gl.createBuffer(); gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib); gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, mesh.idx, gl.STATIC_DRAW);
  const cam = orbit(canvas, centre, radius, draw, () => {}, null);
  function draw() {
    gl.viewport(0, 0, canvas.width, canvas.height); gl.clearColor(0.063, 0.067, 0.078, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT); gl.enable(gl.DEPTH_TEST);
    gl.useProgram(prog);
    const m = cam.matrices(canvas.width / canvas.height);
    gl.uniformMatrix4fv(gl.getUniformLocation(prog, "u_viewProj"), false, m.viewProj);
    gl.uniform3fv(gl.getUniformLocation(prog, "u_eyeDir"), norm(sub(cam.eye(), centre)));
    gl.uniform3fv(gl.getUniformLocation(prog, "u_palette"), new Float32Array(CAT_COLOURS.flatMap(hexRgb)));
    gl.bindVertexArray(vao); gl.drawElements(gl.TRIANGLES, 3 * mesh.t, gl.UNSIGNED_INT, 0);
    E.frames++;
  }
  draw();
  return { setCategories(cats) { gl.bindBuffer(gl.ARRAY_BUFFER, catBuf); gl.bufferData(gl.ARRAY_BUFFER, Float32Array.from(cats), gl.STATIC_DRAW); draw(); } };
}
