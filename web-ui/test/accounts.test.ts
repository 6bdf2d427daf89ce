import { describe, expect, it } from 'vitest';
import { canEdit, canManage, type Project } from '../src/account-api';
import { ApiError } from '../src/api';
import { chooseProject, projectLabel, roleNote } from '../src/projects';
import { checkFromError, signInCredentials } from '../src/session';

const project = (over: Partial<Project>): Project => ({ id: 'p', name: 'field team', personal: false, role: 'owner', created_at: '2026-12-10T10:00:00Z', ...over });

describe('signInCredentials', () => {
  it('signs in with a user name and password', () => {
    expect(signInCredentials(' ann ', 'correct horse', '')).toEqual({ credentials: { user: 'ann', password: 'correct horse' } });
  });

  it('keeps the password as typed (spaces are part of it)', () => {
    expect(signInCredentials('ann', ' pass word ', '')).toEqual({ credentials: { user: 'ann', password: ' pass word ' } });
  });

  it('signs in with an API token alone', () => {
    expect(signInCredentials('', '', ' tp_0123456789abcdef_secret \n')).toEqual({ credentials: { token: 'tp_0123456789abcdef_secret' } });
  });

  it('says what is missing', () => {
    expect(signInCredentials('', '', '')).toEqual({ error: 'Give your user name and password, or an API token.' });
    expect(signInCredentials('ann', '', '')).toEqual({ error: 'Give the password of ann.' });
    expect(signInCredentials('', 'secret12', '')).toEqual({ error: 'Give your user name with the password.' });
    expect(signInCredentials('ann', 'secret12', 'tp_x')).toEqual({ error: 'Give either a user name and password or an API token, not both.' });
  });
});

describe('checkFromError', () => {
  it('shows the form on 401 and goes on without accounts on 404', () => {
    expect(checkFromError(new ApiError({ status: 401, detail: 'sign in' }))).toEqual({ kind: 'signed-out' });
    expect(checkFromError(new ApiError({ status: 404, detail: 'no route' }))).toEqual({ kind: 'no-accounts' });
  });
});

describe('roles', () => {
  it('lets editors and owners write, owners manage', () => {
    expect([canEdit('viewer'), canEdit('editor'), canEdit('owner'), canEdit(null)]).toEqual([false, true, true, false]);
    expect([canManage('viewer'), canManage('editor'), canManage('owner'), canManage(undefined)]).toEqual([false, false, true, false]);
  });
});

describe('projects', () => {
  it('labels a project with whose it is and the caller’s role', () => {
    expect(projectLabel(project({ personal: true, name: 'ann' }))).toBe('ann (personal)');
    expect(projectLabel(project({}))).toBe('field team');
    expect(projectLabel(project({ role: 'viewer' }))).toBe('field team (viewer)');
  });

  it('starts with the project chosen last, else the personal one, else the first', () => {
    const list = [project({ id: 'a' }), project({ id: 'me', personal: true }), project({ id: 'b' })];
    expect(chooseProject(list, 'b', 'me')?.id).toBe('b');
    expect(chooseProject(list, 'gone', 'me')?.id).toBe('me');
    expect(chooseProject(list, null, 'unknown')?.id).toBe('a');
    expect(chooseProject([], 'b', 'me')).toBeNull();
  });

  it('tells viewers what they cannot do', () => {
    expect(roleNote(project({ role: 'viewer' }))).toMatch(/^You are a viewer in “field team”: .*not plan, upload or delete/);
    expect(roleNote(project({ role: 'editor' }))).toBe('');
    expect(roleNote(null)).toBe('');
  });
});
