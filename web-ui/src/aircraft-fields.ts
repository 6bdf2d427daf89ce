// The aircraft on the page: multirotor, fixed wing or VTOL with its turn
// radius, climb angle, cruise speed and lead-in, sent as the request's
// `aircraft`. The member and its reading back are pure (unit-tested);
// readAircraftFields/showAircraftFields wire them to the form's controls.

import { byId, numberValue, setValue } from './dom';

export type AircraftType = 'multirotor' | 'fixed_wing' | 'vtol';

/** The aircraft controls' values; NaN = left empty (the type's default). */
export interface AircraftValues {
  type: AircraftType;
  turnRadiusM: number;
  climbAngleDeg: number;
  cruiseSpeedMS: number;
  leadInM: number;
}

export const AIRCRAFT_DEFAULTS: AircraftValues = { type: 'multirotor', turnRadiusM: NaN, climbAngleDeg: NaN, cruiseSpeedMS: NaN, leadInM: NaN };

/** The API's ranges (lower bound open for the angle and the speed). */
export const TURN_RADIUS_RANGE_M = [5, 1000] as const;
export const CLIMB_ANGLE_RANGE_DEG = [0, 45] as const;
export const CRUISE_SPEED_RANGE_M_S = [0, 50] as const;
export const LEAD_IN_RANGE_M = [0, 2000] as const;

const within = (x: number, [lo, hi]: readonly [number, number], open = false) => (open ? x > lo : x >= lo) && x <= hi;

/** The `aircraft` member of `v` (none for a plain multirotor), or the first fault in plain words. */
export function aircraftMember(v: AircraftValues): { member: Record<string, unknown> | null } | { error: string; control: string } {
  const plane = v.type !== 'multirotor';
  const member: Record<string, unknown> = { type: v.type };
  const checks: [number, string, readonly [number, number], boolean, string, string][] = [
    [v.turnRadiusM, 'turn_radius_m', TURN_RADIUS_RANGE_M, false, 'aircraft-turn-radius', 'Turn radius: give 5 to 1000 m, or leave it empty.'],
    [v.climbAngleDeg, 'max_climb_angle_deg', CLIMB_ANGLE_RANGE_DEG, true, 'aircraft-climb-angle', 'Climb angle: give more than 0 and at most 45 degrees, or leave it empty.'],
    [v.cruiseSpeedMS, 'cruise_speed_m_s', CRUISE_SPEED_RANGE_M_S, true, 'aircraft-cruise-speed', 'Cruise speed: give more than 0 and at most 50 m/s, or leave it empty.'],
    [v.leadInM, 'lead_in_m', LEAD_IN_RANGE_M, false, 'aircraft-lead-in', 'Lead-in: give 0 to 2000 m, or leave it empty.'],
  ];
  for (const [x, key, range, open, control, error] of checks) {
    if (!Number.isFinite(x)) continue;
    // A multirotor turns on the spot: only its cruise speed is sent.
    if (!plane && key !== 'cruise_speed_m_s') continue;
    if (!within(x, range, open)) return { error, control };
    member[key] = x;
  }
  return { member: plane || Object.keys(member).length > 1 ? member : null };
}

/** The aircraft values of a saved request (absent member: a multirotor). */
export function aircraftFromRequest(r: Record<string, unknown>): AircraftValues {
  const a = r.aircraft && typeof r.aircraft === 'object' ? (r.aircraft as Record<string, unknown>) : {};
  const num = (x: unknown) => (typeof x === 'number' && Number.isFinite(x) ? x : NaN);
  const type = a.type === 'fixed_wing' || a.type === 'vtol' ? a.type : 'multirotor';
  return { type, turnRadiusM: num(a.turn_radius_m), climbAngleDeg: num(a.max_climb_angle_deg), cruiseSpeedMS: num(a.cruise_speed_m_s), leadInM: num(a.lead_in_m) };
}

/** The values of the page's aircraft controls. */
export function readAircraftFields(): AircraftValues {
  return {
    type: byId<HTMLSelectElement>('aircraft-type').value as AircraftType,
    turnRadiusM: numberValue('aircraft-turn-radius'),
    climbAngleDeg: numberValue('aircraft-climb-angle'),
    cruiseSpeedMS: numberValue('aircraft-cruise-speed'),
    leadInM: numberValue('aircraft-lead-in'),
  };
}

/** Puts `v` into the page's aircraft controls. */
export function showAircraftFields(v: AircraftValues): void {
  const text = (x: number) => (Number.isFinite(x) ? x : '');
  setValue('aircraft-type', v.type);
  setValue('aircraft-turn-radius', text(v.turnRadiusM));
  setValue('aircraft-climb-angle', text(v.climbAngleDeg));
  setValue('aircraft-cruise-speed', text(v.cruiseSpeedMS));
  setValue('aircraft-lead-in', text(v.leadInM));
}
