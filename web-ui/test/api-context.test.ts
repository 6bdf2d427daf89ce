import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { accounts } from '../src/account-api';
import { api, apiContext, ApiError, inProject, listUrl, requestHeaders, uploadDem } from '../src/api';

interface Call {
  url: string;
  method: string;
  headers: Record<string, string>;
  body: unknown;
}

/** Replaces fetch: records each call and answers `status` with `answer`. */
function fakeFetch(status: number, answer: unknown = {}): Call[] {
  const calls: Call[] = [];
  vi.stubGlobal('fetch', async (url: string, init: RequestInit) => {
    calls.push({
      url,
      method: init.method ?? 'GET',
      headers: (init.headers ?? {}) as Record<string, string>,
      body: init.body === undefined ? undefined : JSON.parse(init.body as string),
    });
    const text = status === 204 ? null : JSON.stringify(answer);
    return new Response(text, { status, headers: { 'Content-Type': 'application/json' } });
  });
  return calls;
}

beforeEach(() => {
  apiContext.csrfToken = 'csrf-123';
  apiContext.projectId = 'p-1';
  apiContext.onUnauthorized = null;
});
afterEach(() => {
  vi.unstubAllGlobals();
  apiContext.csrfToken = null;
  apiContext.projectId = null;
  apiContext.onUnauthorized = null;
});

describe('requestHeaders', () => {
  it('sends the CSRF token on writes only', () => {
    expect(requestHeaders('GET', false)).toEqual({});
    expect(requestHeaders('POST', true)).toEqual({ 'Content-Type': 'application/json', 'X-CSRF-Token': 'csrf-123' });
    expect(requestHeaders('DELETE', false)).toEqual({ 'X-CSRF-Token': 'csrf-123' });
  });

  it('sends none without a session (a server without accounts)', () => {
    apiContext.csrfToken = null;
    expect(requestHeaders('DELETE', false)).toEqual({});
  });
});

describe('project context', () => {
  it('puts the chosen project into create bodies, keeping one named there', () => {
    expect(inProject({ name: 'a' })).toEqual({ name: 'a', project_id: 'p-1' });
    expect(inProject({ name: 'a', project_id: 'p-2' })).toEqual({ name: 'a', project_id: 'p-2' });
    apiContext.projectId = null;
    expect(inProject({ name: 'a' })).toEqual({ name: 'a' });
  });

  it('filters lists by the chosen project unless all are asked for', () => {
    expect(listUrl('/api/v1/surveys')).toBe('/api/v1/surveys?limit=50&offset=0&project_id=p-1');
    expect(listUrl('/api/v1/surveys', 50, true)).toBe('/api/v1/surveys?limit=50&offset=0');
    apiContext.projectId = null;
    expect(listUrl('/api/v1/dems', 10)).toBe('/api/v1/dems?limit=10&offset=0');
  });
});

