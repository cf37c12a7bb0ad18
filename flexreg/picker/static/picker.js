// flexreg pick: the page. Plain JavaScript, no build step, no network beyond this server.
"use strict";

const TOKEN = new URLSearchParams(location.search).get("token") || "";
const $ = (sel) => document.querySelector(sel);
const SVGNS = "http://www.w3.org/2000/svg";

let state = null;          // the server's state (see PickSession.state)
let pending = null;        // half a pair: {side: "camera", u, v} or {side: "lidar", mode, x, y, point, range_m}
let hoverId = null;        // pair id under the mouse (table or marks)
let lidarMode = null;      // current lidar view
let ghosts = { camera: null, lidar: null };  // predicted partner positions while hovering
let snapMark = null;       // where a lidar click would land
let busy = 0;
let autoFitted = false;    // the lidar panorama was zoomed to the camera's view once

// ------------------------------------------------------------------ server calls

function url(path, params = {}) {
  const q = new URLSearchParams({ ...params, token: TOKEN });
  return `${path}?${q}`;
}

async function api(method, path, body, params = {}) {
  const opts = { method, headers: { "X-Flexreg-Token": TOKEN } };
  if (body !== undefined) {
    opts.headers["Content-Type"] = "application/json";
    opts.body = JSON.stringify(body);
  }
  busy += 1;
  setBusy();
  try {
    const r = await fetch(url(path, params), opts);
    const doc = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
    if (!r.ok) throw new Error(doc.error || `HTTP ${r.status}`);
    return doc;
  } finally {
    busy -= 1;
    setBusy();
  }
}

function setBusy() { document.body.dataset.busy = busy > 0 ? "1" : "0"; }

function message(text, info = false) {
  const m = $("#message");
  m.textContent = text || "";
  m.className = info ? "message info" : "message";
}

async function change(method, path, body) {
  try {
    state = await api(method, path, body);
    message("");
    render();
  } catch (e) {
    message(e.message);
  }
}

// ------------------------------------------------------------------ panels: zoom, pan, marks

class Panel {
  constructor(el, side) {
    this.el = el;
    this.side = side;
    this.vp = el.querySelector(".viewport");
    this.stage = el.querySelector(".stage");
    this.base = el.querySelector("img.base");
    this.overlay = el.querySelector("img.overlay");
    this.svg = el.querySelector("svg.marks");
    this.W = 1; this.H = 1; this.aspect = 1; this.previewW = 1; this.mirror = false;
    this.s = 1; this.tx = 0; this.ty = 0;
    this.key = null; this.fullSrc = null; this.fullLoaded = false;
    this.drag = null;
    this.vp.addEventListener("wheel", (e) => this.wheel(e), { passive: false });
    this.vp.addEventListener("pointerdown", (e) => this.down(e));
    this.vp.addEventListener("pointermove", (e) => this.move(e));
    this.vp.addEventListener("pointerup", (e) => this.up(e));
    this.vp.addEventListener("pointerleave", () => { if (!this.drag) hoverEnd(this.side); });
  }

  setImage(key, src, fullSrc, W, H, aspect, previewW) {
    if (this.key === key) return;
    const first = this.key === null || this.W !== W || this.H !== H || this.aspect !== aspect;
    this.key = key;
    this.W = W; this.H = H; this.aspect = aspect; this.previewW = previewW;
    this.fullSrc = previewW < W ? fullSrc : null;
    this.fullLoaded = false;
    this.base.src = src;
    if (first) this.fit(); else this.apply();
  }

  // shown left-right reversed (a panorama whose columns turn the other way than the camera's)
  setMirror(m) {
    if (this.mirror === m) return;
    this.mirror = m;
    this.base.style.transform = m ? "scaleX(-1)" : "";
    this.apply();
  }

