// The map: base layers (DEM hillshade, optional online tiles), the drawn
// areas (ROI, no-fly zones, blocked areas), plan results (cells, UAV routes,
// ground routes) and the click modes that place things on it. Everything
// crossing this module's boundary is WGS84 lon/lat; the view is Web Mercator.

import OlMap from 'ol/Map';
import View from 'ol/View';
import Feature from 'ol/Feature';
import ImageLayer from 'ol/layer/Image';
import TileLayer from 'ol/layer/Tile';
import VectorLayer from 'ol/layer/Vector';
import VectorSource from 'ol/source/Vector';
import ImageStatic from 'ol/source/ImageStatic';
import XYZ from 'ol/source/XYZ';
import Draw from 'ol/interaction/Draw';
import Modify from 'ol/interaction/Modify';
import Snap from 'ol/interaction/Snap';
import { LineString, Point, Polygon, MultiPolygon } from 'ol/geom';
import type Geometry from 'ol/geom/Geometry';
import { asArray } from 'ol/color';
import { Fill, Stroke, Style, Circle as CircleStyle, Text, RegularShape } from 'ol/style';
import { fromLonLat, toLonLat, transformExtent } from 'ol/proj';
import { defaults as defaultControls, ScaleLine, Attribution, MousePosition, Control } from 'ol/control';
import { createEmpty, extend as extendExtent, isEmpty, type Extent } from 'ol/extent';
import type { Coordinate } from 'ol/coordinate';
import type { FeatureLike } from 'ol/Feature';
import type { LonLat, Route, Survey } from './api';
import type { PolygonRings } from './geo-import';
import type { ImagePlacement } from './projection';
import type { UavStart } from './survey-form';

export type MapMode =
  | 'browse'
  | 'draw-roi'
  | 'draw-nfz'
  | 'draw-line'
  | 'place-uav'
  | 'place-rally'
  | 'pick-start'
  | 'pick-goal'
  | 'pick-position'
  | 'draw-block'
  | 'draw-costlier';

type AreaKind = 'roi' | 'nfz' | 'blocked' | 'costlier';

export interface MapEvents {
  /** The ROI or the no-fly zones changed (drawn, edited, removed). */
  areasChanged(roi: PolygonRings | null, noFlyZones: PolygonRings[]): void;
  /** A blocked area for the ground route was drawn. */
  blockedChanged(blocked: PolygonRings[]): void;
  /** A costlier area for the ground route was drawn (the panel knows its cost and shows it with setCostlier). */
  costlierDrawn(areas: PolygonRings[]): void;
  /** A point was picked in one of the click modes. */
  picked(mode: MapMode, at: LonLat): void;
  /** A corridor's centre line was drawn. */
  lineDrawn?(line: LonLat[]): void;
  /** The mode changed (a drawing finished, or Escape). */
  modeChanged(mode: MapMode): void;
}

/** What the map does when browsing, by task (only survey areas are editable). */
const BROWSE_HINTS: Record<'survey' | 'route' | 'all', string> = {
  survey: 'Drag to pan, scroll to zoom. Drag a corner of an area to edit it; click an edge to add one.',
  route: 'Drag to pan, scroll to zoom. Build or choose a costmap, then pick the start and the goal.',
  all: 'Drag to pan, scroll to zoom.',
};

const MODE_HINTS: Record<MapMode, string> = {
  browse: BROWSE_HINTS.survey,
  'draw-roi': 'Click the corners of the survey area; click the first corner or double-click to finish. Backspace removes the last corner, Escape cancels.',
  'draw-nfz': 'Click the corners of a no-fly zone; click the first corner or double-click to finish. Escape cancels.',
  'draw-line': 'Click along the corridor’s centre line; double-click (or Enter) to finish. Backspace removes the last point, Escape cancels.',
  'place-uav': 'Click where each UAV takes off. Escape when done.',
  'place-rally': 'Click each rally point, where a UAV may return instead of home. Escape when done.',
  'pick-start': 'Click the ground route’s start.',
  'pick-goal': 'Click the ground route’s goal.',
  'pick-position': 'Click where the rover is now (the replan starts there).',
  'draw-block': 'Click the corners of the blocked area; click the first corner or double-click to finish.',
  'draw-costlier': 'Click the corners of the costlier area; click the first corner or double-click to finish.',
};

