// The survey panel: area and no-fly zones, camera and flight settings, UAV
// take-off points, and the planned survey (totals, per-UAV table, altitude
// profile, downloads).

import { api, type Survey } from './api';
import { byId, formatLonLat, h, numberValue, parseLonLat } from './dom';
import { ErrorSlots } from './errors-ui';
import { formatArea, formatDuration, formatLength, formatNumber, formatPercent } from './format';
import { ImportError, parsePolygons, type PolygonRings } from './geo-import';
import type { MapView } from './map';
import { SURVEY_FIELDS } from './problems';
import { profileFromRoute, renderProfileChart } from './profile-chart';
import type { DemSelection } from './state';
import { buildSurveyRequest, CAMERA_PRESETS, nextUavId, uavColour, type SurveyFormValues, type UavStart } from './survey-form';

export class SurveyPanel {
  private readonly root = byId('survey-panel');
  private readonly errors = new ErrorSlots(this.root, 'survey', SURVEY_FIELDS);
  private roi: PolygonRings | null = null;
  private noFlyZones: PolygonRings[] = [];
  private uavs: UavStart[] = [];
  private survey: Survey | null = null;

  constructor(
    private readonly map: MapView,
    private readonly dem: DemSelection,
  ) {
    const camera = byId<HTMLSelectElement>('camera');
    for (const c of CAMERA_PRESETS) camera.append(h('option', { value: c.id }, c.label));
    camera.append(h('option', { value: 'custom' }, 'Custom camera…'));
    camera.addEventListener('change', () => (byId('custom-camera').hidden = camera.value !== 'custom'));

    for (const mode of ['altitude', 'gsd'] as const) {
      byId(`height-mode-${mode}`).addEventListener('change', () => {
        byId<HTMLInputElement>('altitude').disabled = mode !== 'altitude';
        byId<HTMLInputElement>('gsd').disabled = mode !== 'gsd';
      });
    }

    byId('draw-roi').addEventListener('click', () => this.map.setMode('draw-roi'));
    byId('draw-nfz').addEventListener('click', () => this.map.setMode('draw-nfz'));
    byId('clear-roi').addEventListener('click', () => this.map.setRoi(null));
    byId<HTMLInputElement>('import-roi').addEventListener('change', (e) => void this.importFile(e.target as HTMLInputElement, 'roi'));
    byId<HTMLInputElement>('import-nfz').addEventListener('change', (e) => void this.importFile(e.target as HTMLInputElement, 'nfz'));

    byId('place-uavs').addEventListener('click', () => this.map.setMode(this.map.getMode() === 'place-uav' ? 'browse' : 'place-uav'));
    byId('clear-uavs').addEventListener('click', () => this.setUavs([]));
    byId<HTMLFormElement>('survey-form').addEventListener('submit', (e) => {
      e.preventDefault();
      void this.plan();
    });
    byId<HTMLSelectElement>('profile-uav').addEventListener('change', () => this.renderProfile());
  }

  // ---- map events ----

  areasChanged(roi: PolygonRings | null, nfz: PolygonRings[]): void {
    this.roi = roi;
    this.noFlyZones = nfz;
    byId('roi-status').textContent = roi ? `Area drawn: ${roi[0].length - 1} corners${roi.length > 1 ? `, ${roi.length - 1} holes` : ''}.` : 'No area yet.';
    const list = byId('nfz-list');
    list.replaceChildren(
      ...nfz.map((z, i) => {
        const remove = h('button', { type: 'button', 'aria-label': `Remove no-fly zone ${i + 1}` }, 'Remove');
        remove.addEventListener('click', () => this.map.removeNoFlyZone(i));
        return h('li', {}, `No-fly zone ${i + 1} (${z[0].length - 1} corners) `, remove);
      }),
    );
  }

  placeUav(at: [number, number]): void {
    this.setUavs([...this.uavs, { id: nextUavId(this.uavs), start: at }]);
  }

  modeChanged(mode: string): void {
    const place = byId('place-uavs');
    place.setAttribute('aria-pressed', String(mode === 'place-uav'));
    place.textContent = mode === 'place-uav' ? 'Done placing' : 'Place take-off points';
  }

