import { describe, expect, it } from 'vitest';
import { AIRCRAFT_DEFAULTS, aircraftFromRequest, aircraftMember } from '../src/aircraft-fields';
import { SURVEY_FIELDS, ruleFor } from '../src/problems';

describe('aircraft member', () => {
  it('sends nothing for a plain multirotor, so a survey is the request it was', () => {
    expect(aircraftMember(AIRCRAFT_DEFAULTS)).toEqual({ member: null });
    // Plane-only numbers are not sent for a multirotor; its cruise speed is.
    expect(aircraftMember({ ...AIRCRAFT_DEFAULTS, turnRadiusM: 30 })).toEqual({ member: null });
    expect(aircraftMember({ ...AIRCRAFT_DEFAULTS, cruiseSpeedMS: 8 })).toEqual({ member: { type: 'multirotor', cruise_speed_m_s: 8 } });
  });

  it('sends a plane with the numbers given, and reads it back', () => {
    const v = { type: 'fixed_wing' as const, turnRadiusM: 35, climbAngleDeg: 8, cruiseSpeedMS: NaN, leadInM: 50 };
    const m = aircraftMember(v);
    expect(m).toEqual({ member: { type: 'fixed_wing', turn_radius_m: 35, max_climb_angle_deg: 8, lead_in_m: 50 } });
    expect(aircraftFromRequest({ aircraft: (m as { member: Record<string, unknown> }).member })).toEqual(v);
    expect(aircraftFromRequest({})).toEqual(AIRCRAFT_DEFAULTS);
  });

  it('refuses values out of the API ranges, naming the control', () => {
    const vtol = { ...AIRCRAFT_DEFAULTS, type: 'vtol' as const };
    expect(aircraftMember({ ...vtol, turnRadiusM: 2 })).toMatchObject({ control: 'aircraft-turn-radius' });
    expect(aircraftMember({ ...vtol, climbAngleDeg: 0 })).toMatchObject({ control: 'aircraft-climb-angle' });
    expect(aircraftMember({ ...vtol, cruiseSpeedMS: 60 })).toMatchObject({ control: 'aircraft-cruise-speed' });
    expect(aircraftMember({ ...vtol, leadInM: -1 })).toMatchObject({ control: 'aircraft-lead-in' });
  });
});

describe('aircraft faults from the server', () => {
  it('land on the aircraft fieldset, on the control at fault', () => {
    expect(ruleFor('/aircraft/turn_radius_m', SURVEY_FIELDS)).toMatchObject({ field: 'aircraft', control: 'aircraft-turn-radius' });
    expect(ruleFor('/aircraft/max_climb_angle_deg', SURVEY_FIELDS)).toMatchObject({ field: 'aircraft', control: 'aircraft-climb-angle' });
    expect(ruleFor('/aircraft/type', SURVEY_FIELDS)).toMatchObject({ field: 'aircraft', control: 'aircraft-type' });
  });
});