const areaStyles: Record<AreaKind, Style> = {
  roi: new Style({ stroke: new Stroke({ color: '#0050d0', width: 2.5 }), fill: new Fill({ color: 'rgba(0, 80, 208, 0.10)' }) }),
  nfz: new Style({ stroke: new Stroke({ color: '#c00000', width: 2, lineDash: [6, 4] }), fill: new Fill({ color: 'rgba(200, 0, 0, 0.25)' }) }),
  blocked: new Style({ stroke: new Stroke({ color: '#000', width: 2 }), fill: new Fill({ color: 'rgba(0, 0, 0, 0.45)' }) }),
  costlier: new Style({ stroke: new Stroke({ color: '#b35806', width: 2, lineDash: [4, 4] }), fill: new Fill({ color: 'rgba(253, 184, 99, 0.45)' }) }),
};

/** A costlier area: dashed orange, labelled with its cost (unlike the black blocked areas). */
function costlierStyle(cost: number): Style {
  return new Style({
    stroke: new Stroke({ color: '#b35806', width: 2, lineDash: [4, 4] }),
    fill: new Fill({ color: 'rgba(253, 184, 99, 0.45)' }),
    text: new Text({ text: `cost ${cost}`, font: 'bold 12px system-ui, sans-serif', fill: new Fill({ color: '#6b3000' }), stroke: new Stroke({ color: '#fff', width: 3 }), overflow: true }),
  });
}

/** A corridor's centre line: the ROI's blue, dashed (the corridor itself comes back with the plan's cells). */
const corridorLineStyle = new Style({ stroke: new Stroke({ color: '#0050d0', width: 3, lineDash: [10, 6] }) });

const cellStyle = new Style({ stroke: new Stroke({ color: 'rgba(40, 40, 40, 0.8)', width: 1, lineDash: [3, 3] }), fill: new Fill({ color: 'rgba(255, 255, 255, 0.12)' }) });
/** A cell whose photos overlap less than requested. */
const lowCellStyle = new Style({ stroke: new Stroke({ color: 'rgba(200, 20, 20, 0.95)', width: 2.5 }), fill: new Fill({ color: 'rgba(220, 40, 40, 0.18)' }) });

/** A photo's footprint, in its UAV's colour. */
function footprintStyle(colour: string): Style {
  const [r, g, b] = asArray(colour);
  return new Style({ stroke: new Stroke({ color: `rgba(${r}, ${g}, ${b}, 0.55)`, width: 1 }), fill: new Fill({ color: `rgba(${r}, ${g}, ${b}, 0.06)` }) });
}

function markerStyle(colour: string, label: string, shape: 'circle' | 'square' = 'circle'): Style {
  const fill = new Fill({ color: colour });
  const stroke = new Stroke({ color: '#fff', width: 2 });
  return new Style({
    image: shape === 'circle' ? new CircleStyle({ radius: 8, fill, stroke }) : new RegularShape({ points: 4, radius: 10, angle: Math.PI / 4, fill, stroke }),
    text: new Text({ text: label, offsetY: -16, font: 'bold 12px system-ui, sans-serif', fill: new Fill({ color: '#111' }), stroke: new Stroke({ color: '#fff', width: 3 }) }),
  });
}

function lineStyles(colour: string, width = 3, dashed = false): Style[] {
  return [
    new Style({ stroke: new Stroke({ color: 'rgba(255, 255, 255, 0.9)', width: width + 2.5 }) }),
    new Style({ stroke: new Stroke({ color: colour, width, lineDash: dashed ? [8, 6] : undefined }) }),
  ];
}

