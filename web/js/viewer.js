// The page: wires the connection, the volume picker, the camera controls, the transfer-function
// editor, the render options, the mode and cut controls and the frame pipeline together, and
// exposes window.brickcast for automated browser tests.

import { Connection, ServerError, DisconnectedError, socketUrl } from './connection.js';
import {
  Type, Capability, Codec, Renderer, Quality, FrameMode, ErrorCode, TECHNIQUES_ALL, LEVEL_AUTOMATIC,
  MAX_IMAGE_EDGE, ProtocolError, RenderFlags, Mode, encodeSetFrameBudget, encodeSetModeAndClip,
} from './protocol.js';
import { Trackball } from './trackball.js';
import { attachControls } from './controls.js';
import { TfEditor } from './tfeditor.js';
import {
  CLIP_AXES, clampIso, clipLabel, cropLabels, defaultCut, isoRangeOf, modeAndClipOf, orderCropRange, snapIso, whyNoCap,
} from './modes.js';
import { CutOverlay } from './cutoverlay.js';
import {
  FrameStats, autoRendererOf, formatBytes, frameDetailLabel, frameSize, isInteractiveSizeOf, residencyLine, volumeLabel,
} from './frames.js';

const STATS_INTERVAL_MS = 3000;
const RENDERER_NAMES = {
  [Renderer.GpuRaycaster]: 'GPU raycaster', [Renderer.CpuRaycaster]: 'CPU raycaster',
  [Renderer.Reference]: 'CPU reference (slow, exact)', [Renderer.Splatter]: 'splatting (CPU)',
  [Renderer.GpuSplatter]: 'splatting (GPU)', [Renderer.Auto]: 'auto (the server picks)',
};
const CODEC_NAMES = ['raw', 'zstd', 'zstd delta', 'JPEG', 'PNG'];
const IMAGE_TYPES = { [Codec.Jpeg]: 'image/jpeg', [Codec.Png]: 'image/png' };
const FRAME_TARGET_TITLE = 'time to draw a frame while the camera moves: the server picks the pyramid level and image scale to meet it';
const REST_PSNR_TITLE = 'at rest, refine until the estimated PSNR against the converged image reaches this';
const NO_FRAME_BUDGET = 'this server does not support frame budgets (SetFrameBudget, Hello capability bit 4)';
const NO_MODES = 'this server does not draw modes and cuts (SetModeAndClip, Hello capability bit 5)';
const MODES_NEED_VOLUME = 'modes and cuts: open a volume first';
const CAP_TITLE = 'draw the faces the crop box and the clip plane cut as a shaded surface: coloured by the transfer function in composite, in the surface\'s colour where the value is at or above the iso value in the isosurface mode';
const NO_CAPPING = 'this server does not cap cuts (SetModeAndClip cutFlags, Hello capability bit 6)';

const $ = (id) => document.getElementById(id);
const els = {
  volume: $('volume'), connection: $('connection'), reconnect: $('reconnect'), view: $('view'),
  overlay: $('overlay'), placeholder: $('placeholder'), renderer: $('renderer'), quality: $('quality'),
  step: $('step'), jpegQuality: $('jpeg-quality'), jpegQualityValue: $('jpeg-quality-value'),
  maxSize: $('max-size'), frameTarget: $('frame-target'), restPsnr: $('rest-psnr'), stats: $('stats'),
  status: $('status'), statusText: $('status-text'),
  statusDismiss: $('status-dismiss'), auth: $('auth'), authForm: $('auth-form'),
  authMessage: $('auth-message'), token: $('token'), tokenRemember: $('token-remember'),
  modeAndCut: $('mode-and-cut'), mode: $('mode'), isoRow: $('iso-row'), iso: $('iso'),
  isoRange: $('iso-range'), crop: $('crop'), clip: $('clip'), clipAxis: $('clip-axis'),
  clipPosition: $('clip-position'), clipPositionValue: $('clip-position-value'), cap: $('cap'),
  cropAxes: ['x', 'y', 'z'].map((a) => ({ low: $(`crop-${a}-low`), high: $(`crop-${a}-high`), value: $(`crop-${a}-value`) })),
  cutOverlay: $('cut-overlay'),
};

const conn = new Connection(socketUrl(location.href));
const ctx = els.view.getContext('2d', { alpha: false });

const state = {
  volumes: [],
  volume: null, // VolumeInfo of the open volume
  opening: null, // name being opened
  trackball: null,
  nextCameraId: 1,
  minCameraId: 0, // frames answering cameras before the current volume's first are stale
  inputTimes: new Map(), // cameraId -> performance.now() of the input that made it
  sentCameras: new Map(), // cameraId -> the SetCamera sent: the cut overlay projects with the shown frame's
  lastCamera: null,
  lastTf: null,
  lastOptions: null,
  options: {
    width: 0, height: 0, stepVoxels: 1, techniques: TECHNIQUES_ALL, ertThreshold: 0.99,
    renderer: Renderer.Auto, quality: Quality.Adaptive, codec: Codec.Jpeg, codecQuality: 80,
    level: LEVEL_AUTOMATIC, refinedCodec: Codec.Png + 1,
    // Interactive frames at the size drawn (half each edge): a quarter of the pixels to encode
    // and send; the canvas scales them up smoothly (draw()).
    flags: RenderFlags.UnscaledInteractive,
  },
  // SetFrameBudget as the controls say (0 and 0: the server's defaults), and as this session's
  // server has it: a session starts with both 0; null when unknown (after an Error).
  frameBudget: { interactiveMs: 0, restPsnrDb: 0 },
  lastFrameBudget: null,
  // The mode and cut controls (modes.js defaultCut's shape), whether the server takes
  // SetModeAndClip (Capability.ModesAndClips, and no UnknownType since) and its cap
  // (Capability.Capping), and the last sent.
  cut: defaultCut({ valueMin: 0, valueMax: 0 }),
  modesSupported: false,
  cappingSupported: false,
  lastModeAndClip: null,
  maxEdge: 1024,
  deviceSize: { width: 0, height: 0 },
  lastDrawnCameraId: 0,
  lastFrame: null,
  shownView: null, // {camera, width, height}: the camera and size of the frame on the canvas (the cut overlay's projection)
  lastBitmap: null, // the last frame drawn, decoded, at its own size (lastFrameImage())
  residency: '',
  autoRenderer: null, // {renderer, reason}: what the server's auto draws with (its Stats)
  frameCount: 0,
  decoding: false,
  pendingFrame: null,
  stats: new FrameStats(),
  statsTimer: 0,
};

