// examples/view_page.hpp
// The page `msgs view` serves at /: one self-contained HTML document (inline CSS and script, no
// external resources, no build step). It talks to /api/info, /api/render and /api/frame.
//
// Camera model in the page: position p and world-to-camera rotation rows (right, down, forward),
// OpenCV axes like msgs::Camera, plus a pivot at distance `dist` along forward for orbiting.
// Intrinsics are kept relative to the image size (fx / W, fy / H, cx / W, cy / H) so that the
// same view renders at any resolution: a third of the width while the camera moves, full size
// once it has been still for 250 ms.
//
// Deep links: ?frame=ID&mode=M&size=W&bg=black&format=png opens at dataset camera ID in mode M
// with the view W pixels wide (any width 64..4096), a background and PNG frames; the address bar
// follows the camera and mode picked. Live views (`msgs train --view`, /api/info has "live") poll
// /api/live every second, show the step and state, and re-render the view and the comparison
// when a new snapshot of the model arrives.
#pragma once

namespace msgs::view {

inline constexpr const char* page_html = R"MSGSPAGE(<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>msgs view</title>
<meta name="viewport" content="width=device-width, initial-scale=1">
<style>
  body { margin: 0; font: 13px/1.35 system-ui, sans-serif; background: #1d1f24; color: #ddd; }
  header { padding: 6px 12px; background: #2a2d34; display: flex; gap: 18px; align-items: baseline; flex-wrap: wrap; }
  header b { font-size: 15px; color: #fff; }
  .stat { color: #9cf; font-variant-numeric: tabular-nums; }
  #live { color: #fc6; font-variant-numeric: tabular-nums; }
  #live.done { color: #8d8; }
  main { display: flex; gap: 12px; padding: 10px; align-items: flex-start; }
  #left { flex: 1 1 auto; min-width: 0; }
  #side { flex: 0 0 330px; display: flex; flex-direction: column; gap: 10px; }
  #viewbox { position: relative; background: #000; display: inline-block; max-width: 100%; cursor: grab;
             user-select: none; outline: none; }
  #viewbox:focus { box-shadow: 0 0 0 2px #58a; }
  #view { display: block; max-width: 100%; height: auto; }
  #badge { position: absolute; left: 6px; top: 6px; background: rgba(0,0,0,.55); padding: 2px 6px; border-radius: 3px; }
  #errmsg { color: #f88; min-height: 1.3em; }
  fieldset { border: 1px solid #444; border-radius: 4px; margin: 0; padding: 6px 8px; }
  legend { color: #aaa; }
  label { display: block; margin: 3px 0; }
  select, button, input { font: inherit; }
  .bar { height: 14px; border: 1px solid #555; }
  .ticks { display: flex; justify-content: space-between; font-size: 11px; color: #bbb; }
  #cams { max-height: 280px; overflow-y: auto; border: 1px solid #444; }
  #cams table { border-collapse: collapse; width: 100%; font-size: 12px; }
  #cams td, #cams th { padding: 2px 4px; text-align: left; white-space: nowrap; }
  #cams tr.sel { background: #35507a; }
  #cams tbody tr:hover { background: #333a48; cursor: pointer; }
  #cams tr.off { color: #777; }
  #compare { margin-top: 10px; display: none; }
  #compare .row { display: flex; gap: 6px; flex-wrap: wrap; }
  #compare figure { margin: 0; flex: 1 1 0; min-width: 120px; }
  #compare img { width: 100%; display: block; background: #000; min-height: 40px; }
  #compare figcaption { color: #aaa; }
  .note { color: #999; font-size: 12px; }
  kbd { background: #333; border: 1px solid #555; border-radius: 3px; padding: 0 3px; font-size: 11px; }
</style>
</head>
<body>
<header>
  <b>msgs view</b>
  <span>Gaussians <span class="stat" id="sGauss">-</span></span>
  <span>render <span class="stat" id="sMs">-</span> ms</span>
  <span>round trip <span class="stat" id="sRt">-</span> ms</span>
  <span><span class="stat" id="sFps">-</span> frames/s</span>
  <span>image <span class="stat" id="sRes">-</span></span>
  <span id="live" hidden></span>
</header>
<main>
  <div id="left">
    <div id="viewbox" tabindex="0"><img id="view" alt="render" draggable="false"><span id="badge"></span></div>
    <div id="errmsg"></div>
    <div id="compare">
      <div><b id="cmpTitle"></b> <span id="cmpStats" class="stat"></span> <button id="cmpClose">close</button></div>
      <div class="row">
        <figure><img id="cmpGt" alt="ground truth"><figcaption>ground truth</figcaption></figure>
        <figure><img id="cmpRender" alt="render"><figcaption>render</figcaption></figure>
        <figure><img id="cmpErr" alt="error"><figcaption>error: mean |render &minus; ground truth|</figcaption></figure>
      </div>
      <div id="cmpNote" class="note"></div>
      <div style="max-width: 320px; margin-top: 4px">
        <div class="bar" id="errBar"></div>
        <div class="ticks" id="errTicks"></div>
      </div>
    </div>
  </div>
  <div id="side">
    <fieldset><legend>Display</legend>
      <label>mode <select id="mode"></select></label>
      <div id="legend"></div>
      <label>gain <input id="gain" type="range" min="-3" max="4" step="0.25" value="0"> <span id="gainv">1&times;</span></label>
      <label>background <select id="bg"><option value="eval">evaluation grey</option><option value="black">black</option><option value="white">white</option></select></label>
      <label>size <select id="size"><option>320</option><option>480</option><option selected>640</option><option>960</option><option>1280</option></select> px wide</label>
      <label><input id="lowres" type="checkbox" checked> lower resolution while moving</label>
      <button id="reset">reset view (R)</button>
    </fieldset>
    <fieldset><legend>Controls</legend>
      <div class="note">drag: orbit &middot; right-drag or shift-drag: pan &middot; wheel: zoom<br>
      <kbd>W</kbd><kbd>S</kbd> forward/back &middot; <kbd>A</kbd><kbd>D</kbd> left/right &middot; <kbd>Q</kbd><kbd>E</kbd> down/up<br>
      arrows: orbit &middot; <kbd>Shift</kbd> faster &middot; <kbd>R</kbd> reset &middot; <kbd>[</kbd><kbd>]</kbd> previous/next camera</div>
    </fieldset>
    <fieldset id="camsBox"><legend>Dataset cameras</legend>
      <label>band <select id="fBand"><option value="">all</option></select>
        split <select id="fSplit"><option value="">all</option><option>train</option><option>eval</option></select></label>
      <div id="cams"><table><thead><tr><th>id</th><th>band</th><th>split</th><th>image</th><th>size</th></tr></thead><tbody id="camRows"></tbody></table></div>
      <div id="camInfo" class="note"></div>
    </fieldset>
  </div>
</main>
<script>
"use strict";
const $ = id => document.getElementById(id);
let info = null;
const IDLE_MS = 250;
const link = new URLSearchParams(location.search);            // deep link (see the file comment)
const imgFormat = link.get("format") === "png" ? "png" : "jpeg";  // frames as JPEG unless asked
const sleep = ms => new Promise(res => setTimeout(res, ms));

// ---- small vector helpers ----
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const mul = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const norm = a => Math.hypot(a[0], a[1], a[2]);
const unit = a => { const n = norm(a); return n > 0 ? mul(a, 1 / n) : a; };
function rotate(v, k, ang) {  // Rodrigues: v about unit axis k
  const c = Math.cos(ang), s = Math.sin(ang);
  return add(add(mul(v, c), mul(cross(k, v), s)), mul(k, dot(k, v) * (1 - c)));
}

// ---- camera state ----
const cam = { pos: [0, 0, 0], right: [1, 0, 0], down: [0, 0, -1], fwd: [0, 1, 0], dist: 1,
              fxn: 1, fyn: 1, cxn: 0.5, cyn: 0.5, aspect: 0.75 };
let up = [0, 0, 1], center = [0, 0, 0], radius = 1;
let selected = -1;  // dataset camera shown in the compare panel
let atCamera = -1;  // dataset camera the view sits at (until the user moves)

function defaultIntrinsics(aspect) {
  cam.aspect = aspect;
  cam.fyn = 0.5 / Math.tan(25 * Math.PI / 180);  // 50 degrees vertical field of view
  cam.fxn = cam.fyn * aspect;                      // square pixels
  cam.cxn = 0.5; cam.cyn = 0.5;
}
function lookAt(eye, target) {
  cam.pos = eye.slice();
  cam.fwd = unit(sub(target, eye));
  let r = cross(cam.fwd, up);
  if (norm(r) < 1e-6) r = cross(cam.fwd, Math.abs(cam.fwd[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0]);
  cam.right = unit(r);
  cam.down = cross(cam.fwd, cam.right);
  cam.dist = Math.max(1e-3, norm(sub(target, eye)));
}
function orthonormalise() {
  cam.fwd = unit(cam.fwd);
  cam.right = unit(sub(cam.right, mul(cam.fwd, dot(cam.right, cam.fwd))));
  cam.down = cross(cam.fwd, cam.right);
}
function pivot() { return add(cam.pos, mul(cam.fwd, cam.dist)); }
function orbit(yaw, pitch) {
  const p = pivot();
  for (const k of ["right", "down", "fwd"]) cam[k] = rotate(cam[k], up, yaw);
  const fwd2 = rotate(cam.fwd, cam.right, pitch);
  if (Math.abs(dot(fwd2, up)) < 0.985) {  // do not tip over the pole
    cam.down = rotate(cam.down, cam.right, pitch);
    cam.fwd = fwd2;
  }
  orthonormalise();
  cam.pos = sub(p, mul(cam.fwd, cam.dist));
  moved();
}
function pan(dx, dy) {  // in screen pixels of the displayed image
  const w = $("view").clientWidth || 640;
  const k = cam.dist / (cam.fxn * w);
  cam.pos = add(cam.pos, add(mul(cam.right, -dx * k), mul(cam.down, -dy * k)));
  moved();
}
function zoom(f) {
  const p = pivot();
  cam.dist = Math.min(Math.max(cam.dist * f, radius * 1e-3), radius * 100);
  cam.pos = sub(p, mul(cam.fwd, cam.dist));
  moved();
}
function move(v) { cam.pos = add(cam.pos, v); moved(); }
function resetView() {
  selected = -1; atCamera = -1;
  if (info.cameras.length) { jump(info.cameras.findIndex(c => c.rendered) >= 0 ? info.cameras.findIndex(c => c.rendered) : 0, false); return; }
  defaultIntrinsics(0.75);
  let h = cross(up, [1, 0, 0]);
  if (norm(h) < 0.1) h = cross(up, [0, 1, 0]);
  lookAt(add(center, mul(unit(add(unit(h), mul(up, 0.6))), 2.5 * radius)), center);
  hideCompare();
  moved(true);
}
function jump(id, compare = true) {
  const c = info.cameras[id];
  cam.right = c.R.slice(0, 3); cam.down = c.R.slice(3, 6); cam.fwd = c.R.slice(6, 9);
  // position = -R^T t
  cam.pos = mul(add(add(mul(cam.right, c.t[0]), mul(cam.down, c.t[1])), mul(cam.fwd, c.t[2])), -1);
  cam.dist = Math.max(0.05 * radius, dot(sub(center, cam.pos), cam.fwd));
  cam.aspect = c.height / c.width;
  cam.fxn = c.fx / c.width; cam.fyn = c.fy / c.height; cam.cxn = c.cx / c.width; cam.cyn = c.cy / c.height;
  selected = id;
  highlightCamera();
  atCamera = id;
  $("camInfo").textContent = `#${id} ${c.name}: ${c.band}, ${c.split}, ${c.width}x${c.height}, ` +
    `fx ${c.fx.toFixed(2)} fy ${c.fy.toFixed(2)} cx ${c.cx.toFixed(2)} cy ${c.cy.toFixed(2)}`;
  moved(true);
  if (compare && c.rendered) showCompare(id); else hideCompare();
  updateLink();
}
function updateLink() {  // keep the address bar a deep link to what is shown
  const q = new URLSearchParams(location.search);
  if (atCamera >= 0) q.set("frame", atCamera); else q.delete("frame");
  q.set("mode", currentMode());
  history.replaceState(null, "", "?" + q.toString());
}

// ---- rendering loop: one request in flight, newest state wins ----
let version = 0, lastMove = 0, inflight = false, shown = { version: -1, full: false }, idleTimer = null;
const times = [];
function moved(settled = false) {
  version++;
  if (!settled) {
    lastMove = performance.now();
    if (atCamera >= 0) { atCamera = -1; updateLink(); }
  }
  pump();
}
function renderSize(full) {
  let w = parseInt($("size").value, 10);
  if (!full && $("lowres").checked) w = Math.max(64, Math.round(w / 3));
  return [w, Math.max(1, Math.round(w * cam.aspect))];
}
function fmt(x) { return Number.isFinite(x) ? x.toPrecision(9) : "0"; }
function currentMode() { return $("mode").value; }
function renderUrl(full) {
  const [w, h] = renderSize(full);
  const R = [...cam.right, ...cam.down, ...cam.fwd];
  const t = [-dot(cam.right, cam.pos), -dot(cam.down, cam.pos), -dot(cam.fwd, cam.pos)];
  const q = new URLSearchParams({ width: w, height: h, fx: fmt(cam.fxn * w), fy: fmt(cam.fyn * h),
    cx: fmt(cam.cxn * w), cy: fmt(cam.cyn * h), R: R.map(fmt).join(","), t: t.map(fmt).join(","),
    mode: currentMode(), bg: $("bg").value, gain: gainValue().toString(), format: imgFormat, quality: full ? "92" : "80" });
  return "/api/render?" + q.toString();
}
async function pump() {
  if (inflight || !info) return;
  const now = performance.now();
  const still = now - lastMove >= IDLE_MS || !$("lowres").checked;
  if (shown.version === version && (shown.full || !still)) {
    if (!shown.full && idleTimer === null)
      idleTimer = setTimeout(() => { idleTimer = null; pump(); }, IDLE_MS - (now - lastMove) + 5);
    return;
  }
  const v = version, full = still;
  inflight = true;
  const t0 = performance.now();
  try {
    const r = await fetch(renderUrl(full));
    if (!r.ok) throw new Error((await r.json().catch(() => ({}))).error || r.statusText);
    const blob = await r.blob();
    const img = $("view"), old = img.src;
    img.src = URL.createObjectURL(blob);
    if (old) URL.revokeObjectURL(old);
    img.style.width = $("size").value + "px";
    const rt = performance.now() - t0;
    times.push(rt); if (times.length > 10) times.shift();
    $("sMs").textContent = r.headers.get("X-Render-Ms");
    $("sRt").textContent = rt.toFixed(0);
    $("sFps").textContent = (1000 * times.length / times.reduce((a, b) => a + b, 0)).toFixed(1);
    $("sRes").textContent = `${r.headers.get("X-Width")}x${r.headers.get("X-Height")}${full ? "" : " (moving)"}`;
    $("sGauss").textContent = Number(r.headers.get("X-Gaussians")).toLocaleString();
    $("badge").textContent = modeLabel(currentMode()) + (atCamera >= 0 ? ` · camera #${atCamera}` : "");
    $("badge").hidden = parseInt($("size").value, 10) < 240;  // it would cover a small view; the title has it
    img.title = $("badge").textContent;
    $("errmsg").textContent = "";
    shown = { version: v, full };
  } catch (e) {
    $("errmsg").textContent = "render failed: " + e.message;
    shown = { version: v, full: true };  // do not retry the same state in a loop
  } finally {
    inflight = false;
  }
  pump();
}

// ---- compare panel: ground truth | render | error at a dataset camera ----
let cmpUrls = [];
function hideCompare() { $("compare").style.display = "none"; }
async function showCompare(id) {
  const c = info.cameras[id];
  const scale = Math.max(info.dataset.downscale, Math.ceil(c.width / 640));
  $("compare").style.display = "block";
  $("cmpTitle").textContent = `camera #${id} ${c.name} (${modeLabel(currentMode())})`;
  $("cmpStats").textContent = "rendering...";
  $("cmpNote").textContent = "";
  for (const u of cmpUrls) URL.revokeObjectURL(u);
  cmpUrls = [];
  const base = { id, mode: currentMode(), bg: $("bg").value, gain: gainValue().toString(), scale, format: imgFormat, quality: "92" };
  const get = async (what, el) => {
    const r = await fetch("/api/frame?" + new URLSearchParams({ ...base, what }).toString());
    if (!r.ok) { el.removeAttribute("src"); el.alt = (await r.json().catch(() => ({}))).error || r.statusText; return r; }
    const u = URL.createObjectURL(await r.blob());
    cmpUrls.push(u);
    el.src = u;
    return r;
  };
  try {
    const rr = await get("render", $("cmpRender"));
    if (selected !== id) return;
    if (!rr.ok) { $("cmpStats").textContent = $("cmpRender").alt; return; }
    const psnr = rr.headers.get("X-PSNR"), mae = rr.headers.get("X-MAE"), missing = rr.headers.get("X-GT-Missing");
    $("cmpStats").textContent = (psnr ? `PSNR ${Number(psnr).toFixed(2)} dB` : mae ? `mean |index difference| ${Number(mae).toFixed(4)}` : "no ground truth") +
      ` · render ${rr.headers.get("X-Render-Ms")} ms · ${rr.headers.get("X-Width")}x${rr.headers.get("X-Height")}`;
    if (missing) $("cmpNote").textContent = missing;
    else if (!(modeInfo(currentMode()).bands.length === 1 && modeInfo(currentMode()).bands[0] === c.band))
      $("cmpNote").textContent = "ground truth of other bands comes from the same capture's cameras (slightly different viewpoints)";
    await get("gt", $("cmpGt"));
    const er = await get("error", $("cmpErr"));
    const scaleTop = Number(er.headers.get("X-Error-Scale") || modeInfo(currentMode()).error_scale);
    setBar($("errBar"), $("errTicks"), info.colormaps.sequential, [0, scaleTop / 2, scaleTop]);
  } catch (e) {
    $("cmpStats").textContent = "failed: " + e.message;
  }
}

// ---- modes and legend ----
function modeInfo(id) { return info.modes.find(m => m.id === id); }
function modeLabel(id) {
  const m = modeInfo(id);
  if (!m) return id;
  if (m.kind === "index") return m.label;
  if (id === "rgb") return "RGB (band D)";
  if (id === "cir") return "CIR (NIR, R, G)";
  return id;
}
function setBar(bar, ticks, stops, labels) {
  bar.style.background = "linear-gradient(to right, " +
    stops.map((s, i) => `rgb(${s.map(v => Math.round(v * 255)).join(",")}) ${(100 * i / (stops.length - 1)).toFixed(1)}%`).join(", ") + ")";
  ticks.innerHTML = "";
  for (const l of labels) { const s = document.createElement("span"); s.textContent = String(l); ticks.appendChild(s); }
}
function updateLegend() {
  const m = modeInfo(currentMode()), el = $("legend");
  el.innerHTML = "";
  const note = document.createElement("div");
  note.className = "note";
  if (m.kind === "index") {
    const bar = document.createElement("div"), ticks = document.createElement("div");
    bar.className = "bar"; ticks.className = "ticks";
    el.appendChild(bar); el.appendChild(ticks);
    setBar(bar, ticks, info.colormaps.diverging, [m.lo, (m.lo + m.hi) / 2, m.hi].map(v => v.toFixed(1)));
    note.textContent = `${m.label} = ${m.formula}; 0 where the denominator vanishes`;
  } else if (m.id === "cir") {
    note.textContent = "colour infrared: NIR shown as red, R as green, G as blue";
  } else if (m.id === "rgb") {
    note.textContent = "the RGB camera band D";
  } else {
    note.textContent = `band ${m.id}, grey: 0 black .. 1 white (times the gain)`;
  }
  el.appendChild(note);
  $("gain").disabled = m.kind === "index";
}
function gainValue() { return Math.pow(2, parseFloat($("gain").value)); }

// ---- camera list ----
function fillCameras(scroll = true) {
  const rows = $("camRows");
  rows.innerHTML = "";
  const band = $("fBand").value, split = $("fSplit").value;
  info.cameras.forEach((c, i) => {
    if ((band && c.band !== band) || (split && c.split !== split)) return;
    const tr = document.createElement("tr");
    tr.dataset.id = i;
    if (!c.rendered) { tr.className = "off"; tr.title = "the model does not render this band"; }
    for (const v of [i, c.band, c.split, c.name.split("/").pop(), `${c.width}x${c.height}`]) {
      const td = document.createElement("td"); td.textContent = v; tr.appendChild(td);
    }
    tr.onclick = () => jump(i);
    rows.appendChild(tr);
  });
  highlightCamera(scroll);
}
function highlightCamera(scroll = true) {
  for (const tr of $("camRows").children) {
    const on = Number(tr.dataset.id) === selected;
    tr.classList.toggle("sel", on);
    if (on && scroll) tr.scrollIntoView({ block: "nearest" });
  }
}
function stepCamera(d) {
  const ids = [...$("camRows").children].map(tr => Number(tr.dataset.id));
  if (!ids.length) return;
  const k = ids.indexOf(selected);
  jump(ids[k < 0 ? 0 : (k + d + ids.length) % ids.length]);
}

// ---- input ----
function setupInput() {
  const box = $("viewbox");
  let drag = null;
  box.addEventListener("contextmenu", e => e.preventDefault());
  box.addEventListener("pointerdown", e => {
    box.focus();
    drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.button === 1 || e.shiftKey };
    box.setPointerCapture(e.pointerId);
    box.style.cursor = "grabbing";
  });
  box.addEventListener("pointermove", e => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (dx === 0 && dy === 0) return;
    if (drag.pan) pan(dx, dy); else orbit(-dx * 0.006, -dy * 0.006);
  });
  const end = () => { drag = null; box.style.cursor = "grab"; };
  box.addEventListener("pointerup", end);
  box.addEventListener("pointercancel", end);
  box.addEventListener("wheel", e => { e.preventDefault(); zoom(Math.exp(Math.max(-1, Math.min(1, e.deltaY * 0.0015)))); }, { passive: false });
  window.addEventListener("keydown", e => {
    const tag = e.target.tagName;
    if (tag === "INPUT" || tag === "SELECT" || e.ctrlKey || e.metaKey || e.altKey) return;
    const step = radius * (e.shiftKey ? 0.15 : 0.04), ang = (e.shiftKey ? 12 : 4) * Math.PI / 180;
    const k = e.key.length === 1 ? e.key.toLowerCase() : e.key;
    const acts = {
      w: () => move(mul(cam.fwd, step)), s: () => move(mul(cam.fwd, -step)),
      a: () => move(mul(cam.right, -step)), d: () => move(mul(cam.right, step)),
      q: () => move(mul(up, -step)), e: () => move(mul(up, step)),
      ArrowLeft: () => orbit(ang, 0), ArrowRight: () => orbit(-ang, 0),
      ArrowUp: () => orbit(0, ang), ArrowDown: () => orbit(0, -ang),
      r: () => resetView(), "[": () => stepCamera(-1), "]": () => stepCamera(1),
    };
    if (acts[k]) { e.preventDefault(); acts[k](); }
  });
  const settingsChanged = () => { moved(true); if (selected >= 0 && $("compare").style.display !== "none") showCompare(selected); };
  $("mode").onchange = () => { updateLegend(); settingsChanged(); updateLink(); };
  $("bg").onchange = settingsChanged;
  $("gain").oninput = () => { $("gainv").textContent = gainValue().toFixed(2).replace(/\.?0+$/, "") + "×"; };
  $("gain").onchange = settingsChanged;
  $("size").onchange = () => moved(true);
  $("lowres").onchange = () => moved(true);
  $("reset").onclick = resetView;
  $("cmpClose").onclick = hideCompare;
  $("fBand").onchange = fillCameras;
  $("fSplit").onchange = fillCameras;
}

// ---- info: modes, cameras; refreshed when a live view has a new snapshot ----
async function fetchInfo() {
  const r = await fetch("/api/info");
  const j = await r.json().catch(() => ({}));
  if (!r.ok) { const e = new Error(j.error || r.statusText); e.status = r.status; throw e; }
  return j;
}
function fillModes() {
  const sel = $("mode"), keep = sel.value;
  sel.innerHTML = "";
  for (const m of info.modes) {
    const o = document.createElement("option");
    o.value = m.id;
    o.textContent = modeLabel(m.id) + (m.kind === "index" ? ` = ${m.formula}` : "");
    if (!m.available) { o.disabled = true; o.title = m.why; }
    sel.appendChild(o);
  }
  const wanted = keep || link.get("mode");
  const first = info.modes.find(m => m.available && m.id === wanted) || info.modes.find(m => m.available && m.id === "rgb") ||
                info.modes.find(m => m.available);
  if (first) sel.value = first.id;
}

// ---- live view: training progress, a fresh render when a new snapshot arrives ----
let liveVersion = 0;
function showLive(L) {
  const el = $("live"), cur = L.models.length ? L.models[L.models.length - 1] : null;
  el.hidden = false;
  el.classList.toggle("done", L.state !== "training");
  const which = cur ? (L.expected_models > 1 ? `model ${cur.key} (${L.models.length} of ${L.expected_models}) ` : "") +
                      `step ${cur.step.toLocaleString()} / ${cur.end.toLocaleString()}` : "waiting for the first step";
  el.textContent = (L.state === "training" ? "● training " : L.state === "done" ? "training done " : "training interrupted ") +
                   `${L.strategy}: ${which} · snapshot ${L.version}`;
}
async function pollLive() {
  let L = null;
  try {
    const r = await fetch("/api/live");
    if (r.ok) L = await r.json();
  } catch (e) {
    $("live").textContent = "viewer stopped";
    return;
  }
  if (L) {
    showLive(L);
    if (L.version > 0 && L.version !== liveVersion) {
      try {
        const was = info;
        info = await fetchInfo();
        liveVersion = L.version;
        // Rebuild the mode list and the camera table only when a band model appeared (Separate,
        // Split): rebuilding would close an open drop-down or scroll the page every second.
        const modesSig = i => i.modes.map(m => m.available ? 1 : 0).join("");
        const camsSig = i => i.cameras.map(c => c.rendered ? 1 : 0).join("");
        if (modesSig(was) !== modesSig(info)) { fillModes(); updateLegend(); }
        if (camsSig(was) !== camsSig(info)) fillCameras(false);
        moved(true);  // the same camera, the new model
        if (selected >= 0 && $("compare").style.display !== "none") showCompare(selected);
      } catch (e) { /* the next poll tries again */ }
    }
  }
  setTimeout(pollLive, !L || L.state === "training" ? 1000 : 5000);
}

function applyLink() {
  if (link.has("bg") && [...$("bg").options].some(o => o.value === link.get("bg"))) $("bg").value = link.get("bg");
  const w = parseInt(link.get("size"), 10);
  if (w >= 64 && w <= 4096) {
    if (![...$("size").options].some(o => o.value === String(w))) {
      const o = document.createElement("option"); o.textContent = String(w); $("size").appendChild(o);
    }
    $("size").value = String(w);
  }
  if (link.get("lowres") === "0") $("lowres").checked = false;
}

async function start() {
  for (;;) {
    try {
      info = await fetchInfo();
      break;
    } catch (e) {
      if (e.status !== 503) { $("errmsg").textContent = "cannot read /api/info: " + e.message; return; }
      $("errmsg").textContent = "waiting for the model: " + e.message;  // a live view before its first step
      await sleep(500);
    }
  }
  $("errmsg").textContent = "";
  up = info.scene.up; center = info.scene.center; radius = info.scene.radius;
  $("sGauss").textContent = info.gaussians.toLocaleString();
  fillModes();
  if (!info.cameras.length) $("camsBox").style.display = "none";
  for (const b of [...new Set(info.cameras.map(c => c.band))]) {
    const o = document.createElement("option"); o.textContent = b; $("fBand").appendChild(o);
  }
  applyLink();
  setupInput();
  updateLegend();
  fillCameras();
  const frame = link.has("frame") ? Number(link.get("frame")) : -1;
  if (Number.isInteger(frame) && frame >= 0 && frame < info.cameras.length) jump(frame); else resetView();
  if (info.live) { liveVersion = info.live.version; pollLive(); }
}
start();
</script>
</body>
</html>
)MSGSPAGE";

}  // namespace msgs::view
