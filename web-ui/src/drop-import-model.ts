// The logic of importing GIS files dropped on the page (or chosen with the
// file chooser): which reader takes a file (the page for WGS84 GeoJSON, the
// server's POST /api/v1/imports for the rest), the request sent, the shapes
// read, what each shape becomes by default (survey area, no-fly zone,
// corridor line) and the messages shown. No DOM here: drop-import.ts puts it
// on the page, and this part is unit-tested.

import { ApiError, apiContext, requestHeaders, type LonLat, type Problem } from './api';
import { lineLengthM } from './corridor-fields';
import { closeRing, foreignGeoJsonCrs, ImportError, toLonLat, utmArea, type PolygonRings } from './geo-import';

export const IMPORT_URL = '/api/v1/imports';

/** The extensions the file chooser offers (the server reads all of them). */
export const IMPORT_ACCEPT = '.zip,.kml,.kmz,.gpx,.gpkg,.geojson,.json';

/** What the formats are called on the page. */
export const IMPORT_FORMATS = 'zipped Shapefile (.zip), KML, KMZ, GPX, GeoPackage (.gpkg) or GeoJSON';

/** Which reader takes a file, or why none does. */
export type Reader = { reader: 'page' | 'server' } | { refused: string };

const SERVER_EXTENSIONS = new Set(['zip', 'kml', 'kmz', 'gpx', 'gpkg']);
const SHAPEFILE_PARTS = new Set(['shp', 'shx', 'dbf', 'prj', 'cpg', 'qix', 'sbn', 'sbx']);
const DEM_EXTENSIONS = new Set(['tif', 'tiff', 'asc', 'hgt']);

function extensionOf(fileName: string): string {
  const dot = fileName.lastIndexOf('.');
  return dot < 0 ? '' : fileName.slice(dot + 1).toLowerCase();
}

/** Whether a file is one part of a Shapefile (.shp, .dbf, …), which must come zipped. */
export function isShapefilePart(fileName: string): boolean {
  return SHAPEFILE_PARTS.has(extensionOf(fileName));
}

/** The message for the loose parts of a Shapefile dropped without their zip. */
export function shapefilePartsMessage(fileNames: string[]): string {
  return (
    `${fileNames.join(', ')}: a Shapefile is several files; zip the .shp, .shx, .dbf and .prj together ` +
    `(the .prj gives its coordinate system) and import the .zip.`
  );
}

/**
 * The reader of a file by its name. GeoJSON is first read by the page
 * (`readerForGeoJson` then decides from its content); the other formats
 * need the server (Shapefiles, GeoPackages and reprojection through PROJ).
 */
export function readerForName(fileName: string): Reader {
  const ext = extensionOf(fileName);
  if (ext === 'geojson' || ext === 'json') return { reader: 'page' };
  if (SERVER_EXTENSIONS.has(ext)) return { reader: 'server' };
  if (SHAPEFILE_PARTS.has(ext)) return { refused: shapefilePartsMessage([fileName]) };
  if (DEM_EXTENSIONS.has(ext)) {
    return { refused: `${fileName}: this looks like a terrain model; upload it under “Terrain model (DEM)”. Areas and lines are imported from a ${IMPORT_FORMATS} file.` };
  }
  return { refused: `${fileName}: not a file the page imports. Give a ${IMPORT_FORMATS} file.` };
}

/**
 * A GeoJSON file's reader from its text: the page for one in WGS84, the
 * server for one whose legacy `crs` names another CRS (it reprojects).
 * `doc` is the parsed document when the page reads it.
 */
export function readerForGeoJson(fileName: string, text: string): { reader: 'page'; doc: unknown } | { reader: 'server' } | { refused: string } {
  if (text.trim() === '') return { refused: `${fileName}: the file is empty.` };
  let doc: unknown;
  try {
    doc = JSON.parse(text);
  } catch (err) {
    return { refused: `${fileName}: not valid JSON (${(err as Error).message}).` };
  }
  return foreignGeoJsonCrs(doc) !== null ? { reader: 'server' } : { reader: 'page', doc };
}

/** The server's answer to an import (and what the page makes of a WGS84 GeoJSON file). */
export interface ImportAnswer {
  features: { type: 'FeatureCollection'; features: unknown[] };
  messages: string[];
}

/** The request that sends `file` to the import endpoint: a multipart form whose part `file` is the file, with its name. */
export function importRequest(file: File): { url: string; init: RequestInit } {
  const form = new FormData();
  form.append('file', file, file.name);
  // No Content-Type: the browser writes multipart/form-data with its boundary.
  return { url: IMPORT_URL, init: { method: 'POST', body: form, headers: requestHeaders('POST', false), credentials: 'same-origin' } };
}

