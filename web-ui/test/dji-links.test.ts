import { describe, expect, it } from 'vitest';
import { djiLinks } from '../src/dji-links';
import type { UavFiles } from '../src/api';

const base: UavFiles = { waypoints: 'w', plan: 'p', route: 'r', fence: 'f', kml: 'k' };

describe('DJI download links', () => {
  it('gives the KMZ and a single Litchi file', () => {
    const links = djiLinks({ ...base, dji_kmz: '/a/mission.kmz', litchi: ['/a/mission.litchi.csv'] }, 'a', '');
    expect(links).toEqual([
      { href: '/a/mission.kmz', text: 'DJI .kmz', label: 'a DJI WPML mission' },
      { href: '/a/mission.litchi.csv', text: 'Litchi', label: 'a Litchi mission' },
    ]);
  });

  it('numbers the parts of a long Litchi mission', () => {
    const litchi = ['/a/mission.part1.litchi.csv?sortie=2', '/a/mission.part2.litchi.csv?sortie=2'];
    const links = djiLinks({ ...base, litchi }, 'a', ' (sortie 2)');
    expect(links.map((l) => l.text)).toEqual(['Litchi 1/2', 'Litchi 2/2']);
    expect(links[1].label).toBe('a Litchi mission part 2/2 (sortie 2)');
  });

  it('gives none for a plane or a survey stored before DJI files', () => {
    expect(djiLinks(base, 'a', '')).toEqual([]);
  });
});
