// @vitest-environment jsdom
// "Send to vehicle": the address chosen from the server's vehicle links, the
// request, the event stream read in arbitrary chunks, the progress and
// messages shown (vehicle-upload-model.ts), and the button and its form on a
// survey's downloads (vehicle-upload.ts).
import { afterEach, describe, expect, it, vi } from 'vitest';
import { ApiError, apiContext, type Survey } from '../src/api';
import { VehicleUpload } from '../src/vehicle-upload';
import {
  LINKS_OFF,
  UPLOAD_START,
  chosenAddress,
  countText,
  fetchVehicleLinks,
  nextView,
  portRange,
  refusalText,
  sendToVehicle,
  takeEvents,
  uploadBody,
  uploadUrl,
  type UploadEvent,
  type UploadView,
} from '../src/vehicle-upload-model';

const TO = 'udpout:127.0.0.1:14550';
const sse = (ev: UploadEvent) => `event: ${ev.event}\ndata: ${JSON.stringify(ev)}\n\n`;
const STREAM: UploadEvent[] = [
  { event: 'started', to: TO, lists: [{ kind: 'mission', items: 4 }, { kind: 'fence', items: 2 }] },
  { event: 'progress', to: TO, kind: 'mission', stage: 'upload', done: 0, total: 4 },
  { event: 'progress', to: TO, kind: 'mission', stage: 'upload', done: 4, total: 4 },
  { event: 'progress', to: TO, kind: 'mission', stage: 'read_back', done: 2, total: 4 },
  { event: 'verified', to: TO, kind: 'mission', done: 4, total: 4 },
  { event: 'progress', to: TO, kind: 'fence', stage: 'upload', done: 2, total: 2 },
  { event: 'verified', to: TO, kind: 'fence', done: 2, total: 2 },
  { event: 'done', to: TO, sent: [{ kind: 'mission', items: 4 }, { kind: 'fence', items: 2 }] },
];

/** An event-stream answer delivered in chunks of `size` characters (cutting events and lines). */
function streamAnswer(text: string, size: number): Response {
  const bytes = new TextEncoder().encode(text);
  const body = new ReadableStream<Uint8Array>({
    start(c) {
      for (let i = 0; i < bytes.length; i += size) c.enqueue(bytes.slice(i, i + size));
      c.close();
    },
  });
  return new Response(body, { status: 200, headers: { 'Content-Type': 'text/event-stream' } });
}

const problem = (status: number, detail: string, errors: { pointer: string; message: string }[] = []) =>
  new Response(JSON.stringify({ type: 'about:blank', title: 'x', status, detail, errors }), { status, headers: { 'Content-Type': 'application/problem+json' } });

afterEach(() => {
  apiContext.csrfToken = null;
  apiContext.onUnauthorized = null;
  vi.restoreAllMocks();
  document.body.replaceChildren();
});

describe('the address', () => {
  it('is the entry itself when exact, else the entry with the port typed', () => {
    expect(chosenAddress({ address: TO, exact: true }, 'ignored')).toEqual({ address: TO });
    const range = { address: 'udpout:10.0.0.5:14550-14560', exact: false };
    expect(portRange(range)).toEqual({ lo: 14550, hi: 14560 });
    expect(chosenAddress(range, ' 14555 ')).toEqual({ address: 'udpout:10.0.0.5:14555' });
    const any = { address: 'tcpout:[::1]:*', exact: false };
    expect(chosenAddress(any, '5760')).toEqual({ address: 'tcpout:[::1]:5760' });
  });

  it('names the fault of a missing or out-of-range port', () => {
    const range = { address: 'udpout:10.0.0.5:14550-14560', exact: false };
    for (const typed of ['', '14561', '14549', '1.5', 'x']) {
      const got = chosenAddress(range, typed);
      expect('fault' in got && got.fault).toContain('from 14550 to 14560');
    }
    const serial = chosenAddress({ address: 'serial:/dev/ttyACM0:*', exact: false }, '');
    expect('fault' in serial && serial.fault).toContain('baud rate');
  });
});

describe('the request', () => {
  it('names the survey and UAV, and the sortie only when given', () => {
    expect(uploadUrl('s 1', 'u/1')).toBe('/api/v1/surveys/s%201/uavs/u%2F1/upload');
    expect(uploadBody(TO, null, true, false)).toEqual({ to: TO, fence: true, rally: false });
    expect(uploadBody(TO, 2, false, true)).toEqual({ to: TO, fence: false, rally: true, sortie: 2 });
  });
});

