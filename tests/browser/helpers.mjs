// Shared set-up of the browser tests: a real `terraplan serve` on a free port
// with a throwaway data directory and the built page, and Debian's Chromium
// driven headless by playwright-core (Playwright's own browser download does
// not work here).

import { spawn, spawnSync } from 'node:child_process';
import { before, after } from 'node:test';
import { mkdtempSync, mkdirSync, rmSync, existsSync } from 'node:fs';
import { createRequire } from 'node:module';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import readline from 'node:readline';

export const ROOT = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..');
export const DTM = path.resolve(ROOT, '../shared/data/dems/opengeos_data__elevation_dtm.tif');
export const SCREENSHOTS = path.join(ROOT, 'target/browser-screenshots');
// `TERRAPLAN_BIN=/path/to/terraplan` tests another build (e.g. one from before accounts).
const BINARY = process.env.TERRAPLAN_BIN ?? path.join(ROOT, 'target/debug/terraplan');
const WEB_DIR = path.join(ROOT, 'web-ui/dist');
const CHROMIUM = process.env.CHROMIUM ?? '/usr/bin/chromium';

// playwright-core is a dev dependency of the web UI.
const require = createRequire(path.join(ROOT, 'web-ui/package.json'));
const { chromium } = require('playwright-core');

/** Fails early with a clear message when something the tests need is missing. */
export function checkPrerequisites() {
  if (!existsSync(BINARY)) throw new Error(`${BINARY} is missing: run \`cargo build -p terraplan\``);
  if (!existsSync(path.join(WEB_DIR, 'index.html'))) throw new Error(`${WEB_DIR} is missing: run \`npm run build\` in web-ui/`);
  if (!existsSync(CHROMIUM)) throw new Error(`${CHROMIUM} is missing: \`apt-get install -y chromium\``);
}

/** Whether this terraplan has accounts (`terraplan user …`); servers from before answer without credentials. */
export function serverHasAccounts() {
  return spawnSync(BINARY, ['user', '--help'], { encoding: 'utf8' }).status === 0;
}

/** Makes a user with `terraplan user create` on the data dir (before `serve`); its API token is stdout's last line. */
function createUser(dataDir, name, password) {
  const r = spawnSync(BINARY, ['user', 'create', name, '--data-dir', dataDir, '--password-stdin'], { input: `${password}\n`, encoding: 'utf8' });
  if (r.status !== 0) throw new Error(`terraplan user create ${name} failed (${r.status}): ${r.stderr}`);
  const token = r.stdout.trim().split('\n').pop().trim();
  if (!token.startsWith('tp_')) throw new Error(`terraplan user create ${name}: the last line is not a token: ${r.stdout}`);
  return { name, password, token };
}

const TEMP_DIRS = [];

/** A temporary directory (downloads, files to import), removed after the calling file's tests. */
export function tempDir(prefix) {
  const dir = mkdtempSync(path.join(tmpdir(), prefix));
  TEMP_DIRS.push(dir);
  return dir;
}

/** The servers started here, by URL: the page signs in as their first user. */
const SERVERS = new Map();

/**
 * Starts `terraplan serve --port 0`; resolves once it prints where it
 * listens. On a terraplan with accounts it first makes `users` (the first
 * one is the tests' default user: `server.fetch` calls the API as it, and
 * `openPage` signs the page in as it). `server.users[name]` has each one's
 * `password` and `token`. `args`: more arguments of `serve`.
 */
export async function startServer({ users = ['tester'], args = [] } = {}) {
  checkPrerequisites();
  const dataDir = mkdtempSync(path.join(tmpdir(), 'terraplan-browser-'));
  const accounts = serverHasAccounts();
  const made = {};
  if (accounts) for (const name of users) made[name] = createUser(dataDir, name, `${name}-browser-password`);
  const proc = spawn(BINARY, ['serve', '--port', '0', '--data-dir', dataDir, '--web-dir', WEB_DIR, ...args], {
    cwd: ROOT,
    stdio: ['ignore', 'pipe', 'pipe'],
  });
  let stderr = '';
  proc.stderr.on('data', (d) => (stderr += d));
  const url = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`terraplan did not start in 30 s:\n${stderr}`)), 30_000);
    const lines = readline.createInterface({ input: proc.stdout });
    lines.once('line', (line) => {
      clearTimeout(timer);
      const m = /listening on (http:\/\/\S+)/.exec(line);
      if (m) resolve(m[1]);
      else reject(new Error(`unexpected first line: ${line}\n${stderr}`));
    });
    proc.once('exit', (code) => reject(new Error(`terraplan exited (${code}):\n${stderr}`)));
  });
  const server = {
    url,
    dataDir,
    accounts,
    users: made,
    defaultUser: accounts ? made[users[0]] : null,
    /** The API as a user (default: the first), with its token (none on a server without accounts). */
    fetch(apiPath, init = {}, as = users[0]) {
      const headers = { ...(init.headers ?? {}) };
      if (accounts) headers.Authorization = `Bearer ${made[as].token}`;
      return fetch(`${url}${apiPath}`, { ...init, headers });
    },
    async stop() {
      proc.kill('SIGTERM');
      await new Promise((r) => (proc.exitCode !== null ? r() : proc.once('exit', r)));
      SERVERS.delete(url);
      rmSync(dataDir, { recursive: true, force: true });
    },
  };
  SERVERS.set(url, server);
  return server;
}

