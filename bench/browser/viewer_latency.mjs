// Input-to-screen latency and bytes per frame of the browser viewer (web/), in Chromium against
// a real brickcastd, beside the native client (brickcast-client) on the same daemon and volume.
//
// Run (from the repository root, after building brickcastd and brickcast-client):
//
//   (cd tests/browser && npm ci --no-audit --no-fund)    # playwright-core, once; no browser download
//   node bench/browser/viewer_latency.mjs [--drags 4] [--steps 40] [--interval-ms 50] [--dims 128]
//
// Environment: BRICKCASTD (default build/tools/brickcastd), BRICKCAST_CLIENT (default
// build/tools/brickcast-client), BC_CHROMIUM (default /usr/bin/chromium), BC_WEB_DIR (serve
// the page from this folder instead of the daemon's compiled-in copy; tests/browser/daemon.mjs).
//
// What it does: one daemon (a temporary config and store folder), a generated phantom of
// dims³ voxels, the CPU raycaster, a 512x512 canvas (deviceScaleFactor 1, so 512x512 refined
// frames; the page asks for unscaled interactive frames, RenderOptions flags bit 0, so those are
// 256x256 and the canvas scales them up).
// For each codec setting it makes `drags` mouse-drag orbits of `steps` moves `interval-ms` apart
// (left-drag on the canvas, as a person would), and after each lets the camera rest until the
// refined frame is on screen. In the page it records, without changing the viewer:
//   - the time of every pointer event (event.timeStamp, as the viewer itself keeps it),
//   - every SetCamera the page sends (its cameraId) with the latest input before it,
//   - every frame drawn to the view (window.brickcast.lastFrame right after the draw:
//     cameraId, codec, refined, bytes, drawnAt).
// Latency = drawnAt - time of the input behind the frame's cameraId: for interactive frames
// ("moving") only the first frame drawn of each camera counts, as in the viewer's overlay; for
// the refined frame ("rest") it is measured from the last input of the drag, so it includes the
// server's rest interval (frames.rest_ms, 150 ms). drawnAt is when drawImage returned; the
// compositor shows it at the next display frame (up to one vsync later).
// The native client renders a 36-frame orbit, one request per frame, at full size (its own
// latency: request sent to frame decoded), with --codec jpeg.

import { execFile } from 'node:child_process';
import { rm } from 'node:fs/promises';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { parseArgs, promisify } from 'node:util';
import { startDaemon, launchChromium, tempDir, useWebDir } from '../../tests/browser/daemon.mjs';
import { Codec, Renderer } from '../../web/js/protocol.js';

const here = path.dirname(fileURLToPath(import.meta.url));
const CLIENT = process.env.BRICKCAST_CLIENT || path.resolve(here, '../../build/tools/brickcast-client');
const { values: opt } = parseArgs({
  options: {
    drags: { type: 'string', default: '4' },
    steps: { type: 'string', default: '40' },
    'interval-ms': { type: 'string', default: '50' },
    dims: { type: 'string', default: '128' },
    size: { type: 'string', default: '512' },
  },
});
const DRAGS = Number(opt.drags), STEPS = Number(opt.steps), INTERVAL = Number(opt['interval-ms']);
const DIMS = Number(opt.dims), SIZE = Number(opt.size);
const TIMEOUT = 60000;

// codecQuality: JPEG's quality (the page's default 80); the server takes only 0 (default) for
// PNG and raw.
const SETTINGS = [
  { name: 'JPEG interactive, PNG refined (the page\'s default)', options: { codec: Codec.Jpeg, codecQuality: 80, refinedCodec: Codec.Png + 1 }, moving: Codec.Jpeg, rest: Codec.Png },
  { name: 'PNG interactive, PNG refined', options: { codec: Codec.Png, codecQuality: 0, refinedCodec: Codec.Png + 1 }, moving: Codec.Png, rest: Codec.Png },
  { name: 'raw interactive, raw refined', options: { codec: Codec.Raw, codecQuality: 0, refinedCodec: 0 }, moving: Codec.Raw, rest: Codec.Raw },
];
const CODEC_NAMES = ['raw', 'zstd', 'zstd delta', 'JPEG', 'PNG'];

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// Runs in the page before its modules: records inputs, SetCamera sends and drawn frames.
function instrument() {
  const rec = { lastInput: null, sends: {}, frames: [] };
  window.__bench = rec;
  const onInput = (e) => { rec.lastInput = e.timeStamp; };
  addEventListener('pointerdown', onInput, { capture: true });
  addEventListener('pointermove', onInput, { capture: true });
  const send = WebSocket.prototype.send;
  WebSocket.prototype.send = function (data) {
    const b = data instanceof ArrayBuffer ? new Uint8Array(data) : null;
    if (b && b.length >= 20 && b[5] === 0x08) { // SetCamera: cameraId is the payload's first u32
      const cameraId = new DataView(data).getUint32(16, true);
      rec.sends[cameraId] = { inputTime: rec.lastInput, sentAt: performance.now() };
      rec.lastInput = null; // a later camera with no new input has no input time
    }
    return send.call(this, data);
  };
  const drawImage = CanvasRenderingContext2D.prototype.drawImage;
  CanvasRenderingContext2D.prototype.drawImage = function (...args) {
    const r = drawImage.apply(this, args);
    // The viewer sets lastFrame right after drawImage, in the same task.
    if (this.canvas.id === 'view') queueMicrotask(() => { const f = window.brickcast?.lastFrame; if (f) rec.frames.push(f); });
    return r;
  };
}

