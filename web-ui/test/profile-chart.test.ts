import { describe, expect, it } from 'vitest';
import type { Uav } from '../src/api';
import { DEFAULT_BOX, niceStep, profileFromRoute, profileScale, sortieProfile, terrainArea } from '../src/profile-chart';

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
  it('measures distance along the coordinates, with the mission altitudes', () => {
    // 0.001° of latitude ≈ 111.2 m; 2D positions, as a survey without a DEM has.
    const p = profileFromRoute([[5, 52], [5, 52.001], [5, 52.002]], [0, 60, 60]);
    expect(p.map((x) => x.altitude_m)).toEqual([0, 60, 60]);
    expect(p[1].distance_m).toBeCloseTo(111.2, 0);
    expect(p[2].distance_m).toBeCloseTo(222.4, 0);
    expect(p[0].terrain_m).toBeNull();
  });
});

describe('sortieProfile', () => {
  const stats = { length_m: 0, length_3d_m: 0, turns: 0, flight_time_s: 0, photos: 0, cells: 0 };
  const files = { waypoints: '', plan: '', route: '', fence: '', kml: '' };
  const terrain = (alt: number) => ({
    home_amsl_m: 10,
    profile: [
      { distance_m: 0, altitude_m: alt, terrain_m: 10 },
      { distance_m: 100, altitude_m: alt + 1, terrain_m: 12 },
    ],
  });
  const uav: Uav = {
    id: 'uav1',
    start: [0, 0],
    speed_m_s: 10,
    stats,
    sorties: [
      { number: 1, stats, files, route: { type: 'LineString', coordinates: [] }, mission_altitudes_m: [], terrain: terrain(70) },
      { number: 2, stats, files, route: { type: 'LineString', coordinates: [] }, mission_altitudes_m: [], terrain: terrain(90) },
      // Without a DEM: 2D positions and the mission's altitudes, no terrain.
      { number: 3, stats, files, route: { type: 'LineString', coordinates: [[0, 0], [0, 0.001]] }, mission_altitudes_m: [60, 60], terrain: null },
    ],
  };

  it('charts the chosen sortie only', () => {
    expect(sortieProfile(uav, 0)).toEqual({ index: 0, count: 3, points: terrain(70).profile, overTerrain: true });
    const second = sortieProfile(uav, 1);
    expect(second.index).toBe(1);
    expect(second.points.map((p) => p.altitude_m)).toEqual([90, 91]);
  });

  it('falls back to the route altitudes without a terrain profile', () => {
    const third = sortieProfile(uav, 2);
    expect(third.overTerrain).toBe(false);
    expect(third.points.map((p) => p.altitude_m)).toEqual([60, 60]);
    expect(third.points[1].distance_m).toBeCloseTo(111.2, 0);
    expect(third.points[1].terrain_m).toBeNull();
  });

  it('clamps an out-of-range or missing choice to a sortie the UAV has', () => {
    expect(sortieProfile(uav, 7).index).toBe(2);
    expect(sortieProfile(uav, -1).index).toBe(0);
    expect(sortieProfile(uav, NaN).index).toBe(0);
    const single = sortieProfile({ ...uav, sorties: [uav.sorties[1]] }, 1);
    expect(single).toMatchObject({ index: 0, count: 1 });
    expect(single.points[0].altitude_m).toBe(90);
    expect(sortieProfile({ ...uav, sorties: [] }, 0)).toEqual({ index: 0, count: 0, points: [], overTerrain: false });
  });
});

describe('terrainArea', () => {
  const identity = { x: (d: number) => d, y: (h: number) => h };
  const pt = (distance_m: number, terrain_m: number | null) => ({ distance_m, altitude_m: 80, terrain_m });

  it('closes each run between DEM gaps down to the axis on its own', () => {
    const path = terrainArea([pt(0, 10), pt(10, 12), pt(20, null), pt(30, 11), pt(40, 13), pt(50, 14)], identity, 0);
    expect(path).toBe('M0.0,10.0L10.0,12.0L10.0,0L0.0,0Z' + 'M30.0,11.0L40.0,13.0L50.0,14.0L50.0,0L30.0,0Z');
  });

  it('draws nothing for lone points or no terrain', () => {
    expect(terrainArea([pt(0, 10), pt(10, null), pt(20, 12)], identity, 0)).toBe('');
    expect(terrainArea([pt(0, null), pt(10, null)], identity, 0)).toBe('');
  });
});