/** Segments shorter than this on screen get no arrow (they would clutter turns). */
const ARROW_MIN_SEGMENT_PX = 70;

/**
 * Arrows at the middle of the longer segments, pointing the way the vehicle
 * goes: what a pilot checks first on a mission (where it starts, which way
 * the lanes are flown).
 */
function directionArrows(line: LineString, colour: string, resolution: number): Style[] {
  const out: Style[] = [];
  const pts = line.getCoordinates();
  for (let i = 1; i < pts.length; i++) {
    const [x0, y0] = pts[i - 1];
    const [x1, y1] = pts[i];
    const dx = x1 - x0;
    const dy = y1 - y0;
    if (Math.hypot(dx, dy) / resolution < ARROW_MIN_SEGMENT_PX) continue;
    out.push(
      new Style({
        geometry: new Point([(x0 + x1) / 2, (y0 + y1) / 2]),
        // A triangle's first point is up; rotation is clockwise from north.
        image: new RegularShape({
          points: 3,
          radius: 6,
          rotation: Math.atan2(dx, dy),
          rotateWithView: true,
          fill: new Fill({ color: colour }),
          stroke: new Stroke({ color: '#fff', width: 1.5 }),
        }),
      }),
    );
  }
  return out;
}

/** A route line: haloed, with direction arrows; faded when another route is highlighted, thicker when it is the one. */
function routeStyle(feature: FeatureLike, resolution: number, emphasis: 'normal' | 'highlighted' | 'faded'): Style[] {
  const colour = feature.get('colour') as string;
  const width = (feature.get('width') as number) + (emphasis === 'highlighted' ? 1.5 : 0);
  const shown = emphasis === 'faded' ? fade(colour) : colour;
  const styles = lineStyles(shown, width);
  if (emphasis === 'faded') styles[0] = new Style({ stroke: new Stroke({ color: 'rgba(255, 255, 255, 0.35)', width: width + 2 }) });
  const geom = feature.getGeometry();
  if (emphasis !== 'faded' && geom instanceof LineString) styles.push(...directionArrows(geom, colour, resolution));
  return styles;
}

/** A colour at 35 % opacity (OpenLayers' own parser reads it). */
function fade(colour: string): string {
  const [r, g, b] = asArray(colour);
  return `rgba(${r}, ${g}, ${b}, 0.35)`;
}

const toMap = (p: LonLat | number[]) => fromLonLat([p[0], p[1]]);
const ringsToMap = (rings: PolygonRings) => rings.map((r) => r.map(toMap));

function polygonRings(geom: Geometry): PolygonRings[] {
  const g = geom.clone().transform('EPSG:3857', 'EPSG:4326');
  if (g instanceof Polygon) return [g.getCoordinates() as PolygonRings];
  if (g instanceof MultiPolygon) return g.getCoordinates() as PolygonRings[];
  return [];
}

export class MapView {
  readonly map: OlMap;
  private mode: MapMode = 'browse';
  private readonly areas = new VectorSource<Feature<Geometry>>();
  private readonly cells = new VectorSource<Feature<Geometry>>();
  private readonly photos = new VectorSource<Feature<Geometry>>();
  private readonly flights = new VectorSource<Feature<Geometry>>();
  private readonly ground = new VectorSource<Feature<Geometry>>();
  private readonly hillshade = new ImageLayer({ visible: false, zIndex: 1 });
  private readonly costmap = new ImageLayer({ visible: false, zIndex: 2, opacity: 0.7 });
  private readonly surveyLayers: VectorLayer[] = [];
  private readonly groundLayer: VectorLayer;
  private tiles: TileLayer<XYZ> | null = null;
  private draw: Draw | null = null;
  private readonly modify: Modify;
  private readonly snap: Snap;

