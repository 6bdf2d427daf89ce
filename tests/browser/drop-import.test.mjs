// GIS files dropped on the page, read by the real server's POST /api/v1/imports:
// a KML (a field, a barn, a road and a mast point) dropped on the map, a zipped
// Shapefile in UTM 18N written by GDAL's ogr2ogr together with a broken zip,
// then a broken zip alone; the shapes go where the dialog says, the skipped
// point and the broken zip's fault are shown, a fault changes nothing, and
// the plan's stored request holds the imported area and no-fly zones. A
// GeoJSON in UTM (a `crs` member) chosen with the file chooser becomes the
// corridor line.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { spawnSync } from 'node:child_process';
import { readFileSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import { withServerAndBrowser, openPage, screenshot, tempDir } from './helpers.mjs';

// In the map's first view (Alexandria, where the other tests' DTM lies).
const FIELD = [[-77.0545, 38.8092], [-77.0515, 38.8092], [-77.0515, 38.8112], [-77.0545, 38.8112], [-77.0545, 38.8092]];
const BARN = [[-77.0540, 38.8095], [-77.0536, 38.8095], [-77.0536, 38.8098], [-77.0540, 38.8098], [-77.0540, 38.8095]];
const POND = [[-77.0525, 38.8104], [-77.0520, 38.8104], [-77.0520, 38.8108], [-77.0525, 38.8108], [-77.0525, 38.8104]];
const ROAD = [[-77.0548, 38.8090], [-77.0512, 38.8114]];

const kmlRing = (ring) => ring.map(([lon, lat]) => `${lon},${lat},0`).join(' ');
const FARM_KML = `<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2"><Document><Folder><name>farm</name>
<Placemark><name>barn</name><Polygon><outerBoundaryIs><LinearRing><coordinates>${kmlRing(BARN)}</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark>
<Placemark><name>field</name><Polygon><outerBoundaryIs><LinearRing><coordinates>${kmlRing(FIELD)}</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark>
<Placemark><name>road</name><LineString><coordinates>${kmlRing(ROAD)}</coordinates></LineString></Placemark>
<Placemark><name>mast</name><Point><coordinates>-77.0530,38.8100,0</coordinates></Point></Placemark>
</Folder></Document></kml>`;

const env = withServerAndBrowser();

/** Runs a command of the test set-up; fails with its stderr. */
function run(cmd, args, cwd) {
  const r = spawnSync(cmd, args, { encoding: 'utf8', cwd });
  assert.equal(r.status, 0, `${cmd} ${args.join(' ')} (ogr2ogr is in gdal-bin, installed by scripts/setup.sh --with-validators): ${r.stderr}`);
}

/** A WGS84 GeoJSON file of one feature, to be turned into other formats by ogr2ogr. */
function geojson(dir, name, geometry) {
  const file = path.join(dir, name);
  writeFileSync(file, JSON.stringify({ type: 'FeatureCollection', features: [{ type: 'Feature', properties: { name: name.replace(/\..*/, '') }, geometry }] }));
  return file;
}

/**
 * Drops files on an element the way a browser does: dragenter, dragover and
 * drop events carrying a DataTransfer that holds the files' bytes.
 */
async function dropFiles(page, files, { selector = '#map', shot = null } = {}) {
  const payload = files.map((f) => ({ name: path.basename(f), b64: readFileSync(f).toString('base64') }));
  const transfer = await page.evaluateHandle((items) => {
    const dt = new DataTransfer();
    for (const { name, b64 } of items) dt.items.add(new File([Uint8Array.from(atob(b64), (c) => c.charCodeAt(0))], name));
    return dt;
  }, payload);
  await page.dispatchEvent(selector, 'dragenter', { dataTransfer: transfer });
  await page.dispatchEvent(selector, 'dragover', { dataTransfer: transfer });
  const highlighted = await page.isVisible('#drop-zone');
  if (shot) await screenshot(page, shot);
  await page.dispatchEvent(selector, 'drop', { dataTransfer: transfer });
  return highlighted;
}

/** Waits until the import dialog has read the files. */
async function dialogRead(page) {
  await page.locator('#import-dialog').waitFor({ state: 'visible' });
  await page.waitForFunction(() => !/^Reading/.test(document.querySelector('#import-busy').textContent), null, { timeout: 30_000 });
}

/** The largest distance, in degrees, between the positions of two rings of equal length. */
function maxGap(a, b) {
  assert.equal(a.length, b.length, `${JSON.stringify(a)} vs ${JSON.stringify(b)}`);
  return Math.max(...a.map((p, i) => Math.max(Math.abs(p[0] - b[i][0]), Math.abs(p[1] - b[i][1]))));
}

/** The same ring whatever its start and direction (a Shapefile writes outer rings clockwise). */
function sameRing(got, want, tolerance, what) {
  const open = (r) => r.slice(0, -1);
  const g = open(got);
  const w = open(want);
  assert.equal(g.length, w.length, `${what}: ${JSON.stringify(got)}`);
  const candidates = [w, [...w].reverse()].flatMap((r) => r.map((_, k) => [...r.slice(k), ...r.slice(0, k)]));
  const best = Math.min(...candidates.map((c) => maxGap(g, c)));
  assert.ok(best <= tolerance, `${what}: ${best}° off: ${JSON.stringify(got)}`);
}

test('GIS files dropped on the page become the survey area, no-fly zones and corridor line', async () => {
  const dir = tempDir('terraplan-drop-');
  const kml = path.join(dir, 'farm.kml');
  writeFileSync(kml, FARM_KML);
  // The pond as a Shapefile in UTM zone 18N, zipped with its .prj.
  const shpDir = path.join(dir, 'pond');
  run('ogr2ogr', ['-f', 'ESRI Shapefile', '-t_srs', 'EPSG:32618', shpDir, geojson(dir, 'pond.geojson', { type: 'Polygon', coordinates: [POND] })]);
  const pondZip = path.join(dir, 'pond.zip');
  run('zip', ['-q', '-j', pondZip, ...['shp', 'shx', 'dbf', 'prj'].map((ext) => path.join(shpDir, `pond.${ext}`))]);
  const brokenZip = path.join(dir, 'broken.zip');
  writeFileSync(brokenZip, Buffer.from('PK\u0003\u0004 this is not a zip archive'));

  const { page, context, problems, outside } = await openPage(env.browser, env.server.url);

  // 1. The KML dropped on the map: the largest polygon the area, the other a no-fly zone, the line the corridor; the point skipped.
  assert.equal(await dropFiles(page, [kml], { shot: 'drop-import-dragging' }), true, 'the drop zone shows while dragging');
  assert.match(await page.textContent('#drop-zone-text'), /^Drop to import into the survey/);
  await dialogRead(page);
  await screenshot(page, 'drop-import-dialog');
  assert.equal(await page.isVisible('#drop-zone'), false);
  const labels = await page.$$eval('#import-features tbody tr', (rows) => rows.map((r) => r.cells[1].textContent));
  assert.deepEqual(labels, ['barn', 'field', 'road']);
  assert.deepEqual(await page.$$eval('#import-features select', (s) => s.map((e) => e.value)), ['nfz', 'roi', 'corridor']);
  assert.match(await page.textContent('#import-messages'), /farm\.kml: Placemark \d+ \("mast"\): 1 Point\(s\) skipped/);
  // The area is wanted here, not the corridor: the road is left out.
  await page.selectOption('#import-role-2', 'none');
  assert.equal(await page.textContent('#import-summary'), 'Imports the survey area and 1 no-fly zone.');
  await page.click('#import-apply');
  await page.locator('#import-dialog').waitFor({ state: 'hidden' });
  let areas = await page.evaluate(() => window.terraplan.areas());
  sameRing(areas.roi[0], FIELD, 1e-9, 'the field');
  assert.equal(areas.nfz.length, 1);
  sameRing(areas.nfz[0][0], BARN, 1e-9, 'the barn');
  assert.match(await page.textContent('#roi-status'), /^Area: /);
  assert.equal(await page.$$eval('#nfz-list li', (l) => l.length), 1);
  assert.match(await page.textContent('#corridor-status'), /No line/);
  assert.match(await page.textContent('#import-status'), /^From farm\.kml: Imported the survey area and 1 no-fly zone\./);
  assert.match(await page.textContent('#import-report-list'), /mast/);

  // 2. The zipped Shapefile (UTM) with a broken zip: the fault named, the pond a no-fly zone (there is an area now).
  await dropFiles(page, [brokenZip, pondZip]);
  await dialogRead(page);
  await screenshot(page, 'drop-import-shapefile-and-broken-zip');
  const errors = await page.textContent('#import-errors');
  assert.match(errors, /^broken\.zip: \S/);
  assert.ok(await page.isVisible('#import-errors'));
  assert.deepEqual(await page.$$eval('#import-features tbody tr', (rows) => rows.map((r) => [r.cells[0].textContent, r.cells[1].textContent])), [['pond.zip', 'pond']]);
  assert.equal(await page.inputValue('#import-role-0'), 'nfz');
  await page.click('#import-apply');
  await page.locator('#import-dialog').waitFor({ state: 'hidden' });
  areas = await page.evaluate(() => window.terraplan.areas());
  assert.equal(areas.nfz.length, 2);
  // UTM metres and back through PROJ: well under a millimetre (1e-8° ≈ 1 mm).
  sameRing(areas.nfz[1][0], POND, 1e-8, 'the pond');
  assert.match(await page.textContent('#import-report-list'), /broken\.zip: /);

  // 3. A broken file alone: said in the dialog, and what the user had is untouched.
  await dropFiles(page, [brokenZip]);
  await dialogRead(page);
  assert.equal(await page.textContent('#import-busy'), 'Nothing to import.');
  assert.equal(await page.isVisible('#import-apply'), false);
  assert.equal(await page.textContent('#import-cancel'), 'Close');
  await page.click('#import-cancel');
  assert.deepEqual(await page.evaluate(() => window.terraplan.areas()), areas);

  // 4. The imported shapes are the survey's: planned and stored with the request.
  await page.fill('#altitude', '40');
  await page.click('#plan-survey');
  await page.waitForFunction(() => document.querySelector('#survey-busy').textContent === 'Planned.', null, { timeout: 60_000 });
  const newest = (await (await env.server.fetch('/api/v1/surveys?limit=1')).json()).items[0];
  const planned = await (await env.server.fetch(`/api/v1/surveys/${newest.id}`)).json();
  sameRing(planned.request.roi.coordinates[0], FIELD, 1e-9, 'the planned area');
  assert.equal(planned.request.no_fly_zones.length, 2);
  assert.equal(planned.request.corridor, undefined);

  // 5. The file chooser (keyboard users): a GeoJSON in UTM (its crs member) goes through the server and becomes the corridor line.
  const roadUtm = path.join(dir, 'road-utm.geojson');
  run('ogr2ogr', ['-f', 'GeoJSON', '-t_srs', 'EPSG:32618', roadUtm, geojson(dir, 'road.geojson', { type: 'LineString', coordinates: ROAD })]);
  assert.match(readFileSync(roadUtm, 'utf8'), /EPSG::32618/, 'ogr2ogr writes the legacy crs member');
  const imports = [];
  page.on('request', (r) => r.url().endsWith('/api/v1/imports') && imports.push(r.url()));
  await page.setInputFiles('#import-gis', roadUtm);
  await dialogRead(page);
  assert.equal(imports.length, 1, 'the GeoJSON in UTM went to the server');
  assert.equal(await page.inputValue('#import-role-0'), 'corridor');
  await page.click('#import-apply');
  await page.waitForFunction(() => /2 positions/.test(document.querySelector('#corridor-status').textContent));
  const corridor = await page.evaluate(() => window.terraplan.corridor());
  assert.ok(maxGap(corridor, ROAD) <= 1e-8, JSON.stringify(corridor));
  await screenshot(page, 'drop-import-done');

  // The broken zips' 422 answers are logged by the browser; nothing else may be.
  assert.deepEqual(problems.filter((p) => !/422/.test(p)), []);
  assert.deepEqual(outside, []);
  await context.close();
});
