// Corridor surveys on the page: a centre line imported from GeoJSON or KML
// and a width, sent as the request's `corridor` and `corridor_width_m`
// instead of `roi`. The reading and the request members are pure (unit-tested);
// CorridorFields wires them to the survey form's controls.

import type { LonLat } from './api';
import { byId, numberValue, setValue } from './dom';
import { ImportError } from './geo-import';

/** A corridor as the form holds it: the centre line (lon/lat) and its width in metres. */
export interface CorridorValues {
  line: LonLat[];
  widthM: number;
}

/** The API's range of `corridor_width_m`. */
export const CORRIDOR_WIDTH_RANGE_M = [1, 2000] as const;

/** The first line of a GeoJSON or KML file (a LineString, or the first part of a MultiLineString). */
export function parseLine(text: string, fileName = ''): LonLat[] {
  const trimmed = text.trimStart();
  if (trimmed === '') throw new ImportError('The file is empty.');
  const isKml = /\.kml$/i.test(fileName) || trimmed.startsWith('<');
  const line = isKml ? kmlLine(text) : geoJsonLine(text);
  if (!line) throw new ImportError('The file holds no line (a GeoJSON LineString or a KML LineString).');
  const distinct = line.filter((p, i) => i === 0 || p[0] !== line[i - 1][0] || p[1] !== line[i - 1][1]);
  if (distinct.length < 2) throw new ImportError('The line has fewer than two distinct positions.');
  return distinct;
}

function geoJsonLine(text: string): LonLat[] | null {
  let doc: unknown;
  try {
    doc = JSON.parse(text);
  } catch {
    throw new ImportError('The file is neither GeoJSON nor KML (it is not valid JSON).');
  }
  return lineOf(doc);
}

/** The first line in a GeoJSON value (geometry, Feature or FeatureCollection), or null. */
export function lineOf(node: unknown): LonLat[] | null {
  if (!node || typeof node !== 'object') return null;
  const n = node as { type?: string; coordinates?: unknown; geometry?: unknown; features?: unknown; geometries?: unknown };
  switch (n.type) {
    case 'LineString':
      return positions(n.coordinates);
    case 'MultiLineString':
      return Array.isArray(n.coordinates) ? positions(n.coordinates[0]) : null;
    case 'Feature':
      return lineOf(n.geometry);
    case 'FeatureCollection':
    case 'GeometryCollection': {
      const members = n.type === 'FeatureCollection' ? n.features : n.geometries;
      for (const m of Array.isArray(members) ? members : []) {
        const line = lineOf(m);
        if (line) return line;
      }
      return null;
    }
    default:
      return null;
  }
}

function positions(coords: unknown): LonLat[] | null {
  if (!Array.isArray(coords)) return null;
  const out: LonLat[] = [];
  for (const p of coords) {
    if (!Array.isArray(p) || p.length < 2) throw new ImportError('A position of the line is not [lon, lat].');
    const [lon, lat] = [Number(p[0]), Number(p[1])];
    if (!Number.isFinite(lon) || !Number.isFinite(lat) || Math.abs(lon) > 180 || Math.abs(lat) > 90) {
      throw new ImportError(`The position ${JSON.stringify(p)} is not a longitude and latitude.`);
    }
    out.push([lon, lat]);
  }
  return out;
}

function kmlLine(text: string): LonLat[] | null {
  const doc = new DOMParser().parseFromString(text, 'application/xml');
  if (doc.getElementsByTagName('parsererror').length > 0) throw new ImportError('The KML file is not well-formed XML.');
  const ls = doc.getElementsByTagName('LineString')[0];
  const coords = ls?.getElementsByTagName('coordinates')[0]?.textContent;
  if (!coords) return null;
  return positions(coords.trim().split(/\s+/).map((t) => t.split(',').map(Number)));
}

