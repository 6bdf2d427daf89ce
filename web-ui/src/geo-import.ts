// Reads polygons (WGS84 lon/lat) from GeoJSON or KML files for the ROI and
// no-fly zones. A small reader of our own rather than OpenLayers' KML format:
// that one builds default icon styles pointing at Google's servers, and we
// only need the polygon rings.

import proj4 from 'proj4';
import type { LonLat, Ring } from './api';

/** A polygon as GeoJSON coordinates: the exterior ring, then holes; rings closed. */
export type PolygonRings = Ring[];

export class ImportError extends Error {}

/** Detects the format from the file name, then the content. */
export function parsePolygons(text: string, fileName = ''): PolygonRings[] {
  const trimmed = text.trimStart();
  if (trimmed === '') throw new ImportError('The file is empty.');
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
    throw new ImportError('The file is neither GeoJSON nor KML (it is not valid JSON). Areas can be imported from GeoJSON (.geojson, .json) and KML (.kml) files.');
  }
  checkGeoJsonCrs(doc);
  const out: PolygonRings[] = [];
  collectGeoJson(doc, out);
  return out;
}

/** Names the 2008 GeoJSON `crs` member may give for longitude/latitude on WGS84. */
const WGS84_NAMES = /^(urn:ogc:def:crs:OGC:(1\.3:)?CRS84|urn:ogc:def:crs:EPSG:(\d*\.?\d*)?:4326|EPSG:4326|CRS84|WGS ?84)$/i;

/**
 * The CRS a GeoJSON document's legacy `crs` member names when it is not
 * longitude/latitude on WGS84 (null: none named, or WGS84). Such a file
 * needs reprojecting: the drop import sends it to the server (PROJ).
 */
export function foreignGeoJsonCrs(doc: unknown): string | null {
  const crs = (doc as { crs?: { properties?: { name?: unknown } } } | null)?.crs;
  const name = crs?.properties?.name;
  return typeof name === 'string' && !WGS84_NAMES.test(name.trim()) ? name : null;
}

/** Refuses a GeoJSON file that says it is in another CRS (old GeoJSON allowed a `crs` member; projected files use it). */
function checkGeoJsonCrs(doc: unknown): void {
  const name = foreignGeoJsonCrs(doc);
  if (name !== null) {
    throw new ImportError(
      `The file's coordinates are in ${name}, not longitude/latitude (WGS84). Export it in EPSG:4326, e.g. ogr2ogr -t_srs EPSG:4326 out.geojson in.geojson.`,
    );
  }
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

/** A GeoJSON position as [lon, lat]; throws an ImportError naming what is wrong. */
export function toLonLat(p: unknown): LonLat {
  if (!Array.isArray(p) || p.length < 2 || !Number.isFinite(p[0]) || !Number.isFinite(p[1])) {
    throw new ImportError('A position is not [longitude, latitude].');
  }
  // Heights (a third number) are dropped: the planner ignores them.
  return checkRange(Number(p[0]), Number(p[1]));
}

/** A position must be longitude/latitude: metres of a projected file would put the area nowhere. */
function checkRange(lon: number, lat: number): LonLat {
  if (Math.abs(lon) > 180 || Math.abs(lat) > 90) {
    throw new ImportError(
      `A position (${lon}, ${lat}) is not a longitude/latitude: the file seems to be in projected coordinates (metres). Export it in WGS84 (EPSG:4326).`,
    );
  }
  return [lon, lat];
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
      return checkRange(lon, lat);
    });
  return closeRing(ring);
}

/**
 * The area of lon/lat rings (exterior minus holes), m², measured as the
 * planner does (SPEC §2): in the UTM zone of the exterior's centroid on
 * WGS84, so the page's figure and the plan's agree.
 */
