// The survey form's values, how they become a `POST /api/v1/surveys` body,
// and how a saved survey's request becomes them again. Pure (no DOM) so it is
// unit-tested.

import type { Camera, LonLat } from './api';
import { aircraftFromRequest, aircraftMember, type AircraftValues } from './aircraft-fields';
import { corridorFromRequest, corridorMembers, type CorridorValues } from './corridor-fields';
import { PATTERN_MEMBERS, patternFromRequest, patternMembers, type PatternValues } from './pattern-fields';
import { polygonsOf, type PolygonRings } from './geo-import';
import type { FieldMessage } from './problems';

/** A camera's numbers (the API's `Camera`), as sent for a custom camera. */
export type CustomCamera = Camera;

/** The numbers of a camera in a sentence, shown under the chooser. */
export function cameraSummary(c: Camera): string {
  return (
    `Sensor ${trim(c.sensor_width_mm)} × ${trim(c.sensor_height_mm)} mm, focal length ${trim(c.focal_length_mm)} mm, ` +
    `${c.image_width_px} × ${c.image_height_px} px (${megapixels(c)} MP), ${c.orientation}.`
  );
}

const megapixels = (c: Camera) => ((c.image_width_px * c.image_height_px) / 1e6).toFixed(1);
const trim = (x: number) => String(Math.round(x * 1000) / 1000);

export interface UavStart {
  id: string;
  start: LonLat;
  /** Kept from a reopened survey (the form has no control for them). */
  speed_m_s?: number;
  max_flight_time_s?: number;
}

export interface SurveyFormValues {
  name: string;
  roi: PolygonRings | null;
  /** A corridor along a line, surveyed instead of the ROI when given. */
  corridor?: CorridorValues | null;
  /** Crosshatch, camera pitch and trigger mode (absent: the API's defaults). */
  patterns?: PatternValues;
  /** The airframe (absent: a multirotor, the API's default). */
  aircraft?: AircraftValues;
  noFlyZones: PolygonRings[];
  demId: string | null;
  allowPartialDem: boolean;
  /** A preset id, or "custom". */
  camera: string;
  customCamera: CustomCamera;
  heightMode: 'altitude' | 'gsd';
  altitudeM: number;
  gsdCmPx: number;
  frontOverlapPct: number;
  sideOverlapPct: number;
  /** "auto" or degrees in [0, 180). */
  sliceAngle: string;
  speedMS: number;
  /** Distance kept by everything flown from every no-fly zone and from the inclusion fence, m, in [0, 100]. */
  nfzClearanceM: number;
  altitudeFrame: 'relative' | 'amsl' | 'terrain';
  assignment: 'balanced' | 'competition' | 'min_reach';
  /** Flight time on one battery, minutes, for every UAV (NaN: unlimited, or each UAV's own from a reopened survey). */
  batteryMin: number;
  uavs: UavStart[];
  /** Where a UAV may return instead of home (the API's `rally_points`). */
  rallyPoints: LonLat[];
  /** Members of a reopened survey's request the form has no control for (sent again as they were). */
  extra: Record<string, unknown>;
}

export interface SurveyRequest {
  body: Record<string, unknown> | null;
  /** Faults the page can tell before asking the server. */
  errors: FieldMessage[];
}

const polygon = (rings: PolygonRings) => ({ type: 'Polygon', coordinates: rings });

