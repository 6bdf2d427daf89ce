// The ground-route panel: build (or choose) a costmap of the current DEM for
// a vehicle, follow its progress, show it as an overlay; pick start and goal,
// plan the route; block areas and replan from the rover's position.

import { api, followCostmap, type Costmap, type Dem, type LonLat, type Route, type Vehicle } from './api';
import { byId, formatLonLat, h, parseLonLat } from './dom';
import { ErrorSlots } from './errors-ui';
import { formatDate, formatDegrees, formatDuration, formatLength, formatNumber } from './format';
import type { PolygonRings } from './geo-import';
import type { MapMode, MapView } from './map';
import { COSTMAP_FIELDS, ROUTE_FIELDS } from './problems';
import { costmapNeedsDem, placeCostmap } from './projection';
import { areaRings, blockedStatus, costlierOfRoute, costlierStatus, costRangeWords, parseCost, replanBody, type CostlierArea } from './route-changes';
import type { DemSelection } from './state';

export class RoutePanel {
  private readonly root = byId('route-panel');
  private readonly costmapErrors = new ErrorSlots(this.root, 'costmap', COSTMAP_FIELDS);
  private readonly routeErrors = new ErrorSlots(this.root, 'route', ROUTE_FIELDS);
  private vehicles: Vehicle[] = [];
  private costmap: Costmap | null = null;
  private route: Route | null = null;
  /** Areas drawn since the route was shown: what the next replan sends. */
  private blocked: PolygonRings[] = [];
  private costlier: CostlierArea[] = [];
  /** The cost of the costlier area being drawn (checked when its drawing starts). */
  private drawingCost = 0;
  /** Set while the panel itself switches the DEM, so the costmap is kept. */
  private switchingDem = false;

  constructor(
    private readonly map: MapView,
    private readonly dem: DemSelection,
    private readonly chooseDem: (id: string, fit: boolean) => Promise<void>,
  ) {
    byId('build-costmap').addEventListener('click', () => void this.buildCostmap());
    byId<HTMLSelectElement>('costmap-select').addEventListener('change', (e) => {
      const id = (e.target as HTMLSelectElement).value;
      if (id) void this.openCostmap(id);
      else this.setCostmap(null);
    });
    byId<HTMLSelectElement>('vehicle').addEventListener('change', () => this.showVehicleNumbers());
    byId<HTMLInputElement>('costmap-opacity').addEventListener('input', (e) => this.map.setCostmapOpacity(Number((e.target as HTMLInputElement).value)));
    byId('pick-start').addEventListener('click', () => this.map.setMode('pick-start'));
    byId('pick-goal').addEventListener('click', () => this.map.setMode('pick-goal'));
    byId('pick-position').addEventListener('click', () => this.map.setMode('pick-position'));
    for (const id of ['route-start', 'route-goal', 'route-position']) byId(id).addEventListener('change', () => this.showPoints());
    // Enter in a typed end plans, as in a form.
    for (const id of ['route-start', 'route-goal', 'route-speed']) {
      byId(id).addEventListener('keydown', (e) => {
        if ((e as KeyboardEvent).key === 'Enter') void this.planRoute();
      });
    }
    byId('plan-route').addEventListener('click', () => void this.planRoute());
    byId('draw-block').addEventListener('click', () => this.map.setMode('draw-block'));
    byId('clear-block').addEventListener('click', () => {
      this.map.setBlocked([]);
      this.blockedChanged([]);
    });
    byId('draw-costlier').addEventListener('click', () => this.drawCostlier());
    byId('clear-costlier').addEventListener('click', () => this.setCostlier([]));
    byId('replan-route').addEventListener('click', () => void this.replan());
    dem.onChange((d) => {
      if (!this.switchingDem) void this.demChanged(d);
    });
  }