  constructor(
    target: HTMLElement,
    private readonly hint: HTMLElement,
    private readonly events: MapEvents,
  ) {
    this.surveyLayers = [
      new VectorLayer({ source: this.cells, style: (f) => (f.get('low') ? lowCellStyle : cellStyle), zIndex: 3 }),
      new VectorLayer({ source: this.photos, style: (f) => f.get('style') as Style, zIndex: 3 }),
      new VectorLayer({ source: this.areas, style: (f) => areaStyles[f.get('kind') as AreaKind], zIndex: 4 }),
      new VectorLayer({ source: this.flights, style: (f, res) => (f.get('kind') === 'route' ? routeStyle(f, res, this.emphasis(f)) : (f.get('style') as Style | Style[])), zIndex: 5 }),
    ];
    this.groundLayer = new VectorLayer({
      source: this.ground,
      style: (f, res) => (f.get('kind') === 'route' ? routeStyle(f, res, 'normal') : (f.get('style') as Style | Style[])),
      zIndex: 6,
    });
    this.map = new OlMap({
      target,
      controls: defaultControls({ attribution: false }).extend([
        new ScaleLine(),
        new Attribution({ collapsible: true }),
        // Where the pointer is, in the lon, lat order the page's fields take.
        new MousePosition({
          projection: 'EPSG:4326',
          coordinateFormat: (c) => (c ? `${c[0].toFixed(6)}, ${c[1].toFixed(6)}` : ''),
          className: 'mouse-position',
          placeholder: '',
        }),
        this.fitControl(),
      ]),
      layers: [this.hillshade, this.costmap, ...this.surveyLayers, this.groundLayer],
      view: new View({ center: fromLonLat([-77.0525, 38.8106]), zoom: 16, maxZoom: 22 }),
      keyboardEventTarget: target,
    });
    target.tabIndex = 0;

    // Drawn areas stay editable: drag a vertex, click an edge to add one.
    this.modify = new Modify({ source: this.areas });
    this.modify.on('modifyend', () => this.emitAreas());
    this.snap = new Snap({ source: this.areas });
    this.map.addInteraction(this.modify);

    this.map.on('click', (e) => {
      if (this.mode === 'place-uav' || this.mode === 'place-rally' || this.mode === 'pick-start' || this.mode === 'pick-goal' || this.mode === 'pick-position') {
        const [lon, lat] = toLonLat(e.coordinate);
        this.events.picked(this.mode, [lon, lat]);
      }
    });
    target.addEventListener('keydown', (e) => this.onKey(e));
    // Escape ends a drawing or picking mode wherever the focus is (right after pressing "Draw area" it is on that button).
    document.addEventListener('keydown', (e) => {
      if (e.key === 'Escape' && this.mode !== 'browse') {
        this.draw?.abortDrawing();
        this.setMode('browse');
      }
    });
    this.setHint();
    this.updateEmpty();
  }

  getMode(): MapMode {
    return this.mode;
  }