  // zoom to [x0, y0, x1, y1] (image pixels), with a margin
  fitBox(b) {
    const r = this.vp.getBoundingClientRect();
    const w = Math.max(b[2] - b[0] + 1, 8) * 1.15, h = Math.max(b[3] - b[1] + 1, 8) * 1.15 * this.aspect;
    this.s = Math.min(r.width / w, r.height / h);
    const [cx, cy] = this.toStage((b[0] + b[2]) / 2, (b[1] + b[3]) / 2);
    this.tx = r.width / 2 - cx * this.s;
    this.ty = r.height / 2 - cy * this.s;
    this.apply();
  }

  fit() {
    const r = this.vp.getBoundingClientRect();
    const h = this.H * this.aspect;
    this.s = Math.min(r.width / this.W, r.height / h);
    this.tx = (r.width - this.W * this.s) / 2;
    this.ty = (r.height - h * this.s) / 2;
    this.apply();
  }

  apply() {
    this.stage.style.width = `${this.W}px`;
    this.stage.style.height = `${this.H * this.aspect}px`;
    this.stage.style.transform = `translate(${this.tx}px, ${this.ty}px) scale(${this.s})`;
    this.svg.setAttribute("viewBox", `0 0 ${this.W} ${this.H * this.aspect}`);
    if (this.fullSrc && !this.fullLoaded && (this.W * this.s) / this.previewW > 1.2) {
      this.fullLoaded = true;  // zoomed past the preview's resolution: the full image
      this.base.src = this.fullSrc;
    }
    if (this.side === "camera") overlaySoon();
    drawMarks(this);
  }

  // image pixel (centre convention) <-> stage units <-> client
  toImage(clientX, clientY) {
    const r = this.vp.getBoundingClientRect();
    const ex = (clientX - r.left - this.tx) / this.s;
    const ey = (clientY - r.top - this.ty) / this.s;
    return [this.mirror ? this.W - ex - 0.5 : ex - 0.5, ey / this.aspect - 0.5];
  }
  toStage(x, y) { return [this.mirror ? this.W - x - 0.5 : x + 0.5, (y + 0.5) * this.aspect]; }
  toClient(x, y) {  // page coordinates of image pixel (x, y)
    const r = this.vp.getBoundingClientRect();
    const [X, Y] = this.toStage(x, y);
    return [r.left + this.tx + X * this.s, r.top + this.ty + Y * this.s];
  }
  inside(x, y) { return x >= -0.5 && x <= this.W - 0.5 && y >= -0.5 && y <= this.H - 0.5; }

  wheel(e) {
    e.preventDefault();
    const r = this.vp.getBoundingClientRect();
    const cx = e.clientX - r.left, cy = e.clientY - r.top;
    const fitS = Math.min(r.width / this.W, r.height / (this.H * this.aspect));
    const s2 = Math.min(Math.max(this.s * Math.exp(-e.deltaY * 0.0015), fitS / 4), 64);
    const k = s2 / this.s;
    this.tx = cx - (cx - this.tx) * k;
    this.ty = cy - (cy - this.ty) * k;
    this.s = s2;
    this.apply();
  }

  down(e) {
    if (e.button !== 0) return;
    const mark = e.target.closest ? e.target.closest("g.mark[data-id]") : null;
    this.drag = {
      x0: e.clientX, y0: e.clientY, tx0: this.tx, ty0: this.ty, moved: false,
      mark: mark && mark.dataset.kind === "pair" ? mark : null,
    };
    this.vp.setPointerCapture(e.pointerId);
  }

  move(e) {
    const d = this.drag;
    if (!d) { hover(this, e); return; }
    const dx = e.clientX - d.x0, dy = e.clientY - d.y0;
    if (!d.moved && Math.hypot(dx, dy) > 3) d.moved = true;
    if (!d.moved) return;
    if (d.mark) {
      const [x, y] = this.toImage(e.clientX, e.clientY);
      const [X, Y] = this.toStage(x, y);
      d.mark.setAttribute("transform", `translate(${X} ${Y})`);
    } else {
      this.vp.classList.add("panning");
      this.tx = d.tx0 + dx;
      this.ty = d.ty0 + dy;
      this.apply();
    }
  }

