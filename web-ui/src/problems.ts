// Turns the API's problem documents into messages for the controls they
// concern. Pure logic (no DOM) so that it is unit-tested; errors-ui.ts puts
// the messages on the page.

import type { Problem } from './api';

/** Where a request member's fault is shown: a field key and its plain name. */
export interface FieldRule {
  /** JSON pointer prefix, matched at a segment boundary ("/uavs" matches "/uavs/2/start"); a `*` segment matches any one segment. */
  prefix: string;
  /** The key of the place on the page (an element id ends in `-error`). */
  field: string;
  /** What the member is called on the page. */
  label: string;
  /** The id of the control to mark invalid, when not the first one the slot describes. */
  control?: string;
}

export interface FieldMessage {
  field: string;
  text: string;
  /** The id of the control to mark invalid (else the first one the field's slot describes). */
  control?: string;
}

/** The survey request's members and where each is shown. Longer prefixes first wins. */
export const SURVEY_FIELDS: FieldRule[] = [
  { prefix: '/roi', field: 'roi', label: 'Survey area' },
  { prefix: '/corridor', field: 'corridor', label: 'Corridor' },
  { prefix: '/no_fly_zones', field: 'nfz', label: 'No-fly zone' },
  { prefix: '/dem_id', field: 'dem', label: 'Terrain model' },
  { prefix: '/allow_partial_dem', field: 'dem', label: 'Terrain model' },
  { prefix: '/camera_preset', field: 'camera', label: 'Camera' },
  { prefix: '/camera', field: 'camera', label: 'Camera' },
  { prefix: '/altitude_m', field: 'altitude', label: 'Altitude' },
  { prefix: '/gsd_cm_px', field: 'altitude', label: 'Ground sample distance' },
  { prefix: '/agl_tolerance_m', field: 'altitude', label: 'Altitude tolerance' },
  { prefix: '/front_overlap', field: 'front-overlap', label: 'Front overlap' },
  { prefix: '/side_overlap', field: 'side-overlap', label: 'Side overlap' },
  { prefix: '/line_spacing_m', field: 'side-overlap', label: 'Line spacing' },
  { prefix: '/slice_angle_deg', field: 'slice-angle', label: 'Slice angle' },
  { prefix: '/speed_m_s', field: 'speed', label: 'Speed' },
  { prefix: '/nfz_clearance_m', field: 'nfz-clearance', label: 'Clearance from no-fly zones' },
  { prefix: '/altitude_frame', field: 'altitude-frame', label: 'Altitude frame' },
  { prefix: '/uavs/*/max_flight_time_s', field: 'battery', label: 'Battery' },
  { prefix: '/uavs', field: 'uavs', label: 'UAVs' },
  { prefix: '/assignment', field: 'uavs', label: 'Assignment' },
  { prefix: '/rally_points', field: 'rally', label: 'Rally points' },
  { prefix: '/pattern', field: 'pattern', label: 'Pattern' },
  { prefix: '/camera_pitch_deg', field: 'pattern', label: 'Camera pitch', control: 'camera-pitch' },
  { prefix: '/trigger/interval_s', field: 'pattern', label: 'Photo interval', control: 'trigger-interval' },
  { prefix: '/trigger/hold_s', field: 'pattern', label: 'Hover per photo', control: 'trigger-hold' },
  { prefix: '/trigger', field: 'pattern', label: 'Trigger', control: 'trigger-mode' },
  { prefix: '/aircraft/turn_radius_m', field: 'aircraft', label: 'Turn radius', control: 'aircraft-turn-radius' },
  { prefix: '/aircraft/max_climb_angle_deg', field: 'aircraft', label: 'Climb angle', control: 'aircraft-climb-angle' },
  { prefix: '/aircraft/cruise_speed_m_s', field: 'aircraft', label: 'Cruise speed', control: 'aircraft-cruise-speed' },
  { prefix: '/aircraft/lead_in_m', field: 'aircraft', label: 'Lead-in', control: 'aircraft-lead-in' },
  { prefix: '/aircraft', field: 'aircraft', label: 'Aircraft', control: 'aircraft-type' },
];

