// The ldimesh viewer: shows the isosurface meshes a running job publishes (docs/api.md).
// Everything comes from the job's own server: the API, the GLB meshes and three.js itself.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { DRACOLoader } from 'three/addons/loaders/DRACOLoader.js';

const token = new URLSearchParams(window.location.search).get('token') || '';
const $ = (id) => document.getElementById(id);

// ---------------------------------------------------------------------------------------------
// Scene

const canvas = $('view');
// preserveDrawingBuffer: the browser test reads the pixels back to check the canvas is not blank.
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
const background = new THREE.Color(0x1d2026);
renderer.setClearColor(background);
const scene = new THREE.Scene();
const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 1000);
camera.position.set(3, 2.2, 3.5);
const controls = new OrbitControls(camera, canvas);
controls.enableDamping = true;

// Shape shows best with a sky/ground fill and a light that moves with the camera.
scene.add(new THREE.HemisphereLight(0xdfe8ff, 0x2a2420, 0.9));
const headlight = new THREE.DirectionalLight(0xffffff, 1.6);
headlight.position.set(0.4, 0.7, 1.0);
camera.add(headlight);
scene.add(camera);

const material = new THREE.MeshStandardMaterial({
  vertexColors: true, roughness: 0.55, metalness: 0.05, side: THREE.DoubleSide,
});
// Plain: the colouring "plain", and a surface without a field while colouring by field.
const plainMaterial = new THREE.MeshStandardMaterial({
  color: 0xb8c4d6, roughness: 0.55, metalness: 0.05, side: THREE.DoubleSide,
});

// Rendering on demand: a frame is drawn only when the picture changes (a step shown, the camera
// moved, a resize, another colouring), never in a loop: with software rendering a big mesh
// costs a CPU core per frame, which the simulation beside it needs. OrbitControls reports each
// camera move as 'change', including the moves of its damping after the pointer lets go (the
// update() in each frame applies them and asks for the next frame until the camera is still).
// document.body.dataset.renders counts the frames drawn (the browser test reads it).
let renderRequested = false, renders = 0;
function requestRender() {
  if (renderRequested) return;
  renderRequested = true;
  requestAnimationFrame(() => {
    renderRequested = false;
    controls.update();
    renderer.render(scene, camera);
    document.body.dataset.renders = String(++renders);
  });
}
controls.addEventListener('change', requestRender);

function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
  requestRender();
}
window.addEventListener('resize', resize);
resize();

// ---------------------------------------------------------------------------------------------
// State shown to the person (the panel) and to tests (data attributes on <body>)

// loading: the step being loaded (null when none), next: the step to load after it (see show()).
const state = { steps: [], loaded: null, loading: null, next: null, mesh: null, camera };
window.ldimesh = state;

function setStatus(text, isError = false) {
  $('status').textContent = text;
  $('status').classList.toggle('error', isError);
  document.body.dataset.status = text;
}

function formatBytes(n) {
  if (n >= 1 << 20) return (n / (1 << 20)).toFixed(2) + ' MiB';
  if (n >= 1 << 10) return (n / (1 << 10)).toFixed(1) + ' KiB';
  return n + ' B';
}

function showMetadata(meta, triangles) {
  $('step').textContent = meta.step;
  $('time').textContent = meta.time !== undefined ? Number(meta.time).toPrecision(6) : '–';
  $('triangles').textContent = triangles.toLocaleString('en');
  $('bytes').textContent = meta.bytes !== undefined ? formatBytes(meta.bytes) : '–';
  $('isovalues').textContent = (meta.isovalues || []).join(', ') || '–';
  const rows = Object.entries(meta.seconds || {}).map(
    ([stage, s]) => `<tr><th>${stage}</th><td>${Number(s).toFixed(3)}</td></tr>`);
  $('stages').innerHTML = rows.join('');
}

// ---------------------------------------------------------------------------------------------
// The API

