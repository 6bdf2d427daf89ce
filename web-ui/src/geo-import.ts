// Reads polygons (WGS84 lon/lat) from GeoJSON or KML files for the ROI and
// no-fly zones. A small reader of our own rather than OpenLayers' KML format:
// that one builds default icon styles pointing at Google's servers, and we
// only need the polygon rings.

import type { LonLat, Ring } from './api';

/** A polygon as GeoJSON coordinates: the exterior ring, then holes; rings closed. */
export type PolygonRings = Ring[];

export class ImportError extends Error {}

/** Detects the format from the file name, then the content. */
export function parsePolygons(text: string, fileName = ''): PolygonRings[] {
  const trimmed = text.trimStart();
  const isKml = /\.kml$/i.test(fileName) || trimmed.startsWith('<');
  const polygons = isKml ? parseKml(text) : parseGeoJson(text);
  if (polygons.length === 0) throw new ImportError('The file holds no polygon.');
  return polygons;
}

export function parseGeoJson(text: string): PolygonRings[] {
  let doc: unknown;
  try {
    doc = JSON.parse(text);
  } catch {
    throw new ImportError('The file is not valid JSON.');
  }
  const out: PolygonRings[] = [];
  collectGeoJson(doc, out);
  return out;
}

/** The polygons of a parsed GeoJSON object (geometry, Feature or collection). */
export function polygonsOf(geojson: unknown): PolygonRings[] {
  const out: PolygonRings[] = [];
  collectGeoJson(geojson, out);
  return out;
}

function collectGeoJson(node: unknown, out: PolygonRings[]): void {
  if (!node || typeof node !== 'object') return;
  const g = node as { type?: string; coordinates?: unknown; geometry?: unknown; features?: unknown[]; geometries?: unknown[] };
  switch (g.type) {
    case 'FeatureCollection':
      for (const f of g.features ?? []) collectGeoJson(f, out);
      break;
    case 'Feature':
      collectGeoJson(g.geometry, out);
      break;
    case 'GeometryCollection':
      for (const c of g.geometries ?? []) collectGeoJson(c, out);
      break;
    case 'Polygon':
      out.push(polygonFromCoords(g.coordinates));
      break;
    case 'MultiPolygon':
      if (!Array.isArray(g.coordinates)) throw new ImportError('A MultiPolygon has no coordinates.');
      for (const p of g.coordinates) out.push(polygonFromCoords(p));
      break;
    default:
      // Points and lines are not areas: skipped.
      break;
  }
}

function polygonFromCoords(coords: unknown): PolygonRings {
  if (!Array.isArray(coords) || coords.length === 0) throw new ImportError('A polygon has no rings.');
  return coords.map((ring) => {
    if (!Array.isArray(ring)) throw new ImportError('A polygon ring is not a list of positions.');
    return closeRing(ring.map(toLonLat));
  });
}

function toLonLat(p: unknown): LonLat {
  if (!Array.isArray(p) || p.length < 2 || !Number.isFinite(p[0]) || !Number.isFinite(p[1])) {
    throw new ImportError('A position is not [longitude, latitude].');
  }
  // Heights (a third number) are dropped: the planner ignores them.
  return [Number(p[0]), Number(p[1])];
}

/** Closes a ring (first position repeated at the end) if it is open. */
export function closeRing(ring: LonLat[]): LonLat[] {
  if (ring.length === 0) return ring;
  const [a, b] = [ring[0], ring[ring.length - 1]];
  return a[0] === b[0] && a[1] === b[1] ? ring : [...ring, [a[0], a[1]]];
}

export function parseKml(text: string): PolygonRings[] {
  const doc = new DOMParser().parseFromString(text, 'application/xml');
  if (doc.getElementsByTagName('parsererror').length > 0) throw new ImportError('The file is not valid KML (XML).');
  const out: PolygonRings[] = [];
  for (const poly of Array.from(doc.getElementsByTagNameNS('*', 'Polygon'))) {
    const outer = firstRing(poly, 'outerBoundaryIs');
    if (!outer) continue;
    const holes = Array.from(poly.getElementsByTagNameNS('*', 'innerBoundaryIs'))
      .map((b) => ringFromCoordinates(b))
      .filter((r): r is LonLat[] => r !== null);
    out.push([outer, ...holes]);
  }
  return out;
}

function firstRing(poly: Element, boundary: string): LonLat[] | null {
  const b = poly.getElementsByTagNameNS('*', boundary)[0];
  return b ? ringFromCoordinates(b) : null;
}

function ringFromCoordinates(boundary: Element): LonLat[] | null {
  const c = boundary.getElementsByTagNameNS('*', 'coordinates')[0];
  if (!c?.textContent) return null;
  // KML tuples are "lon,lat[,alt]" separated by whitespace.
  const ring = c.textContent
    .trim()
    .split(/\s+/)
    .map((tuple) => {
      const [lon, lat] = tuple.split(',').map(Number);
      if (!Number.isFinite(lon) || !Number.isFinite(lat)) throw new ImportError(`A KML coordinate is not "lon,lat": ${tuple}`);
      return [lon, lat] as LonLat;
    });
  return closeRing(ring);
}
