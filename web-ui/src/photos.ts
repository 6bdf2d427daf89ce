// Planned photos on the page: the overlaps each cell achieves on the ground
// against the requested ones (cells below them are flagged on the map), and
// the footprints of a UAV's photos (its photos.geojson) as rings to draw.

import type { LonLat, Survey } from './api';

/** The overlaps asked for; `side` null where `line_spacing_m` set the lanes instead. */
export interface RequestedOverlaps {
  front: number;
  side: number | null;
}

/** A cell's achieved overlaps (minimum over its photos), as the plan reports them. */
export interface CellOverlap {
  id: number;
  photos: number;
  frontMin: number | null;
  sideMin: number | null;
  gsdMedian: number | null;
  /** Below the requested front overlap, or side overlap. */
  lowFront: boolean;
  lowSide: boolean;
}

/** Rounding of the reported figures (1e-4) and of the lanes' placement: not a shortfall. */
const SLACK = 0.005;

const DEFAULT_FRONT = 0.8;
const DEFAULT_SIDE = 0.7;

/** The overlaps a survey's request asked for (the planner's defaults where it gave none). */
export function requestedOverlaps(request: Record<string, unknown> | null | undefined): RequestedOverlaps {
  const r = request ?? {};
  const num = (v: unknown, fallback: number) => (typeof v === 'number' && Number.isFinite(v) ? v : fallback);
  return {
    front: num(r.front_overlap, DEFAULT_FRONT),
    side: typeof r.line_spacing_m === 'number' ? null : num(r.side_overlap, DEFAULT_SIDE),
  };
}

/** Each cell's achieved overlaps (cells planned before photos were have none: left out). */
export function cellOverlaps(survey: Pick<Survey, 'cells'>, requested: RequestedOverlaps): CellOverlap[] {
  const out: CellOverlap[] = [];
  for (const f of survey.cells.features) {
    const p = f.properties ?? {};
    if (typeof p.photos !== 'number' || typeof p.id !== 'number') continue;
    const value = (k: string) => (typeof p[k] === 'number' ? (p[k] as number) : null);
    const frontMin = value('front_overlap_min');
    const sideMin = value('side_overlap_min');
    out.push({
      id: p.id,
      photos: p.photos,
      frontMin,
      sideMin,
      gsdMedian: value('gsd_cm_px_median'),
      lowFront: frontMin !== null && frontMin < requested.front - SLACK,
      lowSide: sideMin !== null && requested.side !== null && sideMin < requested.side - SLACK,
    });
  }
  return out;
}

/** Ids of the cells whose achieved overlap falls below the requested one. */
export function lowOverlapCells(overlaps: CellOverlap[]): Set<number> {
  return new Set(overlaps.filter((c) => c.lowFront || c.lowSide).map((c) => c.id));
}

/** What a flagged cell lacks, for its label: "front 74 % < 80 %, side 62 % < 70 %". */
export function shortfallText(c: CellOverlap, requested: RequestedOverlaps): string {
  const pct = (v: number) => `${Math.round(v * 100)} %`;
  const parts: string[] = [];
  if (c.lowFront && c.frontMin !== null) parts.push(`front ${pct(c.frontMin)} < ${pct(requested.front)}`);
  if (c.lowSide && c.sideMin !== null && requested.side !== null) parts.push(`side ${pct(c.sideMin)} < ${pct(requested.side)}`);
  return parts.join(', ');
}

/** One photo's footprint: its ring (lon/lat, closed) and where it was taken. */
export interface Footprint {
  ring: LonLat[];
  sortie: number;
  cell: number;
  timeS: number;
}

/** The footprints of a photos.geojson FeatureCollection; anything else gives none. */
export function footprints(doc: unknown): Footprint[] {
  const features = (doc as { features?: unknown })?.features;
  if (!Array.isArray(features)) return [];
  const out: Footprint[] = [];
  for (const f of features as { geometry?: { type?: string; coordinates?: unknown }; properties?: Record<string, unknown> }[]) {
    if (f?.geometry?.type !== 'Polygon' || !Array.isArray(f.geometry.coordinates)) continue;
    const ring = (f.geometry.coordinates as unknown[][])[0];
    if (!Array.isArray(ring) || ring.length < 4) continue;
    const p = f.properties ?? {};
    out.push({
      ring: ring.map((c) => [Number((c as number[])[0]), Number((c as number[])[1])] as LonLat),
      sortie: typeof p.sortie === 'number' ? p.sortie : 1,
      cell: typeof p.cell === 'number' ? p.cell : -1,
      timeS: typeof p.time_s === 'number' ? p.time_s : 0,
    });
  }
  return out;
}

/** The URL of a UAV's photos.geojson (every sortie), from a sortie's link; null without one. */
export function uavPhotosUrl(survey: Pick<Survey, 'uavs'>, uav: string): string | null {
  const link = survey.uavs.find((u) => u.id === uav)?.sorties[0]?.files.photos;
  return link ? link.split('?')[0] : null;
}