// ---- status line -------------------------------------------------------------------------

/** Shows a message in the dismissable status line (kind 'error' or 'info'). */
function showStatus(text, kind = 'error') {
  els.statusText.textContent = text;
  els.status.dataset.kind = kind;
  els.status.hidden = false;
}

function clearStatus() {
  els.status.hidden = true;
}

els.statusDismiss.addEventListener('click', clearStatus);

function report(e) {
  if (e instanceof DisconnectedError) return; // the connection line and Reconnect button say it
  if (e instanceof ServerError || e instanceof ProtocolError) showStatus(e.message);
  else showStatus(String(e?.message ?? e));
}

// ---- coalescing --------------------------------------------------------------------------

/** A sender that sends only the latest of the values given to it within one animation frame. */
function coalesced(send) {
  let pending = null, scheduled = false;
  const flush = () => {
    scheduled = false;
    const v = pending;
    pending = null;
    if (v) send(v);
  };
  const schedule = (v) => {
    pending = v;
    if (!scheduled) {
      scheduled = true;
      requestAnimationFrame(flush);
    }
  };
  schedule.cancel = () => { pending = null; };
  return schedule;
}

// ---- sending -----------------------------------------------------------------------------

function trySend(type, body) {
  try {
    return conn.send(type, body);
  } catch (e) {
    report(e);
    return 0;
  }
}

/** Sends a camera with the next cameraId; inputTime is when the input that made it happened. */
function sendCamera(cam, inputTime = performance.now()) {
  if (!state.volume || conn.state !== 'ready') return 0;
  const cameraId = state.nextCameraId;
  const msg = {
    cameraId, eye: cam.eye.slice(), target: cam.target.slice(), up: cam.up.slice(),
    fovYDeg: cam.fovYDeg, orthographic: !!cam.orthographic, orthoHeight: cam.orthoHeight,
  };
  if (!trySend(Type.SetCamera, msg)) return 0;
  state.nextCameraId = cameraId >= 0xffffffff ? 1 : cameraId + 1;
  state.inputTimes.set(cameraId, inputTime);
  state.sentCameras.set(cameraId, msg);
  // Only recent ids can still be answered: keep the maps small.
  if (state.inputTimes.size > 256) state.inputTimes.delete(state.inputTimes.keys().next().value);
  if (state.sentCameras.size > 256) state.sentCameras.delete(state.sentCameras.keys().next().value);
  state.lastCamera = msg;
  return cameraId;
}
const scheduleCamera = coalesced(({ cam, inputTime }) => sendCamera(cam, inputTime));

function sendTransferFunction(tf) {
  if (!state.volume || conn.state !== 'ready') return;
  if (trySend(Type.SetTransferFunction, tf)) state.lastTf = structuredClone(tf);
}
const scheduleTransferFunction = coalesced(sendTransferFunction);

function sendRenderOptions() {
  const o = state.options;
  if (!state.volume || conn.state !== 'ready' || !o.width || !o.height) return;
  if (trySend(Type.SetRenderOptions, o)) state.lastOptions = { ...o };
}
const scheduleRenderOptions = coalesced(sendRenderOptions);

/**
 * Sends SetFrameBudget with both values when the server takes it (Capability.FrameBudget) and
 * they differ from what the session has (or always, with `force`); returns what was sent or null.
 */
function sendFrameBudget(force = false) {
  if (conn.state !== 'ready' || !conn.can(Capability.FrameBudget)) return null;
  const b = state.frameBudget, last = state.lastFrameBudget;
  if (!force && last && last.interactiveMs === b.interactiveMs && last.restPsnrDb === b.restPsnrDb) return null;
  if (!trySend(Type.SetFrameBudget, b)) return null;
  state.lastFrameBudget = { ...b };
  return { ...b };
}

/**
 * Sends SetModeAndClip as the mode and cut controls say when the server takes it
 * (Capability.ModesAndClips) and it differs from the last sent (or always, with `force`); the
 * cap only to a server that takes it (Capability.Capping). Returns what was sent or null.
 */
function sendModeAndClip(force = false) {
  if (!state.volume || conn.state !== 'ready' || !state.modesSupported) return null;
  const m = modeAndClipOf(state.volume, { ...state.cut, cap: state.cut.cap && state.cappingSupported });
  if (!force && JSON.stringify(m) === JSON.stringify(state.lastModeAndClip)) return null;
  if (!trySend(Type.SetModeAndClip, m)) return null;
  state.lastModeAndClip = m;
  return structuredClone(m);
}
const scheduleModeAndClip = coalesced(() => sendModeAndClip());

// ---- connection --------------------------------------------------------------------------

conn.addEventListener('state', (e) => {
  const { state: s, reason, retryInMs } = e.detail;
  els.connection.dataset.state = s;
  els.reconnect.hidden = s !== 'disconnected';
  const label = {
    connecting: 'connecting…',
    auth: 'waiting for a token',
    ready: `connected${conn.serverHello?.software ? ` to ${conn.serverHello.software}` : ''}`,
    disconnected: retryInMs ? `disconnected — reconnecting in ${Math.ceil(retryInMs / 1000)} s…` : 'disconnected',
  }[s];
  els.connection.textContent = label;
  els.connection.title = reason || '';
  if (s === 'disconnected') {
    clearInterval(state.statsTimer);
    els.volume.disabled = true;
    if (reason) showStatus(`Disconnected: ${reason}${retryInMs ? ' — reconnecting…' : ''}`, retryInMs ? 'info' : 'error');
  }
  if (s === 'ready') onReady();
});

