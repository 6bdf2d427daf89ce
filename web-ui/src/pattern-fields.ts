// Survey patterns on the page: the crosshatch, the camera pitch and the
// trigger mode, sent as the request's `pattern`, `camera_pitch_deg` and
// `trigger`. The members and their reading back are pure (unit-tested);
// readPatternFields/showPatternFields wire them to the form's controls.

import { byId, numberValue, setValue } from './dom';

export type TriggerMode = 'distance' | 'time' | 'hover';

/** The pattern controls' values; NaN = left empty (the API's default). */
export interface PatternValues {
  crosshatch: boolean;
  /** Degrees, −90 (nadir) … −30; NaN: no gimbal command. */
  pitchDeg: number;
  trigger: TriggerMode;
  /** Seconds between photos (`time` mode). */
  intervalS: number;
  /** Hover at each photo, seconds (`hover` mode). */
  holdS: number;
}

export const PATTERN_DEFAULTS: PatternValues = { crosshatch: false, pitchDeg: NaN, trigger: 'distance', intervalS: NaN, holdS: NaN };

/** The API's ranges. */
export const PITCH_RANGE_DEG = [-90, -30] as const;
export const INTERVAL_RANGE_S = [0.1, 3600] as const;
export const HOLD_RANGE_S = [0, 60] as const;

/** The request members the pattern controls set. */
export const PATTERN_MEMBERS = ['pattern', 'camera_pitch_deg', 'trigger'] as const;

const within = (x: number, [lo, hi]: readonly [number, number]) => x >= lo && x <= hi;

/** The request members of `v` (defaults left out), or the first fault in plain words. */
export function patternMembers(v: PatternValues): { members: Record<string, unknown> } | { error: string; control: string } {
  const members: Record<string, unknown> = {};
  if (v.crosshatch) members.pattern = 'crosshatch';
  if (Number.isFinite(v.pitchDeg)) {
    if (!within(v.pitchDeg, PITCH_RANGE_DEG)) return { error: 'Camera pitch: give −90 (straight down) to −30 degrees, or leave it empty.', control: 'camera-pitch' };
    members.camera_pitch_deg = v.pitchDeg;
  }
  if (v.trigger !== 'distance') {
    const trigger: Record<string, unknown> = { mode: v.trigger };
    if (v.trigger === 'time' && Number.isFinite(v.intervalS)) {
      if (!within(v.intervalS, INTERVAL_RANGE_S)) return { error: 'Photo interval: give 0.1 to 3600 seconds, or leave it empty.', control: 'trigger-interval' };
      trigger.interval_s = v.intervalS;
    }
    if (v.trigger === 'hover' && Number.isFinite(v.holdS)) {
      if (!within(v.holdS, HOLD_RANGE_S)) return { error: 'Hover per photo: give 0 to 60 seconds, or leave it empty.', control: 'trigger-hold' };
      trigger.hold_s = v.holdS;
    }
    members.trigger = trigger;
  }
  return { members };
}

/** The pattern values of a saved request (absent members: the defaults). */
export function patternFromRequest(r: Record<string, unknown>): PatternValues {
  const t = r.trigger && typeof r.trigger === 'object' ? (r.trigger as Record<string, unknown>) : {};
  const num = (x: unknown) => (typeof x === 'number' && Number.isFinite(x) ? x : NaN);
  const mode = t.mode === 'time' || t.mode === 'hover' ? t.mode : 'distance';
  return { crosshatch: r.pattern === 'crosshatch', pitchDeg: num(r.camera_pitch_deg), trigger: mode, intervalS: num(t.interval_s), holdS: num(t.hold_s) };
}

/** The values of the page's pattern controls. */
export function readPatternFields(): PatternValues {
  return {
    crosshatch: byId<HTMLInputElement>('crosshatch').checked,
    pitchDeg: numberValue('camera-pitch'),
    trigger: byId<HTMLSelectElement>('trigger-mode').value as TriggerMode,
    intervalS: numberValue('trigger-interval'),
    holdS: numberValue('trigger-hold'),
  };
}

/** Puts `v` into the page's pattern controls. */
export function showPatternFields(v: PatternValues): void {
  byId<HTMLInputElement>('crosshatch').checked = v.crosshatch;
  const text = (x: number) => (Number.isFinite(x) ? x : '');
  setValue('camera-pitch', text(v.pitchDeg));
  setValue('trigger-mode', v.trigger);
  setValue('trigger-interval', text(v.intervalS));
  setValue('trigger-hold', text(v.holdS));
}
