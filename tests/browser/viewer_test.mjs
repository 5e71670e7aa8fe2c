// Browser test of the viewer: Debian's chromium, driven by playwright-core, opens the page a
// test publisher serves (real server, real Draco GLB meshes), and checks what a person sees:
// the mesh of step 1 loads (the page's triangle count equals the published one), the canvas
// is not blank, and the view follows to step 2 when it is published. Then:
// - steps published faster than the page can load them (every mesh download held back 1.5 s,
//   a step every 0.3 s): the page still shows newer steps every few seconds, and downloads only
//   meshes it shows;
// - the page draws only when something changes: no frames while nothing happens (counted from
//   the WebGL clears and the page's own counter), frames when the camera is dragged, the
//   colouring changed;
// - the camera keeps the surface in view (no mesh pixels on the canvas's edges, the bounding
//   box of the mesh shown projects inside the view) and re-frames for a surface that outgrows
//   what it framed, until the person moves it: then it stays put; "reset camera" frames again;
// - the slider shows an older step, "follow" goes back to the newest; the panel says how many
//   kept steps are newer than the one shown; "play" shows the newer ones in turn and stops; the
//   screenshot button downloads a PNG;
// - colouring by the field (each vertex's x): chosen by itself for a step that carries
//   one, the canvas shows the colour map's colours (viridis' purple, not cool–warm's red, and
//   the other way round after switching maps), the legend names the field and shows the step's
//   range; a fixed range above every value paints the whole surface in the map's lowest colour;
// - a mesh whose decode runs past its limit (set to 0 s for the test) is stopped and reported,
//   and the next step shows;
// - no request is answered with an error (favicon included), no three.js interleaved-attribute
//   warning in the console.
// Screenshots are kept.
//
//   node tests/browser/viewer_test.mjs PUBLISHER REPO_ROOT ARTIFACT_DIR
import { spawn } from 'node:child_process';
import { mkdirSync, readFileSync } from 'node:fs';
import { createInterface } from 'node:readline';
import { chromium } from 'playwright-core';

const [publisherPath, repoRoot, artifacts] = process.argv.slice(2);
mkdirSync(artifacts, { recursive: true });
let failures = 0, passes = 0;
function check(ok, what) {
  if (ok) { passes++; console.log(`ok   ${what}`); } else { failures++; console.log(`FAIL ${what}`); }
}

const publisher = spawn(publisherPath, [repoRoot], { stdio: ['pipe', 'pipe', 'inherit'] });
const lines = createInterface({ input: publisher.stdout });
const waiting = [];
lines.on('line', (line) => { const w = waiting.shift(); if (w) w(line); });
const nextLine = () => new Promise((resolve, reject) => {
  const timer = setTimeout(() => reject(new Error('the publisher did not answer in 60 s')), 60000);
  waiting.push((line) => { clearTimeout(timer); resolve(line); });
});
const published = (line) => { const [, step, triangles] = line.split(' '); return { step, triangles: Number(triangles) }; };
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
const publishNext = async () => { publisher.stdin.write('next\n'); return published(await nextLine()); };

