import { describe, expect, it } from 'vitest';
import { PATTERN_DEFAULTS, patternFromRequest, patternMembers } from '../src/pattern-fields';
import { SURVEY_FIELDS, ruleFor } from '../src/problems';

describe('pattern members', () => {
  it('leaves the defaults out, so a plain survey is the request it was', () => {
    expect(patternMembers(PATTERN_DEFAULTS)).toEqual({ members: {} });
  });

  it('sends crosshatch, pitch and trigger, and reads them back', () => {
    const v = { crosshatch: true, pitchDeg: -60, trigger: 'hover' as const, intervalS: NaN, holdS: 1.5 };
    const m = patternMembers(v);
    expect(m).toEqual({ members: { pattern: 'crosshatch', camera_pitch_deg: -60, trigger: { mode: 'hover', hold_s: 1.5 } } });
    expect(patternFromRequest((m as { members: Record<string, unknown> }).members)).toEqual(v);
    // The interval only goes with time triggering.
    expect(patternMembers({ ...PATTERN_DEFAULTS, trigger: 'time', intervalS: 2, holdS: 3 })).toEqual({ members: { trigger: { mode: 'time', interval_s: 2 } } });
  });

  it('refuses values out of the API ranges, naming the control', () => {
    expect(patternMembers({ ...PATTERN_DEFAULTS, pitchDeg: -20 })).toMatchObject({ control: 'camera-pitch' });
    expect(patternMembers({ ...PATTERN_DEFAULTS, trigger: 'time', intervalS: 0 })).toMatchObject({ control: 'trigger-interval' });
    expect(patternMembers({ ...PATTERN_DEFAULTS, trigger: 'hover', holdS: 61 })).toMatchObject({ control: 'trigger-hold' });
  });
});

describe('pattern faults from the server', () => {
  it('land on the pattern fieldset, on the control at fault', () => {
    expect(ruleFor('/camera_pitch_deg', SURVEY_FIELDS)).toMatchObject({ field: 'pattern', control: 'camera-pitch' });
    expect(ruleFor('/trigger/interval_s', SURVEY_FIELDS)).toMatchObject({ field: 'pattern', control: 'trigger-interval' });
    expect(ruleFor('/trigger/mode', SURVEY_FIELDS)).toMatchObject({ field: 'pattern', control: 'trigger-mode' });
    expect(ruleFor('/pattern', SURVEY_FIELDS)).toMatchObject({ field: 'pattern' });
  });
});
