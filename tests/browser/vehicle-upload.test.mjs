// "Send to vehicle" on a real page and server started with
// `--vehicle-links udpout:127.0.0.1:*`: a saved survey is reopened, its
// sortie sent to the pymavlink vehicle (tests/validators/mavlink_vehicle.py)
// on a port typed into the form, the progress bar fills and the page says it
// was verified; what the vehicle stored equals the survey's mission file.
// A vehicle that refuses shows the server's message naming the refusal.

import { test, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import { readFileSync } from 'node:fs';
import path from 'node:path';
import readline from 'node:readline';
import { withServerAndBrowser, openPage, screenshot, tempDir, ROOT } from './helpers.mjs';

const env = withServerAndBrowser({ args: ['--vehicle-links', 'udpout:127.0.0.1:*'] });
const VEHICLES = [];
after(() => {
  for (const v of VEHICLES) v.kill('SIGTERM');
});

/** Starts the pymavlink vehicle on a free loopback port; resolves with its port and output file. */
async function startVehicle(extra = []) {
  const out = path.join(tempDir('vehicle-'), 'vehicle.json');
  const proc = spawn(path.join(ROOT, '.venv/bin/python'), [
    path.join(ROOT, 'tests/validators/mavlink_vehicle.py'), '--port', '0', '--out', out, '--max-seconds', '120', ...extra,
  ], { stdio: ['ignore', 'pipe', 'inherit'] });
  VEHICLES.push(proc);
  const line = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error('the vehicle did not start in 30 s')), 30_000);
    readline.createInterface({ input: proc.stdout }).once('line', (l) => {
      clearTimeout(timer);
      resolve(l);
    });
  });
  const m = /^READY (\d+)/.exec(line);
  assert.ok(m, `vehicle: ${line}`);
  return { port: Number(m[1]), out };
}

async function post(apiPath, body) {
  const res = await env.server.fetch(apiPath, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) });
  assert.ok(res.ok, `${apiPath}: ${res.status} ${await res.clone().text()}`);
  return res.json();
}

/** Degrees as MISSION_ITEM_INT carries them: ×1e7, halves rounded away from zero (as the server does). */
const wire = (deg) => Math.sign(Number(deg)) * Math.round(Math.abs(Number(deg) * 1e7));

/** The rows of the survey's mission file as MISSION_ITEM_INT x/y/command. */
async function missionRows(url) {
  const res = await env.server.fetch(url);
  assert.equal(res.status, 200);
  const lines = (await res.text()).trim().split('\n');
  assert.equal(lines[0], 'QGC WPL 110');
  return lines.slice(1).map((l) => {
    const c = l.split('\t');
    return { command: Number(c[3]), x: wire(c[8]), y: wire(c[9]) };
  });
}

test('a saved survey sent to a vehicle from the page, then a refusal shown', async () => {
  const roi = { type: 'Polygon', coordinates: [[[-77.0550, 38.8090], [-77.0527, 38.8090], [-77.0527, 38.8114], [-77.0550, 38.8114], [-77.0550, 38.8090]]] };
  const survey = await post('/api/v1/surveys', {
    name: 'to the vehicle', roi, altitude_m: 60, slice_angle_deg: 0,
    rally_points: [[-77.0552, 38.8088]],
    uavs: [{ id: 'a', start: [-77.0551, 38.8089] }],
  });
  const rows = await missionRows(survey.uavs[0].sorties[0].files.waypoints);
  const vehicle = await startVehicle();

  const { page, context, problems, outside } = await openPage(env.browser, env.server.url);
  await page.click('#tab-saved');
  await page.click('button[aria-label="Open to the vehicle"]');
  await page.waitForSelector('#survey-results:not([hidden])');
  const button = page.locator('button[aria-label="Send a to vehicle"]');
  await button.waitFor();
  await button.click();
  const form = page.locator('form[aria-label="Send a to a vehicle"]');
  await form.waitFor();
  // The only allowed entry is a pattern: the port is asked for.
  assert.equal(await form.locator('select option').allTextContents().then((t) => t.join()), 'udpout:127.0.0.1:*');
  await form.getByLabel('Port').fill(String(vehicle.port));
  assert.equal(await form.getByLabel('Rally points').isChecked(), true);
  await form.getByRole('button', { name: 'Send', exact: true }).click();
  const status = form.locator('.upload-status');
  await page.waitForFunction(() => /verified/.test(document.querySelector('form.vehicle-send .upload-status').textContent), null, { timeout: 60_000 });
  assert.match(await status.textContent(), new RegExp(`^Sent to udpout:127\\.0\\.0\\.1:${vehicle.port} and verified: ${rows.length} mission items, \\d+ fence items, 1 rally point\\.$`));
  assert.equal(await form.locator('progress').evaluate((p) => p.value), 1);
  assert.equal(await form.locator('.error').isVisible(), false);
  await screenshot(page, 'vehicle-upload-done');
  const stored = JSON.parse(readFileSync(vehicle.out, 'utf8'));
  assert.equal(stored.mission.length, rows.length);
  stored.mission.forEach((it, k) => {
    assert.deepEqual({ command: it.command, x: it.x, y: it.y }, rows[k], `mission item ${k}`);
  });
  assert.equal(stored.rally.length, 1);

  // A vehicle that refuses the mission: the failure is shown, naming it.
  const refusing = await startVehicle(['--nack', 'mission:MAV_MISSION_DENIED']);
  await form.getByLabel('Port').fill(String(refusing.port));
  await form.getByRole('button', { name: 'Send', exact: true }).click();
  const error = form.locator('.error');
  await error.waitFor({ state: 'visible', timeout: 60_000 });
  assert.match(await error.textContent(), /mission upload: the vehicle answered MAV_MISSION_DENIED/);
  assert.equal(await status.textContent(), 'The upload failed.');
  // A port the form cannot send: said before anything is sent.
  await form.getByLabel('Port').fill('70000');
  await form.getByRole('button', { name: 'Send', exact: true }).click();
  assert.match(await error.textContent(), /whole number from 1 to 65535/);
  assert.equal(await status.textContent(), '', 'the last outcome is cleared');
  await screenshot(page, 'vehicle-upload-refused');
  assert.deepEqual(problems, []);
  assert.deepEqual(outside, []);
  await context.close();
});