  /** Switches what a click on the map does. Drawing modes add a Draw interaction. */
  setMode(mode: MapMode): void {
    if (this.draw) {
      this.map.removeInteraction(this.draw);
      this.map.removeInteraction(this.snap);
      this.draw = null;
    }
    this.mode = mode;
    const kind: AreaKind | null = mode === 'draw-roi' ? 'roi' : mode === 'draw-nfz' ? 'nfz' : mode === 'draw-block' ? 'blocked' : mode === 'draw-costlier' ? 'costlier' : null;
    if (mode === 'draw-line') {
      this.draw = new Draw({ type: 'LineString', stopClick: true });
      this.draw.on('drawend', (e) => {
        const coords = (e.feature.getGeometry() as LineString).getCoordinates();
        this.events.lineDrawn?.(coords.map((c) => toLonLat(c) as LonLat));
        setTimeout(() => this.setMode('browse'));
      });
      this.map.addInteraction(this.draw);
    } else if (kind) {
      // stopClick keeps the finishing double-click from zooming the map.
      this.draw = new Draw({ type: 'Polygon', stopClick: true });
      this.draw.on('drawend', (e) => {
        const feature = e.feature as Feature<Geometry>;
        feature.set('kind', kind);
        if (kind === 'blocked') {
          feature.set('style', areaStyles.blocked);
          this.ground.addFeature(feature);
          this.emitBlocked();
        } else if (kind === 'costlier') {
          this.events.costlierDrawn(polygonRings(feature.getGeometry()!));
        } else {
          if (kind === 'roi') for (const f of this.areaFeatures('roi')) this.areas.removeFeature(f);
          this.areas.addFeature(feature);
          this.emitAreas();
        }
        // Back to browsing after one area; the panel buttons start another.
        setTimeout(() => this.setMode('browse'));
      });
      this.map.addInteraction(this.draw);
      this.map.addInteraction(this.snap);
    }
    this.updateModify();
    this.map.getTargetElement()?.classList.toggle('picking', mode !== 'browse');
    // On a tablet the map sits above the panel: bring it into view for the clicks it now waits for.
    if (mode !== 'browse') this.map.getTargetElement()?.scrollIntoView({ block: 'nearest' });
    this.setHint();
    this.events.modeChanged(mode);
  }

  private onKey(e: KeyboardEvent): void {
    if (e.key === 'Backspace' && this.draw) {
      this.draw.removeLastPoint();
      e.preventDefault();
    } else if (e.key === 'Enter' && this.draw) {
      this.draw.finishDrawing();
      e.preventDefault();
    }
  }

  private task: 'survey' | 'route' | 'all' = 'survey';

  /**
   * Survey areas are editable only while no area is being drawn and they
   * are shown: hidden ones' corners would still catch drags on the route tab.
   */
  private updateModify(): void {
    this.modify.setActive(this.draw === null && this.surveyLayers[0].getVisible());
  }

  private setHint(): void {
    this.hint.textContent = this.mode === 'browse' ? BROWSE_HINTS[this.task] : MODE_HINTS[this.mode];
  }

  /** Says so over the map while there is no base layer (no DEM, no online tiles). */
  private updateEmpty(): void {
    const empty = !this.hillshade.getVisible() && !this.costmap.getVisible() && !this.tiles?.getVisible();
    this.map.getTargetElement()?.parentElement?.classList.toggle('empty', empty);
  }

  /** Shows the layers of one task (the other's would clutter the map), or all. */
  showTask(task: 'survey' | 'route' | 'all'): void {
    this.task = task;
    this.setHint();
    for (const l of this.surveyLayers) l.setVisible(task !== 'route');
    this.updateModify();
    this.groundLayer.setVisible(task !== 'survey');
    this.costmap.setOpacity(task === 'survey' ? 0 : this.costmapOpacity);
  }

  // ---- base layers ----

  /** Shows a DEM's hillshade as the base layer (null hides it). */
  setHillshade(url: string | null, placement?: ImagePlacement): void {
    if (!url || !placement) {
      this.hillshade.setVisible(false);
      this.hillshadeExtent = null;
      this.updateEmpty();
      return;
    }
    this.hillshade.setSource(new ImageStatic({ url, imageExtent: placement.extent, projection: placement.projection }));
    this.hillshade.setVisible(true);
    this.hillshadeExtent = transformExtent(placement.extent, placement.projection, 'EPSG:3857');
    this.updateEmpty();
  }

  /** Turns the online tile layer on or off; it is created only when first wanted, so no request is made otherwise. */
  setOnlineTiles(urlTemplate: string | null): void {
    if (!urlTemplate) {
      this.tiles?.setVisible(false);
      this.updateEmpty();
      return;
    }
    if (!this.tiles) {
      this.tiles = new TileLayer({ zIndex: 0 });
      this.map.addLayer(this.tiles);
    }
    this.tiles.setSource(new XYZ({ url: urlTemplate, attributions: '© OpenStreetMap contributors', crossOrigin: 'anonymous' }));
    this.tiles.setVisible(true);
    this.updateEmpty();
  }

