import { describe, expect, it } from 'vitest';
import { DEFAULT_BOX, niceStep, profileFromRoute, profileScale } from '../src/profile-chart';

describe('niceStep', () => {
  it('rounds to 1, 2 or 5 × 10^k', () => {
    expect(niceStep(100, 5)).toBe(20);
    expect(niceStep(70, 4)).toBe(20);
    expect(niceStep(1150, 4)).toBe(500);
    expect(niceStep(3, 4)).toBe(1);
    expect(niceStep(0)).toBe(1);
  });
});

describe('profileScale', () => {
  const points = [
    { distance_m: 0, altitude_m: 78.2, terrain_m: 12.4 },
    { distance_m: 500, altitude_m: 81, terrain_m: 20.1 },
    { distance_m: 1151.5, altitude_m: 78.2, terrain_m: null },
  ];
  const s = profileScale(points);

  it('spans both flown altitude and terrain, padded to whole ticks', () => {
    expect(s.yMin).toBe(0);
    expect(s.yMax).toBe(100);
    expect(s.yTicks).toEqual([0, 20, 40, 60, 80, 100]);
    expect(s.xMax).toBe(1151.5);
    expect(s.xTicks).toEqual([0, 500, 1000]);
  });

  it('maps the domain onto the plot area (y grows downwards)', () => {
    const b = DEFAULT_BOX;
    expect(s.x(0)).toBe(b.left);
    expect(s.x(1151.5)).toBeCloseTo(b.width - b.right);
    expect(s.y(100)).toBeCloseTo(b.top);
    expect(s.y(0)).toBeCloseTo(b.height - b.bottom);
    expect(s.y(78.2)).toBeLessThan(s.y(12.4));
  });

  it('survives a flat profile and an empty one', () => {
    const flat = profileScale([{ distance_m: 0, altitude_m: 60 }, { distance_m: 10, altitude_m: 60 }]);
    expect(flat.yMax).toBeGreaterThan(flat.yMin);
    expect(Number.isFinite(flat.y(60))).toBe(true);
    const empty = profileScale([]);
    expect(Number.isFinite(empty.x(0))).toBe(true);
  });
});

describe('profileFromRoute', () => {
  it('measures distance along [lon, lat, alt] coordinates', () => {
    // 0.001° of latitude ≈ 111.2 m.
    const p = profileFromRoute([[5, 52, 0], [5, 52.001, 60], [5, 52.002, 60]]);
    expect(p.map((x) => x.altitude_m)).toEqual([0, 60, 60]);
    expect(p[1].distance_m).toBeCloseTo(111.2, 0);
    expect(p[2].distance_m).toBeCloseTo(222.4, 0);
    expect(p[0].terrain_m).toBeNull();
  });
});