async function api(path) {
  const response = await fetch(path, { headers: { Authorization: `Bearer ${token}` } });
  if (response.status === 401) {
    throw new Error('the server refused the token: open the URL the job printed (…/?token=…)');
  }
  return response;
}

async function json(path) {
  const response = await api(path);
  if (!response.ok) throw new Error(`${path}: HTTP ${response.status}`);
  return response.json();
}

// ---------------------------------------------------------------------------------------------
// Meshes

// Draco decodes in a worker (three.js's DRACOLoader, WebAssembly). A decode that runs past its
// limit (a damaged or hostile mesh: Draco's decoders have loops bounded only by counts in the
// stream, docs/reliability.md) is stopped: its workers are terminated and a fresh loader takes
// over, so one bad step is an error line and never freezes the page. The limit: 10 s + 5 s per
// MiB of GLB (Draco decodes about a MiB a second on one core; three times that and more on a
// busy machine), or ?decode_timeout=SECONDS in the URL (also window.ldimeshViewer.decodeTimeout).
const loader = new GLTFLoader();
let draco = null;
function newDracoLoader() {
  draco = new DRACOLoader();
  draco.setDecoderPath('/vendor/three/examples/jsm/libs/draco/');
  loader.setDRACOLoader(draco);
}
newDracoLoader();
const viewerSettings = { decodeTimeout: null };
{
  const given = new URLSearchParams(window.location.search).get('decode_timeout');
  if (given !== null && given.trim() !== '' && Number(given) >= 0) {
    viewerSettings.decodeTimeout = Number(given);
  }
}
window.ldimeshViewer = viewerSettings;

async function parseGlb(buffer, step) {
  // setTimeout's delay is a 32-bit count of milliseconds: a longer limit is 24.8 days.
  const limit = Math.min(viewerSettings.decodeTimeout ?? 10 + 5 * buffer.byteLength / (1 << 20),
    (2 ** 31 - 1) / 1000);
  let timer = null, expired = false;
  const stop = new Promise((resolve, reject) => {
    timer = setTimeout(() => {
      expired = true;
      reject(new Error(`mesh of step ${step}: decoding took more than ${Number(limit.toFixed(1))} s ` +
        'and was stopped (a damaged mesh?)'));
    }, limit * 1000);
  });
  try {
    const parsing = loader.parseAsync(buffer, '');
    parsing.catch(() => {});  // once stopped, whatever it ends with is not shown
    return await Promise.race([parsing, stop]);
  } finally {
    clearTimeout(timer);
    if (expired) {
      // Terminates its workers, the one decoding included; a worker it is still starting (the
      // decoder's download and compilation) is terminated once started.
      const stopped = draco;
      stopped.dispose();
      stopped.decoderPending?.then(() => stopped.dispose(), () => {});
      newDracoLoader();
    }
  }
}

// Colour maps, sampled at equal steps and interpolated linearly: viridis (perceptually uniform,
// sequential; van der Walt and Smith's colour map for matplotlib) and cool–warm (diverging, for
// values on both sides of a midpoint; Moreland 2009, "Diverging Color Maps for Scientific
// Visualization").
const colourmaps = {
  viridis: [[0.267, 0.005, 0.329], [0.283, 0.141, 0.458], [0.254, 0.265, 0.530],
    [0.207, 0.372, 0.553], [0.164, 0.471, 0.558], [0.128, 0.567, 0.551], [0.135, 0.659, 0.518],
    [0.267, 0.749, 0.441], [0.478, 0.821, 0.318], [0.741, 0.873, 0.150], [0.993, 0.906, 0.144]],
  coolwarm: [[0.230, 0.299, 0.754], [0.384, 0.510, 0.918], [0.553, 0.690, 0.996],
    [0.722, 0.816, 0.976], [0.867, 0.867, 0.867], [0.961, 0.769, 0.678], [0.957, 0.604, 0.482],
    [0.871, 0.376, 0.302], [0.706, 0.016, 0.150]],
};

