import { describe, expect, it } from 'vitest';
import {
  buildSurveyRequest,
  cameraSummary,
  defaultStart,
  describeExtra,
  describeFlightGeometry,
  flightGeometry,
  formFromRequest,
  nextUavId,
  uavColour,
  UAV_COLOURS,
  type SurveyFormValues,
} from '../src/survey-form';
import { formValues, P4 as p4 } from './form-values';

const square: [number, number][][] = [[[5, 52], [5.006, 52], [5.006, 52.004], [5, 52.004], [5, 52]]];

function values(over: Partial<SurveyFormValues> = {}): SurveyFormValues {
  return formValues({ name: '  field 7 ', roi: square, ...over });
}

describe('buildSurveyRequest', () => {
  it('builds the API body from the form (percentages as fractions)', () => {
    const { body, errors } = buildSurveyRequest(values());
    expect(errors).toEqual([]);
    expect(body).toEqual({
      name: 'field 7',
      roi: { type: 'Polygon', coordinates: square },
      no_fly_zones: [],
      front_overlap: 0.8,
      side_overlap: 0.7,
      slice_angle_deg: 'auto',
      speed_m_s: 10,
      nfz_clearance_m: 5,
      altitude_frame: 'relative',
      assignment: 'balanced',
      altitude_m: 60,
      camera_preset: 'dji_phantom4_pro',
    });
  });

  it('sends GSD instead of altitude, a custom camera, a numeric slice angle, the DEM and UAVs', () => {
    const { body } = buildSurveyRequest(
      values({
        heightMode: 'gsd',
        camera: 'custom',
        sliceAngle: '45',
        demId: 'dem-1',
        allowPartialDem: true,
        altitudeFrame: 'amsl',
        uavs: [{ id: 'uav1', start: [5, 52] }, { id: 'uav2', start: [5.006, 52] }],
        noFlyZones: [square],
      }),
    );
    expect(body).toMatchObject({
      gsd_cm_px: 1.5,
      camera: { focal_length_mm: 8.8, orientation: 'landscape' },
      slice_angle_deg: 45,
      dem_id: 'dem-1',
      allow_partial_dem: true,
      altitude_frame: 'amsl',
      uavs: [{ id: 'uav1', start: [5, 52] }, { id: 'uav2', start: [5.006, 52] }],
      no_fly_zones: [{ type: 'Polygon', coordinates: square }],
    });
    expect(body).not.toHaveProperty('altitude_m');
    expect(body).not.toHaveProperty('camera_preset');
  });

  it('sends the clearance from no-fly zones as typed, the default 5 m like the other defaulted settings', () => {
    expect(buildSurveyRequest(values({ nfzClearanceM: 12.5 })).body).toMatchObject({ nfz_clearance_m: 12.5 });
    expect(buildSurveyRequest(values({ nfzClearanceM: 0 })).body).toMatchObject({ nfz_clearance_m: 0 });
    expect(buildSurveyRequest(values()).body).toMatchObject({ nfz_clearance_m: 5 });
  });

  it('sends rally points as [lon, lat] pairs, and none when there are none', () => {
    const { body, errors } = buildSurveyRequest(values({ rallyPoints: [[5.0101, 52.0005], [4.999, 52.004]] }));
    expect(errors).toEqual([]);
    expect(body).toMatchObject({ rally_points: [[5.0101, 52.0005], [4.999, 52.004]] });
    expect(buildSurveyRequest(values()).body).not.toHaveProperty('rally_points');
  });

  it('refuses empty number fields instead of sending 0', () => {
    const { body, errors } = buildSurveyRequest(values({ frontOverlapPct: NaN, speedMS: NaN, altitudeM: NaN, nfzClearanceM: NaN }));
    expect(body).toBeNull();
    expect(errors).toEqual([
      { field: 'altitude', text: 'Altitude (m): give a number.', control: 'altitude' },
      { field: 'front-overlap', text: 'Front overlap (%): give a number.', control: 'front-overlap' },
      { field: 'speed', text: 'Speed (m/s): give a number.', control: 'speed' },
      { field: 'nfz-clearance', text: 'Clearance from no-fly zones (m): give a number.', control: 'nfz-clearance' },
    ]);
    // The altitude is not needed when the GSD sets the height; the custom camera's numbers are when it is used.
    expect(buildSurveyRequest(values({ heightMode: 'gsd', altitudeM: NaN })).errors).toEqual([]);
    expect(buildSurveyRequest(values({ heightMode: 'gsd', gsdCmPx: NaN })).errors).toEqual([
      { field: 'altitude', text: 'Ground sample distance (cm/px): give a number.', control: 'gsd' },
    ]);
    expect(buildSurveyRequest(values({ camera: 'custom', customCamera: { ...p4, focal_length_mm: NaN } })).errors).toEqual([
      { field: 'camera', text: 'Focal length (mm): give a number.', control: 'cam-f' },
    ]);
  });

  it('refuses to send without an ROI, with a bad slice angle, or AMSL without a DEM', () => {
    const { body, errors } = buildSurveyRequest(values({ roi: null, sliceAngle: 'north', altitudeFrame: 'amsl' }));
    expect(body).toBeNull();
    expect(errors.map((e) => e.field)).toEqual(['roi', 'altitude-frame', 'slice-angle']);
  });
});