export const COSTMAP_FIELDS: FieldRule[] = [
  { prefix: '/dem_id', field: 'dem', label: 'Terrain model' },
  { prefix: '/vehicle', field: 'vehicle', label: 'Vehicle' },
  { prefix: '/vehicle/max_slope_deg', field: 'vehicle', label: 'Max slope', control: 'max-slope' },
  { prefix: '/vehicle/max_step_m', field: 'vehicle', label: 'Max step', control: 'max-step' },
  { prefix: '/options/resolution_m', field: 'resolution', label: 'Cell size' },
  { prefix: '/options', field: 'vehicle', label: 'Costmap option' },
];

export const ROUTE_FIELDS: FieldRule[] = [
  { prefix: '/start', field: 'start', label: 'Start' },
  { prefix: '/goal', field: 'goal', label: 'Goal' },
  { prefix: '/position', field: 'position', label: 'Replan position' },
  { prefix: '/blocked', field: 'blocked', label: 'Blocked area' },
  { prefix: '/cost_changes', field: 'cost', label: 'Costlier area' },
  { prefix: '/speed_m_s', field: 'route-speed', label: 'Speed' },
];

function matches(pointer: string, prefix: string): boolean {
  const want = prefix.split('/');
  const have = pointer.split('/');
  return have.length >= want.length && want.every((seg, i) => seg === '*' || seg === have[i]);
}

/** The rule for a pointer: the longest matching prefix, or undefined. */
export function ruleFor(pointer: string, rules: FieldRule[]): FieldRule | undefined {
  let best: FieldRule | undefined;
  for (const r of rules) if (matches(pointer, r.prefix) && (!best || r.prefix.length > best.prefix.length)) best = r;
  return best;
}

const fmtCoord = (lon: string, lat: string) => `lon ${Number(lon).toFixed(5)}, lat ${Number(lat).toFixed(5)}`;

/**
 * Rewrites a server message in plain words where we know a clearer way to
 * say it (geometry faults are phrased for programmers); otherwise keeps it.
 */
export function plainMessage(pointer: string, message: string, rule?: FieldRule): string {
  const label = rule?.label ?? 'Request';
  const self = /self-intersects at \(([-\d.]+),\s*([-\d.]+)\)/.exec(message);
  if (self) {
    return `${label}: the outline crosses itself near ${fmtCoord(self[1], self[2])}. Redraw it so that its edges do not cross.`;
  }
  if (/fewer than|at least (3|4) (distinct )?(points|positions|vertices)/i.test(message)) {
    return `${label}: the outline needs at least three distinct corners. ${capitalise(message)}.`;
  }
  let text = pageWords(message.replace(/^\/[\w/]+:\s*/, ''));
  // The page takes overlaps in percent; the API's messages give fractions.
  if (rule?.field === 'front-overlap' || rule?.field === 'side-overlap') {
    text = text.replace(/^(-?[\d.]+) is outside the allowed range \[([\d.]+), ([\d.]+)\]/, (_, v: string, lo: string, hi: string) => `${pct(v)} % is outside the allowed range ${pct(lo)}–${pct(hi)} %`);
  }
  // The battery field is in minutes and the page shows no cell numbers.
  if (rule?.field === 'battery') {
    text = text.replace(/\bcell \d+\b/g, 'one of the cells').replace(/\b(\d+(?:\.\d+)?) s\b/g, (_, n: string) => minutesAndSeconds(Number(n)));
  }
  // A fault of one UAV or area says which (numbered from 1, as on the page); the battery's own messages name their UAV.
  const item = /^\/(uavs|cost_changes)\/(\d+)/.exec(pointer);
  if (item && rule?.field !== 'battery') {
    const n = Number(item[2]) + 1;
    return `${item[1] === 'uavs' ? `UAV ${n}` : `${label} ${n}`}: ${text}`;
  }
  // "Max step: max step must be …" would say the name twice.
  if (text.toLowerCase().startsWith(`${label.toLowerCase()} `)) text = text.slice(label.length + 1);
  return `${label}: ${text}`;
}