conn.addEventListener('auth', (e) => {
  els.authMessage.textContent = e.detail.failed ? 'The server rejected that token. Enter the right one.' : 'This server requires an access token.';
  els.authMessage.className = e.detail.failed ? 'bad' : '';
  els.auth.hidden = false;
  els.token.value = '';
  els.token.focus();
});

els.authForm.addEventListener('submit', (e) => {
  e.preventDefault();
  const token = els.token.value;
  if (!token) return;
  els.auth.hidden = true;
  els.token.value = '';
  conn.submitToken(token, els.tokenRemember.checked);
});

conn.addEventListener('error', (e) => report(e.detail));
els.reconnect.addEventListener('click', () => conn.reconnectNow());
addEventListener('pagehide', () => conn.close());
// A page restored from the back-forward cache said Bye when it was hidden: connect again.
addEventListener('pageshow', (e) => { if (e.persisted) conn.reconnectNow(); });

conn.addEventListener('message', (e) => {
  const m = e.detail;
  switch (m.type) {
    case Type.Frame: return onFrame(m.body);
    case Type.VolumeList: return onVolumeList(m.body.volumes);
    case Type.VolumeOpened:
      // Unasked (request 0): the operator reloaded the catalog and the server moved us to the new store.
      if (m.request === 0) return onVolumeReloaded(m.body);
      return undefined;
    default: return undefined;
  }
});

conn.addEventListener('error', (e) => {
  const err = e.detail;
  if (!(err instanceof ServerError)) return;
  const gpu = state.options.renderer === Renderer.GpuRaycaster || state.options.renderer === Renderer.GpuSplatter;
  if (gpu && (err.code === ErrorCode.RenderFailed || err.code === ErrorCode.OutOfRange) && /OpenGL/.test(err.serverMessage)) {
    // The server found it cannot draw on the GPU (PROTOCOL.md, Hello): keep viewing on the CPU.
    showStatus(`${err.message} — switched to the CPU raycaster.`);
    setRenderOptions({ renderer: Renderer.CpuRaycaster });
    return;
  }
  if (state.options.renderer === Renderer.Auto && err.code === ErrorCode.OutOfRange &&
      err.offendingType === Type.SetRenderOptions && /renderer/.test(err.serverMessage)) {
    // A server from before 2026-12-03 knows no auto (renderer 5): pick as the page did then.
    setRenderOptions({ renderer: conn.can(Capability.GpuRenderer) ? Renderer.GpuRaycaster : Renderer.CpuRaycaster });
    return;
  }
  if (state.options.flags && err.offendingType === Type.SetRenderOptions && /reserved|flags/.test(err.serverMessage)) {
    // A server from before 2026-12-03 knows no RenderOptions flags (the bytes were reserved):
    // ask for full-size interactive frames instead.
    state.options.flags = 0;
    clearStatus();
    sendRenderOptions();
    return;
  }
  if (err.offendingType === Type.SetFrameBudget) {
    // The session's budget is as it was before, which we may not know: send it again next time.
    state.lastFrameBudget = null;
    if (err.code === ErrorCode.UnknownType) showFrameBudgetControls(false);
    return;
  }
  if (err.offendingType === Type.SetModeAndClip) {
    // What the session draws is unknown now: send the controls again at the next change.
    state.lastModeAndClip = null;
    if (err.code === ErrorCode.UnknownType) {
      state.modesSupported = false;
      showModeControls();
    }
    return;
  }
  if (err.code === ErrorCode.UnknownVolume && err.request === 0 && state.volume) {
    // The volume we view was removed or changed shape by a catalog reload.
    closeVolume();
    conn.send(Type.ListVolumes);
  }
});

function onReady() {
  els.auth.hidden = true;
  clearStatus();
  fillRenderers();
  const o = state.options;
  // Interactive frames: JPEG where offered (small, fast), else PNG, else raw.
  o.codec = conn.hasCodec(Codec.Jpeg) ? Codec.Jpeg : conn.hasCodec(Codec.Png) ? Codec.Png : Codec.Raw;
  o.codecQuality = o.codec === Codec.Jpeg ? Number(els.jpegQuality.value) : 0;
  o.refinedCodec = conn.hasCodec(Codec.Png) ? Codec.Png + 1 : 0;
  els.jpegQuality.disabled = o.codec !== Codec.Jpeg;
  // A new session starts with both budgets 0: a budget chosen before is sent again once the
  // volume is (re)opened (onVolumeOpened), or when a control changes.
  state.lastFrameBudget = { interactiveMs: 0, restPsnrDb: 0 };
  showFrameBudgetControls(conn.can(Capability.FrameBudget));
  // Sent on every (re)open of a volume (onVolumeOpened).
  state.modesSupported = conn.can(Capability.ModesAndClips);
  state.cappingSupported = conn.can(Capability.Capping);
  state.lastModeAndClip = null;
  showModeControls();
  conn.request(Type.ListVolumes, {}, Type.VolumeList).catch(report);
  const reopen = state.volume?.name ?? state.opening;
  if (reopen) openVolume(reopen).catch(report);
  clearInterval(state.statsTimer);
  state.statsTimer = setInterval(requestStats, STATS_INTERVAL_MS);
}

function fillRenderers() {
  // auto first: the server draws on its GPU when it has a hardware one, else on the CPU.
  const allowed = [Renderer.Auto];
  if (conn.can(Capability.GpuRenderer)) allowed.push(Renderer.GpuRaycaster);
  if (conn.can(Capability.CpuRenderer)) allowed.push(Renderer.CpuRaycaster, Renderer.Reference, Renderer.Splatter);
  if (conn.can(Capability.GpuRenderer)) allowed.push(Renderer.GpuSplatter);
  if (allowed.length === 1) {
    showStatus('The server reports neither a CPU nor a GPU renderer.');
    allowed.push(Renderer.CpuRaycaster);
  }
  els.renderer.replaceChildren(...allowed.map((r) => new Option(RENDERER_NAMES[r], String(r))));
  // The first connection starts on auto; later ones keep the user's choice.
  if (!state.rendererChosen || !allowed.includes(state.options.renderer)) state.options.renderer = allowed[0];
  state.rendererChosen = true;
  els.renderer.value = String(state.options.renderer);
}