/** Builds the request body, or the faults that keep it from being sent. */
export function buildSurveyRequest(v: SurveyFormValues): SurveyRequest {
  const errors: FieldMessage[] = [];
  const corridor = v.corridor ? corridorMembers(v.corridor) : null;
  if (corridor && 'error' in corridor) errors.push({ field: 'corridor', text: corridor.error, control: 'corridor-width' });
  const patterns = v.patterns ? patternMembers(v.patterns) : { members: {} };
  if ('error' in patterns) errors.push({ field: 'pattern', text: patterns.error, control: patterns.control });
  const aircraft = v.aircraft ? aircraftMember(v.aircraft) : { member: null };
  if ('error' in aircraft) errors.push({ field: 'aircraft', text: aircraft.error, control: aircraft.control });
  if (!v.roi && !corridor) errors.push({ field: 'roi', text: 'Survey area: draw it on the map or import a file first.' });
  if (v.altitudeFrame !== 'relative' && !v.demId) {
    errors.push({ field: 'altitude-frame', text: `Altitude frame: “${v.altitudeFrame}” needs a terrain model (DEM); choose one or use “relative”.` });
  }
  const slice = v.sliceAngle.trim().toLowerCase();
  if (slice !== 'auto' && slice !== '' && !Number.isFinite(Number(slice))) {
    errors.push({ field: 'slice-angle', text: 'Slice angle: give a number of degrees, or “auto”.' });
  }
  // An empty number field is a fault here, never a silent 0 (an empty overlap would fly 0 % overlap).
  // [error slot, label, value, the control's id]
  const needed: [string, string, number, string][] = [
    v.heightMode === 'gsd' ? ['altitude', 'Ground sample distance (cm/px)', v.gsdCmPx, 'gsd'] : ['altitude', 'Altitude (m)', v.altitudeM, 'altitude'],
    ['front-overlap', 'Front overlap (%)', v.frontOverlapPct, 'front-overlap'],
    ['side-overlap', 'Side overlap (%)', v.sideOverlapPct, 'side-overlap'],
    ['speed', 'Speed (m/s)', v.speedMS, 'speed'],
    ['nfz-clearance', 'Clearance from no-fly zones (m)', v.nfzClearanceM, 'nfz-clearance'],
  ];
  if (v.camera === 'custom') {
    const c = v.customCamera;
    needed.push(
      ['camera', 'Sensor width (mm)', c.sensor_width_mm, 'cam-sw'],
      ['camera', 'Sensor height (mm)', c.sensor_height_mm, 'cam-sh'],
      ['camera', 'Focal length (mm)', c.focal_length_mm, 'cam-f'],
      ['camera', 'Image width (px)', c.image_width_px, 'cam-iw'],
      ['camera', 'Image height (px)', c.image_height_px, 'cam-ih'],
    );
  }
  for (const [field, label, value, control] of needed) {
    if (!Number.isFinite(value)) errors.push({ field, text: `${label}: give a number.`, control });
  }
  const battery = Number.isFinite(v.batteryMin) ? v.batteryMin : null;
  if (battery !== null && (battery < BATTERY_MIN_RANGE[0] || battery > BATTERY_MIN_RANGE[1])) {
    errors.push({ field: 'battery', text: `Battery: give a flight time from ${BATTERY_MIN_RANGE[0]} to ${BATTERY_MIN_RANGE[1]} minutes, or leave it empty for no limit.` });
  }
  if (errors.length > 0) return { body: null, errors };

  const body: Record<string, unknown> = {
    ...v.extra,
    ...(corridor && 'members' in corridor ? corridor.members : { roi: polygon(v.roi!) }),
    no_fly_zones: v.noFlyZones.map(polygon),
    front_overlap: round(v.frontOverlapPct / 100, 4),
    side_overlap: round(v.sideOverlapPct / 100, 4),
    slice_angle_deg: slice === 'auto' || slice === '' ? 'auto' : Number(slice),
    speed_m_s: v.speedMS,
    nfz_clearance_m: v.nfzClearanceM,
    altitude_frame: v.altitudeFrame,
    assignment: v.assignment,
    ...('members' in patterns ? patterns.members : {}),
    ...('member' in aircraft && aircraft.member ? { aircraft: aircraft.member } : {}),
  };
  if (v.name.trim()) body.name = v.name.trim();
  if (v.heightMode === 'gsd') body.gsd_cm_px = v.gsdCmPx;
  else body.altitude_m = v.altitudeM;
  if (v.camera === 'custom') body.camera = { ...v.customCamera };
  else if (v.camera) body.camera_preset = v.camera;
  if (v.demId) {
    body.dem_id = v.demId;
    if (v.allowPartialDem) body.allow_partial_dem = true;
  }
  // No UAVs placed: the server puts one at the ROI's first corner clear of the
  // NFZs; with a battery limit that UAV is spelled out here (the limit is per
  // UAV), at the point the server would choose.
  // A corridor's UAV takes off at the line's start (inside the corridor).
  const start = (): LonLat => (v.corridor ? v.corridor.line[0] : defaultStart(v.roi!, v.noFlyZones, v.nfzClearanceM));
  const uavs: UavStart[] = v.uavs.length > 0 || battery === null ? v.uavs : [{ id: 'uav1', start: start() }];
  if (uavs.length > 0) {
    body.uavs = uavs.map((u) => {
      const uav: Record<string, unknown> = { id: u.id, start: u.start };
      if (u.speed_m_s != null) uav.speed_m_s = u.speed_m_s;
      const seconds = battery !== null ? round(battery * 60, 1) : u.max_flight_time_s;
      if (seconds != null) uav.max_flight_time_s = seconds;
      return uav;
    });
  }
  if (v.rallyPoints.length > 0) body.rally_points = v.rallyPoints.map((p) => [p[0], p[1]]);
  return { body, errors };
}