// The colour map's sRGB colour at t ∈ [0, 1] (the tables are sRGB, as published).
function colourmap(name, t) {
  const table = colourmaps[name] || colourmaps.viridis;
  const x = Math.min(Math.max(t, 0), 1) * (table.length - 1);
  const i = Math.min(Math.floor(x), table.length - 2), f = x - i;
  return table[i].map((c, k) => c + f * (table[i + 1][k] - c));
}

// sRGB to linear: three.js takes vertex colours as linear and converts its output to sRGB, so
// the surface shows the map's own colours (those of the legend) where it is lit fully.
function linear(c) {
  return c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4);
}

// The field surface s of the step is coloured by ({name, min, max}, or null): its entry of the
// metadata's surface_scalars where the step's surfaces differ (each isovalue coloured by a field
// of its own, or by none), else the step's one scalar. undefined s: a step of one surface.
function surfaceField(meta, s) {
  if (!meta) return null;
  if (Array.isArray(meta.surface_scalars)) return meta.surface_scalars[s || 0] || null;
  return meta.scalar || null;
}

// The step's fields, each once (by name), in the order of its surfaces.
function stepFields(meta) {
  if (!meta) return [];
  if (!Array.isArray(meta.surface_scalars)) return meta.scalar ? [meta.scalar] : [];
  const fields = [];
  for (const f of meta.surface_scalars)
    if (f && !fields.some((g) => g.name === f.name)) fields.push(f);
  return fields;
}

// A field's values map to the colour map over this range: the step's own (the field's min and
// max in its metadata) or, for the step's first field, the person's fixed one.
function colourRange(meta, field) {
  const first = stepFields(meta)[0];
  if (!field) field = first;
  if (!field) return [0, 1];
  if ($('range-auto').checked || !first || field.name !== first.name) return [field.min, field.max];
  return [Number($('range-min').value), Number($('range-max').value)];
}

// The controls and the legend for the step shown: colouring by the field is offered when the
// step carries one, and chosen by itself until the person picks a colouring. The fixed range
// applies to the step's first field; the legend has a row per field (the first: the #legend-*
// elements, the others made here).
const colouring = { chosenByPerson: false };
function updateFieldControls(meta) {
  const fields = stepFields(meta), field = fields[0];
  $('colour').querySelector('option[value=scalar]').disabled = !field;
  if (field && !colouring.chosenByPerson) $('colour').value = 'scalar';
  if (!field && $('colour').value === 'scalar') $('colour').value = 'view';
  $('field-controls').disabled = !field;
  if (field && $('range-auto').checked) {
    $('range-min').value = String(field.min);
    $('range-max').value = String(field.max);
  }
  const legend = $('legend');
  legend.hidden = !(field && $('colour').value === 'scalar');
  const more = $('legend-more');
  more.replaceChildren();
  if (legend.hidden) return;
  const drawBar = (bar) => {
    const ctx = bar.getContext('2d');
    for (let x = 0; x < bar.width; ++x) {
      const [r, g, b] = colourmap($('colourmap').value, x / (bar.width - 1));
      ctx.fillStyle = `rgb(${Math.round(255 * r)}, ${Math.round(255 * g)}, ${Math.round(255 * b)})`;
      ctx.fillRect(x, 0, 1, bar.height);
    }
  };
  const [lo, hi] = colourRange(meta, field);
  $('legend-name').textContent = field.name || 'field';
  $('legend-min').textContent = Number(lo).toPrecision(4);
  $('legend-max').textContent = Number(hi).toPrecision(4);
  drawBar($('legend-bar'));
  for (const f of fields.slice(1)) {
    const row = document.createElement('div');
    row.className = 'legend-row';
    row.innerHTML = '<div class="legend-name"></div><canvas class="legend-bar" width="256" height="14"></canvas>' +
      '<div class="legend-range"><span class="legend-min"></span><span class="legend-max"></span></div>';
    const [flo, fhi] = colourRange(meta, f);
    row.querySelector('.legend-name').textContent = f.name || 'field';
    row.querySelector('.legend-min').textContent = Number(flo).toPrecision(4);
    row.querySelector('.legend-max').textContent = Number(fhi).toPrecision(4);
    drawBar(row.querySelector('canvas'));
    more.append(row);
  }
}

