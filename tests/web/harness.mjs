// What the browser viewer's tests share: free loopback ports, irradcast-server with --http-port
// (started and stopped by the test), headless Chromium through puppeteer-core (the system's
// /usr/bin/chromium with SwiftShader's WebGL), irradcast-view's PNG of the same camera, and the
// protocol's messages (proto/irradcast.proto) for checking what the server answers.
import { spawn, execFile } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, createWriteStream } from 'node:fs';
import net from 'node:net';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { createRequire } from 'node:module';

const here = path.dirname(fileURLToPath(import.meta.url));
const web = path.join(here, '..', '..', 'web');
const require = createRequire(path.join(web, 'package.json'));
const puppeteer = require('puppeteer-core');
const protobuf = require('protobufjs');

export const root = protobuf.parse(readFileSync(path.join(here, '..', '..', 'proto', 'irradcast.proto'), 'utf8'),
  { keepCase: true }).root;
export const Envelope = root.lookupType('irradcast.wire.Envelope');
export const ErrorCode = root.lookupEnum('irradcast.wire.ErrorCode').values;

// --server EXE --view EXE --edit EXE --chromium EXE, then the case name.
export function options(argv) {
  const o = { chromium: '/usr/bin/chromium', cases: [] };
  for (let i = 2; i < argv.length; ++i) {
    if (argv[i].startsWith('--')) o[argv[i].slice(2)] = argv[++i];
    else o.cases.push(argv[i]);
  }
  for (const k of ['server', 'view']) if (!o[k]) throw new Error(`--${k} EXE is required`);
  return o;
}

export const tmp = mkdtempSync(path.join(os.tmpdir(), 'irradcast-web-'));
process.on('exit', () => { if (!process.env.IRRADCAST_KEEP_TMP) rmSync(tmp, { recursive: true, force: true }); });

export function freePort() {
  return new Promise((resolve, reject) => {
    const s = net.createServer();
    s.on('error', reject);
    s.listen(0, '127.0.0.1', () => { const { port } = s.address(); s.close(() => resolve(port)); });
  });
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// Servers still running when the test ends (a failure skipped its stop()) are killed with it.
const running = new Set();
process.on('exit', () => { for (const p of running) p.kill('SIGKILL'); });

// irradcast-server on loopback with a TCP port and an HTTP port (free ones unless `ports` names
// them: { port, http }, a server started again where another was); resolves once GET / answers.
export async function startServer(exe, args, name = 'server', ports = {}) {
  const port = ports.port ?? await freePort(), http = ports.http ?? await freePort();
  const log = path.join(tmp, `${name}.log`);
  const out = createWriteStream(log);
  const proc = spawn(exe, ['--bind', '127.0.0.1', '--port', String(port), '--http-port', String(http), ...args],
    { stdio: ['ignore', 'pipe', 'pipe'] });
  proc.stdout.pipe(out);
  proc.stderr.pipe(out);
  let exited = null, exitCode = null;
  running.add(proc);
  proc.on('exit', (code, sig) => { exited = `exit ${code} ${sig || ''}`; exitCode = code; running.delete(proc); });
  for (let i = 0; i < 600; ++i) {
    if (exited) throw new Error(`${name} stopped (${exited}): ${readFileSync(log, 'utf8')}`);
    try {
      const r = await fetch(`http://127.0.0.1:${http}/`);
      if (r.ok) break;
    } catch (_) { /* not listening yet */ }
    await sleep(100);
  }
  return {
    port, http, log, url: `http://127.0.0.1:${http}/`,
    // SIGTERM: the server stops cleanly and exits 0 (under ASan also without leaks or errors).
    async stop() {
      if (!exited) {
        const done = new Promise((r) => proc.on('exit', r));
        proc.kill('SIGTERM');
        const t = setTimeout(() => proc.kill('SIGKILL'), 20000);
        await done;
        clearTimeout(t);
      }
      if (exitCode !== 0) throw new Error(`${name} ended with ${exited}: ${readFileSync(log, 'utf8').slice(-4000)}`);
    },
  };
}

export function run(exe, args, timeoutMs = 120000) {
  return new Promise((resolve, reject) => {
    execFile(exe, args, { timeout: timeoutMs }, (err, stdout, stderr) => {
      if (err) reject(new Error(`${path.basename(exe)} ${args.join(' ')}: ${err.message}\n${stdout}${stderr}`));
      else resolve(stdout + stderr);
    });
  });
}

// irradcast-view's converged PNG (the engine idle: --converge-at far below any reachable value).
export async function viewPng(o, server, { width, height, camera, tonemap, exposure, extra }, name) {
  const out = path.join(tmp, `${name}.png`);
  const args = ['--connect', `127.0.0.1:${server.port}`, '--width', String(width), '--height', String(height),
    '--until-converged', '--converge-at', '1e-9', '--timeout', '60', '--cache-dir', 'none', '--out', out];
  if (camera) args.push('--camera', camera);
  if (tonemap) args.push('--tonemap', tonemap);
  if (exposure !== undefined) args.push('--exposure', String(exposure));
  if (extra) args.push(...extra);
  await run(o.view, args);
  return out;
}

export const chromiumArgs = ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
  '--ignore-gpu-blocklist', '--no-first-run', '--disable-background-timer-throttling',
  '--disable-renderer-backgrounding', '--disable-backgrounding-occluded-windows'];

export async function browser(o) {
  return puppeteer.launch({ executablePath: o.chromium, headless: true, userDataDir: mkdtempSync(path.join(tmp, 'profile-')),
    args: ['--headless=new', ...chromiumArgs], protocolTimeout: 600000 });
}

// What a page that did not converge was waiting for (main.js frame()'s conditions), for the
// failure's message (page.evaluate(pageState)).
export function pageState() {
  const irr = window.irradcast;
  if (!irr) return `no viewer: ${document.body.innerText}`;
  const { conn, state } = irr;
  return JSON.stringify({ text: document.body.innerText, hidden: document.hidden, phase: conn.phase,
    socket: conn.ws && conn.ws.readyState, status: state.status, held: conn.tilesHeld(), counters: conn.counters,
    dirty: state.dirty, view: !!state.view, statsAsked: state.statsAsked, stats: state.stats },
    (_, v) => (typeof v === 'bigint' ? String(v) : v));
}

// Opens the page and waits for "irradcast: converged"; page errors fail the test.
export async function openConverged(b, url, width, height, timeout = 60000) {
  const page = await b.newPage();
  const problems = [];
  page.on('pageerror', (e) => problems.push(e.message));
  await page.setViewport({ width, height });
  await page.goto(url);
  try {
    await page.waitForFunction(() => document.title === 'irradcast: converged', { timeout, polling: 100 });
  } catch (e) {
    const state = await page.evaluate(pageState).catch(() => '?');
    throw new Error(`${url} did not converge: ${e.message}; page: ${state}; errors: ${problems.join('; ')}`);
  }
  if (problems.length) throw new Error(`${url}: page errors: ${problems.join('; ')}`);
  return page;
}

export function query(params) {
  return '?' + Object.entries(params).map(([k, v]) => `${k}=${encodeURIComponent(v)}`).join('&');
}

export { tmp as tmpDir, path };