/**
 * Where the server takes off with the one UAV of a survey given none
 * (planner-core survey/homes.rs): the area's first corner at least the
 * clearance from every no-fly zone, else the clear point of the area's
 * outline nearest that corner (sampled every metre), else the first corner
 * (the server then says why). Distances are measured in a flat frame at the
 * first corner: within a few centimetres of the server's UTM ones over such
 * distances, and a start that close to the clearance is still accepted.
 */
export function defaultStart(roi: PolygonRings, noFlyZones: PolygonRings[], clearanceM: number): LonLat {
  const origin = roi[0][0];
  const mPerDegLat = (Math.PI / 180) * 6_371_008.8;
  const mPerDegLon = mPerDegLat * Math.cos((origin[1] * Math.PI) / 180);
  const flat = (p: number[]): [number, number] => [(p[0] - origin[0]) * mPerDegLon, (p[1] - origin[1]) * mPerDegLat];
  const zones = noFlyZones.map((rings) => rings.map((ring) => ring.map(flat)));
  const clear = (p: [number, number]) => zones.every((rings) => !insideRings(p, rings) && rings.every((ring) => ringDistance(p, ring) >= clearanceM));

  const exterior = roi[0];
  const closed = exterior.length > 1 && exterior[0][0] === exterior[exterior.length - 1][0] && exterior[0][1] === exterior[exterior.length - 1][1];
  const corner = exterior.slice(0, closed ? -1 : undefined).find((p) => clear(flat(p)));
  if (corner) return [corner[0], corner[1]];

  let best: { p: [number, number]; d: number } | null = null;
  for (const ring of roi.map((r) => r.map(flat))) {
    for (let i = 0; i + 1 < ring.length; i++) {
      const [a, b] = [ring[i], ring[i + 1]];
      const steps = Math.max(1, Math.ceil(Math.hypot(b[0] - a[0], b[1] - a[1])));
      for (let k = 0; k <= steps; k++) {
        const p: [number, number] = [a[0] + ((b[0] - a[0]) * k) / steps, a[1] + ((b[1] - a[1]) * k) / steps];
        const d = Math.hypot(p[0], p[1]);
        if ((!best || d < best.d) && clear(p)) best = { p, d };
      }
    }
  }
  return best ? [origin[0] + best.p[0] / mPerDegLon, origin[1] + best.p[1] / mPerDegLat] : [origin[0], origin[1]];
}

/** Inside a polygon given by its rings (even-odd: a point in a hole is outside). */
function insideRings(p: [number, number], rings: [number, number][][]): boolean {
  let inside = false;
  for (const ring of rings) {
    for (let i = 0, j = ring.length - 1; i < ring.length; j = i++) {
      const [a, b] = [ring[i], ring[j]];
      if (a[1] > p[1] !== b[1] > p[1] && p[0] < ((b[0] - a[0]) * (p[1] - a[1])) / (b[1] - a[1]) + a[0]) inside = !inside;
    }
  }
  return inside;
}

/** Distance from a point to a ring's edges (closing edge included). */
function ringDistance(p: [number, number], ring: [number, number][]): number {
  let best = Infinity;
  for (let i = 0, j = ring.length - 1; i < ring.length; j = i++) {
    const [a, b] = [ring[j], ring[i]];
    const [dx, dy] = [b[0] - a[0], b[1] - a[1]];
    const len2 = dx * dx + dy * dy;
    const t = len2 > 0 ? Math.min(1, Math.max(0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2)) : 0;
    best = Math.min(best, Math.hypot(p[0] - a[0] - t * dx, p[1] - a[1] - t * dy));
  }
  return best;
}

/** What a camera at a height gives on the ground (as the server computes it, coverage/camera.rs). */
export interface FlightGeometry {
  altitudeM: number;
  gsdCmPx: number;
  footprintSideM: number;
  footprintFrontM: number;
  lineSpacingM: number;
  triggerDistanceM: number;
  /** Seconds between photos at the survey speed. */
  triggerIntervalS: number;
}

/**
 * The flight geometry of a camera flown at an altitude, or at the altitude
 * giving a GSD (`height` says which); overlaps in percent. Null when the
 * numbers cannot give one (a field empty or out of range).
 */
