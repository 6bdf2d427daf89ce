// The logic of "Send to vehicle" (vehicle-upload.ts): which vehicle links the
// server allows (GET /api/v1/vehicle-links), the address chosen from them,
// the request sent to POST /api/v1/surveys/{id}/uavs/{uav}/upload, its
// Server-Sent Events read from the answer as they arrive, and the progress
// and messages shown.
import { ApiError, apiContext, requestHeaders, type Problem } from './api';

/** One entry of the server's `--vehicle-links`. */
export interface VehicleLinkEntry {
  /** `udpout:HOST:PORT`, or a pattern whose port is `LO-HI` or `*`. */
  address: string;
  /** It names one address; otherwise a port in its range must be chosen. */
  exact: boolean;
}
export interface VehicleLinks {
  enabled: boolean;
  addresses: VehicleLinkEntry[];
}

export const VEHICLE_LINKS_URL = '/api/v1/vehicle-links';

/** What the page knows when the server is older than vehicle links, or refuses: none. */
export const LINKS_OFF: VehicleLinks = { enabled: false, addresses: [] };

/** The links the server allows; off when it cannot tell (older server, network fault). */
export async function fetchVehicleLinks(fetchFn: typeof fetch = fetch): Promise<VehicleLinks> {
  try {
    const res = await fetchFn(VEHICLE_LINKS_URL, { headers: requestHeaders('GET', false) });
    if (!res.ok) return LINKS_OFF;
    const v = (await res.json()) as Partial<VehicleLinks>;
    if (v.enabled !== true || !Array.isArray(v.addresses)) return LINKS_OFF;
    return { enabled: true, addresses: v.addresses.filter((a) => typeof a.address === 'string') };
  } catch {
    return LINKS_OFF;
  }
}

/** The port part of an entry: a range (`*` is 1-65535 for hosts, any baud rate for serial). */
export function portRange(entry: VehicleLinkEntry): { lo: number; hi: number } | null {
  if (entry.exact) return null;
  const tail = entry.address.slice(entry.address.lastIndexOf(':') + 1);
  if (tail === '*') return { lo: 1, hi: entry.address.startsWith('serial:') ? 4_000_000 : 65535 };
  const m = /^(\d+)-(\d+)$/.exec(tail);
  return m ? { lo: Number(m[1]), hi: Number(m[2]) } : null;
}

/** What the port field is called for an entry: a baud rate for a serial device. */
export function portLabel(entry: VehicleLinkEntry): string {
  return entry.address.startsWith('serial:') ? 'Baud rate' : 'Port';
}

/**
 * The address to send for an entry and the port typed for it (ignored for an
 * exact entry); a message naming the fault when the port is missing or out of
 * the entry's range.
 */
export function chosenAddress(entry: VehicleLinkEntry, portText: string): { address: string } | { fault: string } {
  const range = portRange(entry);
  if (!range) return { address: entry.address };
  const what = portLabel(entry).toLowerCase();
  const text = portText.trim();
  const port = Number(text);
  if (text === '' || !Number.isInteger(port) || port < range.lo || port > range.hi) {
    return { fault: `Give the ${what}: a whole number from ${range.lo} to ${range.hi} (${entry.address}).` };
  }
  const head = entry.address.slice(0, entry.address.lastIndexOf(':'));
  return { address: `${head}:${port}` };
}

export function uploadUrl(surveyId: string, uav: string): string {
  return `/api/v1/surveys/${encodeURIComponent(surveyId)}/uavs/${encodeURIComponent(uav)}/upload`;
}

/** The upload request: the sortie only for a UAV that flies several. */
export function uploadBody(to: string, sortie: number | null, fence: boolean, rally: boolean): Record<string, unknown> {
  const body: Record<string, unknown> = { to, fence, rally };
  if (sortie !== null) body.sortie = sortie;
  return body;
}

export type ListKind = 'mission' | 'fence' | 'rally';
/** One event of the upload's stream (the server's UploadEvent). */
export interface UploadEvent {
  event: 'started' | 'progress' | 'verified' | 'done' | 'failed';
  to: string;
  lists?: { kind: ListKind; items: number }[];
  kind?: ListKind;
  stage?: 'upload' | 'read_back';
  done?: number;
  total?: number;
  sent?: { kind: ListKind; items: number }[];
  error?: string;
}

/**
 * Splits Server-Sent Events text as it arrives: the whole events in
 * `buffer` (their `data:` parsed as JSON; comments and keep-alives skipped)
 * and the unfinished rest, to be completed by the next chunk.
 */
export function takeEvents(buffer: string): { events: UploadEvent[]; rest: string } {
  const text = buffer.replace(/\r\n?/g, '\n');
  const blocks = text.split('\n\n');
  const rest = blocks.pop() ?? '';
  const events: UploadEvent[] = [];
  for (const block of blocks) {
    const data = block
      .split('\n')
      .filter((l) => l.startsWith('data:'))
      .map((l) => l.slice(5).replace(/^ /, ''));
    if (!data.length) continue;
    try {
      events.push(JSON.parse(data.join('\n')) as UploadEvent);
    } catch {
      /* not ours: skipped */
    }
  }
  return { events, rest };
}

