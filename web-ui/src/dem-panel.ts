// The terrain-model section: choose an uploaded DEM or upload one (with
// upload progress); the chosen DEM's hillshade becomes the map's base layer.

import { api, ApiError, uploadDem, type Dem } from './api';
import { byId, h } from './dom';
import { ErrorSlots } from './errors-ui';
import { formatNumber } from './format';
import type { MapView } from './map';
import { placeRaster } from './projection';
import type { DemSelection } from './state';

export class DemPanel {
  private readonly select = byId<HTMLSelectElement>('dem-select');
  private readonly file = byId<HTMLInputElement>('dem-file');
  private readonly progress = byId<HTMLProgressElement>('dem-progress');
  private readonly status = byId('dem-status');
  private readonly errors = new ErrorSlots(document.body, 'dem', [], 'upload');
  private dems: Dem[] = [];

  constructor(
    private readonly map: MapView,
    private readonly selection: DemSelection,
  ) {
    this.select.addEventListener('change', () => void this.choose(this.select.value || null));
    this.file.addEventListener('change', () => void this.upload());
  }

  async refresh(): Promise<void> {
    try {
      this.dems = (await api.listDems()).items;
    } catch (err) {
      this.errors.show('upload', `The DEM list could not be loaded: ${(err as Error).message}`);
      return;
    }
    const current = this.select.value;
    // The DEM on the map stays choosable after another project is chosen (it is still the caller's to see).
    const shown = this.selection.current;
    if (shown && shown.id === current && !this.has(shown.id)) this.dems.unshift(shown);
    this.select.replaceChildren(h('option', { value: '' }, 'None (flat, no terrain)'));
    for (const d of this.dems) this.select.append(h('option', { value: d.id }, demLabel(d)));
    this.select.value = this.dems.some((d) => d.id === current) ? current : '';
  }

  /** Lists a new DEM first, after "None". */
  private addOption(dem: Dem): void {
    this.select.options[0].after(h('option', { value: dem.id }, demLabel(dem)));
  }

  /** Takes a deleted DEM out of the chooser. */
  private forget(id: string): void {
    this.dems = this.dems.filter((d) => d.id !== id);
    for (const o of [...this.select.options]) if (o.value === id) o.remove();
  }

  /** Whether the server listed this DEM (at the last refresh). */
  has(id: string): boolean {
    return this.dems.some((d) => d.id === id);
  }

  /** Makes a DEM the current one (null: none), showing its hillshade. */
  async choose(id: string | null, fit = true): Promise<void> {
    this.errors.clear();
    if (!id) {
      this.select.value = '';
      this.map.setHillshade(null);
      this.status.textContent = '';
      this.selection.set(null);
      return;
    }
    // Asked afresh: the list may be older than a deletion made elsewhere.
    let dem: Dem;
    try {
      dem = await api.getDem(id);
    } catch (err) {
      if (err instanceof ApiError && err.problem.status === 404) {
        this.forget(id);
        this.map.setHillshade(null);
        this.select.value = '';
        this.status.textContent = '';
        this.selection.set(null);
        this.errors.show('upload', 'This terrain model (DEM) has been deleted: what was made from it is shown without its hillshade and heights.');
      } else {
        this.errors.showError(err);
      }
      return;
    }
    if (!this.has(id)) {
      this.dems.unshift(dem);
      this.addOption(dem);
    }
    this.select.value = id;
    const placement = placeRaster(dem);
    this.map.setHillshade(dem.hillshade, placement);
    if (fit) this.map.fitLonLat(dem.bounds_wgs84);
    this.status.textContent = describeDem(dem, placement.exact);
    this.selection.set(dem);
  }

  private async upload(): Promise<void> {
    const file = this.file.files?.[0];
    if (!file) return;
    this.errors.clear();
    const crs = parseEpsg(byId<HTMLInputElement>('dem-crs').value);
    if (crs === undefined) {
      this.errors.show('crs', 'CRS of the file: give an EPSG code such as 32633 (or EPSG:32633), or leave it empty.');
      this.file.value = '';
      return;
    }
    this.progress.hidden = false;
    this.progress.value = 0;
    this.status.textContent = `Uploading ${file.name}…`;
    try {
      const dem = await uploadDem(file, file.name.replace(/\.[^.]+$/, ''), crs, (f) => {
        this.progress.value = f;
        this.status.textContent = f < 1 ? `Uploading ${file.name}: ${Math.round(f * 100)} %` : `Reading ${file.name}…`;
      });
      this.dems.unshift(dem);
      this.addOption(dem);
      // The CRS was for this file: the next one may give its own, which a leftover code would override.
      byId<HTMLInputElement>('dem-crs').value = '';
      await this.choose(dem.id);
    } catch (err) {
      // The DEM chosen before stays chosen: say so again.
      this.status.textContent = this.selection.current ? describeDem(this.selection.current, true) : '';
      if (err instanceof ApiError && /coordinate reference system cannot be determined/.test(err.problem.detail ?? '')) {
        this.errors.show('crs', `${file.name} does not say which coordinate system it is in. Give its EPSG code here and choose the file again.`);
      } else {
        this.errors.showError(err);
      }
    } finally {
      this.progress.hidden = true;
      this.file.value = '';
    }
  }
}

/** A DEM's size, cell size (in metres, and degrees for a geographic one), CRS and heights. */
export function describeDem(dem: Dem, exact: boolean): string {
  const [rx, ry] = dem.resolution_m ?? dem.resolution;
  const fmt = (x: number) => formatNumber(x, x < 10 ? 2 : 1);
  const metres = fmt(rx) === fmt(ry) ? `${fmt(rx)} m` : `${fmt(rx)} × ${fmt(ry)} m`;
  // Geographic cells are square in degrees, not on the ground: both, the degrees as arc seconds.
  const cells = dem.crs.geographic ? `${metres} (${formatNumber(dem.resolution[0] * 3600, 2)}″)` : metres;
  return (
    `${dem.width} × ${dem.height} cells of ${cells}, ${dem.crs.name}; heights ${formatNumber(dem.min, 1)}–${formatNumber(dem.max, 1)} m` +
    (exact ? '' : ' (placed approximately: its CRS is not one the page knows)')
  );
}

/** An EPSG code as the API takes it ("EPSG:32633"); null when empty, undefined when it is not one. */
export function parseEpsg(text: string): string | null | undefined {
  const t = text.trim();
  if (t === '') return null;
  const m = /^(?:EPSG:)?(\d{4,6})$/i.exec(t);
  return m ? `EPSG:${m[1]}` : undefined;
}

function demLabel(d: Dem): string {
  return `${d.name ?? d.file_name ?? d.id.slice(0, 8)} (${d.width}×${d.height})`;
}
