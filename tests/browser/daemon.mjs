// Helpers shared by the browser tests and the browser benchmark: a brickcastd started on a
// throw-away config (its own temporary folder, so nothing touches the user's cache), a plain TCP
// protocol client for direct renders, Chromium through playwright-core, and image comparison.
//
// Environment:
//   BRICKCASTD    the daemon binary (default: ../../build/tools/brickcastd from this file)
//   BRICKCAST     the command-line tool, for `brickcast ingest` (default: ../../build/tools/brickcast)
//   BC_CHROMIUM   the Chromium binary (default: /usr/bin/chromium)
//   BC_WEB_DIR    serve the page's own files (web/: index.html, js/, style.css) from this folder
//                 instead of the copies compiled into brickcastd, for trying edits of web/
//                 without rebuilding the daemon (useWebDir); unset: the daemon's own files

import { execFile, spawn } from 'node:child_process';
import { mkdtemp, readFile, rm, writeFile } from 'node:fs/promises';
import { once } from 'node:events';
import net from 'node:net';
import tls from 'node:tls';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { promisify } from 'node:util';
import {
  Type, Codec, Quality, FrameMode, HEADER_BYTES, decode, decodeHeader, encode, errorName,
} from '../../web/js/protocol.js';

const here = path.dirname(fileURLToPath(import.meta.url));
export const BRICKCASTD = process.env.BRICKCASTD || path.resolve(here, '../../build/tools/brickcastd');
export const CHROMIUM = process.env.BC_CHROMIUM || '/usr/bin/chromium';
export const BRICKCAST = process.env.BRICKCAST || path.resolve(here, '../../build/tools/brickcast');

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** A temporary folder, removed by the returned cleanup. */
export async function tempDir(prefix = 'bc-browser-') {
  return mkdtemp(path.join(os.tmpdir(), prefix));
}

/** TOML for one [[volume]] per entry of `volumes`: {name, generate, dims} or {name, store} (a .bcs file). */
export function configToml({ storeDir, token = '', volumes, frames = {}, webHosts = [], tlsFiles = null }) {
  const q = (s) => JSON.stringify(String(s)); // TOML basic strings accept JSON's escapes
  const lines = [
    '[server]',
    'listen = "127.0.0.1:0"',
    `token = ${q(token)}`,
    `store_dir = ${q(storeDir)}`,
    'web = "auto"',
    `web_hosts = [${webHosts.map(q).join(', ')}]`,
  ];
  if (tlsFiles) lines.push(`tls_cert = ${q(tlsFiles.cert)}`, `tls_key = ${q(tlsFiles.key)}`);
  const frameKeys = Object.entries(frames);
  if (frameKeys.length) lines.push('', '[frames]', ...frameKeys.map(([k, v]) => `${k} = ${v}`));
  for (const v of volumes) {
    lines.push('', '[[volume]]', `name = ${q(v.name)}`);
    if (v.store) lines.push(`store = ${q(v.store)}`);
    else lines.push(`generate = ${q(v.generate)}`, `dims = [${v.dims.join(', ')}]`);
  }
  return lines.join('\n') + '\n';
}

export const DEFAULT_VOLUMES = Object.freeze([
  { name: 'phantom', generate: 'phantom', dims: [96, 96, 96] },
  { name: 'vessels', generate: 'vessels', dims: [64, 64, 64] },
]);

async function waitForFile(file, child, what, timeoutMs) {
  const deadline = Date.now() + timeoutMs;
  for (;;) {
    try {
      const text = (await readFile(file, 'utf8')).trim();
      if (/^\d+$/.test(text)) return Number(text);
    } catch (e) {
      if (e.code !== 'ENOENT') throw e;
    }
    if (child.exitCode !== null || child.signalCode !== null) {
      throw new Error(`brickcastd exited (${child.exitCode ?? child.signalCode}) before writing its ${what} port file`);
    }
    if (Date.now() > deadline) throw new Error(`brickcastd wrote no ${what} port file within ${timeoutMs} ms`);
    await sleep(50);
  }
}

/**
 * A self-signed certificate for 127.0.0.1 and localhost in `dir` (openssl req), valid a day:
 * {cert, key} paths.
 */
export async function selfSignedCertificate(dir) {
  const cert = path.join(dir, 'cert.pem');
  const key = path.join(dir, 'key.pem');
  await promisify(execFile)('openssl', ['req', '-x509', '-newkey', 'rsa:2048', '-nodes', '-days', '1',
    '-keyout', key, '-out', cert, '-subj', '/CN=127.0.0.1',
    '-addext', 'subjectAltName=IP:127.0.0.1,DNS:localhost']);
  return { cert, key };
}

