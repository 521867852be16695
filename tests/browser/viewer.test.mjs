// The browser viewer (web/) against a real brickcastd, in Chromium through playwright-core.
// Every test starts its own daemon on a temporary config and compares what the page shows with
// what the daemon renders for a plain TCP client asked for the same camera, transfer function
// and options.
//
//   tests/browser/run.sh                 (installs playwright-core from package-lock.json once)
//   node --test tests/browser/           (after `npm ci` in tests/browser)
//
// Environment: BRICKCASTD (daemon binary), BRICKCAST (the CLI, for the screenshot's ingest),
// BC_CHROMIUM (default /usr/bin/chromium), BC_VIEWER_SCREENSHOT (write a 1280x800 screenshot of
// the viewer there; skipped when unset), BC_SHARED_DATA (the scans, default ../shared/data beside
// the repository), BC_WEB_DIR (serve the page from this folder instead of the daemon's
// compiled-in copy: trying edits of web/ without a rebuild; daemon.mjs's useWebDir).
//
// Frames are drawn by the CPU raycaster (renderer 1) at 256x256: the machine this runs on need
// not have a GPU.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { existsSync } from 'node:fs';
import { mkdir, rm } from 'node:fs/promises';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import {
  startDaemon, directRender, rawOptions, compareRgb, litFraction, launchChromium, tempDir, useWebDir, ingestRaw,
} from './daemon.mjs';
import { Codec, Quality, Renderer } from '../../web/js/protocol.js';

const VIEW = 256; // canvas edge, CSS px (deviceScaleFactor 1: also device px and refined frame px)
// The first test's canvas edge: odd, so its interactive frames (half of each edge, rounded up:
// RenderOptions flags bit 0, which the page sets) are 129x129.
const ODD_VIEW = 257;
const FRAME_TIMEOUT = 30000;
// JPEG interactive frames (as the page decoded them, at the size the server drew them) against
// the raw interactive frame of the same camera, both 129x129: the largest difference of any
// R, G or B seen on this test's view (phantom 96³, the first preset, JPEG quality 80) was
// MEASURED_JPEG_MAX_ABS, the mean over all R, G, B values MEASURED_JPEG_MEAN_ABS: the bounds are
// about twice those.
const MEASURED_JPEG_MAX_ABS = 34;
const MEASURED_JPEG_MEAN_ABS = 1.111;
const JPEG_MAX_ABS = 68;
const JPEG_MEAN_ABS = 2.2;

let browser;
let storeDir; // ingested once, shared by every daemon of this file

before(async () => {
  storeDir = await tempDir('bc-browser-stores-');
  browser = await launchChromium();
});

after(async () => {
  await browser?.close();
  if (storeDir) await rm(storeDir, { recursive: true, force: true });
});

// ---- helpers -----------------------------------------------------------------------------------

/**
 * Runs fn({daemon, open, restart}) with a daemon of `daemonOptions`; open() makes a page (own
 * browser context) on it. Pages and daemon are closed afterwards; a failure carries the
 * daemon's log.
 */
async function withDaemon(daemonOptions, fn) {
  let daemon = await startDaemon({ storeDir, ...daemonOptions });
  const daemons = [daemon];
  const contexts = [];
  const open = async (options = {}) => {
    const v = await openViewer(daemon, options);
    contexts.push(v.context);
    return v;
  };
  const restart = async (options) => {
    daemon = await startDaemon({ storeDir, ...daemonOptions, ...options });
    daemons.push(daemon);
    return daemon;
  };
  try {
    await fn({ daemon, open, restart });
  } catch (e) {
    const logs = daemons.map((d, i) => `--- brickcastd log ${i + 1} (last 3000 characters) ---\n${d.log().slice(-3000)}`);
    e.message += `\n${logs.join('\n')}`;
    throw e;
  } finally {
    for (const c of contexts) await c.close().catch(() => {});
    for (const d of daemons) await d.dispose();
  }
}

/**
 * A page on the daemon's viewer. size: the canvas's CSS edge (null keeps the page's own layout).
 * Returns {context, page, pageErrors, urls}: urls holds every URL the page requested, the
 * WebSocket's included.
 */
async function openViewer(daemon, { size = VIEW, viewport = { width: 900, height: 600 }, url = daemon.url } = {}) {
  // A daemon with TLS has a self-signed certificate: trusted for this context only.
  const context = await browser.newContext({ viewport, deviceScaleFactor: 1, ignoreHTTPSErrors: !!daemon.ca });
  await useWebDir(context, daemon.url);
  const page = await context.newPage();
  const pageErrors = [];
  const urls = [];
  page.on('pageerror', (e) => pageErrors.push(e));
  page.on('request', (r) => urls.push(r.url()));
  page.on('websocket', (ws) => urls.push(ws.url()));
  if (size) {
    // A fixed canvas size, so frames are small; the canvas stays unscaled (CSS size = frame size).
    // Through the CSSOM: the page's Content-Security-Policy refuses inline <style>.
    await page.addInitScript((edge) => {
      document.addEventListener('DOMContentLoaded', () => {
        const c = document.getElementById('view');
        for (const [k, val] of [['inset', '0 auto auto 0'], ['width', `${edge}px`], ['height', `${edge}px`]]) c.style.setProperty(k, val, 'important');
      });
    }, size);
  }
  await page.goto(url);
  return { context, page, pageErrors, urls };
}

const waitReady = (page) => page.waitForFunction(() => window.brickcast?.state === 'ready', null, { timeout: FRAME_TIMEOUT });

/** Waits until the page has drawn a frame of `cameraId` (or later) matching `want` ({refined, codec, width}). */
async function waitForFrame(page, cameraId, want = {}) {
  try {
    await page.waitForFunction(([id, w]) => {
      const f = window.brickcast.lastFrame;
      return !!f && f.cameraId >= id && (w.refined === undefined || f.refined === w.refined) &&
        (w.codec === undefined || f.codec === w.codec) && (w.width === undefined || f.width === w.width);
    }, [cameraId, want], { timeout: FRAME_TIMEOUT, polling: 20 });
  } catch (e) {
    const last = await page.evaluate(() => window.brickcast.lastFrame).catch(() => 'unreadable');
    throw new Error(`no frame of camera ${cameraId} matching ${JSON.stringify(want)} within ${FRAME_TIMEOUT} ms; last drawn: ${JSON.stringify(last)}`, { cause: e });
  }
}