describe('the event stream', () => {
  it('is split into whole events, the rest kept for the next chunk', () => {
    const text = STREAM.slice(0, 2).map(sse).join('') + ': keep-alive\n\n' + sse(STREAM[2]).slice(0, 20);
    const { events, rest } = takeEvents(text.replace(/\n/g, '\r\n'));
    expect(events).toEqual(STREAM.slice(0, 2));
    expect(rest).toBe(sse(STREAM[2]).slice(0, 20));
  });

  it('moves the bar by items sent and read back, and ends verified', () => {
    const views: UploadView[] = [];
    let view = UPLOAD_START;
    for (const ev of STREAM) views.push((view = nextView(view, ev)));
    expect(views[0].status).toBe(`Sending 4 mission items, 2 fence items to ${TO}…`);
    // 12 steps in all: 4 + 4 of the mission, 2 + 2 of the fence.
    expect(views[2].fraction).toBeCloseTo(4 / 12, 12);
    expect(views[3].status).toBe('Mission: reading back 2 of 4');
    expect(views[3].fraction).toBeCloseTo(6 / 12, 12);
    expect(views[4].fraction).toBeCloseTo(8 / 12, 12);
    expect(views[4].status).toBe('Mission: read back and verified (4 mission items)');
    const fractions = views.map((v) => v.fraction);
    expect(fractions).toEqual([...fractions].sort((a, b) => a - b));
    expect(view).toMatchObject({ fraction: 1, finished: true, error: null, status: `Sent to ${TO} and verified: 4 mission items, 2 fence items.` });
  });

  it('ends with the error of a failed event', () => {
    let view = nextView(UPLOAD_START, STREAM[0]);
    view = nextView(view, { event: 'failed', to: TO, kind: 'fence', error: `${TO}: fence upload: the vehicle answered MAV_MISSION_NO_SPACE (…)` });
    expect(view.finished).toBe(true);
    expect(view.error).toContain('MAV_MISSION_NO_SPACE');
    expect(view.status).toBe('The upload failed.');
  });
});

describe('sending', () => {
  it('posts the body with the CSRF token and follows the stream in any chunking', async () => {
    apiContext.csrfToken = 'csrf-1';
    for (const size of [1, 7, 64, 100_000]) {
      const fetchFn = vi.fn(async (_url: RequestInfo | URL, _init?: RequestInit) => streamAnswer(STREAM.map(sse).join(''), size));
      const seen: UploadView[] = [];
      const last = await sendToVehicle('s1', 'u1', uploadBody(TO, null, true, false), (v) => seen.push(v), undefined, fetchFn as typeof fetch);
      expect(last.finished && last.fraction).toBe(1);
      expect(seen.length).toBe(STREAM.length + 1);
      const [url, init] = fetchFn.mock.calls[0];
      expect(url).toBe('/api/v1/surveys/s1/uavs/u1/upload');
      expect(init?.method).toBe('POST');
      expect((init?.headers as Record<string, string>)['X-CSRF-Token']).toBe('csrf-1');
      expect(JSON.parse(init?.body as string)).toEqual({ to: TO, fence: true, rally: false });
    }
  });

  it('rejects with the server problem when refused before starting', async () => {
    const detail = 'udpout:10.9.9.9:14550 is not one of the vehicle links this service may reach (serve --vehicle-links): udpout:127.0.0.1:*';
    const fetchFn = vi.fn(async () => problem(403, detail));
    const err = await sendToVehicle('s1', 'u1', {}, () => {}, undefined, fetchFn as unknown as typeof fetch).catch((e: unknown) => e);
    expect(err).toBeInstanceOf(ApiError);
    expect((err as ApiError).problem.status).toBe(403);
    expect(refusalText((err as ApiError).problem)).toBe(detail);
  });

  it('says so when the stream ends without an outcome', async () => {
    const fetchFn = vi.fn(async () => streamAnswer(STREAM.slice(0, 3).map(sse).join(''), 50));
    const last = await sendToVehicle('s1', 'u1', {}, () => {}, undefined, fetchFn as unknown as typeof fetch);
    expect(last.finished).toBe(true);
    expect(last.error).toContain('lost contact');
  });

  it('counts items and rally points in words', () => {
    expect(countText('mission', 37)).toBe('37 mission items');
    expect(countText('fence', 1)).toBe('1 fence item');
    expect(countText('rally', 1)).toBe('1 rally point');
    expect(countText('rally', 2)).toBe('2 rally points');
  });

  it('lists several faults of a 422', () => {
    const text = refusalText({ status: 422, detail: '2 problems in the request; see errors', errors: [{ pointer: '/sortie', message: 'a' }, { pointer: '/to', message: 'b' }] });
    expect(text).toBe('2 problems in the request; see errors: a; b');
  });
});

