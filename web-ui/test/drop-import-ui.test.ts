// @vitest-environment jsdom
// The drop import on the real page markup (index.html): the highlight while
// dragging, the dialog after a drop (shapes, their roles, skipped features,
// a file's 422), and that only "Import" changes the survey.
import { readFileSync } from 'node:fs';
import path from 'node:path';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import type { LonLat } from '../src/api';
import { DropImport, type DropImportTarget } from '../src/drop-import';
import type { ImportPlan } from '../src/drop-import-model';
import type { PolygonRings } from '../src/geo-import';

const html = readFileSync(path.resolve(process.cwd(), 'index.html'), 'utf8');
const body = /<body>([\s\S]*)<\/body>/.exec(html)![1].replace(/<script[\s\S]*?<\/script>/g, '');
const $ = <T extends HTMLElement = HTMLElement>(id: string) => document.getElementById(id) as T;
const square = (x: number, y: number, d: number) => [[[x, y], [x + d, y], [x + d, y + d], [x, y + d], [x, y]]];

/** Waits until `check` holds (the dialog reads files asynchronously). */
async function until(check: () => boolean): Promise<void> {
  for (let i = 0; i < 200 && !check(); i++) await new Promise((r) => setTimeout(r, 5));
  expect(check()).toBe(true);
}

/** A drag event carrying files, as the browser sends (jsdom has no DataTransfer). */
function dragEvent(type: string, files: File[] = [], target: EventTarget = $('map')): Event {
  const e = new Event(type, { bubbles: true, cancelable: true });
  Object.defineProperty(e, 'dataTransfer', { value: { types: ['Files'], files, dropEffect: 'none' } });
  target.dispatchEvent(e);
  return e;
}

/** A stand-in survey: what the page has, and the plans applied. */
function survey(roi: PolygonRings | null = null) {
  const applied: ImportPlan[] = [];
  const target: DropImportTarget = {
    areas: () => ({ roi, nfz: [] }),
    corridorLine: (): LonLat[] | null => null,
    apply: (plan) => applied.push(plan),
  };
  return { target, applied };
}

/** The server: a KML with two polygons, a line and a skipped point; 422 for broken.zip. */
function server() {
  return vi.fn(async (_url: string, init: RequestInit) => {
    const file = (init.body as FormData).get('file') as File;
    if (file.name === 'broken.zip') {
      return new Response(JSON.stringify({ status: 422, detail: 'invalid', errors: [{ pointer: '/file', message: 'not a zip archive: invalid Zip archive: Could not find EOCD' }] }), { status: 422 });
    }
    return new Response(
      JSON.stringify({
        features: {
          type: 'FeatureCollection',
          features: [
            { type: 'Feature', properties: { name: 'barn' }, geometry: { type: 'Polygon', coordinates: square(10, 50, 0.001) } },
            { type: 'Feature', properties: { name: 'field' }, geometry: { type: 'Polygon', coordinates: square(10, 50, 0.01) } },
            { type: 'Feature', properties: { name: 'track' }, geometry: { type: 'LineString', coordinates: [[10, 50], [10.01, 50.01]] } },
          ],
        },
        messages: ['Placemark 4 ("mast"): 1 Point(s) skipped: points are not imported (only polygons and lines)'],
      }),
      { status: 200 },
    );
  });
}

const imports: DropImport[] = [];
/** The import under test (stopped after the test: its listeners are on the document, which the tests share). */
function dropImport(target: DropImportTarget, fetchImpl: unknown): DropImport {
  const d = new DropImport(target, fetchImpl as typeof fetch);
  imports.push(d);
  return d;
}

beforeEach(() => {
  document.body.innerHTML = body;
});
afterEach(() => {
  for (const d of imports.splice(0)) d.stop();
});

