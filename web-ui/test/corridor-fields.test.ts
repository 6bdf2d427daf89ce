// @vitest-environment jsdom
import { existsSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { describe, expect, it } from 'vitest';
import { corridorFromRequest, corridorMembers, lineLengthM, parseLine } from '../src/corridor-fields';
import { ImportError } from '../src/geo-import';
import { buildSurveyRequest, formFromRequest } from '../src/survey-form';
import { formValues } from './form-values';

// The shared test data (../shared/data beside the repository); vitest runs in web-ui/.
const FIELD = path.resolve(process.cwd(), '../../shared/data/polygons/fields2cover__test.json');

const line: [number, number][] = [[5, 52], [5.01, 52], [5.014, 52.0025]];

describe('corridor line import', () => {
  it('reads a LineString from GeoJSON geometries, features and collections, dropping heights and repeats', () => {
    const ls = { type: 'LineString', coordinates: [[5, 52, 3], [5, 52, 3], [5.01, 52]] };
    expect(parseLine(JSON.stringify(ls))).toEqual([[5, 52], [5.01, 52]]);
    const fc = { type: 'FeatureCollection', features: [{ type: 'Feature', geometry: { type: 'Point', coordinates: [0, 0] } }, { type: 'Feature', geometry: ls }] };
    expect(parseLine(JSON.stringify(fc), 'x.geojson')).toHaveLength(2);
    const mls = { type: 'MultiLineString', coordinates: [[[1, 1], [2, 2]], [[3, 3], [4, 4]]] };
    expect(parseLine(JSON.stringify(mls))).toEqual([[1, 1], [2, 2]]);
  });

  it('reads a KML LineString', () => {
    const kml = '<?xml version="1.0"?><kml xmlns="http://www.opengis.net/kml/2.2"><Placemark><LineString><coordinates>5,52,0 5.01,52,0</coordinates></LineString></Placemark></kml>';
    expect(parseLine(kml, 'road.kml')).toEqual([[5, 52], [5.01, 52]]);
  });

  it('refuses files without a usable line', () => {
    expect(() => parseLine('{"type": "Polygon", "coordinates": []}')).toThrow(ImportError);
    expect(() => parseLine('{"type": "LineString", "coordinates": [[5, 52], [5, 52]]}')).toThrow(/two distinct/);
    expect(() => parseLine('{"type": "LineString", "coordinates": [[5, 95], [5, 52]]}')).toThrow(/longitude and latitude/);
    expect(() => parseLine('')).toThrow(/empty/);
  });

  it.skipIf(!existsSync(FIELD))('measures a real field edge (Fields2Cover, west and south edges) within 1 %', () => {
    const doc = JSON.parse(readFileSync(FIELD, 'utf8'));
    const ring = doc.features[0].geometry.coordinates[0].slice(0, 11);
    const edge = parseLine(JSON.stringify({ type: 'LineString', coordinates: ring }));
    // Its geodesic length on the WGS84 ellipsoid (pyproj's Geod.line_length): 340.98 m.
    expect(Math.abs(lineLengthM(edge) - 340.98) / 340.98).toBeLessThan(0.01);
  });
});

describe('corridor request members', () => {
  it('sends corridor and corridor_width_m instead of roi, and reads them back', () => {
    const { body, errors } = buildSurveyRequest(formValues({ corridor: { line, widthM: 80 } }));
    expect(errors).toEqual([]);
    expect(body!.roi).toBeUndefined();
    expect(body!.corridor).toEqual({ type: 'LineString', coordinates: line });
    expect(body!.corridor_width_m).toBe(80);
    const back = formFromRequest(body!, null, { camera: 'dji_phantom4_pro', customCamera: formValues().customCamera });
    expect(back.values.corridor).toEqual({ line, widthM: 80 });
    expect(back.values.extra).toEqual({});
  });

  it('a corridor replaces the area, and with a battery its UAV starts at the line start', () => {
    const { body } = buildSurveyRequest(formValues({ roi: [[[5, 52], [5.1, 52], [5.1, 52.1], [5, 52]]], corridor: { line, widthM: 50 }, batteryMin: 20 }));
    expect(body!.roi).toBeUndefined();
    expect(body!.uavs).toEqual([{ id: 'uav1', start: [5, 52], max_flight_time_s: 1200 }]);
  });

  it('names a missing or out-of-range width', () => {
    for (const widthM of [NaN, 0.5, 2500]) {
      const { body, errors } = buildSurveyRequest(formValues({ corridor: { line, widthM } }));
      expect(body).toBeNull();
      expect(errors).toEqual([{ field: 'corridor', text: 'Corridor width: give a number of metres from 1 to 2000.', control: 'corridor-width' }]);
    }
    expect(corridorMembers({ line, widthM: 1 })).toHaveProperty('members');
    expect(corridorFromRequest({ roi: {} })).toBeNull();
  });
});
