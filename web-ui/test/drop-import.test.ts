// The logic of the GIS drop import: which reader takes a file, the request
// sent to POST /api/v1/imports, the shapes read, their default roles, the
// faults and messages shown (drop-import-model.ts).
import { afterEach, describe, expect, it, vi } from 'vitest';
import { ApiError, apiContext } from '../src/api';
import {
  IMPORT_URL,
  defaultRoles,
  describePlan,
  importErrorText,
  importOnServer,
  importPlan,
  importRequest,
  planExtent,
  readFiles,
  readerForGeoJson,
  readerForName,
  rolesFault,
  rolesFor,
  setAllRoles,
  shapesOf,
  type ImportedShape,
} from '../src/drop-import-model';
import { ImportError } from '../src/geo-import';

const square = (x: number, y: number, d: number) => [[[x, y], [x + d, y], [x + d, y + d], [x, y + d], [x, y]]];
const feature = (geometry: unknown, properties: Record<string, unknown> = {}) => ({ type: 'Feature', properties, geometry });
const collection = (...features: unknown[]) => ({ type: 'FeatureCollection', features });

/** A problem+json answer as the server gives it. */
const problem = (status: number, detail: string, errors: { pointer: string; message: string }[] = []) =>
  new Response(JSON.stringify({ type: 'about:blank', title: 'x', status, detail, errors }), { status, headers: { 'Content-Type': 'application/problem+json' } });

afterEach(() => {
  apiContext.csrfToken = null;
  apiContext.onUnauthorized = null;
  vi.restoreAllMocks();
});