/** Sends `file` to the server's import; an ApiError (problem+json) when it refuses. */
export async function importOnServer(file: File, fetchImpl: typeof fetch = fetch): Promise<ImportAnswer> {
  const { url, init } = importRequest(file);
  let res: Response;
  try {
    res = await fetchImpl(url, init);
  } catch {
    throw new ApiError({ status: 0, detail: 'The terraplan server cannot be reached.' });
  }
  const text = await res.text();
  if (!res.ok) {
    const problem = problemOf(res, text);
    if (res.status === 401) apiContext.onUnauthorized?.(problem);
    throw new ApiError(problem);
  }
  let answer: unknown;
  try {
    answer = JSON.parse(text);
  } catch {
    throw new ApiError({ status: res.status, detail: 'The server’s answer to the import is not JSON.' });
  }
  const a = answer as Partial<ImportAnswer> | null;
  if (!a || typeof a !== 'object' || !a.features || !Array.isArray(a.features.features)) {
    throw new ApiError({ status: res.status, detail: 'The server’s answer to the import holds no feature collection.' });
  }
  return { features: a.features, messages: Array.isArray(a.messages) ? a.messages.map(String) : [] };
}

function problemOf(res: Response, text: string): Problem {
  try {
    const p = JSON.parse(text) as Problem;
    if (typeof p.detail === 'string' || Array.isArray(p.errors)) return { ...p, status: res.status };
  } catch {
    /* not JSON */
  }
  return { status: res.status, detail: text || res.statusText || `HTTP ${res.status}` };
}

/** A file's fault as one plain sentence, naming the file. */
export function importErrorText(fileName: string, err: unknown): string {
  if (err instanceof ApiError) {
    const p = err.problem;
    if (p.status === 401) return `${fileName}: you are signed out. Sign in again, then import the file again.`;
    if (p.status === 0) return `${fileName}: ${p.detail} Nothing was imported.`;
    const faults = (p.errors ?? []).map((e) => e.message).filter((m) => m);
    const what = faults.length ? faults.join('; ') : p.detail || p.title || `HTTP ${p.status}`;
    return `${fileName}: ${what}`;
  }
  if (err instanceof ImportError) return `${fileName}: ${err.message}`;
  return `${fileName}: the file could not be read (${err instanceof Error ? err.message : String(err)}).`;
}

// ---- shapes ----

export type Shape =
  | { type: 'polygon'; rings: PolygonRings }
  | { type: 'line'; line: LonLat[] };

/** One polygon or line read from a file, with what the page shows of it. */
export interface ImportedShape {
  /** The file it came from. */
  file: string;
  /** Its name in the file (a `name` attribute), else its place ("feature 3", "feature 3, part 2"). */
  label: string;
  shape: Shape;
  /** Area (m², polygons) or length (m, lines). */
  size: number;
}

/** The name attribute of a feature, when it has one. */
function nameOf(properties: unknown): string | null {
  if (!properties || typeof properties !== 'object') return null;
  const p = properties as Record<string, unknown>;
  for (const key of ['name', 'Name', 'NAME', 'title', 'id', 'ID']) {
    const v = p[key];
    if ((typeof v === 'string' && v.trim() !== '') || typeof v === 'number') return String(v).trim();
  }
  return null;
}

function ringOf(coords: unknown): LonLat[] {
  if (!Array.isArray(coords)) throw new ImportError('a polygon ring is not a list of positions');
  return closeRing(coords.map(toLonLat));
}

function lineFrom(coords: unknown): LonLat[] {
  if (!Array.isArray(coords)) throw new ImportError('a line is not a list of positions');
  const line = coords.map(toLonLat);
  return line.filter((p, i) => i === 0 || p[0] !== line[i - 1][0] || p[1] !== line[i - 1][1]);
}

/** The polygon from GeoJSON Polygon coordinates, or why it is unusable. */
function polygonFrom(coords: unknown): PolygonRings | string {
  if (!Array.isArray(coords) || coords.length === 0) return 'a polygon without rings';
  const rings = coords.map(ringOf);
  if (rings[0].length < 4) return 'its outline has fewer than three corners';
  return rings.filter((r, i) => i === 0 || r.length >= 4);
}

/**
 * The polygons and lines of a GeoJSON FeatureCollection (WGS84), each part
 * of a Multi* geometry a shape of its own (each may become something else),
 * and a message for every feature that gives none (points, empty or
 * degenerate geometries). Positions that are not lon/lat throw: the whole
 * file is then in another CRS.
 */