/** Sends the current camera again under a new cameraId: frames carrying it reflect everything sent before. */
const fence = (page) => page.evaluate(() => window.brickcast.setCamera({}));

/** Fences and waits for the refined PNG frame of the fence's camera at the view size. */
async function settleRefined(page, width = VIEW) {
  const id = await fence(page);
  assert.ok(id > 0, 'setCamera sent nothing (no volume open, or not connected)');
  await waitForFrame(page, id, { refined: true, codec: Codec.Png, width });
  return id;
}

/**
 * What the page shows, read in one go: the canvas pixels (getImageData of its backing store),
 * the last frame, sizes, and the camera/TF/options the page sent.
 */
async function readView(page) {
  const v = await page.evaluate(() => {
    const base64 = (bytes) => {
      let s = '';
      for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
      return btoa(s);
    };
    const c = document.getElementById('view');
    const img = c.getContext('2d').getImageData(0, 0, c.width, c.height);
    const r = c.getBoundingClientRect();
    const b = window.brickcast;
    // The last frame as decoded, before the page scaled it to the canvas.
    const decoded = b.lastFrameImage();
    return {
      pixels: base64(new Uint8Array(img.data.buffer)), width: c.width, height: c.height, cssWidth: r.width, cssHeight: r.height,
      dpr: devicePixelRatio, frame: b.lastFrame, camera: b.camera(), tf: b.transferFunction(), options: b.renderOptions(),
      modeAndClip: b.modeAndClip(),
      decoded: decoded && { width: decoded.width, height: decoded.height, data: base64(new Uint8Array(decoded.data.buffer)) },
    };
  });
  v.pixels = new Uint8Array(Buffer.from(v.pixels, 'base64'));
  if (v.decoded) v.decoded.data = new Uint8Array(Buffer.from(v.decoded.data, 'base64'));
  return v;
}

/** Asserts the canvas is unscaled: backing size = frame size = CSS size × devicePixelRatio. */
function assertUnscaled(v) {
  assert.equal(v.width, v.frame.width, `canvas backing width ${v.width} != frame width ${v.frame.width}`);
  assert.equal(v.height, v.frame.height, `canvas backing height ${v.height} != frame height ${v.frame.height}`);
  assert.equal(v.width, Math.round(v.cssWidth * v.dpr), `frame width ${v.width} != CSS width ${v.cssWidth} × dpr ${v.dpr}`);
  assert.equal(v.height, Math.round(v.cssHeight * v.dpr), `frame height ${v.height} != CSS height ${v.cssHeight} × dpr ${v.dpr}`);
  assert.equal(v.options.width, v.width, 'RenderOptions width differs from the canvas');
  assert.equal(v.options.height, v.height, 'RenderOptions height differs from the canvas');
}

/** The direct render of what the page shows (same camera, TF and options; raw codec). */
async function renderLikePage(daemon, volume, v, quality = Quality.Refined, auth = {}) {
  assert.ok(v.camera && v.tf && v.options, 'the page has not sent a camera, a transfer function and options yet');
  const f = await directRender(daemon, volume,
    { camera: v.camera, tf: v.tf, options: rawOptions(v.options, quality), modeAndClip: v.modeAndClip }, auth);
  assert.equal(f.codec, Codec.Raw, 'direct render: not a raw frame');
  assert.equal(f.width, v.width, 'direct render: width differs from the page frame');
  assert.equal(f.height, v.height, 'direct render: height differs from the page frame');
  return f;
}

/** Asserts the page's canvas equals the direct render exactly (R, G, B). */
async function assertMatchesDirect(daemon, volume, v, what, auth = {}) {
  const f = await renderLikePage(daemon, volume, v, Quality.Refined, auth);
  const d = compareRgb(v.pixels, f.image, v.width, v.height);
  assert.ok(litFraction(f.image) > 0.02, `${what}: the direct render is (nearly) black; nothing to compare`);
  assert.equal(d.maxAbs, 0, `${what}: page and direct render differ: max abs ${d.maxAbs}, mean ${d.meanAbs.toFixed(3)}, ${d.differing} pixels, worst ${JSON.stringify(d.worst)}`);
  return f;
}

/** No uncaught page error, and no error in the status line. */
async function assertHealthy({ page, pageErrors }) {
  assert.deepEqual(pageErrors.map((e) => e.message), [], 'uncaught errors in the page');
  const status = await page.evaluate(() => {
    const s = document.getElementById('status');
    return s.hidden ? null : { kind: s.dataset.kind, text: document.getElementById('status-text').textContent };
  });
  assert.ok(!status || status.kind !== 'error', `the page shows an error: ${status?.text}`);
}

/**
 * Picks the CPU raycaster (the page starts on auto, the server's choice), opens
 * `name` through the page's volume picker and waits for its first frame.
 */
async function chooseVolume(page, name) {
  await page.evaluate((r) => window.brickcast.setRenderOptions({ renderer: r }), Renderer.CpuRaycaster);
  await page.waitForFunction((n) => [...document.querySelectorAll('#volume option')].some((o) => o.value === n && !o.disabled) &&
    !document.getElementById('volume').disabled, name, { timeout: FRAME_TIMEOUT });
  await page.selectOption('#volume', name);
  await page.waitForFunction(() => window.brickcast.camera() !== null, null, { timeout: FRAME_TIMEOUT });
  const id = await page.evaluate(() => window.brickcast.camera().cameraId);
  await waitForFrame(page, id);
}

/** A mouse drag of `steps` moves across the canvas from its centre by (dx, dy) CSS px. */
async function drag(page, dx, dy, steps = 10) {
  const box = await page.locator('#view').boundingBox();
  const x = box.x + box.width / 2, y = box.y + box.height / 2;
  await page.mouse.move(x, y);
  await page.mouse.down();
  for (let i = 1; i <= steps; ++i) await page.mouse.move(x + (dx * i) / steps, y + (dy * i) / steps);
  await page.mouse.up();
}

