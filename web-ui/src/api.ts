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
  /** The project it belongs to (absent from servers without accounts). */
  project_id?: string | null;
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
  /** The sortie's planned photos (footprints) as GeoJSON (absent from older surveys and planes). */
  photos?: string;
  /** DJI WPML mission (KMZ), when DJI can fly the sortie. */
  dji_kmz?: string;
  /** Litchi mission(s): one file, or numbered parts past 99 waypoints. */
  litchi?: string[];
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
  /** The project it belongs to (absent from servers without accounts). */
  project_id?: string | null;
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
  /** The project it belongs to (absent from servers without accounts). */
  project_id?: string | null;
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
  /** The project it belongs to (absent from servers without accounts). */
  project_id?: string | null;
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
  /** The project it belongs to (absent from servers without accounts). */
  project_id?: string | null;
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

/**
 * What every request carries besides its own data: the session's CSRF token
 * (sent on writes: the server refuses cookie-authenticated writes without
 * it), the chosen project (sent on creates, filtering lists) and what to do
 * when the server answers 401 (sign in again). Null members: a server without
 * accounts, or nothing chosen yet.
 */
export const apiContext: {
  csrfToken: string | null;
  projectId: string | null;
  onUnauthorized: ((problem: Problem) => void) | null;
} = { csrfToken: null, projectId: null, onUnauthorized: null };

/** The headers of a request: its body type and, on a write, the CSRF token. */
export function requestHeaders(method: string, hasJsonBody: boolean): Record<string, string> {
  const headers: Record<string, string> = hasJsonBody ? { 'Content-Type': 'application/json' } : {};
  if (method !== 'GET' && method !== 'HEAD' && apiContext.csrfToken) headers['X-CSRF-Token'] = apiContext.csrfToken;
  return headers;
}

/** A create request's body with the chosen project (when there is one and the body names none). */
export function inProject(body: unknown): unknown {
  if (!apiContext.projectId || typeof body !== 'object' || body === null || Array.isArray(body)) return body;
  const b = body as Record<string, unknown>;
  return 'project_id' in b ? b : { ...b, project_id: apiContext.projectId };
}

/** `quiet`: a 401 is the answer asked about (the session check, signing in), not a lost session. */
export async function request<T>(method: string, url: string, body?: unknown, quiet = false): Promise<T> {
  let res: Response;
  try {
    res = await fetch(url, {
      method,
      headers: requestHeaders(method, body !== undefined),
      body: body === undefined ? undefined : JSON.stringify(body),
    });
  } catch {
    throw new ApiError({ status: 0, detail: 'The terraplan server cannot be reached.' });
  }
  if (!res.ok) {
    const problem = await problemOf(res);
    if (res.status === 401 && !quiet) apiContext.onUnauthorized?.(problem);
    throw new ApiError(problem);
  }
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

/**
 * A list's URL: the first page, of the chosen project (`allProjects`: of
 * every project the caller may see).
 */
export function listUrl(path: string, limit = 50, allProjects = false): string {
  const params = new URLSearchParams({ limit: String(limit), offset: '0' });
  if (apiContext.projectId && !allProjects) params.set('project_id', apiContext.projectId);
  return `${path}?${params}`;
}

const list = <T>(path: string, allProjects = false) => request<Page<T>>('GET', listUrl(path, 50, allProjects));

export const api = {
  listDems: (allProjects = false) => list<Dem>('/api/v1/dems', allProjects),
  getDem: (id: string) => request<Dem>('GET', `/api/v1/dems/${id}`),
  deleteDem: (id: string) => request<void>('DELETE', `/api/v1/dems/${id}`),

  listCameras: () => request<{ items: CameraPreset[] }>('GET', '/api/v1/cameras'),
  createSurvey: (body: unknown) => request<Survey>('POST', '/api/v1/surveys', inProject(body)),
  listSurveys: (allProjects = false) => list<SurveySummary>('/api/v1/surveys', allProjects),
  getSurvey: (id: string) => request<Survey>('GET', `/api/v1/surveys/${id}`),
  deleteSurvey: (id: string) => request<void>('DELETE', `/api/v1/surveys/${id}`),

  listVehicles: () => request<{ items: Vehicle[] }>('GET', '/api/v1/vehicles'),
  createCostmap: (body: unknown) => request<Costmap>('POST', '/api/v1/costmaps', inProject(body)),
  listCostmaps: (allProjects = false) => list<Costmap>('/api/v1/costmaps', allProjects),
  getCostmap: (id: string) => request<Costmap>('GET', `/api/v1/costmaps/${id}`),
  deleteCostmap: (id: string) => request<void>('DELETE', `/api/v1/costmaps/${id}`),

  // A route belongs to its costmap's project: no project_id.
  createRoute: (costmapId: string, body: unknown) =>
    request<Route>('POST', `/api/v1/costmaps/${costmapId}/routes`, body),
  replanRoute: (routeId: string, body: unknown) => request<Route>('POST', `/api/v1/routes/${routeId}/replan`, body),
  listRoutes: (allProjects = false) => list<Route>('/api/v1/routes', allProjects),
  getRoute: (id: string) => request<Route>('GET', `/api/v1/routes/${id}`),
  deleteRoute: (id: string) => request<void>('DELETE', `/api/v1/routes/${id}`),
};

/**
 * Uploads a DEM file as the raw body into the chosen project; `crs`
 * ("EPSG:32633") for a file that does not give its own. XMLHttpRequest
 * rather than fetch because only XHR reports upload progress.
 */
export function uploadDem(file: File, name: string, crs: string | null, onProgress: (fraction: number) => void): Promise<Dem> {
  return new Promise((resolve, reject) => {
    const xhr = new XMLHttpRequest();
    const params = new URLSearchParams({ name, file_name: file.name });
    if (crs) params.set('crs', crs);
    if (apiContext.projectId) params.set('project_id', apiContext.projectId);
    xhr.open('POST', `/api/v1/dems?${params}`);
    const type = /\.(tif|tiff)$/i.test(file.name) ? 'image/tiff' : /\.asc$/i.test(file.name) ? 'text/plain' : 'application/octet-stream';
    xhr.setRequestHeader('Content-Type', type);
    for (const [k, v] of Object.entries(requestHeaders('POST', false))) xhr.setRequestHeader(k, v);
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
      if (xhr.status === 401) apiContext.onUnauthorized?.(problem);
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
