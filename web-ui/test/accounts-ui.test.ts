// @vitest-environment jsdom
// The sign-in form, project switcher and members dialog on the real page
// markup (index.html), against a stand-in server (fetch replaced).
import { readFileSync } from 'node:fs';
import path from 'node:path';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import type { Member, Project, Session } from '../src/account-api';
import { apiContext } from '../src/api';
import { MembersDialog } from '../src/members-dialog';
import { ProjectSwitcher } from '../src/projects';
import { SessionUi } from '../src/session';

const EVIL = '<img src=x onerror=alert(1)>';
const html = readFileSync(path.resolve(process.cwd(), 'index.html'), 'utf8');
const body = /<body>([\s\S]*)<\/body>/.exec(html)![1].replace(/<script[\s\S]*?<\/script>/g, '');

interface Call {
  method: string;
  url: string;
  headers: Record<string, string>;
  body: unknown;
}
type Handler = (c: Call) => [number, unknown?];

/** Replaces fetch with `handler`; returns the calls made. */
function server(handler: Handler): Call[] {
  const calls: Call[] = [];
  vi.stubGlobal('fetch', async (url: string, init: RequestInit = {}) => {
    const call = { method: init.method ?? 'GET', url, headers: (init.headers ?? {}) as Record<string, string>, body: init.body ? JSON.parse(init.body as string) : undefined };
    calls.push(call);
    const [status, answer] = handler(call);
    return new Response(status === 204 ? null : JSON.stringify(answer ?? {}), { status, headers: { 'Content-Type': 'application/json' } });
  });
  return calls;
}

const flush = () => new Promise((r) => setTimeout(r, 0));
const $ = <T extends HTMLElement = HTMLElement>(id: string) => document.getElementById(id) as T;
const session = (name: string, id = `u-${name}`): Session => ({ user: { id, name, admin: false }, csrf_token: `csrf-${name}`, personal_project_id: `p-${name}` });
const project = (over: Partial<Project>): Project => ({ id: 'p', name: 'x', personal: false, role: 'owner', created_at: '2026-12-10T10:00:00Z', ...over });
const page = <T>(items: T[]) => ({ items, total: items.length, limit: 100, offset: 0 });

beforeEach(() => {
  document.body.innerHTML = body;
  localStorage.clear();
  Element.prototype.scrollIntoView = () => {};
  vi.stubGlobal('confirm', () => true);
});
afterEach(() => {
  vi.unstubAllGlobals();
  apiContext.csrfToken = null;
  apiContext.projectId = null;
  apiContext.onUnauthorized = null;
});