function percentile(sorted, p) {
  if (!sorted.length) return NaN;
  return sorted[Math.min(sorted.length - 1, Math.max(0, Math.ceil((p / 100) * sorted.length) - 1))];
}

function summarize(rows) {
  const lat = rows.map((r) => r.latency).filter((x) => x !== null).sort((a, b) => a - b);
  const bytes = rows.reduce((s, r) => s + r.bytes, 0) / (rows.length || 1);
  return { frames: rows.length, samples: lat.length, p50: percentile(lat, 50), p99: percentile(lat, 99), bytes };
}

async function waitForFrame(page, cameraId, refined) {
  await page.waitForFunction(([id, want]) => {
    const f = window.brickcast.lastFrame;
    return !!f && f.cameraId >= id && (want === undefined || f.refined === want);
  }, [cameraId, refined], { timeout: TIMEOUT, polling: 10 });
}

/** One drag of STEPS moves INTERVAL ms apart, (dx, dy) px in all, from the canvas centre. */
async function paceDrag(page, box, dx, dy) {
  const x0 = box.x + box.width / 2 - dx / 2, y0 = box.y + box.height / 2 - dy / 2;
  await page.mouse.move(x0, y0);
  await page.mouse.down();
  const t0 = Date.now();
  for (let i = 1; i <= STEPS; ++i) {
    const wait = t0 + i * INTERVAL - Date.now();
    if (wait > 0) await sleep(wait);
    await page.mouse.move(x0 + (dx * i) / STEPS, y0 + (dy * i) / STEPS);
  }
  await page.mouse.up();
}

async function measureSetting(page, setting) {
  await page.evaluate((o) => window.brickcast.setRenderOptions(o), setting.options);
  const fence = await page.evaluate(() => window.brickcast.setCamera({}));
  await waitForFrame(page, fence, true);
  const status = await page.evaluate(() => (document.getElementById('status').hidden ? '' : document.getElementById('status-text').textContent));
  if (status) throw new Error(`${setting.name}: the page says '${status}'`);
  const box = await page.locator('#view').boundingBox();
  await page.evaluate(() => { window.__bench.frames = []; });
  for (let d = 0; d < DRAGS; ++d) {
    const dir = d % 2 ? -1 : 1;
    await paceDrag(page, box, dir * box.width * 0.4, dir * box.height * 0.1);
    const last = await page.evaluate(() => window.brickcast.camera().cameraId);
    await waitForFrame(page, last, true); // at rest: the refined frame of the last camera
  }
  const { frames, sends } = await page.evaluate(() => window.__bench);
  const seen = new Set();
  const moving = [], rest = [];
  for (const f of frames) {
    const input = sends[f.cameraId]?.inputTime ?? null;
    if (f.refined) {
      rest.push({ bytes: f.bytes, codec: f.codec, latency: input === null ? null : f.drawnAt - input });
    } else {
      const first = !seen.has(f.cameraId);
      moving.push({ bytes: f.bytes, codec: f.codec, latency: first && input !== null ? f.drawnAt - input : null });
    }
    seen.add(f.cameraId);
  }
  for (const [rows, want, what] of [[moving, setting.moving, 'interactive'], [rest, setting.rest, 'refined']]) {
    const other = rows.find((r) => r.codec !== want);
    if (other) throw new Error(`${setting.name}: a ${what} frame came as ${CODEC_NAMES[other.codec]}, not ${CODEC_NAMES[want]}`);
  }
  const codecOf = (rows) => [...new Set(rows.map((r) => CODEC_NAMES[r.codec] ?? r.codec))].join('+') || '-';
  const sizesOf = (refined) => [...new Set(frames.filter((f) => f.refined === refined).map((f) => `${f.width}x${f.height}`))].join(', ') || '-';
  return [
    { setting: setting.name, codec: codecOf(moving), phase: 'moving (interactive)', sizes: sizesOf(false), ...summarize(moving) },
    { setting: setting.name, codec: codecOf(rest), phase: 'rest (refined)', sizes: sizesOf(true), ...summarize(rest) },
  ];
}