/** The line's length in metres (haversine on the mean Earth radius: for the status line only). */
export function lineLengthM(line: LonLat[]): number {
  const r = 6_371_008.8;
  const rad = Math.PI / 180;
  let total = 0;
  for (let i = 1; i < line.length; i++) {
    const [a, b] = [line[i - 1], line[i]];
    const dLat = (b[1] - a[1]) * rad;
    const dLon = (b[0] - a[0]) * rad;
    const h = Math.sin(dLat / 2) ** 2 + Math.cos(a[1] * rad) * Math.cos(b[1] * rad) * Math.sin(dLon / 2) ** 2;
    total += 2 * r * Math.asin(Math.sqrt(h));
  }
  return total;
}

/** The request members of a corridor, or the fault that keeps it from being sent. */
export function corridorMembers(c: CorridorValues): { members: Record<string, unknown> } | { error: string } {
  const [lo, hi] = CORRIDOR_WIDTH_RANGE_M;
  if (!Number.isFinite(c.widthM) || c.widthM < lo || c.widthM > hi) {
    return { error: `Corridor width: give a number of metres from ${lo} to ${hi}.` };
  }
  return { members: { corridor: { type: 'LineString', coordinates: c.line.map((p) => [p[0], p[1]]) }, corridor_width_m: c.widthM } };
}

/** A saved request's corridor, if it was one. */
export function corridorFromRequest(r: Record<string, unknown>): CorridorValues | null {
  const line = lineOf(r.corridor);
  if (!line) return null;
  return { line, widthM: typeof r.corridor_width_m === 'number' ? r.corridor_width_m : NaN };
}

/** The corridor controls of the survey form: import, clear, width, status. */
export class CorridorFields {
  private line: LonLat[] | null = null;

  /** `show` puts the line on the map (`fit`: and zooms to it); `changed` marks the plan stale; `fault` shows an import error. */
  constructor(
    private readonly show: (line: LonLat[] | null, fit: boolean) => void,
    private readonly changed: () => void,
    private readonly fault: (text: string) => void,
  ) {
    byId<HTMLInputElement>('import-corridor').addEventListener('change', (e) => void this.importFile(e.target as HTMLInputElement));
    byId('clear-corridor').addEventListener('click', () => this.set(null));
    byId('corridor-width').addEventListener('input', () => this.showStatus());
  }

  /** The corridor to plan, or null to plan the area. */
  values(): CorridorValues | null {
    return this.line ? { line: this.line, widthM: numberValue('corridor-width') } : null;
  }

  restore(c: CorridorValues | null): void {
    if (c && Number.isFinite(c.widthM)) setValue('corridor-width', c.widthM);
    this.set(c?.line ?? null);
  }

  /** A line drawn on the map (two distinct points at least). */
  drawn(line: LonLat[]): void {
    const distinct = line.filter((p, i) => i === 0 || p[0] !== line[i - 1][0] || p[1] !== line[i - 1][1]);
    if (distinct.length < 2) this.fault('Corridor: draw at least two distinct points.');
    else this.set(distinct);
  }

  private set(line: LonLat[] | null, fit = false): void {
    this.line = line;
    this.show(line, fit);
    byId<HTMLDetailsElement>('corridor-fields').open ||= line !== null;
    this.showStatus();
    this.changed();
  }

  private showStatus(): void {
    const w = numberValue('corridor-width');
    byId('corridor-status').textContent = this.line
      ? `Corridor: a line of ${(lineLengthM(this.line) / 1000).toFixed(2)} km (${this.line.length} positions), ` +
        `${Number.isFinite(w) ? `${w} m` : '–'} wide: surveyed instead of the area.`
      : 'No line: the area is surveyed.';
  }

  private async importFile(input: HTMLInputElement): Promise<void> {
    const file = input.files?.[0];
    input.value = '';
    if (!file) return;
    try {
      this.set(parseLine(await file.text(), file.name), true);
    } catch (err) {
      const message = err instanceof ImportError ? err.message : `The file could not be read (${(err as Error).message}).`;
      this.fault(`${file.name}: ${message}`);
    }
  }
}
