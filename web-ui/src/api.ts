// Typed client of terraplan's REST API (/api/v1). Only the fields the page
// uses are typed; the server's OpenAPI document (/api/v1/openapi.json) is the
// full reference.

export type LonLat = [number, number];
export type Ring = LonLat[];
export interface Polygon {
  type: 'Polygon';
  coordinates: Ring[];
}

export interface Issue {
  pointer: string;
  message: string;
}
export interface Problem {
  type?: string;
  title?: string;
  status: number;
  detail: string;
  errors?: Issue[];
}

/** An error answer of the API (RFC 9457 problem+json), or a network fault. */
export class ApiError extends Error {
  constructor(public readonly problem: Problem) {
    super(problem.detail || problem.title || `HTTP ${problem.status}`);
  }
}

export interface Page<T> {
  items: T[];
  total: number;
  limit: number;
  offset: number;
}

export interface Dem {
  id: string;
  name: string | null;
  file_name: string | null;
  created_at: string;
  width: number;
  height: number;
  /** `proj4`: the CRS as a PROJ string bound to WGS84 (absent from older servers). */
  crs: { epsg: number | null; name: string; geographic: boolean; proj4?: string };
  resolution: [number, number];
  /** The cell size in metres (at the centre, for a geographic DEM). */
  resolution_m?: [number, number];
  bounds: [number, number, number, number];
  bounds_wgs84: [number, number, number, number];
  min: number;
  max: number;
  hillshade: string;
  url: string;
}

export interface UavStats {
  length_m: number;
  length_3d_m: number;
  turns: number;
  flight_time_s: number;
  photos: number;
  cells: number;
  sorties?: number;
}
export interface ProfilePoint {
  distance_m: number;
  altitude_m: number;
  terrain_m?: number | null;
}
export interface UavFiles {
  waypoints: string;
  plan: string;
  route: string;
  fence: string;
  /** Rally points (MAVLink rally file), when the survey has some. */
  rally?: string;
  kml: string;
}
export interface Sortie {
  number: number;
  stats: UavStats;
  /** [lon, lat, height above the WGS 84 ellipsoid] over a DEM, [lon, lat] without one. */
  route: { type: 'LineString'; coordinates: number[][] };
  /** The mission's altitude (in the survey's altitude_frame) at each route position. */
  mission_altitudes_m: number[];
  terrain?: { home_amsl_m: number; profile: ProfilePoint[] } | null;
  files: UavFiles;
}
export interface Uav {
  id: string;
  start: LonLat;
  speed_m_s: number;
  stats: UavStats;
  sorties: Sortie[];
}
export interface SurveyStats {
  area_m2: number;
  free_area_m2: number;
  /** The free area less the band within the clearance of the no-fly zones: what the cells tile (absent from older surveys). */
  flyable_area_m2?: number;
  /** The clearance kept from the no-fly zones and the inclusion fence, m (absent from older surveys). */
  nfz_clearance_m?: number;
  altitude_m: number;
  gsd_cm_px: number;
  photos: number;
  length_m: number;
  flight_time_s: number;
  coverage_ratio: number;
  cell_count: number;
  makespan_s?: number;
  uav_count?: number;
  /** The slice angle used (the one "auto" chose), the lane spacing and the distance between photos. */
  slice_angle_deg?: number;
  line_spacing_m?: number;
  trigger_distance_m?: number;
}
export interface Camera {
  sensor_width_mm: number;
  sensor_height_mm: number;
  focal_length_mm: number;
  image_width_px: number;
  image_height_px: number;
  orientation: 'landscape' | 'portrait';
}
export interface CameraPreset {
  name: string;
  camera: Camera;
}

export interface Survey {
  id: string;
  name: string | null;
  created_at: string;
  altitude_frame: string;
  stats: SurveyStats;
  cells: { type: 'FeatureCollection'; features: { geometry: { type: string; coordinates: unknown }; properties: Record<string, unknown> | null }[] };
  uavs: Uav[];
  fences: { inclusion: boolean; vertices: LonLat[] }[];
  warnings: string[];
  files: { cells: string };
  /** The request as made, without `name` (absent from surveys of older servers). */
  request?: Record<string, unknown> | null;
}
export interface SurveySummary {
  id: string;
  name: string | null;
  created_at: string;
  uav_count: number;
  area_m2: number;
  makespan_s: number;
}