// The legend's rows as shown: name, bar (a canvas), min and max.
function legendRows() {
  const rows = [{ name: $('legend-name').textContent, bar: $('legend-bar'),
    min: $('legend-min').textContent, max: $('legend-max').textContent }];
  for (const row of $('legend-more').children)
    rows.push({ name: row.querySelector('.legend-name').textContent, bar: row.querySelector('canvas'),
      min: row.querySelector('.legend-min').textContent, max: row.querySelector('.legend-max').textContent });
  return rows;
}

// The surface a mesh object of the GLB belongs to: the extras {"ldimesh_surface": s} of its
// node (three.js: userData of the object or, for a mesh of several primitives, of its group).
function surfaceOf(object) {
  for (let o = object; o; o = o.parent)
    if (o.userData && Number.isInteger(o.userData.ldimesh_surface)) return o.userData.ldimesh_surface;
  return undefined;
}

// Colours by view (the GLB's COLOR_0), by the field (_SCALAR, the value's place in its
// surface's field's range, through the colour map over colourRange; TEXCOORD_0.u in GLBs written
// before; a surface without a field plain) or plain. The colour attributes are swapped, never
// modified, so the GLB's own (which the Draco loader may hand over interleaved: cloning it would
// de-interleave it, with a warning) is kept as it is.
function applyColouring(root, meta) {
  const mode = $('colour').value;
  root.traverse((object) => {
    if (!object.isMesh) return;
    const g = object.geometry;
    const field = surfaceField(meta, surfaceOf(object));
    const [lo, hi] = colourRange(meta, field);
    const key = `${$('colourmap').value} ${lo} ${hi}`;
    if (!g.userData.viewColours && g.attributes.color) g.userData.viewColours = g.attributes.color;
    const scalar = g.attributes._scalar || g.attributes.uv;
    const byField = mode === 'scalar' && field && scalar;
    if (byField) {
      if (g.userData.scalarKey !== key) {
        const colours = new Float32Array(scalar.count * 3);
        const span = field.max - field.min, width = hi - lo;
        for (let i = 0; i < scalar.count; ++i) {
          const value = field.min + scalar.getX(i) * span;
          const rgb = colourmap($('colourmap').value, width > 0 ? (value - lo) / width : 0.5);
          colours.set(rgb.map(linear), 3 * i);
        }
        g.userData.scalarColours = new THREE.BufferAttribute(colours, 3);
        g.userData.scalarKey = key;
      }
      g.setAttribute('color', g.userData.scalarColours);
    } else if (mode === 'view' && g.userData.viewColours) {
      g.setAttribute('color', g.userData.viewColours);
    }
    const coloured = byField || (mode === 'view' && !!g.attributes.color);
    object.material = coloured ? material : plainMaterial;
  });
}

// A step with several isovalues has a surface each: a GLB node with extras
// {"ldimesh_surface": s} (three.js: userData), surface s for the step's isovalues[s]. A
// checkbox each shows or hides it; what the person chose holds from step to step, by isovalue
// (a step with other isovalues keeps the choice for those it shares).
// document.body.dataset.surfaces: the number of surfaces of the step shown.
const hiddenIsovalues = new Set();

function surfaceNodes(root) {
  const nodes = [];
  root.traverse((object) => {
    const surface = object.userData && object.userData.ldimesh_surface;
    if (Number.isInteger(surface)) nodes.push([surface, object]);
  });
  return nodes;
}

function applySurfaces(root, meta) {
  const isovalues = (meta && meta.isovalues) || [];
  for (const [surface, node] of surfaceNodes(root))
    node.visible = !hiddenIsovalues.has(String(isovalues[surface]));
  requestRender();
}

