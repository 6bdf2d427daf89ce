// Accounts in the browser: sign in with the form, make a project and switch
// between projects, share a survey read-only with another user who signs in
// with an API token, opens it and cannot delete it; a lost session brings the
// form back without losing what was typed; sign out. Users are made with
// `terraplan user create` before the server starts.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { withServerAndBrowser, openPage, screenshot, DTM } from './helpers.mjs';

const env = withServerAndBrowser({ users: ['alice', 'bob'] });

// A survey name written as markup: the page must show it as these characters.
const EVIL = '<img src=x onerror=alert(1)> field';
const ROI = { type: 'Polygon', coordinates: [[[-77.0550, 38.8090], [-77.0527, 38.8090], [-77.0527, 38.8114], [-77.0550, 38.8114], [-77.0550, 38.8090]]] };

/** The API's JSON answer as `as`, asserting the status. */
async function call(path, init, status, as = 'alice') {
  const res = await env.server.fetch(path, init, as);
  const text = await res.text();
  assert.equal(res.status, status, `${init?.method ?? 'GET'} ${path} as ${as}: ${res.status} ${text}`);
  return text ? JSON.parse(text) : null;
}
const json = (method, body) => ({ method, headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) });

/** The page's errors, less the 401 of the session check before signing in (and `also`). */
const unexpected = (problems, also = /$^/) => problems.filter((p) => !/status of 401/.test(p) && !also.test(p));

/** Fills the sign-in form's fields by their labels and presses "Sign in". */
async function submitSignIn(page, fields) {
  const form = page.locator('#signin-form');
  for (const [label, value] of Object.entries(fields)) await form.getByLabel(label, { exact: true }).fill(value);
  await form.getByRole('button', { name: 'Sign in' }).click();
}

async function signInWithForm(page, fields) {
  await submitSignIn(page, fields);
  await page.waitForSelector('body[data-ready="true"]');
}

