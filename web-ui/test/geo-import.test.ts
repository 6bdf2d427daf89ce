// @vitest-environment jsdom
import { existsSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { describe, expect, it } from 'vitest';
import { closeRing, foreignGeoJsonCrs, ImportError, parsePolygons, ringCrossesItself, toLonLat, utmArea } from '../src/geo-import';

// The shared test data (../shared/data beside the repository); vitest runs in web-ui/.
const FIELD = path.resolve(process.cwd(), '../../shared/data/polygons/fields2cover__test.json');

describe('GeoJSON import', () => {
  it('reads Polygon, MultiPolygon, Feature and FeatureCollection, dropping heights and closing rings', () => {
    const fc = {
      type: 'FeatureCollection',
      features: [
        { type: 'Feature', properties: {}, geometry: { type: 'Polygon', coordinates: [[[0, 0, 5], [1, 0, 5], [1, 1, 5]]] } },
        { type: 'Feature', properties: {}, geometry: { type: 'Point', coordinates: [0, 0] } },
        { type: 'Feature', properties: {}, geometry: { type: 'MultiPolygon', coordinates: [[[[2, 2], [3, 2], [3, 3], [2, 2]]], [[[4, 4], [5, 4], [5, 5], [4, 4]]]] } },
      ],
    };
    const polys = parsePolygons(JSON.stringify(fc), 'x.geojson');
    expect(polys).toHaveLength(3);
    expect(polys[0]).toEqual([[[0, 0], [1, 0], [1, 1], [0, 0]]]);
  });

  it.skipIf(!existsSync(FIELD))('reads a real field boundary (Fields2Cover, 3D positions)', () => {
    const text = readFileSync(FIELD, 'utf8');
    const polys = parsePolygons(text, 'fields2cover__test.json');
    expect(polys.length).toBeGreaterThan(0);
    const ring = polys[0][0];
    expect(ring[0]).toHaveLength(2);
    expect(ring[0]).toEqual(ring[ring.length - 1]);
  });

  it('says what is wrong with a bad file', () => {
    expect(() => parsePolygons('{not json', 'a.geojson')).toThrow(ImportError);
    expect(() => parsePolygons('{"type":"Point","coordinates":[0,0]}', 'a.geojson')).toThrow('no polygon');
    expect(() => parsePolygons('{"type":"Polygon","coordinates":[[["a",1]]]}', 'a.geojson')).toThrow('longitude');
    expect(() => parsePolygons('  \n', 'a.geojson')).toThrow('The file is empty.');
    expect(() => parsePolygons('AC R\nAN TMA\n', 'airspace.txt')).toThrow(/neither GeoJSON nor KML.*\.kml/);
  });

  it('refuses projected coordinates, with or without a crs member, and keeps WGS84 ones', () => {
    const square = [[[321600, 4297700], [321700, 4297700], [321700, 4297800], [321600, 4297700]]];
    expect(() => parsePolygons(JSON.stringify({ type: 'Polygon', coordinates: square }), 'utm.geojson')).toThrow(
      'A position (321600, 4297700) is not a longitude/latitude: the file seems to be in projected coordinates (metres).',
    );
    const named = { type: 'FeatureCollection', crs: { type: 'name', properties: { name: 'urn:ogc:def:crs:EPSG::26918' } }, features: [] };
    expect(() => parsePolygons(JSON.stringify(named), 'utm.geojson')).toThrow(/in urn:ogc:def:crs:EPSG::26918, not longitude\/latitude/);
    for (const name of ['urn:ogc:def:crs:OGC:1.3:CRS84', 'EPSG:4326', 'urn:ogc:def:crs:EPSG::4326']) {
      const wgs84 = { type: 'Feature', crs: { type: 'name', properties: { name } }, geometry: { type: 'Polygon', coordinates: [[[5, 52], [5.1, 52], [5.1, 52.1], [5, 52]]] } };
      expect(parsePolygons(JSON.stringify(wgs84), 'ok.geojson')).toHaveLength(1);
    }
    const kml = '<kml xmlns="http://www.opengis.net/kml/2.2"><Polygon><outerBoundaryIs><LinearRing><coordinates>321600,4297700 321700,4297700 321700,4297800</coordinates></LinearRing></outerBoundaryIs></Polygon></kml>';
    expect(() => parsePolygons(kml, 'utm.kml')).toThrow('not a longitude/latitude');
  });
});

describe('KML import', () => {
  const kml = `<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2"><Document><Placemark><name>field</name>
<MultiGeometry>
  <Polygon><outerBoundaryIs><LinearRing><coordinates>
    -77.055,38.809,0 -77.052,38.809,0 -77.052,38.811,0 -77.055,38.811,0 -77.055,38.809,0
  </coordinates></LinearRing></outerBoundaryIs>
  <innerBoundaryIs><LinearRing><coordinates>-77.054,38.8095 -77.053,38.8095 -77.053,38.8100</coordinates></LinearRing></innerBoundaryIs></Polygon>
  <Polygon><outerBoundaryIs><LinearRing><coordinates>1,1 2,1 2,2</coordinates></LinearRing></outerBoundaryIs></Polygon>
</MultiGeometry></Placemark></Document></kml>`;

  it('reads polygons with holes from placemarks and multigeometries', () => {
    const polys = parsePolygons(kml, 'field.kml');
    expect(polys).toHaveLength(2);
    expect(polys[0]).toHaveLength(2);
    expect(polys[0][0][0]).toEqual([-77.055, 38.809]);
    expect(polys[0][1]).toEqual([[-77.054, 38.8095], [-77.053, 38.8095], [-77.053, 38.81], [-77.054, 38.8095]]);
    expect(polys[1][0]).toHaveLength(4);
  });

  it('reads the route KML terraplan writes (the UAV cells are polygons)', () => {
    // A KML without polygons (a track only) has nothing to import.
    const track = '<kml xmlns="http://www.opengis.net/kml/2.2"><Placemark><LineString><coordinates>0,0 1,1</coordinates></LineString></Placemark></kml>';
    expect(() => parsePolygons(track, 'route.kml')).toThrow('no polygon');
  });

  it('refuses broken XML', () => {
    expect(() => parsePolygons('<kml><Polygon>', 'x.kml')).toThrow(ImportError);
  });
});

describe('closeRing', () => {
  it('repeats the first position only when needed', () => {
    expect(closeRing([[0, 0], [1, 0], [1, 1]])).toHaveLength(4);
    expect(closeRing([[0, 0], [1, 0], [1, 1], [0, 0]])).toHaveLength(4);
  });
});

describe('utmArea', () => {
  // Expected: pyproj (EPSG:32618 / 32733) + shapely on the same rings.
  const roi: [number, number][] = [[-77.055, 38.809], [-77.0527, 38.809], [-77.0527, 38.8114], [-77.055, 38.8114], [-77.055, 38.809]];
  const hole: [number, number][] = [[-77.0542, 38.81], [-77.0535, 38.81], [-77.0535, 38.8106], [-77.0542, 38.8106], [-77.0542, 38.81]];

  it('measures in the UTM zone of the centroid, as the planner does, holes subtracted', () => {
    expect(utmArea([roi])).toBeCloseTo(53224.036855, 3);
    expect(utmArea([roi, hole])).toBeCloseTo(49174.387478, 3);
    // Either winding; the southern hemisphere's zone.
    expect(utmArea([[...roi].reverse()])).toBeCloseTo(53224.036855, 3);
    expect(utmArea([[[15, -10], [15.01, -10], [15.01, -9.99], [15, -9.99], [15, -10]]])).toBeCloseTo(1211744.706282, 2);
  });

  it('is 0 for a degenerate ring', () => {
    expect(utmArea([[[0, 0], [1, 1]]])).toBe(0);
  });
});

describe('ringCrossesItself', () => {
  const square: [number, number][] = [[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]];

  it('is false for simple rings, closed or open, either winding, and for triangles', () => {
    expect(ringCrossesItself(square)).toBe(false);
    expect(ringCrossesItself(square.slice(0, -1))).toBe(false);
    expect(ringCrossesItself([...square].reverse())).toBe(false);
    expect(ringCrossesItself([[0, 0], [1, 0], [0, 1], [0, 0]])).toBe(false);
    // A concave ring whose corner comes close to, but not onto, another edge.
    expect(ringCrossesItself([[0, 0], [2, 0], [2, 2], [1, 0.001], [0, 2], [0, 0]])).toBe(false);
  });

  it('finds a bow tie, a loop, and a corner touching another edge', () => {
    expect(ringCrossesItself([[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]])).toBe(true);
    // The last edge runs back across the first.
    expect(ringCrossesItself([[0, 0], [3, 0], [3, 2], [1, -1], [0, 0]])).toBe(true);
    expect(ringCrossesItself([[0, 0], [2, 0], [2, 2], [1, 0], [0, 2], [0, 0]])).toBe(true);
  });
});

describe('foreignGeoJsonCrs', () => {
  const named = (name: unknown) => ({ type: 'FeatureCollection', features: [], crs: { type: 'name', properties: { name } } });

  it('names a CRS other than WGS84 lon/lat (the file then goes to the server to be reprojected)', () => {
    expect(foreignGeoJsonCrs(named('urn:ogc:def:crs:EPSG::28992'))).toBe('urn:ogc:def:crs:EPSG::28992');
    expect(foreignGeoJsonCrs(named('EPSG:32618'))).toBe('EPSG:32618');
  });

  it('is null without a crs member and for the names of WGS84', () => {
    expect(foreignGeoJsonCrs({ type: 'FeatureCollection', features: [] })).toBeNull();
    expect(foreignGeoJsonCrs(null)).toBeNull();
    for (const name of ['urn:ogc:def:crs:OGC:1.3:CRS84', 'urn:ogc:def:crs:EPSG::4326', 'EPSG:4326', ' CRS84 ']) expect(foreignGeoJsonCrs(named(name))).toBeNull();
    expect(foreignGeoJsonCrs(named(42))).toBeNull();
  });
});

describe('toLonLat', () => {
  it('keeps lon/lat, drops heights, and refuses what is not a position in degrees', () => {
    expect(toLonLat([-77.05, 38.81, 12])).toEqual([-77.05, 38.81]);
    expect(() => toLonLat([1])).toThrow(ImportError);
    expect(() => toLonLat(['1', 2])).toThrow(ImportError);
    expect(() => toLonLat([155000, 463000])).toThrow(/projected coordinates/);
  });
});
