// Small DOM helpers shared by the panels.

/** The element with this id; throws early when the page and the code disagree. */
export function byId<T extends HTMLElement = HTMLElement>(id: string): T {
  const el = document.getElementById(id);
  if (!el) throw new Error(`missing element #${id}`);
  return el as T;
}

/** A number field's value; NaN when it is empty (not 0, which `Number('')` gives) or not a number. */
export function numberValue(id: string): number {
  const text = byId<HTMLInputElement>(id).value.trim();
  return text === '' ? NaN : Number(text);
}

/** Puts a value into an input or select. */
export function setValue(id: string, value: string | number): void {
  byId<HTMLInputElement | HTMLSelectElement>(id).value = String(value);
}

/**
 * Creates an element with text and attributes. Strings are text, never
 * markup. No `style` attribute: the server's Content-Security-Policy refuses
 * inline style attributes (set styles through `el.style`, as `swatch` does).
 */
export function h<K extends keyof HTMLElementTagNameMap>(
  tag: K,
  attrs: Record<string, string> = {},
  ...children: (Node | string)[]
): HTMLElementTagNameMap[K] {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'style') throw new Error(`h(${tag}): a style attribute is refused by the page's CSP; set el.style instead`);
    el.setAttribute(k, v);
  }
  el.append(...children);
  return el;
}

/** A small square of a colour (the UAV colours in lists and legends). */
export function swatch(colour: string, className = 'swatch'): HTMLSpanElement {
  const el = h('span', { class: className });
  el.style.background = colour;
  return el;
}

/** "lon, lat" text from a point, 6 decimals (≈ 0.1 m). */
export function formatLonLat(p: [number, number]): string {
  return `${p[0].toFixed(6)}, ${p[1].toFixed(6)}`;
}

/** Parses "lon, lat" (comma or space separated); null when it is not two numbers. */
export function parseLonLat(text: string): [number, number] | null {
  const parts = text.trim().split(/[\s,;]+/).filter(Boolean).map(Number);
  if (parts.length !== 2 || !parts.every(Number.isFinite)) return null;
  return [parts[0], parts[1]];
}