describe('the sign-in form', () => {
  it('shows on 401, signs in with the user name and password, and keeps the CSRF token', async () => {
    const calls = server((c) => {
      if (c.method === 'GET') return [401, { status: 401, detail: 'sign in first' }];
      const b = c.body as { password?: string };
      return b.password === 'correct horse' ? [201, session('ann')] : [401, { status: 401, detail: 'wrong user name, password or token' }];
    });
    const ui = new SessionUi({ signedInAgain: vi.fn() });
    let signedIn: Session | null | undefined;
    void ui.start().then((s) => (signedIn = s));
    await flush();
    expect($('signin').hidden).toBe(false);
    expect($('panel').closest('main')!.hasAttribute('inert')).toBe(true);
    expect(document.activeElement).toBe($('signin-user'));

    // Nothing typed: said in the form, nothing sent.
    $('signin-form').dispatchEvent(new Event('submit', { cancelable: true }));
    await flush();
    expect($('signin-form-error').textContent).toBe('Give your user name and password, or an API token.');
    expect(calls).toHaveLength(1);

    $<HTMLInputElement>('signin-user').value = 'ann';
    $<HTMLInputElement>('signin-password').value = 'wrong';
    $('signin-form').dispatchEvent(new Event('submit', { cancelable: true }));
    await flush();
    await flush();
    expect($('signin-form-error').textContent).toBe('wrong user name, password or token');
    expect(signedIn).toBeUndefined();

    $<HTMLInputElement>('signin-password').value = 'correct horse';
    $('signin-form').dispatchEvent(new Event('submit', { cancelable: true }));
    await flush();
    await flush();
    expect(calls.at(-1)).toMatchObject({ method: 'POST', url: '/api/v1/session', body: { user: 'ann', password: 'correct horse' } });
    expect(signedIn?.user.name).toBe('ann');
    expect($('signin').hidden).toBe(true);
    expect($('panel').closest('main')!.hasAttribute('inert')).toBe(false);
    expect($<HTMLInputElement>('signin-password').value).toBe('');
    expect(apiContext.csrfToken).toBe('csrf-ann');
    expect($('signed-in-as').textContent).toBe('Signed in as ann');
  });

  it('signs in with an API token alone', async () => {
    const calls = server((c) => (c.method === 'GET' ? [401, { status: 401, detail: '' }] : [201, session('bob')]));
    const ui = new SessionUi({ signedInAgain: vi.fn() });
    const started = ui.start();
    await flush();
    $<HTMLInputElement>('signin-token').value = 'tp_0123456789abcdef_s3cret';
    $('signin-form').dispatchEvent(new Event('submit', { cancelable: true }));
    expect((await started)?.user.name).toBe('bob');
    expect(calls[1].body).toEqual({ token: 'tp_0123456789abcdef_s3cret' });
    expect($<HTMLInputElement>('signin-token').value).toBe('');
  });

  it('goes on without accounts when the server has no session endpoint (404)', async () => {
    server(() => [404, { status: 404, detail: 'no such path' }]);
    const ui = new SessionUi({ signedInAgain: vi.fn() });
    expect(await ui.start()).toBeNull();
    expect($('signin').hidden).toBe(true);
    expect(apiContext.onUnauthorized).toBeNull();
  });

  it('comes back over the page on a later 401, keeping what was typed', async () => {
    let signedIn = true;
    server((c) => {
      if (c.url === '/api/v1/session' && c.method === 'POST') {
        signedIn = true;
        return [201, session('ann')];
      }
      if (c.url === '/api/v1/session') return [200, session('ann')];
      return signedIn ? [200, page([])] : [401, { status: 401, detail: 'sign in first' }];
    });
    const again = vi.fn();
    const ui = new SessionUi({ signedInAgain: again });
    await ui.start();
    $<HTMLInputElement>('survey-name').value = 'field 7';
    signedIn = false;
    const { api } = await import('../src/api');
    await expect(api.listSurveys()).rejects.toThrow('sign in first');
    expect($('signin').hidden).toBe(false);
    expect($('signin-reason').textContent).toMatch(/session has ended/);
    $<HTMLInputElement>('signin-user').value = 'ann';
    $<HTMLInputElement>('signin-password').value = 'correct horse';
    $('signin-form').dispatchEvent(new Event('submit', { cancelable: true }));
    await flush();
    await flush();
    expect($('signin').hidden).toBe(true);
    expect(again).toHaveBeenCalledTimes(1);
    expect(again.mock.calls[0][0].user.name).toBe('ann');
    expect(again.mock.calls[0][1].user.name).toBe('ann');
    expect($<HTMLInputElement>('survey-name').value).toBe('field 7');
  });
});

describe('the project switcher', () => {
  const projects = [project({ id: 'p-ann', name: 'ann', personal: true }), project({ id: 't', name: EVIL, role: 'viewer' })];

  it('lists the projects as text, starts in the personal one and says what a viewer cannot do', async () => {
    server(() => [200, page(projects)]);
    const changed = vi.fn();
    const switcher = new ProjectSwitcher(changed);
    await switcher.load(session('ann'));
    const select = $<HTMLSelectElement>('project-select');
    expect([...select.options].map((o) => o.textContent)).toEqual(['ann (personal)', `${EVIL} (viewer)`]);
    expect(document.querySelector('#account img')).toBeNull();
    expect(select.value).toBe('p-ann');
    expect(apiContext.projectId).toBe('p-ann');
    expect($('account').hidden).toBe(false);
    expect($('project-role').hidden).toBe(true);
    expect(changed).not.toHaveBeenCalled();

    select.value = 't';
    select.dispatchEvent(new Event('change'));
    expect(apiContext.projectId).toBe('t');
    expect(changed).toHaveBeenCalledWith(projects[1]);
    expect($('project-role').textContent).toBe(`You are a viewer in “${EVIL}”: you can open and download its work, but not plan, upload or delete there.`);
    expect(switcher.roleOf('t')).toBe('viewer');

    // The choice is remembered per user.
    const next = new ProjectSwitcher(vi.fn());
    await next.load(session('ann'));
    expect(apiContext.projectId).toBe('t');
  });

  it('makes a project by name (with the CSRF token) and chooses it', async () => {
    apiContext.csrfToken = 'csrf-ann';
    const calls = server((c) => (c.method === 'GET' ? [200, page(projects)] : [201, project({ id: 'new', name: (c.body as { name: string }).name })]));
    const changed = vi.fn();
    const switcher = new ProjectSwitcher(changed);
    await switcher.load(session('ann'));
    $('new-project').click();
    expect($('project-dialog').hidden).toBe(false);
    $('project-form').dispatchEvent(new Event('submit', { cancelable: true }));
    expect($('project-name-error').textContent).toBe('Project name: give the new project a name.');
    $<HTMLInputElement>('project-name').value = '  Field team ';
    $('project-form').dispatchEvent(new Event('submit', { cancelable: true }));
    await flush();
    await flush();
    expect(calls.at(-1)).toEqual({ method: 'POST', url: '/api/v1/projects', headers: { 'Content-Type': 'application/json', 'X-CSRF-Token': 'csrf-ann' }, body: { name: 'Field team' } });
    expect($('project-dialog').hidden).toBe(true);
    expect(document.activeElement).toBe($('project-select'));
    expect($<HTMLSelectElement>('project-select').value).toBe('new');
    expect(apiContext.projectId).toBe('new');
    expect(changed).toHaveBeenCalledTimes(1);
  });
});

