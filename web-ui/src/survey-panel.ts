// The survey panel: area and no-fly zones, camera and flight settings, UAV
// take-off points, and the planned survey (totals, per-UAV table, altitude
// profile, downloads).

import { api, request, type CameraPreset, type LonLat, type Survey } from './api';
import { CorridorFields } from './corridor-fields';
import { djiLinks } from './dji-links';
import { PATTERN_DEFAULTS, readPatternFields, showPatternFields } from './pattern-fields';
import { AIRCRAFT_DEFAULTS, readAircraftFields, showAircraftFields } from './aircraft-fields';
import { byId, formatLonLat, h, numberValue, parseLonLat, setValue, swatch } from './dom';
import { ErrorSlots } from './errors-ui';
import { formatArea, formatDegrees, formatDuration, formatLength, formatNumber, formatPercent } from './format';
import { ImportError, parsePolygons, ringCrossesItself, utmArea, type PolygonRings } from './geo-import';
import type { MapView } from './map';
import { SURVEY_FIELDS } from './problems';
import { VehicleUpload } from './vehicle-upload';
import { cellOverlaps, footprints, lowOverlapCells, requestedOverlaps, shortfallText, uavPhotosUrl } from './photos';
import { renderProfileChart, sortieProfile } from './profile-chart';
import type { DemSelection } from './state';
import {
  buildSurveyRequest,
  cameraSummary,
  describeExtra,
  describeFlightGeometry,
  flightGeometry,
  formFromRequest,
  nextUavId,
  uavColour,
  type CustomCamera,
  type SurveyFormValues,
  type UavStart,
} from './survey-form';

export class SurveyPanel {
  private readonly root = byId('survey-panel');
  private readonly errors = new ErrorSlots(this.root, 'survey', SURVEY_FIELDS);
  private roi: PolygonRings | null = null;
  private readonly corridor: CorridorFields;
  private noFlyZones: PolygonRings[] = [];
  private uavs: UavStart[] = [];
  private rally: LonLat[] = [];
  private survey: Survey | null = null;
  private cameras: CameraPreset[] = [];
  /** The preset chosen last: "custom" starts from its numbers. */
  private lastPreset: CameraPreset | null = null;
  /** Request members of a reopened survey the form has no control for. */
  private extra: Record<string, unknown> = {};
  /** "Send to vehicle" buttons (vehicle-upload.ts). */
  private readonly vehicles = new VehicleUpload();

