// Entry point: builds the map and the panels and wires them together.

import 'ol/ol.css';
import './style.css';
import { api } from './api';
import type { Session } from './account-api';
import { DemPanel } from './dem-panel';
import { byId } from './dom';
import { DropImport } from './drop-import';
import { planExtent } from './drop-import-model';
import { MapView } from './map';
import { MembersDialog } from './members-dialog';
import { ProjectSwitcher } from './projects';
import { RoutePanel } from './route-panel';
import { SavedPanel } from './saved-panel';
import { SessionUi } from './session';
import { DemSelection } from './state';
import { SurveyPanel } from './survey-panel';

/**
 * The online tile layer is off by default (the page must work offline). The
 * checkbox turns it on and is remembered; `?tiles=URL-template` sets another
 * XYZ source (e.g. a local tile server).
 */
const OSM_TILES = 'https://tile.openstreetmap.org/{z}/{x}/{y}.png';
const params = new URLSearchParams(location.search);
const tileUrl = params.get('tiles') ?? localStorage.getItem('terraplan.tiles') ?? OSM_TILES;

const selection = new DemSelection();
let survey: SurveyPanel;
let route: RoutePanel;

const map = new MapView(byId('map'), byId('map-hint'), {
  areasChanged: (roi, nfz) => survey.areasChanged(roi, nfz),
  blockedChanged: (blocked) => route.blockedChanged(blocked),
  costlierDrawn: (areas) => route.costlierDrawn(areas),
  picked: (mode, at) => {
    if (mode === 'place-uav') survey.placeUav(at);
    else if (mode === 'place-rally') survey.placeRally(at);
    else route.picked(mode, at);
  },
  lineDrawn: (line) => survey.lineDrawn(line),
  modeChanged: (mode) => survey?.modeChanged(mode),
});

const dems = new DemPanel(map, selection);
survey = new SurveyPanel(map, selection, (id, fit) => dems.choose(id, fit));
route = new RoutePanel(map, selection, (id, fit) => dems.choose(id, fit));
const saved = new SavedPanel({
  openSurvey: async (id) => {
    const saved = await api.getSurvey(id);
    selectTab('survey');
    await survey.open(saved);
  },
  openCostmap: async (id) => {
    selectTab('route');
    await route.openCostmap(id);
  },
  openRoute: async (id) => {
    selectTab('route');
    await route.openRoute(id);
  },
  openDem: async (id) => {
    await dems.choose(id);
  },
  deleted: (kind, id) => {
    // Take what was deleted off the map too.
    if (kind === 'survey') survey.forget(id);
    else if (kind === 'costmap' || kind === 'route') route.forget(kind, id);
    else {
      if (selection.current?.id === id) void dems.choose(null);
      void dems.refresh();
    }
  },
});

// ---- GIS files dropped on the page or chosen: into the survey, as drawing them would ----
new DropImport({
  areas: () => map.getAreas(),
  corridorLine: () => map.getCorridorLine(),
  apply: (plan) => {
    selectTab('survey');
    if (plan.roi) map.setRoi(plan.roi);
    if (plan.noFlyZones.length) map.addNoFlyZones(plan.noFlyZones);
    if (plan.corridor) survey.lineDrawn(plan.corridor);
    const extent = planExtent(plan);
    if (extent) map.fitLonLat(extent);
  },
});

// ---- accounts: session, project switcher, members ----
/** The lists that depend on who is signed in and on the chosen project. */
async function refreshLists(): Promise<void> {
  await Promise.all([dems.refresh(), route.refreshCostmaps(), byId('saved-panel').hidden ? Promise.resolve() : saved.refresh()]);
}
const projects = new ProjectSwitcher(() => void refreshLists());
const members = new MembersDialog();
byId('members-open').addEventListener('click', () => {
  if (projects.current) void members.open(projects.current);
});
const session = new SessionUi({
  signedInAgain: (now: Session, before: Session | null) => {
    // The same user: the page goes on where it was. Someone else: their projects and work.
    if (before?.user.id !== now.user.id) void projects.load(now).then(refreshLists);
  },
});

// ---- tabs (WAI-ARIA tabs: arrow keys move between them) ----
const TABS = ['survey', 'route', 'saved'] as const;
type Tab = (typeof TABS)[number];

function selectTab(tab: Tab, focus = false): void {
  for (const t of TABS) {
    const button = byId(`tab-${t}`);
    const selected = t === tab;
    button.setAttribute('aria-selected', String(selected));
    button.tabIndex = selected ? 0 : -1;
    byId(`${t}-panel`).hidden = !selected;
    if (selected && focus) button.focus();
  }
  if (map.getMode() !== 'browse') map.setMode('browse');
  map.showTask(tab === 'saved' ? 'all' : tab);
  if (tab === 'saved') void saved.refresh();
}

for (const [i, t] of TABS.entries()) {
  const button = byId(`tab-${t}`);
  button.addEventListener('click', () => selectTab(t));
  button.addEventListener('keydown', (e) => {
    const step = e.key === 'ArrowRight' ? 1 : e.key === 'ArrowLeft' ? -1 : 0;
    if (step) selectTab(TABS[(i + step + TABS.length) % TABS.length], true);
  });
}

// ---- online base map ----
const online = byId<HTMLInputElement>('online-tiles');
online.checked = params.get('online') === '1' || (params.get('online') !== '0' && localStorage.getItem('terraplan.online') === '1');
const applyOnline = () => {
  map.setOnlineTiles(online.checked ? tileUrl : null);
  localStorage.setItem('terraplan.online', online.checked ? '1' : '0');
};
online.addEventListener('change', applyOnline);
if (online.checked) applyOnline();

// First complete drawing of the map: the page's "first render" (measured by the browser tests).
map.map.once('rendercomplete', () => performance.mark('terraplan:map-rendered'));

// Hooks for the browser tests: where a lon/lat point is on the screen; the drawn areas.
(window as unknown as { terraplan: unknown }).terraplan = {
  pixelFor: (lon: number, lat: number) => map.pixelFor(lon, lat),
  areas: () => map.getAreas(),
  corridor: () => map.getCorridorLine(),
  fit: (extent: [number, number, number, number]) => map.fitLonLat(extent),
};

// The DEM chosen last comes back after a reload (the map is its hillshade).
const LAST_DEM = 'terraplan.dem';
selection.onChange((d) => (d ? localStorage.setItem(LAST_DEM, d.id) : localStorage.removeItem(LAST_DEM)));

// The static catalogues need no account; the rest waits for the session (and a project).
const catalogues = Promise.all([route.loadVehicles(), survey.loadCameras()]);
void session.start().then(async (signedIn) => {
  if (signedIn) {
    await projects.load(signedIn);
    saved.useProjects(projects);
  }
  await Promise.all([dems.refresh(), catalogues]);
  const last = localStorage.getItem(LAST_DEM);
  if (last && dems.has(last)) await dems.choose(last);
  document.body.dataset.ready = 'true';
});