  private setUavs(uavs: UavStart[]): void {
    this.uavs = uavs;
    this.map.setUavStarts(uavs, uavColour);
    byId('uav-hint').hidden = uavs.length > 0;
    const list = byId('uav-list');
    list.replaceChildren(
      ...uavs.map((u, i) => {
        // Editable lon/lat so take-off points can be typed, not only clicked.
        const input = h('input', { type: 'text', id: `uav-start-${i}`, value: formatLonLat(u.start), 'aria-describedby': 'survey-uavs-error' });
        input.addEventListener('change', () => {
          const p = parseLonLat(input.value);
          if (p) this.setUavs(this.uavs.map((x, j) => (j === i ? { ...x, start: p } : x)));
          else input.setAttribute('aria-invalid', 'true');
        });
        const remove = h('button', { type: 'button', 'aria-label': `Remove ${u.id}` }, 'Remove');
        remove.addEventListener('click', () => this.setUavs(this.uavs.filter((_, j) => j !== i)));
        return h('li', {}, h('span', { class: 'swatch', style: `background:${uavColour(i)}` }), h('label', { for: input.id }, `${u.id} start`), input, remove);
      }),
    );
  }

  private async importFile(input: HTMLInputElement, kind: 'roi' | 'nfz'): Promise<void> {
    const file = input.files?.[0];
    input.value = '';
    if (!file) return;
    this.errors.clear();
    try {
      const polygons = parsePolygons(await file.text(), file.name);
      if (kind === 'roi') {
        this.map.setRoi(polygons[0]);
        if (polygons.length > 1) {
          this.errors.show('roi', `${file.name} holds ${polygons.length} polygons: the first is the survey area; import the file as no-fly zones for the others.`);
        }
        this.map.fitLonLat(extentOf(polygons[0]));
      } else {
        this.map.addNoFlyZones(polygons);
      }
    } catch (err) {
      const message = err instanceof ImportError ? err.message : `The file could not be read (${(err as Error).message}).`;
      this.errors.show(kind, `${file.name}: ${message}`);
    }
  }

  private formValues(): SurveyFormValues {
    const val = (id: string) => byId<HTMLInputElement | HTMLSelectElement>(id).value;
    const follow = byId<HTMLInputElement>('follow-terrain').checked;
    return {
      name: val('survey-name'),
      roi: this.roi,
      noFlyZones: this.noFlyZones,
      demId: follow ? (this.dem.current?.id ?? null) : null,
      allowPartialDem: byId<HTMLInputElement>('allow-partial-dem').checked,
      camera: val('camera'),
      customCamera: {
        sensor_width_mm: numberValue('cam-sw'),
        sensor_height_mm: numberValue('cam-sh'),
        focal_length_mm: numberValue('cam-f'),
        image_width_px: numberValue('cam-iw'),
        image_height_px: numberValue('cam-ih'),
        orientation: val('cam-orient') as 'landscape' | 'portrait',
      },
      heightMode: byId<HTMLInputElement>('height-mode-gsd').checked ? 'gsd' : 'altitude',
      altitudeM: numberValue('altitude'),
      gsdCmPx: numberValue('gsd'),
      frontOverlapPct: numberValue('front-overlap'),
      sideOverlapPct: numberValue('side-overlap'),
      sliceAngle: val('slice-angle'),
      speedMS: numberValue('speed'),
      altitudeFrame: val('altitude-frame') as SurveyFormValues['altitudeFrame'],
      assignment: val('assignment') as SurveyFormValues['assignment'],
      uavs: this.uavs,
    };
  }

  private async plan(): Promise<void> {
    this.errors.clear();
    const { body, errors } = buildSurveyRequest(this.formValues());
    for (const e of errors) this.errors.show(e.field, e.text);
    if (!body) return;
    const button = byId<HTMLButtonElement>('plan-survey');
    button.disabled = true;
    byId('survey-busy').textContent = 'Planning…';
    try {
      this.show(await api.createSurvey(body));
      byId('survey-busy').textContent = 'Planned.';
      byId('survey-results').scrollIntoView({ block: 'start' });
    } catch (err) {
      byId('survey-busy').textContent = '';
      this.errors.showError(err);
    } finally {
      button.disabled = false;
    }
  }