/**
 * Starts brickcastd. Options: token, volumes, storeDir (shared between daemons to ingest once;
 * default a fresh temporary folder), web ('auto' or '127.0.0.1:PORT'), frames ({key: value} for
 * [frames]), webHosts (server.web_hosts), tls (true: both addresses speak TLS with a fresh
 * self-signed certificate), startTimeoutMs. Resolves once both port files are written:
 * {port, webPort, url, log(), stop(), kill(), dir, configFile, ca (the certificate's PEM, with tls)}.
 */
export async function startDaemon({
  token = '', volumes = DEFAULT_VOLUMES, storeDir, web = 'auto', frames = {}, webHosts = [], tls: withTls = false,
  startTimeoutMs = 60000,
} = {}) {
  const dir = await tempDir('bc-daemon-');
  const store = storeDir ?? path.join(dir, 'stores');
  const configFile = path.join(dir, 'brickcastd.toml');
  const tlsFiles = withTls ? await selfSignedCertificate(dir) : null;
  await writeFile(configFile, configToml({ storeDir: store, token, volumes, frames, webHosts, tlsFiles }));
  const portFile = path.join(dir, 'port');
  const webPortFile = path.join(dir, 'web-port');
  const args = ['--config', configFile, '--listen', '127.0.0.1:0', '--port-file', portFile,
    '--web', web, '--web-port-file', webPortFile];
  const child = spawn(BRICKCASTD, args, { stdio: ['ignore', 'pipe', 'pipe'] });
  let log = '';
  child.stdout.setEncoding('utf8').on('data', (s) => { log += s; });
  child.stderr.setEncoding('utf8').on('data', (s) => { log += s; });
  const spawnError = once(child, 'spawn').then(() => null, (e) => e);
  const err = await spawnError;
  if (err) {
    await rm(dir, { recursive: true, force: true });
    throw new Error(`cannot start ${BRICKCASTD}: ${err.message} (set BRICKCASTD)`);
  }

  const exited = new Promise((resolve) => child.once('exit', (code, signal) => resolve({ code, signal })));
  const daemon = {
    dir, configFile, storeDir: store, child, exited,
    log: () => log,
    /** SIGTERM and wait for the exit; returns {code, signal}. */
    async stop(timeoutMs = 20000) {
      if (child.exitCode === null && child.signalCode === null) {
        child.kill('SIGTERM');
        const timer = setTimeout(() => child.kill('SIGKILL'), timeoutMs);
        const r = await exited;
        clearTimeout(timer);
        return r;
      }
      return exited;
    },
    /** SIGKILL and wait for the exit. */
    async kill() {
      if (child.exitCode === null && child.signalCode === null) child.kill('SIGKILL');
      return exited;
    },
    /** Stops the daemon and removes its folder (and the store folder when it is its own). */
    async dispose() {
      await daemon.stop();
      await rm(dir, { recursive: true, force: true });
    },
  };
  try {
    daemon.webPort = await waitForFile(webPortFile, child, 'web', startTimeoutMs);
    daemon.port = await waitForFile(portFile, child, 'protocol', startTimeoutMs);
  } catch (e) {
    await daemon.dispose();
    throw new Error(`${e.message}\n--- brickcastd log ---\n${log}`);
  }
  daemon.url = `${tlsFiles ? 'https' : 'http'}://127.0.0.1:${daemon.webPort}/`;
  if (tlsFiles) daemon.ca = await readFile(tlsFiles.cert, 'utf8');
  return daemon;
}

/**
 * Makes a brick store of a raw volume with `brickcast ingest` (args: the ingest options, e.g.
 * ['--dims', '256,256,113', '--type', 'u16']); resolves with the store's path.
 */
export async function ingestRaw(input, output, args = []) {
  try {
    await promisify(execFile)(BRICKCAST, ['ingest', input, '-o', output, '-q', ...args], { maxBuffer: 1 << 20 });
  } catch (e) {
    throw new Error(`${BRICKCAST} ingest ${input} failed (set BRICKCAST): ${e.stderr || e.message}`);
  }
  return output;
}

// ---- a plain TCP protocol client ---------------------------------------------------------------

/** One TCP session speaking protocol.js's messages: request(), waitFor(), close(). */
export class TcpClient {
  /** ca: speak TLS, trusting this PEM (the daemon's self-signed certificate). */
  static async connect(port, { host = '127.0.0.1', token = '', software = 'browser-test', ca = null } = {}) {
    const socket = ca ? tls.connect({ port, host, ca }) : net.connect({ port, host });
    await once(socket, ca ? 'secureConnect' : 'connect');
    socket.setNoDelay(true);
    const c = new TcpClient(socket);
    c.send(Type.Hello, { versionMin: 1, versionMax: 1, capabilities: 0, codecs: [Codec.Raw, Codec.Jpeg, Codec.Png], software });
    c.hello = (await c.waitFor((m) => m.type === Type.Hello, 'Hello')).body;
    if (c.hello.capabilities & 1) {
      const id = c.send(Type.Auth, { token });
      await c.waitFor((m) => m.type === Type.AuthOk, 'AuthOk', { requests: [id] });
    }
    return c;
  }