describe('battery', () => {
  it('gives every UAV the battery, over any it kept from a reopened survey', () => {
    const { body, errors } = buildSurveyRequest(
      values({ batteryMin: 12.5, uavs: [{ id: 'a', start: [5, 52], max_flight_time_s: 900, speed_m_s: 6 }, { id: 'b', start: [5.006, 52] }] }),
    );
    expect(errors).toEqual([]);
    expect(body!.uavs).toEqual([
      { id: 'a', start: [5, 52], speed_m_s: 6, max_flight_time_s: 750 },
      { id: 'b', start: [5.006, 52], max_flight_time_s: 750 },
    ]);
  });

  it('spells out the default UAV (at the area’s first corner) to carry a battery', () => {
    expect(buildSurveyRequest(values({ batteryMin: 1 })).body!.uavs).toEqual([{ id: 'uav1', start: [5, 52], max_flight_time_s: 60 }]);
    expect(buildSurveyRequest(values()).body).not.toHaveProperty('uavs');
  });

  it('gives that UAV the corner the server would take off from when the first one is in or near a no-fly zone', () => {
    const overCorner: [number, number][][] = [[[4.999, 51.999], [5.001, 51.999], [5.001, 52.001], [4.999, 52.001], [4.999, 51.999]]];
    const { body, errors } = buildSurveyRequest(values({ batteryMin: 1, noFlyZones: [overCorner] }));
    expect(errors).toEqual([]);
    expect(body!.uavs).toEqual([{ id: 'uav1', start: [5.006, 52], max_flight_time_s: 60 }]);
  });

  it('keeps each UAV’s own battery when the field is empty', () => {
    const { body } = buildSurveyRequest(values({ uavs: [{ id: 'a', start: [5, 52], max_flight_time_s: 900 }, { id: 'b', start: [5.006, 52] }] }));
    expect(body!.uavs).toEqual([{ id: 'a', start: [5, 52], max_flight_time_s: 900 }, { id: 'b', start: [5.006, 52] }]);
  });

  it('refuses a battery outside 30 s … 24 h, naming the field', () => {
    for (const batteryMin of [0.4, 1441, -3]) {
      const { body, errors } = buildSurveyRequest(values({ batteryMin }));
      expect(body).toBeNull();
      expect(errors).toEqual([{ field: 'battery', text: expect.stringMatching(/^Battery: .*0\.5 to 1440 minutes/) }]);
    }
  });

  it('puts a battery shared by every UAV of a reopened survey back in the field', () => {
    const request = { roi: { type: 'Polygon', coordinates: square }, uavs: [{ id: 'a', start: [5, 52], max_flight_time_s: 600 }, { id: 'b', start: [5.006, 52], max_flight_time_s: 600 }] };
    const { values: v, notes } = formFromRequest(request, null, { camera: 'x', customCamera: p4 });
    expect(notes).toEqual([]);
    expect(v.batteryMin).toBe(10);
    expect(v.uavs).toEqual([{ id: 'a', start: [5, 52] }, { id: 'b', start: [5.006, 52] }]);
    expect(buildSurveyRequest(v).body!.uavs).toEqual(request.uavs);
  });

  it('leaves different batteries with their UAVs, and says so', () => {
    const uavs = [{ id: 'a', start: [5, 52], max_flight_time_s: 600 }, { id: 'b', start: [5.006, 52] }];
    const { values: v, notes } = formFromRequest({ roi: { type: 'Polygon', coordinates: square }, uavs }, null, { camera: 'x', customCamera: p4 });
    expect(Number.isNaN(v.batteryMin)).toBe(true);
    expect(notes).toEqual([expect.stringMatching(/different batteries/)]);
    expect(buildSurveyRequest(v).body!.uavs).toEqual(uavs);
  });
});