export function utmArea(rings: PolygonRings): number {
  const outer = rings[0] ?? [];
  if (outer.length < 3) return 0;
  const [lon, lat] = centroid(outer);
  const zone = Math.min(60, Math.floor((lon + 180) / 6) + 1);
  const utm = proj4('EPSG:4326', `+proj=utm +zone=${zone}${lat < 0 ? ' +south' : ''} +datum=WGS84 +units=m +no_defs`);
  const planar = (ring: LonLat[]) => Math.abs(shoelace(ring.map((p) => utm.forward([p[0], p[1]]) as LonLat)));
  return planar(outer) - rings.slice(1).reduce((sum, hole) => sum + planar(hole), 0);
}

/** Signed area of a ring (closed or not) by the shoelace formula. */
function shoelace(ring: LonLat[]): number {
  let twice = 0;
  for (let i = 0; i < ring.length; i++) {
    const [x0, y0] = ring[i];
    const [x1, y1] = ring[(i + 1) % ring.length];
    twice += x0 * y1 - x1 * y0;
  }
  return twice / 2;
}

/** The area centroid of a ring in lon/lat (planar, which is all a zone choice needs). */
function centroid(ring: LonLat[]): LonLat {
  const a = shoelace(ring);
  if (Math.abs(a) < 1e-18) return ring[0];
  let cx = 0;
  let cy = 0;
  for (let i = 0; i < ring.length; i++) {
    const [x0, y0] = ring[i];
    const [x1, y1] = ring[(i + 1) % ring.length];
    const f = x0 * y1 - x1 * y0;
    cx += (x0 + x1) * f;
    cy += (y0 + y1) * f;
  }
  return [cx / (6 * a), cy / (6 * a)];
}

/** Rings longer than this are not checked for crossings by the page (the server still checks them). */
const CROSSING_CHECK_MAX = 2000;

/**
 * Whether a ring's edges cross or touch other than at the corners they
 * share: such an outline has no meaningful area (a bow tie's halves cancel
 * in the shoelace sum), so the page says it crosses itself instead of
 * showing a figure. Planar in lon/lat, which is enough to tell crossing;
 * false for rings too long to check (the server's validation decides).
 */
export function ringCrossesItself(ring: LonLat[]): boolean {
  const pts = ring.length > 1 && ring[0][0] === ring[ring.length - 1][0] && ring[0][1] === ring[ring.length - 1][1] ? ring.slice(0, -1) : ring;
  const n = pts.length;
  if (n < 4 || n > CROSSING_CHECK_MAX) return false;
  for (let i = 0; i < n; i++) {
    const a0 = pts[i];
    const a1 = pts[(i + 1) % n];
    // Edges i and j are adjacent when j = i ± 1 (mod n): they share a corner by construction.
    for (let j = i + 2; j < n; j++) {
      if (i === 0 && j === n - 1) continue;
      if (segmentsMeet(a0, a1, pts[j], pts[(j + 1) % n])) return true;
    }
  }
  return false;
}

/** Whether closed segments p0p1 and q0q1 share a point. */
function segmentsMeet(p0: LonLat, p1: LonLat, q0: LonLat, q1: LonLat): boolean {
  const d1 = orient(q0, q1, p0);
  const d2 = orient(q0, q1, p1);
  const d3 = orient(p0, p1, q0);
  const d4 = orient(p0, p1, q1);
  if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) return true;
  return (d1 === 0 && onSegment(q0, q1, p0)) || (d2 === 0 && onSegment(q0, q1, p1)) || (d3 === 0 && onSegment(p0, p1, q0)) || (d4 === 0 && onSegment(p0, p1, q1));
}

/** Twice the signed area of triangle abc: > 0 when c is left of ab. */
function orient(a: LonLat, b: LonLat, c: LonLat): number {
  return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

/** Whether c, collinear with ab, lies within its bounding box. */
function onSegment(a: LonLat, b: LonLat, c: LonLat): boolean {
  return Math.min(a[0], b[0]) <= c[0] && c[0] <= Math.max(a[0], b[0]) && Math.min(a[1], b[1]) <= c[1] && c[1] <= Math.max(a[1], b[1]);
}