export interface Vehicle {
  name: string;
  max_step_m: number;
  max_slope_deg: number;
  width_m: number;
  length_m: number;
  w_infl: number;
  w_slope: number;
}
export type JobStatus = 'queued' | 'running' | 'done' | 'failed';
export interface Costmap {
  id: string;
  name: string | null;
  dem_id: string;
  created_at: string;
  status: JobStatus;
  progress: number;
  stage: string | null;
  error?: string | null;
  vehicle: Vehicle;
  width?: number;
  height?: number;
  params?: { resample_factor: [number, number]; resolution_m: [number, number] } | null;
  /** Once done: the exact extent of `preview.png` in `crs`, and in WGS84 (absent from older servers' costmaps). */
  crs?: Dem['crs'] | null;
  bounds?: [number, number, number, number] | null;
  bounds_wgs84?: [number, number, number, number] | null;
  warnings: string[];
  /** Once done: among others the range of the traversable cells' costs. */
  stats?: { cost_min: number | null; cost_max: number | null } | null;
  urls: { self: string; events: string; preview_png: string; legend_svg: string; costmap_tif: string };
}
export interface JobEvent {
  status: JobStatus;
  progress: number;
  stage?: string | null;
  error?: string | null;
}

export type Position = LonLat | { utm: [number, number] };
export interface Route {
  id: string;
  name: string | null;
  costmap_id: string;
  parent_id: string | null;
  created_at: string;
  start: Position;
  goal: Position;
  speed_m_s: number | null;
  planner: string;
  reused_search: boolean;
  waypoints: { lon: number; lat: number; height_m: number | null }[];
  geometry: { type: 'LineString'; coordinates: number[][] };
  length_2d_m: number;
  /** Null (like the slopes, grade, climb and descent) when the costmap's DEM is gone: no heights. */
  length_3d_m: number | null;
  cost: number;
  max_slope_deg: number | null;
  mean_slope_deg: number | null;
  max_grade_deg: number | null;
  climb_m: number | null;
  descent_m: number | null;
  search_ms: number;
  blocked: unknown[];
  /** Every cost change of the chain of replans so far (absent from older servers). */
  cost_changes?: { area: unknown; cost: number }[];
  urls: { geojson: string; csv: string; waypoints: string; replan: string };
}

async function request<T>(method: string, url: string, body?: unknown): Promise<T> {
  let res: Response;
  try {
    res = await fetch(url, {
      method,
      headers: body === undefined ? {} : { 'Content-Type': 'application/json' },
      body: body === undefined ? undefined : JSON.stringify(body),
    });
  } catch {
    throw new ApiError({ status: 0, detail: 'The terraplan server cannot be reached.' });
  }
  if (!res.ok) throw new ApiError(await problemOf(res));
  if (res.status === 204) return undefined as T;
  return (await res.json()) as T;
}

async function problemOf(res: Response): Promise<Problem> {
  const text = await res.text();
  try {
    const p = JSON.parse(text) as Problem;
    if (typeof p.detail === 'string' || Array.isArray(p.errors)) return { ...p, status: res.status };
  } catch {
    /* not JSON: fall through */
  }
  return { status: res.status, detail: text || res.statusText || `HTTP ${res.status}` };
}

const list = <T>(path: string, limit = 50) => request<Page<T>>('GET', `${path}?limit=${limit}&offset=0`);