// Before the page's scripts: count the WebGL clears (one per frame three.js draws) and note when
// the page shows each step (body's data-loaded-step), with the time.
function instrument() {
  window.testGlClears = 0;
  for (const gl of [window.WebGLRenderingContext, window.WebGL2RenderingContext]) {
    const clear = gl.prototype.clear;
    gl.prototype.clear = function (...args) { window.testGlClears++; return clear.apply(this, args); };
  }
  window.testShown = [];
  new MutationObserver(() => {
    const step = document.body.dataset.loadedStep;
    const last = window.testShown[window.testShown.length - 1];
    if (step !== undefined && (!last || last.step !== Number(step))) window.testShown.push({ step: Number(step), t: Date.now() });
  }).observe(document, { subtree: true, attributes: true, attributeFilter: ['data-loaded-step'] });
  // The canvas's RGBA bytes, row by row.
  window.testCanvasPixels = () => {
    const gl = document.getElementById('view');
    const copy = document.createElement('canvas');
    copy.width = gl.width; copy.height = gl.height;
    const ctx = copy.getContext('2d');
    ctx.drawImage(gl, 0, 0);
    return { width: copy.width, height: copy.height, data: ctx.getImageData(0, 0, copy.width, copy.height).data };
  };
  // The canvas's pixels that differ from the background #1d2026 (where the mesh shows), row by
  // row: { width, height, mesh } with mesh[y * width + x] true there.
  window.testMeshPixels = () => {
    const { width, height, data: d } = window.testCanvasPixels();
    const mesh = new Array(d.length / 4);
    for (let i = 0; i < d.length; i += 4)
      mesh[i / 4] = Math.abs(d[i] - 0x1d) + Math.abs(d[i + 1] - 0x20) + Math.abs(d[i + 2] - 0x26) > 24;
    return { width, height, mesh };
  };
  // Mesh pixels by hue: viridis' purple end and cool–warm's red end, which the other map does
  // not produce.
  window.testColourCounts = () => {
    const d = window.testCanvasPixels().data;
    let mesh = 0, purple = 0, red = 0, green = 0, blue = 0, grey = 0;
    for (let i = 0; i < d.length; i += 4) {
      const [r, g, b] = [d[i], d[i + 1], d[i + 2]];
      if (Math.abs(r - 0x1d) + Math.abs(g - 0x20) + Math.abs(b - 0x26) <= 24) continue;
      mesh++;
      // By hue (degrees) and saturation, which lighting changes little: viridis' low end
      // sRGB (68, 1, 84) has hue 288, cool–warm's high end (180, 4, 38) 348, its low end 232;
      // viridis passes from 288 down through blue and green to yellow (55), never red;
      // cool–warm's hues stay near 232 and 348–20 (its middle is grey), never green.
      const max = Math.max(r, g, b), min = Math.min(r, g, b);
      // Grey: the plain colour (sRGB b8c4d6), lit; viridis and cool–warm are saturated but for
      // cool–warm's middle.
      if (max >= 48 && max - min < 0.25 * max) grey++;
      if (max < 16 || max - min < 0.25 * max) continue;
      let hue = max === r ? (g - b) / (max - min) : max === g ? 2 + (b - r) / (max - min) : 4 + (r - g) / (max - min);
      hue = (60 * hue + 360) % 360;
      if (hue >= 260 && hue <= 320) purple++;
      if (hue >= 330 || hue <= 15) red++;
      if (hue >= 70 && hue <= 180) green++;
      if (hue >= 190 && hue <= 250) blue++;
    }
    return { mesh, purple, red, green, blue, grey };
  };
}