test('sign in with the form, switch projects, share a survey read-only', async (t) => {
  if (!env.server.accounts) return t.skip('this terraplan has no accounts yet (`terraplan user` is missing)');
  const { alice, bob } = env.server.users;

  // ---- alice signs in with her user name and password ----
  const a = await openPage(env.browser, env.server.url, undefined, { signIn: null });
  let alerts = 0;
  a.page.on('dialog', (d) => {
    if (d.type() === 'alert') alerts++;
    void d.accept();
  });
  assert.equal(await a.page.locator('#signin').isVisible(), true);
  assert.equal(await a.page.locator('#account').isVisible(), false);
  await screenshot(a.page, 'accounts-sign-in-form');
  // A wrong password is refused, in the form.
  await submitSignIn(a.page, { 'User name': 'alice', Password: 'not her password' });
  await a.page.locator('#signin-form-error').waitFor({ state: 'visible' });
  assert.equal(await a.page.textContent('#signin-form-error'), 'wrong user name, password or token');
  await signInWithForm(a.page, { 'User name': 'alice', Password: alice.password });
  assert.equal(await a.page.locator('#signin').isVisible(), false);
  assert.equal(await a.page.textContent('#signed-in-as'), 'Signed in as alice');
  const session = await call('/api/v1/session', {}, 200);
  assert.equal(await a.page.inputValue('#project-select'), session.personal_project_id, 'starts in the personal project');

  // ---- a new project, chosen at once; a DEM uploaded through the page goes into it ----
  await a.page.click('#new-project');
  await a.page.getByLabel('Project name').fill('Field team');
  await a.page.click('#project-create');
  await a.page.waitForFunction(() => document.querySelector('#project-dialog').hidden);
  const team = (await call('/api/v1/projects?limit=100', {}, 200)).items.find((p) => p.name === 'Field team');
  assert.ok(team, 'the project was made');
  assert.equal(team.role, 'owner');
  assert.equal(await a.page.inputValue('#project-select'), team.id);
  await a.page.setInputFiles('#dem-file', DTM);
  await a.page.waitForFunction(() => document.querySelector('#dem-select').value !== '', null, { timeout: 30_000 });
  const dems = (await call(`/api/v1/dems?project_id=${team.id}`, {}, 200)).items;
  assert.equal(dems.length, 1, 'the upload went into the chosen project');
  assert.equal(dems[0].project_id, team.id);
  assert.equal((await call(`/api/v1/dems?project_id=${session.personal_project_id}`, {}, 200)).items.length, 0);

  // A survey in the team project, one in alice's own.
  const survey = await call('/api/v1/surveys', json('POST', { name: EVIL, roi: ROI, project_id: team.id, dem_id: dems[0].id }), 201);
  await call('/api/v1/surveys', json('POST', { name: 'private field', roi: ROI }), 201);

  // ---- switching projects switches the lists ----
  await a.page.click('#tab-saved');
  await a.page.waitForSelector('#saved-surveys li strong');
  assert.deepEqual(await a.page.locator('#saved-surveys li strong').allTextContents(), [EVIL]);
  assert.equal(await a.page.locator('#saved-surveys img').count(), 0, 'the name is text, not an image');
  await a.page.selectOption('#project-select', session.personal_project_id);
  await a.page.waitForFunction(() => document.querySelector('#saved-surveys li strong')?.textContent === 'private field');
  assert.equal(await a.page.locator('#saved-surveys li').count(), 1);
  assert.equal(await a.page.locator('#saved-dems li').textContent(), 'None yet.');
  // All projects at once, each item naming its project.
  await a.page.check('#saved-all-projects');
  await a.page.waitForFunction(() => document.querySelectorAll('#saved-surveys li').length === 2);
  assert.match(await a.page.locator('#saved-surveys li', { hasText: 'onerror' }).locator('small').textContent(), /· project Field team$/);
  await a.page.uncheck('#saved-all-projects');
  await a.page.selectOption('#project-select', team.id);
  await a.page.waitForFunction(() => document.querySelectorAll('#saved-surveys li').length === 1 && /onerror/.test(document.querySelector('#saved-surveys li strong').textContent));

  // ---- share it read-only with bob ----
  await a.page.click('#members-open');
  await a.page.waitForSelector('#members-table tbody tr');
  assert.deepEqual(await a.page.locator('#members-table tbody th').allTextContents(), ['alice']);
  // An unknown user: the server's fault, next to the field.
  const dialog = a.page.locator('#members');
  await dialog.getByLabel('User name', { exact: true }).fill('nobody-here');
  await a.page.click('#member-add');
  await a.page.locator('#members-user-error').waitFor({ state: 'visible' });
  assert.match(await a.page.textContent('#members-user-error'), /^User name: /);
  await dialog.getByLabel('User name', { exact: true }).fill('bob');
  await dialog.getByLabel('Role', { exact: true }).selectOption('viewer');
  await a.page.click('#member-add');
  await a.page.waitForFunction(() => document.querySelectorAll('#members-table tbody tr').length === 2);
  assert.equal(await a.page.getByLabel('Role of bob').inputValue(), 'viewer');
  await screenshot(a.page, 'accounts-members');
  await a.page.click('#members-close');
  const members = (await call(`/api/v1/projects/${team.id}/members`, {}, 200)).items;
  assert.deepEqual(members.map((m) => [m.user, m.role]).sort(), [['alice', 'owner'], ['bob', 'viewer']]);

  // ---- bob signs in with his API token, opens the survey, cannot delete it ----
  const b = await openPage(env.browser, env.server.url, undefined, { signIn: null });
  b.page.on('dialog', (d) => {
    if (d.type() === 'alert') alerts++;
    void d.accept();
  });
  await signInWithForm(b.page, { 'API token': bob.token });
  assert.equal(await b.page.textContent('#signed-in-as'), 'Signed in as bob');
  const label = await b.page.locator(`#project-select option[value="${team.id}"]`).textContent();
  assert.equal(label, 'Field team (viewer)');
  await b.page.selectOption('#project-select', team.id);
  assert.match(await b.page.textContent('#project-role'), /^You are a viewer in “Field team”/);
  await b.page.click('#tab-saved');
  await b.page.waitForSelector('#saved-surveys li strong');
  assert.deepEqual(await b.page.locator('#saved-surveys li strong').allTextContents(), [EVIL]);
  assert.equal(await b.page.locator('#saved-surveys button.danger').count(), 0, 'no Delete for a viewer');
  assert.match(await b.page.locator('#saved-surveys li').textContent(), /view only/);
  await b.page.getByRole('button', { name: `Open ${EVIL}` }).click();
  await b.page.waitForSelector('#survey-results:not([hidden])');
  assert.equal(await b.page.inputValue('#survey-name'), EVIL);
  assert.equal(await b.page.inputValue('#dem-select'), dems[0].id, 'the survey’s DEM comes with it');
  await screenshot(b.page, 'accounts-viewer-opened');
  // The API refuses the delete too, naming the role needed; the survey is still there for both.
  const refused = await call(`/api/v1/surveys/${survey.id}`, { method: 'DELETE' }, 403, 'bob');
  assert.match(refused.detail, /editor/);
  await call(`/api/v1/surveys/${survey.id}`, {}, 200, 'bob');
  await call(`/api/v1/surveys/${survey.id}`, {}, 200, 'alice');
  // bob sees nothing of alice's own project.
  assert.equal(await b.page.locator(`#project-select option[value="${session.personal_project_id}"]`).count(), 0);

  assert.equal(alerts, 0, 'no script ran from a name');
  assert.deepEqual(unexpected(a.problems, /422/), []);
  assert.deepEqual(unexpected(b.problems), []);
  assert.deepEqual([...a.outside, ...b.outside], []);
  await a.context.close();
  await b.context.close();
});

test('a lost session brings the form back over the page, keeping what was typed; sign out', async (t) => {
  if (!env.server.accounts) return t.skip('this terraplan has no accounts yet (`terraplan user` is missing)');
  const { page, context, problems } = await openPage(env.browser, env.server.url);
  await page.fill('#survey-name', 'kept while signing in again');
  await page.fill('#speed', '7');

  // The session ends behind the page's back (as when it expires).
  const csrf = (await (await context.request.get(`${env.server.url}/api/v1/session`)).json()).csrf_token;
  const ended = await context.request.delete(`${env.server.url}/api/v1/session`, { headers: { 'X-CSRF-Token': csrf } });
  assert.equal(ended.status(), 204);
  await page.click('#tab-saved');
  await page.locator('#signin').waitFor({ state: 'visible' });
  assert.match(await page.textContent('#signin-reason'), /session has ended/);
  await submitSignIn(page, { 'User name': 'alice', Password: env.server.users.alice.password });
  await page.locator('#signin').waitFor({ state: 'hidden' });
  await page.click('#saved-refresh');
  await page.waitForFunction(() => document.querySelector('#saved-status').textContent === '');
  assert.equal(await page.locator('#saved-form-error').isVisible(), false);
  await page.click('#tab-survey');
  assert.equal(await page.inputValue('#survey-name'), 'kept while signing in again');
  assert.equal(await page.inputValue('#speed'), '7');
  assert.equal(await page.inputValue('#signin-password'), '', 'the password does not stay in the page');

  // Sign out: the session is gone and the form is back.
  await page.click('#sign-out');
  await page.locator('#signin').waitFor({ state: 'visible' });
  assert.equal((await context.request.get(`${env.server.url}/api/v1/session`)).status(), 401);
  assert.deepEqual(unexpected(problems), []);
  await context.close();
});