export function flightGeometry(
  camera: Camera,
  height: { mode: 'altitude'; altitudeM: number } | { mode: 'gsd'; gsdCmPx: number },
  sideOverlapPct: number,
  frontOverlapPct: number,
  speedMS: number,
): FlightGeometry | null {
  const portrait = camera.orientation === 'portrait';
  const acrossMm = portrait ? camera.sensor_height_mm : camera.sensor_width_mm;
  const acrossPx = portrait ? camera.image_height_px : camera.image_width_px;
  const alongMm = portrait ? camera.sensor_width_mm : camera.sensor_height_mm;
  const f = camera.focal_length_mm;
  if (![acrossMm, acrossPx, alongMm, f].every((x) => Number.isFinite(x) && x > 0)) return null;
  const altitudeM = height.mode === 'altitude' ? height.altitudeM : (height.gsdCmPx / 100) * acrossPx * f / acrossMm;
  if (!Number.isFinite(altitudeM) || altitudeM <= 0) return null;
  const footprintSideM = (altitudeM * acrossMm) / f;
  const footprintFrontM = (altitudeM * alongMm) / f;
  const triggerDistanceM = footprintFrontM * (1 - frontOverlapPct / 100);
  return {
    altitudeM,
    gsdCmPx: (footprintSideM * 100) / acrossPx,
    footprintSideM,
    footprintFrontM,
    lineSpacingM: footprintSideM * (1 - sideOverlapPct / 100),
    triggerDistanceM,
    triggerIntervalS: speedMS > 0 ? triggerDistanceM / speedMS : NaN,
  };
}

/** The flight geometry in a line, shown under the height fields. */
export function describeFlightGeometry(g: FlightGeometry, by: 'altitude' | 'gsd'): string {
  const n = (x: number, d: number) => (Number.isFinite(x) ? x.toFixed(d) : '–');
  const height = by === 'altitude' ? `GSD ${n(g.gsdCmPx, 2)} cm/px` : `altitude ${n(g.altitudeM, 1)} m`;
  return (
    `${height}; each photo covers ${n(g.footprintSideM, 1)} × ${n(g.footprintFrontM, 1)} m; ` +
    `lanes ${n(g.lineSpacingM, 1)} m apart; a photo every ${n(g.triggerDistanceM, 1)} m (${n(g.triggerIntervalS, 1)} s).`
  );
}

/** The battery field's range, minutes: the API takes 30 s to 24 h per UAV. */
export const BATTERY_MIN_RANGE = [0.5, 1440] as const;

/** The form's values before anything is changed: the API's defaults (index.html shows the same). */
export const FORM_DEFAULTS = {
  heightMode: 'altitude',
  altitudeM: 60,
  gsdCmPx: 1.5,
  frontOverlapPct: 80,
  sideOverlapPct: 70,
  sliceAngle: 'auto',
  speedMS: 10,
  nfzClearanceM: 5,
  altitudeFrame: 'relative',
  assignment: 'balanced',
} as const satisfies Partial<SurveyFormValues>;

/**
 * Request members the form has controls for (the rest are kept as `extra`).
 * `project_id` too: a plan made again goes to the project chosen now.
 */
const FORM_MEMBERS = new Set([
  'name', 'project_id', 'roi', 'corridor', 'corridor_width_m', 'no_fly_zones', 'dem_id', 'allow_partial_dem', 'camera', 'camera_preset', 'altitude_m', 'gsd_cm_px',
  'front_overlap', 'side_overlap', 'slice_angle_deg', 'speed_m_s', 'nfz_clearance_m', 'altitude_frame', 'assignment', 'uavs', 'rally_points',
  ...PATTERN_MEMBERS,
  'aircraft',
]);

export interface RestoredForm {
  values: SurveyFormValues;
  /** What could not be put back as it was, in plain words. */
  notes: string[];
}

/**
 * The form's values from a saved survey's `request` (as made; members left
 * out took the API's defaults, so the form shows those). `base` gives the
 * camera when the request names none (the default preset) and the custom
 * camera's numbers when it used a preset.
 */
