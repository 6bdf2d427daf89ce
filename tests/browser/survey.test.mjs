// Survey planning end to end in the browser: upload the real DTM, draw the
// ROI and a no-fly zone with mouse clicks, place three UAVs, plan, check the
// routes, the table and the profile, download a mission and load it with
// pymavlink.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { writeFileSync } from 'node:fs';
import path from 'node:path';
import {
  withServerAndBrowser, openPage, drawPolygon, clickLonLat, uploadDtm, screenshot, loadWaypoints, countMapPixels, tempDir, SCREENSHOTS,
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

  // Nothing to see yet: the map says how to get a base layer, until the DEM's hillshade is there.
  assert.equal(await page.locator('#map-empty').isVisible(), true);
  await uploadDtm(page);
  assert.match(await page.textContent('#dem-status'), /283 × 259 cells/);
  assert.equal(await page.locator('#map-empty').isVisible(), false);

  await drawPolygon(page, '#draw-roi', ROI);
  await page.waitForFunction(() => /4 corners/.test(document.querySelector('#roi-status').textContent));
  await drawPolygon(page, '#draw-nfz', NFZ);
  await page.waitForSelector('#nfz-list li');

  await page.click('#place-uavs');
  for (const [lon, lat] of STARTS) await clickLonLat(page, lon, lat);
  await page.keyboard.press('Escape'); // the map has focus after the clicks
  assert.equal(await page.locator('#uav-list li').count(), 3);
  // A wider clearance from the no-fly zone than the default 5 m.
  assert.equal(await page.inputValue('#nfz-clearance'), '5');
  await page.fill('#nfz-clearance', '7.5');

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
  // The area shown while drawing is measured as the planner measures it (in UTM): the same figure.
  const drawnHa = /Area: ([\d.]+) ha/.exec(await page.textContent('#roi-status'))[1];
  const plannedHa = /^Area([\d.]+) ha/.exec(totals)[1];
  assert.equal(drawnHa, plannedHa);
  // What the planner chose and derived, beside the totals (the API's numbers).
  const planStats = (await (await env.server.fetch(`/api/v1/surveys/${(await (await env.server.fetch(`/api/v1/surveys?limit=1`)).json()).items[0].id}`)).json()).stats;
  assert.match(totals, new RegExp(`Slice angle${planStats.slice_angle_deg.toFixed(1)}°`));
  assert.match(totals, new RegExp(`Lane spacing${planStats.line_spacing_m.toFixed(1)} m`));
  assert.match(totals, new RegExp(`Photo spacing${planStats.trigger_distance_m.toFixed(1)} m`));
  // The clearance typed was planned with, and what the cells tile is shown beside the free area.
  assert.equal(planStats.nfz_clearance_m, 7.5);
  assert.match(totals, /NFZ clearance7\.5 m/);
  const freeHa = Number(/Free area([\d.]+) ha/.exec(totals)[1]);
  const flyableHa = Number(/Flyable area([\d.]+) ha/.exec(totals)[1]);
  assert.equal(flyableHa, Number((planStats.flyable_area_m2 / 10_000).toFixed(2)));
  assert.ok(flyableHa < freeHa, `the clearance band is left out: ${flyableHa} < ${freeHa} ha`);
  // The flight geometry shown before planning is the server's.
  const gsd = /GSD([\d.]+) cm\/px/.exec(totals)[1];
  assert.match(await page.textContent('#flight-geometry'), new RegExp(`^GSD ${gsd.replace('.', '\\.')} cm/px; each photo covers`));
  assert.match(await page.textContent('#nfz-list li'), /^No-fly zone 1 \(0\.\d\d ha, 4 corners\)/);
  assert.match(totals, /GSD.*cm\/px/);
  assert.match(totals, /Coverage.*%/);

  // Three routes in three different colours, really drawn on the map.
  const colours = await page.$$eval('#uav-table tbody .swatch', (s) => s.map((e) => getComputedStyle(e).backgroundColor));
  assert.equal(new Set(colours).size, 3, `three distinct colours: ${colours}`);
  await page.waitForTimeout(500);
  const pixels = await countMapPixels(page, colours);
  for (const [i, n] of pixels.entries()) assert.ok(n > 50, `UAV ${i + 1}'s route is drawn (${n} pixels of ${colours[i]})`);

  // Clicking a UAV in the table charts it and brings its route forward: the others fade (far fewer pixels of their full colour).
  await page.click('#uav-table tbody tr:nth-child(2) button.link');
  assert.equal(await page.inputValue('#profile-uav'), 'uav2');
  assert.equal(await page.getAttribute('#uav-table tbody tr:nth-child(2) button.link', 'aria-pressed'), 'true');
  await page.waitForTimeout(300);
  const highlighted = await countMapPixels(page, colours);
  assert.ok(highlighted[1] >= pixels[1], `uav2 drawn thicker (${highlighted[1]} ≥ ${pixels[1]} pixels)`);
  for (const i of [0, 2]) assert.ok(highlighted[i] < pixels[i] / 4, `UAV ${i + 1} faded (${highlighted[i]} of ${pixels[i]} pixels)`);
  await screenshot(page, 'survey-uav2-highlighted');
  // Again: all alike.
  await page.click('#uav-table tbody tr:nth-child(2) button.link');
  await page.waitForTimeout(300);
  const again = await countMapPixels(page, colours);
  for (const i of [0, 2]) assert.ok(again[i] > pixels[i] / 2, `UAV ${i + 1} shown again (${again[i]} pixels)`);

  // The altitude profile over the terrain.
  assert.equal(await page.locator('#profile-chart svg path.terrain').count(), 1);
  assert.equal(await page.locator('#profile-chart svg path.flown').count(), 1);
  // The sortie chooser shows only for a UAV flying several sorties.
  const newest = (await (await env.server.fetch(`/api/v1/surveys?limit=1`)).json()).items[0];
  const planned = await (await env.server.fetch(`/api/v1/surveys/${newest.id}`)).json();
  const charted = await page.inputValue('#profile-uav');
  const sorties = planned.uavs.find((u) => u.id === charted).sorties.length;
  assert.equal(await page.locator('#profile-sortie-field').isVisible(), sorties > 1, `${sorties} sortie(s)`);
  assert.equal(await page.locator('#profile-sortie option').count(), sorties);

  await screenshot(page, 'survey-3-uavs');

  // The pointer's position reads in lon, lat; the fit button brings the plan back into view from elsewhere.
  const [px, py] = await page.evaluate(([lo, la]) => window.terraplan.pixelFor(lo, la), STARTS[1]);
  await page.mouse.move(px, py);
  const [mlon, mlat] = (await page.textContent('.mouse-position')).split(',').map(Number);
  assert.ok(Math.abs(mlon - STARTS[1][0]) < 2e-5 && Math.abs(mlat - STARTS[1][1]) < 2e-5, `pointer at ${mlon}, ${mlat}`);
  await page.evaluate(() => window.terraplan.fit([-77.2, 38.9, -77.19, 38.91]));
  await page.click('.fit-all button');
  await page.waitForTimeout(600);
  const mapRect = await page.locator('#map').boundingBox();
  for (const [lon, lat] of [...ROI, ...STARTS]) {
    const [x, y] = await page.evaluate(([lo, la]) => window.terraplan.pixelFor(lo, la), [lon, lat]);
    assert.ok(x > mapRect.x && x < mapRect.x + mapRect.width && y > mapRect.y && y < mapRect.y + mapRect.height, `${lon}, ${lat} in view after fitting`);
  }

  // Download uav1's mission through the page's link and load it with pymavlink.
  const [download] = await Promise.all([
    page.waitForEvent('download'),
    page.click('a[aria-label="uav1 mission waypoints"]'),
  ]);
  const dir = tempDir('terraplan-dl-');
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

  // Changing a setting after planning marks the shown plan as stale.
  assert.equal(await page.locator('#survey-stale').isVisible(), false);
  await page.fill('#altitude', '70');
  assert.equal(await page.locator('#survey-stale').isVisible(), true);
  await page.fill('#altitude', '60');

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

test('a battery limit splits a UAV’s mission into sorties, each charted and downloadable', async () => {
  const { page, context, problems } = await openPage(env.browser, env.server.url);
  await uploadDtm(page);
  await drawPolygon(page, '#draw-roi', ROI);
  await page.waitForFunction(() => /4 corners/.test(document.querySelector('#roi-status').textContent));
  await page.click('#place-uavs');
  await clickLonLat(page, ...STARTS[0]);
  await page.keyboard.press('Escape');

  // Far too small: getting from the take-off point to any cell and back takes longer. The fault is shown at the battery.
  // (Planned without the DEM: the take-off point is off it.)
  await page.uncheck('#follow-terrain');
  await page.fill('#battery', '0.5');
  await page.fill('#uav-start-0', '-77.0650, 38.8090'); // about 800 m west of the area
  await page.dispatchEvent('#uav-start-0', 'change');
  await page.click('#plan-survey');
  await page.waitForSelector('#survey-battery-error:not([hidden])', { timeout: 60_000 });
  const fault = await page.textContent('#survey-battery-error');
  assert.match(fault, /^Battery: UAV uav1 cannot fly one of the cells within its battery of 30 s: getting there and back alone takes \d+ min( \d+ s)?;/, fault);
  assert.doesNotMatch(fault, /max_flight_time_s/);
  assert.equal(await page.getAttribute('#battery', 'aria-invalid'), 'true');
  await screenshot(page, 'survey-battery-error');

  // 1.5 minutes from the area's corner: the ~13 minute mission needs several sorties.
  await page.fill('#uav-start-0', STARTS[0].join(', '));
  await page.dispatchEvent('#uav-start-0', 'change');
  await page.fill('#battery', '1.5');
  await page.check('#follow-terrain');
  await page.click('#plan-survey');
  await page.waitForFunction(() => document.querySelector('#survey-busy').textContent === 'Planned.', null, { timeout: 60_000 });
  assert.equal(await page.locator('#survey-battery-error').isVisible(), false);

  const newest = (await (await env.server.fetch(`/api/v1/surveys?limit=1`)).json()).items[0];
  const planned = await (await env.server.fetch(`/api/v1/surveys/${newest.id}`)).json();
  assert.equal(planned.request.uavs[0].max_flight_time_s, 90);
  const sorties = planned.uavs[0].sorties;
  assert.ok(sorties.length >= 2, `${sorties.length} sorties`);
  for (const so of sorties) assert.ok(so.stats.flight_time_s <= 90 + 1e-6, `sortie ${so.number}: ${so.stats.flight_time_s} s within the battery`);

  // The table's sorties column, the chooser, and one chart per sortie.
  assert.equal(await page.locator('#uav-table th.sorties-col').isVisible(), true);
  assert.equal((await page.locator('#uav-table tbody td.sorties-col').textContent()).trim(), String(sorties.length));
  assert.equal(await page.locator('#profile-sortie-field').isVisible(), true);
  assert.equal(await page.locator('#profile-sortie option').count(), sorties.length);
  await page.selectOption('#profile-sortie', '1');
  const title = await page.textContent('#profile-chart svg title');
  assert.equal(title, `Altitude profile of uav1 (sortie 2 of ${sorties.length})`);
  // The chart spans the second sortie's length, not the whole mission's.
  const xTicks = await page.$$eval('#profile-chart svg text.tick[text-anchor="middle"]', (t) => t.map((e) => Number(e.textContent)));
  const second = sorties[1].stats.length_3d_m ?? sorties[1].stats.length_m;
  assert.ok(xTicks.length > 1 && Math.max(...xTicks) <= second + 1, `distance ticks ${xTicks} within sortie 2's ${second} m`);
  assert.ok(Math.max(...xTicks) > second / 2, `distance ticks ${xTicks} span sortie 2's ${second} m`);
  await screenshot(page, 'survey-sorties');

  // The long results scroll inside the panel; the page itself (header, tabs) stays put.
  const page_ = await page.evaluate(() => ({ scrollHeight: document.documentElement.scrollHeight, innerHeight: window.innerHeight, scrollY: window.scrollY }));
  assert.ok(page_.scrollHeight <= page_.innerHeight && page_.scrollY === 0, `the page does not scroll: ${JSON.stringify(page_)}`);

  // One mission file per sortie: the second one loads in pymavlink and starts and ends at home.
  assert.equal(await page.locator('#uav-downloads li').count(), sorties.length);
  const [download] = await Promise.all([
    page.waitForEvent('download'),
    page.click('a[aria-label="uav1 mission waypoints (sortie 2)"]'),
  ]);
  const dir = tempDir('terraplan-dl-');
  const file = path.join(dir, download.suggestedFilename());
  await download.saveAs(file);
  const mission = loadWaypoints(file);
  const home = mission.items[0];
  assert.ok(Math.abs(home.lon - STARTS[0][0]) < 1e-6 && Math.abs(home.lat - STARTS[0][1]) < 1e-6, `home ${home.lon},${home.lat} is the take-off point`);
  const nav = mission.items.filter((w) => w.command === 16 && w.seq > 0);
  assert.ok(nav.length >= 2, `${nav.length} navigation waypoints`);

  // Only the battery fault's 422, answered on purpose.
  assert.deepEqual(problems.filter((p) => !/422/.test(p)), []);
  assert.equal(problems.length, 1);
  await context.close();
});

test('import the area from GeoJSON and no-fly zones from KML', async () => {
  const { page, context, problems } = await openPage(env.browser, env.server.url);
  const dir = tempDir('terraplan-import-');
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
  assert.equal(await page.locator('#clear-nfz').isVisible(), false, 'no "Remove all" for one zone');

  // Many zones (a file of building footprints) go with one button.
  const manyFile = path.join(dir, 'buildings.geojson');
  const box = (x, y) => ({ type: 'Feature', properties: {}, geometry: { type: 'Polygon', coordinates: [[[x, y], [x + 1e-4, y], [x + 1e-4, y + 1e-4], [x, y + 1e-4], [x, y]]] } });
  writeFileSync(manyFile, JSON.stringify({ type: 'FeatureCollection', features: [box(-77.0545, 38.8095), box(-77.0535, 38.8108), box(-77.0530, 38.8095)] }));
  await page.setInputFiles('#import-nfz', manyFile);
  await page.waitForFunction(() => document.querySelectorAll('#nfz-list li').length === 4);
  await page.click('#clear-nfz');
  assert.equal(await page.locator('#nfz-list li').count(), 0);
  assert.equal((await page.evaluate(() => window.terraplan.areas())).nfz.length, 0);
  await page.setInputFiles('#import-nfz', nfzFile);
  await page.waitForSelector('#nfz-list li');

  // A file in projected coordinates (metres) is refused at the import, not planned into nowhere.
  const utmFile = path.join(dir, 'utm.geojson');
  writeFileSync(utmFile, JSON.stringify({ type: 'Polygon', coordinates: [[[321600, 4297700], [321700, 4297700], [321700, 4297800], [321600, 4297700]]] }));
  await page.setInputFiles('#import-roi', utmFile);
  await page.locator('#survey-roi-error').waitFor({ state: 'visible' });
  assert.match(await page.textContent('#survey-roi-error'), /^utm\.geojson: A position \(321600, 4297700\) is not a longitude\/latitude/);
  assert.match(await page.textContent('#roi-status'), /4 corners/, 'the area imported before is kept');

  // Escape ends a drawing mode even with the focus still on the button that started it.
  await page.click('#draw-nfz');
  assert.match(await page.textContent('#map-hint'), /no-fly zone/);
  await page.keyboard.press('Escape');
  assert.match(await page.textContent('#map-hint'), /^Drag to pan/);

  // An emptied number field is a fault at that field, not a silent 0 % overlap.
  await page.fill('#front-overlap', '');
  await page.click('#plan-survey');
  await page.locator('#survey-front-overlap-error').waitFor({ state: 'visible' });
  assert.equal(await page.textContent('#survey-front-overlap-error'), 'Front overlap (%): give a number.');
  await page.fill('#front-overlap', '80');
  // So is an emptied clearance, and one out of range is the server's fault shown at the field.
  await page.fill('#nfz-clearance', '');
  await page.click('#plan-survey');
  await page.locator('#survey-nfz-clearance-error').waitFor({ state: 'visible' });
  assert.equal(await page.textContent('#survey-nfz-clearance-error'), 'Clearance from no-fly zones (m): give a number.');
  assert.equal(await page.getAttribute('#nfz-clearance', 'aria-invalid'), 'true');
  await page.fill('#nfz-clearance', '150');
  await page.click('#plan-survey');
  await page.waitForFunction(() => /outside the allowed range/.test(document.querySelector('#survey-nfz-clearance-error').textContent));
  assert.equal(await page.textContent('#survey-nfz-clearance-error'), 'Clearance from no-fly zones: 150 is outside the allowed range [0, 100]');
  await page.fill('#nfz-clearance', '5');
  // Without a DEM and without UAVs placed: one UAV at the area's first corner.
  await page.click('#plan-survey');
  await page.waitForSelector('#survey-results:not([hidden])', { timeout: 60_000 });
  assert.equal(await page.locator('#uav-table tbody tr').count(), 1);
  await screenshot(page, 'survey-imported');
  // The one 422 is the clearance out of range, asked for above.
  assert.deepEqual(problems.filter((p) => !/422/.test(p)), []);
  assert.equal(problems.length, 1);
  await context.close();
});