describe('the members dialog', () => {
  it('lets owners add, change and remove members, showing the server’s faults', async () => {
    let members: Member[] = [{ user: 'ann', role: 'owner' }];
    const calls = server((c) => {
      if (c.method === 'GET') return [200, page(members)];
      if (c.method === 'DELETE') return [409, { status: 409, detail: 'the project needs an owner: ann is its last one' }];
      const b = c.body as Member;
      if (b.user === 'nobody') return [422, { status: 422, detail: 'invalid', errors: [{ pointer: '/user', message: 'no user nobody' }] }];
      members = [...members.filter((m) => m.user !== b.user), b];
      return [201, b];
    });
    const dialog = new MembersDialog();
    await dialog.open(project({ id: 't', name: 'Field team' }));
    expect($('members').hidden).toBe(false);
    expect($('members-add').hidden).toBe(false);
    expect($('members-project').textContent).toBe('Field team');

    $<HTMLInputElement>('member-user').value = 'nobody';
    $('members-add').dispatchEvent(new Event('submit', { cancelable: true }));
    await vi.waitFor(() => expect($('members-user-error').textContent).toBe('User name: no user nobody'));
    expect($('member-user').getAttribute('aria-invalid')).toBe('true');

    $<HTMLInputElement>('member-user').value = EVIL;
    $<HTMLSelectElement>('member-role').value = 'viewer';
    $('members-add').dispatchEvent(new Event('submit', { cancelable: true }));
    await vi.waitFor(() => expect(document.querySelectorAll('#members-table tbody tr')).toHaveLength(2));
    expect(calls.find((c) => c.method === 'POST' && (c.body as Member).user === EVIL)).toMatchObject({ url: '/api/v1/projects/t/members', body: { role: 'viewer' } });
    expect(document.querySelector('#members-table img')).toBeNull();
    expect($<HTMLInputElement>('member-user').value).toBe('');

    const role = document.querySelector<HTMLSelectElement>(`select[aria-label="Role of ${EVIL}"]`)!;
    role.value = 'editor';
    role.dispatchEvent(new Event('change'));
    await vi.waitFor(() => expect(members.find((m) => m.user === EVIL)?.role).toBe('editor'));

    document.querySelector<HTMLButtonElement>('button[aria-label="Remove ann"]')!.click();
    await vi.waitFor(() => expect($('members-form-error').textContent).toBe('the project needs an owner: ann is its last one'));
    expect(calls.filter((c) => c.method === 'DELETE').map((c) => c.url)).toEqual(['/api/v1/projects/t/members/ann']);
    // The list is the server's again: ann is still the owner.
    await vi.waitFor(() => expect(document.querySelector<HTMLSelectElement>('select[aria-label="Role of ann"]')!.value).toBe('owner'));
  });

  it('only lists the members for others', async () => {
    server(() => [200, page([{ user: 'ann', role: 'owner' }, { user: 'bob', role: 'viewer' }])]);
    await new MembersDialog().open(project({ id: 't', role: 'viewer' }));
    await vi.waitFor(() => expect(document.querySelectorAll('#members-table tbody tr')).toHaveLength(2));
    expect($('members-add').hidden).toBe(true);
    expect(document.querySelector('#members-table select, #members-table button')).toBeNull();
  });
});
