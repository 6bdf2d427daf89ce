// The changes of the costmap sent with a replan: blocked areas and costlier
// areas ({area, cost}). Pure logic (no DOM) so that it is unit-tested.
//
// The server keeps the changes of a whole chain of replans and applies the
// earlier ones again by itself, so a replan sends only the areas drawn since
// the route was shown; those of the route (its `blocked`, `cost_changes`)
// are shown on the map as "inherited" and never sent twice.

import type { LonLat } from './api';
import type { PolygonRings } from './geo-import';

/** The cost the costlier-area input starts at (costmaps use costs in [1, 20]). */
export const DEFAULT_COST = 15;
/** The largest cost the API takes. */
export const COST_MAX = 1e6;

export interface CostlierArea {
  rings: PolygonRings;
  cost: number;
}

export interface StoredCostChange {
  area: unknown;
  cost: number;
}

/** "the costmap’s cells cost 1.0 to 20.0", for the hint and the messages (null range: not said). */
export function costRangeWords(range: [number, number] | null): string {
  return range ? `the costmap’s cells cost ${range[0].toFixed(1)} to ${range[1].toFixed(1)}` : 'the costmap’s cells cost 1 and more';
}

/** The cost typed in the input, or why it cannot be used; `range` is the costmap's own (its stats). */
export function parseCost(text: string, range: [number, number] | null = null): { cost: number } | { error: string } {
  const t = text.trim();
  const cost = t === '' ? NaN : Number(t);
  if (!Number.isFinite(cost)) return { error: `Cost: type a number greater than 0 (${costRangeWords(range)}).` };
  if (!(cost > 0)) return { error: `Cost: it must be greater than 0, not ${t} (block the area instead to make it impassable).` };
  if (cost > COST_MAX) return { error: `Cost: at most ${COST_MAX.toLocaleString('en')}.` };
  return { cost };
}

/** Polygon rings of a stored area (a Polygon, MultiPolygon or Feature). */
export function areaRings(area: unknown): PolygonRings[] {
  const g = area as { type?: string; coordinates?: unknown; geometry?: unknown } | null;
  if (g?.type === 'Feature') return areaRings(g.geometry);
  if (g?.type === 'Polygon') return [g.coordinates as PolygonRings];
  if (g?.type === 'MultiPolygon') return g.coordinates as PolygonRings[];
  return [];
}

/** A route's stored cost changes as areas to draw. */
export function costlierOfRoute(changes: StoredCostChange[] | undefined): CostlierArea[] {
  return (changes ?? []).flatMap((c) => areaRings(c.area).map((rings) => ({ rings, cost: c.cost })));
}

/**
 * The replan request for the areas drawn since the route was shown, or what
 * is missing. Members without areas are left out.
 */
export function replanBody(
  position: LonLat,
  blocked: PolygonRings[],
  costlier: CostlierArea[],
): { body: Record<string, unknown> } | { error: string } {
  if (blocked.length === 0 && costlier.length === 0) {
    return { error: 'Draw a blocked or a costlier area on the map first.' };
  }
  const polygon = (rings: PolygonRings) => ({ type: 'Polygon', coordinates: rings });
  const body: Record<string, unknown> = { position };
  if (blocked.length) body.blocked = blocked.map(polygon);
  if (costlier.length) body.cost_changes = costlier.map((c) => ({ area: polygon(c.rings), cost: c.cost }));
  return { body };
}

function plural(n: number, what: string): string {
  return `${n} ${what}${n === 1 ? '' : 's'}`;
}

/** The line under the blocked-area buttons. */
export function blockedStatus(drawn: number, inherited: number): string {
  const earlier = inherited ? ` ${plural(inherited, 'area')} blocked by earlier replans.` : '';
  return (drawn ? `${plural(drawn, 'blocked area')} to send.` : 'No blocked area.') + earlier;
}

/** The line under the costlier-area buttons. */
export function costlierStatus(drawn: CostlierArea[], inherited: number): string {
  const costs = [...new Set(drawn.map((c) => c.cost))].join(', ');
  const earlier = inherited ? ` ${plural(inherited, 'area')} made costlier by earlier replans.` : '';
  return (drawn.length ? `${plural(drawn.length, 'costlier area')} to send (cost ${costs}).` : 'No costlier area.') + earlier;
}