export function formFromRequest(
  request: Record<string, unknown>,
  name: string | null,
  base: { camera: string; customCamera: CustomCamera },
): RestoredForm {
  const notes: string[] = [];
  const r = request;
  const num = (x: unknown, fallback: number) => (typeof x === 'number' && Number.isFinite(x) ? x : fallback);
  const pct = (x: unknown, fallback: number) => (typeof x === 'number' ? round(x * 100, 2) : fallback);
  const oneOf = <T extends string>(x: unknown, allowed: readonly T[], fallback: T): T => (allowed.includes(x as T) ? (x as T) : fallback);

  const rois = polygonsOf(r.roi);
  const corridor = corridorFromRequest(r);
  if (rois.length > 1) notes.push(`The saved area has ${rois.length} parts; only the first is shown and planned again.`);
  const noFlyZones = Array.isArray(r.no_fly_zones) ? r.no_fly_zones.flatMap((z) => polygonsOf(z)) : [];

  const custom = r.camera && typeof r.camera === 'object' ? (r.camera as CustomCamera) : null;
  const camera = custom ? 'custom' : typeof r.camera_preset === 'string' ? r.camera_preset : base.camera;
  const gsd = typeof r.gsd_cm_px === 'number';

  const uavs: UavStart[] = [];
  for (const u of Array.isArray(r.uavs) ? r.uavs : []) {
    const spec = u as Partial<UavStart> | null;
    if (!spec || typeof spec.id !== 'string' || !Array.isArray(spec.start)) continue;
    const uav: UavStart = { id: spec.id, start: [Number(spec.start[0]), Number(spec.start[1])] };
    if (typeof spec.speed_m_s === 'number') uav.speed_m_s = spec.speed_m_s;
    if (typeof spec.max_flight_time_s === 'number') uav.max_flight_time_s = spec.max_flight_time_s;
    uavs.push(uav);
  }

  // One battery for every UAV goes back in the battery field; different ones stay with their UAVs.
  const batteries = new Set(uavs.map((u) => u.max_flight_time_s));
  const shared = uavs.length > 0 && batteries.size === 1 ? [...batteries][0] : undefined;
  if (shared != null) for (const u of uavs) delete u.max_flight_time_s;
  if (batteries.size > 1) notes.push('Its UAVs have different batteries: each keeps its own unless a battery is given here.');

  const rallyPoints: LonLat[] = (Array.isArray(r.rally_points) ? r.rally_points : [])
    .filter((p): p is [number, number] => Array.isArray(p) && p.length === 2 && p.every((x) => typeof x === 'number'))
    .map((p) => [p[0], p[1]]);

  const extra: Record<string, unknown> = {};
  for (const [k, v] of Object.entries(r)) if (!FORM_MEMBERS.has(k) && v !== null && v !== undefined) extra[k] = v;

  const d = FORM_DEFAULTS;
  return {
    values: {
      name: name ?? '',
      roi: rois[0] ?? null,
      ...(corridor ? { corridor } : {}),
      ...(PATTERN_MEMBERS.some((k) => r[k] != null) ? { patterns: patternFromRequest(r) } : {}),
      ...(r.aircraft != null ? { aircraft: aircraftFromRequest(r) } : {}),
      noFlyZones,
      demId: typeof r.dem_id === 'string' ? r.dem_id : null,
      allowPartialDem: r.allow_partial_dem === true,
      camera,
      customCamera: custom ? { ...base.customCamera, ...custom } : base.customCamera,
      heightMode: gsd ? 'gsd' : 'altitude',
      altitudeM: num(r.altitude_m, d.altitudeM),
      gsdCmPx: num(r.gsd_cm_px, d.gsdCmPx),
      frontOverlapPct: pct(r.front_overlap, d.frontOverlapPct),
      sideOverlapPct: pct(r.side_overlap, d.sideOverlapPct),
      sliceAngle: typeof r.slice_angle_deg === 'number' ? String(r.slice_angle_deg) : d.sliceAngle,
      speedMS: num(r.speed_m_s, d.speedMS),
      nfzClearanceM: num(r.nfz_clearance_m, d.nfzClearanceM),
      altitudeFrame: oneOf(r.altitude_frame, ['relative', 'amsl', 'terrain'] as const, d.altitudeFrame),
      assignment: oneOf(r.assignment, ['balanced', 'competition', 'min_reach'] as const, d.assignment),
      batteryMin: shared != null ? round(shared / 60, 3) : NaN,
      uavs,
      rallyPoints,
      extra,
    },
    notes,
  };
}

/** The kept members in a line ("line_spacing_m 25, turn_penalty_s 3"). */
export function describeExtra(extra: Record<string, unknown>): string {
  return Object.entries(extra)
    .map(([k, v]) => `${k} ${typeof v === 'object' ? JSON.stringify(v) : String(v)}`)
    .join(', ');
}

function round(x: number, digits: number): number {
  const f = 10 ** digits;
  return Math.round(x * f) / f;
}

/** The next free UAV id ("uav1", "uav2", …) for a new start position. */
export function nextUavId(existing: UavStart[]): string {
  const taken = new Set(existing.map((u) => u.id));
  for (let i = 1; ; i++) if (!taken.has(`uav${i}`)) return `uav${i}`;
}

/** Distinct colours for UAV routes, in order; readable on the grey hillshade. */
export const UAV_COLOURS = ['#e6194b', '#1f78b4', '#2ca02c', '#ff7f00', '#9467bd', '#00a6a6', '#d62790', '#8c564b', '#b8a000', '#17becf'];

export function uavColour(index: number): string {
  return UAV_COLOURS[index % UAV_COLOURS.length];
}