  constructor(
    private readonly map: MapView,
    private readonly dem: DemSelection,
    private readonly chooseDem: (id: string, fit: boolean) => Promise<void>,
  ) {
    byId<HTMLSelectElement>('camera').addEventListener('change', () => this.cameraChanged());

    for (const mode of ['altitude', 'gsd'] as const) {
      byId(`height-mode-${mode}`).addEventListener('change', () => this.setHeightMode(mode));
    }
    byId('drop-extra').addEventListener('click', () => {
      this.extra = {};
      byId('survey-extra').hidden = true;
      byId('survey-reopened').hidden = !byId('survey-reopened-text').textContent;
    });

    byId('draw-roi').addEventListener('click', () => this.map.setMode('draw-roi'));
    byId('draw-nfz').addEventListener('click', () => this.map.setMode('draw-nfz'));
    byId('clear-roi').addEventListener('click', () => this.map.setRoi(null));
    byId('clear-nfz').addEventListener('click', () => this.map.clearNoFlyZones());
    byId<HTMLInputElement>('import-roi').addEventListener('change', (e) => void this.importFile(e.target as HTMLInputElement, 'roi'));
    byId<HTMLInputElement>('import-nfz').addEventListener('change', (e) => void this.importFile(e.target as HTMLInputElement, 'nfz'));
    byId('draw-corridor').addEventListener('click', () => this.map.setMode('draw-line'));
    this.corridor = new CorridorFields(
      (line, fit) => {
        this.map.setCorridorLine(line);
        if (line && fit) this.map.fitLonLat(extentOf([line]));
      },
      () => this.markStale(),
      (text) => this.errors.show('corridor', text),
    );

    // Any edit of the form: the flight geometry follows the numbers as they are typed, and the
    // results of an earlier plan must not pass for the current settings.
    for (const type of ['input', 'change']) {
      byId('survey-form').addEventListener(type, () => {
        this.showFlightGeometry();
        this.markStale();
      });
    }
    this.dem.onChange(() => this.markStale());

    byId('place-uavs').addEventListener('click', () => this.map.setMode(this.map.getMode() === 'place-uav' ? 'browse' : 'place-uav'));
    byId('clear-uavs').addEventListener('click', () => this.setUavs([]));
    // Take-off points typed rather than clicked (keyboard use, known launch sites).
    byId('add-uav').addEventListener('click', () => this.addTypedUav());
    byId('uav-add').addEventListener('keydown', (e) => {
      if ((e as KeyboardEvent).key === 'Enter') {
        e.preventDefault(); // not the survey form's submit
        this.addTypedUav();
      }
    });
    // Rally points: clicked or typed, like take-off points.
    byId('place-rally').addEventListener('click', () => this.map.setMode(this.map.getMode() === 'place-rally' ? 'browse' : 'place-rally'));
    byId('clear-rally').addEventListener('click', () => this.setRally([]));
    byId('add-rally').addEventListener('click', () => this.addTypedRally());
    byId('rally-add').addEventListener('keydown', (e) => {
      if ((e as KeyboardEvent).key === 'Enter') {
        e.preventDefault();
        this.addTypedRally();
      }
    });
    byId<HTMLFormElement>('survey-form').addEventListener('submit', (e) => {
      e.preventDefault();
      void this.plan();
    });
    // Choosing what to chart also brings that route forward on the map.
    byId<HTMLSelectElement>('profile-uav').addEventListener('change', () => this.selectUav(byId<HTMLSelectElement>('profile-uav').value));
    byId<HTMLSelectElement>('profile-sortie').addEventListener('change', () => {
      this.renderProfile();
      this.highlight();
    });
  }

  /** Fills the camera chooser from the API's presets (the default first); their numbers show below it. */
  async loadCameras(): Promise<void> {
    try {
      this.cameras = (await api.listCameras()).items;
    } catch (err) {
      this.errors.showError(err);
    }
    const select = byId<HTMLSelectElement>('camera');
    select.replaceChildren(
      ...this.cameras.map((c) => h('option', { value: c.name }, c.name)),
      h('option', { value: 'custom' }, 'Custom camera…'),
    );
    this.cameraChanged();
  }

  /** Shows the chosen preset's numbers; "custom" starts from the preset chosen before. */
  private cameraChanged(): void {
    const value = byId<HTMLSelectElement>('camera').value;
    const custom = value === 'custom';
    byId('custom-camera').hidden = !custom;
    const preset = this.cameras.find((c) => c.name === value) ?? null;
    if (preset) this.lastPreset = preset;
    else if (custom && this.lastPreset) this.setCustomCamera(this.lastPreset.camera);
    byId('camera-numbers').textContent = preset ? cameraSummary(preset.camera) : '';
    this.showFlightGeometry();
  }

  /** GSD (or altitude), photo footprint, lane spacing and photo interval of the form's numbers, before planning. */
  private showFlightGeometry(): void {
    const v = this.formValues();
    const camera = v.camera === 'custom' ? v.customCamera : this.cameras.find((c) => c.name === v.camera)?.camera;
    const height = v.heightMode === 'gsd' ? { mode: 'gsd' as const, gsdCmPx: v.gsdCmPx } : { mode: 'altitude' as const, altitudeM: v.altitudeM };
    const g = camera ? flightGeometry(camera, height, v.sideOverlapPct, v.frontOverlapPct, v.speedMS) : null;
    byId('flight-geometry').textContent = g ? describeFlightGeometry(g, v.heightMode) : '';
  }

  private setCustomCamera(c: CustomCamera): void {
    setValue('cam-sw', c.sensor_width_mm);
    setValue('cam-sh', c.sensor_height_mm);
    setValue('cam-f', c.focal_length_mm);
    setValue('cam-iw', c.image_width_px);
    setValue('cam-ih', c.image_height_px);
    setValue('cam-orient', c.orientation);
  }

