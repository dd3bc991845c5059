// The raycore viewer: renders the chosen scene through the service's render endpoint, orbits,
// pans and zooms with the mouse, picks with one intersect ray, uploads meshes.  No build step,
// no library: the page asks nothing of anyone but the service that served it.

const $ = (id) => document.getElementById(id);
const view = $("view"), stage = $("stage"), marker = $("marker");
const sceneChooser = $("scene"), shadingChooser = $("shading"), samplesChooser = $("samples");

// While the pointer moves, frames are this fraction of the stage's size, one sample a pixel.
const PREVIEW_SCALE = 0.25;
// A full frame follows this long after the last move.
const IDLE_MS = 200;
// A press that moves less than this (pixels) is a click: a pick, not a drag.
const CLICK_SLOP = 3;
const FOV = 45;

const state = {
  scene: "demo",
  camera: null,        // {target, distance, yaw, pitch} around the scene's bounds
  frame: null,         // {controller, preview} of the render in flight
  pendingPreview: false,
  idleTimer: null,
  names: new Map(),    // scene id -> file name of an upload
  shown: 0,            // frames shown, for tests and the status line
};

// ------------------------------------------------------------------ vectors

const sub = (a, b) => a.map((x, i) => x - b[i]);
const add = (a, b) => a.map((x, i) => x + b[i]);
const scale = (a, s) => a.map((x) => x * s);
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                         a[0] * b[1] - a[1] * b[0]];
const unit = (a) => scale(a, 1 / Math.sqrt(dot(a, a)));

// ------------------------------------------------------------------ the service

function headers(extra = {}) {
  const key = $("api-key").value.trim();
  return key ? { ...extra, "X-API-Key": key } : extra;
}

class ServiceError extends Error {}

// fetch, with the service's own words for a failure: its JSON "detail"
async function call(path, options = {}) {
  const response = await fetch(path, { ...options, headers: headers(options.headers) });
  if (!response.ok) {
    let detail = `${response.status} ${response.statusText}`;
    try {
      const body = await response.json();
      if (body && typeof body.detail === "string") detail = body.detail;
    } catch (_) { /* not JSON: keep the status line */ }
    throw new ServiceError(detail);
  }
  return response;
}

function showError(error) {
  if (error.name === "AbortError") return; // a superseded frame
  const box = $("error");
  box.textContent = error instanceof ServiceError ? error.message : String(error);
  box.hidden = false;
}

function clearError() {
  $("error").hidden = true;
  $("error").textContent = "";
}

// ------------------------------------------------------------------ camera

// The camera as the render endpoint takes it, for a frame of width x height pixels.
function renderCamera(width, height) {
  const { target, distance, yaw, pitch } = state.camera;
  const offset = [Math.cos(pitch) * Math.sin(yaw), Math.sin(pitch), Math.cos(pitch) * Math.cos(yaw)];
  return { type: "perspective", position: add(target, scale(offset, distance)), look_at: target,
           up: [0, 1, 0], fov: FOV, width, height };
}

// Frame the scene's bounds from a three-quarter view (as raycore.camera.frame_box does).
function frameBounds(bounds) {
  let lo = [-1, -1, -1], hi = [1, 1, 1];
  if (bounds && bounds.lo.every(Number.isFinite) && bounds.hi.every(Number.isFinite)) {
    ({ lo, hi } = bounds);
  }
  const radius = Math.max(Math.sqrt(dot(sub(hi, lo), sub(hi, lo))) / 2, 1e-6);
  state.camera = { target: scale(add(lo, hi), 0.5),
                   distance: 1.1 * radius / Math.sin((FOV / 2) * Math.PI / 180),
                   yaw: 0.56, pitch: 0.35 };
}

// The ray of a pixel's centre, as raycore.camera.perspective_rays makes it.
function pixelRay(camera, x, y) {
  const forward = unit(sub(camera.look_at, camera.position));
  const right = unit(cross(forward, camera.up));
  const up = cross(right, forward);
  const half = Math.tan((camera.fov * Math.PI / 180) / 2);
  const across = ((x + 0.5) / camera.width * 2 - 1) * half * camera.width / camera.height;
  const rise = (1 - (y + 0.5) / camera.height * 2) * half;
  return { origin: camera.position,
           direction: unit(add(forward, add(scale(right, across), scale(up, rise)))) };
}

// ------------------------------------------------------------------ frames

