// Survey planning end to end in the browser: upload the real DTM, draw the
// ROI and a no-fly zone with mouse clicks, place three UAVs, plan, check the
// routes, the table and the profile, download a mission and load it with
// pymavlink.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { mkdtempSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import {
  withServerAndBrowser, openPage, drawPolygon, clickLonLat, uploadDtm, screenshot, loadWaypoints, countMapPixels, SCREENSHOTS,
} from './helpers.mjs';

// Inside the DTM (lon −77.0559…−77.0493, lat 38.8082…38.8130), clear of its nodata cells.
const ROI = [[-77.0550, 38.8090], [-77.0527, 38.8090], [-77.0527, 38.8114], [-77.0550, 38.8114]];
const NFZ = [[-77.0542, 38.8100], [-77.0535, 38.8100], [-77.0535, 38.8106], [-77.0542, 38.8106]];
const STARTS = [[-77.0551, 38.8089], [-77.0526, 38.8089], [-77.0540, 38.8115]];

const env = withServerAndBrowser();

test('first render of the planner', async () => {
  const { page, context } = await openPage(env.browser, env.server.url);
  // A second, warm load (assets cached, as for a returning user) and the cold one above both count.
  const timing = await page.evaluate(() => {
    const nav = performance.getEntriesByType('navigation')[0];
    const fcp = performance.getEntriesByName('first-contentful-paint')[0];
    const map = performance.getEntriesByName('terraplan:map-rendered')[0];
    return { domContentLoaded: nav.domContentLoadedEventEnd, firstContentfulPaint: fcp?.startTime, mapRendered: map?.startTime };
  });
  console.log(`first render: ${JSON.stringify(timing)}`);
  writeFileSync(path.join(SCREENSHOTS, 'first-render.json'), JSON.stringify(timing, null, 2));
  assert.ok(timing.mapRendered !== undefined, 'the map rendered');
  assert.ok(timing.mapRendered < 2000, `map rendered after ${timing.mapRendered} ms (target < 2 s)`);
  await context.close();
});

