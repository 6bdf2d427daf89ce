import { describe, expect, it } from 'vitest';
import {
  buildSurveyRequest,
  cameraSummary,
  describeExtra,
  formFromRequest,
  nextUavId,
  uavColour,
  UAV_COLOURS,
  type CustomCamera,
  type SurveyFormValues,
} from '../src/survey-form';

const square: [number, number][][] = [[[5, 52], [5.006, 52], [5.006, 52.004], [5, 52.004], [5, 52]]];
const p4: CustomCamera = { sensor_width_mm: 13.2, sensor_height_mm: 8.8, focal_length_mm: 8.8, image_width_px: 5472, image_height_px: 3648, orientation: 'landscape' };

function values(over: Partial<SurveyFormValues> = {}): SurveyFormValues {
  return {
    name: '  field 7 ',
    roi: square,
    noFlyZones: [],
    demId: null,
    allowPartialDem: false,
    camera: 'dji_phantom4_pro',
    customCamera: p4,
    heightMode: 'altitude',
    altitudeM: 60,
    gsdCmPx: 1.5,
    frontOverlapPct: 80,
    sideOverlapPct: 70,
    sliceAngle: 'auto',
    speedMS: 10,
    altitudeFrame: 'relative',
    assignment: 'balanced',
    uavs: [],
    extra: {},
    ...over,
  };
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

  it('refuses to send without an ROI, with a bad slice angle, or AMSL without a DEM', () => {
    const { body, errors } = buildSurveyRequest(values({ roi: null, sliceAngle: 'north', altitudeFrame: 'amsl' }));
    expect(body).toBeNull();
    expect(errors.map((e) => e.field)).toEqual(['roi', 'altitude-frame', 'slice-angle']);
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
      altitude_frame: 'terrain',
      assignment: 'competition',
      uavs: [{ id: 'a', start: [5, 52], speed_m_s: 6, max_flight_time_s: 900 }, { id: 'b', start: [5.006, 52] }],
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
      altitudeFrame: 'terrain',
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