  private setHeightMode(mode: 'altitude' | 'gsd'): void {
    byId<HTMLInputElement>(`height-mode-${mode}`).checked = true;
    byId<HTMLInputElement>('altitude').disabled = mode !== 'altitude';
    byId<HTMLInputElement>('gsd').disabled = mode !== 'gsd';
    this.showFlightGeometry();
  }

  // ---- map events ----

  /** Says over the shown plan that the form has changed since (until the next plan). */
  private markStale(): void {
    if (this.survey && !this.restoring) byId('survey-stale').hidden = false;
  }

  /** True while a saved survey's values are being put back into the form (not a change by the user). */
  private restoring = false;

  /** A corridor's centre line drawn on the map. */
  lineDrawn(line: LonLat[]): void {
    this.errors.clear();
    this.corridor.drawn(line);
  }

  areasChanged(roi: PolygonRings | null, nfz: PolygonRings[]): void {
    this.roi = roi;
    this.noFlyZones = nfz;
    this.markStale();
    byId('roi-status').textContent = roi
      ? `Area: ${areaText(roi)}, ${roi[0].length - 1} corners${roi.length > 1 ? `, ${roi.length - 1} hole${roi.length > 2 ? 's' : ''}` : ''}.`
      : 'No area yet.';
    // A file of building footprints can bring many zones: one button takes them all away.
    byId('clear-nfz').hidden = nfz.length < 2;
    const list = byId('nfz-list');
    list.replaceChildren(
      ...nfz.map((z, i) => {
        const remove = h('button', { type: 'button', 'aria-label': `Remove no-fly zone ${i + 1}` }, 'Remove');
        remove.addEventListener('click', () => this.map.removeNoFlyZone(i));
        return h('li', {}, `No-fly zone ${i + 1} (${areaText(z)}, ${z[0].length - 1} corners) `, remove);
      }),
    );
  }

  private addTypedUav(): void {
    const input = byId<HTMLInputElement>('uav-add');
    const at = parseLonLat(input.value);
    if (!at) {
      this.errors.show('uavs', 'Take-off point: give it as “lon, lat” in degrees, e.g. -77.0551, 38.8089.', 'uav-add');
      return;
    }
    input.value = '';
    input.removeAttribute('aria-invalid');
    this.placeUav(at);
  }

  placeUav(at: [number, number]): void {
    this.setUavs([...this.uavs, { id: nextUavId(this.uavs), start: at }]);
  }

  modeChanged(mode: string): void {
    const place = byId('place-uavs');
    place.setAttribute('aria-pressed', String(mode === 'place-uav'));
    place.textContent = mode === 'place-uav' ? 'Done placing' : 'Place take-off points';
    const rally = byId('place-rally');
    rally.setAttribute('aria-pressed', String(mode === 'place-rally'));
    rally.textContent = mode === 'place-rally' ? 'Done placing' : 'Place rally points';
  }

  private addTypedRally(): void {
    const input = byId<HTMLInputElement>('rally-add');
    const at = parseLonLat(input.value);
    if (!at) {
      this.errors.show('rally', 'Rally point: give it as “lon, lat” in degrees, e.g. -77.0551, 38.8089.', 'rally-add');
      return;
    }
    input.value = '';
    input.removeAttribute('aria-invalid');
    this.placeRally(at);
  }

  placeRally(at: LonLat): void {
    this.setRally([...this.rally, at]);
  }

  private setRally(points: LonLat[]): void {
    this.rally = points;
    this.markStale();
    this.map.setRallyPoints(points);
    const list = byId('rally-list');
    list.replaceChildren(
      ...points.map((p, i) => {
        const input = h('input', { type: 'text', id: `rally-point-${i}`, value: formatLonLat(p), 'aria-describedby': 'survey-rally-error' });
        input.addEventListener('change', () => {
          const q = parseLonLat(input.value);
          if (q) this.setRally(this.rally.map((x, j) => (j === i ? q : x)));
          else this.errors.show('rally', badRally(i), input.id);
        });
        const remove = h('button', { type: 'button', 'aria-label': `Remove rally point R${i + 1}` }, 'Remove');
        remove.addEventListener('click', () => this.setRally(this.rally.filter((_, j) => j !== i)));
        return h('li', {}, h('label', { for: input.id }, `R${i + 1}`), input, remove);
      }),
    );
  }