/** Waits two animation frames: what the page coalesces to one send per animation frame has been sent. */
const sendsFlushed = (page) => page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));

/** A viewer (open()'s) on the phantom, its first refined frame shown. */
async function phantomViewer(open) {
  const v = await open();
  await waitReady(v.page);
  await chooseVolume(v.page, 'phantom');
  await settleRefined(v.page);
  return v;
}

// ---- tests -------------------------------------------------------------------------------------

test('the page lists volumes, opens one and shows what the daemon renders (PNG exact, JPEG within bound)', { timeout: 90000 }, async () => {
  // Half-size interactive frames, exactly: the server's frame-time budget off (its sizes follow
  // the machine's speed; they are the server tests' business).
  await withDaemon({ frames: { interactive_ms: 0 } }, async ({ daemon, open }) => {
    assert.match(daemon.log(), /viewer: http:\/\/127\.0\.0\.1:\d+\//, 'the log names no viewer URL');
    const v = await open({ size: ODD_VIEW });
    const { page } = v;
    await waitReady(page);
    await page.waitForFunction(() => document.querySelectorAll('#volume option').length >= 3, null, { timeout: FRAME_TIMEOUT });
    const listed = await page.$$eval('#volume option', (os) => os.map((o) => ({ value: o.value, text: o.textContent })));
    const names = listed.map((o) => o.value).filter(Boolean);
    assert.deepEqual(names.sort(), ['phantom', 'vessels'], `the picker lists ${JSON.stringify(listed)}`);
    assert.match(listed.find((o) => o.value === 'phantom').text, /96×96×96/, 'the picker does not show the phantom\'s dims');

    await chooseVolume(page, 'phantom');
    await settleRefined(page, ODD_VIEW);
    const shown = await readView(page);
    assert.equal(shown.frame.refined, true);
    assert.equal(shown.frame.codec, Codec.Png, 'the refined frame is not PNG');
    assert.equal(shown.options.renderer, Renderer.CpuRaycaster);
    assert.equal(shown.options.flags, 1, 'the page does not ask for unscaled interactive frames (RenderOptions flags bit 0)');
    assertUnscaled(shown);
    assert.deepEqual([shown.decoded.width, shown.decoded.height], [ODD_VIEW, ODD_VIEW], 'lastFrameImage() of the refined frame is not its size');
    assert.equal(compareRgb(shown.decoded.data, shown.pixels, ODD_VIEW, ODD_VIEW).maxAbs, 0, 'the refined frame was not drawn 1:1');
    await assertMatchesDirect(daemon, 'phantom', shown, 'refined PNG frame');

    // Interactive JPEG frames, at the size the server drew them (half of each edge, rounded up),
    // against the raw interactive frame of the same camera, TF and options (flags 1 too).
    await page.evaluate((q) => window.brickcast.setRenderOptions({ quality: q }), Quality.Interactive);
    const id = await fence(page);
    await waitForFrame(page, id, { refined: false, codec: Codec.Jpeg });
    const jpeg = await readView(page);
    assert.equal(jpeg.frame.cameraId, id);
    const half = { width: Math.ceil(jpeg.width / 2), height: Math.ceil(jpeg.height / 2) };
    assert.deepEqual([jpeg.width, jpeg.height], [ODD_VIEW, ODD_VIEW], 'the canvas backing size changed for an interactive frame');
    assert.deepEqual([jpeg.options.width, jpeg.options.height], [jpeg.width, jpeg.height], 'RenderOptions size differs from the canvas');
    assert.deepEqual([jpeg.frame.width, jpeg.frame.height], [half.width, half.height],
      `the interactive frame is ${jpeg.frame.width}x${jpeg.frame.height}, not half the canvas's ${jpeg.width}x${jpeg.height} rounded up`);
    assert.deepEqual([jpeg.decoded.width, jpeg.decoded.height], [half.width, half.height], 'lastFrameImage() is not the frame\'s own size');
    const raw = await directRender(daemon, 'phantom', { camera: jpeg.camera, tf: jpeg.tf, options: rawOptions(jpeg.options, Quality.Interactive) });
    assert.equal(raw.codec, Codec.Raw, 'direct render: not a raw frame');
    assert.equal(raw.refined, false, 'the direct interactive render came back refined');
    assert.deepEqual([raw.width, raw.height], [half.width, half.height], 'the direct interactive render (flags 1) is not half size');
    assert.ok(litFraction(raw.image) > 0.02, 'the direct interactive render is (nearly) black; nothing to compare');
    const d = compareRgb(jpeg.decoded.data, raw.image, half.width, half.height);
    console.log(`# JPEG interactive frame (${half.width}x${half.height}) vs raw: max abs ${d.maxAbs}, mean abs ${d.meanAbs.toFixed(3)}, ` +
      `${d.differing} of ${half.width * half.height} pixels differ (bounds: max ${JPEG_MAX_ABS}, mean ${JPEG_MEAN_ABS}; ` +
      `measured ${MEASURED_JPEG_MAX_ABS} and ${MEASURED_JPEG_MEAN_ABS} when they were set)`);
    assert.ok(d.maxAbs <= JPEG_MAX_ABS, `JPEG frame off the raw frame by ${d.maxAbs} > ${JPEG_MAX_ABS} (worst ${JSON.stringify(d.worst)})`);
    assert.ok(d.meanAbs <= JPEG_MEAN_ABS, `JPEG frame off the raw frame by ${d.meanAbs.toFixed(3)} on average > ${JPEG_MEAN_ABS}`);
    assert.ok(d.maxAbs > 0, 'the JPEG frame is bit-identical to the raw frame: was it JPEG at all?');
    // The canvas shows it scaled up to the view, and the overlay says so.
    assert.ok(litFraction(jpeg.pixels) > 0.02, 'the canvas is (nearly) black after the interactive frame');
    const overlay = await page.textContent('#overlay');
    assert.ok(overlay.includes(`interactive ${half.width}×${half.height} → ${ODD_VIEW}×${ODD_VIEW}`), `the overlay does not show the frame's size and the view's: ${overlay}`);

    // {codec} alone: the codec's default quality (0), not the JPEG slider's 80 (OutOfRange for PNG).
    const sent = await page.evaluate((c) => window.brickcast.setRenderOptions({ codec: c }), Codec.Png);
    assert.equal(sent.codec, Codec.Png);
    assert.equal(sent.codecQuality, 0, 'a codec change without codecQuality kept the JPEG quality');
    const id2 = await fence(page);
    await waitForFrame(page, id2, { refined: false, codec: Codec.Png });
    const back = await page.evaluate((c) => window.brickcast.setRenderOptions({ codec: c }), Codec.Jpeg);
    assert.equal(back.codecQuality, 80, 'back to JPEG without codecQuality: not the slider\'s value');

    // One residency line, of the open volume only.
    await page.waitForFunction(() => /cache [\d.]+/.test(document.getElementById('overlay').textContent), null, { timeout: FRAME_TIMEOUT });
    const lines = (await page.textContent('#overlay')).split('\n');
    assert.ok(lines.length <= 6, `the overlay has ${lines.length} lines:\n${lines.join('\n')}`);
    assert.equal(lines.filter((l) => /cache/.test(l)).length, 1, `not one residency line:\n${lines.join('\n')}`);
    assert.ok(!lines.some((l) => /vessels|volume=/.test(l)), `the overlay shows raw counters or another volume:\n${lines.join('\n')}`);

    // Headless Chromium asks for no favicon either way: check the page names an inline one too.
    assert.ok(!v.urls.some((u) => new URL(u).pathname === '/favicon.ico'), 'the page asked for /favicon.ico');
    const icon = await page.evaluate(() => document.querySelector('link[rel~="icon"]')?.getAttribute('href') ?? null);
    assert.ok(icon?.startsWith('data:'), `no inline icon, so browsers ask for /favicon.ico (a 404): ${icon}`);
    await assertHealthy(v);
  });
});

test('an error bound at rest brings refined passes until the estimate reaches it, and the overlay shows it', { timeout: 60000 }, async () => {
  await withDaemon({}, async ({ open }) => {
    const v = await phantomViewer(open);
    const { page } = v;
    assert.equal(await page.evaluate(() => document.getElementById('rest-psnr').disabled), false,
      'the error-bound control is disabled on a server that takes SetFrameBudget');
    const sent = await page.evaluate(() => window.brickcast.setFrameBudget({ restPsnrDb: 45 }));
    assert.deepEqual(sent, { interactiveMs: 0, restPsnrDb: 45 });
    const id = await fence(page); // a new camera: its refinement passes follow at rest
    await page.waitForFunction((cid) => {
      const f = window.brickcast.lastFrame;
      return f && f.cameraId === cid && f.refined && f.estimatedPsnrDb >= 45;
    }, id, { timeout: FRAME_TIMEOUT });
    const f = await page.evaluate(() => window.brickcast.lastFrame);
    assert.equal(f.scale, 1, 'a refined pass is drawn at full size');
    const overlay = await page.textContent('#overlay');
    assert.match(overlay, new RegExp(`PSNR ≈ ${f.estimatedPsnrDb} dB`), `the overlay does not show the estimate: ${overlay}`);
    await assertHealthy(v);
  });
});

test('a mouse drag on the canvas orbits the camera and a frame of the new camera arrives', { timeout: 60000 }, async () => {
  await withDaemon({}, async ({ open }) => {
    const v = await phantomViewer(open);
    const { page } = v;
    const before = await readView(page);

    await drag(page, 80, 30, 12);
    const after = await page.evaluate(() => window.brickcast.camera());
    assert.ok(after.cameraId > before.camera.cameraId, `cameraId did not grow: ${before.camera.cameraId} -> ${after.cameraId}`);
    const moved = Math.hypot(...after.eye.map((e, i) => e - before.camera.eye[i]));
    assert.ok(moved > 1, `the drag did not move the eye (moved ${moved} mm)`);
    await waitForFrame(page, after.cameraId, { width: VIEW });
    const f = await page.evaluate(() => window.brickcast.lastFrame);
    assert.equal(f.cameraId, after.cameraId, 'the frame drawn does not carry the dragged camera\'s id');

    await waitForFrame(page, after.cameraId, { refined: true, codec: Codec.Png, width: VIEW });
    const shown = await readView(page);
    assert.equal(shown.camera.cameraId, after.cameraId, 'the camera changed after the drag ended');
    const d = compareRgb(before.pixels, shown.pixels, VIEW, VIEW);
    assert.ok(d.differing > VIEW * VIEW * 0.01, `the view hardly changed after the drag (${d.differing} pixels)`);
    await assertHealthy(v);
  });
});

test('a transfer-function edit changes the image as the direct render does (exact)', { timeout: 90000 }, async () => {
  await withDaemon({}, async ({ daemon, open }) => {
    const v = await phantomViewer(open);
    const { page } = v;
    const first = await readView(page);
    assert.equal(first.tf.kind, 0, 'the page did not start from a preset');

    // Points through the test API (kind 1).
    const points = [
      { fraction: 0.15, rgba: [0.2, 0.4, 1.0, 0.0] },
      { fraction: 0.35, rgba: [1.0, 0.5, 0.2, 0.08] },
      { fraction: 0.8, rgba: [1.0, 1.0, 0.9, 0.6] },
    ];
    await page.evaluate(([p]) => window.brickcast.setTransferFunction(p, false), [points]);
    const sent = await page.evaluate(() => window.brickcast.transferFunction());
    assert.equal(sent.kind, 1, 'setTransferFunction did not send points');
    assert.equal(sent.points.length, 3);
    await settleRefined(page);
    const edited = await readView(page);
    const change = compareRgb(first.pixels, edited.pixels, VIEW, VIEW);
    assert.ok(change.differing > VIEW * VIEW * 0.01, `the TF edit hardly changed the view (${change.differing} pixels)`);
    await assertMatchesDirect(daemon, 'phantom', edited, 'after setTransferFunction');

    // A preset chosen in the page's own select.
    const presets = await page.$$eval('#preset option', (os) => os.filter((o) => !o.disabled).map((o) => o.value));
    assert.ok(presets.includes('ct-skin'), `the preset list lacks ct-skin: ${presets}`);
    await page.selectOption('#preset', 'ct-skin');
    await page.waitForFunction(() => window.brickcast.transferFunction()?.preset === 'ct-skin', null, { timeout: FRAME_TIMEOUT });
    await settleRefined(page);
    const skin = await readView(page);
    assert.equal(skin.tf.kind, 0);
    const change2 = compareRgb(edited.pixels, skin.pixels, VIEW, VIEW);
    assert.ok(change2.differing > VIEW * VIEW * 0.01, `choosing ct-skin hardly changed the view (${change2.differing} pixels)`);
    await assertMatchesDirect(daemon, 'phantom', skin, 'after choosing ct-skin in the preset select');
    await assertHealthy(v);
  });
});

test('MIP, an isosurface, a crop box with a clip plane and their capped faces chosen in the page each show the direct render (exact)', { timeout: 120000 }, async () => {
  await withDaemon({}, async ({ daemon, open }) => {
    const v = await phantomViewer(open);
    const { page } = v;
    const first = await readView(page);
    assert.equal(first.modeAndClip?.mode ?? 0, 0, 'the page did not start in composite');
    let previous = first;
    const steps = [
      ['MIP chosen in the mode select', async () => page.selectOption('#mode', '1')],
      ['an isosurface at the middle value', async () => page.selectOption('#mode', '4')],
      ['a crop box and a clip plane', async () => page.evaluate(() => window.brickcast.setModeAndClip(
        { cropped: true, low: [0.1, 0.2, 0.1], high: [0.9, 0.8, 0.7], clip: true, axis: '-x', position: 0.6 }))],
      // The direct render is asked for the page's SetModeAndClip, its cap included.
      ['a capped crop box and clip plane', async () => page.evaluate(() => window.brickcast.setModeAndClip({ mode: 0, cap: true }))],
    ];
    for (const [what, act] of steps) {
      const before = await page.evaluate(() => JSON.stringify(window.brickcast.modeAndClip()));
      await act();
      await page.waitForFunction((b) => JSON.stringify(window.brickcast.modeAndClip()) !== b, before, { timeout: FRAME_TIMEOUT });
      await settleRefined(page); // a camera sent after the change: its refined frame shows it
      const view = await readView(page);
      const change = compareRgb(previous.pixels, view.pixels, VIEW, VIEW);
      assert.ok(change.differing > VIEW * VIEW * 0.01, `${what} hardly changed the view (${change.differing} pixels)`);
      await assertMatchesDirect(daemon, 'phantom', view, what);
      previous = view;
    }
    const sent = await page.evaluate(() => window.brickcast.modeAndClip());
    assert.equal(sent.mode, 0);
    assert.ok(sent.crop && sent.planes.length === 1 && sent.cap === true, `the capped cut was not sent: ${JSON.stringify(sent)}`);
    assert.ok(await page.isChecked('#cap') && await page.isEnabled('#cap'), 'the cap box does not show the cap');
    // The cap reached the server: the same cut uncapped renders otherwise (in composite a cap adds
    // one voxel's length of the function at the face, so only where that shows).
    const uncapped = await renderLikePage(daemon, 'phantom', { ...previous, modeAndClip: { ...sent, cap: false } });
    const capChange = compareRgb(previous.pixels, uncapped.image, VIEW, VIEW);
    assert.ok(capChange.differing > 0, 'the capped view equals the uncapped direct render');
    // MIP draws no surface: the box is off (its tooltip says why) and no cap is sent.
    await page.selectOption('#mode', '1');
    await page.waitForFunction(() => window.brickcast.modeAndClip()?.mode === 1, null, { timeout: FRAME_TIMEOUT });
    assert.equal((await page.evaluate(() => window.brickcast.modeAndClip())).cap, false);
    assert.equal(await page.isEnabled('#cap'), false);
    assert.match(await page.getAttribute('#cap', 'title'), /no surface to cap/);
    await assertHealthy(v);
  });
});

test('the crop box is drawn over the view, and dragging a face handle moves that face, not the camera', { timeout: 60000 }, async () => {
  await withDaemon({}, async ({ open }) => {
    const v = await phantomViewer(open);
    const { page } = v;
    const info = await page.evaluate(() => window.brickcast.volumes.find((x) => x.name === 'phantom'));
    const extent = info.dims.map((d, a) => d * info.spacingMm[a]);
    const centre = extent.map((e) => e / 2);
    // Looking down -z (+x right, +y up), orthographic, twice the x extent tall: pxPerMm px per mm
    // about the view's centre.
    const orthoHeight = 2 * Math.max(extent[0], extent[1]);
    const pxPerMm = VIEW / orthoHeight;
    const id = await page.evaluate((cam) => window.brickcast.setCamera(cam),
      { eye: [centre[0], centre[1], centre[2] + 3 * extent[2]], target: centre, up: [0, 1, 0], orthographic: true, orthoHeight });
    await waitForFrame(page, id);
    assert.equal(await page.locator('#cut-overlay').isHidden(), true, 'the overlay shows with nothing cut');

    await page.check('#crop');
    await page.waitForFunction(() => !!window.brickcast.modeAndClip()?.crop, null, { timeout: FRAME_TIMEOUT });
    const drawn = await page.evaluate(() => window.brickcast.cutOverlay());
    assert.equal(drawn?.edges, 12, `the crop box's edges are not drawn: ${JSON.stringify(drawn)}`);
    assert.equal(drawn.handles.length, 6);
    const view = await page.locator('#view').boundingBox();
    const handleAt = async (name) => {
      const b = await page.locator(`#cut-overlay [data-handle="${name}"]`).boundingBox();
      assert.ok(b, `no ${name} handle on the page`);
      return { x: b.x + b.width / 2 - view.x, y: b.y + b.height / 2 - view.y };
    };
    // The x high face's centre (extent x, centre y) and the y high face's, where the server's rays put them.
    const xHigh = await handleAt('x-high');
    const yHigh = await handleAt('y-high');
    const want = (dx, dy) => ({ x: VIEW / 2 + dx * pxPerMm, y: VIEW / 2 - dy * pxPerMm });
    for (const [what, got, w] of [['x-high', xHigh, want(extent[0] / 2, 0)], ['y-high', yHigh, want(0, extent[1] / 2)]]) {
      assert.ok(Math.hypot(got.x - w.x, got.y - w.y) < 1, `the ${what} handle is at (${got.x}, ${got.y}), not (${w.x}, ${w.y})`);
    }

    // 32 px to the left (and 10 down, across the axis: no effect) is 32 / pxPerMm mm down x.
    const before = await page.evaluate(() => ({ frameId: window.brickcast.lastFrame.frameId, cameraId: window.brickcast.camera().cameraId }));
    await page.mouse.move(view.x + xHigh.x, view.y + xHigh.y);
    await page.mouse.down();
    for (let i = 1; i <= 4; ++i) await page.mouse.move(view.x + xHigh.x - 8 * i, view.y + xHigh.y + 2.5 * i);
    await page.mouse.up();
    const high = 1 - 32 / pxPerMm / extent[0];
    await sendsFlushed(page);
    const after = await page.evaluate(() => ({ sent: window.brickcast.modeAndClip(), cameraId: window.brickcast.camera().cameraId,
      slider: Number(document.getElementById('crop-x-high').value), label: document.getElementById('crop-x-value').textContent }));
    assert.equal(after.cameraId, before.cameraId, 'dragging a handle moved the camera');
    assert.ok(Math.abs(after.sent.crop.max[0] - high * extent[0]) < 1e-6, `the x high face is at ${after.sent.crop.max[0]} mm, not ${high * extent[0]}`);
    assert.ok(Math.abs(after.slider - high) <= 0.0005, `the x high slider is at ${after.slider}, not ${high}`);
    assert.deepEqual(after.sent.crop.min, [0, 0, 0]);
    assert.deepEqual(after.sent.crop.max.slice(1), extent.slice(1), 'the drag moved another face');
    assert.match(after.label, new RegExp(`^0–${Math.round(high * extent[0] * 10) / 10} mm$`));
    await page.waitForFunction((f) => window.brickcast.lastFrame.frameId > f, before.frameId, { timeout: FRAME_TIMEOUT });
    const moved = await handleAt('x-high');
    assert.ok(Math.abs(moved.x - (xHigh.x - 32)) < 1 && Math.abs(moved.y - xHigh.y) < 1, `the handle did not follow: (${moved.x}, ${moved.y})`);

    // Away from the handles the view still orbits; the overlay follows the camera of the frame shown.
    await page.mouse.move(view.x + 30, view.y + 30);
    await page.mouse.down();
    for (let i = 1; i <= 4; ++i) await page.mouse.move(view.x + 30 + 10 * i, view.y + 30);
    await page.mouse.up();
    const orbit = await page.evaluate(() => window.brickcast.camera().cameraId);
    assert.ok(orbit > before.cameraId, 'a drag away from the handles did not orbit');
    await waitForFrame(page, orbit);
    const turned = await handleAt('x-high');
    assert.ok(Math.hypot(turned.x - moved.x, turned.y - moved.y) > 1, 'the overlay did not follow the camera');

    await page.uncheck('#crop');
    await page.waitForFunction(() => window.brickcast.modeAndClip()?.crop === null, null, { timeout: FRAME_TIMEOUT });
    assert.equal(await page.locator('#cut-overlay').isHidden(), true, 'the overlay stays after cropping is off');
    await assertHealthy(v);
  });
});

test('in the isosurface mode the iso value is a line on the histogram, dragged to change it', { timeout: 60000 }, async () => {
  await withDaemon({}, async ({ open }) => {
    const v = await phantomViewer(open);
    const { page } = v;
    assert.equal(await page.evaluate(() => window.brickcast.isoMarker()), null, 'the iso line shows in composite');
    await page.selectOption('#mode', '4');
    await page.waitForFunction(() => window.brickcast.modeAndClip()?.mode === 4 && window.brickcast.isoMarker() !== null, null, { timeout: FRAME_TIMEOUT });
    const info = await page.evaluate(() => window.brickcast.volumes.find((x) => x.name === 'phantom'));
    const start = await page.evaluate(() => ({ marker: window.brickcast.isoMarker(), frameId: window.brickcast.lastFrame.frameId,
      sent: window.brickcast.modeAndClip().isoValue }));
    assert.equal(start.marker.value, start.sent, 'the line is not at the iso value sent');
    const tf = await page.locator('#tf').boundingBox();
    // The plot spans the canvas less 8 px each side: 40 px is 40 / (its width - 16) of the value range.
    const y = tf.y + tf.height / 3;
    await page.mouse.move(tf.x + start.marker.x, y);
    await page.mouse.down();
    for (let i = 1; i <= 4; ++i) await page.mouse.move(tf.x + start.marker.x + 10 * i, y);
    await page.mouse.up();
    const plotWidth = (await page.evaluate(() => document.getElementById('tf').clientWidth)) - 16;
    const want = start.sent + (40 / plotWidth) * (info.valueMax - info.valueMin);
    await sendsFlushed(page);
    const after = await page.evaluate(() => ({ sent: window.brickcast.modeAndClip().isoValue, marker: window.brickcast.isoMarker(),
      input: Number(document.getElementById('iso').value), slider: Number(document.getElementById('iso-range').value) }));
    const step = Number(await page.getAttribute('#iso-range', 'step'));
    assert.ok(Math.abs(after.sent - want) <= step, `the iso value is ${after.sent} after the drag, not ${want}`);
    assert.equal(after.marker.value, after.sent, 'the line is not at the iso value sent');
    assert.ok(Math.abs(after.marker.x - start.marker.x - 40) < 1, `the line moved ${after.marker.x - start.marker.x} px, not 40`);
    assert.equal(after.input, after.sent, 'the iso number is not the value sent');
    assert.equal(after.slider, after.sent, 'the iso slider is not at the value sent');
    await page.waitForFunction((f) => window.brickcast.lastFrame.frameId > f, start.frameId, { timeout: FRAME_TIMEOUT });

    // The slider moves the line.
    const slid = await page.evaluate((value) => {
      const range = document.getElementById('iso-range');
      range.value = String(value);
      range.dispatchEvent(new Event('input', { bubbles: true }));
      return { slider: Number(range.value), marker: window.brickcast.isoMarker() };
    }, info.valueMin + (info.valueMax - info.valueMin) / 4);
    assert.equal(slid.marker.value, slid.slider, 'the line did not follow the slider');
    await page.selectOption('#mode', '1');
    assert.equal(await page.evaluate(() => window.brickcast.isoMarker()), null, 'the iso line stays in MIP');
    await assertHealthy(v);
  });
});

test('two pages on one daemon are served at once, each its own camera', { timeout: 90000 }, async () => {
  await withDaemon({}, async ({ daemon, open }) => {
    const a = await open();
    const b = await open();
    await Promise.all([waitReady(a.page), waitReady(b.page)]);
    await Promise.all([chooseVolume(a.page, 'phantom'), chooseVolume(b.page, 'phantom')]);
    await Promise.all([settleRefined(a.page), settleRefined(b.page)]);

    // Both drag at once, in different directions; both must get frames of their own cameras.
    await Promise.all([drag(a.page, 90, 0, 10), drag(b.page, -40, 70, 10)]);
    const ids = await Promise.all([a, b].map(({ page }) => page.evaluate(() => window.brickcast.camera().cameraId)));
    await Promise.all([waitForFrame(a.page, ids[0], { refined: true, codec: Codec.Png, width: VIEW }),
      waitForFrame(b.page, ids[1], { refined: true, codec: Codec.Png, width: VIEW })]);
    const [va, vb] = [await readView(a.page), await readView(b.page)];
    assert.equal(va.frame.cameraId, ids[0]);
    assert.equal(vb.frame.cameraId, ids[1]);
    const eyeGap = Math.hypot(...va.camera.eye.map((e, i) => e - vb.camera.eye[i]));
    assert.ok(eyeGap > 1, 'the two pages ended with the same camera; the test proves nothing');
    const apart = compareRgb(va.pixels, vb.pixels, VIEW, VIEW);
    assert.ok(apart.differing > VIEW * VIEW * 0.01, 'the two pages show the same image for different cameras');
    await assertMatchesDirect(daemon, 'phantom', va, 'page A');
    await assertMatchesDirect(daemon, 'phantom', vb, 'page B');

    // Still both served: a new camera on each, at the same time.
    const next = await Promise.all([fence(a.page), fence(b.page)]);
    await Promise.all([waitForFrame(a.page, next[0], { refined: true }), waitForFrame(b.page, next[1], { refined: true })]);
    await assertHealthy(a);
    await assertHealthy(b);
  });
});

test('a token is asked for: a wrong one is refused, the right one works, and it leaks into no URL or log', { timeout: 60000 }, async () => {
  const token = `tok-${Math.random().toString(36).slice(2)}-${Date.now().toString(36)}`;
  const wrong = `bad-${Math.random().toString(36).slice(2)}`;
  await withDaemon({ token }, async ({ daemon, open }) => {
    const v = await open();
    const { page } = v;
    await page.waitForFunction(() => window.brickcast?.state === 'auth', null, { timeout: FRAME_TIMEOUT });
    await page.locator('#auth').waitFor({ state: 'visible' });
    assert.equal(await page.locator('#volume option[value="phantom"]').count(), 0, 'the catalog shows before authentication');

    await page.fill('#token', wrong);
    await page.click('#auth button[type=submit]');
    await page.waitForFunction(() => !document.getElementById('auth').hidden &&
      /rejected/.test(document.getElementById('auth-message').textContent), null, { timeout: FRAME_TIMEOUT });
    assert.notEqual(await page.evaluate(() => window.brickcast.state), 'ready', 'a wrong token made the page ready');
    assert.equal(await page.locator('#volume option[value="phantom"]').count(), 0, 'the catalog shows after a wrong token');

    await page.fill('#token', token);
    await page.click('#auth button[type=submit]');
    await waitReady(page);
    await chooseVolume(page, 'phantom');
    await settleRefined(page);
    assert.equal(await page.locator('#auth').isHidden(), true, 'the token prompt is still shown');

    const shown = await readView(page);
    await assertMatchesDirect(daemon, 'phantom', shown, 'with a token', { token });
    assert.ok(v.urls.some((u) => u.startsWith('ws://')), `no WebSocket URL recorded: ${v.urls}`);
    for (const u of v.urls) {
      for (const secret of [token, wrong]) assert.ok(!u.includes(secret), `a token appears in a URL the page requested: ${u}`);
    }
    const stored = await page.evaluate(() => JSON.stringify({ ...sessionStorage }) + JSON.stringify({ ...localStorage }));
    assert.ok(!stored.includes(token), 'the token was stored although "remember" was not ticked');
    await assertHealthy(v);
    await daemon.stop();
    const log = daemon.log();
    assert.ok(!log.includes(token), 'the token appears in the daemon\'s log');
    assert.ok(!log.includes(wrong), 'the wrong token appears in the daemon\'s log');
  });
});

test('over TLS (a self-signed certificate) the page is https, its WebSocket wss, and it shows what the daemon renders', { timeout: 90000 }, async () => {
  await withDaemon({ tls: true }, async ({ daemon, open }) => {
    assert.ok(daemon.url.startsWith('https://'), daemon.url);
    const v = await open();
    const { page } = v;
    await waitReady(page);
    await chooseVolume(page, 'phantom');
    await settleRefined(page);
    const shown = await readView(page);
    await assertMatchesDirect(daemon, 'phantom', shown, 'over TLS');
    assert.ok(v.urls.some((u) => u.startsWith('wss://')), `no wss:// WebSocket: ${v.urls}`);
    assert.ok(!v.urls.some((u) => u.startsWith('ws://') || u.startsWith('http://')), `a plain URL: ${v.urls}`);
    await assertHealthy(v);
  });
});

test('on a configured host name the page works; under a name it was not given (DNS rebinding) it is refused', { timeout: 90000 }, async () => {
  await withDaemon({ webHosts: ['viewer.test'] }, async ({ daemon, open }) => {
    const named = `http://viewer.test:${daemon.webPort}/`;
    const v = await open({ url: named });
    const { page } = v;
    await waitReady(page);
    await chooseVolume(page, 'phantom');
    await settleRefined(page);
    await assertMatchesDirect(daemon, 'phantom', await readView(page), 'under web_hosts');
    await assertHealthy(v);

    const context = await browser.newContext();
    try {
      const rebound = await context.newPage();
      const answer = await rebound.goto(`http://rebound.test:${daemon.webPort}/`);
      assert.equal(answer.status(), 403, 'the page under a name the daemon was not given');
      // The rebound page's own script cannot open the daemon's WebSocket either.
      const opened = await rebound.evaluate((port) => new Promise((resolve) => {
        const ws = new WebSocket(`ws://rebound.test:${port}/ws`);
        ws.onopen = () => resolve(true);
        ws.onerror = () => resolve(false);
      }), daemon.webPort);
      assert.equal(opened, false, 'a WebSocket under the rebound name was opened');
    } finally {
      await context.close();
    }
  });
});

test('a killed daemon shows as disconnected; a new one on the same web port is reconnected to', { timeout: 90000 }, async () => {
  await withDaemon({}, async ({ daemon, open, restart }) => {
    const v = await phantomViewer(open);
    const { page } = v;
    const beforeKill = await page.evaluate(() => ({ frames: window.brickcast.frameCount, cameraId: window.brickcast.camera().cameraId }));

    await daemon.kill();
    await page.waitForFunction(() => window.brickcast.state === 'disconnected', null, { timeout: FRAME_TIMEOUT });
    const label = await page.textContent('#connection');
    assert.match(label, /disconnected/, `the connection line says '${label}'`);
    assert.equal(await page.getAttribute('#connection', 'data-state'), 'disconnected');

    const again = await restart({ web: `127.0.0.1:${daemon.webPort}` });
    assert.equal(again.webPort, daemon.webPort, 'the new daemon did not take the same web port');
    await waitReady(page);
    await page.waitForFunction((n) => window.brickcast.frameCount > n, beforeKill.frames, { timeout: FRAME_TIMEOUT });
    const id = await settleRefined(page);
    assert.ok(id > beforeKill.cameraId, 'cameraIds went backwards across the reconnect');
    const shown = await readView(page);
    assert.equal(shown.frame.refined, true);
    assertUnscaled(shown);
    await assertMatchesDirect(again, 'phantom', shown, 'after the reconnect');
    assert.match(await page.textContent('#connection'), /connected/);
    assert.deepEqual(v.pageErrors.map((e) => e.message), [], 'uncaught errors in the page');
  });
});

// The README's screenshot: the Stanford CT head (../shared/data, beside the repository) when it
// is there, ingested into a temporary store, else the generated vessels volume.
const SHARED_DATA = process.env.BC_SHARED_DATA || path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../../../shared/data');
const CTHEAD = path.join(SHARED_DATA, 'stanford_cthead_256x256x113_uint16.raw');

test('a screenshot of the viewer (BC_VIEWER_SCREENSHOT)', { timeout: 120000 }, async (t) => {
  const out = process.env.BC_VIEWER_SCREENSHOT;
  if (!out) {
    t.skip('BC_VIEWER_SCREENSHOT is not set');
    return;
  }
  const scans = await tempDir('bc-browser-scan-');
  try {
    let scene;
    if (existsSync(CTHEAD)) {
      const store = await ingestRaw(CTHEAD, path.join(scans, 'cthead.bcs'), ['--dims', '256,256,113', '--type', 'u16', '--spacing', '1,1,2']);
      // A 3/4 view from the front left and a little above; the scan's head points to -z.
      const centre = [128, 128, 113];
      const az = (255 * Math.PI) / 180, el = (-15 * Math.PI) / 180, distance = 640;
      const eye = [centre[0] + distance * Math.cos(el) * Math.cos(az), centre[1] + distance * Math.cos(el) * Math.sin(az), centre[2] + distance * Math.sin(el)];
      scene = { volume: { name: 'cthead', store }, preset: 'ct-bone', camera: { eye, target: centre, up: [0, 0, -1] } };
    } else {
      t.diagnostic(`${CTHEAD} is missing: the screenshot shows the generated vessels volume`);
      scene = { volume: { name: 'vessels', generate: 'vessels', dims: [128, 128, 128] }, preset: 'vessels', camera: null };
    }
    await withDaemon({ volumes: [scene.volume] }, async ({ open }) => {
      const v = await open({ size: null, viewport: { width: 1280, height: 800 } });
      const { page } = v;
      await waitReady(page);
      await chooseVolume(page, scene.volume.name);
      await page.evaluate(({ preset, camera }) => {
        window.brickcast.setRenderOptions({ stepVoxels: 0.5 });
        window.brickcast.setPreset(preset);
        if (camera) window.brickcast.setCamera(camera);
      }, scene);
      // The histogram under the transfer function, and the overlay's residency line.
      await page.waitForFunction(() => !document.getElementById('tf-hint').textContent, null, { timeout: FRAME_TIMEOUT });
      await page.waitForFunction(() => /cache/.test(document.getElementById('overlay').textContent), null, { timeout: FRAME_TIMEOUT });
      const width = await page.evaluate(() => window.brickcast.renderOptions().width);
      await settleRefined(page, width);
      await mkdir(path.dirname(path.resolve(out)), { recursive: true });
      await page.screenshot({ path: out });
      console.log(`# wrote ${out} (${scene.volume.name}, ${scene.preset})`);
      await assertHealthy(v);
    });
  } finally {
    await rm(scans, { recursive: true, force: true });
  }
});