describe('dropping GIS files on the page', () => {
  it('highlights the page while files are dragged over it, and lets a file input keep its own drop', () => {
    const { target } = survey();
    dropImport(target, server());
    expect($('drop-zone').hidden).toBe(true);
    const enter = dragEvent('dragenter');
    expect(enter.defaultPrevented).toBe(true);
    expect($('drop-zone').hidden).toBe(false);
    expect(document.body.classList.contains('dragging-files')).toBe(true);
    expect($('drop-zone-text').textContent).toMatch(/Drop to import into the survey/);
    // Without preventDefault on dragover the browser would open the file instead of the page.
    expect(dragEvent('dragover').defaultPrevented).toBe(true);
    dragEvent('dragleave');
    expect($('drop-zone').hidden).toBe(true);
    expect(dragEvent('dragover', [], $('dem-file')).defaultPrevented).toBe(false);
  });

  it('reads a dropped file on the server, offers the defaults, lists what was skipped, and imports only on "Import"', async () => {
    const { target, applied } = survey();
    const fetchStub = server();
    dropImport(target, fetchStub);
    dragEvent('dragenter');
    const drop = dragEvent('drop', [new File(['<kml/>'], 'farm.kml')]);
    expect(drop.defaultPrevented).toBe(true);
    expect($('drop-zone').hidden).toBe(true);
    expect($('import-dialog').hidden).toBe(false);
    await until(() => !$('import-choices').hidden);
    expect(fetchStub).toHaveBeenCalledTimes(1);
    expect(((fetchStub.mock.calls[0][1] as RequestInit).body as FormData).get('file')).toHaveProperty('name', 'farm.kml');

    const rows = [...$('import-features').querySelectorAll('tbody tr')].map((tr) => [...tr.querySelectorAll('td')].slice(0, 3).map((td) => td.textContent));
    expect(rows.map((r) => r[1])).toEqual(['barn', 'field', 'track']);
    expect(rows[2][2]).toMatch(/^line, /);
    expect($<HTMLSelectElement>('import-role-0').value).toBe('nfz');
    expect($<HTMLSelectElement>('import-role-1').value).toBe('roi');
    expect($<HTMLSelectElement>('import-role-2').value).toBe('corridor');
    // A line can only become the corridor line (or nothing).
    expect([...$<HTMLSelectElement>('import-role-2').options].map((o) => o.value)).toEqual(['corridor', 'none']);
    expect($('import-skipped').hidden).toBe(false);
    expect($('import-messages').textContent).toBe('farm.kml: Placemark 4 ("mast"): 1 Point(s) skipped: points are not imported (only polygons and lines)');
    expect($('import-summary').textContent).toBe('Imports the survey area, 1 no-fly zone and the corridor line (the corridor is planned instead of the area).');

    // Two survey areas cannot be applied: said, and Import is off until fixed.
    const barn = $<HTMLSelectElement>('import-role-0');
    barn.value = 'roi';
    barn.dispatchEvent(new Event('change'));
    expect($('import-form-error').hidden).toBe(false);
    expect($('import-form-error').textContent).toMatch(/2 polygons are chosen as the survey area/);
    expect($<HTMLButtonElement>('import-apply').disabled).toBe(true);
    barn.value = 'none';
    barn.dispatchEvent(new Event('change'));
    expect($<HTMLButtonElement>('import-apply').disabled).toBe(false);
    expect(applied).toEqual([]);

    $('import-apply').click();
    expect($('import-dialog').hidden).toBe(true);
    expect(applied).toHaveLength(1);
    expect(applied[0].roi).toEqual(square(10, 50, 0.01));
    expect(applied[0].noFlyZones).toEqual([]);
    expect(applied[0].corridor).toEqual([[10, 50], [10.01, 50.01]]);
    expect($('import-status').textContent).toBe('From farm.kml: Imported the survey area and the corridor line (the corridor is planned instead of the area).');
    expect($('import-report').hidden).toBe(false);
    expect($('import-report-list').textContent).toMatch(/mast/);
  });

  it('shows a 422 naming the fault beside the files that did read, and Cancel leaves the survey as it was', async () => {
    const { target, applied } = survey(square(0, 0, 1) as PolygonRings);
    dropImport(target, server());
    dragEvent('drop', [new File(['PK'], 'broken.zip'), new File(['<kml/>'], 'farm.kml')]);
    await until(() => !$('import-choices').hidden);
    expect($('import-errors').hidden).toBe(false);
    expect($('import-errors').textContent).toBe('broken.zip: not a zip archive: invalid Zip archive: Could not find EOCD');
    // A survey area exists already: the polygons default to no-fly zones.
    expect($<HTMLSelectElement>('import-role-1').value).toBe('nfz');
    expect($('import-polygons-default').textContent).toMatch(/no-fly zones \(there is a survey area already\)/);
    $('import-cancel').click();
    expect($('import-dialog').hidden).toBe(true);
    expect(applied).toEqual([]);
    expect($('import-status').textContent).toBe('');
  });

  it('offers only "Close" when no file gave anything, and sets whole groups at once', async () => {
    const { target, applied } = survey();
    dropImport(target, server());
    dragEvent('drop', [new File(['PK'], 'broken.zip'), new File(['x'], 'dtm.tif')]);
    await until(() => $('import-busy').textContent === 'Nothing to import.');
    expect($('import-errors').querySelectorAll('li')).toHaveLength(2);
    expect($('import-errors').textContent).toMatch(/dtm\.tif: this looks like a terrain model/);
    expect($('import-apply').hidden).toBe(true);
    expect($('import-cancel').textContent).toBe('Close');
    $('import-cancel').click();

    // The file chooser takes the same path as a drop.
    const chooser = $<HTMLInputElement>('import-gis');
    expect(chooser.multiple).toBe(true);
    Object.defineProperty(chooser, 'files', { value: [new File(['<kml/>'], 'farm.kml')], configurable: true });
    chooser.dispatchEvent(new Event('change'));
    await until(() => !$('import-choices').hidden);
    const polygons = $<HTMLSelectElement>('import-polygons-as');
    polygons.value = 'nfz';
    polygons.dispatchEvent(new Event('change'));
    expect([0, 1, 2].map((i) => $<HTMLSelectElement>(`import-role-${i}`).value)).toEqual(['nfz', 'nfz', 'corridor']);
    const lines = $<HTMLSelectElement>('import-lines-as');
    lines.value = 'none';
    lines.dispatchEvent(new Event('change'));
    $('import-apply').click();
    expect(applied).toHaveLength(1);
    expect(applied[0]).toMatchObject({ roi: null, corridor: null });
    expect(applied[0].noFlyZones).toHaveLength(2);
  });
});
