// API faults shown next to the control they concern: a self-intersecting ROI
// drawn with the mouse → the server's 422 (/roi/...) → a plain-words message
// in the survey-area section. Also: a route start outside the costmap.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { withServerAndBrowser, openPage, drawPolygon, uploadDtm, screenshot } from './helpers.mjs';

const env = withServerAndBrowser();

test('a self-intersecting ROI gets a plain-words error next to the area controls', async () => {
  const { page, context, problems } = await openPage(env.browser, env.server.url);
  await uploadDtm(page);
  // A bow tie: the edge from the first to the second corner crosses the third edge.
  await drawPolygon(page, '#draw-roi', [[-77.0545, 38.8090], [-77.0515, 38.8115], [-77.0515, 38.8090], [-77.0545, 38.8115]]);
  await page.waitForFunction(() => /4 corners/.test(document.querySelector('#roi-status').textContent));
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
  await context.close();
});