export function shapesOf(fileName: string, collection: unknown): { shapes: ImportedShape[]; messages: string[] } {
  const shapes: ImportedShape[] = [];
  const messages: string[] = [];
  const c = collection as { type?: string; features?: unknown[] } | null;
  const features: unknown[] =
    c?.type === 'FeatureCollection' && Array.isArray(c.features)
      ? c.features
      : c?.type === 'Feature'
        ? [c]
        : c && typeof c === 'object' && 'type' in c
          ? [{ type: 'Feature', properties: {}, geometry: c }]
          : [];
  if (features.length === 0 && !(c?.type === 'FeatureCollection')) throw new ImportError('not GeoJSON (no FeatureCollection, Feature or geometry)');
  features.forEach((f, i) => {
    const feature = f as { geometry?: { type?: string; coordinates?: unknown; geometries?: unknown[] } | null; properties?: unknown };
    const name = nameOf(feature?.properties);
    const label = name ?? `feature ${i + 1}`;
    const geometries = feature?.geometry?.type === 'GeometryCollection' ? (feature.geometry.geometries ?? []) : [feature?.geometry];
    const parts: { shape: Shape }[] = [];
    const skipped: string[] = [];
    for (const g0 of geometries) {
      const g = g0 as { type?: string; coordinates?: unknown } | null | undefined;
      switch (g?.type) {
        case 'Polygon':
        case 'MultiPolygon': {
          const polys = g.type === 'Polygon' ? [g.coordinates] : Array.isArray(g.coordinates) ? g.coordinates : [];
          for (const p of polys) {
            const rings = polygonFrom(p);
            if (typeof rings === 'string') skipped.push(rings);
            else parts.push({ shape: { type: 'polygon', rings } });
          }
          break;
        }
        case 'LineString':
        case 'MultiLineString': {
          const lines = g.type === 'LineString' ? [g.coordinates] : Array.isArray(g.coordinates) ? g.coordinates : [];
          for (const l of lines) {
            const line = lineFrom(l);
            if (line.length < 2) skipped.push('a line with fewer than two distinct positions');
            else parts.push({ shape: { type: 'line', line } });
          }
          break;
        }
        case 'Point':
        case 'MultiPoint':
          skipped.push('points are not imported (only polygons and lines)');
          break;
        case undefined:
          skipped.push('no geometry');
          break;
        default:
          skipped.push(`a ${g?.type} is neither a polygon nor a line`);
      }
    }
    parts.forEach((p, k) => {
      const partLabel = parts.length > 1 ? `${label}, part ${k + 1}` : label;
      const size = p.shape.type === 'polygon' ? utmArea(p.shape.rings) : lineLengthM(p.shape.line);
      shapes.push({ file: fileName, label: partLabel, shape: p.shape, size });
    });
    for (const why of new Set(skipped)) messages.push(`${label} skipped: ${why}`);
  });
  return { shapes, messages };
}

// ---- what the shapes become ----

export type Role = 'roi' | 'nfz' | 'corridor' | 'none';

export const ROLE_NAMES: Record<Role, string> = {
  roi: 'Survey area',
  nfz: 'No-fly zone',
  corridor: 'Corridor line',
  none: 'Not used',
};

/** The roles a shape may take: polygons are areas, lines only corridor lines. */
export function rolesFor(shape: Shape): Role[] {
  return shape.type === 'polygon' ? ['roi', 'nfz', 'none'] : ['corridor', 'none'];
}

/**
 * What each shape becomes unless the user says otherwise: the largest
 * polygon the survey area when there is none yet, the other polygons
 * no-fly zones; the longest line the corridor's centre line (a survey flies
 * one), other lines not used.
 */
export function defaultRoles(shapes: ImportedShape[], hasRoi: boolean): Role[] {
  const roles: Role[] = shapes.map((s) => (s.shape.type === 'polygon' ? 'nfz' : 'none'));
  const largest = (type: Shape['type']) =>
    shapes.reduce((best, s, i) => (s.shape.type === type && (best < 0 || s.size > shapes[best].size) ? i : best), -1);
  const roi = hasRoi ? -1 : largest('polygon');
  if (roi >= 0) roles[roi] = 'roi';
  const line = largest('line');
  if (line >= 0) roles[line] = 'corridor';
  return roles;
}

/** Sets every polygon (or every line) to `role`, keeping one survey area and one corridor line at most. */
export function setAllRoles(shapes: ImportedShape[], roles: Role[], type: Shape['type'], role: Role): Role[] {
  return roles.map((r, i) => (shapes[i].shape.type === type ? role : r));
}

/** Why the chosen roles cannot be applied (null: they can). */
export function rolesFault(shapes: ImportedShape[], roles: Role[]): string | null {
  const count = (role: Role) => roles.filter((r) => r === role).length;
  if (count('roi') > 1) return `${count('roi')} polygons are chosen as the survey area: a survey has one. Make the others no-fly zones or leave them out.`;
  if (count('corridor') > 1) return `${count('corridor')} lines are chosen as the corridor line: a corridor follows one line. Leave the others out.`;
  for (const [i, r] of roles.entries()) {
    if (!rolesFor(shapes[i].shape).includes(r)) return `${shapes[i].label} (${shapes[i].file}) is a ${shapes[i].shape.type}: it cannot be a ${ROLE_NAMES[r].toLowerCase()}.`;
  }
  if (roles.every((r) => r === 'none')) return 'Nothing is chosen to import.';
  return null;
}

