// The survey form's values and how they become a `POST /api/v1/surveys`
// body. Pure (no DOM) so it is unit-tested.

import type { LonLat } from './api';
import type { PolygonRings } from './geo-import';
import type { FieldMessage } from './problems';

/**
 * Camera presets the API accepts as `camera_preset` (planner_core::coverage::PRESETS).
 * The API does not list them, so they are repeated here with their specs for display.
 */
export const CAMERA_PRESETS: { id: string; label: string }[] = [
  { id: 'dji_phantom4_pro', label: 'DJI Phantom 4 Pro (1″ 20 MP, 8.8 mm)' },
  { id: 'dji_phantom4_rtk', label: 'DJI Phantom 4 RTK (1″ 20 MP, 8.8 mm)' },
  { id: 'dji_phantom3_pro', label: 'DJI Phantom 3 Pro (1/2.3″ 12 MP, 3.61 mm)' },
  { id: 'dji_mavic2_pro', label: 'DJI Mavic 2 Pro (1″ 20 MP, 10.26 mm)' },
  { id: 'dji_mavic3_enterprise', label: 'DJI Mavic 3 Enterprise (4/3 20 MP, 12.29 mm)' },
  { id: 'dji_zenmuse_p1_35mm', label: 'DJI Zenmuse P1, 35 mm (FF 45 MP)' },
  { id: 'sony_rx1r2', label: 'Sony RX1R II (FF 42 MP, 35 mm)' },
];

export interface CustomCamera {
  sensor_width_mm: number;
  sensor_height_mm: number;
  focal_length_mm: number;
  image_width_px: number;
  image_height_px: number;
  orientation: 'landscape' | 'portrait';
}

export interface UavStart {
  id: string;
  start: LonLat;
}

export interface SurveyFormValues {
  name: string;
  roi: PolygonRings | null;
  noFlyZones: PolygonRings[];
  demId: string | null;
  allowPartialDem: boolean;
  /** A preset id, or "custom". */
  camera: string;
  customCamera: CustomCamera;
  heightMode: 'altitude' | 'gsd';
  altitudeM: number;
  gsdCmPx: number;
  frontOverlapPct: number;
  sideOverlapPct: number;
  /** "auto" or degrees in [0, 180). */
  sliceAngle: string;
  speedMS: number;
  altitudeFrame: 'relative' | 'amsl' | 'terrain';
  assignment: 'balanced' | 'competition' | 'min_reach';
  uavs: UavStart[];
}

export interface SurveyRequest {
  body: Record<string, unknown> | null;
  /** Faults the page can tell before asking the server. */
  errors: FieldMessage[];
}

const polygon = (rings: PolygonRings) => ({ type: 'Polygon', coordinates: rings });

/** Builds the request body, or the faults that keep it from being sent. */
export function buildSurveyRequest(v: SurveyFormValues): SurveyRequest {
  const errors: FieldMessage[] = [];
  if (!v.roi) errors.push({ field: 'roi', text: 'Survey area: draw it on the map or import a file first.' });
  if (v.altitudeFrame !== 'relative' && !v.demId) {
    errors.push({ field: 'altitude-frame', text: `Altitude frame: “${v.altitudeFrame}” needs a terrain model (DEM); choose one or use “relative”.` });
  }
  const slice = v.sliceAngle.trim().toLowerCase();
  if (slice !== 'auto' && slice !== '' && !Number.isFinite(Number(slice))) {
    errors.push({ field: 'slice-angle', text: 'Slice angle: give a number of degrees, or “auto”.' });
  }
  if (errors.length > 0) return { body: null, errors };

  const body: Record<string, unknown> = {
    roi: polygon(v.roi!),
    no_fly_zones: v.noFlyZones.map(polygon),
    front_overlap: round(v.frontOverlapPct / 100, 4),
    side_overlap: round(v.sideOverlapPct / 100, 4),
    slice_angle_deg: slice === 'auto' || slice === '' ? 'auto' : Number(slice),
    speed_m_s: v.speedMS,
    altitude_frame: v.altitudeFrame,
    assignment: v.assignment,
  };
  if (v.name.trim()) body.name = v.name.trim();
  if (v.heightMode === 'gsd') body.gsd_cm_px = v.gsdCmPx;
  else body.altitude_m = v.altitudeM;
  if (v.camera === 'custom') body.camera = { ...v.customCamera };
  else if (v.camera) body.camera_preset = v.camera;
  if (v.demId) {
    body.dem_id = v.demId;
    if (v.allowPartialDem) body.allow_partial_dem = true;
  }
  // No UAVs placed: the server puts one at the ROI's first vertex.
  if (v.uavs.length > 0) body.uavs = v.uavs.map((u) => ({ id: u.id, start: u.start }));
  return { body, errors };
}

function round(x: number, digits: number): number {
  const f = 10 ** digits;
  return Math.round(x * f) / f;
}

/** The next free UAV id ("uav1", "uav2", …) for a new start position. */
export function nextUavId(existing: UavStart[]): string {
  const taken = new Set(existing.map((u) => u.id));
  for (let i = 1; ; i++) if (!taken.has(`uav${i}`)) return `uav${i}`;
}

/** Distinct colours for UAV routes, in order; readable on the grey hillshade. */
export const UAV_COLOURS = ['#e6194b', '#1f78b4', '#2ca02c', '#ff7f00', '#9467bd', '#00a6a6', '#d62790', '#8c564b', '#b8a000', '#17becf'];

export function uavColour(index: number): string {
  return UAV_COLOURS[index % UAV_COLOURS.length];
}
