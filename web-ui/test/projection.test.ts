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

describe('placeImage with the server’s PROJ definition', () => {
  // What the server gives for British National Grid (bound to WGS84: the Helmert shift from OSGB36).
  const bng = '+proj=tmerc +lat_0=49 +lon_0=-2 +k=0.9996012717 +x_0=400000 +y_0=-100000 +ellps=airy +towgs84=446.448,-125.157,542.06,0.15,0.247,0.842,-20.489 +units=m +no_defs';

  it('places an image in any CRS the server defines, datum shift included', () => {
    const placed = placeImage({ epsg: 27700, proj4: bng }, [434000, 289000, 435000, 290000], [-1.51, 52.49, -1.49, 52.51]);
    expect(placed).toEqual({ projection: 'EPSG:27700', extent: [434000, 289000, 435000, 290000], exact: true });
    // PROJ (gdaltransform -s_srs EPSG:4326 -t_srs EPSG:27700) puts lon −1.5, lat 52.5 at 434039.457, 289239.281.
    const [x, y] = proj4('EPSG:4326', 'EPSG:27700', [-1.5, 52.5]);
    expect(Math.hypot(x - 434039.457, y - 289239.281)).toBeLessThan(2);
  });

  it('prefers the server’s definition to the page’s own, and falls back when it cannot be read', () => {
    expect(placeImage({ epsg: 2056, proj4: '+proj=somerc +lat_0=46.9524055555556 +lon_0=7.43958333333333 +k_0=1 +x_0=2600000 +y_0=1200000 +ellps=bessel +towgs84=674.374,15.056,405.346,0,0,0,0 +units=m +no_defs' }, [2600000, 1200000, 2601000, 1201000], [7.4, 46.9, 7.42, 46.91]).exact).toBe(true);
    expect(placeImage({ epsg: null, proj4: '+proj=nonsense +x=1' }, [0, 0, 1, 1], [5, 52, 6, 53])).toEqual({ projection: 'EPSG:4326', extent: [5, 52, 6, 53], exact: false });
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
    const cm = costmap({ crs: { epsg: 2065, name: 'S-JTSK (Ferro) / Krovak', geographic: false }, bounds: [2600000, 1200000, 2601000, 1201000], bounds_wgs84: [7.4, 46.9, 7.42, 46.91] });
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
