// Browser test of the README's demo: the real mini-app ldimesh-grayscott runs under mpiexec on
// two ranks with the in situ adaptor's HTTP server (as scripts/demo does, only smaller), and
// Debian's chromium, driven by playwright-core, opens the `viewer:` URL it prints. Checked, while
// the simulation runs: the page loads a mesh (its triangle count, panel and status agree with
// the job's JSON API), the canvas is not blank, the displayed step advances at least twice to
// later steps with a different surface (another GLB, other pixels on the canvas), no script
// errors. Screenshots of an early and a later step: build/test-artifacts/demo_*_step.png. The
// job (mpiexec's process group and its ranks) is killed at the end, on failure, on SIGTERM and
// after 240 s at most.
//
//   node tests/browser/demo_test.mjs MPIEXEC GRAYSCOTT REPO_ROOT ARTIFACT_DIR
import { spawn } from 'node:child_process';
import { createHash } from 'node:crypto';
import { mkdirSync, mkdtempSync, readFileSync, readdirSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { createInterface } from 'node:readline';
import { chromium } from 'playwright-core';

const [mpiexec, grayscott, repoRoot, artifacts] = process.argv.slice(2);
if (!artifacts) {
  console.log('usage: node demo_test.mjs MPIEXEC GRAYSCOTT REPO_ROOT ARTIFACT_DIR');
  process.exit(2);
}
mkdirSync(artifacts, { recursive: true });
for (const name of ['demo_first_step.png', 'demo_later_step.png']) rmSync(join(artifacts, name), { force: true });

let failures = 0, passes = 0;
function check(ok, what) {
  if (ok) { passes++; console.log(`ok   ${what}`); } else { failures++; console.log(`FAIL ${what}`); }
  return ok;
}
const started = Date.now();
const seconds = () => ((Date.now() - started) / 1000).toFixed(1);

// The job: 48³ points, 400 solver steps per output step (about 0.2–0.5 s each on two busy
// cores), 150 output steps: it runs for far longer than the checks need (they stop it).
const dir = mkdtempSync(join(tmpdir(), 'ldimesh-demo-test-'));
const optionsPath = join(dir, 'options.json');
writeFileSync(optionsPath, JSON.stringify({
  isovalues: [0.25], resolution: 128, keep: 16, log: true,
  server: { enabled: true, bind: '127.0.0.1', port: 0 },
}));
const jobArgs = ['-n', '2', '--oversubscribe', '--bind-to', 'none', grayscott,
  '--size', '48', '--substeps', '400', '--steps', '150', '--options', optionsPath];
console.log(`job: ${mpiexec} ${jobArgs.join(' ')}`);
const job = spawn(mpiexec, jobArgs, {
  cwd: repoRoot,
  detached: true,  // its own process group: killed as a whole
  stdio: ['ignore', 'pipe', 'pipe'],
  env: { ...process.env, OMPI_ALLOW_RUN_AS_ROOT: '1', OMPI_ALLOW_RUN_AS_ROOT_CONFIRM: '1',
    OMPI_MCA_rmaps_base_oversubscribe: '1' },
});
const jobOutput = [];
let viewerLine;
const viewerUrl = new Promise((resolve) => { viewerLine = resolve; });
createInterface({ input: job.stdout }).on('line', (line) => {
  jobOutput.push(line);
  if (line.startsWith('viewer: ')) viewerLine(line.slice(8).trim());
});
createInterface({ input: job.stderr }).on('line', (line) => jobOutput.push(`stderr: ${line}`));
let jobExited = false;
const jobExit = new Promise((resolve) => job.on('exit', (code, signal) => {
  jobExited = true;
  resolve(`the job ended (${signal ? `signal ${signal}` : `exit code ${code}`})`);
}));
job.on('error', (e) => jobOutput.push(`spawn error: ${e.message}`));

// Every process of the job: the mpiexec process group plus its descendants (in case a rank
// ends up in another group), from /proc.
function descendants(root) {
  const children = new Map();
  for (const entry of readdirSync('/proc')) {
    if (!/^\d+$/.test(entry)) continue;
    try {
      const stat = readFileSync(`/proc/${entry}/stat`, 'utf8');
      const ppid = Number(stat.slice(stat.lastIndexOf(')') + 2).split(' ')[1]);
      if (!children.has(ppid)) children.set(ppid, []);
      children.get(ppid).push(Number(entry));
    } catch { /* gone meanwhile */ }
  }
  const found = [], todo = [root];
  while (todo.length) for (const c of children.get(todo.pop()) || []) { found.push(c); todo.push(c); }
  return found;
}
function signal(pid, sig) { try { process.kill(pid, sig); return true; } catch { return false; } }
function alive(pid) {  // a zombie is gone too
  try { return !readFileSync(`/proc/${pid}/stat`, 'utf8').includes(') Z '); } catch { return false; }
}
let killed = false;
async function killJob() {
  if (killed || !job.pid) return;
  killed = true;
  const ranks = descendants(job.pid);
  signal(-job.pid, 'SIGTERM');
  for (const pid of ranks) signal(pid, 'SIGTERM');
  const deadline = Date.now() + 5000;
  while (Date.now() < deadline && (!jobExited || ranks.some(alive)))
    await new Promise((r) => setTimeout(r, 100));
  signal(-job.pid, 'SIGKILL');
  for (const pid of ranks) signal(pid, 'SIGKILL');
}
process.on('exit', () => {  // last resort, synchronous
  if (job.pid && !jobExited) { signal(-job.pid, 'SIGKILL'); for (const p of descendants(job.pid)) signal(p, 'SIGKILL'); }
  rmSync(dir, { recursive: true, force: true });
});
for (const sig of ['SIGINT', 'SIGTERM']) process.on(sig, () => { console.log(`FAIL stopped by ${sig}`); process.exit(1); });

// Waits for `promise`, failing when the job ends first or after `ms` milliseconds.
function within(ms, what, promise) {
  let timer;
  return Promise.race([
    promise,
    jobExit.then((how) => { throw new Error(`${what}: ${how} first`); }),
    new Promise((_, reject) => { timer = setTimeout(() => reject(new Error(`${what}: not within ${ms / 1000} s`)), ms); }),
  ]).finally(() => clearTimeout(timer));
}

let browser;
const hardTimeout = setTimeout(async () => {
  console.log('FAIL the test took over 240 s');
  if (browser) await Promise.race([browser.close(), new Promise((r) => setTimeout(r, 5000))]).catch(() => {});
  await killJob();
  process.exit(1);
}, 240000);
try {
  const url = await within(60000, 'the job printing its viewer URL', viewerUrl);
  check(/^http:\/\/127\.0\.0\.1:\d+\/\?token=\w+$/.test(url), `the job prints the viewer URL ${url}`);
  const origin = new URL(url).origin, token = new URL(url).searchParams.get('token');
  const api = async (path) => {
    const response = await fetch(origin + path, { headers: { Authorization: `Bearer ${token}` } });
    if (!response.ok) throw new Error(`GET ${path}: HTTP ${response.status}`);
    return response;
  };
  // The job's own record of a step, fetched while the page shows it (the server keeps 16).
  const published = async (step) => {
    const meta = await (await api(`/api/v1/steps/${step}`)).json();
    const glb = Buffer.from(await (await api(`/api/v1/steps/${step}/mesh.glb`)).arrayBuffer());
    return { meta, bytes: glb.length, sha: createHash('sha256').update(glb).digest('hex').slice(0, 16) };
  };

  browser = await chromium.launch({
    executablePath: '/usr/bin/chromium',
    args: ['--headless', '--no-sandbox', '--enable-unsafe-swiftshader', '--use-angle=swiftshader',
      '--disable-background-networking', '--disable-component-update', '--no-first-run'],
  });
  console.log(`       [${seconds()} s] chromium started`);
  const page = await browser.newPage({ viewport: { width: 960, height: 640 } });
  const pageErrors = [];
  page.on('pageerror', (e) => { pageErrors.push(e.message); console.log(`page error: ${e.message}`); });
  await within(60000, 'opening the viewer', page.goto(url, { timeout: 0 }));
  console.log(`       [${seconds()} s] page opened`);

  // What the page shows once it has loaded a step after `after`: the step, its triangle count,
  // the panel and the status line, read at one instant.
  const waitForStepAfter = async (after, what) => {
    const handle = await within(60000, what, page.waitForFunction((a) => {
      const body = document.body, status = document.getElementById('status');
      if (status.classList.contains('error')) return { error: status.textContent };
      if (body.dataset.loadedStep === undefined || !(Number(body.dataset.loadedStep) > a)) return null;
      return {
        step: Number(body.dataset.loadedStep),
        triangles: Number(body.dataset.triangles),
        panelStep: document.getElementById('step').textContent,
        panelTriangles: document.getElementById('triangles').textContent,
        status: body.dataset.status || '',
      };
    }, after, { timeout: 0, polling: 100 }));
    const view = await handle.jsonValue();
    if (view.error !== undefined) throw new Error(`${what}: the page reports an error: "${view.error}"`);
    return { view, job: await published(view.step) };
  };
  // Reads the canvas back (the viewer keeps its drawing buffer) in an animation frame, after the
  // viewer drew it, with the step it shows: the fraction of its pixels that differ from the
  // background #1d2026 and, when `compareWith` names an earlier read, the fraction that differ
  // from that one (the pixels stay in the page). Then a screenshot: the page follows the job
  // and may move on meanwhile, so the step shown before and after it are noted.
  const capture = async (keepAs, compareWith, file) => {
    const pixels = await page.evaluate(([keep, other]) => new Promise((resolve) => requestAnimationFrame(() => {
      const gl = document.getElementById('view');
      const copy = document.createElement('canvas');
      copy.width = gl.width; copy.height = gl.height;
      const ctx = copy.getContext('2d');
      ctx.drawImage(gl, 0, 0);
      const step = Number(document.body.dataset.loadedStep);
      const d = ctx.getImageData(0, 0, copy.width, copy.height).data;
      const near = (a, i, r, g, b) => Math.abs(a[i] - r) + Math.abs(a[i + 1] - g) + Math.abs(a[i + 2] - b) <= 24;
      let drawn = 0, changed = 0;
      const o = other && window.demoTestPixels[other];
      for (let i = 0; i < d.length; i += 4) {
        if (!near(d, i, 0x1d, 0x20, 0x26)) drawn++;
        if (o && (o.length !== d.length || !near(o, i, d[i], d[i + 1], d[i + 2]))) changed++;
      }
      window.demoTestPixels = { ...window.demoTestPixels, [keep]: d };
      resolve({ step, drawn: drawn / (d.length / 4), changed: o ? changed / (d.length / 4) : null });
    })), [keepAs, compareWith]);
    const stepNow = () => page.evaluate(() => Number(document.body.dataset.loadedStep));
    const before = await stepNow();
    await page.screenshot({ path: join(artifacts, file) });
    const after = await stepNow();
    return { ...pixels, shot: { before, after, text: before === after ? `step ${after}` : `step ${before} or ${after}` } };
  };
  const agrees = (label, { view, job }) => {
    check(view.triangles > 0 && view.triangles === job.meta.triangles,
      `${label} step ${view.step}: the page shows ${view.triangles} triangles, the job's API ${job.meta.triangles}`);
    check(view.panelStep === String(view.step) && view.panelTriangles === view.triangles.toLocaleString('en'),
      `${label} step ${view.step}: the panel reads step ${view.panelStep}, ${view.panelTriangles} triangles`);
    // (or already loading a newer one)
    const loading = /^loading step (\d+)…$/.exec(view.status);
    check(view.status === `step ${view.step} (following)` || (loading && Number(loading[1]) > view.step),
      `${label} step ${view.step}: the status reads "${view.status}"`);
  };

  // (1) A mesh is loaded, and (3) drawn (4: a screenshot).
  const first = await waitForStepAfter(0, 'the page showing a first mesh');
  console.log(`       [${seconds()} s] first step shown: ${first.view.step} (GLB ${first.job.bytes} bytes, sha ${first.job.sha})`);
  agrees('first', first);
  const shotA = await capture('A', null, 'demo_first_step.png');
  check(shotA.drawn > 0.03, `step ${shotA.step}: the canvas is not blank (${(100 * shotA.drawn).toFixed(1)} % of its pixels show the mesh)`);

  // (2) The view follows the running simulation, twice, to other surfaces (3 and 4 again).
  const second = await waitForStepAfter(first.view.step, `the page moving on from step ${first.view.step}`);
  console.log(`       [${seconds()} s] second step shown: ${second.view.step} (GLB ${second.job.bytes} bytes, sha ${second.job.sha})`);
  agrees('second', second);
  const third = await waitForStepAfter(second.view.step, `the page moving on from step ${second.view.step}`);
  console.log(`       [${seconds()} s] third step shown: ${third.view.step} (GLB ${third.job.bytes} bytes, sha ${third.job.sha})`);
  agrees('third', third);
  check(first.view.step < second.view.step && second.view.step < third.view.step,
    `the displayed step advanced twice: ${first.view.step} → ${second.view.step} → ${third.view.step}`);
  check(first.job.sha !== second.job.sha && second.job.sha !== third.job.sha && first.job.sha !== third.job.sha,
    `the surface evolves: three different meshes (${first.view.triangles}, ${second.view.triangles}, ${third.view.triangles} triangles; ` +
    `${first.job.bytes}, ${second.job.bytes}, ${third.job.bytes} GLB bytes)`);
  const shotB = await capture('B', 'A', 'demo_later_step.png');
  check(shotB.drawn > 0.03, `step ${shotB.step}: the canvas is not blank (${(100 * shotB.drawn).toFixed(1)} % of its pixels show the mesh)`);
  check(shotB.step > shotA.step && shotB.changed > 0.002,
    `the picture changed from step ${shotA.step} to step ${shotB.step} (${(100 * shotB.changed).toFixed(1)} % of the pixels)`);
  check(shotB.shot.before > shotA.shot.after,
    `screenshots of two steps: ${shotA.shot.text} in demo_first_step.png, ${shotB.shot.text} in demo_later_step.png`);
  check(pageErrors.length === 0, `no script errors on the page (${pageErrors.length})`);
} catch (e) {
  failures++;
  console.log(`FAIL ${e.message}`);
} finally {
  clearTimeout(hardTimeout);
  if (browser) await browser.close().catch(() => {});
  const ranks = job.pid ? descendants(job.pid) : [];
  console.log(`       [${seconds()} s] chromium closed`);
  await killJob();
  console.log(`       [${seconds()} s] job stopped`);
  check(job.pid && !alive(job.pid) && !ranks.some(alive), `mpiexec and the job's ${ranks.length} ranks are gone`);
  if (failures) console.log(`the job's last output:\n  ${jobOutput.slice(-20).join('\n  ')}`);
}
console.log(`${passes} passed, ${failures} failed (${seconds()} s; screenshots in ${artifacts})`);
process.exit(failures ? 1 : 0);
