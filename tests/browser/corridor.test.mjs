// Corridor surveys in the browser: draw a centre line with mouse clicks,
// give the width, plan, and find the corridor (not an area) in the stored
// request; then import a line from KML instead, and clear it.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { writeFileSync } from 'node:fs';
import path from 'node:path';
import { withServerAndBrowser, openPage, clickLonLat, screenshot, tempDir } from './helpers.mjs';

// Across the map's first view (Alexandria, where the other tests' DTM lies), bent once.
const LINE = [[-77.0545, 38.8097], [-77.0530, 38.8093], [-77.0515, 38.8098]];

const env = withServerAndBrowser();

test('draw a corridor line, plan it, and import one from KML', async () => {
  const { page, context, problems } = await openPage(env.browser, env.server.url);
  await page.click('#corridor-fields summary');
  await page.click('#draw-corridor');
  assert.match(await page.textContent('#map-hint'), /centre line/);
  for (const [lon, lat] of LINE) await clickLonLat(page, lon, lat);
  await page.keyboard.press('Enter');
  await page.waitForFunction(() => /3 positions/.test(document.querySelector('#corridor-status').textContent));
  await page.fill('#corridor-width', '60');
  await page.fill('#altitude', '40');
  await page.click('#plan-survey');
  await page.waitForFunction(() => document.querySelector('#survey-busy').textContent === 'Planned.', null, { timeout: 60_000 });
  await screenshot(page, 'corridor-planned');

  const newest = (await (await env.server.fetch('/api/v1/surveys?limit=1')).json()).items[0];
  const planned = await (await env.server.fetch(`/api/v1/surveys/${newest.id}`)).json();
  assert.equal(planned.request.roi, undefined);
  assert.equal(planned.request.corridor.type, 'LineString');
  assert.equal(planned.request.corridor.coordinates.length, 3);
  for (const [i, [lon, lat]] of LINE.entries()) {
    // Clicked to the pixel: about a metre at this zoom.
    assert.ok(Math.abs(planned.request.corridor.coordinates[i][0] - lon) < 2e-5, 'lon');
    assert.ok(Math.abs(planned.request.corridor.coordinates[i][1] - lat) < 2e-5, 'lat');
  }
  assert.equal(planned.request.corridor_width_m, 60);
  assert.ok(planned.stats.lane_count > 0);
  // The corridor is about 270 m × 60 m.
  assert.ok(planned.stats.area_m2 > 14_000 && planned.stats.area_m2 < 18_000, `${planned.stats.area_m2}`);

  // A line from a KML file replaces the drawn one; clearing it leaves the area to plan.
  const dir = tempDir('terraplan-corridor-');
  const kml = path.join(dir, 'road.kml');
  writeFileSync(kml, `<?xml version="1.0"?><kml xmlns="http://www.opengis.net/kml/2.2"><Placemark><LineString><coordinates>-77.0540,38.8100,0 -77.0520,38.8100,0</coordinates></LineString></Placemark></kml>`);
  await page.setInputFiles('#import-corridor', kml);
  await page.waitForFunction(() => /2 positions/.test(document.querySelector('#corridor-status').textContent));
  await page.click('#clear-corridor');
  assert.match(await page.textContent('#corridor-status'), /No line/);
  await page.click('#plan-survey');
  await page.locator('#survey-roi-error').waitFor({ state: 'visible' });
  assert.deepEqual(problems, []);
  await context.close();
});