  up(e) {
    const d = this.drag;
    this.drag = null;
    this.vp.classList.remove("panning");
    if (!d) return;
    const [x, y] = this.toImage(e.clientX, e.clientY);
    if (!d.moved) { pick(this, x, y); return; }
    if (d.mark) dragged(this, Number(d.mark.dataset.id), x, y);
  }
}

const panels = {};

function gridOf(mode) { return mode === "perspective" ? "perspective" : "panorama"; }

function positionIn(panel, item) {
  if (panel.side === "camera") return [item.u, item.v];
  const p = item.lidar && item.lidar[gridOf(lidarMode)];
  return p ? p : null;
}

function svgEl(name, attrs, parent) {
  const el = document.createElementNS(SVGNS, name);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, v);
  if (parent) parent.appendChild(el);
  return el;
}

function mark(panel, x, y, cls, label, id, kind) {
  const r = 7 / panel.s;
  const [X, Y] = panel.toStage(x, y);
  const g = svgEl("g", { class: `mark ${cls}`, transform: `translate(${X} ${Y})` }, panel.svg);
  if (id !== undefined) { g.dataset.id = id; g.dataset.kind = kind; }
  svgEl("circle", { r }, g);
  if (label !== "") {
    const t = svgEl("text", { x: r * 1.2, y: -r * 0.9, "font-size": 13 / panel.s }, g);
    t.textContent = label;
  }
  if (id !== undefined && kind === "pair") {
    g.addEventListener("mouseenter", () => setHover(id));
    g.addEventListener("mouseleave", () => setHover(null));
  }
  return g;
}

function drawMarks(panel) {
  const svg = panel.svg;
  while (svg.firstChild) svg.removeChild(svg.firstChild);
  svg.style.setProperty("--k", String(1 / panel.s));
  if (!state) return;
  const sol = state.solution;
  const solved = sol && sol.source === "solution";
  for (const p of state.pairs) {
    const at = positionIn(panel, p);
    if (!at) continue;
    if (panel.side === "camera" && p.projected_uv && $("#show-overlay").checked) {
      const [X1, Y1] = panel.toStage(p.u, p.v);
      const [X2, Y2] = panel.toStage(p.projected_uv[0], p.projected_uv[1]);
      svgEl("line", { x1: X1, y1: Y1, x2: X2, y2: Y2, class: "residual" }, svg);
    }
    let cls = solved ? (p.inlier ? "inlier" : "outlier") : "unsolved";
    if (p.id === hoverId) cls += " hover";
    mark(panel, at[0], at[1], cls, String(p.id), p.id, "pair");
  }
  for (const s of state.suggestions) {
    const at = positionIn(panel, s);
    if (at) mark(panel, at[0], at[1], "suggestion", "s", s.id, "suggestion");
  }
  if (pending) {
    if (pending.side === panel.side) {
      const at = panel.side === "camera" ? [pending.u, pending.v] : [pending.x, pending.y];
      if (panel.side === "camera" || gridOf(pending.mode) === gridOf(lidarMode)) {
        mark(panel, at[0], at[1], "pending", "?");
      }
    }
  }
  const ghost = ghosts[panel.side];
  if (ghost) {
    const [X, Y] = panel.toStage(ghost[0], ghost[1]);
    const g = svgEl("g", { class: "ghost", transform: `translate(${X} ${Y})` }, svg);
    const r = 10 / panel.s;
    svgEl("circle", { r }, g);
    svgEl("line", { x1: -2 * r, y1: 0, x2: 2 * r, y2: 0 }, g);
    svgEl("line", { x1: 0, y1: -2 * r, x2: 0, y2: 2 * r }, g);
  }
  drawCameraView(panel);
  if (panel.side === "lidar" && snapMark) {
    const [X, Y] = panel.toStage(snapMark[0], snapMark[1]);
    svgEl("circle", { cx: X, cy: Y, r: 3 / panel.s, fill: "#fff" }, svg);
  }
}

