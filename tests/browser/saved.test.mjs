// Saved work: surveys, costmaps and routes made through the API are listed,
// reopen on the map, and can be deleted from the page.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { startServer, launchBrowser, openPage, screenshot, DTM } from './helpers.mjs';

let server;
let browser;
before(async () => {
  server = await startServer();
  browser = await launchBrowser();
});
after(async () => {
  await browser?.close();
  await server?.stop();
});

async function post(path, body, type = 'application/json') {
  const res = await fetch(`${server.url}${path}`, { method: 'POST', headers: { 'Content-Type': type }, body });
  assert.ok(res.ok, `${path}: ${res.status} ${await res.clone().text()}`);
  return res.json();
}

test('list, reopen and delete saved surveys, costmaps and routes', async () => {
  const dem = await post('/api/v1/dems?name=dtm', readFileSync(DTM), 'image/tiff');
  const roi = { type: 'Polygon', coordinates: [[[-77.0550, 38.8090], [-77.0527, 38.8090], [-77.0527, 38.8114], [-77.0550, 38.8114], [-77.0550, 38.8090]]] };
  const survey = await post('/api/v1/surveys', JSON.stringify({
    name: 'saved field', roi, dem_id: dem.id,
    uavs: [{ id: 'a', start: [-77.0551, 38.8089] }, { id: 'b', start: [-77.0526, 38.8089] }],
  }));
  let costmap = await post('/api/v1/costmaps', JSON.stringify({ name: 'u-go map', dem_id: dem.id }));
  for (let i = 0; i < 100 && costmap.status !== 'done'; i++) {
    await new Promise((r) => setTimeout(r, 200));
    costmap = await (await fetch(`${server.url}/api/v1/costmaps/${costmap.id}`)).json();
  }
  assert.equal(costmap.status, 'done');
  await post(`/api/v1/costmaps/${costmap.id}/routes`, JSON.stringify({ name: 'to the gate', start: [-77.0543, 38.81068], goal: [-77.05512, 38.80874] }));

  const { page, context, problems } = await openPage(browser, server.url);
  page.on('dialog', (d) => d.accept());
  await page.click('#tab-saved');
  await page.waitForSelector('#saved-surveys li strong');
  assert.equal(await page.textContent('#saved-surveys li strong'), 'saved field');
  assert.equal(await page.textContent('#saved-costmaps li strong'), 'u-go map');
  assert.equal(await page.textContent('#saved-routes li strong'), 'to the gate');

  // Reopen the survey: its table and routes come back.
  await page.click('button[aria-label="Open saved field"]');
  await page.waitForSelector('#survey-results:not([hidden])');
  assert.equal(await page.locator('#uav-table tbody tr').count(), 2);
  assert.equal(await page.getAttribute('#tab-survey', 'aria-selected'), 'true');

  // Reopen the route: its DEM, costmap overlay and statistics come back.
  await page.click('#tab-saved');
  await page.click('button[aria-label="Open to the gate"]');
  await page.waitForSelector('#route-result:not([hidden])');
  assert.match(await page.textContent('#route-stats'), /Length \(2D\)\s*3\d\d m/);
  assert.equal(await page.inputValue('#dem-select'), dem.id);
  await screenshot(page, 'saved-route-reopened');

  // Delete the survey, then the costmap (its routes go with it).
  await page.click('#tab-saved');
  await page.click('button[aria-label="Delete saved field"]');
  await page.waitForFunction(() => document.querySelector('#saved-surveys li')?.textContent === 'None yet.');
  await page.click('button[aria-label="Delete u-go map"]');
  await page.waitForFunction(() => document.querySelector('#saved-routes li')?.textContent === 'None yet.');
  assert.equal((await (await fetch(`${server.url}/api/v1/surveys/${survey.id}`)).status), 404);
  await screenshot(page, 'saved-after-delete');
  assert.deepEqual(problems, []);
  await context.close();
});