  setCostmapOverlay(url: string | null, placement?: ImagePlacement): void {
    if (!url || !placement) {
      this.costmap.setVisible(false);
      this.updateEmpty();
      return;
    }
    // No interpolation: class colours must stay crisp at any zoom.
    this.costmap.setSource(new ImageStatic({ url, imageExtent: placement.extent, projection: placement.projection, interpolate: false }));
    this.costmap.setVisible(true);
    this.updateEmpty();
  }

  private costmapOpacity = 0.7;

  setCostmapOpacity(opacity: number): void {
    this.costmapOpacity = opacity;
    this.costmap.setOpacity(opacity);
  }

  /** A map button that zooms to what is shown: the areas and routes, else the terrain model. */
  private fitControl(): Control {
    const button = document.createElement('button');
    button.type = 'button';
    button.textContent = '⤢';
    button.title = 'Zoom to the areas and routes, or the terrain model';
    button.setAttribute('aria-label', button.title);
    button.addEventListener('click', () => this.fitAll());
    const element = document.createElement('div');
    element.className = 'fit-all ol-unselectable ol-control';
    element.append(button);
    return new Control({ element });
  }

  /** The extent of the hillshade shown, in the view's projection (null when none). */
  private hillshadeExtent: Extent | null = null;

  /** Zooms to the shown areas and routes, or the terrain model when there are none. */
  fitAll(): void {
    const extent = createEmpty();
    const sources = [this.areas, ...(this.surveyLayers[0].getVisible() ? [this.cells, this.flights] : []), ...(this.groundLayer.getVisible() ? [this.ground] : [])];
    for (const src of sources) {
      const e = src.getFeatures().length ? src.getExtent() : null;
      if (e) extendExtent(extent, e);
    }
    const target = !isEmpty(extent) ? extent : this.hillshadeExtent;
    if (target) this.map.getView().fit(target, { padding: [30, 30, 30, 30], maxZoom: 19, duration: 250 });
  }

  /** Zooms to a lon/lat extent [west, south, east, north]. */
  fitLonLat(extent: [number, number, number, number]): void {
    const e = transformExtent(extent, 'EPSG:4326', 'EPSG:3857');
    this.map.getView().fit(e, { padding: [30, 30, 30, 30], maxZoom: 19 });
  }

  // ---- ROI and no-fly zones ----

  private areaFeatures(kind: AreaKind): Feature<Geometry>[] {
    return this.areas.getFeatures().filter((f) => f.get('kind') === kind);
  }

  /** The ROI and no-fly zones on the map, in lon/lat. */
  getAreas(): { roi: PolygonRings | null; nfz: PolygonRings[] } {
    const roi = this.areaFeatures('roi').flatMap((f) => polygonRings(f.getGeometry()!))[0] ?? null;
    const nfz = this.areaFeatures('nfz').flatMap((f) => polygonRings(f.getGeometry()!));
    return { roi, nfz };
  }

  private emitAreas(): void {
    const { roi, nfz } = this.getAreas();
    this.events.areasChanged(roi, nfz);
  }

  setRoi(rings: PolygonRings | null): void {
    for (const f of this.areaFeatures('roi')) this.areas.removeFeature(f);
    if (rings) this.areas.addFeature(new Feature({ geometry: new Polygon(ringsToMap(rings)), kind: 'roi' }));
    this.emitAreas();
  }

  /** Shows a corridor's centre line (null: none). */
  setCorridorLine(line: LonLat[] | null): void {
    for (const f of this.flights.getFeatures().filter((f) => f.get('kind') === 'corridor-line')) this.flights.removeFeature(f);
    if (line) this.flights.addFeature(new Feature({ geometry: new LineString(line.map(toMap)), kind: 'corridor-line', style: corridorLineStyle }));
  }

