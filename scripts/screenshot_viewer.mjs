// Takes a screenshot of the viewer at URL (the one a job or ldimesh-serve prints) once a step is
// shown: node scripts/screenshot_viewer.mjs URL OUT.png [WIDTHxHEIGHT]
// COLOUR=view|scalar|plain picks the colouring (default: the viewer's own choice).
import { chromium } from 'playwright-core';

const [url, out, size = '1200x800'] = process.argv.slice(2);
if (!url || !out) {
  console.error('usage: node scripts/screenshot_viewer.mjs URL OUT.png [WIDTHxHEIGHT]');
  process.exit(2);
}
const [width, height] = size.split('x').map(Number);
const browser = await chromium.launch({
  executablePath: '/usr/bin/chromium',
  args: ['--headless', '--no-sandbox', '--enable-unsafe-swiftshader', '--use-angle=swiftshader',
    '--disable-background-networking', '--disable-component-update', '--no-first-run'],
});
try {
  const page = await browser.newPage({ viewport: { width, height } });
  await page.goto(url);
  await page.waitForFunction(() => document.body.dataset.loadedStep, null, { timeout: 60000 });
  if (process.env.COLOUR) await page.selectOption('#colour', process.env.COLOUR);
  await page.waitForTimeout(1000);
  await page.screenshot({ path: out });
  console.log(`wrote ${out} (step ${await page.evaluate(() => document.body.dataset.loadedStep)})`);
} finally {
  await browser.close();
}