async function nativeClient(port) {
  const args = ['--port', String(port), '--volume', 'phantom', '--frames', '36', '--size', `${SIZE},${SIZE}`, '--renderer', 'cpu', '--codec', 'jpeg'];
  const { stdout } = await promisify(execFile)(CLIENT, args, { maxBuffer: 16 << 20 });
  const perFrame = [...stdout.matchAll(/^frame\s+\d+\s+camera\s+\d+\s+([\d.]+) ms.*?(\d+) bytes$/gm)];
  const summary = stdout.match(/latency p50 ([\d.]+) ms, p99 ([\d.]+) ms/);
  if (!summary || !perFrame.length) throw new Error(`cannot read brickcast-client's output:\n${stdout}`);
  const bytes = perFrame.reduce((s, m) => s + Number(m[2]), 0) / perFrame.length;
  return {
    setting: `native brickcast-client ${args.join(' ')}`, codec: 'JPEG', phase: 'orbit, a request per frame',
    sizes: `${SIZE}x${SIZE}`, frames: perFrame.length, samples: perFrame.length,
    p50: Number(summary[1]), p99: Number(summary[2]), bytes, summaryLine: stdout.trim().split('\n').pop(),
  };
}

function table(rows) {
  const fmt = (x) => (Number.isFinite(x) ? x.toFixed(1) : '-');
  const out = [
    '| client / setting | codec | phase | frame size | frames | latency samples | p50 ms | p99 ms | mean bytes/frame |',
    '|---|---|---|---|---:|---:|---:|---:|---:|',
  ];
  for (const r of rows) {
    out.push(`| ${r.setting} | ${r.codec} | ${r.phase} | ${r.sizes} | ${r.frames} | ${r.samples} | ${fmt(r.p50)} | ${fmt(r.p99)} | ${Math.round(r.bytes)} |`);
  }
  return out.join('\n');
}

async function main() {
  const store = await tempDir('bc-bench-store-');
  const daemon = await startDaemon({ storeDir: store, volumes: [{ name: 'phantom', generate: 'phantom', dims: [DIMS, DIMS, DIMS] }] });
  let browser;
  const rows = [];
  try {
    browser = await launchChromium();
    const chromiumVersion = browser.version();
    const context = await browser.newContext({ viewport: { width: SIZE + 400, height: SIZE + 120 }, deviceScaleFactor: 1 });
    await useWebDir(context, daemon.url);
    const page = await context.newPage();
    await page.addInitScript(instrument);
    await page.addInitScript((edge) => {
      document.addEventListener('DOMContentLoaded', () => {
        const c = document.getElementById('view');
        for (const [k, v] of [['inset', '0 auto auto 0'], ['width', `${edge}px`], ['height', `${edge}px`]]) c.style.setProperty(k, v, 'important');
      });
    }, SIZE);
    await page.goto(daemon.url);
    await page.waitForFunction(() => window.brickcast?.state === 'ready', null, { timeout: TIMEOUT });
    await page.evaluate((r) => window.brickcast.setRenderOptions({ renderer: r }), Renderer.CpuRaycaster);
    await page.evaluate(() => window.brickcast.openVolume('phantom'));
    await page.waitForFunction((s) => window.brickcast.lastFrame?.width === s && window.brickcast.lastFrame.refined, SIZE, { timeout: TIMEOUT });
    const flags = await page.evaluate(() => window.brickcast.renderOptions().flags ?? 0);
    const t0 = Date.now();
    for (const s of SETTINGS) rows.push(...await measureSetting(page, s));
    const browserSeconds = (Date.now() - t0) / 1000;
    await context.close();
    await browser.close();
    browser = null;
    const native = await nativeClient(daemon.port);
    rows.push(native);

    console.log(`brickcast viewer latency: phantom ${DIMS}³ (generated), CPU raycaster, ${SIZE}x${SIZE} frames, ` +
      `${DRAGS} drags × ${STEPS} moves ${INTERVAL} ms apart per setting (${browserSeconds.toFixed(0)} s in the browser), ` +
      `Chromium ${chromiumVersion}, ${new Date().toISOString()}\n`);
    console.log(table(rows));
    console.log(`\nthe page's RenderOptions flags: ${flags} (${flags & 1 ? 'interactive frames sent at the half size they are drawn at, scaled up by the canvas' : 'interactive frames scaled up by the server'})`);
    console.log(`native client: ${native.summaryLine}`);
  } finally {
    await browser?.close();
    await daemon.stop();
    await rm(daemon.dir, { recursive: true, force: true });
    await rm(store, { recursive: true, force: true });
  }
}

main().catch((e) => {
  console.error(e);
  process.exitCode = 1;
});
