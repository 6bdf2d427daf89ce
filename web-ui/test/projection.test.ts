import { describe, expect, it } from 'vitest';
import proj4 from 'proj4';
import type { Costmap, Dem } from '../src/api';
import { costmapExtent, costmapNeedsDem, placeCostmap, placeImage, proj4Definition } from '../src/projection';

const dem = {
  width: 283,
  height: 259,
  bounds: [321498, 4297500, 322064, 4298018],
  bounds_wgs84: [-77.05592, 38.8082, -77.04927, 38.81298],
  crs: { epsg: 26918, name: 'NAD83 / UTM zone 18N', geographic: false },
} as unknown as Dem;

describe('proj4Definition', () => {
  it('builds UTM definitions that place the DTM where GDAL does', () => {
    const def = proj4Definition(26918)!;
    const [lon, lat] = proj4(def, 'EPSG:4326', [321498, 4297500]);
    // The DTM's south-west corner (bounds_wgs84 is the envelope of the reprojected edges).
    expect(lon).toBeCloseTo(-77.0559, 3);
    expect(lat).toBeCloseTo(38.8082, 3);
    expect(proj4Definition(32733)).toContain('+south');
    expect(proj4Definition(2056)).toBeNull();
  });
});

describe('costmapExtent', () => {
  it('is the DEM grid at factor 1 and drops short edge blocks when resampled', () => {
    expect(costmapExtent(dem, 283, 259)).toEqual([321498, 4297500, 322064, 4298018]);
    // 4 m cells: 70 × 64 blocks of 2 × 2 from the top-left corner.
    expect(costmapExtent(dem, 70, 64, [2, 2])).toEqual([321498, 4298018 - 256, 321498 + 280, 4298018]);
  });
});

describe('placeCostmap', () => {
  const costmap = (over: Partial<Costmap>) => ({ dem_id: 'd', width: 141, height: 129, params: { resample_factor: [2, 2], resolution_m: [4, 4] }, ...over }) as Costmap;

  it('places the preview at the costmap’s own bounds, without its DEM', () => {
    // Bounds as the server reports them for 4 m cells on the 2 m DTM.
    const cm = costmap({ crs: dem.crs, bounds: [321498, 4297502, 322062, 4298018], bounds_wgs84: [-77.0559, 38.8082, -77.0493, 38.813] });
    expect(costmapNeedsDem(cm)).toBe(false);
    expect(placeCostmap(cm, null)).toEqual({ projection: 'EPSG:26918', extent: [321498, 4297502, 322062, 4298018], exact: true });
  });

  it('falls back to the WGS84 bounds for a CRS the page cannot define', () => {
    const cm = costmap({ crs: { epsg: 2056, name: 'CH1903+', geographic: false }, bounds: [2600000, 1200000, 2601000, 1201000], bounds_wgs84: [7.4, 46.9, 7.42, 46.91] });
    expect(placeCostmap(cm, null)).toEqual({ projection: 'EPSG:4326', extent: [7.4, 46.9, 7.42, 46.91], exact: false });
    expect(placeImage(null, [0, 0, 1, 1], [5, 52, 6, 53]).exact).toBe(false);
  });

  it('derives the extent from the DEM for costmaps of older servers (no bounds)', () => {
    const cm = costmap({ width: 141, height: 129 });
    expect(costmapNeedsDem(cm)).toBe(true);
    expect(placeCostmap(cm, null)).toBeNull();
    expect(placeCostmap(cm, dem)).toEqual({ projection: 'EPSG:26918', extent: [321498, 4298018 - 516, 321498 + 564, 4298018], exact: true });
  });
});
