// Soak test (issue 26; a benchmark, not in CI): the Gray–Scott mini-app publishes many steps while every kind
// of client is attached, and the root rank's resources are sampled from /proc. Attached for the
// whole run: the web viewer in Debian's chromium (playwright-core), `ldimesh-fetch --follow`
// (writing every step it gets), and an event-stream client that connects and never reads a byte.
// Printed: the root's resident memory (VmRSS), open file descriptors and threads at the first
// published step and every tenth of the run, their growth from the first tenth to the end, and
// how many steps the viewer and the fetcher got. Exit status 1 when the job fails.
//
//   node bench/soak.mjs [STEPS (1000)] [RANKS (2)] [RESOLUTION (96)]
//
// Run from the repository root after scripts/build.sh (binaries in build/bin).
import { spawn } from 'node:child_process';
import { mkdtempSync, readFileSync, readdirSync, rmSync, writeFileSync } from 'node:fs';
import net from 'node:net';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { createInterface } from 'node:readline';
import { chromium } from 'playwright-core';

const steps = Number(process.argv[2] ?? 1000);
const ranks = Number(process.argv[3] ?? 2);
const resolution = Number(process.argv[4] ?? 96);
const bin = 'build/bin';
const dir = mkdtempSync(join(tmpdir(), 'ldimesh-soak-'));
const optionsPath = join(dir, 'options.json');
writeFileSync(optionsPath, JSON.stringify({
  resolution, keep: 16, log: true, server: { enabled: true, bind: '127.0.0.1', port: 0 },
}));
const env = { ...process.env, OMPI_ALLOW_RUN_AS_ROOT: '1', OMPI_ALLOW_RUN_AS_ROOT_CONFIRM: '1',
  OMPI_MCA_rmaps_base_oversubscribe: '1' };
// Gray–Scott at 48³ with 50 solver steps per output step: tens of milliseconds a step, so that
// the clients see a job that runs for a while, not one that is over before they attach.
const jobArgs = ['-n', String(ranks), '--oversubscribe', '--bind-to', 'none', `${bin}/ldimesh-grayscott`,
  '--size', '48', '--substeps', '50', '--steps', String(steps), '--options', optionsPath];
console.log(`job: mpiexec ${jobArgs.join(' ')}`);
const job = spawn('mpiexec', jobArgs, { detached: true, stdio: ['ignore', 'pipe', 'pipe'], env });
let viewerLine;
const viewerUrl = new Promise((resolve) => { viewerLine = resolve; });
createInterface({ input: job.stdout }).on('line', (line) => {
  if (line.startsWith('viewer: ')) viewerLine(line.slice(8).trim());
});
const jobErrors = [];
createInterface({ input: job.stderr }).on('line', (line) => jobErrors.push(line));
const jobDone = new Promise((resolve) => job.on('exit', (code) => resolve(code)));

// The root: the mini-app's process whose MPI rank is 0.
function rootPid() {
  for (const entry of readdirSync('/proc')) {
    if (!/^\d+$/.test(entry)) continue;
    try {
      if (!readFileSync(`/proc/${entry}/cmdline`, 'latin1').includes('ldimesh-grayscott')) continue;
      if (readFileSync(`/proc/${entry}/environ`, 'latin1').split('\0').includes('OMPI_COMM_WORLD_RANK=0'))
        return Number(entry);
    } catch { /* gone */ }
  }
  return undefined;
}
function sample(pid) {
  try {
    const status = readFileSync(`/proc/${pid}/status`, 'latin1');
    const field = (name) => Number(status.match(new RegExp(`^${name}:\\s+(\\d+)`, 'm'))[1]);
    return { rssMiB: field('VmRSS') / 1024, threads: field('Threads'), fds: readdirSync(`/proc/${pid}/fd`).length };
  } catch { return undefined; }
}

const url = await Promise.race([viewerUrl, jobDone.then(() => undefined)]);
if (!url) {
  console.log(`the job ended before printing its viewer URL:\n${jobErrors.join('\n')}`);
  process.exit(1);
}
const base = new URL(url);
const token = base.searchParams.get('token');
console.log(`viewer: ${url}`);

// The clients.
const browser = await chromium.launch({ executablePath: '/usr/bin/chromium',
  args: ['--headless', '--no-sandbox', '--enable-unsafe-swiftshader', '--use-angle=swiftshader'] });
const page = await browser.newPage({ viewport: { width: 640, height: 480 } });
const pageErrors = [];
page.on('pageerror', (e) => pageErrors.push(String(e)));
await page.goto(url);
const fetchOut = join(dir, 'fetched');
const fetcher = spawn(`${bin}/ldimesh-fetch`, ['--url', url, '--follow', '--wait', '10', '-o', fetchOut],
  { stdio: ['ignore', 'pipe', 'pipe'] });
let fetched = 0;
createInterface({ input: fetcher.stdout }).on('line', (line) => { if (line.startsWith('step ')) fetched++; });
const silent = net.connect(Number(base.port), base.hostname, () => {
  silent.write(`GET /api/v1/events?token=${token} HTTP/1.1\r\nHost: x\r\n\r\n`);
  silent.pause();  // never reads: the server's writes fill the socket's buffers
});
silent.on('error', () => {});

// Sampling: once a second, with the step the server has.
async function latestStep() {
  try {
    const res = await fetch(new URL(`/api/v1/latest?token=${token}`, base));
    return res.ok ? (await res.json()).step : 0;
  } catch { return undefined; }
}
const samples = [];
let pid;
const started = Date.now();
while (true) {
  const code = await Promise.race([jobDone, new Promise((r) => setTimeout(() => r('tick'), 1000))]);
  if (code !== 'tick') break;
  pid ??= rootPid();
  const step = await latestStep();
  const s = pid && sample(pid);
  if (s && step) samples.push({ seconds: (Date.now() - started) / 1000, step, ...s });
}
const exitCode = await jobDone;
const viewerStep = await page.evaluate(() => document.getElementById('step')?.textContent).catch(() => undefined);
fetcher.kill('SIGINT');
silent.destroy();
await browser.close();

console.log(`\n${steps} steps, ${ranks} ranks, resolution ${resolution}; the root's resources (rank 0, /proc):\n`);
console.log('| s | step | RSS MiB | file descriptors | threads |');
console.log('|---|---|---|---|---|');
const picks = new Set([0, samples.length - 1]);
for (let k = 1; k < 10; k++) picks.add(Math.floor((k * samples.length) / 10));
for (const k of [...picks].sort((a, b) => a - b)) {
  const s = samples[k];
  if (s) console.log(`| ${s.seconds.toFixed(0)} | ${s.step} | ${s.rssMiB.toFixed(1)} | ${s.fds} | ${s.threads} |`);
}
const tenth = samples[Math.floor(samples.length / 10)], last = samples[samples.length - 1];
if (tenth && last) {
  console.log(`\nFrom step ${tenth.step} to step ${last.step}: RSS ${(last.rssMiB - tenth.rssMiB).toFixed(1)} MiB` +
    ` (${(100 * (last.rssMiB / tenth.rssMiB - 1)).toFixed(1)} %), file descriptors ${last.fds - tenth.fds},` +
    ` threads ${last.threads - tenth.threads}.`);
}
console.log(`Published: up to step ${last?.step}; ldimesh-fetch --follow got ${fetched} steps; the viewer` +
  ` showed step ${viewerStep ?? '?'} at the end; page errors: ${pageErrors.length}; job exit status ${exitCode}.`);
rmSync(dir, { recursive: true, force: true });
process.exit(exitCode === 0 ? 0 : 1);
