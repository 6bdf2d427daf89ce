import { describe, expect, it } from 'vitest';
import type { Dem } from '../src/api';
import { describeDem, parseEpsg } from '../src/dem-panel';
import { idTail } from '../src/saved-panel';

const dem = (over: Partial<Dem>): Dem =>
  ({
    width: 283,
    height: 259,
    crs: { epsg: 26918, name: 'NAD83 / UTM zone 18N', geographic: false },
    resolution: [2, 2],
    resolution_m: [2, 2],
    min: 6.94,
    max: 22.06,
    ...over,
  }) as Dem;

describe('describeDem', () => {
  it('gives a projected DEM’s cells in metres', () => {
    expect(describeDem(dem({}), true)).toBe('283 × 259 cells of 2.00 m, NAD83 / UTM zone 18N; heights 6.9–22.1 m');
    expect(describeDem(dem({}), false)).toMatch(/\(placed approximately/);
  });

  it('gives a geographic DEM’s cells in metres on the ground and in arc seconds', () => {
    // SRTM at 3″ near 39.6° N: 71.6 m east–west, 92.5 m north–south (the API's resolution_m).
    const srtm = dem({ width: 1000, height: 1000, crs: { epsg: 4326, name: 'WGS 84', geographic: true }, resolution: [1 / 1200, 1 / 1200], resolution_m: [71.59, 92.52] });
    expect(describeDem(srtm, true)).toBe('1000 × 1000 cells of 71.6 × 92.5 m (3.00″), WGS 84; heights 6.9–22.1 m');
  });
});

describe('parseEpsg', () => {
  it('takes a code with or without EPSG:, nothing, or says it is not one', () => {
    expect(parseEpsg(' 32633 ')).toBe('EPSG:32633');
    expect(parseEpsg('epsg:4326')).toBe('EPSG:4326');
    expect(parseEpsg('')).toBeNull();
    expect(parseEpsg('UTM 33')).toBeUndefined();
    expect(parseEpsg('EPSG:12')).toBeUndefined();
  });
});

describe('idTail', () => {
  it('tells apart ids made in the same millisecond (UUIDv7: time first, random last)', () => {
    expect(idTail('01a206a1-4cc3-72f7-bfc8-dde4ed521906')).toBe('#521906');
    expect(idTail('01a206a1-4cc3-72f7-bfc8-aaaaaa000001')).not.toBe(idTail('01a206a1-4cc3-72f7-bfc8-dde4ed521906'));
  });
});