  constructor(socket) {
    this.socket = socket;
    this.buffer = Buffer.alloc(0);
    this.messages = [];
    this.waiters = [];
    this.nextRequest = 1;
    this.closed = null;
    socket.on('data', (chunk) => this.onData(chunk));
    socket.on('close', () => this.fail(new Error('the server closed the connection')));
    socket.on('error', (e) => this.fail(e));
  }

  onData(chunk) {
    this.buffer = this.buffer.length ? Buffer.concat([this.buffer, chunk]) : chunk;
    while (this.buffer.length >= HEADER_BYTES) {
      const h = decodeHeader(this.buffer);
      const total = HEADER_BYTES + h.length;
      if (this.buffer.length < total) break;
      // Copy out: decode() keeps views into the buffer.
      const m = decode(new Uint8Array(this.buffer.subarray(0, total)));
      this.buffer = this.buffer.subarray(total);
      this.deliver(m);
    }
  }

  deliver(m) {
    if (m.type === Type.Error) {
      // An Error answering a request a waiter names (or any fatal one) rejects that waiter.
      const e = new Error(`server Error ${errorName(m.body.code)}: ${m.body.message}`);
      e.code = m.body.code;
      const hit = this.waiters.filter((w) => m.body.fatal || w.requests.includes(m.request));
      if (hit.length) {
        for (const w of hit) w.reject(e);
        return;
      }
    }
    const w = this.waiters.find((x) => x.match(m));
    if (w) {
      w.resolve(m);
    } else {
      this.messages.push(m);
      if (this.messages.length > 64) this.messages.shift();
    }
  }

  fail(e) {
    if (!this.closed) this.closed = e;
    for (const w of this.waiters.splice(0)) w.reject(e);
  }

  send(type, body = {}) {
    const request = this.nextRequest++;
    this.socket.write(Buffer.from(encode(type, body, request)));
    return request;
  }

  /** The first message (already received or to come) matching `match`; an Error answering one of `requests` rejects. */
  waitFor(match, what, { requests = [], timeoutMs = 60000 } = {}) {
    const i = this.messages.findIndex(match);
    if (i >= 0) return Promise.resolve(this.messages.splice(i, 1)[0]);
    if (this.closed) return Promise.reject(this.closed);
    return new Promise((resolve, reject) => {
      const done = () => {
        clearTimeout(timer);
        const k = this.waiters.indexOf(w);
        if (k >= 0) this.waiters.splice(k, 1);
      };
      const w = { match, requests, resolve: (m) => { done(); resolve(m); }, reject: (e) => { done(); reject(e); } };
      const timer = setTimeout(() => w.reject(new Error(`no ${what} within ${timeoutMs} ms`)), timeoutMs);
      this.waiters.push(w);
    });
  }

  async openVolume(name) {
    const id = this.send(Type.OpenVolume, { name });
    return (await this.waitFor((m) => m.type === Type.VolumeOpened && m.request === id, 'VolumeOpened', { requests: [id] })).body;
  }

  /**
   * One frame of camera/tf/options (RequestFrame mode 0): returns the Frame body. An Error
   * answering any of these messages rejects.
   */
  async renderOnce({ camera, tf, options, modeAndClip = null }, timeoutMs = 120000) {
    const ids = [];
    if (tf) ids.push(this.send(Type.SetTransferFunction, tf));
    ids.push(this.send(Type.SetRenderOptions, options));
    if (modeAndClip) ids.push(this.send(Type.SetModeAndClip, modeAndClip));
    ids.push(this.send(Type.SetCamera, camera));
    ids.push(this.send(Type.RequestFrame, { mode: FrameMode.Once }));
    const m = await this.waitFor((x) => x.type === Type.Frame && x.body.cameraId === camera.cameraId,
      `Frame for camera ${camera.cameraId}`, { requests: ids, timeoutMs });
    return m.body;
  }

  close() {
    try { this.socket.write(Buffer.from(encode(Type.Bye, { reason: 0 }, 0))); } catch { /* gone */ }
    this.socket.end();
    this.socket.destroy();
  }
}

/**
 * Renders camera/tf/options (and a SetModeAndClip body, when given) once on a fresh TCP session;
 * returns the Frame body (image copied).
 */