function drawAll() { for (const p of Object.values(panels)) drawMarks(p); }

// the camera's view on the panorama (under the solution, the initial guess, or roughly from
// the first pairs), outlined with where it comes from
function drawCameraView(panel) {
  const view = state.lidar.camera_view;
  if (panel.side !== "lidar" || gridOf(lidarMode) !== "panorama" || !view || !view.box) return;
  const [x0, y0, x1, y1] = view.box;
  const [Xa, Ya] = panel.toStage(x0 - 0.5, y0 - 0.5);
  const [Xb, Yb] = panel.toStage(x1 + 0.5, y1 + 0.5);
  const g = svgEl("g", { class: `camera-view ${view.source === "pairs" ? "rough" : ""}` }, panel.svg);
  svgEl("rect", { x: Math.min(Xa, Xb), y: Ya, width: Math.abs(Xb - Xa), height: Yb - Ya }, g);
  const t = svgEl("text", { x: Math.min(Xa, Xb) + 4 / panel.s, y: Ya - 5 / panel.s, "font-size": 13 / panel.s }, g);
  t.textContent = view.source === "pairs" ? "camera (rough, from the pairs)" : `camera (${view.source})`;
}

// the projected-lidar layer is drawn for the camera panel's zoom (dots of a few screen pixels,
// thinned to stay apart): asked for again when the zoom changes by half an octave
function overlayZoom() {
  const p = panels.camera;
  const z = (p.s * p.W) / Math.max(p.previewW, 1);
  return Math.pow(2, Math.round(2 * Math.log2(Math.max(z, 1e-3))) / 2).toPrecision(4);
}

let overlayTimer = null;
function overlaySoon() {
  clearTimeout(overlayTimer);
  overlayTimer = setTimeout(() => { if (state) renderOverlay(); }, 120);
}

function renderOverlay() {
  const ov = panels.camera.overlay;
  const show = $("#show-overlay").checked && state.solution && state.solution.T_camera_lidar;
  ov.hidden = !show;
  if (show) {
    const src = url("/api/overlay.png", { rev: state.revision, zoom: overlayZoom() });
    if (ov.dataset.src !== src) { ov.dataset.src = src; ov.src = src; }
  }
  ov.style.opacity = $("#opacity").value / 100;
}

// ------------------------------------------------------------------ picking

async function pick(panel, x, y) {
  if (!panel.inside(x, y)) return;
  if (panel.side === "camera") {
    if (pending && pending.side === "lidar") {
      await change("POST", "/api/pairs", { u: x, v: y, mode: pending.mode, x: pending.x, y: pending.y });
      pending = null;
    } else {
      pending = { side: "camera", u: x, v: y };
    }
  } else {
    let snap;
    try {
      snap = await api("GET", "/api/snap", undefined, { mode: lidarMode, x, y });
    } catch (e) { message(e.message); return; }
    if (pending && pending.side === "camera") {
      await change("POST", "/api/pairs", { u: pending.u, v: pending.v, mode: lidarMode, x: snap.x, y: snap.y });
      pending = null;
    } else {
      pending = { side: "lidar", mode: lidarMode, ...snap };
    }
  }
  renderPending();
  drawAll();
}

async function dragged(panel, id, x, y) {
  if (panel.side === "camera") await change("PATCH", `/api/pairs/${id}`, { u: x, v: y });
  else await change("PATCH", `/api/pairs/${id}`, { mode: lidarMode, x, y });
  drawAll();
}

let hoverTimer = null;
let hoverInFlight = false;