let browser;
const timeout = setTimeout(() => { console.log('FAIL the test took over 4 minutes'); process.exit(1); }, 240000);
try {
  const url = (await nextLine()).replace(/^url /, '');
  const first = published(await nextLine());
  browser = await chromium.launch({
    executablePath: '/usr/bin/chromium',
    args: ['--headless', '--no-sandbox', '--enable-unsafe-swiftshader', '--use-angle=swiftshader',
      '--disable-background-networking', '--disable-component-update', '--no-first-run'],
  });
  const page = await browser.newPage({ viewport: { width: 960, height: 640 } });
  const pageErrors = [];
  page.on('pageerror', (e) => { pageErrors.push(e.message); console.log(`page error: ${e.message}`); });
  const consoleMessages = [], httpErrors = [], meshRequests = [];
  page.on('console', (m) => {
    consoleMessages.push(`${m.type()}: ${m.text()}`);
    if (m.type() === 'warning' || m.type() === 'error') console.log(`       console ${m.type()}: ${m.text()}`);
  });
  page.on('response', (r) => { if (r.status() >= 400) httpErrors.push(`${r.status()} ${r.url()}`); });
  page.on('requestfailed', (r) => httpErrors.push(`failed (${r.failure()?.errorText}) ${r.url()}`));
  page.on('request', (r) => {
    const m = /\/api\/v1\/steps\/(\d+)\/mesh\.glb/.exec(r.url());
    if (m) meshRequests.push({ step: Number(m[1]), t: Date.now() });
  });
  await page.addInitScript(instrument);
  const loadedStep = () => page.evaluate(() => Number(document.body.dataset.loadedStep));
  const waitForStep = (step, ms = 60000) =>
    page.waitForFunction((s) => document.body.dataset.loadedStep === String(s), step, { timeout: ms });
  const counters = () => page.evaluate(() => ({ gl: window.testGlClears, page: Number(document.body.dataset.renders) }));
  // Waits until the page has drawn nothing for 600 ms (the camera's damping settled); false
  // after `ms`.
  const settle = async (ms) => {
    const end = Date.now() + ms;
    for (let last = null; Date.now() < end; await sleep(600)) {
      const now = (await counters()).gl;
      if (now === last) return true;
      last = now;
    }
    return false;
  };
  // Whether the shown mesh is in view, read in an animation frame after the page's own (which
  // places the camera and draws): the pixels along the canvas's edges that differ from the
  // background (a surface cut off by the edges shows there) and how far the corners of the
  // mesh's bounding box project from the canvas centre (> 1: outside the view).
  const inView = () => page.evaluate(() => new Promise((resolve) => requestAnimationFrame(async () => {
    const { width, height, mesh: shown } = window.testMeshPixels();
    let edge = 0;
    for (let y = 0; y < height; ++y) for (let x = 0; x < width; ++x) {
      if (y > 0 && y < height - 1 && x > 0 && x < width - 1) continue;
      if (shown[y * width + x]) edge++;
    }
    const THREE = await import('/vendor/three/build/three.module.js');
    const { camera, mesh } = window.ldimesh;
    let box = Infinity;
    if (camera && mesh) {
      camera.updateMatrixWorld();
      const b = new THREE.Box3().setFromObject(mesh);
      box = 0;
      for (const x of [b.min.x, b.max.x]) for (const y of [b.min.y, b.max.y]) for (const z of [b.min.z, b.max.z]) {
        const p = new THREE.Vector3(x, y, z).project(camera);
        box = Math.max(box, Math.abs(p.x), Math.abs(p.y), Math.abs(p.z));
      }
    }
    resolve({ edge, box, ok: edge === 0 && box <= 1,
      text: `${edge} mesh pixels on the canvas's edges, bounding box within ${box.toFixed(2)} of the view` });
  })));
  const cameraPosition = () => page.evaluate(() => window.ldimesh.camera ? window.ldimesh.camera.position.toArray() : null);
  const distance = (a, b) => (a && b ? Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]) : Infinity);
  const cameraMode = () => page.evaluate(() => document.body.dataset.camera);
  await page.goto(url);
  await page.waitForFunction((s) => document.body.dataset.loadedStep === s, first.step, { timeout: 60000 });
  const triangles = await page.evaluate(() => Number(document.body.dataset.triangles));
  check(triangles === first.triangles, `step 1: the page shows ${triangles} triangles, ${first.triangles} were published`);

  await page.waitForTimeout(500);  // a few frames
  const drawn = await page.evaluate(() => {
    const { mesh: shown } = window.testMeshPixels();
    return shown.filter(Boolean).length / shown.length;
  });
  check(drawn > 0.03, `the canvas is not blank (${(100 * drawn).toFixed(1)} % of its pixels show the mesh)`);
  await page.screenshot({ path: `${artifacts}/viewer_step1.png` });

  // Colour by the field: chosen by itself, the colour map on the canvas, the legend.
  const field = await page.evaluate(() => window.ldimesh.loaded.scalar);
  const legend = () => page.evaluate(() => ({
    hidden: document.getElementById('legend').hidden,
    name: document.getElementById('legend-name').textContent,
    min: document.getElementById('legend-min').textContent,
    max: document.getElementById('legend-max').textContent,
  }));
  const colours = async () => { await settle(10000); return page.evaluate(() => window.testColourCounts()); };
  check(field && field.name === 'x' && field.min < field.max, `step 1 carries a field to colour by: ${JSON.stringify(field)}`);
  check(await page.evaluate(() => document.getElementById('colour').value) === 'scalar', 'colouring by the field is chosen by itself');
  let shownLegend = await legend();
  check(!shownLegend.hidden && shownLegend.name === 'x' && shownLegend.min === Number(field.min).toPrecision(4) &&
    shownLegend.max === Number(field.max).toPrecision(4), `the legend names the field and its range: ${JSON.stringify(shownLegend)}`);
  let counts = await colours();
  check(counts.green > 0.2 * counts.mesh && counts.purple > 0.002 * counts.mesh && counts.red === 0,
    `viridis on the canvas: ${counts.green} green, ${counts.purple} purple, ${counts.red} red of ${counts.mesh} mesh pixels`);
  await page.selectOption('#colourmap', 'coolwarm');
  counts = await colours();
  check(counts.red > 0.05 * counts.mesh && counts.purple === 0 && counts.green === 0,
    `cool–warm on the canvas: ${counts.red} red, ${counts.purple} purple, ${counts.green} green of ${counts.mesh} mesh pixels`);
  await page.screenshot({ path: `${artifacts}/viewer_coolwarm.png` });
  await page.selectOption('#colourmap', 'viridis');
  // A fixed range above every value: the whole surface in viridis' lowest colour.
  const above = [field.max + 1, field.max + 2];
  await page.click('#range-auto');
  await page.fill('#range-min', String(above[0]));
  await page.fill('#range-max', String(above[1]));
  await page.dispatchEvent('#range-max', 'change');
  counts = await colours();
  shownLegend = await legend();
  check(counts.purple > 0.8 * counts.mesh && shownLegend.min === Number(above[0]).toPrecision(4),
    `a fixed range above every value: ${counts.purple} of ${counts.mesh} mesh pixels purple, legend from ${shownLegend.min}`);
  await page.click('#range-auto');
  shownLegend = await legend();
  check(shownLegend.min === Number(field.min).toPrecision(4), `back to the step's range: legend from ${shownLegend.min}`);

  publisher.stdin.write('next\n');
  const second = published(await nextLine());
  await page.waitForFunction((s) => document.body.dataset.loadedStep === s, second.step, { timeout: 60000 });
  const triangles2 = await page.evaluate(() => Number(document.body.dataset.triangles));
  check(triangles2 === second.triangles, `step 2 followed: ${triangles2} triangles shown, ${second.triangles} published`);
  const panel = await page.evaluate(() => document.getElementById('step').textContent);
  check(panel === second.step, `the panel shows step ${panel}`);
  await page.waitForTimeout(300);
  await page.screenshot({ path: `${artifacts}/viewer_step2.png` });
  let view = await inView();
  check(view.ok, `step 2 is in view (${view.text})`);

  // A surface that outgrows the ones before (step 3: the Klein bottle) is framed anew.
  const grown = await publishNext();
  await waitForStep(grown.step);
  view = await inView();
  check(view.ok, `step ${grown.step}, larger than steps 1 and 2, is in view (${view.text})`);

  // Nothing happens: nothing is drawn.
  await settle(10000);
  let before = await counters();
  await sleep(2000);
  let after = await counters();
  check(after.gl - before.gl <= 1 && after.page - before.page <= 1,
    `no frames drawn while nothing changes: ${after.gl - before.gl} WebGL clears, ${after.page - before.page} renders counted by the page in 2 s`);

  // Steps published faster than the page can load them: each mesh download is held back 1.5 s,
  // a step is published every 0.3 s for 9 s. The page shows a newer step within 4 s, then
  // again at least every 4 s, and downloads only meshes it shows.
  await page.route('**/mesh.glb', async (route) => { await sleep(1500); await route.continue(); });
  const burstStart = Date.now(), fromStep = Number(grown.step);
  let last;
  for (let i = 1; i <= 30; ++i) {
    last = await publishNext();
    await sleep(burstStart + 300 * i - Date.now());
  }
  const burstEnd = Date.now();
  await waitForStep(last.step, 15000).catch(() => {});
  const lastShownAt = Date.now();
  const shown = (await page.evaluate(() => window.testShown)).filter((s) => s.t >= burstStart);
  const during = shown.filter((s) => s.t <= burstEnd);
  const times = [burstStart, ...during.map((s) => s.t), burstEnd];
  const gaps = times.slice(1).map((t, i) => t - times[i]);
  console.log(`       steps ${fromStep + 1}–${last.step} published in ${((burstEnd - burstStart) / 1000).toFixed(1)} s; shown: ` +
    shown.map((s) => `${s.step} at ${((s.t - burstStart) / 1000).toFixed(1)} s`).join(', '));
  check(during.length >= 3 && during.every((s, i) => s.step > (i ? during[i - 1].step : fromStep)),
    `steps published faster than they download: the page showed ${during.length} newer steps while they were published (≥ 3)`);
  check(Math.max(...gaps) < 4000, `… a newer step at least every 4 s (longest wait ${(Math.max(...gaps) / 1000).toFixed(1)} s)`);
  check(await loadedStep() === Number(last.step),
    `… and the newest, step ${last.step}, ${(lastShownAt - burstEnd) / 1000} s after it was published`);
  const wasted = meshRequests.filter((r) => r.t >= burstStart && !shown.some((s) => s.step === r.step)).map((r) => r.step);
  check(wasted.length === 0, `… downloading only meshes it shows (${meshRequests.filter((r) => r.t >= burstStart).length} downloads; not shown: ${wasted.join(', ') || 'none'})`);
  await page.unroute('**/mesh.glb');
  view = await inView();
  check(view.ok, `step ${last.step} is in view (${view.text})`);

  // The camera: "reset camera" frames the step shown (the torus); the next surface (the Barth
  // sextic) outgrows it and is framed anew; once the person drags the camera it stays put, also
  // for the next (the Klein bottle, larger again).
  await page.click('#reset');
  view = await inView();
  check(view.ok && await cameraMode() === 'framed', `after "reset camera" the camera is framed (${view.text})`);
  let position = await cameraPosition();
  const third = await publishNext();
  await waitForStep(third.step);
  view = await inView();
  const moved = distance(position, await cameraPosition());
  check(view.ok && moved > 0.1, `step ${third.step}, larger, is framed anew: in view (${view.text}), the camera moved by ${moved.toFixed(2)}`);
  await settle(10000);
  before = await counters();
  await page.mouse.move(600, 320);
  await page.mouse.down();
  await page.mouse.move(700, 360, { steps: 10 });
  await page.mouse.up();
  const settled = await settle(30000);
  after = await counters();
  check(after.page - before.page >= 5 && await cameraMode() === 'user' && settled,
    `dragging the camera draws frames (${after.page - before.page}), then stops (${settled}); the camera is the person's: ${await cameraMode()}`);
  position = await cameraPosition();
  const fourth = await publishNext();
  await waitForStep(fourth.step);
  await settle(10000);
  // (up to the last, imperceptible steps of OrbitControls' damping, applied when a frame is
  // drawn: within 1 % of the camera's distance; framing anew would move it by far more)
  const shift = distance(position, await cameraPosition());
  check(shift < 0.01 * distance(position, [0, 0, 0]),
    `step ${fourth.step}, larger again, leaves the person's camera where it was (moved by ${shift.toExponential(1)})`);
  await page.screenshot({ path: `${artifacts}/viewer_user_camera.png` });
  await page.click('#reset');
  view = await inView();
  check(view.ok && await cameraMode() === 'framed', `"reset camera" frames step ${fourth.step} again (${view.text})`);

  // Another colouring is drawn (one frame or two, not a loop).
  await settle(10000);
  before = await counters();
  await page.selectOption('#colour', 'plain');
  await sleep(500);
  after = await counters();
  await page.selectOption('#colour', 'view');
  check(after.page - before.page >= 1 && after.page - before.page <= 3, `a change of colouring is drawn (${after.page - before.page} frames)`);

  // The slider shows an older stored step, "follow" the newest again.
  const older = await page.evaluate(() => {
    const slider = document.getElementById('slider');
    slider.value = String(Number(slider.max) - 2);
    slider.dispatchEvent(new Event('input'));
    return window.ldimesh.steps[Number(slider.value)];
  });
  await waitForStep(older, 15000).catch(() => {});
  let status = await page.evaluate(() => document.body.dataset.status);
  check(await loadedStep() === older && status === `step ${older}`, `the slider shows step ${older}: "${status}"`);
  await page.click('#follow');
  await waitForStep(fourth.step, 15000).catch(() => {});
  status = await page.evaluate(() => document.body.dataset.status);
  check(await loadedStep() === Number(fourth.step) && status === `step ${fourth.step} (following)`, `"follow" goes back to step ${fourth.step}: "${status}"`);

  // How far behind the picture is: none while following the newest step.
  let lagText = await page.evaluate(() => [document.body.dataset.behind, document.getElementById('lag').textContent]);
  check(lagText[0] === '0' && lagText[1].startsWith('showing the newest step'), `following: "${lagText[1]}"`);
  // Play: from an older kept step, each kept step after it in turn up to the newest, then it stops.
  const kept = await page.evaluate(() => window.ldimesh.steps.slice());
  const from = kept[kept.length - 4];
  await page.evaluate((step) => {
    const slider = document.getElementById('slider');
    slider.value = String(window.ldimesh.steps.indexOf(step));
    slider.dispatchEvent(new Event('input'));
  }, from);
  await waitForStep(from, 15000).catch(() => {});
  lagText = await page.evaluate(() => [document.body.dataset.behind, document.getElementById('lag').textContent]);
  check(lagText[0] === '3' && lagText[1].startsWith('behind by 3 steps'), `step ${from} shown: "${lagText[1]}"`);
  const playStart = Date.now();
  await page.click('#play');
  await page.waitForFunction((s) => document.body.dataset.loadedStep === String(s) &&
    document.body.dataset.playing === 'false', kept[kept.length - 1], { timeout: 30000 }).catch(() => {});
  const played = (await page.evaluate(() => window.testShown)).filter((s) => s.t >= playStart).map((s) => s.step);
  const stopped = await page.evaluate(() => document.body.dataset.playing === 'false' &&
    document.getElementById('play').textContent === 'play');
  check(JSON.stringify(played) === JSON.stringify(kept.slice(-3)) && stopped,
    `play shows the kept steps after ${from} in turn, then stops: ${played.join(', ')} (kept: ${kept.slice(-3).join(', ')})`);
  // Screenshot: a PNG of the canvas, downloaded.
  const [download] = await Promise.all([page.waitForEvent('download', { timeout: 15000 }), page.click('#screenshot')]);
  const png = readFileSync(await download.path());
  check(png.length > 10000 && png.subarray(1, 4).toString() === 'PNG' && download.suggestedFilename() === `ldimesh_step_${kept[kept.length - 1]}.png`,
    `the screenshot button saves ${download.suggestedFilename()} (${png.length} bytes of PNG)`);

  // Several isovalues: a surface each (two concentric spheres, r = 1 and 0.6), each shown or
  // hidden by its checkbox; the choice holds for the next step.
  if (!(await page.isChecked('#follow'))) await page.click('#follow');
  const meshPixels = async () => {
    await page.waitForTimeout(400);  // a frame or more
    return page.evaluate(() => window.testMeshPixels().mesh.filter(Boolean).length);
  };
  publisher.stdin.write('nested\n');
  const nested = published(await nextLine());
  await waitForStep(nested.step, 30000).catch(() => {});
  const shownSurfaces = await page.evaluate(() => ({
    nodes: document.body.dataset.surfaces,
    boxes: [...document.querySelectorAll('#surfaces input')].map((i) => i.parentElement.textContent.trim()),
    triangles: Number(document.body.dataset.triangles),
  }));
  check(await loadedStep() === Number(nested.step) && shownSurfaces.nodes === '2' &&
    shownSurfaces.boxes.join(', ') === 'isovalue 1, isovalue 0.36' && shownSurfaces.triangles === nested.triangles,
    `two isovalues: ${shownSurfaces.nodes} surfaces, checkboxes "${shownSurfaces.boxes.join('", "')}", ${shownSurfaces.triangles} triangles (${nested.triangles} published)`);
  const both = await meshPixels();
  await page.click('#surface-0');  // the outer sphere hidden: the inner one shows, smaller
  const inner = await meshPixels();
  await page.click('#surface-1');  // both hidden
  const none = await meshPixels();
  await page.click('#surface-0');  // the outer one again
  const outer = await meshPixels();
  check(both > 2000 && inner > 0.15 * both && inner < 0.6 * both && none === 0 && Math.abs(outer - both) <= 0.02 * both,
    `the checkboxes show and hide each surface: both ${both} mesh pixels, the inner alone ${inner}, none ${none}, the outer alone ${outer}`);
  await page.click('#surface-0');  // both hidden again: the next step keeps them hidden
  publisher.stdin.write('nested\n');
  const nestedAgain = published(await nextLine());
  await waitForStep(nestedAgain.step, 30000).catch(() => {});
  const stillHidden = [await loadedStep(), await meshPixels(), await page.isChecked('#surface-0'), await page.isChecked('#surface-1')];
  check(stillHidden[0] === Number(nestedAgain.step) && stillHidden[1] === 0 && !stillHidden[2] && !stillHidden[3],
    `the next step (${stillHidden[0]}) keeps both surfaces hidden: ${stillHidden[1]} mesh pixels`);
  await page.click('#surface-0');
  await page.click('#surface-1');

  // Each surface its own colour field (the adaptor's "colour_by" per isovalue): the outer sphere
  // without one shows plain while colouring by field, the inner one (by T = 300 + 100·x) takes the
  // colour map over its own range; two fields give the legend a row each.
  await page.selectOption('#colour', 'scalar');
  const legendRows = () => page.evaluate(() => {
    const rows = [[document.getElementById('legend-name'), document.getElementById('legend-min'),
      document.getElementById('legend-max')]];
    for (const row of document.getElementById('legend-more').children)
      rows.push([row.querySelector('.legend-name'), row.querySelector('.legend-min'), row.querySelector('.legend-max')]);
    return document.getElementById('legend').hidden ? [] : rows.map((r) => r.map((e) => e.textContent));
  });
  const rowOf = (f) => [f.name, Number(f.min).toPrecision(4), Number(f.max).toPrecision(4)];
  for (const [command, outerField] of [['nested-colours', null], ['nested-fields', 'x']]) {
    publisher.stdin.write(`${command}\n`);
    const coloured = published(await nextLine());
    await waitForStep(coloured.step, 30000).catch(() => {});
    const fields = await page.evaluate(() => window.ldimesh.loaded.surface_scalars);
    const rows = await legendRows();
    const expected = [fields[0], fields[1]].filter(Boolean).map(rowOf);
    check(await loadedStep() === Number(coloured.step) && Array.isArray(fields) &&
      (fields[0] ? fields[0].name : null) === outerField && fields[1].name === 'T' && fields[1].min > 200 &&
      JSON.stringify(rows) === JSON.stringify(expected),
      `${command}: surface fields ${JSON.stringify(fields)}, legend rows ${JSON.stringify(rows)}`);
    const both = await colours();
    if (!outerField)
      check(both.grey > 0.8 * both.mesh && both.green + both.purple < 0.02 * both.mesh,
        `${command}: the outer sphere, without a field, shows plain (${both.grey} grey, ${both.green} green, ${both.purple} purple of ${both.mesh} mesh pixels)`);
    await page.click('#surface-0');  // the inner sphere alone, over its own range
    const inner = await colours();
    // (Over another range, x's, every T would be past its top: all yellow.)
    check(inner.green > 0.2 * inner.mesh && inner.blue > 0.05 * inner.mesh && inner.grey < 0.05 * inner.mesh,
      `${command}: the inner sphere in viridis over T's range (${inner.green} green, ${inner.blue} blue, ${inner.grey} grey of ${inner.mesh} mesh pixels)`);
    await page.screenshot({ path: `${artifacts}/viewer_${command}.png` });
    await page.click('#surface-0');
  }

  // A decode that runs past its limit is stopped and reported, and the page goes on: with the
  // limit at 0 s (window.ldimeshViewer, as ?decode_timeout=0 sets it) the next step's decode is
  // over it; back at the default, the step after shows (a fresh Draco loader, its workers new).
  await page.evaluate(() => { window.ldimeshViewer.decodeTimeout = 0; });
  const overLimit = await publishNext();
  await page.waitForFunction((step) => (document.body.dataset.status || '').includes(
    `mesh of step ${step}: decoding took more than 0 s and was stopped`), overLimit.step, { timeout: 30000 })
    .catch(() => {});
  const overStatus = [await page.evaluate(() => document.body.dataset.status), await loadedStep()];
  check(overStatus[0].includes(`mesh of step ${overLimit.step}: decoding took more than 0 s`) &&
    overStatus[1] !== Number(overLimit.step),
    `a decode over its limit is stopped and reported: "${overStatus[0]}", step ${overStatus[1]} still shown`);
  await page.evaluate(() => { window.ldimeshViewer.decodeTimeout = null; });
  const afterStop = await publishNext();
  await waitForStep(afterStop.step, 30000).catch(() => {});
  const recovered = [await loadedStep(), Number(await page.evaluate(() => document.body.dataset.triangles))];
  check(recovered[0] === Number(afterStop.step) && recovered[1] === afterStop.triangles,
    `then the next step shows: step ${recovered[0]}, ${recovered[1]} of ${afterStop.triangles} triangles`);

  const interleaved = consoleMessages.filter((m) => m.includes('InterleavedBufferAttribute'));
  check(interleaved.length === 0, `no InterleavedBufferAttribute warning in the console (${interleaved.length})`);
  // (the browser's own request for /favicon.ico shows only as a console error)
  const failedLoads = consoleMessages.filter((m) => m.includes('Failed to load resource'));
  check(httpErrors.length === 0 && failedLoads.length === 0,
    `no request answered with an error, favicon included (${[...httpErrors, ...failedLoads].join(', ') || 'none'})`);

  // An uncaught script error anywhere above fails the test, even where the page still drew.
  check(pageErrors.length === 0, `no uncaught script errors on the page (${pageErrors.join('; ') || 'none'})`);

  // Without the token the page says so instead of showing anything.
  const bare = await browser.newPage();
  await bare.goto(url.replace(/\?token=.*/, ''));
  const bareStatus = await bare.evaluate(() => document.body.dataset.status || '');
  check(bareStatus.includes('token'), `without a token the page explains: "${bareStatus}"`);
} catch (e) {
  failures++;
  console.log(`FAIL ${e.message}`);
} finally {
  clearTimeout(timeout);
  if (browser) await browser.close();
  publisher.stdin.end('quit\n');
  publisher.kill();
}
console.log(`${passes} passed, ${failures} failed`);
process.exit(failures ? 1 : 0);