export const api = {
  listDems: () => list<Dem>('/api/v1/dems'),
  getDem: (id: string) => request<Dem>('GET', `/api/v1/dems/${id}`),
  deleteDem: (id: string) => request<void>('DELETE', `/api/v1/dems/${id}`),

  listCameras: () => request<{ items: CameraPreset[] }>('GET', '/api/v1/cameras'),
  createSurvey: (body: unknown) => request<Survey>('POST', '/api/v1/surveys', body),
  listSurveys: () => list<SurveySummary>('/api/v1/surveys'),
  getSurvey: (id: string) => request<Survey>('GET', `/api/v1/surveys/${id}`),
  deleteSurvey: (id: string) => request<void>('DELETE', `/api/v1/surveys/${id}`),

  listVehicles: () => request<{ items: Vehicle[] }>('GET', '/api/v1/vehicles'),
  createCostmap: (body: unknown) => request<Costmap>('POST', '/api/v1/costmaps', body),
  listCostmaps: () => list<Costmap>('/api/v1/costmaps'),
  getCostmap: (id: string) => request<Costmap>('GET', `/api/v1/costmaps/${id}`),
  deleteCostmap: (id: string) => request<void>('DELETE', `/api/v1/costmaps/${id}`),

  createRoute: (costmapId: string, body: unknown) =>
    request<Route>('POST', `/api/v1/costmaps/${costmapId}/routes`, body),
  replanRoute: (routeId: string, body: unknown) => request<Route>('POST', `/api/v1/routes/${routeId}/replan`, body),
  listRoutes: () => list<Route>('/api/v1/routes'),
  getRoute: (id: string) => request<Route>('GET', `/api/v1/routes/${id}`),
  deleteRoute: (id: string) => request<void>('DELETE', `/api/v1/routes/${id}`),
};

/**
 * Uploads a DEM file as the raw body. XMLHttpRequest rather than fetch
 * because only XHR reports upload progress.
 */
/** Uploads a DEM; `crs` ("EPSG:32633") for a file that does not give its own. */
export function uploadDem(file: File, name: string, crs: string | null, onProgress: (fraction: number) => void): Promise<Dem> {
  return new Promise((resolve, reject) => {
    const xhr = new XMLHttpRequest();
    const params = new URLSearchParams({ name, file_name: file.name });
    if (crs) params.set('crs', crs);
    xhr.open('POST', `/api/v1/dems?${params}`);
    const type = /\.(tif|tiff)$/i.test(file.name) ? 'image/tiff' : /\.asc$/i.test(file.name) ? 'text/plain' : 'application/octet-stream';
    xhr.setRequestHeader('Content-Type', type);
    xhr.upload.onprogress = (e) => {
      if (e.lengthComputable) onProgress(e.loaded / e.total);
    };
    xhr.onload = () => {
      if (xhr.status >= 200 && xhr.status < 300) {
        onProgress(1);
        resolve(JSON.parse(xhr.responseText) as Dem);
        return;
      }
      let problem: Problem = { status: xhr.status, detail: xhr.responseText || xhr.statusText };
      try {
        problem = { ...(JSON.parse(xhr.responseText) as Problem), status: xhr.status };
      } catch {
        /* keep the text */
      }
      reject(new ApiError(problem));
    };
    xhr.onerror = () => reject(new ApiError({ status: 0, detail: 'The upload failed: the server cannot be reached.' }));
    xhr.send(file);
  });
}

/**
 * Follows a costmap job's Server-Sent Events until it is done or failed.
 * Resolves with the final event; calls onProgress for every event.
 */
export function followCostmap(eventsUrl: string, onProgress: (e: JobEvent) => void): Promise<JobEvent> {
  return new Promise((resolve) => {
    const source = new EventSource(eventsUrl);
    const handle = (msg: MessageEvent) => {
      const event = JSON.parse(msg.data as string) as JobEvent;
      onProgress(event);
      if (event.status === 'done' || event.status === 'failed') {
        source.close();
        resolve(event);
      }
    };
    for (const name of ['progress', 'done', 'failed', 'message']) source.addEventListener(name, handle as EventListener);
    source.onerror = () => {
      // The stream ended without a final event (server restart): ask once.
      source.close();
      const id = eventsUrl.split('/').slice(-2)[0];
      api.getCostmap(id).then(
        (c) => resolve({ status: c.status, progress: c.progress, stage: c.stage, error: c.error }),
        () => resolve({ status: 'failed', progress: 0, error: 'lost contact with the server' }),
      );
    };
  });
}
