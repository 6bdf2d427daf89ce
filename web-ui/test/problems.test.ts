import { describe, expect, it } from 'vitest';
import { COSTMAP_FIELDS, problemToMessages, ROUTE_FIELDS, ruleFor, statusMessage, SURVEY_FIELDS } from '../src/problems';

describe('ruleFor', () => {
  it('matches whole pointer segments, longest prefix first', () => {
    expect(ruleFor('/roi/coordinates/0', SURVEY_FIELDS)?.field).toBe('roi');
    expect(ruleFor('/camera_preset', SURVEY_FIELDS)?.field).toBe('camera');
    expect(ruleFor('/camera/focal_length_mm', SURVEY_FIELDS)?.field).toBe('camera');
    expect(ruleFor('/uavs/2/start', SURVEY_FIELDS)?.field).toBe('uavs');
    expect(ruleFor('/options/resolution_m', COSTMAP_FIELDS)?.field).toBe('resolution');
    expect(ruleFor('/options/pca_radius_m', COSTMAP_FIELDS)?.field).toBe('vehicle');
    // "/roi_extra" is not under "/roi".
    expect(ruleFor('/roi_extra', SURVEY_FIELDS)).toBeUndefined();
  });
});

describe('problemToMessages', () => {
  it('puts a self-intersecting ROI in the area panel, in plain words', () => {
    const messages = problemToMessages(
      {
        status: 422,
        detail: '/roi/coordinates/0: exterior ring self-intersects at (-77.05275000, 38.81050000): edge 0 meets edge 2',
        errors: [{ pointer: '/roi/coordinates/0', message: 'exterior ring self-intersects at (-77.05275000, 38.81050000): edge 0 meets edge 2' }],
      },
      SURVEY_FIELDS,
    );
    expect(messages).toEqual([
      { field: 'roi', text: 'Survey area: the outline crosses itself near lon -77.05275, lat 38.81050. Redraw it so that its edges do not cross.' },
    ]);
  });

  it('maps route faults to the start, goal and position fields', () => {
    const messages = problemToMessages(
      {
        status: 422,
        detail: 'invalid',
        errors: [
          { pointer: '/start', message: 'the start (lon -77.05, lat 38.81) is on an obstacle (a step)' },
          { pointer: '/goal', message: 'outside the costmap' },
          { pointer: '/blocked/0', message: 'covers the goal' },
        ],
      },
      ROUTE_FIELDS,
    );
    expect(messages.map((m) => m.field)).toEqual(['start', 'goal', 'blocked']);
    expect(messages[0].text).toBe('Start: the start (lon -77.05, lat 38.81) is on an obstacle (a step)');
  });

  it('numbers UAVs from 1 and sends unknown pointers to the form', () => {
    const messages = problemToMessages(
      { status: 422, detail: 'x', errors: [{ pointer: '/uavs/1/max_flight_time_s', message: 'too short' }, { pointer: '/weird', message: 'unknown field' }] },
      SURVEY_FIELDS,
    );
    expect(messages).toEqual([
      { field: 'uavs', text: 'UAVs 2: too short' },
      { field: 'form', text: 'Request: unknown field' },
    ]);
  });

  it('keeps one copy of repeated messages', () => {
    const e = { pointer: '/roi', message: 'too large' };
    expect(problemToMessages({ status: 422, detail: '', errors: [e, e] }, SURVEY_FIELDS)).toHaveLength(1);
  });

  it('reads the pointer from detail when errors is missing', () => {
    expect(problemToMessages({ status: 422, detail: '/dem_id: not an uploaded DEM' }, SURVEY_FIELDS)).toEqual([
      { field: 'dem', text: 'Terrain model: not an uploaded DEM' },
    ]);
  });

  it('explains problems without field faults by status', () => {
    expect(problemToMessages({ status: 409, detail: 'the costmap is running (normals, 40 %)' }, COSTMAP_FIELDS)).toEqual([
      { field: 'form', text: 'Not ready yet: the costmap is running (normals, 40 %)' },
    ]);
    expect(statusMessage({ status: 0, detail: '' })).toMatch(/cannot be reached/);
  });
});