/** The frame-budget controls work only with a server that takes SetFrameBudget; older ones answer UnknownType. */
function showFrameBudgetControls(supported) {
  els.frameTarget.disabled = els.restPsnr.disabled = !supported;
  els.frameTarget.title = supported ? FRAME_TARGET_TITLE : NO_FRAME_BUDGET;
  els.restPsnr.title = supported ? REST_PSNR_TITLE : NO_FRAME_BUDGET;
}

// ---- volumes -----------------------------------------------------------------------------

function onVolumeList(volumes) {
  state.volumes = volumes;
  const current = state.volume?.name ?? state.opening ?? '';
  const none = new Option(volumes.length ? '— choose a volume —' : '— the catalog is empty —', '');
  none.disabled = true;
  els.volume.replaceChildren(none, ...volumes.map((v) => {
    const o = new Option(volumeLabel(v), v.name);
    o.title = `${v.levels} levels, values ${v.valueMin}..${v.valueMax}, spacing ${v.spacingMm.join(' × ')} mm`;
    return o;
  }));
  els.volume.value = volumes.some((v) => v.name === current) ? current : '';
  els.volume.disabled = volumes.length === 0;
}

els.volume.addEventListener('change', () => {
  if (els.volume.value) openVolume(els.volume.value).catch(report);
});

/** Opens a catalog volume; resolves with its VolumeInfo once it is shown. */
async function openVolume(name) {
  state.opening = name;
  let info;
  try {
    info = await conn.request(Type.OpenVolume, { name }, Type.VolumeOpened);
  } catch (e) {
    // An open cut short by a disconnect is retried when the connection is back (onReady).
    if (!(e instanceof DisconnectedError) && state.opening === name) state.opening = null;
    throw e;
  }
  if (state.opening === name) state.opening = null;
  onVolumeOpened(info);
  return info;
}

function sameGeometry(a, b) {
  return !!a && !!b && a.name === b.name && a.voxelType === b.voxelType &&
    a.dims.every((d, i) => d === b.dims[i]) && a.spacingMm.every((s, i) => s === b.spacingMm[i]);
}

function onVolumeOpened(info) {
  // Reopening the same volume (a reconnect) keeps the user's view and edits.
  const same = sameGeometry(state.volume, info) && state.trackball;
  state.volume = info;
  if (!same) {
    state.trackball = new Trackball(info);
    state.shownView = null; // until the new volume's first frame
  }
  els.volume.value = info.name;
  els.placeholder.hidden = true;
  tfEditor.setVolume(info, same);
  scheduleCamera.cancel();
  const cameraId = sendCamera(state.trackball.camera);
  state.minCameraId = cameraId;
  requestHistogram();
  const tf = tfEditor.current();
  if (tf) sendTransferFunction(tf);
  sendRenderOptions();
  // Only when the user chose a budget: a session starts with both 0.
  sendFrameBudget();
  // Another volume starts composite, uncut; the same one (a reconnect) keeps the controls.
  if (!same) state.cut = defaultCut(info);
  showCut();
  showModeControls();
  sendModeAndClip(true);
  trySend(Type.RequestFrame, { mode: FrameMode.ContinuousOn });
}

function onVolumeReloaded(info) {
  // Same name and geometry by the server's rule: camera and transfer function stay; values may not.
  state.volume = info;
  tfEditor.setVolume(info, true);
  requestHistogram();
  // The iso value stays within the values the volume has now.
  showCut();
  scheduleModeAndClip(true);
  const i = state.volumes.findIndex((v) => v.name === info.name);
  if (i >= 0) {
    state.volumes[i] = info;
    onVolumeList(state.volumes);
  }
  showStatus(`Volume '${info.name}' was reloaded by the server.`, 'info');
}

function closeVolume() {
  state.volume = null;
  state.trackball = null;
  state.pendingFrame = null;
  els.volume.value = '';
  els.placeholder.hidden = false;
  els.overlay.textContent = '';
  ctx.fillStyle = '#000';
  ctx.fillRect(0, 0, els.view.width, els.view.height);
  state.lastBitmap?.close();
  state.lastBitmap = null;
  state.shownView = null;
  tfEditor.setHistogram(null, '');
  showModeControls();
  drawCutOverlay();
}

function requestHistogram() {
  const name = state.volume?.name;
  conn.request(Type.RequestHistogram, {}, Type.Histogram)
    .then((h) => { if (state.volume?.name === name) tfEditor.setHistogram(h); })
    .catch((e) => {
      if (state.volume?.name === name) tfEditor.setHistogram(null, `no histogram: ${e.message}`);
    });
}

function requestStats() {
  // A hidden tab asks nothing, so the server's idle timeout can still end a forgotten session.
  if (!state.volume || conn.state !== 'ready' || document.hidden) return;
  conn.request(Type.RequestStats, {}, Type.Stats).then(showStats).catch(() => {});
}

function showStats({ counters }) {
  els.stats.textContent = counters.length
    ? counters.map(({ name, value }) => `${name} ${formatCounter(value)}`).join('\n')
    : 'no counters';
  // The overlay gets one line for the open volume; the panel above keeps every counter.
  state.residency = state.volume ? residencyLine(counters, state.volume.name) : '';
  showAutoRenderer(autoRendererOf(counters));
  drawOverlay();
}

/** The renderer control's auto entry and the overlay say what the server's auto chose. */
function showAutoRenderer(choice) {
  state.autoRenderer = choice;
  const option = [...els.renderer.options].find((o) => o.value === String(Renderer.Auto));
  if (option) option.textContent = choice ? `auto: ${choice.renderer} (the server's choice)` : RENDERER_NAMES[Renderer.Auto];
  if (option && choice) option.title = choice.reason;
}

function formatCounter(v) {
  return Number.isInteger(v) ? String(v) : v.toPrecision(4);
}