describe('the links the server allows', () => {
  it('are off for an older server or a fault', async () => {
    expect(await fetchVehicleLinks((async () => problem(404, 'no')) as unknown as typeof fetch)).toEqual(LINKS_OFF);
    expect(await fetchVehicleLinks((async () => { throw new TypeError('down'); }) as unknown as typeof fetch)).toEqual(LINKS_OFF);
    const on = { enabled: true, addresses: [{ address: TO, exact: true }] };
    expect(await fetchVehicleLinks((async () => new Response(JSON.stringify(on))) as unknown as typeof fetch)).toEqual(on);
  });
});

describe('the button on the downloads', () => {
  const survey = {
    id: 's1',
    uavs: [
      { id: 'u1', sorties: [{ number: 1, files: { rally: '/r' } }] },
      { id: 'u2', sorties: [{ number: 1, files: {} }, { number: 2, files: {} }] },
    ],
  } as unknown as Survey;

  function downloads(): HTMLUListElement {
    const ul = document.createElement('ul');
    for (const [uav, sortie] of [['u1', 1], ['u2', 1], ['u2', 2]] as const) {
      const li = document.createElement('li');
      li.dataset.uav = uav;
      li.dataset.sortie = String(sortie);
      ul.append(li);
    }
    document.body.append(ul);
    return ul;
  }

  const links = (addresses: { address: string; exact: boolean }[]) => new Response(JSON.stringify({ enabled: addresses.length > 0, addresses }));

  it('is not shown when the server has no vehicle links', async () => {
    const ul = downloads();
    await new VehicleUpload((async () => links([])) as unknown as typeof fetch).attach(ul, survey);
    expect(ul.querySelectorAll('.send-vehicle').length).toBe(0);
  });

  it('sends the sortie to the address picked, with a progress bar, and shows a refusal', async () => {
    const ul = downloads();
    const calls: { url: string; body: unknown }[] = [];
    const fetchFn = vi.fn(async (url: RequestInfo | URL, init?: RequestInit) => {
      if (String(url) === '/api/v1/vehicle-links') return links([{ address: 'udpout:127.0.0.1:14550-14560', exact: false }, { address: TO, exact: true }]);
      calls.push({ url: String(url), body: JSON.parse(init?.body as string) });
      if (calls.length === 1) return streamAnswer(STREAM.map(sse).join(''), 33);
      return problem(409, `${TO} is busy: another upload to it is running; retry when it has ended`);
    });
    await new VehicleUpload(fetchFn as unknown as typeof fetch).attach(ul, survey);
    const buttons = [...ul.querySelectorAll<HTMLButtonElement>('.send-vehicle')];
    expect(buttons.map((b) => b.getAttribute('aria-label'))).toEqual(['Send u1 to vehicle', 'Send u2 to vehicle (sortie 1)', 'Send u2 to vehicle (sortie 2)']);
    buttons[2].click();
    const form = ul.querySelectorAll('li')[2].querySelector('form')!;
    const port = form.querySelector<HTMLInputElement>('input[type=number]')!;
    // The range entry is first: a port must be typed.
    expect(port.closest('label')!.hidden).toBe(false);
    port.value = '14570';
    form.requestSubmit();
    const error = form.querySelector<HTMLElement>('.error')!;
    expect(error.hidden).toBe(false);
    expect(error.textContent).toContain('from 14550 to 14560');
    expect(calls.length).toBe(0);
    // The exact entry: no port; the rally box is hidden for a sortie without rally points.
    const select = form.querySelector('select')!;
    select.value = '1';
    select.dispatchEvent(new Event('change'));
    expect(port.closest('label')!.hidden).toBe(true);
    expect(form.querySelector<HTMLInputElement>('input[id$=rally]')!.closest('label')!.hidden).toBe(true);
    form.requestSubmit();
    const progress = form.querySelector('progress')!;
    await vi.waitFor(() => expect(progress.value).toBe(1));
    expect(error.hidden).toBe(true);
    expect(form.querySelector('.upload-status')!.textContent).toBe(`Sent to ${TO} and verified: 4 mission items, 2 fence items.`);
    expect(calls[0]).toEqual({ url: '/api/v1/surveys/s1/uavs/u2/upload', body: { to: TO, fence: true, rally: false, sortie: 2 } });
    // Again: the server refuses (busy), and says why.
    await vi.waitFor(() => expect(form.querySelector<HTMLButtonElement>('button[type=submit]')!.disabled).toBe(false));
    form.requestSubmit();
    await vi.waitFor(() => expect(error.textContent).toContain('is busy'));
    expect(error.hidden).toBe(false);
  });
});
