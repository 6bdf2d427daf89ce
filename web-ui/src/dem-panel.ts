// The terrain-model section: choose an uploaded DEM or upload one (with
// upload progress); the chosen DEM's hillshade becomes the map's base layer.

import { api, uploadDem, type Dem } from './api';
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
    this.select.replaceChildren(h('option', { value: '' }, 'None (flat, no terrain)'));
    for (const d of this.dems) this.select.append(h('option', { value: d.id }, demLabel(d)));
    this.select.value = this.dems.some((d) => d.id === current) ? current : '';
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
    let dem = this.dems.find((d) => d.id === id);
    if (!dem) {
      try {
        dem = await api.getDem(id);
      } catch (err) {
        this.errors.showError(err);
        return;
      }
      this.dems.unshift(dem);
      this.select.prepend(h('option', { value: dem.id }, demLabel(dem)));
    }
    this.select.value = id;
    const placement = placeRaster(dem);
    this.map.setHillshade(dem.hillshade, placement);
    if (fit) this.map.fitLonLat(dem.bounds_wgs84);
    this.status.textContent =
      `${dem.width} × ${dem.height} cells, ${formatNumber(dem.resolution[0], 2)} ${dem.crs.geographic ? '°' : 'm'}, ` +
      `${dem.crs.name}; heights ${formatNumber(dem.min, 1)}–${formatNumber(dem.max, 1)} m` +
      (placement.exact ? '' : ' (placed approximately: its CRS is not one the page knows)');
    this.selection.set(dem);
  }

  private async upload(): Promise<void> {
    const file = this.file.files?.[0];
    if (!file) return;
    this.errors.clear();
    this.progress.hidden = false;
    this.progress.value = 0;
    this.status.textContent = `Uploading ${file.name}…`;
    try {
      const dem = await uploadDem(file, file.name.replace(/\.[^.]+$/, ''), (f) => {
        this.progress.value = f;
        this.status.textContent = f < 1 ? `Uploading ${file.name}: ${Math.round(f * 100)} %` : `Reading ${file.name}…`;
      });
      this.dems.unshift(dem);
      this.select.prepend(h('option', { value: dem.id }, demLabel(dem)));
      await this.choose(dem.id);
    } catch (err) {
      this.status.textContent = '';
      this.errors.showError(err);
    } finally {
      this.progress.hidden = true;
      this.file.value = '';
    }
  }
}

function demLabel(d: Dem): string {
  return `${d.name ?? d.file_name ?? d.id.slice(0, 8)} (${d.width}×${d.height})`;
}
