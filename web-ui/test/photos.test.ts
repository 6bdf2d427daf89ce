import { describe, expect, it } from 'vitest';
import { cellOverlaps, footprints, lowOverlapCells, requestedOverlaps, shortfallText, uavPhotosUrl } from '../src/photos';
import type { Survey } from '../src/api';

/** A cells FeatureCollection as the service answers it, figures as properties. */
function cells(props: Record<string, unknown>[]): Pick<Survey, 'cells'> {
  return {
    cells: {
      type: 'FeatureCollection',
      features: props.map((p) => ({ geometry: { type: 'Polygon', coordinates: [] }, properties: p })),
    },
  };
}

describe('achieved overlap against the requested', () => {
  it('takes the request, with the planner defaults', () => {
    expect(requestedOverlaps({ front_overlap: 0.75, side_overlap: 0.6 })).toEqual({ front: 0.75, side: 0.6 });
    expect(requestedOverlaps(null)).toEqual({ front: 0.8, side: 0.7 });
    // A direct lane spacing asks for no side overlap.
    expect(requestedOverlaps({ line_spacing_m: 30 })).toEqual({ front: 0.8, side: null });
  });

  it('flags cells below it, not those at it give or take rounding', () => {
    const survey = cells([
      { id: 0, photos: 40, front_overlap_min: 0.8, side_overlap_min: 0.6981, gsd_cm_px_median: 2.1 },
      { id: 1, photos: 12, front_overlap_min: 0.7412, side_overlap_min: 0.71, gsd_cm_px_median: 2.0 },
      { id: 2, photos: 5, front_overlap_min: 0.81, side_overlap_min: 0.62, gsd_cm_px_median: 1.9 },
      { id: 3, photos: 1, front_overlap_min: null, side_overlap_min: null, gsd_cm_px_median: 2.2 },
      // A cell of an older survey: no figures.
      { id: 4, area_m2: 100 },
    ]);
    const requested = requestedOverlaps({});
    const o = cellOverlaps(survey, requested);
    expect(o.map((c) => c.id)).toEqual([0, 1, 2, 3]);
    expect([...lowOverlapCells(o)]).toEqual([1, 2]);
    expect(shortfallText(o[1], requested)).toBe('front 74 % < 80 %');
    expect(shortfallText(o[2], requested)).toBe('side 62 % < 70 %');
    // Without a requested side overlap only the front counts.
    const spaced = cellOverlaps(survey, { front: 0.8, side: null });
    expect([...lowOverlapCells(spaced)]).toEqual([1]);
  });
});

describe('photo footprints', () => {
  it('reads the rings of photos.geojson and skips what is not a footprint', () => {
    const ring = [[5, 52], [5.001, 52], [5.001, 52.001], [5, 52.001], [5, 52]];
    const doc = {
      type: 'FeatureCollection',
      features: [
        { type: 'Feature', geometry: { type: 'Polygon', coordinates: [ring] }, properties: { sortie: 2, cell: 7, time_s: 31.5 } },
        { type: 'Feature', geometry: { type: 'Point', coordinates: [5, 52] }, properties: {} },
        { type: 'Feature', geometry: { type: 'Polygon', coordinates: [[[5, 52], [5, 52.1]]] }, properties: {} },
      ],
    };
    const f = footprints(doc);
    expect(f).toHaveLength(1);
    expect(f[0]).toEqual({ ring, sortie: 2, cell: 7, timeS: 31.5 });
    expect(footprints({ detail: 'not found' })).toEqual([]);
    expect(footprints(null)).toEqual([]);
  });

  it("finds a UAV's photos file from a sortie's link", () => {
    const files = (photos?: string) => ({ waypoints: '', plan: '', route: '', fence: '', kml: '', photos });
    const survey = {
      uavs: [
        { id: 'a', sorties: [{ files: files('/api/v1/surveys/s/uavs/a/photos.geojson?sortie=1') }] },
        { id: 'b', sorties: [{ files: files() }] },
      ],
    } as unknown as Pick<Survey, 'uavs'>;
    expect(uavPhotosUrl(survey, 'a')).toBe('/api/v1/surveys/s/uavs/a/photos.geojson');
    expect(uavPhotosUrl(survey, 'b')).toBeNull();
    expect(uavPhotosUrl(survey, 'zz')).toBeNull();
  });
});
