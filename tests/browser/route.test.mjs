// Ground routes end to end in the browser: build a costmap of the real DTM
// (progress over SSE), click start and goal on the map, plan, check the route
// and its statistics; block part of it and replan; make part of it costlier and
// replan again; download the rover mission.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import path from 'node:path';
import { withServerAndBrowser, openPage, clickLonLat, drawPolygon, uploadDtm, screenshot, loadWaypoints, tempDir } from './helpers.mjs';

// Traversable ground for the default vehicle (u-go) on the DTM's costmap (see README: Ground routes).
const START = [-77.05430, 38.81068];
const GOAL = [-77.05512, 38.80874];

const env = withServerAndBrowser();

test('build a costmap, click start and goal, plan, block and replan', async () => {
  const { page, context, problems, outside } = await openPage(env.browser, env.server.url);
  await uploadDtm(page);
  await page.click('#tab-route');
  assert.equal(await page.inputValue('#vehicle'), 'u-go');
  // The preset's numbers (from GET /api/v1/vehicles) and what the map does on this tab.
  assert.equal(await page.textContent('#vehicle-numbers'), '0.88 × 0.75 m (width × length); climbs steps up to 0.15 m and slopes up to 25°.');
  assert.match(await page.textContent('#map-hint'), /pick the start and the goal/);

  // Watch the progress bar while the job runs (it may be quick on this DTM).
  await page.click('#build-costmap');
  await page.waitForFunction(() => /Costmap ready/.test(document.querySelector('#costmap-status').textContent), null, { timeout: 60_000 });
  assert.ok(await page.locator('#costmap-view').isVisible());
  assert.ok(await page.locator('#costmap-legend').evaluate((img) => img.complete && img.naturalWidth > 0), 'legend shown');
  // The costlier-area hint gives this costmap's own cost range (its statistics).
  const costmaps = await (await env.server.fetch(`/api/v1/costmaps`)).json();
  const built = await (await env.server.fetch(`/api/v1/costmaps/${costmaps.items[0].id}`)).json();
  assert.match(await page.textContent('#cost-hint'), new RegExp(`cells cost ${built.stats.cost_min.toFixed(1)} to ${built.stats.cost_max.toFixed(1)}\\)`));

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
  const routes = await (await env.server.fetch(`/api/v1/routes?limit=1`)).json();
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

  // A costlier area across the detour: the cost is checked before drawing, sent with the replan
  // (only the new area: the earlier blocked square stays with the route), and shown on the map.
  const detour = (await (await env.server.fetch(`/api/v1/routes?limit=1`)).json()).items[0];
  assert.equal(detour.blocked.length, 1);
  assert.equal(detour.cost_changes.length, 0);
  assert.match(await page.textContent('#block-status'), /1 area blocked by earlier replans/);
  await page.fill('#cost-value', '0');
  await page.click('#draw-costlier');
  await page.waitForSelector('#route-cost-error:not([hidden])');
  assert.match(await page.textContent('#route-cost-error'), /greater than 0/);
  assert.equal(await page.getAttribute('#cost-value', 'aria-invalid'), 'true');
  await page.fill('#cost-value', '15');
  const third = detour.waypoints[Math.floor(detour.waypoints.length / 3)];
  const c = 0.00018; // about 15 m
  await drawPolygon(page, '#draw-costlier', [
    [third.lon - c, third.lat - c], [third.lon + c, third.lat - c], [third.lon + c, third.lat + c], [third.lon - c, third.lat + c],
  ]);
  assert.ok(await page.locator('#route-cost-error').isHidden(), 'the error went with a valid cost');
  await page.waitForFunction(() => /1 costlier area to send \(cost 15\)/.test(document.querySelector('#costlier-status').textContent));
  const beforeCostlier = replanned;
  const [replanRequest] = await Promise.all([
    page.waitForRequest((r) => r.method() === 'POST' && r.url().endsWith('/replan')),
    page.click('#replan-route'),
  ]);
  const sent = replanRequest.postDataJSON();
  assert.equal(sent.blocked, undefined, 'the earlier blocked area is not sent again');
  assert.equal(sent.cost_changes.length, 1);
  assert.equal(sent.cost_changes[0].cost, 15);
  assert.equal(sent.cost_changes[0].area.type, 'Polygon');
  await page.waitForFunction((old) => document.querySelector('#route-stats').textContent !== old, beforeCostlier, { timeout: 60_000 });
  const costlier = (await (await env.server.fetch(`/api/v1/routes?limit=1`)).json()).items[0];
  assert.equal(costlier.parent_id, detour.id);
  assert.equal(costlier.cost_changes.length, 1, 'the new route carries the cost change');
  assert.equal(costlier.cost_changes[0].cost, 15);
  assert.equal(costlier.blocked.length, 1, 'the blocked area is not doubled');
  const moved = JSON.stringify(costlier.geometry.coordinates) !== JSON.stringify(detour.geometry.coordinates);
  assert.ok(moved || costlier.cost > detour.cost, `the route avoids the costlier area (moved: ${moved}) or costs more (${costlier.cost} > ${detour.cost})`);
  assert.match(await page.textContent('#costlier-status'), /No costlier area\. 1 area made costlier by earlier replans/);
  await screenshot(page, 'route-costlier');

  // "Clear" takes the costlier areas not yet sent off the map.
  await drawPolygon(page, '#draw-costlier', [
    [third.lon - c, third.lat - c], [third.lon + c, third.lat - c], [third.lon + c, third.lat + c],
  ]);
  await page.waitForFunction(() => /1 costlier area to send/.test(document.querySelector('#costlier-status').textContent));
  await page.click('#clear-costlier');
  assert.match(await page.textContent('#costlier-status'), /^No costlier area\./);

  // "Plan route" now would start from the costmap as built: the page asks before dropping the replans' areas.
  const routesBefore = (await (await env.server.fetch(`/api/v1/routes`)).json()).items.length;
  const dialog = new Promise((resolve) => page.once('dialog', async (d) => { resolve(d.message()); await d.dismiss(); }));
  await page.click('#plan-route');
  assert.match(await dialog, /does not keep the 2 blocked or costlier areas of the replans/);
  await page.waitForTimeout(300);
  assert.equal((await (await env.server.fetch(`/api/v1/routes`)).json()).items.length, routesBefore, 'declined: nothing planned');
  assert.match(await page.textContent('#block-status'), /1 area blocked by earlier replans/);

  // The rover mission loads in pymavlink.
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#route-downloads a[href$="mission.waypoints"]')]);
  const file = path.join(tempDir('terraplan-dl-'), download.suggestedFilename());
  await download.saveAs(file);
  const mission = loadWaypoints(file);
  assert.ok(mission.count > 3, `rover mission with ${mission.count} items`);

  assert.deepEqual(outside, [], 'no request left the local server');
  assert.deepEqual(problems, []);
  await context.close();
});

