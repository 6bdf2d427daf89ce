// The DJI downloads of a sortie: its WPML mission (.kmz) for DJI Pilot 2 or
// FlightHub 2, and its Litchi mission, in numbered parts past 99 waypoints.
import type { UavFiles } from './api';

/** One download link: where it points, its text and its accessible label. */
export interface DjiLink {
  href: string;
  text: string;
  label: string;
}

/** The DJI links of a sortie's files (none for a plane's, or a sortie DJI cannot fly). */
export function djiLinks(files: UavFiles, uav: string, tag: string): DjiLink[] {
  const out: DjiLink[] = [];
  if (files.dji_kmz) {
    out.push({ href: files.dji_kmz, text: 'DJI .kmz', label: `${uav} DJI WPML mission${tag}` });
  }
  const litchi = files.litchi ?? [];
  litchi.forEach((href, k) => {
    const part = litchi.length > 1 ? ` ${k + 1}/${litchi.length}` : '';
    out.push({ href, text: `Litchi${part}`, label: `${uav} Litchi mission${part ? ` part${part}` : ''}${tag}` });
  });
  return out;
}