function updateSurfaceControls(meta) {
  const box = $('surfaces');
  const isovalues = (meta && meta.isovalues) || [];
  if (isovalues.length < 2) {
    box.hidden = true;
    return;
  }
  const key = isovalues.join(' ');
  if (box.dataset.key !== key) {
    box.replaceChildren();
    isovalues.forEach((value, surface) => {
      const input = document.createElement('input');
      input.type = 'checkbox';
      input.id = `surface-${surface}`;
      input.checked = !hiddenIsovalues.has(String(value));
      input.addEventListener('change', () => {
        if (input.checked) hiddenIsovalues.delete(String(value));
        else hiddenIsovalues.add(String(value));
        if (state.mesh) applySurfaces(state.mesh, state.loaded);
      });
      const label = document.createElement('label');
      label.append(input, ` isovalue ${value}`);
      box.append(label);
    });
    box.dataset.key = key;
  }
  box.hidden = false;
}

function countTriangles(root) {
  let n = 0;
  root.traverse((object) => {
    if (!object.isMesh) return;
    const g = object.geometry;
    n += (g.index ? g.index.count : g.attributes.position.count) / 3;
  });
  return n;
}

// The camera is framed by the page until the person moves it (a drag, the wheel or a touch that
// moves it): it frames the union of the bounds of the steps shown so far, and is framed anew
// only when a step's surface leaves those bounds, so a growing surface stays in view and the
// camera does not jump with every step. Once the person has moved the camera it stays where
// they put it; "reset camera" frames the step shown and hands the camera back to the page.
// document.body.dataset.camera: "framed" or "user".
const framing = { byUser: false, interacting: false, bounds: null };
controls.addEventListener('start', () => { framing.interacting = true; });
controls.addEventListener('end', () => { framing.interacting = false; });
controls.addEventListener('change', () => {
  if (!framing.interacting || framing.byUser) return;
  framing.byUser = true;
  document.body.dataset.camera = 'user';
});
document.body.dataset.camera = 'framed';

function frame(box) {
  const sphere = box.getBoundingSphere(new THREE.Sphere());
  if (!(sphere.radius > 0)) return;
  controls.target.copy(sphere.center);
  const distance = sphere.radius / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2));
  camera.position.copy(sphere.center).add(new THREE.Vector3(0.55, 0.45, 0.7).normalize().multiplyScalar(distance));
  camera.near = distance / 100;
  camera.far = distance * 10;
  camera.updateProjectionMatrix();
  requestRender();
}

function frameShown(reset) {
  if (!state.mesh) return;
  const box = new THREE.Box3().setFromObject(state.mesh);
  if (box.isEmpty()) return;
  if (reset) {
    framing.byUser = false;
    framing.bounds = null;
    document.body.dataset.camera = 'framed';
  }
  if (framing.byUser || (framing.bounds && framing.bounds.containsBox(box))) return;
  framing.bounds = framing.bounds ? framing.bounds.union(box) : box;
  frame(framing.bounds);
}

async function loadStep(step) {
  setStatus(`loading step ${step}…`);
  const [meta, response] = await Promise.all([
    json(`/api/v1/steps/${step}`), api(`/api/v1/steps/${step}/mesh.glb`)]);
  if (!response.ok) throw new Error(`mesh of step ${step}: HTTP ${response.status}`);
  const buffer = await response.arrayBuffer();
  const gltf = await parseGlb(buffer, step);
  if (state.mesh) {
    scene.remove(state.mesh);
    state.mesh.traverse((o) => o.isMesh && o.geometry.dispose());
  }
  state.mesh = gltf.scene;
  state.loaded = meta;
  updateFieldControls(meta);
  applyColouring(state.mesh, meta);
  updateSurfaceControls(meta);
  applySurfaces(state.mesh, meta);
  document.body.dataset.surfaces = String(surfaceNodes(state.mesh).length);
  scene.add(state.mesh);
  frameShown(false);
  requestRender();
  const triangles = countTriangles(state.mesh);
  showMetadata(meta, triangles);
  syncSlider();
  document.body.dataset.loadedStep = String(meta.step);
  showLag();
  document.body.dataset.triangles = String(triangles);
  setStatus($('follow').checked ? `step ${meta.step} (following)` : `step ${meta.step}`);
}