  private setUavs(uavs: UavStart[]): void {
    this.uavs = uavs;
    this.markStale();
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
          else this.errors.show('uavs', badStart(u.id), input.id);
        });
        const remove = h('button', { type: 'button', 'aria-label': `Remove ${u.id}` }, 'Remove');
        remove.addEventListener('click', () => this.setUavs(this.uavs.filter((_, j) => j !== i)));
        return h('li', {}, swatch(uavColour(i)), h('label', { for: input.id }, `${u.id} start`), input, remove);
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
      corridor: this.corridor.values(),
      patterns: readPatternFields(),
      aircraft: readAircraftFields(),
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
      nfzClearanceM: numberValue('nfz-clearance'),
      altitudeFrame: val('altitude-frame') as SurveyFormValues['altitudeFrame'],
      assignment: val('assignment') as SurveyFormValues['assignment'],
      batteryMin: numberValue('battery'),
      uavs: this.uavs,
      rallyPoints: this.rally,
      extra: this.extra,
    };
  }

  private async plan(): Promise<void> {
    this.errors.clear();
    const { body, errors } = buildSurveyRequest(this.formValues());
    for (const e of errors) this.errors.show(e.field, e.text, e.control);
    // A take-off point typed wrong is not planned from where it was before.
    const badStarts = this.uavs.map((u, i) => ({ id: u.id, input: `uav-start-${i}` })).filter((b) => !parseLonLat(byId<HTMLInputElement>(b.input).value));
    for (const b of badStarts) this.errors.show('uavs', badStart(b.id), b.input);
    const badRallies = this.rally.map((_, i) => i).filter((i) => !parseLonLat(byId<HTMLInputElement>(`rally-point-${i}`).value));
    for (const i of badRallies) this.errors.show('rally', badRally(i), `rally-point-${i}`);
    if (!body || badStarts.length > 0 || badRallies.length > 0) return;
    const button = byId<HTMLButtonElement>('plan-survey');
    button.disabled = true;
    byId('survey-busy').textContent = 'Planning…';
    try {
      this.show(await api.createSurvey(body));
      byId('survey-busy').textContent = 'Planned.';
      // A new survey now: the "reopened" note is stale; the kept settings stay (and stay said).
      byId('survey-reopened-text').textContent = '';
      byId('survey-reopened').hidden = byId('survey-extra').hidden;
      byId('survey-results').scrollIntoView({ block: 'start' });
    } catch (err) {
      byId('survey-busy').textContent = '';
      this.errors.showError(err);
    } finally {
      button.disabled = false;
    }
  }

  /**
   * Reopens a saved survey: its area, no-fly zones, form values and UAV
   * take-off points come back (editable, to plan again), with its results.
   */
  async open(survey: Survey): Promise<void> {
    this.errors.clear();
    this.restoring = true;
    try {
      await this.restore(survey);
    } finally {
      this.restoring = false;
    }
    // From the top: the "reopened" note first (the panel may have been scrolled down a long list).
    byId('panel').scrollTop = 0;
  }

  private async restore(survey: Survey): Promise<void> {
    const notes: string[] = [];
    const request = survey.request;
    if (request) {
      const current = this.formValues();
      const restored = formFromRequest(request, survey.name, {
        camera: this.cameras[0]?.name ?? 'custom',
        customCamera: current.customCamera,
      });
      notes.push(...restored.notes);
      const v = restored.values;
      setValue('survey-name', v.name);
      this.map.clearNoFlyZones();
      this.map.addNoFlyZones(v.noFlyZones);
      this.map.setRoi(v.roi);
      this.corridor.restore(v.corridor ?? null);
      showPatternFields(v.patterns ?? PATTERN_DEFAULTS);
      showAircraftFields(v.aircraft ?? AIRCRAFT_DEFAULTS);

      const select = byId<HTMLSelectElement>('camera');
      if (v.camera !== 'custom' && ![...select.options].some((o) => o.value === v.camera)) {
        // A preset this server no longer lists: kept by name so the request is the same.
        select.prepend(h('option', { value: v.camera }, v.camera));
      }
      select.value = v.camera;
      if (v.camera === 'custom') this.setCustomCamera(v.customCamera);
      this.cameraChanged();

      this.setHeightMode(v.heightMode);
      setValue('altitude', v.altitudeM);
      setValue('gsd', v.gsdCmPx);
      setValue('front-overlap', v.frontOverlapPct);
      setValue('side-overlap', v.sideOverlapPct);
      setValue('slice-angle', v.sliceAngle);
      setValue('speed', v.speedMS);
      setValue('nfz-clearance', v.nfzClearanceM);
      setValue('altitude-frame', v.altitudeFrame);
      setValue('assignment', v.assignment);
      setValue('battery', Number.isFinite(v.batteryMin) ? v.batteryMin : '');
      byId<HTMLInputElement>('allow-partial-dem').checked = v.allowPartialDem;

      let follow = false;
      if (v.demId) {
        if (this.dem.current?.id !== v.demId) await this.chooseDem(v.demId, false);
        follow = this.dem.current?.id === v.demId;
        if (!follow) notes.push('Its terrain model (DEM) is no longer stored: choose one, or plan without terrain.');
      }
      byId<HTMLInputElement>('follow-terrain').checked = follow;

      this.setUavs(v.uavs);
      this.setRally(v.rallyPoints);
      this.extra = v.extra;
      this.showFlightGeometry();
    } else {
      // Surveys saved by older servers do not keep their request: only the take-off points come back.
      this.setUavs(survey.uavs.map((u) => ({ id: u.id, start: u.start })));
      this.setRally([]);
      this.extra = {};
      notes.push('This survey was saved without its settings: only its take-off points are restored.');
    }
    const label = survey.name ? `“${survey.name}”` : 'the survey';
    byId('survey-reopened-text').textContent = `Reopened ${label}: change the area or the settings and plan it again. ${notes.join(' ')}`.trim();
    byId('survey-reopened').hidden = false;
    const kept = describeExtra(this.extra);
    byId('survey-extra').hidden = !kept;
    byId('survey-extra-text').textContent = kept ? `Settings without a control here, kept from it: ${kept}.` : '';

    this.show(survey);
    const pts = [...(this.roi?.[0] ?? []), ...survey.uavs.map((u) => u.start), ...survey.fences.flatMap((f) => f.vertices)];
    if (pts.length) this.map.fitLonLat(extentOf([pts]));
  }

  /** Shows a planned survey (just planned, or reopened from the saved list). */
  show(survey: Survey): void {
    this.survey = survey;
    byId('survey-stale').hidden = true;
    const requested = requestedOverlaps(survey.request);
    const overlaps = cellOverlaps(survey, requested);
    const low = lowOverlapCells(overlaps);
    this.map.showSurvey(survey, uavColour, low);
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
      // What the planner chose or derived: the angle "auto" picked, the lane spacing and photo distance.
      ['Slice angle', formatDegrees(s.slice_angle_deg)],
      ['Lane spacing', formatNumber(s.line_spacing_m, 1, 'm')],
      ['Photo spacing', formatNumber(s.trigger_distance_m, 1, 'm')],
    ];
    // What the cells tile and the clearance kept, after the free area; surveys saved before
    // the clearance applied to lanes have neither, so they are shown only when given.
    const clearance: [string, string][] = [];
    if (s.flyable_area_m2 != null) clearance.push(['Flyable area', formatArea(s.flyable_area_m2)]);
    if (s.nfz_clearance_m != null) clearance.push(['NFZ clearance', formatNumber(s.nfz_clearance_m, 1, 'm')]);
    totals.splice(2, 0, ...clearance);
    // The overlaps the photos achieve on the ground (surveys planned before photos were have none).
    if (overlaps.length) totals.push(['Cells below the requested overlap', `${low.size} of ${overlaps.length}`]);
    byId('survey-totals').replaceChildren(...totals.flatMap(([k, v]) => [h('dt', {}, k), h('dd', {}, v)]));
    const shortfalls = overlaps
      .filter((c) => low.has(c.id))
      .map((c) => `Cell ${c.id}: achieved overlap ${shortfallText(c, requested)} (outlined red on the map).`);
    byId('survey-warnings').replaceChildren(...[...survey.warnings, ...shortfalls].map((w) => h('li', {}, w)));

    const rows = survey.uavs.map((u, i) =>
      h(
        'tr',
        { 'data-uav': u.id },
        h('th', { scope: 'row' }, swatch(uavColour(i)), this.uavButton(u.id)),
        h('td', {}, formatLength(u.stats.length_3d_m ?? u.stats.length_m)),
        h('td', {}, formatDuration(u.stats.flight_time_s)),
        h('td', {}, formatNumber(u.stats.photos)),
        h('td', {}, formatNumber(u.stats.turns)),
        h('td', { class: 'sorties-col' }, formatNumber(u.sorties.length)),
      ),
    );
    // The sorties column only when a battery made some UAV fly more than one.
    byId('uav-table').classList.toggle('with-sorties', survey.uavs.some((u) => u.sorties.length > 1));
    // Files per UAV and sortie (a UAV with a small battery flies several missions).
    const downloads = survey.uavs.flatMap((u, i) =>
      u.sorties.map((so) => {
        const tag = u.sorties.length > 1 ? ` (sortie ${so.number})` : '';
        // With several sorties each says how long it flies, to check against the battery.
        const shown = u.sorties.length > 1 ? ` (sortie ${so.number}, ${formatDuration(so.stats.flight_time_s)})` : '';
        return h(
          'li',
          { 'data-uav': u.id, 'data-sortie': String(so.number) },
          swatch(uavColour(i)),
          h('strong', {}, `${u.id}${shown}: `),
          link(so.files.waypoints, '.waypoints', `${u.id} mission waypoints${tag}`),
          link(so.files.plan, '.plan', `${u.id} QGroundControl plan${tag}`),
          link(so.files.route, 'GeoJSON', `${u.id} route GeoJSON${tag}`),
          link(so.files.kml, 'KML', `${u.id} route KML${tag}`),
          link(so.files.fence, 'fence', `${u.id} fence mission${tag}`),
          ...(so.files.rally ? [link(so.files.rally, 'rally', `${u.id} rally points${tag}`)] : []),
          ...(so.files.photos ? [link(so.files.photos, 'photos', `${u.id} photo footprints GeoJSON${tag}`)] : []),
          ...djiLinks(so.files, u.id, tag).map((d) => link(d.href, d.text, d.label)),
        );
      }),
    );
    byId('uav-downloads').replaceChildren(...downloads);
    // "Send to vehicle" per sortie, when the server allows vehicle links.
    void this.vehicles.attach(byId('uav-downloads'), survey);
    byId('uav-table').querySelector('tbody')!.replaceChildren(...rows);
    byId<HTMLAnchorElement>('cells-link').href = survey.files.cells;

    const select = byId<HTMLSelectElement>('profile-uav');
    select.replaceChildren(...survey.uavs.map((u) => h('option', { value: u.id }, u.id)));
    this.highlighted = false;
    this.highlight();
    this.renderProfile(true);
  }

  /** Whether the charted UAV's route is brought forward on the map (after the user chose one). */
  private highlighted = false;

  /** The UAV's name in the table: a button that charts its profile and brings its route forward (again: all alike). */
  private uavButton(id: string): HTMLButtonElement {
    const b = h('button', { type: 'button', class: 'link', 'aria-pressed': 'false', title: `Show ${id}'s route and profile` }, id);
    b.addEventListener('click', () => {
      if (this.highlighted && byId<HTMLSelectElement>('profile-uav').value === id) {
        this.highlighted = false;
        this.highlight();
      } else {
        this.selectUav(id);
      }
    });
    return b;
  }

  private selectUav(id: string): void {
    byId<HTMLSelectElement>('profile-uav').value = id;
    this.highlighted = true;
    this.renderProfile(true);
    this.highlight();
  }

  /** Brings the charted UAV (its charted sortie when it flies several) forward, or shows all alike. */
  private highlight(): void {
    const id = this.highlighted ? byId<HTMLSelectElement>('profile-uav').value : null;
    const multi = !byId('profile-sortie-field').hidden;
    this.map.highlightRoute(id, id && multi ? Number(byId<HTMLSelectElement>('profile-sortie').value) : null);
    void this.showFootprints(id);
    for (const b of byId('uav-table').querySelectorAll<HTMLButtonElement>('tbody button.link')) {
      b.setAttribute('aria-pressed', String(b.textContent === id));
    }
  }

  /** Draws the photo footprints of UAV `id` (none for null, or a survey without planned photos). */
  private async showFootprints(id: string | null): Promise<void> {
    const survey = this.survey;
    const url = survey && id ? uavPhotosUrl(survey, id) : null;
    if (!survey || !id || !url) {
      this.map.showFootprints([], '#000');
      return;
    }
    const index = survey.uavs.findIndex((u) => u.id === id);
    try {
      const doc = await request<unknown>('GET', url);
      // Another UAV or survey chosen meanwhile: not these.
      if (this.survey !== survey || byId<HTMLSelectElement>('profile-uav').value !== id || !this.highlighted) return;
      this.map.showFootprints(footprints(doc).map((f) => f.ring), uavColour(index));
    } catch {
      this.map.showFootprints([], '#000');
    }
  }

  /** Takes a deleted survey off the page if it is the one shown. */
  forget(id: string): void {
    if (this.survey?.id !== id) return;
    this.survey = null;
    this.map.showSurvey(null, uavColour);
    byId('survey-results').hidden = true;
  }

  /** Charts the chosen UAV's chosen sortie (`uavChanged`: the UAV changed, so its first sortie). */
  private renderProfile(uavChanged = false): void {
    const survey = this.survey;
    if (!survey) return;
    const id = byId<HTMLSelectElement>('profile-uav').value;
    const index = Math.max(0, survey.uavs.findIndex((u) => u.id === id));
    const uav = survey.uavs[index];
    if (!uav) return;
    const sortieSelect = byId<HTMLSelectElement>('profile-sortie');
    const p = sortieProfile(uav, uavChanged ? 0 : Number(sortieSelect.value));
    // The sortie chooser only for UAVs flying more than one.
    byId('profile-sortie-field').hidden = p.count < 2;
    if (uavChanged) {
      sortieSelect.replaceChildren(...uav.sorties.map((s, i) => h('option', { value: String(i) }, `Sortie ${s.number ?? i + 1} of ${p.count}`)));
    }
    sortieSelect.value = String(p.index);
    const number = uav.sorties[p.index]?.number ?? p.index + 1;
    renderProfileChart(byId('profile-chart'), p.points, {
      colour: uavColour(index),
      title: `Altitude profile of ${uav.id}${p.count > 1 ? ` (sortie ${number} of ${p.count})` : ''}`,
      altitudeLabel: p.overTerrain ? 'flown altitude (AMSL)' : `flown altitude (${survey.altitude_frame})`,
    });
  }
}

function badStart(id: string): string {
  return `${id} start: give it as “lon, lat” in degrees, e.g. -77.0551, 38.8089.`;
}

function badRally(index: number): string {
  return `Rally point R${index + 1}: give it as “lon, lat” in degrees, e.g. -77.0551, 38.8089.`;
}

function link(href: string, text: string, label: string): HTMLAnchorElement {
  return h('a', { href, download: '', 'aria-label': label }, text);
}

/** Area of lon/lat rings (holes subtracted), m², as the planner measures it: in the UTM zone of the area's centroid. */
/** A polygon's area as the page shows it, or why it has none. */
function areaText(rings: PolygonRings): string {
  return rings.some(ringCrossesItself) ? 'outline crosses itself' : formatArea(utmArea(rings));
}

function extentOf(rings: [number, number][][]): [number, number, number, number] {
  const pts = rings.flat();
  const lons = pts.map((p) => p[0]);
  const lats = pts.map((p) => p[1]);
  return [Math.min(...lons), Math.min(...lats), Math.max(...lons), Math.max(...lats)];
}