// ---- camera input ------------------------------------------------------------------------

attachControls(els.view, () => state.trackball, (cam, inputTime) => scheduleCamera({ cam, inputTime }));

// ---- transfer function -------------------------------------------------------------------

const tfEditor = new TfEditor({
  canvas: $('tf'), strip: $('tf-colours'), presetSelect: $('preset'), shading: $('shading'),
  valueInput: $('tf-value'), alphaInput: $('tf-alpha'), hint: $('tf-hint'),
  onChange: (tf) => scheduleTransferFunction(tf),
  // The iso line dragged on the histogram: as the iso slider (its step, coalesced sends).
  onIso: (value) => {
    if (!state.volume || state.cut.mode !== Mode.Isosurface || els.modeAndCut.disabled) return;
    state.cut.isoValue = snapIso(state.volume, value);
    cutChanged();
  },
});

fetch(new URL('presets.json', location.href))
  .then((r) => {
    if (!r.ok) throw new Error(`presets.json: HTTP ${r.status}`);
    return r.json();
  })
  .then((presets) => {
    if (!Array.isArray(presets)) throw new Error('presets.json is not an array');
    const hadNone = !tfEditor.current();
    tfEditor.setPresets(presets);
    // A volume opened before the presets arrived has had no transfer function from us yet.
    if (hadNone && tfEditor.current()) sendTransferFunction(tfEditor.current());
  })
  .catch((e) => showStatus(`Transfer-function presets unavailable: ${e.message}`));

// ---- render options ----------------------------------------------------------------------

function optionsChanged() {
  scheduleRenderOptions(state.options);
}

els.renderer.addEventListener('change', () => { state.options.renderer = Number(els.renderer.value); optionsChanged(); });
els.quality.addEventListener('change', () => { state.options.quality = Number(els.quality.value); optionsChanged(); });
els.step.addEventListener('change', () => { state.options.stepVoxels = Number(els.step.value); optionsChanged(); });
els.jpegQuality.addEventListener('input', () => {
  els.jpegQualityValue.textContent = els.jpegQuality.value;
  state.options.codecQuality = Number(els.jpegQuality.value);
  optionsChanged();
});
els.maxSize.addEventListener('change', () => {
  state.maxEdge = Number(els.maxSize.value);
  applySize();
});

function frameBudgetChanged() {
  state.frameBudget = { interactiveMs: Number(els.frameTarget.value), restPsnrDb: Number(els.restPsnr.value) };
  sendFrameBudget();
}
els.frameTarget.addEventListener('change', frameBudgetChanged);
els.restPsnr.addEventListener('change', frameBudgetChanged);

/** Selects `value` in a select, adding an option labelled `label` when it has none for it (values the test API sets). */
function selectValue(select, value, label) {
  const v = String(value);
  if (![...select.options].some((o) => o.value === v)) select.add(new Option(label, v));
  select.value = v;
}

/** Merges a partial {interactiveMs, restPsnrDb} into the budget, shows it in the controls and sends it now. */
function setFrameBudget(partial) {
  const b = { ...state.frameBudget, ...partial };
  // Checked before the controls change: encode() would refuse it after.
  encodeSetFrameBudget(b);
  state.frameBudget = b;
  selectValue(els.frameTarget, b.interactiveMs, b.interactiveMs ? `${b.interactiveMs} ms` : 'server default');
  selectValue(els.restPsnr, b.restPsnrDb, b.restPsnrDb ? `${b.restPsnrDb} dB` : 'off');
  return sendFrameBudget(true);
}

function applySize() {
  const { width, height } = frameSize(state.deviceSize.width, state.deviceSize.height, Math.min(MAX_IMAGE_EDGE, state.maxEdge));
  if (width === state.options.width && height === state.options.height) return;
  state.options.width = width;
  state.options.height = height;
  optionsChanged();
}

function measure(entry) {
  const dpr = devicePixelRatio || 1;
  const width = entry.contentRect.width * dpr, height = entry.contentRect.height * dpr;
  // The browser's exact device-pixel size where it reports one that agrees with CSS size × ratio
  // (device emulation can report CSS pixels there).
  const box = entry.devicePixelContentBoxSize?.[0];
  const exact = box && Math.abs(box.inlineSize - width) <= 1 && Math.abs(box.blockSize - height) <= 1;
  state.deviceSize = exact ? { width: box.inlineSize, height: box.blockSize } : { width, height };
  applySize();
}

let lastEntry = null;
new ResizeObserver(([entry]) => {
  lastEntry = entry;
  measure(entry);
  drawCutOverlay();
}).observe(els.view);

// A window moved to a screen of another pixel ratio keeps its CSS size: no resize event then.
(function watchPixelRatio() {
  matchMedia(`(resolution: ${devicePixelRatio}dppx)`).addEventListener('change', () => {
    if (lastEntry) measure(lastEntry);
    watchPixelRatio();
  }, { once: true });
})();

/**
 * Merges a partial RenderOptions into the current ones, shows them in the controls and sends
 * them now. A new codec without a codecQuality gets that codec's default (0), or the slider's
 * JPEG quality when it is JPEG: another codec's quality would be out of range.
 */
function setRenderOptions(partial) {
  const p = { ...partial };
  if (p.codec !== undefined && p.codec !== state.options.codec && p.codecQuality === undefined) {
    p.codecQuality = p.codec === Codec.Jpeg ? Number(els.jpegQuality.value) : 0;
  }
  Object.assign(state.options, p);
  els.renderer.value = String(state.options.renderer);
  els.quality.value = String(state.options.quality);
  els.step.value = String(state.options.stepVoxels);
  els.jpegQuality.disabled = state.options.codec !== Codec.Jpeg;
  // The slider shows JPEG qualities (1..100) only; 0 (the default) leaves it as it is.
  if (state.options.codec === Codec.Jpeg && state.options.codecQuality >= 1) {
    els.jpegQuality.value = String(state.options.codecQuality);
    els.jpegQualityValue.textContent = String(state.options.codecQuality);
  }
  scheduleRenderOptions.cancel();
  sendRenderOptions();
  return state.lastOptions && { ...state.lastOptions };
}