// At most one load is in flight, and every load that starts is shown. While one runs, only the
// step to show next is remembered (state.next: the newest announced one when following, else
// the slider's), each request replacing the previous; when the load finishes or fails, that
// step is loaded unless it is the one shown. So however fast the job publishes, the page shows
// a new step each time a load completes (a load abandoned for every newer step would never
// finish on a slow link), and nothing is downloaded that will not be shown: no download is ever
// abandoned, so there is none to cancel (no AbortController).
function show(step) {
  if (state.loading === null && state.loaded && state.loaded.step === step) return;
  if (state.loading !== null) {
    state.next = step;
    return;
  }
  state.next = null;
  state.loading = step;
  loadStep(step).catch((e) => {
    setStatus(e.message, true);
    setPlaying(false);  // a step that cannot be shown (evicted since listed): play stops there
  }).finally(() => {
    state.loading = null;
    const next = state.next;
    state.next = null;
    if (next !== null && !(state.loaded && state.loaded.step === next)) show(next);
  });
}

// The newest step shown, being loaded or to be loaded (-Infinity before the first).
function newestWanted() {
  return Math.max(state.loaded ? state.loaded.step : -Infinity, state.loading ?? -Infinity,
    state.next ?? -Infinity);
}

// ---------------------------------------------------------------------------------------------
// Steps: the slider over the stored ones, following the newest

function syncSlider() {
  const slider = $('slider');
  slider.max = String(Math.max(state.steps.length - 1, 0));
  slider.disabled = state.steps.length < 2;
  // The slider follows the step shown while following; otherwise it is the person's.
  const at = state.loaded ? state.steps.indexOf(state.loaded.step) : -1;
  if (at >= 0 && ($('follow').checked || player.playing)) slider.value = String(at);
  $('slider-step').textContent = state.loaded ? `#${state.loaded.step}` : '';
}

function addStep(meta) {
  if (!state.steps.includes(meta.step)) state.steps.push(meta.step);
  state.steps.sort((a, b) => a - b);
  syncSlider();
  showLag();
}

// How far the picture is behind the job: kept steps newer than the one shown, and the time
// since the job last published (document.body.dataset.behind: the first, for tests).
const lag = { lastPublished: null };
function showLag() {
  if (!state.loaded || !state.steps.length) return;
  const behind = state.steps.filter((s) => s > state.loaded.step).length;
  const newest = state.steps[state.steps.length - 1];
  const ago = lag.lastPublished === null ? '' :
    `; last step ${Math.round((Date.now() - lag.lastPublished) / 1000)} s ago`;
  $('lag').textContent = (behind ? `behind by ${behind} step${behind > 1 ? 's' : ''} (newest ${newest})`
    : 'showing the newest step') + ago;
  document.body.dataset.behind = String(behind);
}
setInterval(showLag, 1000);

// Play: the kept steps one after another, from the one shown to the newest, each as soon as the
// one before is shown and half a second has passed; then it stops.
const player = { playing: false, timer: null };
function setPlaying(on) {
  player.playing = on;
  $('play').textContent = on ? 'pause' : 'play';
  document.body.dataset.playing = String(on);
  clearInterval(player.timer);
  if (!on) return;
  $('follow').checked = false;
  player.timer = setInterval(() => {
    if (state.loading !== null || state.next !== null || !state.loaded) return;
    const at = state.steps.indexOf(state.loaded.step);
    if (at < 0 || at + 1 >= state.steps.length) return setPlaying(false);
    show(state.steps[at + 1]);
  }, 500);
}
$('play').addEventListener('click', async () => {
  if (player.playing) return setPlaying(false);
  if (state.loaded && state.steps.indexOf(state.loaded.step) === state.steps.length - 1) {
    // At the newest: from the oldest step the server still keeps (older ones were evicted).
    try {
      const list = await json('/api/v1/steps');
      state.steps = (list.steps || []).map((m) => m.step).sort((a, b) => a - b);
      syncSlider();
    } catch (e) {
      return setStatus(e.message, true);
    }
    if (state.steps.length) show(state.steps[0]);
  }
  setPlaying(true);
});

