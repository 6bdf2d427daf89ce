// The altitude profile of a UAV's flight over the terrain: a small SVG line
// chart (a chart library would weigh more than the rest of the page).

import type { ProfilePoint, Uav } from './api';
import { h, swatch } from './dom';

export interface ChartBox {
  width: number;
  height: number;
  left: number;
  right: number;
  top: number;
  bottom: number;
}

export interface ChartScale {
  xMax: number;
  yMin: number;
  yMax: number;
  x: (distance: number) => number;
  y: (height: number) => number;
  xTicks: number[];
  yTicks: number[];
}

export const DEFAULT_BOX: ChartBox = { width: 360, height: 170, left: 44, right: 10, top: 10, bottom: 28 };

/** A "nice" tick step (1, 2 or 5 × 10^k) giving about `count` ticks over `span`. */
export function niceStep(span: number, count = 5): number {
  if (!(span > 0)) return 1;
  const raw = span / count;
  const mag = 10 ** Math.floor(Math.log10(raw));
  const norm = raw / mag;
  return (norm <= 1 ? 1 : norm <= 2 ? 2 : norm <= 5 ? 5 : 10) * mag;
}

function ticks(min: number, max: number, step: number): number[] {
  const out: number[] = [];
  for (let v = Math.ceil(min / step - 1e-9) * step; v <= max + 1e-9; v += step) out.push(Number(v.toFixed(10)));
  return out;
}

/**
 * Scales a profile into the box: distance 0…max on x; heights on y over both
 * the flown altitude and the terrain, padded out to whole tick steps so the
 * lines never touch the frame.
 */
export function profileScale(points: ProfilePoint[], box: ChartBox = DEFAULT_BOX): ChartScale {
  const heights: number[] = [];
  let xMax = 0;
  for (const p of points) {
    xMax = Math.max(xMax, p.distance_m);
    heights.push(p.altitude_m);
    if (p.terrain_m != null && Number.isFinite(p.terrain_m)) heights.push(p.terrain_m);
  }
  let lo = heights.length ? Math.min(...heights) : 0;
  let hi = heights.length ? Math.max(...heights) : 1;
  if (hi - lo < 1) {
    lo -= 0.5;
    hi += 0.5;
  }
  const yStep = niceStep(hi - lo, 4);
  const yMin = Math.floor(lo / yStep) * yStep;
  const yMax = Math.ceil(hi / yStep) * yStep;
  if (xMax <= 0) xMax = 1;
  const plotW = box.width - box.left - box.right;
  const plotH = box.height - box.top - box.bottom;
  return {
    xMax,
    yMin,
    yMax,
    x: (d) => box.left + (d / xMax) * plotW,
    y: (h) => box.top + (1 - (h - yMin) / (yMax - yMin)) * plotH,
    xTicks: ticks(0, xMax, niceStep(xMax, 4)),
    yTicks: ticks(yMin, yMax, yStep),
  };
}

/**
 * Profile points from a route's coordinates and the mission's altitude at
 * each (no terrain), for surveys without a DEM. The altitudes come from the
 * sortie's `mission_altitudes_m`, not the coordinates: a GeoJSON position's
 * third value is a height above the WGS 84 ellipsoid, and a survey without a
 * DEM has 2D positions.
 */
export function profileFromRoute(coords: number[][], altitudes: number[]): ProfilePoint[] {
  const out: ProfilePoint[] = [];
  let dist = 0;
  for (let i = 0; i < coords.length; i++) {
    if (i > 0) dist += haversine(coords[i - 1], coords[i]);
    out.push({ distance_m: dist, altitude_m: altitudes[i] ?? 0, terrain_m: null });
  }
  return out;
}

/** What the chart shows for one sortie of a UAV. */
export interface SortieProfile {
  /** The sortie charted (0-based), clamped to the UAV's sorties. */
  index: number;
  /** How many sorties the UAV flies (the sortie chooser shows when more than one). */
  count: number;
  points: ProfilePoint[];
  /** Whether the points are the server's terrain profile (AMSL, with the DEM under them). */
  overTerrain: boolean;
}

/**
 * The profile of one sortie of a UAV: its terrain profile when the survey
 * followed a DEM, else one derived from the route and its mission altitudes.
 *
 * One sortie at a time, chosen by the user, rather than all of them one after
 * another: each sortie starts again from the take-off point (distance 0,
 * climb and descent at home), so chained profiles would show saw-teeth that
 * are not flown in one go, and would squeeze each sortie's detail into a
 * fraction of the chart's width. It also matches the per-sortie downloads.
 */