function hover(panel, e) {
  const [x, y] = panel.toImage(e.clientX, e.clientY);
  const ro = panel.side === "camera" ? $("#camera-readout") : $("#lidar-readout");
  if (!panel.inside(x, y)) { ro.textContent = ""; return; }
  ro.textContent = panel.side === "camera"
    ? `u ${x.toFixed(1)}  v ${y.toFixed(1)} px`
    : `col ${x.toFixed(1)}  row ${y.toFixed(1)}`;
  clearTimeout(hoverTimer);
  hoverTimer = setTimeout(() => hoverQuery(panel, x, y), 40);
}

async function hoverQuery(panel, x, y) {
  if (hoverInFlight || !state) return;
  hoverInFlight = true;
  try {
    if (panel.side === "lidar") {
      const s = await api("GET", "/api/snap", undefined, { mode: lidarMode, x, y });
      snapMark = [s.x, s.y];
      ghosts.camera = s.predicted_uv;
      $("#lidar-readout").textContent =
        `col ${s.x}  row ${s.y} · return at ${s.range_m.toFixed(2)} m` +
        ` (${s.point.map((c) => c.toFixed(2)).join(", ")})` +
        (s.predicted_uv ? " · predicted partner shown on the camera image" : "");
    } else if (state.solution) {
      const r = await api("GET", "/api/predict", undefined, { u: x, v: y, mode: lidarMode });
      ghosts.lidar = r.lidar ? [r.lidar.x, r.lidar.y] : null;
    }
  } catch (e) {
    snapMark = null;
  } finally {
    hoverInFlight = false;
  }
  drawAll();
}

function hoverEnd(side) {
  if (side === "lidar") { snapMark = null; ghosts.camera = null; }
  else ghosts.lidar = null;
  drawAll();
}

function setHover(id) {
  // classes only: re-drawing the marks would replace the element under the pointer
  hoverId = id;
  for (const tr of document.querySelectorAll("#pairs tbody tr")) {
    tr.classList.toggle("hover", Number(tr.dataset.id) === id);
  }
  for (const g of document.querySelectorAll("g.mark[data-kind='pair']")) {
    g.classList.toggle("hover", Number(g.dataset.id) === id);
  }
}

// ------------------------------------------------------------------ side panel

const fmt = (x, d = 2) => (x === null || x === undefined ? "–" : Number(x).toFixed(d));

function renderPending() {
  const el = $("#pending");
  if (!pending) { el.hidden = true; el.textContent = ""; delete el.dataset.side; return; }
  el.hidden = false;
  el.dataset.side = pending.side;
  if (pending.side === "camera") {
    el.textContent = `camera pixel (${fmt(pending.u, 1)}, ${fmt(pending.v, 1)}): now click its partner in the lidar view (Esc cancels)`;
  } else {
    el.dataset.x = pending.x; el.dataset.y = pending.y;
    el.dataset.point = JSON.stringify(pending.point);
    el.textContent = `lidar return (${pending.point.map((c) => c.toFixed(3)).join(", ")}) at ${fmt(pending.range_m)} m: now click its partner in the camera image (Esc cancels)`;
  }
}

