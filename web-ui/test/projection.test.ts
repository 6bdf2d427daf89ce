import { describe, expect, it } from 'vitest';
import proj4 from 'proj4';
import type { Dem } from '../src/api';
import { costmapExtent, proj4Definition } from '../src/projection';

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