test('ends in one cell, ends forgotten with the DEM, and a route whose DEM was deleted', async () => {
  // The first test left a DEM, its costmap and routes on the server.
  const { page, context, problems } = await openPage(env.browser, env.server.url);
  const dems = (await (await env.server.fetch(`/api/v1/dems`)).json()).items;
  const costmaps = (await (await env.server.fetch(`/api/v1/costmaps`)).json()).items;
  await page.selectOption('#dem-select', dems[0].id);
  await page.click('#tab-route');
  await page.selectOption('#costmap-select', costmaps[0].id);
  await page.waitForSelector('#costmap-view:not([hidden])');

  // Start and goal typed into the same cell: planned, and said to be nothing to drive.
  await page.fill('#route-start', START.join(', '));
  await page.fill('#route-goal', `${START[0] + 1e-6}, ${START[1]}`);
  await page.click('#plan-route');
  await page.waitForFunction(() => /same cell: there is nothing to drive/.test(document.querySelector('#route-busy').textContent), null, { timeout: 30_000 });

  // Another terrain: the ends belonged to the one before.
  await page.selectOption('#dem-select', '');
  assert.equal(await page.inputValue('#route-start'), '');
  assert.equal(await page.inputValue('#route-goal'), '');

  // Delete the DEM behind the page's back, then reopen a route made on it from Saved work.
  const routes = (await (await env.server.fetch(`/api/v1/routes`)).json()).items;
  const longest = routes.reduce((a, b) => (b.length_2d_m > a.length_2d_m ? b : a));
  assert.equal((await env.server.fetch(`/api/v1/dems/${dems[0].id}`, { method: 'DELETE' })).status, 204);
  await page.click('#tab-saved');
  await page.click('#saved-refresh');
  await page.waitForFunction(() => document.querySelector('#saved-status').textContent === '');
  const title = longest.name ?? `Unnamed route #${longest.id.replace(/-/g, '').slice(-6)}`;
  await page.click(`button[aria-label="Open ${title}"]`);
  await page.waitForSelector('#route-result:not([hidden])');
  assert.match(await page.textContent('#dem-upload-error'), /has been deleted: what was made from it is shown without its hillshade/);
  // The costmap overlay is the base map now: no "no base map" note over it. The time falls back to the 2D length.
  assert.equal(await page.locator('#map-empty').isVisible(), false);
  const stats = await page.textContent('#route-stats');
  assert.doesNotMatch(stats, /Time0 s/, stats);
  assert.match(stats, /Time\d+ min \d+ s at/, stats);
  await screenshot(page, 'route-dem-deleted');
  assert.deepEqual(problems.filter((p) => !/404/.test(p)), []);
  await context.close();
});