describe('defaultStart', () => {
  // At lat 52°, 1 m east is 1 / (6371008.8 × π/180 × cos 52°) = 1.4607e-5° of longitude.
  const degPerMEast = 1 / ((Math.PI / 180) * 6_371_008.8 * Math.cos((52 * Math.PI) / 180));
  const box = (w: number, s: number, e: number, n: number): [number, number][][] => [[[w, s], [e, s], [e, n], [w, n], [w, s]]];

  it('takes the first corner when no zone is within the clearance', () => {
    expect(defaultStart(square, [], 5)).toEqual([5, 52]);
    expect(defaultStart(square, [box(5.002, 52.001, 5.003, 52.002)], 5)).toEqual([5, 52]);
  });

  it('skips a corner closer than the clearance, and only then', () => {
    // A zone 3 m west of the first corner (its east edge at lon 5 − 3 m).
    const near = box(4.999, 51.9995, 5 - 3 * degPerMEast, 52.0005);
    expect(defaultStart(square, [near], 5)).toEqual([5.006, 52]);
    expect(defaultStart(square, [near], 2.9)).toEqual([5, 52]);
    // A point in a zone's hole is outside the zone.
    const holed = [box(4.99, 51.99, 5.01, 52.01)[0], box(4.999, 51.999, 5.001, 52.001)[0]];
    expect(defaultStart(square, [holed], 5)).toEqual([5, 52]);
  });

  it('falls back to the nearest clear point of the outline, else the first corner', () => {
    // One zone over the whole area but for a hole reaching over the south edge from lon 5.002 to 5.004.
    const zone = [box(4.99, 51.99, 5.01, 52.01)[0], box(5.002, 51.999, 5.004, 52.001)[0]];
    const [lon, lat] = defaultStart(square, [zone], 5);
    expect(lat).toBeCloseTo(52, 9);
    // 5 m inside the hole's west edge, within the 1-m sampling.
    const east = (lon - 5.002) / degPerMEast;
    expect(east).toBeGreaterThanOrEqual(5);
    expect(east).toBeLessThan(6);
    expect(defaultStart(square, [box(4.99, 51.99, 5.01, 52.01)], 5)).toEqual([5, 52]);
  });
});

describe('flightGeometry', () => {
  // The Phantom 4 Pro at 60 m: 13.2 mm × 60 m / 8.8 mm = 90 m across, 60 m along; 90 m / 5472 px = 1.645 cm/px.
  it('gives the server’s GSD, footprint, line spacing and trigger distance', () => {
    const g = flightGeometry(p4, { mode: 'altitude', altitudeM: 60 }, 70, 80, 10)!;
    expect(g.footprintSideM).toBeCloseTo(90, 9);
    expect(g.footprintFrontM).toBeCloseTo(60, 9);
    expect(g.gsdCmPx).toBeCloseTo(90 * 100 / 5472, 9);
    expect(g.lineSpacingM).toBeCloseTo(27, 9);
    expect(g.triggerDistanceM).toBeCloseTo(12, 9);
    expect(g.triggerIntervalS).toBeCloseTo(1.2, 9);
    expect(describeFlightGeometry(g, 'altitude')).toBe('GSD 1.64 cm/px; each photo covers 90.0 × 60.0 m; lanes 27.0 m apart; a photo every 12.0 m (1.2 s).');
  });

  it('finds the altitude for a GSD, and swaps the sides in portrait', () => {
    const g = flightGeometry(p4, { mode: 'gsd', gsdCmPx: 90 * 100 / 5472 }, 70, 80, 10)!;
    expect(g.altitudeM).toBeCloseTo(60, 9);
    expect(describeFlightGeometry(g, 'gsd')).toMatch(/^altitude 60\.0 m;/);
    const portrait = flightGeometry({ ...p4, orientation: 'portrait' }, { mode: 'altitude', altitudeM: 60 }, 70, 80, 10)!;
    expect(portrait.footprintSideM).toBeCloseTo(60, 9);
    expect(portrait.footprintFrontM).toBeCloseTo(90, 9);
    expect(portrait.gsdCmPx).toBeCloseTo(60 * 100 / 3648, 9);
  });

  it('gives nothing for empty or impossible numbers', () => {
    expect(flightGeometry({ ...p4, focal_length_mm: 0 }, { mode: 'altitude', altitudeM: 60 }, 70, 80, 10)).toBeNull();
    expect(flightGeometry(p4, { mode: 'altitude', altitudeM: NaN }, 70, 80, 10)).toBeNull();
    expect(flightGeometry(p4, { mode: 'gsd', gsdCmPx: -1 }, 70, 80, 10)).toBeNull();
  });
});