describe('requests', () => {
  it('creates in the chosen project with the CSRF token', async () => {
    const calls = fakeFetch(201, { id: 's-1' });
    await api.createSurvey({ name: 'field 7' });
    expect(calls).toEqual([
      { url: '/api/v1/surveys', method: 'POST', headers: { 'Content-Type': 'application/json', 'X-CSRF-Token': 'csrf-123' }, body: { name: 'field 7', project_id: 'p-1' } },
    ]);
  });

  it('sends no project with a route: it belongs to its costmap’s project', async () => {
    const calls = fakeFetch(201, { id: 'r-1' });
    await api.createRoute('c-1', { start: [0, 0], goal: [1, 1] });
    expect(calls[0].body).toEqual({ start: [0, 0], goal: [1, 1] });
    expect(calls[0].headers['X-CSRF-Token']).toBe('csrf-123');
  });

  it('deletes with the CSRF token', async () => {
    const calls = fakeFetch(204);
    await api.deleteSurvey('s-1');
    expect(calls[0]).toMatchObject({ url: '/api/v1/surveys/s-1', method: 'DELETE', headers: { 'X-CSRF-Token': 'csrf-123' } });
  });

  it('asks to sign in again on a 401, and throws the problem', async () => {
    fakeFetch(401, { status: 401, detail: 'sign in first' });
    const lost = vi.fn();
    apiContext.onUnauthorized = lost;
    await expect(api.listSurveys()).rejects.toThrow(ApiError);
    expect(lost).toHaveBeenCalledTimes(1);
    expect(lost.mock.calls[0][0]).toMatchObject({ status: 401, detail: 'sign in first' });
  });

  it('does not on the session check or a refused sign-in (401 is their answer)', async () => {
    fakeFetch(401, { status: 401, detail: 'wrong user name, password or token' });
    const lost = vi.fn();
    apiContext.onUnauthorized = lost;
    await expect(accounts.getSession()).rejects.toThrow('wrong user name, password or token');
    await expect(accounts.signIn({ user: 'ann', password: 'x' })).rejects.toThrow(ApiError);
    expect(lost).not.toHaveBeenCalled();
  });

  it('manages members with the CSRF token, user names escaped in the path', async () => {
    const calls = fakeFetch(201, { user: 'bo/b', role: 'viewer' });
    await accounts.setMember('p 1', 'bo/b', 'viewer');
    await accounts.removeMember('p-1', 'bo/b');
    expect(calls[0]).toEqual({
      url: '/api/v1/projects/p%201/members',
      method: 'POST',
      headers: { 'Content-Type': 'application/json', 'X-CSRF-Token': 'csrf-123' },
      body: { user: 'bo/b', role: 'viewer' },
    });
    expect(calls[1]).toMatchObject({ url: '/api/v1/projects/p-1/members/bo%2Fb', method: 'DELETE', headers: { 'X-CSRF-Token': 'csrf-123' } });
  });
});

/** A stand-in XMLHttpRequest: records what the upload sets and answers `status`. */
class FakeXhr {
  static last: FakeXhr | null = null;
  static status = 201;
  static answer = '{"id":"d-1"}';
  url = '';
  headers: Record<string, string> = {};
  status = 0;
  responseText = '';
  statusText = '';
  upload = { onprogress: null as ((e: unknown) => void) | null };
  onload: (() => void) | null = null;
  onerror: (() => void) | null = null;
  constructor() {
    FakeXhr.last = this;
  }
  open(_method: string, url: string) {
    this.url = url;
  }
  setRequestHeader(k: string, v: string) {
    this.headers[k] = v;
  }
  send() {
    this.status = FakeXhr.status;
    this.responseText = FakeXhr.answer;
    queueMicrotask(() => this.onload?.());
  }
}

describe('uploadDem', () => {
  it('uploads into the chosen project with the CSRF token', async () => {
    vi.stubGlobal('XMLHttpRequest', FakeXhr);
    FakeXhr.status = 201;
    FakeXhr.answer = '{"id":"d-1"}';
    const file = new File([new Uint8Array(4)], 'dtm.tif');
    const dem = await uploadDem(file, 'dtm', null, () => {});
    expect(dem.id).toBe('d-1');
    const sent = new URL(FakeXhr.last!.url, 'http://x');
    expect(sent.pathname).toBe('/api/v1/dems');
    expect(sent.searchParams.get('project_id')).toBe('p-1');
    expect(FakeXhr.last!.headers).toEqual({ 'Content-Type': 'image/tiff', 'X-CSRF-Token': 'csrf-123' });
  });

  it('asks to sign in again when the upload is refused with 401', async () => {
    vi.stubGlobal('XMLHttpRequest', FakeXhr);
    FakeXhr.status = 401;
    FakeXhr.answer = '{"status":401,"detail":"sign in first"}';
    const lost = vi.fn();
    apiContext.onUnauthorized = lost;
    await expect(uploadDem(new File(['x'], 'a.asc'), 'a', null, () => {})).rejects.toThrow('sign in first');
    expect(lost).toHaveBeenCalledTimes(1);
  });
});
