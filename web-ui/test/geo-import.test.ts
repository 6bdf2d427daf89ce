// @vitest-environment jsdom
import { existsSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { describe, expect, it } from 'vitest';
import { closeRing, ImportError, parsePolygons } from '../src/geo-import';

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
