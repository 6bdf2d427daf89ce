// Placing raster images (DEM hillshades, costmap previews) on the map. They
// are drawn in the raster's own CRS, so OpenLayers needs that projection:
// the server gives its PROJ definition (`crs.proj4`, bound to WGS84 so the
// datum shift is in it); for servers that did not, definitions are built
// here for the common projected families (UTM on WGS84, NAD83, ETRS89), and
// any other CRS falls back to the WGS84 bounds, which is only approximate.

import proj4 from 'proj4';
import { register } from 'ol/proj/proj4';
import { get as getProjection } from 'ol/proj';
import type { Costmap, Dem } from './api';

/** A proj4 definition for an EPSG code, or null when we cannot build one. */
export function proj4Definition(epsg: number): string | null {
  if (epsg === 4326) return '+proj=longlat +datum=WGS84 +no_defs';
  if (epsg >= 32601 && epsg <= 32660) return `+proj=utm +zone=${epsg - 32600} +datum=WGS84 +units=m +no_defs`;
  if (epsg >= 32701 && epsg <= 32760) return `+proj=utm +zone=${epsg - 32700} +south +datum=WGS84 +units=m +no_defs`;
  if (epsg >= 26901 && epsg <= 26923) return `+proj=utm +zone=${epsg - 26900} +datum=NAD83 +units=m +no_defs`;
  if (epsg >= 25828 && epsg <= 25838) return `+proj=utm +zone=${epsg - 25800} +ellps=GRS80 +towgs84=0,0,0,0,0,0,0 +units=m +no_defs`;
  if (epsg === 3857) return '+proj=merc +a=6378137 +b=6378137 +lat_ts=0 +lon_0=0 +x_0=0 +y_0=0 +k=1 +units=m +nadgrids=@null +no_defs';
  return null;
}

export interface ImagePlacement {
  /** An OpenLayers projection code the image is drawn in. */
  projection: string;
  extent: [number, number, number, number];
  /** False when the placement is the approximate WGS84 fallback. */
  exact: boolean;
}

type Extent = [number, number, number, number];

/**
 * Where an image goes, given its extent in its CRS and its WGS84 envelope
 * (the approximate fallback when the CRS is not one we can define).
 */
export function placeImage(
  crs: { epsg: number | null; proj4?: string | null } | null | undefined,
  extent: Extent,
  wgs84: Extent,
): ImagePlacement {
  const epsg = crs?.epsg;
  const def = crs?.proj4?.trim() || (epsg != null ? proj4Definition(epsg) : null);
  const code = epsg != null ? `EPSG:${epsg}` : def ? `TERRAPLAN:${def}` : null;
  if (code && getProjection(code)) return { projection: code, extent, exact: true };
  if (code && def) {
    try {
      proj4.defs(code, def);
      register(proj4);
      return { projection: code, extent, exact: true };
    } catch {
      // A definition proj4js cannot read: forgotten (so later registrations work), and the image placed approximately.
      delete (proj4.defs as unknown as Record<string, unknown>)[code];
    }
  }
  return { projection: 'EPSG:4326', extent: wgs84, exact: false };
}

/** Where a raster lying on the DEM's grid goes, given its extent in the DEM's CRS. */
export function placeRaster(dem: Dem, nativeExtent: Extent = dem.bounds): ImagePlacement {
  return placeImage(dem.crs, nativeExtent, dem.bounds_wgs84);
}

/**
 * Where a costmap's `preview.png` goes: its own `bounds` (exact), or for
 * costmaps of older servers, which do not report them, derived from its
 * DEM (`dem` is needed only then; null when it is missing).
 */
export function placeCostmap(cm: Costmap, dem: Dem | null): ImagePlacement | null {
  if (cm.bounds && cm.bounds_wgs84) return placeImage(cm.crs ?? dem?.crs, cm.bounds, cm.bounds_wgs84);
  if (!dem) return null;
  return placeRaster(dem, costmapExtent(dem, cm.width ?? dem.width, cm.height ?? dem.height, cm.params?.resample_factor));
}

/** Whether placing this costmap needs its DEM (older servers did not report costmap bounds). */
export function costmapNeedsDem(cm: Costmap): boolean {
  return !cm.bounds || !cm.bounds_wgs84;
}

/**
 * The native extent of a costmap on a DEM, for costmaps without `bounds`
 * (built by older servers): the DEM's grid, or blocks of `factor` cells from
 * its top-left corner (short edge blocks are dropped).
 */
export function costmapExtent(
  dem: Dem,
  width: number,
  height: number,
  factor: [number, number] = [1, 1],
): Extent {
  const [minX, , , maxY] = dem.bounds;
  const cellX = (dem.bounds[2] - dem.bounds[0]) / dem.width;
  const cellY = (dem.bounds[3] - dem.bounds[1]) / dem.height;
  return [minX, maxY - height * factor[1] * cellY, minX + width * factor[0] * cellX, maxY];
}