/** API member names as the page calls them (messages are written for API users). */
const PAGE_WORDS: [RegExp, string][] = [
  [/\bset allow_partial_dem: true\b/g, 'tick “Plan even where the DEM has gaps”'],
  [/\ballow_partial_dem\b/g, '“Plan even where the DEM has gaps”'],
  [/\bmax_flight_time_s\b/g, 'battery time'],
  [/\bmax_step_m\b/g, 'max step'],
  [/\bmax_slope_deg\b/g, 'max slope'],
  [/\baltitude_m\b/g, 'altitude'],
  [/\bgsd_cm_px\b/g, 'GSD'],
  [/\bspeed_m_s\b/g, 'speed'],
  // "the 5 m kept from them (nfz_clearance_m)" says it once in words already.
  [/ \(nfz_clearance_m\)/g, ''],
  [/\bnfz_clearance_m\b/g, 'the clearance from no-fly zones'],
  [/\bslice_angle_deg\b/g, 'slice angle'],
  [/\bresolution_m\b/g, 'cell size'],
  [/\bfront_overlap\b/g, 'front overlap'],
  [/\bside_overlap\b/g, 'side overlap'],
];

function pageWords(message: string): string {
  let text = message;
  for (const [pattern, words] of PAGE_WORDS) text = text.replace(pattern, words);
  return text;
}

/** 45 → "45 s", 360 → "6 min", 367 → "6 min 7 s". */
function minutesAndSeconds(seconds: number): string {
  const total = Math.round(seconds);
  const min = Math.floor(total / 60);
  const sec = total % 60;
  if (min === 0) return `${sec} s`;
  return sec === 0 ? `${min} min` : `${min} min ${sec} s`;
}

const pct = (fraction: string) => String(Math.round(Number(fraction) * 1000) / 10);

function capitalise(s: string): string {
  return s.charAt(0).toUpperCase() + s.slice(1);
}

/**
 * Splits a problem into messages per field. Faults without a known field,
 * and problems without `errors`, go to `fallback` (the form's own message).
 */
export function problemToMessages(problem: Problem, rules: FieldRule[], fallback = 'form'): FieldMessage[] {
  const issues = problem.errors ?? [];
  if (issues.length === 0) {
    // Some faults come only in `detail`, prefixed by their pointer ("/dem_id: ...").
    const m = /^(\/[\w/]*):\s*(.*)$/s.exec(problem.detail ?? '');
    if (m) {
      const rule = ruleFor(m[1], rules);
      if (rule) return [withControl({ field: rule.field, text: plainMessage(m[1], m[2], rule) }, rule)];
    }
    return [{ field: fallback, text: statusMessage(problem) }];
  }
  const out: FieldMessage[] = [];
  for (const issue of issues) {
    const rule = ruleFor(issue.pointer, rules);
    const text = plainMessage(issue.pointer, issue.message, rule);
    const field = rule?.field ?? fallback;
    // One message per field and text: a ring fault is often reported per ring.
    if (!out.some((o) => o.field === field && o.text === text)) out.push(withControl({ field, text }, rule));
  }
  return out;
}

function withControl(m: FieldMessage, rule: FieldRule | undefined): FieldMessage {
  return rule?.control ? { ...m, control: rule.control } : m;
}

/** A problem without field faults in plain words, by status. */
export function statusMessage(problem: Problem): string {
  switch (problem.status) {
    case 0:
      return problem.detail || 'The terraplan server cannot be reached.';
    case 404:
      return `Not found: ${problem.detail}`;
    case 409:
      return `Not ready yet: ${problem.detail}`;
    case 413:
      return `Too large: ${problem.detail}`;
    case 503:
      return `The server is busy or the search took too long: ${problem.detail}`;
    default:
      return problem.detail || problem.title || `The server answered ${problem.status}.`;
  }
}
