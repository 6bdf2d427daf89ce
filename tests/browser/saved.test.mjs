// Saved work: surveys, costmaps and routes made through the API are listed,
// reopen on the map, and can be deleted from the page.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { withServerAndBrowser, openPage, screenshot, DTM } from './helpers.mjs';

const env = withServerAndBrowser();

async function post(path, body, type = 'application/json') {
  const res = await env.server.fetch(path, { method: 'POST', headers: { 'Content-Type': type }, body });
  assert.ok(res.ok, `${path}: ${res.status} ${await res.clone().text()}`);
  return res.json();
}

test('list, reopen and delete saved surveys, costmaps and routes', async () => {
  const dem = await post('/api/v1/dems?name=dtm', readFileSync(DTM), 'image/tiff');
  const roi = { type: 'Polygon', coordinates: [[[-77.0550, 38.8090], [-77.0527, 38.8090], [-77.0527, 38.8114], [-77.0550, 38.8114], [-77.0550, 38.8090]]] };
  const nfz = { type: 'Polygon', coordinates: [[[-77.0542, 38.8100], [-77.0536, 38.8100], [-77.0536, 38.8104], [-77.0542, 38.8104], [-77.0542, 38.8100]]] };
  const survey = await post('/api/v1/surveys', JSON.stringify({
    name: 'saved field', roi, no_fly_zones: [nfz], dem_id: dem.id,
    camera_preset: 'dji_mavic2_pro', gsd_cm_px: 2, front_overlap: 0.75, side_overlap: 0.65, slice_angle_deg: 30,
    speed_m_s: 8, assignment: 'competition', turn_penalty_s: 3, nfz_clearance_m: 6.5,
    uavs: [{ id: 'a', start: [-77.0551, 38.8089], speed_m_s: 6 }, { id: 'b', start: [-77.0526, 38.8089] }],
  }));
  let costmap = await post('/api/v1/costmaps', JSON.stringify({ name: 'u-go map', dem_id: dem.id }));
  for (let i = 0; i < 100 && costmap.status !== 'done'; i++) {
    await new Promise((r) => setTimeout(r, 200));
    costmap = await (await env.server.fetch(`/api/v1/costmaps/${costmap.id}`)).json();
  }
  assert.equal(costmap.status, 'done');
  await post(`/api/v1/costmaps/${costmap.id}/routes`, JSON.stringify({ name: 'to the gate', start: [-77.0543, 38.81068], goal: [-77.05512, 38.80874] }));

  const { page, context, problems } = await openPage(env.browser, env.server.url);
  page.on('dialog', (d) => d.accept());
  await page.click('#tab-saved');
  await page.waitForSelector('#saved-surveys li strong');
  assert.equal(await page.textContent('#saved-surveys li strong'), 'saved field');
  assert.equal(await page.textContent('#saved-costmaps li strong'), 'u-go map');
  assert.equal(await page.textContent('#saved-routes li strong'), 'to the gate');

  // Reopen the survey: its table and routes come back, and so do its area,
  // no-fly zone, settings and take-off points, ready to edit and plan again.
  await page.click('button[aria-label="Open saved field"]');
  await page.waitForSelector('#survey-results:not([hidden])');
  await page.waitForSelector('#survey-reopened:not([hidden])');
  assert.equal(await page.locator('#uav-table tbody tr').count(), 2);
  assert.equal(await page.getAttribute('#tab-survey', 'aria-selected'), 'true');
  const areas = await page.evaluate(() => window.terraplan.areas());
  assert.equal(areas.roi.length, 1);
  assert.equal(areas.roi[0].length, 5);
  areas.roi[0].forEach((p, i) => {
    assert.ok(Math.hypot(p[0] - roi.coordinates[0][i][0], p[1] - roi.coordinates[0][i][1]) < 1e-9, `ROI corner ${i}: ${p}`);
  });
  assert.equal(areas.nfz.length, 1);
  assert.match(await page.textContent('#roi-status'), /^Area: \d+\.\d\d ha, 4 corners\.$/);
  assert.equal(await page.locator('#nfz-list li').count(), 1);
  assert.equal(await page.inputValue('#survey-name'), 'saved field');
  assert.equal(await page.locator('#survey-stale').isVisible(), false, 'a reopened plan is not stale');
  assert.equal(await page.evaluate(() => document.querySelector('#panel').scrollTop), 0, 'the panel shows the reopened note from the top');
  assert.equal(await page.inputValue('#camera'), 'dji_mavic2_pro');
  assert.match(await page.textContent('#camera-numbers'), /focal length 10\.26 mm/);
  assert.equal(await page.isChecked('#height-mode-gsd'), true);
  assert.match(await page.textContent('#flight-geometry'), /^altitude \d+\.\d m; each photo covers/);
  assert.equal(await page.isDisabled('#altitude'), true);
  assert.equal(await page.inputValue('#gsd'), '2');
  assert.equal(await page.inputValue('#front-overlap'), '75');
  assert.equal(await page.inputValue('#side-overlap'), '65');
  assert.equal(await page.inputValue('#slice-angle'), '30');
  assert.equal(await page.inputValue('#speed'), '8');
  assert.equal(await page.inputValue('#nfz-clearance'), '6.5');
  assert.equal(await page.inputValue('#altitude-frame'), 'relative');
  assert.equal(await page.inputValue('#assignment'), 'competition');
  assert.equal(await page.isChecked('#follow-terrain'), true);
  assert.equal(await page.inputValue('#dem-select'), dem.id);
  assert.equal(await page.inputValue('#uav-start-0'), '-77.055100, 38.808900');
  assert.equal(await page.inputValue('#uav-start-1'), '-77.052600, 38.808900');
  assert.match(await page.textContent('#survey-extra-text'), /turn_penalty_s 3/);
  await page.waitForTimeout(500);
  await screenshot(page, 'saved-survey-reopened');

  // "Custom" starts from the chosen preset's numbers.
  await page.selectOption('#camera', 'custom');
  assert.equal(await page.inputValue('#cam-f'), '10.26');
  await page.selectOption('#camera', 'dji_mavic2_pro');

  // Edit: drag the north-west corner of the area, rename, and plan again.
  const from = await page.evaluate(() => window.terraplan.pixelFor(-77.0550, 38.8114));
  const to = await page.evaluate(() => window.terraplan.pixelFor(-77.0553, 38.8117));
  await page.mouse.move(from[0], from[1]);
  await page.mouse.down();
  await page.mouse.move(to[0], to[1], { steps: 8 });
  await page.mouse.up();
  await page.fill('#survey-name', 'saved field v2');
  await page.click('#plan-survey');
  await page.waitForFunction(() => document.querySelector('#results-heading').textContent === 'Plan: saved field v2', null, { timeout: 30_000 });
  const surveys = await (await env.server.fetch(`/api/v1/surveys`)).json();
  const again = await (await env.server.fetch(`/api/v1/surveys/${surveys.items.find((s) => s.name === 'saved field v2').id}`)).json();
  const moved = again.request.roi.coordinates[0].find((p) => p[0] < -77.0551);
  assert.ok(moved && Math.abs(moved[0] + 77.0553) < 2e-5 && Math.abs(moved[1] - 38.8117) < 2e-5, `moved corner: ${moved}`);
  assert.equal(again.request.no_fly_zones.length, 1);
  assert.equal(again.request.camera_preset, 'dji_mavic2_pro');
  assert.equal(again.request.gsd_cm_px, 2);
  assert.equal(again.request.turn_penalty_s, 3);
  assert.equal(again.request.nfz_clearance_m, 6.5);
  assert.equal(again.request.dem_id, dem.id);
  assert.deepEqual(again.request.uavs, [{ id: 'a', start: [-77.0551, 38.8089], speed_m_s: 6 }, { id: 'b', start: [-77.0526, 38.8089] }]);

  // Reopen the route: its DEM, costmap overlay and statistics come back.
  await page.click('#tab-saved');
  await page.click('button[aria-label="Open to the gate"]');
  await page.waitForSelector('#route-result:not([hidden])');
  assert.match(await page.textContent('#route-stats'), /Length \(2D\)\s*3\d\d m/);
  assert.equal(await page.inputValue('#dem-select'), dem.id);
  await screenshot(page, 'saved-route-reopened');

  // On the route tab the survey's (hidden) area cannot be dragged by accident.
  const before = await page.evaluate(() => window.terraplan.areas().roi);
  const corner = await page.evaluate(() => window.terraplan.pixelFor(-77.0527, 38.8090));
  const away = await page.evaluate(() => window.terraplan.pixelFor(-77.0520, 38.8085));
  await page.mouse.move(corner[0], corner[1]);
  await page.mouse.down();
  await page.mouse.move(away[0], away[1], { steps: 8 });
  await page.mouse.up();
  assert.deepEqual(await page.evaluate(() => window.terraplan.areas().roi), before, 'the hidden area is unchanged');

  // Delete the survey, then the costmap (its routes go with it).
  await page.click('#tab-saved');
  await page.click('button[aria-label="Delete saved field"]');
  await page.waitForFunction(() => document.querySelectorAll('#saved-surveys li').length === 1);
  await page.click('button[aria-label="Delete saved field v2"]');
  await page.waitForFunction(() => document.querySelector('#saved-surveys li')?.textContent === 'None yet.');
  await page.click('button[aria-label="Delete u-go map"]');
  await page.waitForFunction(() => document.querySelector('#saved-routes li')?.textContent === 'None yet.');
  assert.equal((await (await env.server.fetch(`/api/v1/surveys/${survey.id}`)).status), 404);
  await screenshot(page, 'saved-after-delete');

  // After a reload the DEM chosen last is the base map again.
  await page.reload();
  await page.waitForSelector('body[data-ready="true"]');
  assert.equal(await page.inputValue('#dem-select'), dem.id);
  assert.equal(await page.locator('#map-empty').isVisible(), false);
  assert.deepEqual(problems, []);
  await context.close();
});