// ---- mode and cut ------------------------------------------------------------------------

// The controls' own titles (or none), put back when the group is enabled again; the group has none then.
// The cap's title says why it is off (showCap).
const modeTitles = new Map([els.modeAndCut, ...els.modeAndCut.querySelectorAll('input:not(#cap), select')].map((el) => [el, el.title]));
modeTitles.set(els.modeAndCut, '');

/**
 * The mode and cut group works only with a server that takes SetModeAndClip (older ones answer
 * UnknownType) and an open volume (the iso value and the cuts are in its values and its mm).
 */
function showModeControls() {
  const why = !state.modesSupported ? NO_MODES : !state.volume ? MODES_NEED_VOLUME : '';
  els.modeAndCut.disabled = !!why;
  for (const [el, title] of modeTitles) {
    if (why || title) el.title = why || title;
    else el.removeAttribute('title');
  }
  showCap();
  drawCutOverlay();
}

/**
 * The cap box: checked when the cut faces are capped; disabled, its tooltip saying why, with a
 * server that does not cap (Capability.Capping), in MIP, MinIP or average, or with nothing cut.
 * It keeps the choice for when capping is possible again.
 */
function showCap() {
  const why = !state.cappingSupported ? NO_CAPPING : whyNoCap(state.cut);
  els.cap.disabled = !!why;
  els.cap.checked = state.cut.cap && !why;
  // The disabled group's tooltip says why first; the label has it too (a disabled box shows none in some browsers).
  const title = els.modeAndCut.disabled ? els.modeAndCut.title : why ? `cap the cut faces: ${why}` : CAP_TITLE;
  els.cap.title = els.cap.parentElement.title = title;
}

/** Shows state.cut in the controls: the iso value only in the isosurface mode, the sliders of a cut only while it is on. */
function showCut() {
  const c = state.cut, v = state.volume;
  els.mode.value = String(c.mode);
  const iso = c.mode === Mode.Isosurface;
  els.isoRow.hidden = !iso;
  els.iso.disabled = els.isoRange.disabled = !iso;
  if (v) {
    const r = isoRangeOf(v);
    c.isoValue = clampIso(v, c.isoValue);
    for (const el of [els.iso, els.isoRange]) {
      el.min = String(r.min);
      el.max = String(r.max);
    }
    els.isoRange.step = String(r.step);
    els.isoRange.value = String(c.isoValue);
    els.iso.value = String(c.isoValue);
  }
  els.crop.checked = c.cropped;
  const labels = v ? cropLabels(v, c.low, c.high) : ['', '', ''];
  els.cropAxes.forEach((axis, a) => {
    axis.low.value = String(c.low[a]);
    axis.high.value = String(c.high[a]);
    axis.low.disabled = axis.high.disabled = !c.cropped;
    axis.value.textContent = labels[a];
  });
  els.clip.checked = c.clip;
  els.clipAxis.value = c.axis;
  els.clipPosition.value = String(c.position);
  els.clipAxis.disabled = els.clipPosition.disabled = !c.clip;
  els.clipPositionValue.textContent = v ? clipLabel(v, c.axis, c.position) : '';
  showCap();
  tfEditor.setIso(iso && v ? c.isoValue : null);
  drawCutOverlay();
}

function cutChanged() {
  showCut();
  scheduleModeAndClip(true);
}

els.mode.addEventListener('change', () => { state.cut.mode = Number(els.mode.value); cutChanged(); });
els.isoRange.addEventListener('input', () => { state.cut.isoValue = Number(els.isoRange.value); cutChanged(); });
els.iso.addEventListener('input', () => {
  // While typing: only numbers (an empty or partial entry waits), kept within the volume's values on 'change'.
  const v = els.iso.value === '' ? NaN : Number(els.iso.value);
  if (!Number.isFinite(v) || !state.volume) return;
  state.cut.isoValue = clampIso(state.volume, v);
  els.isoRange.value = String(state.cut.isoValue);
  scheduleModeAndClip(true);
});
els.iso.addEventListener('change', cutChanged);
els.crop.addEventListener('change', () => { state.cut.cropped = els.crop.checked; cutChanged(); });
els.cropAxes.forEach((axis, a) => {
  for (const moved of ['low', 'high']) {
    axis[moved].addEventListener('input', () => {
      // The slider moved stops short of the other one.
      const r = orderCropRange(Number(axis.low.value), Number(axis.high.value), moved);
      state.cut.low[a] = r.low;
      state.cut.high[a] = r.high;
      cutChanged();
    });
  }
});
els.clip.addEventListener('change', () => { state.cut.clip = els.clip.checked; cutChanged(); });
els.clipAxis.addEventListener('change', () => { state.cut.axis = els.clipAxis.value; cutChanged(); });
els.clipPosition.addEventListener('input', () => { state.cut.position = Number(els.clipPosition.value); cutChanged(); });
els.cap.addEventListener('change', () => { state.cut.cap = els.cap.checked; cutChanged(); });

/**
 * Merges a partial mode and cut state ({mode, isoValue, cropped, low, high, clip, axis,
 * position, cap}, fractions of the volume's extent) into the controls, shows it and sends it now.
 */
function setModeAndClip(partial) {
  if (!state.volume) throw new Error('no volume is open');
  const cut = { ...structuredClone(state.cut), ...structuredClone(partial) };
  if (!CLIP_AXES.includes(cut.axis)) throw new RangeError(`axis: '${cut.axis}' is not one of ${CLIP_AXES.join(' ')}`);
  if (typeof cut.cap !== 'boolean') throw new TypeError(`cap: ${cut.cap} is not a boolean`);
  for (let a = 0; a < 3; ++a) ({ low: cut.low[a], high: cut.high[a] } = orderCropRange(cut.low[a], cut.high[a]));
  cut.position = Number.isFinite(cut.position) ? Math.min(1, Math.max(0, cut.position)) : 0.5;
  // Checked before the controls change: encode() would refuse it after.
  encodeSetModeAndClip(modeAndClipOf(state.volume, cut));
  state.cut = cut;
  showCut();
  scheduleModeAndClip.cancel();
  return sendModeAndClip(true);
}