function renderSolution() {
  const el = $("#solution");
  const s = state.solution;
  const n = state.pairs.length;
  if (!s) {
    el.innerHTML = `Pick ${Math.max(0, state.min_pairs - n)} more pair(s) to solve.`;
    return;
  }
  const rows = [];
  const row = (k, v) => rows.push(`<div class="row"><span>${k}</span><span>${v}</span></div>`);
  if (s.error) rows.push(`<div class="error">${escapeHtml(s.error)}</div>`);
  if (s.T_camera_lidar) {
    if (s.source === "solution") {
      const v = s.verdict;
      if (v) {
        row("verdict", `<span class="verdict-${v.status}">${v.status}</span>`);
        for (const r of v.reasons || []) rows.push(`<div class="row"><span></span><span>${escapeHtml(r.message)}</span></div>`);
      }
      row("inliers", `${s.inliers} of ${s.pairs} within ${fmt(s.threshold_px, 1)} px`);
      row("reprojection RMSE", `${fmt(s.rmse_px, 3)} px`);
    } else {
      row("pose", `initial guess (solving from ${state.min_pairs} pairs)`);
    }
    row("rotation (vector)", `[${s.rotation_vector_deg.map((x) => fmt(x, 3)).join(", ")}]° · ${fmt(s.rotation_angle_deg, 3)}°`);
    row("translation", `[${s.translation_m.map((x) => fmt(x, 4)).join(", ")}] m`);
    if (s.change) row("change since last solve", `${fmt(s.change.rotation_deg, 3)}° · ${fmt(100 * s.change.translation_m, 2)} cm`);
    const T = s.T_camera_lidar.map((r) => r.map((x) => x.toFixed(6).padStart(11)).join(" ")).join("\n");
    rows.push(`<div>T_camera_lidar (lidar points into the camera frame)</div><pre id="T">${T}</pre>`);
  }
  el.innerHTML = rows.join("");
  const pre = $("#T");
  if (pre) pre.dataset.t = JSON.stringify(s.T_camera_lidar);
  el.dataset.source = s.source || "";
  el.dataset.revision = state.revision;
}

function escapeHtml(t) {
  return String(t).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);
}

function renderPairs() {
  const tb = $("#pairs tbody");
  tb.innerHTML = "";
  for (const p of state.pairs) {
    const tr = document.createElement("tr");
    tr.dataset.id = p.id;
    if (p.inlier === false) tr.className = "outlier";
    tr.innerHTML =
      `<td>${p.id}</td><td>${fmt(p.u, 1)}, ${fmt(p.v, 1)}</td>` +
      `<td>${p.point.map((x) => fmt(x, 3)).join(", ")}</td><td>${fmt(p.range_m)} m</td>` +
      `<td>${p.residual_px === null ? "–" : fmt(p.residual_px, 2) + " px"}${p.inlier === false ? " ✗" : ""}</td>` +
      `<td><button class="small" title="delete pair ${p.id}">✕</button></td>`;
    tr.querySelector("button").addEventListener("click", () => change("DELETE", `/api/pairs/${p.id}`));
    tr.addEventListener("mouseenter", () => setHover(p.id));
    tr.addEventListener("mouseleave", () => setHover(null));
    tb.appendChild(tr);
  }
  $("#pair-count").textContent = `(${state.pairs.length})`;
  const tbs = $("#suggestions tbody");
  tbs.innerHTML = "";
  const has = state.suggestions.length > 0;
  $("#suggestions").hidden = !has;
  $("#suggestions-title").hidden = !has;
  for (const s of state.suggestions) {
    const tr = document.createElement("tr");
    tr.dataset.id = s.id;
    tr.innerHTML =
      `<td>s${s.id}</td><td>${fmt(s.u, 1)}, ${fmt(s.v, 1)}</td><td>${fmt(s.range_m)} m</td>` +
      `<td><button class="small accept">accept</button> <button class="small reject">reject</button></td>`;
    tr.querySelector(".accept").addEventListener("click", () => change("POST", `/api/suggestions/${s.id}/accept`));
    tr.querySelector(".reject").addEventListener("click", () => change("POST", `/api/suggestions/${s.id}/reject`));
    tbs.appendChild(tr);
  }
}

function renderStatus() {
  const st = $("#status");
  const s = state.solution;
  let text = `${state.pairs.length} pairs`;
  let cls = "status";
  if (s && s.source === "solution") {
    text += ` · solved, ${s.verdict ? s.verdict.status : ""}, RMSE ${fmt(s.rmse_px)} px`;
    cls += s.verdict && s.verdict.status === "confident" ? " ok" : " warn";
  } else if (s && s.error) {
    text += " · no solution"; cls += " warn";
  }
  text += state.saved ? " · saved" : " · not saved";
  st.textContent = text;
  st.className = cls;
}

