import { describe, expect, it } from 'vitest';
import { problemToMessages, ROUTE_FIELDS } from '../src/problems';
import { blockedStatus, costlierOfRoute, costlierStatus, DEFAULT_COST, parseCost, replanBody } from '../src/route-changes';
import type { PolygonRings } from '../src/geo-import';

const square: PolygonRings = [[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]];
const other: PolygonRings = [[[2, 2], [3, 2], [3, 3], [2, 2]]];

describe('parseCost', () => {
  it('takes numbers greater than 0', () => {
    expect(parseCost(String(DEFAULT_COST))).toEqual({ cost: 15 });
    expect(parseCost(' 0.5 ')).toEqual({ cost: 0.5 });
  });
  it('refuses blanks, non-numbers, zero, negatives and more than the API takes', () => {
    for (const t of ['', 'abc', '0', '-3', '1e7', 'Infinity']) expect(parseCost(t)).toHaveProperty('error');
    expect((parseCost('0') as { error: string }).error).toMatch(/greater than 0/);
    // The costmap's own range, when known (small-wheeled: 1.5 to 25).
    expect(parseCost('x', [1.5, 25])).toEqual({ error: 'Cost: type a number greater than 0 (the costmap’s cells cost 1.5 to 25.0).' });
    expect(parseCost('x')).toEqual({ error: 'Cost: type a number greater than 0 (the costmap’s cells cost 1 and more).' });
  });
});

describe('replanBody', () => {
  it('sends cost changes as {area: Polygon, cost}, without an empty blocked member', () => {
    const r = replanBody([1, 2], [], [{ rings: square, cost: 15 }]);
    expect(r).toEqual({ body: { position: [1, 2], cost_changes: [{ area: { type: 'Polygon', coordinates: square }, cost: 15 }] } });
  });
  it('sends blocked areas and cost changes together', () => {
    const r = replanBody([1, 2], [other], [{ rings: square, cost: 3 }]) as { body: Record<string, unknown> };
    expect(r.body.blocked).toEqual([{ type: 'Polygon', coordinates: other }]);
    expect(r.body.cost_changes).toHaveLength(1);
  });
  it('needs at least one area', () => {
    expect(replanBody([1, 2], [], [])).toHaveProperty('error');
  });
});

describe('costlierOfRoute', () => {
  it('reads Polygons, MultiPolygons and Features, each with its cost', () => {
    const areas = costlierOfRoute([
      { area: { type: 'Polygon', coordinates: square }, cost: 15 },
      { area: { type: 'Feature', geometry: { type: 'MultiPolygon', coordinates: [square, other] } }, cost: 4 },
    ]);
    expect(areas).toEqual([{ rings: square, cost: 15 }, { rings: square, cost: 4 }, { rings: other, cost: 4 }]);
    expect(costlierOfRoute(undefined)).toEqual([]);
  });
});

describe('status lines', () => {
  it('count the areas to send and those of earlier replans', () => {
    expect(blockedStatus(0, 0)).toBe('No blocked area.');
    expect(blockedStatus(1, 2)).toBe('1 blocked area to send. 2 areas blocked by earlier replans.');
    expect(costlierStatus([{ rings: square, cost: 15 }, { rings: other, cost: 15 }], 0)).toBe('2 costlier areas to send (cost 15).');
    expect(costlierStatus([], 1)).toBe('No costlier area. 1 area made costlier by earlier replans.');
  });
});

describe('cost change faults', () => {
  it('go next to the costlier-area controls, naming the area', () => {
    const messages = problemToMessages(
      {
        status: 422,
        detail: 'invalid request',
        errors: [
          { pointer: '/cost_changes/0/cost', message: 'the cost must be a number in (0, 1000000], got 0' },
          { pointer: '/cost_changes/1/area', message: 'covers the goal' },
        ],
      },
      ROUTE_FIELDS,
    );
    expect(messages).toEqual([
      { field: 'cost', text: 'Costlier area 1: the cost must be a number in (0, 1000000], got 0' },
      { field: 'cost', text: 'Costlier area 2: covers the goal' },
    ]);
  });
});