export function sortieProfile(uav: Uav, sortie: number): SortieProfile {
  const count = uav.sorties.length;
  const index = Math.min(Math.max(0, Math.trunc(sortie) || 0), Math.max(0, count - 1));
  const s = uav.sorties[index];
  const terrain = s?.terrain?.profile;
  if (terrain && terrain.length > 1) return { index, count, points: terrain, overTerrain: true };
  return { index, count, points: profileFromRoute(s?.route.coordinates ?? [], s?.mission_altitudes_m ?? []), overTerrain: false };
}

function haversine(a: number[], b: number[]): number {
  const R = 6_371_008.8;
  const rad = Math.PI / 180;
  const dLat = (b[1] - a[1]) * rad;
  const dLon = (b[0] - a[0]) * rad;
  const h = Math.sin(dLat / 2) ** 2 + Math.cos(a[1] * rad) * Math.cos(b[1] * rad) * Math.sin(dLon / 2) ** 2;
  return 2 * R * Math.asin(Math.sqrt(h));
}

const SVG = 'http://www.w3.org/2000/svg';

function el(name: string, attrs: Record<string, string | number>, text?: string): SVGElement {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (text !== undefined) e.textContent = text;
  return e;
}

/**
 * The SVG path of the terrain under a profile: one closed area per run of
 * points with a known terrain height, each down to the axis at `bottom`
 * (a gap in the DEM splits the terrain, rather than one area spanning it).
 */
export function terrainArea(points: ProfilePoint[], s: { x(d: number): number; y(h: number): number }, bottom: number): string {
  let path = '';
  let run: ProfilePoint[] = [];
  const close = () => {
    if (run.length >= 2) {
      path += run.map((p, i) => `${i ? 'L' : 'M'}${s.x(p.distance_m).toFixed(1)},${s.y(p.terrain_m!).toFixed(1)}`).join('');
      path += `L${s.x(run[run.length - 1].distance_m).toFixed(1)},${bottom}L${s.x(run[0].distance_m).toFixed(1)},${bottom}Z`;
    }
    run = [];
  };
  for (const p of points) {
    if (p.terrain_m == null) close();
    else run.push(p);
  }
  close();
  return path;
}

/** Draws the chart into `container` (replacing what was there). */
export function renderProfileChart(
  container: HTMLElement,
  points: ProfilePoint[],
  opts: { colour: string; title: string; altitudeLabel: string },
  box: ChartBox = DEFAULT_BOX,
): void {
  container.replaceChildren();
  if (points.length < 2) {
    container.textContent = 'No altitude profile for this UAV.';
    return;
  }
  const s = profileScale(points, box);
  const svg = el('svg', {
    viewBox: `0 0 ${box.width} ${box.height}`,
    role: 'img',
    'aria-label': opts.title,
    class: 'profile-chart',
  }) as SVGSVGElement;
  const title = el('title', {}, opts.title);
  svg.append(title);
  const bottom = box.height - box.bottom;
  for (const t of s.yTicks) {
    svg.append(el('line', { x1: box.left, x2: box.width - box.right, y1: s.y(t), y2: s.y(t), class: 'grid' }));
    svg.append(el('text', { x: box.left - 4, y: s.y(t) + 4, 'text-anchor': 'end', class: 'tick' }, `${Math.round(t)}`));
  }
  for (const t of s.xTicks) {
    svg.append(el('text', { x: s.x(t), y: bottom + 14, 'text-anchor': 'middle', class: 'tick' }, `${Math.round(t)}`));
  }
  svg.append(el('text', { x: box.width - box.right, y: box.height - 2, 'text-anchor': 'end', class: 'axis' }, 'distance (m)'));
  svg.append(el('text', { x: 2, y: box.top + 8, class: 'axis' }, 'm'));

  // Terrain as a filled area, where known: each run between gaps is its own area down to the axis.
  const terrainPath = terrainArea(points, s, bottom);
  if (terrainPath) svg.append(el('path', { d: terrainPath, class: 'terrain' }));
  const flown = points.map((p, i) => `${i ? 'L' : 'M'}${s.x(p.distance_m).toFixed(1)},${s.y(p.altitude_m).toFixed(1)}`).join('');
  svg.append(el('path', { d: flown, class: 'flown', stroke: opts.colour }));
  container.append(svg);
  const legend = document.createElement('p');
  legend.className = 'chart-legend';
  // Built as nodes, not markup: the page sets no HTML from strings (and the CSP takes no style attributes).
  legend.append(swatch(opts.colour), ` ${opts.altitudeLabel}`);
  if (terrainPath) legend.append(' ', h('span', { class: 'swatch terrain-swatch' }), ' terrain (DEM)');
  container.append(legend);
}