function renderImages() {
  const cam = state.camera;
  panels.camera.setImage("camera", url("/api/camera.png"), url("/api/camera.png", { full: 1 }),
    cam.width, cam.height, 1, cam.preview[0]);
  const sel = $("#lidar-mode");
  if (sel.options.length !== state.lidar.modes.length) {
    sel.innerHTML = state.lidar.modes.map((m) => `<option value="${m}">${m}</option>`).join("");
    lidarMode = lidarMode || state.lidar.modes[0];
    sel.value = lidarMode;
  }
  const [W, H] = state.lidar.sizes[lidarMode];
  const pw = Math.min(W, Math.round(W * Math.min(1, state.preview_px / Math.max(W, H))));
  panels.lidar.setImage(lidarMode, url(`/api/lidar/${lidarMode}.png`),
    url(`/api/lidar/${lidarMode}.png`, { full: 1 }), W, H, state.lidar.aspect[lidarMode], pw);
  const box = gridOf(lidarMode) === "panorama" ? state.lidar.camera_box : null;
  $("#fit-camera").hidden = !box;
  const grid = gridOf(lidarMode);
  if (panels.lidar.grid === undefined) $("#mirror").checked = state.lidar.mirror;
  panels.lidar.setMirror(grid === "panorama" && $("#mirror").checked);
  if (!autoFitted || panels.lidar.grid !== grid) {
    // on opening, and back from the perspective view: the part of the scan the camera sees
    autoFitted = true;
    if (box) panels.lidar.fitBox(box);
  }
  panels.lidar.grid = grid;
  const view = state.lidar.camera_view;
  const note = $("#view-note");
  note.textContent = grid === "panorama" && view ? view.note : "";
  note.dataset.source = view && view.box ? view.source : "";
  renderOverlay();
}

function render() {
  renderImages();
  renderStatus();
  renderSolution();
  renderPairs();
  renderPending();
  drawAll();
  document.body.dataset.revision = state.revision;
}

// ------------------------------------------------------------------ start

async function main() {
  panels.camera = new Panel($("#camera-panel"), "camera");
  panels.lidar = new Panel($("#lidar-panel"), "lidar");
  $("#lidar-mode").addEventListener("change", (e) => { lidarMode = e.target.value; snapMark = null; render(); });
  $("#show-overlay").addEventListener("change", render);
  $("#fit-camera").addEventListener("click", () => { if (state.lidar.camera_box) panels.lidar.fitBox(state.lidar.camera_box); });
  $("#fit-all").addEventListener("click", () => panels.lidar.fit());
  $("#mirror").addEventListener("change", render);
  $("#opacity").addEventListener("input", () => { panels.camera.overlay.style.opacity = $("#opacity").value / 100; });
  $("#save").addEventListener("click", async () => {
    try {
      state = await api("POST", "/api/save");
      render();
      message(`saved ${state.saved_files.join(" and ")}`, true);
    } catch (e) { message(e.message); }
  });
  $("#suggest").addEventListener("click", async () => {
    message("looking for suggestions…", true);
    await change("POST", "/api/suggestions");
    if (state && !$("#message").textContent) {
      message(`${state.suggestions.length} suggestion(s): accept or reject them one by one`, true);
    }
  });
  document.addEventListener("keydown", (e) => {
    if (e.key === "Escape") { pending = null; renderPending(); drawAll(); }
    if (e.key === "Delete" && hoverId !== null && e.target === document.body) {
      change("DELETE", `/api/pairs/${hoverId}`);
    }
  });
  window.addEventListener("resize", () => { panels.camera.fit(); panels.lidar.fit(); });
  window.addEventListener("beforeunload", (e) => { if (state && !state.saved && state.pairs.length) e.preventDefault(); });
  try {
    state = await api("GET", "/api/state");
    render();
    document.body.dataset.ready = "1";
  } catch (e) {
    message(e.message);
  }
}

window.picker = { panels, state: () => state };
main();
