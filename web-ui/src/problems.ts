// Turns the API's problem documents into messages for the controls they
// concern. Pure logic (no DOM) so that it is unit-tested; errors-ui.ts puts
// the messages on the page.

import type { Problem } from './api';

/** Where a request member's fault is shown: a field key and its plain name. */
export interface FieldRule {
  /** JSON pointer prefix, matched at a segment boundary ("/uavs" matches "/uavs/2/start"). */
  prefix: string;
  /** The key of the place on the page (an element id ends in `-error`). */
  field: string;
  /** What the member is called on the page. */
  label: string;
}

export interface FieldMessage {
  field: string;
  text: string;
}

/** The survey request's members and where each is shown. Longer prefixes first wins. */
export const SURVEY_FIELDS: FieldRule[] = [
  { prefix: '/roi', field: 'roi', label: 'Survey area' },
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
  { prefix: '/altitude_frame', field: 'altitude-frame', label: 'Altitude frame' },
  { prefix: '/uavs', field: 'uavs', label: 'UAVs' },
  { prefix: '/assignment', field: 'uavs', label: 'Assignment' },
];

export const COSTMAP_FIELDS: FieldRule[] = [
  { prefix: '/dem_id', field: 'dem', label: 'Terrain model' },
  { prefix: '/vehicle', field: 'vehicle', label: 'Vehicle' },
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
  return pointer === prefix || pointer.startsWith(prefix + '/');
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
  const uav = /^\/(?:uavs|cost_changes)\/(\d+)/.exec(pointer);
  const which = uav ? ` ${Number(uav[1]) + 1}` : '';
  return `${label}${which}: ${message.replace(/^\/[\w/]+:\s*/, '')}`;
}

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
      if (rule) return [{ field: rule.field, text: plainMessage(m[1], m[2], rule) }];
    }
    return [{ field: fallback, text: statusMessage(problem) }];
  }
  const out: FieldMessage[] = [];
  for (const issue of issues) {
    const rule = ruleFor(issue.pointer, rules);
    const text = plainMessage(issue.pointer, issue.message, rule);
    const field = rule?.field ?? fallback;
    // One message per field and text: a ring fault is often reported per ring.
    if (!out.some((o) => o.field === field && o.text === text)) out.push({ field, text });
  }
  return out;
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