// Render a frame; a full frame replaces whatever is in flight, a preview waits for the one in
// flight (moves made meanwhile are drawn by the next).
async function render(preview) {
  if (state.frame) {
    if (preview && state.frame.preview) {
      state.pendingPreview = true;
      return;
    }
    state.frame.controller.abort();
  }
  const controller = new AbortController();
  const frame = { controller, preview };
  state.frame = frame;
  const factor = preview ? PREVIEW_SCALE : 1;
  const width = Math.max(1, Math.round(stage.clientWidth * factor));
  const height = Math.max(1, Math.round(stage.clientHeight * factor));
  const camera = renderCamera(width, height);
  const body = { camera, shading: shadingChooser.value,
                 samples: preview ? 1 : Number(samplesChooser.value) };
  $("status").textContent = preview ? "moving…" : "rendering…";
  try {
    const response = await call(`/v1/scenes/${encodeURIComponent(state.scene)}/render`, {
      method: "POST", body: JSON.stringify(body), signal: controller.signal,
      headers: { "Content-Type": "application/json", Accept: "image/png" } });
    const blob = await response.blob();
    if (controller.signal.aborted) return;
    const old = view.src;
    view.src = URL.createObjectURL(blob);
    await view.decode().catch(() => {});
    if (old.startsWith("blob:")) URL.revokeObjectURL(old);
    view.dataset.camera = JSON.stringify(camera);
    view.dataset.scene = state.scene;
    view.dataset.shading = body.shading;
    view.dataset.samples = String(body.samples);
    view.dataset.kind = preview ? "preview" : "full";
    view.dataset.frame = String(++state.shown);
    stage.classList.toggle("preview", preview);
    $("status").textContent = `${width}×${height}, ${body.samples} sample${body.samples > 1 ? "s" : ""} a pixel`;
    clearError();
  } catch (error) {
    showError(error);
    if (!controller.signal.aborted) $("status").textContent = "";
  } finally {
    if (state.frame === frame) state.frame = null;
  }
  if (preview && state.pendingPreview && !state.frame) {
    state.pendingPreview = false;
    render(true);
  }
}

// A preview now, and a full frame once the pointer rests.
function moved() {
  render(true);
  clearTimeout(state.idleTimer);
  state.idleTimer = setTimeout(() => { state.pendingPreview = false; render(false); }, IDLE_MS);
}

// ------------------------------------------------------------------ scenes

async function loadScene(id) {
  const info = await (await call(`/v1/scenes/${encodeURIComponent(id)}`)).json();
  state.scene = id;
  frameBounds(info.bounds);
  marker.hidden = true;
  await render(false);
}

async function listScenes(selected) {
  const listing = await (await call("/v1/scenes?limit=100")).json();
  const demo = await call("/v1/scenes/demo").then((r) => r.json(), () => null);
  sceneChooser.replaceChildren();
  const option = (value, label) => {
    const element = document.createElement("option");
    element.value = value;
    element.textContent = label;
    sceneChooser.append(element);
  };
  if (demo) option("demo", "demo");
  for (const item of listing.items) {
    if (demo && item.id === demo.id) continue;
    option(item.id, state.names.get(item.id) || item.id.slice(0, 12));
  }
  const wanted = selected || (demo ? "demo" : listing.items[0]?.id);
  if (wanted) sceneChooser.value = wanted;
  return wanted;
}

async function upload(file) {
  clearError();
  $("status").textContent = `uploading ${file.name}…`;
  const form = new FormData();
  form.append("file", file, file.name);
  const mesh = await (await call("/v1/meshes", { method: "POST", body: form })).json();
  const scene = await (await call("/v1/scenes", {
    method: "POST", headers: { "Content-Type": "application/json" },
    body: JSON.stringify({ objects: [{ type: "mesh", mesh: mesh.id }] }) })).json();
  state.names.set(scene.id, file.name);
  await listScenes(scene.id);
  await loadScene(scene.id);
}

// ------------------------------------------------------------------ picking

