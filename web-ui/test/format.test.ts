import { describe, expect, it } from 'vitest';
import { formatArea, formatDegrees, formatDuration, formatLength, formatNumber, formatPercent } from '../src/format';

describe('statistics formatting', () => {
  it('lengths', () => {
    expect(formatLength(3.456)).toBe('3.5 m');
    expect(formatLength(383.1)).toBe('383 m');
    expect(formatLength(3424)).toBe('3,424 m');
    expect(formatLength(12_345)).toBe('12.3 km');
    expect(formatLength(null)).toBe('–');
    expect(formatLength(Number.NaN)).toBe('–');
  });
  it('durations', () => {
    expect(formatDuration(44.6)).toBe('45 s');
    expect(formatDuration(154.18)).toBe('2 min 34 s');
    expect(formatDuration(65)).toBe('1 min 05 s');
    expect(formatDuration(3725)).toBe('1 h 02 min');
  });
  it('areas, percentages, numbers, degrees', () => {
    expect(formatArea(532)).toBe('532 m²');
    expect(formatArea(53_224)).toBe('5.32 ha');
    expect(formatPercent(0.99999997)).toBe('100.0 %');
    expect(formatPercent(0.6190)).toBe('61.9 %');
    expect(formatNumber(1.6447, 2, 'cm/px')).toBe('1.64 cm/px');
    expect(formatNumber(192)).toBe('192');
    expect(formatDegrees(9.6219)).toBe('9.6°');
  });
});