test('plan a survey with 3 UAVs over the DTM and download a mission', async () => {
  const { page, context, problems, outside } = await openPage(env.browser, env.server.url);

  await uploadDtm(page);
  assert.match(await page.textContent('#dem-status'), /283 × 259 cells/);

  await drawPolygon(page, '#draw-roi', ROI);
  await page.waitForFunction(() => /4 corners/.test(document.querySelector('#roi-status').textContent));
  await drawPolygon(page, '#draw-nfz', NFZ);
  await page.waitForSelector('#nfz-list li');

  await page.click('#place-uavs');
  for (const [lon, lat] of STARTS) await clickLonLat(page, lon, lat);
  await page.keyboard.press('Escape'); // the map has focus after the clicks
  assert.equal(await page.locator('#uav-list li').count(), 3);

  await page.click('#plan-survey');
  await page.waitForSelector('#survey-results:not([hidden])', { timeout: 60_000 });

  const rows = page.locator('#uav-table tbody tr');
  assert.equal(await rows.count(), 3, 'one row per UAV');
  for (let i = 0; i < 3; i++) {
    const cells = await rows.nth(i).locator('td').allTextContents();
    assert.match(cells[0], /\d+ m/, 'length');
    assert.match(cells[1], /\d+ (s|min)/, 'time');
    assert.ok(Number(cells[2].replace(/\D/g, '')) > 0, 'photos');
  }
  const totals = await page.textContent('#survey-totals');
  assert.match(totals, /Area.*ha/);
  assert.match(totals, /GSD.*cm\/px/);
  assert.match(totals, /Coverage.*%/);

  // Three routes in three different colours, really drawn on the map.
  const colours = await page.$$eval('#uav-table tbody .swatch', (s) => s.map((e) => getComputedStyle(e).backgroundColor));
  assert.equal(new Set(colours).size, 3, `three distinct colours: ${colours}`);
  await page.waitForTimeout(500);
  const pixels = await countMapPixels(page, colours);
  for (const [i, n] of pixels.entries()) assert.ok(n > 50, `UAV ${i + 1}'s route is drawn (${n} pixels of ${colours[i]})`);

  // The altitude profile over the terrain.
  assert.equal(await page.locator('#profile-chart svg path.terrain').count(), 1);
  assert.equal(await page.locator('#profile-chart svg path.flown').count(), 1);
  // The sortie chooser shows only for a UAV flying several sorties.
  const newest = (await (await fetch(`${env.server.url}/api/v1/surveys?limit=1`)).json()).items[0];
  const planned = await (await fetch(`${env.server.url}/api/v1/surveys/${newest.id}`)).json();
  const charted = await page.inputValue('#profile-uav');
  const sorties = planned.uavs.find((u) => u.id === charted).sorties.length;
  assert.equal(await page.locator('#profile-sortie-field').isVisible(), sorties > 1, `${sorties} sortie(s)`);
  assert.equal(await page.locator('#profile-sortie option').count(), sorties);

  await screenshot(page, 'survey-3-uavs');

  // Download uav1's mission through the page's link and load it with pymavlink.
  const [download] = await Promise.all([
    page.waitForEvent('download'),
    page.click('a[aria-label="uav1 mission waypoints"]'),
  ]);
  const dir = mkdtempSync(path.join(tmpdir(), 'terraplan-dl-'));
  const file = path.join(dir, download.suggestedFilename());
  await download.saveAs(file);
  assert.match(download.suggestedFilename(), /\.waypoints$/);
  const mission = loadWaypoints(file);
  const items = mission.items;
  assert.ok(mission.count > 5 && items.length === mission.count, `pymavlink loaded ${mission.count} items`);
  const nav = items.filter((w) => w.command === 16 && w.seq > 0); // MAV_CMD_NAV_WAYPOINT, not home
  assert.ok(nav.length > 2, 'navigation waypoints');
  for (const { lat, lon } of nav) {
    assert.ok(lon > -77.0565 && lon < -77.049 && lat > 38.808 && lat < 38.8125, `waypoint ${lon},${lat} near the area`);
  }

  // The tablet layout: map above, panel below.
  await page.setViewportSize({ width: 768, height: 1024 });
  await page.waitForTimeout(400);
  await screenshot(page, 'survey-tablet-768');
  const mapBox = await page.locator('#map').boundingBox();
  const panelBox = await page.locator('#panel').boundingBox();
  assert.ok(panelBox.y >= mapBox.y + mapBox.height - 1, 'the panel is below the map at 768 px');

  assert.deepEqual(outside, [], 'no request left the local server');
  assert.deepEqual(problems, []);
  await context.close();
});

test('import the area from GeoJSON and no-fly zones from KML', async () => {
  const { page, context, problems } = await openPage(env.browser, env.server.url);
  const dir = mkdtempSync(path.join(tmpdir(), 'terraplan-import-'));
  const roiFile = path.join(dir, 'field.geojson');
  writeFileSync(roiFile, JSON.stringify({
    type: 'FeatureCollection',
    features: [{ type: 'Feature', properties: {}, geometry: { type: 'Polygon', coordinates: [[...ROI, ROI[0]].map(([x, y]) => [x, y, 12])] } }],
  }));
  const nfzFile = path.join(dir, 'nfz.kml');
  const coords = [...NFZ, NFZ[0]].map(([x, y]) => `${x},${y},0`).join(' ');
  writeFileSync(nfzFile, `<?xml version="1.0"?><kml xmlns="http://www.opengis.net/kml/2.2"><Placemark><Polygon><outerBoundaryIs><LinearRing><coordinates>${coords}</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark></kml>`);
  await page.setInputFiles('#import-roi', roiFile);
  await page.waitForFunction(() => /4 corners/.test(document.querySelector('#roi-status').textContent));
  await page.setInputFiles('#import-nfz', nfzFile);
  await page.waitForSelector('#nfz-list li');
  assert.equal(await page.locator('#nfz-list li').count(), 1);
  // Without a DEM and without UAVs placed: one UAV at the area's first corner.
  await page.click('#plan-survey');
  await page.waitForSelector('#survey-results:not([hidden])', { timeout: 60_000 });
  assert.equal(await page.locator('#uav-table tbody tr').count(), 1);
  await screenshot(page, 'survey-imported');
  assert.deepEqual(problems, []);
  await context.close();
});