describe('which reader takes a file', () => {
  it('sends Shapefile zips, KML, KMZ, GPX and GeoPackages to the server, whatever the case of the extension', () => {
    for (const name of ['rmnp.zip', 'a.KML', 'b.kmz', 'track.gpx', 'parcels.GPKG']) expect(readerForName(name)).toEqual({ reader: 'server' });
  });

  it('reads GeoJSON in the page first', () => {
    expect(readerForName('field.geojson')).toEqual({ reader: 'page' });
    expect(readerForName('field.json')).toEqual({ reader: 'page' });
  });

  it('refuses loose Shapefile parts, terrain models and other files, saying what to do', () => {
    const shp = readerForName('rmnp.shp');
    expect('refused' in shp && shp.refused).toMatch(/rmnp\.shp: a Shapefile is several files; zip the \.shp, \.shx, \.dbf and \.prj/);
    const tif = readerForName('dtm.tif');
    expect('refused' in tif && tif.refused).toMatch(/terrain model; upload it under “Terrain model \(DEM\)”/);
    const txt = readerForName('notes.txt');
    expect('refused' in txt && txt.refused).toMatch(/notes\.txt: not a file the page imports.*zipped Shapefile \(\.zip\), KML, KMZ, GPX, GeoPackage/);
    expect('refused' in readerForName('no-extension')).toBe(true);
  });

  it('keeps WGS84 GeoJSON in the page and sends GeoJSON in another named CRS to the server', () => {
    const wgs = readerForGeoJson('a.geojson', JSON.stringify(collection()));
    expect(wgs).toEqual({ reader: 'page', doc: collection() });
    const crs84 = { ...collection(), crs: { type: 'name', properties: { name: 'urn:ogc:def:crs:OGC:1.3:CRS84' } } };
    expect(readerForGeoJson('b.geojson', JSON.stringify(crs84))).toMatchObject({ reader: 'page' });
    const rd = { ...collection(), crs: { type: 'name', properties: { name: 'urn:ogc:def:crs:EPSG::28992' } } };
    expect(readerForGeoJson('c.geojson', JSON.stringify(rd))).toEqual({ reader: 'server' });
  });

  it('refuses empty and malformed JSON naming the file', () => {
    expect(readerForGeoJson('e.geojson', '  \n')).toEqual({ refused: 'e.geojson: the file is empty.' });
    const bad = readerForGeoJson('bad.json', '{"type": "FeatureCollection",');
    expect('refused' in bad && bad.refused).toMatch(/^bad\.json: not valid JSON \(/);
  });
});

describe('the request to POST /api/v1/imports', () => {
  it('is a multipart form whose part "file" is the file under its own name, with the CSRF token and no Content-Type of its own', async () => {
    apiContext.csrfToken = 'csrf-123';
    const file = new File(['<kml/>'], 'area.kml', { type: 'application/vnd.google-earth.kml+xml' });
    const { url, init } = importRequest(file);
    expect(url).toBe(IMPORT_URL);
    expect(init.method).toBe('POST');
    const headers = init.headers as Record<string, string>;
    expect(headers['X-CSRF-Token']).toBe('csrf-123');
    expect(Object.keys(headers).map((k) => k.toLowerCase())).not.toContain('content-type');
    const form = init.body as FormData;
    expect([...form.keys()]).toEqual(['file']);
    const part = form.get('file') as File;
    expect(part.name).toBe('area.kml');
    expect(await part.text()).toBe('<kml/>');
  });

  it('gives the features and messages of a 200 answer', async () => {
    const answer = { features: collection(feature({ type: 'Polygon', coordinates: square(0, 0, 0.01) })), messages: ['Placemark 2: 1 Point(s) skipped'] };
    const fetchStub = vi.fn(async () => new Response(JSON.stringify(answer), { status: 200 }));
    const got = await importOnServer(new File(['x'], 'a.kml'), fetchStub as unknown as typeof fetch);
    expect(got).toEqual(answer);
    expect(fetchStub).toHaveBeenCalledTimes(1);
  });

  it('throws the 422 problem and names the fault with the file', async () => {
    const fetchStub = async () => problem(422, 'invalid', [{ pointer: '/file', message: 'the zip holds no .prj: its CRS is unknown' }]);
    const err = await importOnServer(new File(['PK'], 'parcels.zip'), fetchStub as unknown as typeof fetch).catch((e: unknown) => e);
    expect(err).toBeInstanceOf(ApiError);
    expect((err as ApiError).problem.status).toBe(422);
    expect(importErrorText('parcels.zip', err)).toBe('parcels.zip: the zip holds no .prj: its CRS is unknown');
  });

  it('on 401 asks the page to sign in again and says so', async () => {
    const unauthorized = vi.fn();
    apiContext.onUnauthorized = unauthorized;
    const err = await importOnServer(new File(['x'], 'a.gpx'), (async () => problem(401, 'sign in')) as unknown as typeof fetch).catch((e: unknown) => e);
    expect(unauthorized).toHaveBeenCalledTimes(1);
    expect(importErrorText('a.gpx', err)).toMatch(/^a\.gpx: you are signed out\. Sign in again/);
  });

  it('turns a lost server, a 413 and an answer without features into clear messages', async () => {
    const down = await importOnServer(new File(['x'], 'a.kmz'), (async () => {
      throw new TypeError('Failed to fetch');
    }) as unknown as typeof fetch).catch((e: unknown) => e);
    expect(importErrorText('a.kmz', down)).toBe('a.kmz: The terraplan server cannot be reached. Nothing was imported.');
    const big = await importOnServer(new File(['x'], 'a.gpkg'), (async () => problem(413, 'the file is larger than 512 MB')) as unknown as typeof fetch).catch((e: unknown) => e);
    expect(importErrorText('a.gpkg', big)).toBe('a.gpkg: the file is larger than 512 MB');
    const odd = await importOnServer(new File(['x'], 'a.kml'), (async () => new Response('{"x": 1}', { status: 200 })) as unknown as typeof fetch).catch((e: unknown) => e);
    expect(importErrorText('a.kml', odd)).toMatch(/holds no feature collection/);
    expect(importErrorText('a.kml', new ImportError('A position (500000, 6000000) is not a longitude/latitude'))).toBe('a.kml: A position (500000, 6000000) is not a longitude/latitude');
  });
});

describe('the shapes of a feature collection', () => {
  it('gives each polygon and line (Multi* parts apart) with its name, size and the skipped features', () => {
    const fc = collection(
      feature({ type: 'Polygon', coordinates: square(0, 0, 0.01) }, { name: 'field 7' }),
      feature({ type: 'MultiPolygon', coordinates: [square(1, 0, 0.001), square(1, 1, 0.002)] }, { NAME: 'barns' }),
      feature({ type: 'LineString', coordinates: [[0, 0], [0, 0], [0.01, 0]] }),
      feature({ type: 'Point', coordinates: [0, 0] }, { name: 'mast' }),
      feature(null),
      feature({ type: 'Polygon', coordinates: [[[0, 0], [1, 1], [0, 0]]] }),
    );
    const { shapes, messages } = shapesOf('farm.geojson', fc);
    expect(shapes.map((s) => [s.label, s.shape.type])).toEqual([
      ['field 7', 'polygon'],
      ['barns, part 1', 'polygon'],
      ['barns, part 2', 'polygon'],
      ['feature 3', 'line'],
    ]);
    expect(shapes.every((s) => s.file === 'farm.geojson')).toBe(true);
    // 0.01° × 0.01° at the equator: about 1113 m × 1106 m (UTM); the line 0.01° ≈ 1113 m long, its repeated position dropped.
    expect(shapes[0].size).toBeGreaterThan(1.2e6);
    expect(shapes[0].size).toBeLessThan(1.25e6);
    expect(shapes[3].shape).toEqual({ type: 'line', line: [[0, 0], [0.01, 0]] });
    expect(Math.abs(shapes[3].size - 1113.2)).toBeLessThan(2);
    expect(messages).toEqual([
      'mast skipped: points are not imported (only polygons and lines)',
      'feature 5 skipped: no geometry',
      'feature 6 skipped: its outline has fewer than three corners',
    ]);
  });

  it('closes open rings and drops heights', () => {
    const { shapes } = shapesOf('a.geojson', feature({ type: 'Polygon', coordinates: [[[0, 0, 9], [1, 0, 9], [1, 1, 9]]] }));
    expect(shapes[0].shape).toEqual({ type: 'polygon', rings: [[[0, 0], [1, 0], [1, 1], [0, 0]]] });
  });

  it('throws when positions are metres, not lon/lat (a projected file without a crs member)', () => {
    expect(() => shapesOf('rd.geojson', collection(feature({ type: 'Polygon', coordinates: square(155000, 463000, 100) })))).toThrow(ImportError);
  });
});

/** A shape of a given size (m² or m). */
const shape = (type: 'polygon' | 'line', size: number, label = `${type} ${size}`): ImportedShape => ({
  file: 'f.kml',
  label,
  size,
  shape: type === 'polygon' ? { type, rings: square(size, 0, 0.001) as [number, number][][] } : { type, line: [[size, 0], [size, 1]] },
});

describe('what the shapes become', () => {
  it('makes the largest polygon the survey area when there is none yet, the others no-fly zones, the longest line the corridor', () => {
    const shapes = [shape('polygon', 10), shape('line', 5), shape('polygon', 30), shape('line', 50), shape('polygon', 20)];
    expect(defaultRoles(shapes, false)).toEqual(['nfz', 'none', 'roi', 'corridor', 'nfz']);
  });

  it('makes every polygon a no-fly zone when the survey has an area already', () => {
    expect(defaultRoles([shape('polygon', 10), shape('polygon', 30)], true)).toEqual(['nfz', 'nfz']);
  });

  it('offers areas for polygons and only the corridor for lines', () => {
    expect(rolesFor({ type: 'polygon', rings: [] })).toEqual(['roi', 'nfz', 'none']);
    expect(rolesFor({ type: 'line', line: [] })).toEqual(['corridor', 'none']);
  });

  it('sets a group at once, leaving the other kind alone', () => {
    const shapes = [shape('polygon', 10), shape('line', 5), shape('polygon', 30)];
    expect(setAllRoles(shapes, ['roi', 'corridor', 'nfz'], 'polygon', 'none')).toEqual(['none', 'corridor', 'none']);
  });

  it('refuses two survey areas, two corridor lines, a polygon as a line, and nothing at all', () => {
    const shapes = [shape('polygon', 10), shape('polygon', 30), shape('line', 5), shape('line', 6)];
    expect(rolesFault(shapes, ['roi', 'roi', 'none', 'none'])).toMatch(/^2 polygons are chosen as the survey area: a survey has one/);
    expect(rolesFault(shapes, ['nfz', 'nfz', 'corridor', 'corridor'])).toMatch(/^2 lines are chosen as the corridor line/);
    expect(rolesFault(shapes, ['corridor', 'nfz', 'none', 'none'])).toBe('polygon 10 (f.kml) is a polygon: it cannot be a corridor line.');
    expect(rolesFault(shapes, ['none', 'none', 'none', 'none'])).toBe('Nothing is chosen to import.');
    expect(rolesFault(shapes, ['roi', 'nfz', 'corridor', 'none'])).toBeNull();
  });

  it('puts the chosen shapes into the plan and says what importing does', () => {
    const shapes = [shape('polygon', 10), shape('polygon', 30), shape('polygon', 40), shape('line', 5)];
    const plan = importPlan(shapes, ['nfz', 'roi', 'nfz', 'corridor']);
    expect(plan.roi).toBe(shapes[1].shape.type === 'polygon' && shapes[1].shape.rings);
    expect(plan.noFlyZones).toHaveLength(2);
    expect(plan.corridor).toEqual([[5, 0], [5, 1]]);
    expect(describePlan(plan, { roi: false, corridor: false })).toBe(
      'Imports the survey area, 2 no-fly zones and the corridor line (the corridor is planned instead of the area).',
    );
    expect(describePlan(importPlan(shapes, ['roi', 'none', 'none', 'none']), { roi: true, corridor: false })).toBe('Imports the survey area (replacing the current one).');
    expect(describePlan(importPlan(shapes, ['nfz', 'none', 'none', 'none']), { roi: true, corridor: false })).toBe('Imports 1 no-fly zone.');
    expect(planExtent(plan)).toEqual([5, 0, 40.001, 1]);
    expect(planExtent(importPlan(shapes, ['none', 'none', 'none', 'none']))).toBeNull();
  });
});

describe('reading dropped files', () => {
  it('reads WGS84 GeoJSON in the page, sends the rest (GeoJSON in RD New too) to the server one by one, and keeps each fault to its file', async () => {
    const sent: string[] = [];
    const fetchStub = vi.fn(async (_url: string, init: RequestInit) => {
      const file = (init.body as FormData).get('file') as File;
      sent.push(file.name);
      if (file.name === 'broken.kml') return problem(422, 'invalid', [{ pointer: '/file', message: 'malformed XML at byte 12: unexpected end of file' }]);
      return new Response(JSON.stringify({ features: collection(feature({ type: 'Polygon', coordinates: square(5, 52, 0.01) }, { name: 'perceel' })), messages: ['feature 2 skipped: no geometry'] }), { status: 200 });
    });
    const wgs = new File([JSON.stringify(collection(feature({ type: 'LineString', coordinates: [[0, 0], [0.01, 0]] })))], 'road.geojson');
    const rd = new File([JSON.stringify({ ...collection(), crs: { type: 'name', properties: { name: 'urn:ogc:def:crs:EPSG::28992' } } })], 'rd.geojson');
    const results = await readFiles(
      [wgs, new File(['x'], 'parts.shp'), rd, new File(['<kml'], 'broken.kml'), new File(['x'], 'parts.dbf')],
      fetchStub as unknown as typeof fetch,
    );
    expect(sent).toEqual(['rd.geojson', 'broken.kml']);
    expect(results.map((r) => [r.file, r.readBy, r.shapes.length, r.error])).toEqual([
      ['parts.shp, parts.dbf', null, 0, expect.stringMatching(/^parts\.shp, parts\.dbf: a Shapefile is several files/)],
      ['road.geojson', 'page', 1, null],
      ['rd.geojson', 'server', 1, null],
      ['broken.kml', 'server', 0, 'broken.kml: malformed XML at byte 12: unexpected end of file'],
    ]);
    expect(results[2].messages).toEqual(['feature 2 skipped: no geometry']);
    expect(results[2].shapes[0].label).toBe('perceel');
  });

  it('says a file gave nothing to import when all its features were skipped', async () => {
    const points = new File([JSON.stringify(collection(feature({ type: 'Point', coordinates: [1, 2] })))], 'masts.geojson');
    const [r] = await readFiles([points], (() => {
      throw new Error('no request expected');
    }) as unknown as typeof fetch);
    expect(r.error).toBe('masts.geojson: no polygon or line to import (see what was skipped).');
    expect(r.messages).toEqual(['feature 1 skipped: points are not imported (only polygons and lines)']);
  });
});
