// Browser test of the viewer: Debian's chromium, driven by playwright-core, opens the page a
// test publisher serves (real server, real Draco GLB meshes), and checks what a person sees:
// the mesh of step 1 loads (the page's triangle count equals the published one), the canvas
// is not blank, and the view follows to step 2 when it is published. Screenshots are kept.
//
//   node tests/browser/viewer_test.mjs PUBLISHER REPO_ROOT ARTIFACT_DIR
import { spawn } from 'node:child_process';
import { mkdirSync } from 'node:fs';
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
  page.on('pageerror', (e) => console.log(`page error: ${e.message}`));
  await page.goto(url);
  await page.waitForFunction((s) => document.body.dataset.loadedStep === s, first.step, { timeout: 60000 });
  const triangles = await page.evaluate(() => Number(document.body.dataset.triangles));
  check(triangles === first.triangles, `step 1: the page shows ${triangles} triangles, ${first.triangles} were published`);

  await page.waitForTimeout(500);  // a few frames
  const drawn = await page.evaluate(() => {
    const gl = document.getElementById('view');
    const copy = document.createElement('canvas');
    copy.width = gl.width; copy.height = gl.height;
    const ctx = copy.getContext('2d');
    ctx.drawImage(gl, 0, 0);
    const d = ctx.getImageData(0, 0, copy.width, copy.height).data;
    let differing = 0;
    for (let i = 0; i < d.length; i += 4)  // background #1d2026
      if (Math.abs(d[i] - 0x1d) + Math.abs(d[i + 1] - 0x20) + Math.abs(d[i + 2] - 0x26) > 24) differing++;
    return differing / (d.length / 4);
  });
  check(drawn > 0.03, `the canvas is not blank (${(100 * drawn).toFixed(1)} % of its pixels show the mesh)`);
  await page.screenshot({ path: `${artifacts}/viewer_step1.png` });

  publisher.stdin.write('next\n');
  const second = published(await nextLine());
  await page.waitForFunction((s) => document.body.dataset.loadedStep === s, second.step, { timeout: 60000 });
  const triangles2 = await page.evaluate(() => Number(document.body.dataset.triangles));
  check(triangles2 === second.triangles, `step 2 followed: ${triangles2} triangles shown, ${second.triangles} published`);
  const panel = await page.evaluate(() => document.getElementById('step').textContent);
  check(panel === second.step, `the panel shows step ${panel}`);
  await page.waitForTimeout(300);
  await page.screenshot({ path: `${artifacts}/viewer_step2.png` });

  // Without the token the page says so instead of showing anything.
  const bare = await browser.newPage();
  await bare.goto(url.replace(/\?token=.*/, ''));
  const status = await bare.evaluate(() => document.body.dataset.status || '');
  check(status.includes('token'), `without a token the page explains: "${status}"`);
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
