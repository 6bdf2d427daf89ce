// API faults shown next to the control they concern: a self-intersecting ROI
// drawn with the mouse → the server's 422 (/roi/...) → a plain-words message
// in the survey-area section. Also: a costmap vehicle out of range, and a
// route whose start is off the costmap and whose goal is on an obstacle.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import path from 'node:path';
import { withServerAndBrowser, openPage, drawPolygon, uploadDtm, screenshot, ROOT } from './helpers.mjs';

// On the DTM's u-go costmap: west of the DTM (it ends at lon −77.0559), and the middle of a 5 × 5 block of step cells (a building).
const OFF_THE_MAP = '-77.0600, 38.8100';
const ON_A_STEP = '-77.053493, 38.812177';

const env = withServerAndBrowser();

test('a self-intersecting ROI gets a plain-words error next to the area controls', async () => {
  const { page, context, problems } = await openPage(env.browser, env.server.url);
  await uploadDtm(page);
  // A bow tie: the edge from the first to the second corner crosses the third edge.
  await drawPolygon(page, '#draw-roi', [[-77.0545, 38.8090], [-77.0515, 38.8115], [-77.0515, 38.8090], [-77.0545, 38.8115]]);
  await page.waitForFunction(() => /4 corners/.test(document.querySelector('#roi-status').textContent));
  // No area figure for it (a bow tie's halves would cancel to 0 m²).
  assert.equal(await page.textContent('#roi-status'), 'Area: outline crosses itself, 4 corners.');
  await page.click('#plan-survey');

  const error = page.locator('#survey-roi-error');
  await error.waitFor({ state: 'visible', timeout: 30_000 });
  const text = await error.textContent();
  assert.match(text, /^Survey area: the outline crosses itself near lon -77\.\d+, lat 38\.\d+\. Redraw it/);
  // It sits in the survey-area section, right under the area's controls, and marks them invalid.
  assert.equal(await error.evaluate((e) => e.closest('section').id || e.closest('section').getAttribute('aria-labelledby')), 'roi-heading');
  assert.equal(await page.getAttribute('#draw-roi', 'aria-invalid'), 'true');
  assert.equal(await page.locator('#survey-form-error').isVisible(), false, 'not dumped in the form-wide slot');
  await error.scrollIntoViewIfNeeded();
  await screenshot(page, 'error-self-intersecting-roi');

  // Drawing a proper area clears the fault on the next plan.
  assert.deepEqual(problems.filter((p) => !/422/.test(p)), []);
  await context.close();
});

test('planning with nothing drawn says what to do, without asking the server', async () => {
  const { page, context } = await openPage(env.browser, env.server.url);
  await page.click('#plan-survey');
  await page.locator('#survey-roi-error').waitFor({ state: 'visible' });
  assert.match(await page.textContent('#survey-roi-error'), /draw it on the map or import a file/);

  // A take-off point typed wrong is said at once, and again when planning (not planned from where it was).
  await page.click('#place-uavs');
  await page.locator('#map').click({ position: { x: 300, y: 300 } });
  await page.keyboard.press('Escape');
  await page.fill('#uav-start-0', '40.40 39.49x');
  await page.dispatchEvent('#uav-start-0', 'change');
  const uavError = page.locator('#survey-uavs-error');
  await uavError.waitFor({ state: 'visible' });
  assert.equal(await uavError.textContent(), 'uav1 start: give it as “lon, lat” in degrees, e.g. -77.0551, 38.8089.');
  assert.equal(await page.getAttribute('#uav-start-0', 'aria-invalid'), 'true');
  await page.click('#plan-survey');
  await uavError.waitFor({ state: 'visible' });
  assert.equal(await page.getAttribute('#uav-start-0', 'aria-invalid'), 'true');
  await context.close();
});

test('the page is usable with the keyboard alone: tabs, labels, survey form', async () => {
  const { page, context } = await openPage(env.browser, env.server.url);
  // Every form control has a label.
  const unlabelled = await page.$$eval('input, select, textarea', (els) =>
    els.filter((e) => e.type !== 'hidden' && !e.labels?.length && !e.getAttribute('aria-label')).map((e) => e.id || e.outerHTML));
  assert.deepEqual(unlabelled, []);
  // Arrow keys move between the tabs.
  await page.focus('#tab-survey');
  await page.keyboard.press('ArrowRight');
  assert.equal(await page.getAttribute('#tab-route', 'aria-selected'), 'true');
  assert.equal(await page.locator('#route-panel').isVisible(), true);
  await page.keyboard.press('ArrowRight');
  assert.equal(await page.getAttribute('#tab-saved', 'aria-selected'), 'true');

  // Take-off points typed, Enter to add (not to submit the survey form), without the mouse.
  await page.focus('#tab-survey');
  await page.keyboard.press('Enter');
  await page.focus('#uav-add');
  await page.keyboard.type('-77.0551, 38.8089');
  await page.keyboard.press('Enter');
  await page.keyboard.type('-77.0526 38.8089');
  await page.keyboard.press('Enter');
  assert.equal(await page.locator('#uav-list li').count(), 2);
  assert.equal(await page.inputValue('#uav-start-1'), '-77.052600, 38.808900');
  assert.equal(await page.locator('#survey-roi-error').isVisible(), false, 'Enter did not submit the form');
  await page.keyboard.type('west of here');
  await page.keyboard.press('Enter');
  assert.match(await page.textContent('#survey-uavs-error'), /^Take-off point: give it as “lon, lat”/);
  assert.equal(await page.getAttribute('#uav-add', 'aria-invalid'), 'true');
  await context.close();
});