  async loadVehicles(): Promise<void> {
    try {
      this.vehicles = (await api.listVehicles()).items;
    } catch (err) {
      this.costmapErrors.showError(err);
      return;
    }
    byId('vehicle').replaceChildren(...this.vehicles.map((v) => h('option', { value: v.name }, v.name)));
    this.showVehicleNumbers();
  }

  /** The preset's numbers as placeholders: a blank field keeps the preset's value. */
  private showVehicleNumbers(): void {
    const v = this.vehicles.find((x) => x.name === byId<HTMLSelectElement>('vehicle').value);
    if (!v) return;
    byId<HTMLInputElement>('max-slope').placeholder = String(v.max_slope_deg);
    byId<HTMLInputElement>('max-step').placeholder = String(v.max_step_m);
    byId('vehicle-numbers').textContent = vehicleSummary(v);
  }

  private async demChanged(dem: Dem | null): Promise<void> {
    this.clearEnds();
    this.setCostmap(null);
    await this.listCostmaps(dem);
  }

  /** Forgets the start, goal and rover position: they belong to the terrain shown before. */
  private clearEnds(): void {
    for (const id of ['route-start', 'route-goal', 'route-position']) byId<HTMLInputElement>(id).value = '';
    this.showPoints();
  }

  /** Lists the costmaps again (another project was chosen). */
  refreshCostmaps(): Promise<void> {
    return this.listCostmaps(this.dem.current);
  }

  /** Fills the costmap chooser with the finished costmaps of this DEM. */
  private async listCostmaps(dem: Dem | null): Promise<void> {
    const select = byId<HTMLSelectElement>('costmap-select');
    select.replaceChildren(h('option', { value: '' }, '(build a new one)'));
    if (!dem) return;
    try {
      const items = (await api.listCostmaps()).items.filter((c) => c.dem_id === dem.id && c.status === 'done');
      for (const c of items) select.append(h('option', { value: c.id }, `${c.name ?? c.vehicle.name}, ${formatDate(c.created_at)}`));
      if (this.costmap) select.value = this.costmap.id;
    } catch {
      /* the chooser stays empty; building still works */
    }
  }

  private async buildCostmap(): Promise<void> {
    this.costmapErrors.clear();
    const dem = this.dem.current;
    if (!dem) {
      this.costmapErrors.show('dem', 'Terrain model: choose or upload a DEM first (above); the costmap is built from it.');
      return;
    }
    const vehicle: Record<string, unknown> = { preset: byId<HTMLSelectElement>('vehicle').value };
    const slope = byId<HTMLInputElement>('max-slope').value;
    const step = byId<HTMLInputElement>('max-step').value;
    if (slope !== '') vehicle.max_slope_deg = Number(slope);
    if (step !== '') vehicle.max_step_m = Number(step);
    const body: Record<string, unknown> = { dem_id: dem.id, vehicle };
    const resolution = byId<HTMLInputElement>('cm-resolution').value;
    if (resolution !== '') body.options = { resolution_m: Number(resolution) };

    const button = byId<HTMLButtonElement>('build-costmap');
    const progress = byId<HTMLProgressElement>('costmap-progress');
    const status = byId('costmap-status');
    button.disabled = true;
    try {
      const job = await api.createCostmap(body);
      progress.hidden = false;
      progress.value = 0;
      status.textContent = 'Queued…';
      const end = await followCostmap(job.urls.events, (e) => {
        progress.value = e.progress;
        status.textContent = `${e.status === 'queued' ? 'Queued' : 'Building'}${e.stage ? `: ${e.stage}` : ''} — ${Math.round(e.progress * 100)} %`;
      });
      if (end.status === 'failed') {
        status.textContent = '';
        this.costmapErrors.show('form', `The costmap failed: ${end.error ?? 'no reason given'}.`);
        return;
      }
      const done = await api.getCostmap(job.id);
      await this.setCostmap(done);
      status.textContent = `Costmap ready (${done.vehicle.name}, ${done.width}×${done.height} cells). Click the start, then the goal, on the map.`;
      await this.listCostmaps(dem);
      if (!parseLonLat(byId<HTMLInputElement>('route-start').value)) this.map.setMode('pick-start');
    } catch (err) {
      status.textContent = '';
      this.costmapErrors.showError(err);
    } finally {
      button.disabled = false;
      progress.hidden = true;
    }
  }

