import { describe, expect, it } from 'vitest';
import { COSTMAP_FIELDS, problemToMessages, ROUTE_FIELDS, ruleFor, statusMessage, SURVEY_FIELDS } from '../src/problems';

describe('ruleFor', () => {
  it('matches whole pointer segments, longest prefix first', () => {
    expect(ruleFor('/roi/coordinates/0', SURVEY_FIELDS)?.field).toBe('roi');
    expect(ruleFor('/camera_preset', SURVEY_FIELDS)?.field).toBe('camera');
    expect(ruleFor('/camera/focal_length_mm', SURVEY_FIELDS)?.field).toBe('camera');
    expect(ruleFor('/uavs/2/start', SURVEY_FIELDS)?.field).toBe('uavs');
    expect(ruleFor('/uavs/2/max_flight_time_s', SURVEY_FIELDS)?.field).toBe('battery');
    expect(ruleFor('/uavs/max_flight_time_s', SURVEY_FIELDS)?.field).toBe('uavs');
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

  it('shows clearance faults at the clearance field, in the page’s words', () => {
    expect(ruleFor('/nfz_clearance_m', SURVEY_FIELDS)?.field).toBe('nfz-clearance');
    const messages = problemToMessages(
      {
        status: 422,
        detail: 'x',
        errors: [
          { pointer: '/nfz_clearance_m', message: '150 is outside the allowed range [0, 100]' },
          {
            pointer: '/nfz_clearance_m',
            message: 'the no-fly zones and the 40 m kept from them (nfz_clearance_m) leave nothing of the region of interest to fly over: lower nfz_clearance_m',
          },
        ],
      },
      SURVEY_FIELDS,
    );
    expect(messages).toEqual([
      { field: 'nfz-clearance', text: 'Clearance from no-fly zones: 150 is outside the allowed range [0, 100]' },
      {
        field: 'nfz-clearance',
        text: 'Clearance from no-fly zones: the no-fly zones and the 40 m kept from them leave nothing of the region of interest to fly over: lower the clearance from no-fly zones',
      },
    ]);
  });

  it('sends a battery fault to the battery and unknown pointers to the form', () => {
    const messages = problemToMessages(
      { status: 422, detail: 'x', errors: [{ pointer: '/uavs/1/max_flight_time_s', message: 'too short' }, { pointer: '/weird', message: 'unknown field' }] },
      SURVEY_FIELDS,
    );
    expect(messages).toEqual([
      { field: 'battery', text: 'Battery: too short' },
      { field: 'form', text: 'Request: unknown field' },
    ]);
  });

  it('says which UAV, and the battery in plain words', () => {
    const messages = problemToMessages(
      {
        status: 422,
        detail: 'x',
        errors: [
          { pointer: '/uavs/2/start', message: 'is inside a no-fly zone' },
          { pointer: '/uavs/0/max_flight_time_s', message: 'UAV uav1 cannot fly cell 3 within its battery of 360 s: getting there and back alone takes 367 s; start it nearer or give it a longer max_flight_time_s' },
        ],
      },
      SURVEY_FIELDS,
    );
    expect(messages).toEqual([
      { field: 'uavs', text: 'UAV 3: is inside a no-fly zone' },
      { field: 'battery', text: 'Battery: UAV uav1 cannot fly one of the cells within its battery of 6 min: getting there and back alone takes 6 min 7 s; start it nearer or give it a longer battery time' },
    ]);
  });

  it('names the control at fault when a slot serves several', () => {
    expect(problemToMessages({ status: 422, detail: 'x', errors: [{ pointer: '/vehicle/max_slope_deg', message: 'must be in (0, 60] (got 75)' }] }, COSTMAP_FIELDS)).toEqual([
      { field: 'vehicle', text: 'Max slope: must be in (0, 60] (got 75)', control: 'max-slope' },
    ]);
    expect(problemToMessages({ status: 422, detail: 'x', errors: [{ pointer: '/vehicle/width_m', message: 'too wide' }] }, COSTMAP_FIELDS)).toEqual([
      { field: 'vehicle', text: 'Vehicle: too wide' },
    ]);
  });

  it('speaks the page’s words: percent for overlaps, labels for API member names', () => {
    const messages = (pointer: string, message: string, rules = SURVEY_FIELDS) => problemToMessages({ status: 422, detail: 'x', errors: [{ pointer, message }] }, rules)[0].text;
    expect(messages('/front_overlap', '0.99 is outside the allowed range [0, 0.95]')).toBe('Front overlap: 99 % is outside the allowed range 0–95 %');
    expect(messages('/side_overlap', '-0.1 is outside the allowed range [0, 0.95]')).toBe('Side overlap: -10 % is outside the allowed range 0–95 %');
    expect(messages('/dem_id', 'the DEM has gaps under the area; plan elsewhere or set allow_partial_dem: true')).toBe(
      'Terrain model: the DEM has gaps under the area; plan elsewhere or tick “Plan even where the DEM has gaps”',
    );
    expect(messages('/vehicle/max_step_m', 'max_step_m must be in (0, 5], got 50', COSTMAP_FIELDS)).toBe('Max step: must be in (0, 5], got 50');
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
