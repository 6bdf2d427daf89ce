// Number formatting for statistics tables: units people read at a glance.

const nf = (digits: number) =>
  new Intl.NumberFormat('en-GB', { maximumFractionDigits: digits, minimumFractionDigits: digits });

/** Metres below 10 km as "845 m" / "1 234 m", above as "12.3 km". */
export function formatLength(m: number | null | undefined): string {
  if (m == null || !Number.isFinite(m)) return '–';
  if (Math.abs(m) >= 10_000) return `${nf(1).format(m / 1000)} km`;
  if (Math.abs(m) < 10) return `${nf(1).format(m)} m`;
  return `${nf(0).format(m)} m`;
}

/** Seconds as "45 s", "3 min 05 s", "1 h 02 min". */
export function formatDuration(s: number | null | undefined): string {
  if (s == null || !Number.isFinite(s)) return '–';
  const total = Math.round(s);
  if (total < 60) return `${total} s`;
  const h = Math.floor(total / 3600);
  const min = Math.floor((total % 3600) / 60);
  const sec = total % 60;
  if (h > 0) return `${h} h ${String(min).padStart(2, '0')} min`;
  return `${min} min ${String(sec).padStart(2, '0')} s`;
}

/** Square metres as hectares ("5.32 ha"), or m² below 0.1 ha. */
export function formatArea(m2: number | null | undefined): string {
  if (m2 == null || !Number.isFinite(m2)) return '–';
  if (m2 < 1000) return `${nf(0).format(m2)} m²`;
  return `${nf(2).format(m2 / 10_000)} ha`;
}

/** A fraction in [0, 1] as a percentage with one decimal ("99.9 %"). */
export function formatPercent(f: number | null | undefined): string {
  if (f == null || !Number.isFinite(f)) return '–';
  return `${nf(1).format(f * 100)} %`;
}

export function formatNumber(x: number | null | undefined, digits = 0, unit = ''): string {
  if (x == null || !Number.isFinite(x)) return '–';
  return `${nf(digits).format(x)}${unit ? ` ${unit}` : ''}`;
}

/** Degrees with one decimal: "9.6°". */
export function formatDegrees(x: number | null | undefined): string {
  if (x == null || !Number.isFinite(x)) return '–';
  return `${nf(1).format(x)}°`;
}

/** A short local date-time for lists of saved work. */
export function formatDate(iso: string): string {
  const d = new Date(iso);
  if (Number.isNaN(d.getTime())) return iso;
  return d.toLocaleString('en-GB', { dateStyle: 'short', timeStyle: 'short' });
}