  /** Opens a saved costmap: selects its DEM and shows it (following it if it is still being built). */
  async openCostmap(id: string): Promise<void> {
    this.costmapErrors.clear();
    try {
      const cm = await api.getCostmap(id);
      if (this.dem.current?.id !== cm.dem_id) {
        this.clearEnds();
        this.switchingDem = true;
        try {
          await this.chooseDem(cm.dem_id, true);
        } finally {
          this.switchingDem = false;
        }
        await this.listCostmaps(this.dem.current);
      }
      if (cm.status === 'done') await this.setCostmap(cm);
      else byId('costmap-status').textContent = `This costmap is ${cm.status}${cm.error ? `: ${cm.error}` : ''}.`;
    } catch (err) {
      this.costmapErrors.showError(err);
    }
  }

  private async setCostmap(cm: Costmap | null): Promise<void> {
    this.costmap = cm;
    this.setRoute(null);
    byId('costmap-view').hidden = !cm;
    if (!cm) {
      this.map.setCostmapOverlay(null);
      byId<HTMLSelectElement>('costmap-select').value = '';
      byId('costmap-status').textContent = '';
      return;
    }
    // The costmap's own bounds place it; only costmaps of older servers need their DEM.
    const dem = !costmapNeedsDem(cm) ? null : this.dem.current?.id === cm.dem_id ? this.dem.current : await api.getDem(cm.dem_id);
    this.map.setCostmapOverlay(cm.urls.preview_png, placeCostmap(cm, dem) ?? undefined);
    this.map.setCostmapOpacity(Number(byId<HTMLInputElement>('costmap-opacity').value));
    byId<HTMLImageElement>('costmap-legend').src = cm.urls.legend_svg;
    byId('costmap-warnings').replaceChildren(...cm.warnings.map((w) => h('li', {}, w)));
    const select = byId<HTMLSelectElement>('costmap-select');
    if (![...select.options].some((o) => o.value === cm.id)) select.append(h('option', { value: cm.id }, cm.name ?? cm.vehicle.name));
    select.value = cm.id;
    byId('costmap-status').textContent = `Costmap for ${cm.vehicle.name} (${cm.width}×${cm.height} cells).`;
    byId('cost-hint').textContent = `Cells inside the area cost this instead (${costRangeWords(this.costRange())}); the route avoids it where a detour is cheaper.`;
  }

  /** The range of the shown costmap's traversable costs (null when it does not say). */
  private costRange(): [number, number] | null {
    const s = this.costmap?.stats;
    return s && s.cost_min != null && s.cost_max != null ? [s.cost_min, s.cost_max] : null;
  }

  // ---- map events ----

  picked(mode: MapMode, at: LonLat): void {
    const field = mode === 'pick-start' ? 'route-start' : mode === 'pick-goal' ? 'route-goal' : 'route-position';
    byId<HTMLInputElement>(field).value = formatLonLat(at);
    this.showPoints();
    // Start then goal: the natural order, so one click sequence does both.
    if (mode === 'pick-start' && !parseLonLat(byId<HTMLInputElement>('route-goal').value)) this.map.setMode('pick-goal');
    else this.map.setMode('browse');
  }

  blockedChanged(blocked: PolygonRings[]): void {
    this.blocked = blocked;
    byId('block-status').textContent = blockedStatus(blocked.length, this.route?.blocked.flatMap(areaRings).length ?? 0);
  }

  private drawCostlier(): void {
    this.routeErrors.clear();
    const parsed = parseCost(byId<HTMLInputElement>('cost-value').value, this.costRange());
    if ('error' in parsed) {
      this.routeErrors.show('cost', parsed.error);
      return;
    }
    this.drawingCost = parsed.cost;
    this.map.setMode('draw-costlier');
  }