// ---- cut overlay -------------------------------------------------------------------------

// A handle dragged on the view moves its face or the plane as its slider does.
const cutOverlay = new CutOverlay({
  svg: els.cutOverlay, canvas: els.view,
  canDrag: () => !els.modeAndCut.disabled,
  onDrag: ({ name, axis, side, fraction }) => {
    const c = state.cut;
    if (name === 'clip') {
      c.position = fraction;
    } else {
      // The face dragged stops short of the opposite one, as its slider does.
      const r = orderCropRange(side === 'low' ? fraction : c.low[axis], side === 'high' ? fraction : c.high[axis], side);
      c.low[axis] = r.low;
      c.high[axis] = r.high;
    }
    cutChanged();
  },
});

/** The cuts over the view, projected with the camera and size of the frame shown; hidden where the server draws none. */
function drawCutOverlay() {
  cutOverlay.update(state.modesSupported ? state.shownView : null, state.volume, state.cut);
}

showCut();

// ---- frames ------------------------------------------------------------------------------

function onFrame(f) {
  // Stale frames: older than what is on screen, or of the volume before this one.
  if (f.cameraId < state.minCameraId || f.cameraId < state.lastDrawnCameraId) return;
  if (state.decoding) {
    // One decode at a time; a frame waiting behind it is replaced by a newer one.
    state.pendingFrame = f;
    return;
  }
  decodeAndDraw(f);
}

async function decodeAndDraw(f) {
  state.decoding = true;
  try {
    const bitmap = await toBitmap(f);
    if (bitmap && state.volume && f.cameraId >= state.lastDrawnCameraId && f.cameraId >= state.minCameraId) {
      draw(f, bitmap);
      // Kept (until the next frame replaces it) for lastFrameImage().
      state.lastBitmap?.close();
      state.lastBitmap = bitmap;
    } else {
      bitmap?.close();
    }
  } catch (e) {
    report(new Error(`frame ${f.frameId}: ${e.message}`));
  } finally {
    state.decoding = false;
    const next = state.pendingFrame;
    state.pendingFrame = null;
    if (next) onFrame(next);
  }
}

/** An ImageBitmap of a frame's image, decoded off the main thread; raw frames drawn over black. */
async function toBitmap(f) {
  const type = IMAGE_TYPES[f.codec];
  if (type) {
    return createImageBitmap(new Blob([f.image], { type }), { premultiplyAlpha: 'none', colorSpaceConversion: 'none' });
  }
  if (f.codec === Codec.Raw) {
    const n = f.width * f.height * 4;
    if (f.image.length !== n) throw new Error(`raw image of ${f.image.length} bytes, ${f.width}×${f.height} needs ${n}`);
    // Premultiplied colour is the image composited over black; drop alpha by making it opaque.
    const pixels = new Uint8ClampedArray(n);
    pixels.set(f.image);
    const words = new Uint32Array(pixels.buffer);
    for (let i = 0; i < words.length; ++i) words[i] |= 0xff000000; // little-endian: alpha is the high byte
    return createImageBitmap(new ImageData(pixels, f.width, f.height));
  }
  throw new Error(`codec ${CODEC_NAMES[f.codec] ?? f.codec} is not one this page asked for`);
}

/**
 * The canvas backing size a frame is shown at: a refined frame's own size (drawn 1:1); for an
 * interactive frame the size of the RenderOptions it answers (under flags bit 0 it may be drawn
 * smaller: half of each edge rounded up, or over another divisor under the server's frame-time
 * budget), or the canvas's size when it answers options sent before a resize.
 */
function canvasSizeFor(f) {
  const own = { width: f.width, height: f.height };
  if (f.refined) return own;
  const o = state.lastOptions;
  if (o) {
    if (isInteractiveSizeOf(f.width, f.height, o.width, o.height)) {
      return { width: o.width, height: o.height };
    }
  }
  const c = els.view;
  if (state.lastFrame) return { width: c.width, height: c.height };
  return state.options.flags & RenderFlags.UnscaledInteractive ? { width: 2 * f.width, height: 2 * f.height } : own;
}

function draw(f, bitmap) {
  const c = els.view;
  const size = canvasSizeFor(f);
  if (c.width !== size.width || c.height !== size.height) {
    c.width = size.width; // resets the context's state: smoothing is set below, every frame
    c.height = size.height;
  }
  if (size.width === f.width && size.height === f.height) {
    // 1:1 (refined frames, and interactive ones at full size): every pixel as the server made it.
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(bitmap, 0, 0);
  } else {
    // An interactive frame drawn smaller: scaled up smoothly, not pixel-replicated.
    ctx.imageSmoothingEnabled = true;
    ctx.imageSmoothingQuality = 'high';
    ctx.drawImage(bitmap, 0, 0, c.width, c.height);
  }
  const drawnAt = performance.now();
  const firstOfCamera = f.cameraId !== state.lastDrawnCameraId;
  state.lastDrawnCameraId = f.cameraId;
  state.frameCount += 1;
  const inputTime = state.inputTimes.get(f.cameraId);
  state.stats.frameDrawn(drawnAt, firstOfCamera && inputTime !== undefined ? drawnAt - inputTime : null);
  state.lastFrame = {
    cameraId: f.cameraId, frameId: f.frameId, codec: f.codec, refined: f.refined,
    width: f.width, height: f.height, bytes: f.image.length, drawnAt,
    level: f.level, scale: f.scale, estimatedPsnrDb: f.estimatedPsnrDb,
    canvasWidth: c.width, canvasHeight: c.height,
  };
  state.lastFrameHeader = f;
  const camera = state.sentCameras.get(f.cameraId);
  // The frame's own size: its aspect is the one its rays were cast for.
  if (camera) state.shownView = { camera, width: f.width, height: f.height };
  drawOverlay();
  drawCutOverlay();
}

