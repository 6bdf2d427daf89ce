// A DEM in a CRS other than UTM or WGS84 (here NAD83 / CONUS Albers, EPSG:5070,
// made from the DTM by GDAL's gdalwarp) is placed on the map exactly, with
// the PROJ definition the server gives: its hillshade lands where the
// original UTM DTM's does, pixel for pixel.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { spawnSync } from 'node:child_process';
import path from 'node:path';
import { withServerAndBrowser, openPage, uploadDtm, screenshot, tempDir, DTM } from './helpers.mjs';

const env = withServerAndBrowser();

// An inner part of the DTM, shown the same way for both DEMs.
const VIEW = [-77.0545, 38.8092, -77.0505, 38.8120];

/** The map's canvas as grey levels (kept in the page for the comparison). */
async function captureGrey(page, slot) {
  await page.evaluate((extent) => window.terraplan.fit(extent), VIEW);
  await page.waitForTimeout(1200);
  return page.evaluate((name) => {
    const canvas = [...document.querySelectorAll('#map canvas')].find((c) => c.width > 0);
    const { data, width, height } = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height);
    const grey = new Float32Array(width * height);
    for (let i = 0; i < grey.length; i++) grey[i] = data[4 * i + 3] < 200 ? NaN : (data[4 * i] + data[4 * i + 1] + data[4 * i + 2]) / 3;
    window[name] = { grey, width, height };
    return { width, height };
  }, slot);
}

test('a DEM in CONUS Albers is placed exactly where the same terrain in UTM is', async () => {
  const dir = tempDir('terraplan-crs-');
  const albers = path.join(dir, 'dtm_conus_albers.tif');
  const warp = spawnSync('gdalwarp', ['-q', '-t_srs', 'EPSG:5070', '-r', 'bilinear', '-tr', '2', '2', DTM, albers], { encoding: 'utf8' });
  assert.equal(warp.status, 0, `gdalwarp (package gdal-bin, installed by scripts/setup.sh --with-validators): ${warp.stderr}`);

  const { page, context, problems, outside } = await openPage(env.browser, env.server.url);
  await uploadDtm(page);
  await captureGrey(page, '__utm');

  await page.setInputFiles('#dem-file', albers);
  await page.waitForFunction(() => /Albers/.test(document.querySelector('#dem-status').textContent), null, { timeout: 30_000 });
  const status = await page.textContent('#dem-status');
  assert.doesNotMatch(status, /approximately/, status);
  assert.match(status, /NAD83 \/ Conus Albers/);
  // The newest DEM is listed first, after "None".
  const options = await page.$$eval('#dem-select option', (o) => o.map((e) => e.textContent));
  assert.match(options[0], /^None/);
  assert.match(options[1], /^dtm_conus_albers/);
  await captureGrey(page, '__albers');
  await screenshot(page, 'dem-conus-albers');

  // The shift that best lines the two hillshades up, searched over ±8 pixels; the approximate
  // placement (the WGS84 envelope stretched) is off by several pixels and rotated.
  const fit = await page.evaluate(() => {
    const a = window.__utm;
    const b = window.__albers;
    const w = Math.min(a.width, b.width);
    const h = Math.min(a.height, b.height);
    const diff = (dx, dy) => {
      let sum = 0;
      let n = 0;
      for (let y = 40; y < h - 40; y += 2) {
        for (let x = 40; x < w - 40; x += 2) {
          const p = a.grey[y * a.width + x];
          const q = b.grey[(y + dy) * b.width + (x + dx)];
          if (Number.isFinite(p) && Number.isFinite(q)) {
            sum += Math.abs(p - q);
            n++;
          }
        }
      }
      return n > 1000 ? sum / n : Infinity;
    };
    let best = { dx: 0, dy: 0, d: Infinity };
    for (let dy = -8; dy <= 8; dy++) for (let dx = -8; dx <= 8; dx++) {
      const d = diff(dx, dy);
      if (d < best.d) best = { dx, dy, d };
    }
    return { best, atZero: diff(0, 0), shifted: diff(6, 0) };
  });
  console.log(`hillshade alignment: ${JSON.stringify(fit)}`);
  assert.ok(Math.abs(fit.best.dx) <= 1 && Math.abs(fit.best.dy) <= 1, `best alignment at a shift of (${fit.best.dx}, ${fit.best.dy}) px`);
  assert.ok(fit.atZero < 0.6 * fit.shifted, `aligned difference ${fit.atZero} against ${fit.shifted} 6 px off`);

  assert.deepEqual(outside, []);
  assert.deepEqual(problems, []);
  await context.close();
});