describe('UAV ids and colours', () => {
  it('takes the first free id', () => {
    expect(nextUavId([])).toBe('uav1');
    expect(nextUavId([{ id: 'uav1', start: [0, 0] }, { id: 'uav3', start: [0, 0] }])).toBe('uav2');
  });
  it('gives distinct colours to the first ten UAVs', () => {
    expect(new Set(UAV_COLOURS.map((_, i) => uavColour(i))).size).toBe(10);
    expect(uavColour(10)).toBe(uavColour(0));
  });
});

describe('camera presets', () => {
  it('spells out a camera’s numbers', () => {
    expect(cameraSummary({ ...p4, sensor_width_mm: 6.17, focal_length_mm: 3.6100000001 })).toBe(
      'Sensor 6.17 × 8.8 mm, focal length 3.61 mm, 5472 × 3648 px (20.0 MP), landscape.',
    );
  });
});

describe('formFromRequest', () => {
  const base = { camera: 'dji_phantom4_pro', customCamera: p4 };

  it('gives the API defaults for members left out, and the name', () => {
    const { values, notes } = formFromRequest({ roi: { type: 'Polygon', coordinates: square } }, 'field 7', base);
    expect(notes).toEqual([]);
    expect(values).toEqual(values_({ name: 'field 7', camera: 'dji_phantom4_pro', gsdCmPx: 1.5 }));
  });

  it('does not keep the saved survey’s project: a plan made again goes to the project chosen now', () => {
    const { values, notes } = formFromRequest({ roi: { type: 'Polygon', coordinates: square }, project_id: 'p-old' }, 'field 7', base);
    expect(notes).toEqual([]);
    expect(values.extra).toEqual({});
    expect(buildSurveyRequest(values).body).not.toHaveProperty('project_id');
  });

  it('round-trips what the form sends, and keeps members it has no control for', () => {
    const request = {
      roi: { type: 'Feature', properties: {}, geometry: { type: 'Polygon', coordinates: square } },
      no_fly_zones: [{ type: 'MultiPolygon', coordinates: [square, square] }],
      dem_id: 'dem-1',
      allow_partial_dem: true,
      camera: { ...p4, focal_length_mm: 12 },
      gsd_cm_px: 2,
      front_overlap: 0.75,
      side_overlap: 0.65,
      slice_angle_deg: 30,
      speed_m_s: 8,
      nfz_clearance_m: 12.5,
      altitude_frame: 'terrain',
      assignment: 'competition',
      uavs: [{ id: 'a', start: [5, 52], speed_m_s: 6, max_flight_time_s: 900 }, { id: 'b', start: [5.006, 52] }],
      rally_points: [[5.01, 52.001]],
      turn_penalty_s: 3,
      line_spacing_m: null,
    };
    const { values } = formFromRequest(request, null, base);
    expect(values).toMatchObject({
      name: '',
      roi: square,
      noFlyZones: [square, square],
      demId: 'dem-1',
      camera: 'custom',
      customCamera: { focal_length_mm: 12 },
      heightMode: 'gsd',
      frontOverlapPct: 75,
      sideOverlapPct: 65,
      sliceAngle: '30',
      nfzClearanceM: 12.5,
      altitudeFrame: 'terrain',
      rallyPoints: [[5.01, 52.001]],
      extra: { turn_penalty_s: 3 },
    });
    const { body } = buildSurveyRequest(values);
    expect(body).toEqual({
      ...request,
      roi: { type: 'Polygon', coordinates: square },
      no_fly_zones: [{ type: 'Polygon', coordinates: square }, { type: 'Polygon', coordinates: square }],
      line_spacing_m: undefined,
    });
    expect(body).not.toHaveProperty('line_spacing_m');
    expect(describeExtra(values.extra)).toBe('turn_penalty_s 3');
  });

  it('keeps the first part of a multi-part area and says so', () => {
    const { values, notes } = formFromRequest({ roi: { type: 'MultiPolygon', coordinates: [square, square] }, camera_preset: 'sony_rx1r2' }, null, base);
    expect(values.roi).toEqual(square);
    expect(values.camera).toBe('sony_rx1r2');
    expect(notes[0]).toMatch(/2 parts/);
  });
});

function values_(over: Partial<SurveyFormValues>): SurveyFormValues {
  return { ...values(over), name: over.name ?? '' };
}