// The picture as a PNG, with the legend drawn in where it shows.
$('screenshot').addEventListener('click', () => {
  renderer.render(scene, camera);
  const out = document.createElement('canvas');
  out.width = canvas.width;
  out.height = canvas.height;
  const ctx = out.getContext('2d');
  ctx.drawImage(canvas, 0, 0);
  if (!$('legend').hidden) {
    // A row per field, top to bottom as the page shows them.
    const rows = legendRows();
    rows.forEach((row, k) => {
      const bar = row.bar, x = out.width - bar.width - 20, y = out.height - 50 - 70 * (rows.length - 1 - k);
      ctx.fillStyle = 'rgba(20, 22, 27, 0.85)';
      ctx.fillRect(x - 10, y - 26, bar.width + 20, 70);
      ctx.fillStyle = '#e8e8e8';
      ctx.font = '13px system-ui, sans-serif';
      ctx.fillText(row.name, x, y - 8);
      ctx.drawImage(bar, x, y);
      ctx.fillText(row.min, x, y + bar.height + 16);
      ctx.fillText(row.max, x + bar.width - ctx.measureText(row.max).width, y + bar.height + 16);
    });
  }
  out.toBlob((blob) => {
    const link = document.createElement('a');
    link.href = URL.createObjectURL(blob);
    link.download = `ldimesh_step_${state.loaded ? state.loaded.step : 0}.png`;
    link.click();
    setTimeout(() => URL.revokeObjectURL(link.href), 10000);
  }, 'image/png');
});

$('slider').addEventListener('input', () => {
  $('follow').checked = false;
  setPlaying(false);
  show(state.steps[Number($('slider').value)]);
});
$('follow').addEventListener('change', () => {
  if ($('follow').checked) setPlaying(false);
  if ($('follow').checked && state.steps.length) show(state.steps[state.steps.length - 1]);
});
// A change of colouring, colour map or range recolours the step shown.
function recolour() {
  updateFieldControls(state.loaded);
  if (!state.mesh) return;
  applyColouring(state.mesh, state.loaded);
  requestRender();
}
$('colour').addEventListener('change', () => {
  colouring.chosenByPerson = true;
  recolour();
});
$('colourmap').addEventListener('change', recolour);
$('range-auto').addEventListener('change', () => {
  $('range-min').disabled = $('range-max').disabled = $('range-auto').checked;
  recolour();
});
for (const id of ['range-min', 'range-max']) $(id).addEventListener('change', recolour);
$('reset').addEventListener('click', () => frameShown(true));

function listen() {
  // Server-sent events: the newest step first, then each new one. EventSource reconnects by
  // itself after a dropped connection.
  const events = new EventSource(`/api/v1/events?token=${encodeURIComponent(token)}`);
  events.addEventListener('step', (event) => {
    const meta = JSON.parse(event.data);
    // (a reconnect announces the newest step again: not a new one)
    if (!state.steps.includes(meta.step)) lag.lastPublished = Date.now();
    addStep(meta);
    if ($('follow').checked && meta.step > newestWanted()) show(meta.step);
  });
  events.onerror = () => {
    if (!state.loaded) setStatus('waiting for the job…');
  };
}

async function start() {
  if (!token) {
    setStatus('no token in the URL: open the URL the job printed (…/?token=…)', true);
    return;
  }
  try {
    const list = await json('/api/v1/steps');
    for (const meta of list.steps || []) addStep(meta);
    if (state.steps.length) show(state.steps[state.steps.length - 1]);
    else setStatus('waiting for the first step…');
  } catch (e) {
    setStatus(e.message, true);
    if (e.message.startsWith('the server refused')) return;
  }
  listen();
}

start();
