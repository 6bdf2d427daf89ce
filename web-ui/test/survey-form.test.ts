import { describe, expect, it } from 'vitest';
import { buildSurveyRequest, nextUavId, uavColour, UAV_COLOURS, type SurveyFormValues } from '../src/survey-form';

const square: [number, number][][] = [[[5, 52], [5.006, 52], [5.006, 52.004], [5, 52.004], [5, 52]]];

function values(over: Partial<SurveyFormValues> = {}): SurveyFormValues {
  return {
    name: '  field 7 ',
    roi: square,
    noFlyZones: [],
    demId: null,
    allowPartialDem: false,
    camera: 'dji_phantom4_pro',
    customCamera: { sensor_width_mm: 13.2, sensor_height_mm: 8.8, focal_length_mm: 8.8, image_width_px: 5472, image_height_px: 3648, orientation: 'landscape' },
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