  /** The corridor's centre line shown (null: none), in lon/lat. */
  getCorridorLine(): LonLat[] | null {
    const f = this.flights.getFeatures().find((f) => f.get('kind') === 'corridor-line');
    const g = f?.getGeometry();
    return g instanceof LineString ? g.getCoordinates().map((c) => toLonLat(c) as LonLat) : null;
  }

  addNoFlyZones(zones: PolygonRings[]): void {
    for (const z of zones) this.areas.addFeature(new Feature({ geometry: new Polygon(ringsToMap(z)), kind: 'nfz' }));
    this.emitAreas();
  }

  removeNoFlyZone(index: number): void {
    const f = this.areaFeatures('nfz')[index];
    if (f) this.areas.removeFeature(f);
    this.emitAreas();
  }

  clearNoFlyZones(): void {
    for (const f of this.areaFeatures('nfz')) this.areas.removeFeature(f);
    this.emitAreas();
  }

  // ---- survey results ----

  setUavStarts(starts: UavStart[], colours: (i: number) => string): void {
    for (const f of this.flights.getFeatures().filter((f) => f.get('kind') === 'start')) this.flights.removeFeature(f);
    starts.forEach((u, i) => {
      this.flights.addFeature(new Feature({ geometry: new Point(toMap(u.start)), kind: 'start', style: markerStyle(colours(i), u.id) }));
    });
  }

  /** Shows the rally points as dark green squares, R1, R2, … */
  setRallyPoints(points: LonLat[]): void {
    for (const f of this.flights.getFeatures().filter((f) => f.get('kind') === 'rally')) this.flights.removeFeature(f);
    points.forEach((p, i) => {
      this.flights.addFeature(new Feature({ geometry: new Point(toMap(p)), kind: 'rally', style: markerStyle('#1b5e20', `R${i + 1}`, 'square') }));
    });
  }

  /** Shows a planned survey: cells (those in `lowCells` flagged), and each UAV's route in its colour. */
  showSurvey(survey: Survey | null, colours: (i: number) => string, lowCells: Set<number> = new Set()): void {
    this.cells.clear();
    this.photos.clear();
    for (const f of this.flights.getFeatures().filter((f) => f.get('kind') === 'route')) this.flights.removeFeature(f);
    if (!survey) return;
    for (const cell of survey.cells.features) {
      const g = cell.geometry;
      const geom = g.type === 'Polygon'
        ? new Polygon((g.coordinates as number[][][]).map((r) => r.map(toMap)))
        : new MultiPolygon((g.coordinates as number[][][][]).map((p) => p.map((r) => r.map(toMap))));
      const id = cell.properties?.id;
      this.cells.addFeature(new Feature({ geometry: geom, low: typeof id === 'number' && lowCells.has(id) }));
    }
    survey.uavs.forEach((uav, i) => {
      uav.sorties.forEach((sortie, k) => {
        const line = new LineString(sortie.route.coordinates.map(toMap));
        this.flights.addFeature(new Feature({ geometry: line, kind: 'route', uav: uav.id, sortie: k, colour: colours(i), width: 2.5 }));
      });
    });
  }

  /** Shows photo footprints (lon/lat rings) in `colour`; none clears them. */
  showFootprints(rings: LonLat[][], colour: string): void {
    this.photos.clear();
    const style = footprintStyle(colour);
    this.photos.addFeatures(rings.map((r) => new Feature({ geometry: new Polygon([r.map(toMap)]), style })));
  }

  private highlighted: { uav: string; sortie: number | null } | null = null;

  /**
   * Brings one UAV's route (or one of its sorties) forward: thicker, with
   * the others faded. Null shows them all alike.
   */
  highlightRoute(uav: string | null, sortie: number | null = null): void {
    this.highlighted = uav === null ? null : { uav, sortie };
    this.flights.changed();
  }