export async function directRender(daemon, volume, { camera, tf, options, modeAndClip = null }, { token = '' } = {}) {
  const c = await TcpClient.connect(daemon.port, { token, ca: daemon.ca ?? null });
  try {
    await c.openVolume(volume);
    const f = await c.renderOnce({ camera, tf, options, modeAndClip });
    return { ...f, image: new Uint8Array(f.image) };
  } finally {
    c.close();
  }
}

/** Options for a direct raw render matching the page's: codec raw, the given quality, no refined codec. */
export function rawOptions(pageOptions, quality = Quality.Refined) {
  return { ...pageOptions, codec: Codec.Raw, codecQuality: 0, quality, refinedCodec: 0 };
}

// ---- images ------------------------------------------------------------------------------------

/**
 * Compares the R, G, B of two width × height RGBA images (alpha ignored): {maxAbs, meanAbs,
 * differing (pixels with any channel off), worst: {x, y, a, b}}.
 */
export function compareRgb(a, b, width, height) {
  if (a.length !== width * height * 4 || b.length !== width * height * 4) {
    throw new Error(`image sizes differ: ${a.length} and ${b.length} bytes for ${width}x${height}`);
  }
  let maxAbs = 0, sum = 0, differing = 0, worst = null;
  for (let p = 0; p < width * height; ++p) {
    let off = false;
    for (let c = 0; c < 3; ++c) {
      const d = Math.abs(a[p * 4 + c] - b[p * 4 + c]);
      sum += d;
      if (d) off = true;
      if (d > maxAbs) {
        maxAbs = d;
        worst = { x: p % width, y: Math.floor(p / width), a: Array.from(a.subarray(p * 4, p * 4 + 3)), b: Array.from(b.subarray(p * 4, p * 4 + 3)) };
      }
    }
    if (off) differing += 1;
  }
  return { maxAbs, meanAbs: sum / (width * height * 3), differing, worst };
}

/** Fraction of pixels whose RGB is not black: a guard against comparing two empty images. */
export function litFraction(rgba) {
  let lit = 0;
  const n = rgba.length / 4;
  for (let p = 0; p < n; ++p) if (rgba[p * 4] | rgba[p * 4 + 1] | rgba[p * 4 + 2]) lit += 1;
  return lit / n;
}

// ---- the browser -------------------------------------------------------------------------------

const WEB_TYPES = { '.html': 'text/html; charset=utf-8', '.js': 'text/javascript; charset=utf-8', '.css': 'text/css; charset=utf-8' };

/**
 * With BC_WEB_DIR set, answers the context's requests under `baseUrl` for files of that folder
 * (/ is index.html) with the folder's file, keeping the daemon's status and headers (its
 * Content-Security-Policy among them); other requests, the WebSocket's included, go to the
 * daemon. Returns the folder, or null when BC_WEB_DIR is unset (nothing is routed).
 */
export async function useWebDir(context, baseUrl) {
  const dir = process.env.BC_WEB_DIR;
  if (!dir) return null;
  const root = path.resolve(dir);
  await context.route((u) => u.href.startsWith(baseUrl), async (route) => {
    const rel = new URL(route.request().url()).pathname.replace(/^\/+/, '') || 'index.html';
    const file = path.resolve(root, rel);
    const type = WEB_TYPES[path.extname(file)];
    if (!type || !file.startsWith(root + path.sep)) return route.continue();
    let body;
    try {
      body = await readFile(file);
    } catch {
      return route.continue();
    }
    const response = await route.fetch();
    const headers = { ...response.headers(), 'content-type': type };
    delete headers['content-length'];
    return route.fulfill({ status: response.status(), headers, body });
  });
  return root;
}

/** Launches Chromium through playwright-core (no browser download; --no-sandbox as root). */
export async function launchChromium() {
  const { chromium } = await import('playwright-core');
  // Names for the host-name tests: a configured name of the viewer, and one it was not given
  // (what a DNS rebinding attack makes of the daemon's address).
  const args = ['--host-resolver-rules=MAP viewer.test 127.0.0.1, MAP rebound.test 127.0.0.1'];
  if (process.getuid?.() === 0) args.push('--no-sandbox');
  // A page answered by useWebDir's route has no address Chromium knows, so it counts as public
  // and its WebSocket to 127.0.0.1 is blocked (ERR_BLOCKED_BY_LOCAL_NETWORK_ACCESS_CHECKS).
  if (process.env.BC_WEB_DIR) args.push('--disable-features=LocalNetworkAccessChecks,BlockInsecurePrivateNetworkRequests');
  try {
    return await chromium.launch({ executablePath: CHROMIUM, args });
  } catch (e) {
    throw new Error(`cannot launch Chromium at ${CHROMIUM} (set BC_CHROMIUM): ${e.message}`);
  }
}