test('costmap and route faults are shown at their fields in plain words', async () => {
  const { page, context, problems } = await openPage(env.browser, env.server.url);
  await uploadDtm(page);
  await page.click('#tab-route');

  // A slope limit the API does not take: shown at the vehicle's fields, not built.
  await page.fill('#max-slope', '75');
  await page.click('#build-costmap');
  const vehicleError = page.locator('#costmap-vehicle-error');
  await vehicleError.waitFor({ state: 'visible', timeout: 30_000 });
  const vehicleText = await vehicleError.textContent();
  assert.match(vehicleText, /^Max slope: .*75/, vehicleText);
  assert.equal(await page.getAttribute('#max-slope', 'aria-invalid'), 'true');

  await page.fill('#max-slope', '');
  await page.click('#build-costmap');
  await page.waitForFunction(() => /Costmap ready/.test(document.querySelector('#costmap-status').textContent), null, { timeout: 60_000 });
  assert.equal(await vehicleError.isVisible(), false, 'the fault is cleared by the next build');

  // Start off the map, goal on a building: each said at its own field.
  await page.keyboard.press('Escape');
  await page.fill('#route-start', OFF_THE_MAP);
  await page.fill('#route-goal', ON_A_STEP);
  await page.click('#plan-route');
  await page.locator('#route-start-error').waitFor({ state: 'visible', timeout: 30_000 });
  const startText = await page.textContent('#route-start-error');
  assert.match(startText, /^Start: .*outside/, startText);
  assert.equal(await page.getAttribute('#route-start', 'aria-invalid'), 'true');
  await page.fill('#route-start', '-77.05430, 38.81068');
  await page.click('#plan-route');
  await page.locator('#route-goal-error').waitFor({ state: 'visible', timeout: 30_000 });
  const goalText = await page.textContent('#route-goal-error');
  assert.match(goalText, /^Goal: the goal \(lon -77\.053493, lat 38\.812177\) is on an obstacle \(a step higher than the vehicle can climb\)/, goalText);
  assert.equal(await page.locator('#route-start-error').isVisible(), false);
  // Typed ends: the map no longer waits for a click.
  assert.doesNotMatch(await page.textContent('#map-hint'), /Click the ground route/);
  await page.locator('#route-goal-error').scrollIntoViewIfNeeded();
  await screenshot(page, 'error-route-goal-on-obstacle');
  assert.deepEqual(problems.filter((p) => !/422/.test(p)), []);
  await context.close();
});

test('a DEM that does not give its CRS is asked for one at the CRS field, then placed', async () => {
  const { page, context, problems } = await openPage(env.browser, env.server.url);
  // A real ESRI ASCII grid (landlab's West Bijou gully, Colorado: UTM zone 13 metres) without a .prj.
  const asc = path.resolve(ROOT, '../shared/data/dems/landlab__west_bijou_gully.asc');
  await page.setInputFiles('#dem-file', asc);
  const crsError = page.locator('#dem-crs-error');
  await crsError.waitFor({ state: 'visible', timeout: 30_000 });
  assert.equal(await crsError.textContent(), 'landlab__west_bijou_gully.asc does not say which coordinate system it is in. Give its EPSG code here and choose the file again.');
  assert.equal(await page.getAttribute('#dem-crs', 'aria-invalid'), 'true');
  assert.equal(await page.inputValue('#dem-select'), '', 'nothing chosen');

  // Not an EPSG code: said before uploading.
  await page.fill('#dem-crs', 'UTM 13');
  await page.setInputFiles('#dem-file', asc);
  await page.waitForFunction(() => /give an EPSG code such as 32633/.test(document.querySelector('#dem-crs-error').textContent));

  await page.fill('#dem-crs', '32613');
  await page.setInputFiles('#dem-file', asc);
  await page.waitForFunction(() => document.querySelector('#dem-select').value !== '', null, { timeout: 30_000 });
  const status = await page.textContent('#dem-status');
  assert.match(status, /^43 × 89 cells of 3\.00 m, WGS 84 \/ UTM zone 13N; heights/, status);
  assert.equal(await crsError.isVisible(), false);
  await page.waitForTimeout(500);
  await screenshot(page, 'dem-asc-with-crs');
  assert.deepEqual(problems.filter((p) => !/422/.test(p)), []);
  await context.close();
});