  costlierDrawn(areas: PolygonRings[]): void {
    this.setCostlier([...this.costlier, ...areas.map((rings) => ({ rings, cost: this.drawingCost }))]);
  }

  private setCostlier(areas: CostlierArea[]): void {
    this.costlier = areas;
    this.map.setCostlier(areas);
    byId('costlier-status').textContent = costlierStatus(areas, costlierOfRoute(this.route?.cost_changes).length);
  }

  private showPoints(): void {
    const get = (id: string) => parseLonLat(byId<HTMLInputElement>(id).value);
    const start = get('route-start');
    const position = this.route ? get('route-position') : null;
    // The rover marker only where it differs from the start (it would hide it).
    const moved = position && (!start || Math.hypot(position[0] - start[0], position[1] - start[1]) > 1e-6);
    this.map.setGroundPoints({ start, goal: get('route-goal'), position: moved ? position : null });
  }

  // ---- routes ----

  private async planRoute(): Promise<void> {
    this.routeErrors.clear();
    if (!this.costmap) {
      this.routeErrors.show('form', 'Build or choose a costmap first.');
      return;
    }
    const start = parseLonLat(byId<HTMLInputElement>('route-start').value);
    const goal = parseLonLat(byId<HTMLInputElement>('route-goal').value);
    if (!start) this.routeErrors.show('start', 'Start: pick it on the map or type “lon, lat”.');
    if (!goal) this.routeErrors.show('goal', 'Goal: pick it on the map or type “lon, lat”.');
    if (!start || !goal) return;
    // A new route starts from the costmap as built: the areas of the shown route's replans do not come with it.
    const inherited = (this.route?.blocked.length ?? 0) + (this.route?.cost_changes?.length ?? 0);
    if (inherited > 0 && !window.confirm(`Plan a new route on the costmap as built? It does not keep the ${inherited} blocked or costlier area${inherited === 1 ? '' : 's'} of the replans; “Replan around the areas” keeps them.`)) return;
    // Both ends are set (typed, perhaps): the map stops waiting for a click that would move one.
    const mode = this.map.getMode();
    if (mode === 'pick-start' || mode === 'pick-goal') this.map.setMode('browse');
    const body: Record<string, unknown> = { start, goal };
    const speed = byId<HTMLInputElement>('route-speed').value;
    if (speed !== '') body.speed_m_s = Number(speed);
    let planned: Route | null = null;
    await this.busy('Planning…', async () => {
      planned = await api.createRoute(this.costmap!.id, body);
      this.setRoute(planned);
    });
    // Both ends in one cell: a "route" of one point, which is worth saying.
    if (planned && (planned as Route).waypoints.length < 2) byId('route-busy').textContent = 'Start and goal are in the same cell: there is nothing to drive.';
  }

  private async replan(): Promise<void> {
    this.routeErrors.clear();
    if (!this.route) return;
    const position = parseLonLat(byId<HTMLInputElement>('route-position').value);
    if (!position) {
      this.routeErrors.show('position', 'Rover position: pick it on the map or type “lon, lat”.');
      return;
    }
    const request = replanBody(position, this.blocked, this.costlier);
    if ('error' in request) {
      this.routeErrors.show('blocked', request.error);
      return;
    }
    const previous = this.route;
    await this.busy('Replanning…', async () => {
      this.setRoute(await api.replanRoute(previous.id, request.body), previous);
    });
  }

  private async busy(text: string, work: () => Promise<void>): Promise<void> {
    const status = byId('route-busy');
    const buttons = ['plan-route', 'replan-route'].map((id) => byId<HTMLButtonElement>(id));
    for (const b of buttons) b.disabled = true;
    status.textContent = text;
    try {
      await work();
      status.textContent = '';
    } catch (err) {
      status.textContent = '';
      this.routeErrors.showError(err);
    } finally {
      for (const b of buttons) b.disabled = false;
    }
  }