async function pick(event) {
  const camera = JSON.parse(view.dataset.camera || "null");
  if (!camera) return;
  const box = view.getBoundingClientRect();
  const x = Math.min(camera.width - 1, Math.floor((event.clientX - box.left) / box.width * camera.width));
  const y = Math.min(camera.height - 1, Math.floor((event.clientY - box.top) / box.height * camera.height));
  const ray = pixelRay(camera, x, y);
  marker.style.left = `${(x + 0.5) / camera.width * 100}%`;
  marker.style.top = `${(y + 0.5) / camera.height * 100}%`;
  marker.hidden = false;
  const answer = await (await call(`/v1/scenes/${encodeURIComponent(view.dataset.scene)}/intersect`, {
    method: "POST", headers: { "Content-Type": "application/json" },
    body: JSON.stringify({ origins: [ray.origin], directions: [ray.direction],
                           fields: ["normal", "point"] }) })).json();
  const readout = $("pick");
  const rows = [["pixel", `${x}, ${y}`]];
  const vector = (v) => (v ? v.map((c) => c.toFixed(4)).join(", ") : "—");
  if (answer.geom_id[0] < 0) {
    rows.push(["hit", "none (the ray missed)"]);
  } else {
    rows.push(["t", answer.t[0].toPrecision(7)], ["geom_id", answer.geom_id[0]],
              ["prim_id", answer.prim_id[0]], ["normal", vector(answer.normal[0])],
              ["point", vector(answer.point[0])]);
  }
  readout.replaceChildren(...rows.flatMap(([name, value]) => {
    const term = document.createElement("dt");
    term.textContent = name;
    const detail = document.createElement("dd");
    detail.textContent = value;
    detail.dataset.field = name;
    return [term, detail];
  }));
  Object.assign(readout.dataset, { x, y, t: answer.t[0] ?? "", geomId: answer.geom_id[0],
                                   primId: answer.prim_id[0] });
  clearError();
}

// ------------------------------------------------------------------ input

let drag = null;

stage.addEventListener("contextmenu", (event) => event.preventDefault());
stage.addEventListener("pointerdown", (event) => {
  if (!state.camera) return;
  drag = { x: event.clientX, y: event.clientY, moved: false,
           pan: event.shiftKey || event.button === 2 };
  stage.setPointerCapture(event.pointerId);
});
stage.addEventListener("pointermove", (event) => {
  if (!drag) return;
  const dx = event.clientX - drag.x, dy = event.clientY - drag.y;
  if (!drag.moved && Math.hypot(dx, dy) < CLICK_SLOP) return;
  drag.moved = true;
  stage.classList.add("dragging");
  drag.x = event.clientX;
  drag.y = event.clientY;
  const camera = state.camera;
  if (drag.pan) {
    const frame = renderCamera(stage.clientWidth, stage.clientHeight);
    const forward = unit(sub(frame.look_at, frame.position));
    const right = unit(cross(forward, frame.up));
    const up = cross(right, forward);
    // a pixel's size at the target's distance
    const step = 2 * camera.distance * Math.tan((FOV * Math.PI / 180) / 2) / stage.clientHeight;
    camera.target = add(camera.target, add(scale(right, -dx * step), scale(up, dy * step)));
  } else {
    camera.yaw -= dx * 0.01;
    camera.pitch = Math.max(-1.55, Math.min(1.55, camera.pitch + dy * 0.01));
  }
  moved();
});
stage.addEventListener("pointerup", (event) => {
  if (!drag) return;
  const click = !drag.moved && event.button === 0 && !drag.pan;
  drag = null;
  stage.classList.remove("dragging");
  if (click) pick(event).catch(showError);
});
stage.addEventListener("wheel", (event) => {
  if (!state.camera) return;
  event.preventDefault();
  state.camera.distance *= Math.exp(event.deltaY * 0.001);
  moved();
}, { passive: false });

for (const type of ["dragenter", "dragover"]) {
  stage.addEventListener(type, (event) => { event.preventDefault(); $("drop").hidden = false; });
}
stage.addEventListener("dragleave", () => { $("drop").hidden = true; });
stage.addEventListener("drop", (event) => {
  event.preventDefault();
  $("drop").hidden = true;
  const file = event.dataTransfer.files[0];
  if (file) upload(file).catch(showError);
});
$("upload").addEventListener("change", (event) => {
  const file = event.target.files[0];
  if (file) upload(file).catch(showError).finally(() => { event.target.value = ""; });
});
sceneChooser.addEventListener("change", () => loadScene(sceneChooser.value).catch(showError));
shadingChooser.addEventListener("change", () => render(false));
samplesChooser.addEventListener("change", () => render(false));

// ------------------------------------------------------------------ start

listScenes().then((id) => (id ? loadScene(id) : null)).catch(showError);