/** What the page shows of an upload. */
export interface UploadView {
  /** 0 to 1: items sent and read back over twice the items of every list. */
  fraction: number;
  /** One line: what happens now, or how it ended. */
  status: string;
  /** The error of a failed upload, to be shown as such. */
  error: string | null;
  finished: boolean;
  /** Per list: items sent and read back so far, and its size. */
  lists: { kind: ListKind; items: number; sent: number; readBack: number; verified: boolean }[];
}

export const UPLOAD_START: UploadView = { fraction: 0, status: 'Connecting…', error: null, finished: false, lists: [] };

const listName = (kind: ListKind) => (kind === 'mission' ? 'Mission' : kind === 'fence' ? 'Fence' : 'Rally points');

/** "37 mission items", "1 rally point". */
export function countText(kind: ListKind, n: number): string {
  const noun = kind === 'rally' ? 'rally point' : `${kind} item`;
  return `${n} ${noun}${n === 1 ? '' : 's'}`;
}

/** The view after one more event. */
export function nextView(view: UploadView, ev: UploadEvent): UploadView {
  const lists = view.lists.map((l) => ({ ...l }));
  const list = lists.find((l) => l.kind === ev.kind);
  let status = view.status;
  switch (ev.event) {
    case 'started': {
      const named = (ev.lists ?? []).map((l) => ({ kind: l.kind, items: l.items, sent: 0, readBack: 0, verified: false }));
      const what = named.map((l) => countText(l.kind, l.items)).join(', ');
      return { ...view, lists: named, status: `Sending ${what} to ${ev.to}…`, fraction: 0 };
    }
    case 'progress':
      if (list && ev.done !== undefined) {
        if (ev.stage === 'read_back') list.readBack = ev.done;
        else list.sent = ev.done;
        const doing = ev.stage === 'read_back' ? 'reading back' : 'uploading';
        status = `${listName(list.kind)}: ${doing} ${ev.done} of ${ev.total ?? list.items}`;
      }
      break;
    case 'verified':
      if (list) {
        list.sent = list.items;
        list.readBack = list.items;
        list.verified = true;
        status = `${listName(list.kind)}: read back and verified (${countText(list.kind, list.items)})`;
      }
      break;
    case 'done': {
      const sent = (ev.sent ?? []).map((l) => countText(l.kind, l.items)).join(', ');
      return { ...view, lists: lists.map((l) => ({ ...l, sent: l.items, readBack: l.items, verified: true })), fraction: 1, finished: true, error: null, status: `Sent to ${ev.to} and verified: ${sent}.` };
    }
    case 'failed':
      return { ...view, lists, finished: true, error: ev.error ?? 'the upload failed', status: 'The upload failed.' };
  }
  const total = lists.reduce((n, l) => n + 2 * l.items, 0);
  const done = lists.reduce((n, l) => n + l.sent + l.readBack, 0);
  return { ...view, lists, status, fraction: total > 0 ? done / total : 0 };
}

/** A refusal as the page shows it: the server's detail, and each fault when it names several. */
export function refusalText(problem: Problem): string {
  const faults = problem.errors ?? [];
  if (faults.length > 1) return `${problem.detail}: ${faults.map((f) => f.message).join('; ')}`;
  return problem.detail;
}

/** An answer that is no event stream: the problem the server gave, or one from its status. */
async function problemOf(res: Response): Promise<Problem> {
  const text = await res.text();
  try {
    const p = JSON.parse(text) as Problem;
    if (typeof p.detail === 'string') return { ...p, status: res.status };
  } catch {
    /* not JSON */
  }
  return { status: res.status, detail: text || res.statusText || `HTTP ${res.status}` };
}

/**
 * Sends the upload and follows its event stream, calling `onView` after each
 * event; resolves with the last view. A refusal before it starts (403 not an
 * allowed address, 409 busy, 422 a bad member…) rejects with the server's
 * ApiError. `signal` stops it (the server then stops the upload too).
 */
export async function sendToVehicle(
  surveyId: string,
  uav: string,
  body: Record<string, unknown>,
  onView: (view: UploadView) => void,
  signal?: AbortSignal,
  fetchFn: typeof fetch = fetch,
): Promise<UploadView> {
  let res: Response;
  try {
    res = await fetchFn(uploadUrl(surveyId, uav), {
      method: 'POST',
      headers: requestHeaders('POST', true),
      body: JSON.stringify(body),
      signal,
    });
  } catch {
    throw new ApiError({ status: 0, detail: 'The terraplan server cannot be reached.' });
  }
  if (!res.ok || !res.body) {
    const problem = await problemOf(res);
    if (res.status === 401) apiContext.onUnauthorized?.(problem);
    throw new ApiError(problem);
  }
  let view = UPLOAD_START;
  onView(view);
  const reader = res.body.getReader();
  const decoder = new TextDecoder();
  let buffer = '';
  try {
    for (;;) {
      const { value, done } = await reader.read();
      if (done) break;
      buffer += decoder.decode(value, { stream: true });
      const taken = takeEvents(buffer);
      buffer = taken.rest;
      for (const ev of taken.events) {
        view = nextView(view, ev);
        onView(view);
      }
    }
  } catch {
    // The connection broke (or was stopped): said below.
  }
  if (!view.finished) {
    view = { ...view, finished: true, error: signal?.aborted ? 'stopped: the upload was cancelled' : 'lost contact with the server before the upload ended', status: 'The upload did not finish.' };
    onView(view);
  }
  return view;
}