  /** Shows a route (and the one it replaced, dashed). */
  setRoute(route: Route | null, previous: Route | null = null): void {
    this.route = route;
    this.map.showGroundRoute(route, previous);
    // The route's own changes (of its earlier replans) are shown, not sent again; new ones start empty.
    this.map.setBlocked(route?.blocked.flatMap(areaRings) ?? [], true);
    this.map.setCostlier(costlierOfRoute(route?.cost_changes), true);
    this.map.setBlocked([]);
    this.blockedChanged([]);
    this.setCostlier([]);
    byId('route-result').hidden = !route;
    if (!route) {
      this.showPoints();
      return;
    }
    const first = route.waypoints[0];
    const last = route.waypoints[route.waypoints.length - 1];
    byId<HTMLInputElement>('route-start').value = formatLonLat([first.lon, first.lat]);
    byId<HTMLInputElement>('route-goal').value = formatLonLat([last.lon, last.lat]);
    byId<HTMLInputElement>('route-position').value = formatLonLat([first.lon, first.lat]);
    this.showPoints();

    const speed = route.speed_m_s ?? Number(byId<HTMLInputElement>('route-speed').value);
    const stats: [string, string][] = [
      ['Length (2D)', formatLength(route.length_2d_m)],
      ['Length (3D)', formatLength(route.length_3d_m)],
      ['Cost', formatNumber(route.cost, 1)],
      // Along the terrain when its heights are known (no DEM: the plain length).
      ['Time', speed > 0 ? `${formatDuration((route.length_3d_m ?? route.length_2d_m) / speed)} at ${formatNumber(speed, 1)} m/s` : '–'],
      ['Max slope', formatDegrees(route.max_slope_deg)],
      ['Mean slope', formatDegrees(route.mean_slope_deg)],
      ['Max grade', formatDegrees(route.max_grade_deg)],
      ['Climb / descent', `${formatNumber(route.climb_m, 1)} / ${formatNumber(route.descent_m, 1)} m`],
      ['Waypoints', formatNumber(route.waypoints.length)],
      ['Search', `${route.planner}${route.reused_search ? ' (repaired)' : ''}, ${formatNumber(route.search_ms, 0)} ms`],
    ];
    byId('route-stats').replaceChildren(...stats.flatMap(([k, v]) => [h('dt', {}, k), h('dd', {}, v)]));
    byId('route-downloads').replaceChildren(
      'Download: ',
      h('a', { href: route.urls.waypoints, download: '' }, 'rover mission (.waypoints)'),
      ' · ',
      h('a', { href: route.urls.csv, download: '' }, 'CSV'),
      ' · ',
      h('a', { href: route.urls.geojson, download: '' }, 'GeoJSON'),
    );
  }

  /** Takes a deleted costmap or route off the page if it is the one shown. */
  forget(kind: 'costmap' | 'route', id: string): void {
    if (kind === 'costmap' && this.costmap?.id === id) {
      void this.setCostmap(null);
      void this.listCostmaps(this.dem.current);
    } else if (kind === 'route' && this.route?.id === id) {
      this.setRoute(null);
    }
  }

  /** Opens a saved route with its costmap. */
  async openRoute(id: string): Promise<void> {
    this.routeErrors.clear();
    try {
      const route = await api.getRoute(id);
      if (this.costmap?.id !== route.costmap_id) await this.openCostmap(route.costmap_id);
      this.setRoute(route);
    } catch (err) {
      this.routeErrors.showError(err);
    }
  }
}

/** A vehicle preset's numbers in a sentence, under the chooser. */
export function vehicleSummary(v: Vehicle): string {
  return `${v.width_m} × ${v.length_m} m (width × length); climbs steps up to ${v.max_step_m} m and slopes up to ${v.max_slope_deg}°.`;
}