// fps falls to 0 when frames stop: refresh the overlay even when nothing is drawn.
setInterval(() => drawOverlay(), 1000);

function drawOverlay() {
  const f = state.lastFrameHeader;
  if (!f || !state.volume) return;
  const s = state.stats;
  const shown = state.lastFrame;
  const scaled = shown && (shown.canvasWidth !== f.width || shown.canvasHeight !== f.height)
    ? ` → ${shown.canvasWidth}×${shown.canvasHeight}` : '';
  const lines = [
    `${s.fps(performance.now()).toFixed(1)} fps   latency ${s.latencyMs === null ? '—' : `${Math.round(s.latencyMs)} ms`}`,
    `${f.refined ? 'refined' : 'interactive'} ${f.width}×${f.height}${scaled}  ${frameDetailLabel(f)}  ${CODEC_NAMES[f.codec] ?? f.codec} ${formatBytes(f.image.length)}`,
    `render ${f.renderMs.toFixed(1)} ms  encode ${f.encodeMs.toFixed(1)} ms  queue ${f.queueMs.toFixed(1)} ms`,
    // (no "cache" in it: the residency line is the overlay's one line that says cache)
    f.cached ? 'reused: the server drew this view before, nothing drawn now'
      : `bricks ${f.bricksDrawn} drawn, ${f.bricksSkipped} skipped  uploaded ${formatBytes(f.bytesUploaded)}`,
  ];
  if (state.residency) lines.push(state.residency);
  if (state.options.renderer === Renderer.Auto && state.autoRenderer) lines.push(state.autoRenderer.reason);
  els.overlay.textContent = lines.join('\n');
}

// ---- test API ----------------------------------------------------------------------------

const clone = (v) => (v == null ? null : structuredClone(v));

window.brickcast = {
  /** 'connecting' | 'auth' | 'ready' | 'disconnected'. */
  get state() { return conn.state; },
  /** The last VolumeList's volumes. */
  get volumes() { return clone(state.volumes); },
  /** The last SetCamera sent, or null. */
  camera: () => clone(state.lastCamera),
  /** The last SetTransferFunction sent, or null. */
  transferFunction: () => clone(state.lastTf),
  /** The last RenderOptions sent, or null. */
  renderOptions: () => clone(state.lastOptions),
  /**
   * The last frame drawn: {cameraId, frameId, codec, refined, width, height (the frame's own), bytes, drawnAt,
   * level, scale, estimatedPsnrDb (FrameHeader; scale 0 from older servers), canvasWidth, canvasHeight (the size shown at)}, or null.
   */
  get lastFrame() { return clone(state.lastFrame); },
  /**
   * The last frame drawn as decoded, before any scaling (an interactive frame at the size the
   * server drew it): {width, height, data: Uint8ClampedArray RGBA}, or null.
   */
  lastFrameImage() {
    const b = state.lastBitmap;
    if (!b) return null;
    const off = new OffscreenCanvas(b.width, b.height);
    const c = off.getContext('2d', { willReadFrequently: true });
    c.imageSmoothingEnabled = false;
    c.drawImage(b, 0, 0);
    const img = c.getImageData(0, 0, b.width, b.height);
    return { width: img.width, height: img.height, data: img.data };
  },
  /** Frames drawn since the page loaded. */
  get frameCount() { return state.frameCount; },
  /** Opens a volume by name; resolves with its VolumeInfo, rejects with the server's Error. */
  openVolume: (name) => openVolume(name),
  /** Sends a camera now (fields missing from `cam` keep their current values); returns its cameraId (0 when nothing was sent). */
  setCamera(cam) {
    if (!state.trackball) throw new Error('no volume is open');
    scheduleCamera.cancel();
    return sendCamera(state.trackball.set(cam));
  },
  /** Chooses a preset from /presets.json and sends it now. */
  setPreset(name) {
    tfEditor.choosePreset(name);
    scheduleTransferFunction.cancel();
    sendTransferFunction(tfEditor.current());
  },
  /** Sends points ({placement, position, rgba} or {value|fraction|percentile, rgba}) and shading now. */
  setTransferFunction(points, shading) {
    tfEditor.setPoints(points, shading);
    scheduleTransferFunction.cancel();
    sendTransferFunction(tfEditor.current());
  },
  /** Merges and sends render options now; returns what was sent. */
  setRenderOptions: (partial) => setRenderOptions(partial),
  /** The last SetFrameBudget sent on this session ({interactiveMs, restPsnrDb}; both 0 before any), or null when unknown. */
  frameBudget: () => clone(state.lastFrameBudget),
  /**
   * Merges {interactiveMs, restPsnrDb} into the frame budget, shows it in the controls and sends it
   * now; returns what was sent, or null when the server does not take SetFrameBudget (or is not
   * connected). Throws ProtocolError on a value out of range.
   */
  setFrameBudget: (partial) => setFrameBudget(partial),
  /** The last SetModeAndClip sent on this session ({mode, isoValue, crop, planes, cap}), or null (none yet, or unknown after an Error). */
  modeAndClip: () => clone(state.lastModeAndClip),
  /**
   * Merges a partial {mode, isoValue, cropped, low: [3], high: [3], clip, axis ('+x' .. '-z'),
   * position, cap} (low, high and position fractions of the volume's extent) into the mode and
   * cut controls, shows it and sends it now (cap only with a cut, in composite or isosurface
   * mode, to a server that caps); returns what was sent, or null when the server does not take
   * SetModeAndClip (or is not connected). Throws on a value out of range.
   */
  setModeAndClip: (partial) => setModeAndClip(partial),
  /**
   * The cut overlay as drawn: {handles: [{name ('x-low' .. 'z-high', 'clip'), x, y (CSS px from
   * the view's top left), mm (the handle's position on its axis)}], edges (the crop box's
   * segments drawn)}, or null while it is hidden.
   */
  cutOverlay: () => cutOverlay.drawn(),
  /** The iso value's line on the histogram: {value, x (CSS px from the #tf canvas's left)}, or null while it is hidden. */
  isoMarker: () => tfEditor.isoMarker(),
};

conn.connect();
