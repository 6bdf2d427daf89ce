// Ground routes end to end in the browser: build a costmap of the real DTM
// (progress over SSE), click start and goal on the map, plan, check the route
// and its statistics; block part of it and replan; download the rover mission.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { startServer, launchBrowser, openPage, clickLonLat, drawPolygon, uploadDtm, screenshot, loadWaypoints } from './helpers.mjs';

// Traversable ground for the default vehicle (u-go) on the DTM's costmap (see README: Ground routes).
const START = [-77.05430, 38.81068];
const GOAL = [-77.05512, 38.80874];

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

test('build a costmap, click start and goal, plan, block and replan', async () => {
  const { page, context, problems, outside } = await openPage(browser, server.url);
  await uploadDtm(page);
  await page.click('#tab-route');
  assert.equal(await page.inputValue('#vehicle'), 'u-go');

  // Watch the progress bar while the job runs (it may be quick on this DTM).
  await page.click('#build-costmap');
  await page.waitForFunction(() => /Costmap ready/.test(document.querySelector('#costmap-status').textContent), null, { timeout: 60_000 });
  assert.ok(await page.locator('#costmap-view').isVisible());
  assert.ok(await page.locator('#costmap-legend').evaluate((img) => img.complete && img.naturalWidth > 0), 'legend shown');

  // After the costmap, the map waits for the start, then the goal.
  await clickLonLat(page, ...START);
  await clickLonLat(page, ...GOAL);
  assert.notEqual(await page.inputValue('#route-start'), '');
  assert.notEqual(await page.inputValue('#route-goal'), '');

  await page.click('#plan-route');
  await page.waitForSelector('#route-result:not([hidden])', { timeout: 60_000 });
  const stats = await page.textContent('#route-stats');
  const length = Number(/Length \(2D\)([\d,.]+) m/.exec(stats)?.[1].replace(/,/g, ''));
  assert.ok(length > 300 && length < 500, `route length ${length} m (the CLI finds 385 m)`);
  assert.match(stats, /Cost[\d,.]+/);
  assert.match(stats, /Max slope[\d.]+°/);
  assert.match(stats, /Time.*at 1\.2 m\/s/);
  const opacity = page.locator('#costmap-opacity');
  await opacity.fill('0.4');
  await screenshot(page, 'route-planned');

  // Block a square across the middle of the route (its waypoints from the API), replan from the start.
  const routes = await (await fetch(`${server.url}/api/v1/routes?limit=1`)).json();
  const wps = routes.items[0].waypoints;
  const mid = wps[Math.floor(wps.length / 2)];
  const d = 0.00012; // about 10 m
  await page.locator('#route-result').scrollIntoViewIfNeeded();
  await drawPolygon(page, '#draw-block', [
    [mid.lon - d, mid.lat - d], [mid.lon + d, mid.lat - d], [mid.lon + d, mid.lat + d], [mid.lon - d, mid.lat + d],
  ]);
  await page.waitForFunction(() => /1 blocked area/.test(document.querySelector('#block-status').textContent));
  const before = stats;
  await page.click('#replan-route');
  await page.waitForFunction((old) => document.querySelector('#route-stats').textContent !== old, before, { timeout: 60_000 });
  const replanned = await page.textContent('#route-stats');
  assert.match(replanned, /dstar_lite \(repaired\)/);
  // The cheapest route went through the blocked square: the new one costs more (it may be shorter).
  const costOf = (text) => Number(/Cost([\d,.]+)/.exec(text)?.[1].replace(/,/g, ''));
  assert.ok(costOf(replanned) > costOf(before), `the detour costs ${costOf(replanned)}, the blocked route ${costOf(before)}`);
  await screenshot(page, 'route-replanned');

  // The rover mission loads in pymavlink.
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#route-downloads a[href$="mission.waypoints"]')]);
  const file = path.join(mkdtempSync(path.join(tmpdir(), 'terraplan-dl-')), download.suggestedFilename());
  await download.saveAs(file);
  const mission = loadWaypoints(file);
  assert.ok(mission.count > 3, `rover mission with ${mission.count} items`);

  assert.deepEqual(outside, [], 'no request left the local server');
  assert.deepEqual(problems, []);
  await context.close();
});