/** What applying the roles puts into the survey. */
export interface ImportPlan {
  roi: PolygonRings | null;
  noFlyZones: PolygonRings[];
  corridor: LonLat[] | null;
}

export function importPlan(shapes: ImportedShape[], roles: Role[]): ImportPlan {
  const plan: ImportPlan = { roi: null, noFlyZones: [], corridor: null };
  shapes.forEach((s, i) => {
    if (s.shape.type === 'polygon' && roles[i] === 'roi') plan.roi = s.shape.rings;
    else if (s.shape.type === 'polygon' && roles[i] === 'nfz') plan.noFlyZones.push(s.shape.rings);
    else if (s.shape.type === 'line' && roles[i] === 'corridor') plan.corridor = s.shape.line;
  });
  return plan;
}

/** One sentence on what applying the plan does, for the dialog and the panel. */
export function describePlan(plan: ImportPlan, had: { roi: boolean; corridor: boolean }): string {
  const parts: string[] = [];
  if (plan.roi) parts.push(had.roi ? 'the survey area (replacing the current one)' : 'the survey area');
  if (plan.noFlyZones.length) parts.push(`${plan.noFlyZones.length} no-fly zone${plan.noFlyZones.length > 1 ? 's' : ''}`);
  if (plan.corridor) parts.push(had.corridor ? 'the corridor line (replacing the current one; the corridor is planned instead of the area)' : 'the corridor line (the corridor is planned instead of the area)');
  if (parts.length === 0) return 'Nothing is imported.';
  const list = parts.length === 1 ? parts[0] : `${parts.slice(0, -1).join(', ')} and ${parts[parts.length - 1]}`;
  return `Imports ${list}.`;
}

/** The lon/lat extent [west, south, east, north] of a plan's shapes (null when empty). */
export function planExtent(plan: ImportPlan): [number, number, number, number] | null {
  const pts: LonLat[] = [...(plan.roi ?? []).flat(), ...plan.noFlyZones.flatMap((z) => z.flat()), ...(plan.corridor ?? [])];
  if (pts.length === 0) return null;
  let [w, s, e, n] = [Infinity, Infinity, -Infinity, -Infinity];
  for (const [lon, lat] of pts) {
    w = Math.min(w, lon);
    e = Math.max(e, lon);
    s = Math.min(s, lat);
    n = Math.max(n, lat);
  }
  return [w, s, e, n];
}

// ---- reading files ----

/** What one file gave: its shapes and messages about what was skipped, or the fault that stopped it. */
export interface FileResult {
  file: string;
  /** Who read it: the page (WGS84 GeoJSON) or the server. */
  readBy: 'page' | 'server' | null;
  shapes: ImportedShape[];
  messages: string[];
  error: string | null;
}

/**
 * Reads the dropped or chosen files, one after the other (one request
 * each: the endpoint takes one file). Loose Shapefile parts are reported
 * once together. Never throws: each file's fault is in its result.
 */
export async function readFiles(files: File[], fetchImpl: typeof fetch = fetch): Promise<FileResult[]> {
  const results: FileResult[] = [];
  const parts = files.filter((f) => isShapefilePart(f.name));
  if (parts.length) {
    results.push({ file: parts.map((f) => f.name).join(', '), readBy: null, shapes: [], messages: [], error: shapefilePartsMessage(parts.map((f) => f.name)) });
  }
  for (const file of files.filter((f) => !isShapefilePart(f.name))) results.push(await readFile(file, fetchImpl));
  return results;
}

export async function readFile(file: File, fetchImpl: typeof fetch = fetch): Promise<FileResult> {
  const result: FileResult = { file: file.name, readBy: null, shapes: [], messages: [], error: null };
  try {
    let reader = readerForName(file.name);
    let doc: unknown;
    if ('reader' in reader && reader.reader === 'page') {
      const byContent = readerForGeoJson(file.name, await file.text());
      if ('doc' in byContent) doc = byContent.doc;
      reader = byContent;
    }
    if ('refused' in reader) {
      result.error = reader.refused;
      return result;
    }
    result.readBy = reader.reader;
    const answer = reader.reader === 'server' ? await importOnServer(file, fetchImpl) : { features: doc, messages: [] as string[] };
    const read = shapesOf(file.name, answer.features);
    result.shapes = read.shapes;
    result.messages = [...answer.messages, ...read.messages];
    if (read.shapes.length === 0) result.error = `${file.name}: no polygon or line to import${result.messages.length ? ' (see what was skipped)' : ''}.`;
  } catch (err) {
    result.error = importErrorText(file.name, err);
  }
  return result;
}