/**
 * A test file's server and browser: started before its tests, closed after
 * them (node:test hooks of the calling file). Read `env.server` and
 * `env.browser` inside the tests.
 */
export function withServerAndBrowser(options) {
  const env = {};
  before(async () => {
    env.server = await startServer(options);
    env.browser = await launchBrowser();
  });
  after(async () => {
    await env.browser?.close();
    await env.server?.stop();
    for (const dir of TEMP_DIRS.splice(0)) rmSync(dir, { recursive: true, force: true });
  });
  return env;
}

export async function launchBrowser() {
  return chromium.launch({ executablePath: CHROMIUM, headless: true, args: ['--no-sandbox', '--disable-gpu'] });
}

/**
 * Opens the page and waits until its lists are loaded and the map has drawn.
 * On a server with accounts the page is signed in first, as `signIn` (a
 * user of the server; default its first), through the API: the browser
 * keeps the session cookie. `signIn: null`: not signed in, the page waits
 * at its sign-in form.
 */
export async function openPage(browser, url, viewport = { width: 1280, height: 800 }, { signIn } = {}) {
  const context = await browser.newContext({ viewport, acceptDownloads: true });
  const server = SERVERS.get(url);
  const user = signIn === undefined ? server?.defaultUser : signIn;
  if (server?.accounts && user) {
    const res = await context.request.post(`${url}/api/v1/session`, { data: { user: user.name, password: user.password } });
    if (res.status() !== 201) throw new Error(`signing in as ${user.name}: ${res.status()} ${await res.text()}`);
  }
  const page = await context.newPage();
  const problems = [];
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('console', (m) => {
    if (m.type() !== 'error') return;
    // A server from before accounts answers the page's session check with 404: the page then goes on without.
    if (!server?.accounts && m.location().url.endsWith('/api/v1/session')) return;
    problems.push(`console: ${m.text()}`);
  });
  // No request may leave the local server (the page must work offline).
  const outside = [];
  page.on('request', (r) => {
    if (!r.url().startsWith(url) && !r.url().startsWith('data:') && !r.url().startsWith('blob:')) outside.push(r.url());
  });
  await page.goto(url);
  await page.waitForSelector(server?.accounts && !user ? '#signin-form' : 'body[data-ready="true"]');
  return { page, context, problems, outside };
}

/** Clicks the map at a lon/lat point, with a real mouse click. */
export async function clickLonLat(page, lon, lat) {
  const px = await page.evaluate(([lo, la]) => window.terraplan.pixelFor(lo, la), [lon, lat]);
  if (!px) throw new Error('the map has no size yet');
  await page.mouse.click(px[0], px[1]);
  // Clicks closer than OpenLayers' 250 ms double-click window would be read as a double-click.
  await page.waitForTimeout(300);
}

/** Draws a polygon after pressing a button: clicks each corner, then the first one to finish. */
export async function drawPolygon(page, buttonSelector, corners) {
  await page.click(buttonSelector);
  for (const [lon, lat] of corners) await clickLonLat(page, lon, lat);
  await clickLonLat(page, corners[0][0], corners[0][1]);
}

/** Uploads the DTM through the page's file input and waits for it to be chosen. */
export async function uploadDtm(page) {
  await page.setInputFiles('#dem-file', DTM);
  await page.waitForFunction(() => document.querySelector('#dem-select').value !== '', null, { timeout: 30_000 });
  // The hillshade is the base layer: wait for the map to draw it.
  await page.waitForTimeout(500);
}

export async function screenshot(page, name) {
  mkdirSync(SCREENSHOTS, { recursive: true });
  const file = path.join(SCREENSHOTS, `${name}.png`);
  await page.screenshot({ path: file, fullPage: false });
  return file;
}

/** Loads a mission with pymavlink (tests/validators/load_waypoints.py) and returns its JSON. */
export function loadWaypoints(file) {
  const python = path.join(ROOT, '.venv/bin/python');
  const r = spawnSync(python, [path.join(ROOT, 'tests/validators/load_waypoints.py'), file], { encoding: 'utf8' });
  if (r.status !== 0) throw new Error(`load_waypoints.py failed (${r.status}): ${r.stderr}`);
  return JSON.parse(r.stdout);
}

/**
 * Counts, per colour, the map pixels close to it across the map's canvases
 * (so a test can tell that lines of that colour were really drawn).
 */
export async function countMapPixels(page, colours) {
  return page.evaluate((cols) => {
    const rgb = cols.map((c) => {
      const m = /^#?([\da-f]{2})([\da-f]{2})([\da-f]{2})$/i.exec(c.trim());
      if (m) return [1, 2, 3].map((i) => parseInt(m[i], 16));
      const n = /rgb\((\d+),\s*(\d+),\s*(\d+)/.exec(c);
      return n ? [1, 2, 3].map((i) => Number(n[i])) : [0, 0, 0];
    });
    const counts = cols.map(() => 0);
    for (const canvas of document.querySelectorAll('#map canvas')) {
      const ctx = canvas.getContext('2d');
      if (!ctx || !canvas.width) continue;
      const { data } = ctx.getImageData(0, 0, canvas.width, canvas.height);
      for (let i = 0; i < data.length; i += 4) {
        if (data[i + 3] < 200) continue;
        rgb.forEach(([r, g, b], k) => {
          if (Math.abs(data[i] - r) < 24 && Math.abs(data[i + 1] - g) < 24 && Math.abs(data[i + 2] - b) < 24) counts[k]++;
        });
      }
    }
    return counts;
  }, colours);
}