  /** Shows a planned survey (just planned, or reopened from the saved list). */
  show(survey: Survey, fit = false): void {
    this.survey = survey;
    this.map.showSurvey(survey, uavColour);
    if (fit) {
      const starts = survey.uavs.map((u) => u.start);
      this.map.setUavStarts(survey.uavs.map((u) => ({ id: u.id, start: u.start })), uavColour);
      const pts = [...starts, ...survey.fences.flatMap((f) => f.vertices)];
      if (pts.length) this.map.fitLonLat(extentOf([pts]));
    }
    byId('survey-results').hidden = false;
    byId('results-heading').textContent = `Plan${survey.name ? `: ${survey.name}` : ''}`;

    const s = survey.stats;
    const totals: [string, string][] = [
      ['Area', formatArea(s.area_m2)],
      ['Free area', formatArea(s.free_area_m2)],
      ['Altitude', formatNumber(s.altitude_m, 1, 'm')],
      ['GSD', formatNumber(s.gsd_cm_px, 2, 'cm/px')],
      ['Photos', formatNumber(s.photos)],
      ['Makespan', formatDuration(s.makespan_s ?? s.flight_time_s)],
      ['Coverage', formatPercent(s.coverage_ratio)],
      ['Cells', formatNumber(s.cell_count)],
    ];
    byId('survey-totals').replaceChildren(...totals.flatMap(([k, v]) => [h('dt', {}, k), h('dd', {}, v)]));
    byId('survey-warnings').replaceChildren(...survey.warnings.map((w) => h('li', {}, w)));

    const swatch = (i: number) => h('span', { class: 'swatch', style: `background:${uavColour(i)}` });
    const rows = survey.uavs.map((u, i) =>
      h(
        'tr',
        { 'data-uav': u.id },
        h('th', { scope: 'row' }, swatch(i), u.id),
        h('td', {}, formatLength(u.stats.length_3d_m ?? u.stats.length_m)),
        h('td', {}, formatDuration(u.stats.flight_time_s)),
        h('td', {}, formatNumber(u.stats.photos)),
        h('td', {}, formatNumber(u.stats.turns)),
      ),
    );
    // Files per UAV and sortie (a UAV with a small battery flies several missions).
    const downloads = survey.uavs.flatMap((u, i) =>
      u.sorties.map((so) => {
        const tag = u.sorties.length > 1 ? ` (sortie ${so.number})` : '';
        return h(
          'li',
          {},
          swatch(i),
          h('strong', {}, `${u.id}${tag}: `),
          link(so.files.waypoints, '.waypoints', `${u.id} mission waypoints${tag}`),
          link(so.files.plan, '.plan', `${u.id} QGroundControl plan${tag}`),
          link(so.files.route, 'GeoJSON', `${u.id} route GeoJSON${tag}`),
          link(so.files.kml, 'KML', `${u.id} route KML${tag}`),
          link(so.files.fence, 'fence', `${u.id} fence mission${tag}`),
        );
      }),
    );
    byId('uav-downloads').replaceChildren(...downloads);
    byId('uav-table').querySelector('tbody')!.replaceChildren(...rows);
    byId<HTMLAnchorElement>('cells-link').href = survey.files.cells;

    const select = byId<HTMLSelectElement>('profile-uav');
    select.replaceChildren(...survey.uavs.map((u) => h('option', { value: u.id }, u.id)));
    this.renderProfile();
  }

  /** Takes a deleted survey off the page if it is the one shown. */
  forget(id: string): void {
    if (this.survey?.id !== id) return;
    this.survey = null;
    this.map.showSurvey(null, uavColour);
    byId('survey-results').hidden = true;
  }

  private renderProfile(): void {
    const survey = this.survey;
    if (!survey) return;
    const id = byId<HTMLSelectElement>('profile-uav').value;
    const index = Math.max(0, survey.uavs.findIndex((u) => u.id === id));
    const uav = survey.uavs[index];
    if (!uav) return;
    // Profiles of several sorties are shown one after the other.
    const sortie = uav.sorties[0];
    const terrain = sortie?.terrain?.profile;
    const points = terrain && terrain.length > 1 ? terrain : profileFromRoute(sortie?.route.coordinates ?? []);
    renderProfileChart(byId('profile-chart'), points, {
      colour: uavColour(index),
      title: `Altitude profile of ${uav.id}${uav.sorties.length > 1 ? ' (sortie 1)' : ''}`,
      altitudeLabel: terrain ? 'flown altitude (AMSL)' : `flown altitude (${survey.altitude_frame})`,
    });
  }
}

function link(href: string, text: string, label: string): HTMLAnchorElement {
  return h('a', { href, download: '', 'aria-label': label }, text);
}

function extentOf(rings: [number, number][][]): [number, number, number, number] {
  const pts = rings.flat();
  const lons = pts.map((p) => p[0]);
  const lats = pts.map((p) => p[1]);
  return [Math.min(...lons), Math.min(...lats), Math.max(...lons), Math.max(...lats)];
}