  private emphasis(f: FeatureLike): 'normal' | 'highlighted' | 'faded' {
    const h = this.highlighted;
    if (!h) return 'normal';
    const mine = f.get('uav') === h.uav && (h.sortie === null || f.get('sortie') === h.sortie);
    return mine ? 'highlighted' : 'faded';
  }

  // ---- ground routes ----

  private groundFeatures(kind: string): Feature<Geometry>[] {
    return this.ground.getFeatures().filter((f) => f.get('kind') === kind);
  }

  /** The blocked areas drawn since the route was shown (not those it inherited). */
  private emitBlocked(): void {
    this.events.blockedChanged(this.groundFeatures('blocked').filter((f) => !f.get('inherited')).flatMap((f) => polygonRings(f.getGeometry()!)));
  }

  /** Shows the route's start, goal and replan position markers (null removes one). */
  setGroundPoints(points: { start: LonLat | null; goal: LonLat | null; position: LonLat | null }): void {
    for (const kind of ['start', 'goal', 'position']) for (const f of this.groundFeatures(kind)) this.ground.removeFeature(f);
    if (points.start) this.ground.addFeature(new Feature({ geometry: new Point(toMap(points.start)), kind: 'start', style: markerStyle('#1a9641', 'start') }));
    if (points.goal) this.ground.addFeature(new Feature({ geometry: new Point(toMap(points.goal)), kind: 'goal', style: markerStyle('#d7191c', 'goal', 'square') }));
    if (points.position) this.ground.addFeature(new Feature({ geometry: new Point(toMap(points.position)), kind: 'position', style: markerStyle('#f0a000', 'rover') }));
  }

  /** Shows the current route (solid) and the one it replaced (dashed, grey). */
  showGroundRoute(route: Route | null, previous: Route | null = null): void {
    for (const kind of ['route', 'previous']) for (const f of this.groundFeatures(kind)) this.ground.removeFeature(f);
    if (previous) {
      const line = new LineString(previous.geometry.coordinates.map(toMap));
      this.ground.addFeature(new Feature({ geometry: line, kind: 'previous', style: lineStyles('#777', 2.5, true) }));
    }
    if (route) {
      const line = new LineString(route.geometry.coordinates.map(toMap));
      this.ground.addFeature(new Feature({ geometry: line, kind: 'route', colour: '#00b4ff', width: 3.5 }));
    }
  }

  /**
   * Replaces the blocked areas drawn since the route was shown, or (with
   * `inherited`) those of the route itself, from its earlier replans.
   */
  setBlocked(areas: PolygonRings[], inherited = false): void {
    for (const f of this.groundFeatures('blocked')) if (!!f.get('inherited') === inherited) this.ground.removeFeature(f);
    for (const a of areas) this.ground.addFeature(new Feature({ geometry: new Polygon(ringsToMap(a)), kind: 'blocked', inherited, style: areaStyles.blocked }));
  }

  /** Like setBlocked, for the costlier areas (each labelled with its cost). */
  setCostlier(areas: { rings: PolygonRings; cost: number }[], inherited = false): void {
    for (const f of this.groundFeatures('costlier')) if (!!f.get('inherited') === inherited) this.ground.removeFeature(f);
    for (const a of areas) {
      this.ground.addFeature(new Feature({ geometry: new Polygon(ringsToMap(a.rings)), kind: 'costlier', inherited, cost: a.cost, style: costlierStyle(a.cost) }));
    }
  }

  /** Page coordinates of a lon/lat point (for tests that click on the map). */
  pixelFor(lon: number, lat: number): [number, number] | null {
    const px = this.map.getPixelFromCoordinate(fromLonLat([lon, lat]) as Coordinate);
    if (!px) return null;
    const rect = this.map.getTargetElement()!.getBoundingClientRect();
    return [rect.left + px[0], rect.top + px[1]];
  }
}
