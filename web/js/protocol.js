// The brickcast wire protocol, version 1 (protocol/PROTOCOL.md): pure encoders and decoders
// on ArrayBuffer/DataView, no I/O. Every message is a 16-byte little-endian header and a
// payload; a decoder checks the header before it looks at the payload and requires the
// payload to be consumed exactly, as the server's decoder does.

export const MAGIC = 0x54534342; // the bytes 'B' 'C' 'S' 'T' read as a little-endian u32
export const VERSION = 1;
export const HEADER_BYTES = 16;
export const MAX_CLIENT_PAYLOAD = 64 * 1024;
export const MAX_SERVER_PAYLOAD = 80 * 1024 * 1024;
export const MAX_IMAGE_EDGE = 4096;
export const MAX_TF_POINTS = 256;
export const MAX_HISTOGRAM_BINS = 4096;

export const Type = Object.freeze({
  Hello: 0x01, Auth: 0x02, AuthOk: 0x03, ListVolumes: 0x04, VolumeList: 0x05,
  OpenVolume: 0x06, VolumeOpened: 0x07, SetCamera: 0x08, SetTransferFunction: 0x09,
  SetRenderOptions: 0x0a, RequestFrame: 0x0b, Frame: 0x0c, RequestStats: 0x0d, Stats: 0x0e,
  Error: 0x0f, Bye: 0x10, RequestHistogram: 0x11, Histogram: 0x12, SetFrameBudget: 0x13,
  SetModeAndClip: 0x14,
});

const typeNames = new Map(Object.entries(Type).map(([name, t]) => [t, name]));

/** Name of a message type, or "unknown" (for messages shown to people). */
export function typeName(type) {
  return typeNames.get(type) ?? 'unknown';
}

export const ErrorCode = Object.freeze({
  BadMagic: 1, UnsupportedVersion: 2, TooLarge: 3, UnknownType: 4, BadPayload: 5,
  OutOfRange: 6, NotAuthenticated: 7, AuthFailed: 8, UnknownVolume: 9, NoVolume: 10, Busy: 11,
  Timeout: 12, RenderFailed: 13, ShuttingDown: 14, BadState: 15, Internal: 16, NotFound: 17,
});

const errorNames = new Map(Object.entries(ErrorCode).map(([name, c]) => [c, name]));

/** Name of an Error code, or "error N" for a code this client does not know. */
export function errorName(code) {
  return errorNames.get(code) ?? `error ${code}`;
}

// FrameBudget (bit 4, since 2026-12-06): the server takes SetFrameBudget; older servers answer it UnknownType.
// ModesAndClips (bit 5, since 2026-12-07): the server takes SetModeAndClip; older servers answer it UnknownType.
// Capping (bit 6, since 2026-12-08): the server takes SetModeAndClip's cutFlags; older servers answer the byte BadPayload.
export const Capability = Object.freeze({
  AuthRequired: 1, CpuRenderer: 2, GpuRenderer: 4, Continuous: 8, FrameBudget: 16, ModesAndClips: 32, Capping: 64,
});
export const Codec = Object.freeze({ Raw: 0, Zstd: 1, ZstdDelta: 2, Jpeg: 3, Png: 4 });
// Auto (5, since 2026-12-03): the server picks the GPU raycaster on a hardware GPU, else the CPU raycaster.
export const Renderer = Object.freeze({ GpuRaycaster: 0, CpuRaycaster: 1, Reference: 2, Splatter: 3, GpuSplatter: 4, Auto: 5 });
export const Quality = Object.freeze({ Adaptive: 0, Refined: 1, Interactive: 2 });
export const FrameMode = Object.freeze({ Once: 0, ContinuousOn: 1, ContinuousOff: 2 });
export const Placement = Object.freeze({ Value: 0, Fraction: 1, Percentile: 2 });
export const VOXEL_TYPE_NAMES = Object.freeze(['u8', 'u16', 'i16', 'f32']);
export const TECHNIQUES_ALL = 0x7f;
export const LEVEL_AUTOMATIC = 255;
/** RenderOptions flags (u16 at offset 22): bit 0 unscaled interactive frames (half size, rounded up). */
export const RenderFlags = Object.freeze({ UnscaledInteractive: 1 });
export const RENDER_FLAGS_ALL = 0x1;
/** SetFrameBudget.interactiveMs: 0 (the server's default) or 1..MAX_INTERACTIVE_MS. */
export const MAX_INTERACTIVE_MS = 10000;
/** SetFrameBudget.restPsnrDb: 0 (no error bound) or REST_PSNR_MIN_DB..REST_PSNR_MAX_DB. */
export const REST_PSNR_MIN_DB = 20;
export const REST_PSNR_MAX_DB = 50;
/**
 * FrameHeader.scale: at most this. 0 from servers before 2026-12-06, 1 refined, 1, 2, 3, 4, 6 or
 * 8 interactive; checked as 0..8, as the server's own decoder does (protocol/MessageRules.cpp).
 */
export const MAX_FRAME_SCALE = 8;
/** FrameHeader.estimatedPsnrDb: 0 (no estimate) up to this, whole dB. */
export const MAX_ESTIMATED_PSNR_DB = 50;
/** SetModeAndClip.mode: what a ray makes of its samples (render/MODES.md). */
export const Mode = Object.freeze({ Composite: 0, Maximum: 1, Minimum: 2, Average: 3, Isosurface: 4 });
/** SetModeAndClip: at most this many clip planes. */
export const MAX_CLIP_PLANES = 6;
/** SetModeAndClip.cutFlags (the optional u8 after the planes): bit 0 cap, draw the faces the cuts make. */
export const CutFlags = Object.freeze({ Cap: 1 });
export const CUT_FLAGS_ALL = 0x1;
const MODE_NAMES = Object.freeze(['composite', 'maximum', 'minimum', 'average', 'isosurface']);
/** SetModeAndClip: a plane's normal whose largest |component| is not above this is zero (it has no direction). */
const MIN_NORMAL_COMPONENT = 1e-30;

/** Thrown for malformed input; `code` is the ErrorCode name the server would answer with. */
export class ProtocolError extends Error {
  constructor(code, message) {
    super(message);
    this.name = 'ProtocolError';
    this.code = code;
  }
}

const utf8Encoder = new TextEncoder();
const utf8Decoder = new TextDecoder('utf-8', { fatal: true });
const VOLUME_NAME = /^[A-Za-z0-9_-][A-Za-z0-9._-]{0,63}$/;

// ---- writing ---------------------------------------------------------------------------

class Writer {
  constructor() {
    this.bytes = new Uint8Array(64);
    this.view = new DataView(this.bytes.buffer);
    this.length = 0;
  }

  reserve(n) {
    if (this.length + n <= this.bytes.length) return;
    const grown = new Uint8Array(Math.max(this.bytes.length * 2, this.length + n));
    grown.set(this.bytes);
    this.bytes = grown;
    this.view = new DataView(grown.buffer);
  }

  u8(v, field) { checkInt(v, 0, 0xff, field); this.reserve(1); this.view.setUint8(this.length, v); this.length += 1; }
  u16(v, field) { checkInt(v, 0, 0xffff, field); this.reserve(2); this.view.setUint16(this.length, v, true); this.length += 2; }
  u32(v, field) { checkInt(v, 0, 0xffffffff, field); this.reserve(4); this.view.setUint32(this.length, v, true); this.length += 4; }
  u64(v, field) {
    checkInt(v, 0, Number.MAX_SAFE_INTEGER, field);
    this.reserve(8); this.view.setBigUint64(this.length, BigInt(v), true); this.length += 8;
  }
  f32(v, field) { checkNumber(v, field); this.reserve(4); this.view.setFloat32(this.length, v, true); this.length += 4; }
  f64(v, field) { checkNumber(v, field); this.reserve(8); this.view.setFloat64(this.length, v, true); this.length += 8; }
  bool(v, field) {
    if (typeof v !== 'boolean') throw new ProtocolError('BadPayload', `${field}: expected a boolean, got ${v}`);
    this.u8(v ? 1 : 0, field);
  }
  str(s, minBytes, maxBytes, field) {
    if (typeof s !== 'string') throw new ProtocolError('BadPayload', `${field}: expected a string`);
    const b = utf8Encoder.encode(s);
    if (b.length < minBytes || b.length > maxBytes)
      throw new ProtocolError('OutOfRange', `${field}: ${b.length} bytes, expected ${minBytes}..${maxBytes}`);
    this.u16(b.length, field);
    this.raw(b);
  }
  raw(b) { this.reserve(b.length); this.bytes.set(b, this.length); this.length += b.length; }
  finish() { return this.bytes.slice(0, this.length); }
}

function checkNumber(v, field) {
  if (typeof v !== 'number' || Number.isNaN(v))
    throw new ProtocolError('BadPayload', `${field}: expected a number, got ${v}`);
}

function checkInt(v, min, max, field) {
  if (!Number.isInteger(v) || v < min || v > max)
    throw new ProtocolError('OutOfRange', `${field}: ${v} is not an integer in ${min}..${max}`);
}

function checkFinite(v, field) {
  if (typeof v !== 'number' || !Number.isFinite(v))
    throw new ProtocolError('OutOfRange', `${field}: ${v} is not a finite number`);
}

function checkRange(v, lo, hi, field) {
  checkFinite(v, field);
  if (v < lo || v > hi) throw new ProtocolError('OutOfRange', `${field}: ${v} outside [${lo}, ${hi}]`);
}

function checkVec3(v, field) {
  if (!Array.isArray(v) && !ArrayBuffer.isView(v)) throw new ProtocolError('BadPayload', `${field}: expected 3 numbers`);
  if (v.length !== 3) throw new ProtocolError('BadPayload', `${field}: expected 3 numbers, got ${v.length}`);
  for (let i = 0; i < 3; ++i) checkFinite(v[i], `${field}[${i}]`);
}

// ---- reading ---------------------------------------------------------------------------

class Reader {
  constructor(view, offset, length, what) {
    this.view = view;
    this.pos = offset;
    this.end = offset + length;
    this.what = what;
  }

  need(n, field) {
    if (this.pos + n > this.end)
      throw new ProtocolError('BadPayload', `${this.what}: payload too short at ${field}`);
  }
  u8(field) { this.need(1, field); const v = this.view.getUint8(this.pos); this.pos += 1; return v; }
  u16(field) { this.need(2, field); const v = this.view.getUint16(this.pos, true); this.pos += 2; return v; }
  u32(field) { this.need(4, field); const v = this.view.getUint32(this.pos, true); this.pos += 4; return v; }
  u64(field) {
    this.need(8, field);
    const v = this.view.getBigUint64(this.pos, true);
    this.pos += 8;
    // Counts and byte sizes; beyond 2^53 a double is the honest approximation.
    return Number(v);
  }
  f32(field) { this.need(4, field); const v = this.view.getFloat32(this.pos, true); this.pos += 4; return v; }
  f64(field) { this.need(8, field); const v = this.view.getFloat64(this.pos, true); this.pos += 8; return v; }
  bool(field) {
    const v = this.u8(field);
    if (v > 1) throw new ProtocolError('BadPayload', `${this.what}: ${field} is ${v}, not a bool`);
    return v === 1;
  }
  str(maxBytes, field) {
    const n = this.u16(field);
    if (n > maxBytes) throw new ProtocolError('BadPayload', `${this.what}: ${field} is ${n} bytes, over ${maxBytes}`);
    this.need(n, field);
    const bytes = new Uint8Array(this.view.buffer, this.view.byteOffset + this.pos, n);
    this.pos += n;
    try {
      return utf8Decoder.decode(bytes);
    } catch {
      throw new ProtocolError('BadPayload', `${this.what}: ${field} is not UTF-8`);
    }
  }
  bytes(n, field) {
    this.need(n, field);
    const b = new Uint8Array(this.view.buffer, this.view.byteOffset + this.pos, n);
    this.pos += n;
    return b;
  }
  left() { return this.end - this.pos; }
  done() {
    if (this.pos !== this.end)
      throw new ProtocolError('BadPayload', `${this.what}: ${this.end - this.pos} bytes left over`);
  }
}

// ---- payloads --------------------------------------------------------------------------

function writeVolumeInfo(w, v) {
  w.str(v.name, 1, 64, 'name');
  for (let i = 0; i < 3; ++i) w.u32(v.dims[i], `dims[${i}]`);
  for (let i = 0; i < 3; ++i) w.f64(v.spacingMm[i], `spacingMm[${i}]`);
  w.u8(v.voxelType, 'voxelType');
  w.u8(v.levels, 'levels');
  w.f64(v.valueMin, 'valueMin');
  w.f64(v.valueMax, 'valueMax');
  w.u64(v.storedBytes, 'storedBytes');
}

function readVolumeInfo(r) {
  const name = r.str(64, 'name');
  const dims = [r.u32('dims[0]'), r.u32('dims[1]'), r.u32('dims[2]')];
  const spacingMm = [r.f64('spacingMm[0]'), r.f64('spacingMm[1]'), r.f64('spacingMm[2]')];
  const voxelType = r.u8('voxelType');
  if (voxelType > 3) throw new ProtocolError('BadPayload', `${r.what}: voxelType ${voxelType} unknown`);
  const levels = r.u8('levels');
  const valueMin = r.f64('valueMin');
  const valueMax = r.f64('valueMax');
  const storedBytes = r.u64('storedBytes');
  return { name, dims, spacingMm, voxelType, levels, valueMin, valueMax, storedBytes };
}

function writePoint(w, p, i) {
  const f = `points[${i}]`;
  checkInt(p.placement, 0, 2, `${f}.placement`);
  checkFinite(p.position, `${f}.position`);
  w.u8(p.placement, `${f}.placement`);
  w.f64(p.position, `${f}.position`);
  if (!p.rgba || p.rgba.length !== 4) throw new ProtocolError('BadPayload', `${f}.rgba: expected 4 numbers`);
  for (let c = 0; c < 4; ++c) {
    checkRange(p.rgba[c], 0, 1, `${f}.rgba[${c}]`);
    w.f32(p.rgba[c], `${f}.rgba[${c}]`);
  }
}

function readPoint(r, i) {
  const f = `points[${i}]`;
  const placement = r.u8(`${f}.placement`);
  if (placement > 2) throw new ProtocolError('BadPayload', `${r.what}: ${f}.placement ${placement} unknown`);
  const position = r.f64(`${f}.position`);
  const rgba = [r.f32(`${f}.rgba[0]`), r.f32(`${f}.rgba[1]`), r.f32(`${f}.rgba[2]`), r.f32(`${f}.rgba[3]`)];
  return { placement, position, rgba };
}

function validateRenderOptions(o) {
  checkInt(o.width, 1, MAX_IMAGE_EDGE, 'width');
  checkInt(o.height, 1, MAX_IMAGE_EDGE, 'height');
  checkFinite(o.stepVoxels, 'stepVoxels');
  if (!(o.stepVoxels > 0 && o.stepVoxels <= 64)) throw new ProtocolError('OutOfRange', `stepVoxels: ${o.stepVoxels} outside (0, 64]`);
  checkInt(o.techniques, 0, TECHNIQUES_ALL, 'techniques');
  checkFinite(o.ertThreshold, 'ertThreshold');
  if (!(o.ertThreshold > 0 && o.ertThreshold <= 1)) throw new ProtocolError('OutOfRange', `ertThreshold: ${o.ertThreshold} outside (0, 1]`);
  checkInt(o.renderer, 0, Renderer.Auto, 'renderer');
  checkInt(o.quality, 0, 2, 'quality');
  checkInt(o.codec, 0, 255, 'codec');
  checkInt(o.codecQuality, 0, 100, 'codecQuality');
  if (!(Number.isInteger(o.level) && (o.level <= 15 && o.level >= 0 || o.level === LEVEL_AUTOMATIC)))
    throw new ProtocolError('OutOfRange', `level: ${o.level} is neither 0..15 nor 255`);
  checkInt(o.refinedCodec ?? 0, 0, 255, 'refinedCodec');
  checkInt(o.flags ?? 0, 0, 0xffff, 'flags');
  if ((o.flags ?? 0) & ~RENDER_FLAGS_ALL)
    throw new ProtocolError('OutOfRange', `flags: 0x${(o.flags).toString(16)} has bits other than 0x${RENDER_FLAGS_ALL.toString(16)}`);
}

function validateFrameBudget(b, code) {
  if (!Number.isInteger(b.interactiveMs) || b.interactiveMs < 0 || b.interactiveMs > MAX_INTERACTIVE_MS)
    throw new ProtocolError(code, `interactiveMs: ${b.interactiveMs} is not an integer in 0..${MAX_INTERACTIVE_MS}`);
  const db = b.restPsnrDb;
  if (!Number.isInteger(db) || !(db === 0 || (db >= REST_PSNR_MIN_DB && db <= REST_PSNR_MAX_DB)))
    throw new ProtocolError(code, `restPsnrDb: ${db} is neither 0 nor an integer in ${REST_PSNR_MIN_DB}..${REST_PSNR_MAX_DB}`);
}

/**
 * SetModeAndClip as the server checks it (all OutOfRange, naming the field): a mode of 0..4, a
 * finite isoValue (the server also wants it within the volume's [valueMin, valueMax] in mode 4,
 * which only it knows), a crop box (null: none) of finite bounds with min < max on every axis,
 * at most MAX_CLIP_PLANES planes with finite normals and offsets, no normal zero; cap a boolean,
 * true only in the composite and isosurface modes (the others draw no surface), named cutFlags.
 */
function validateModeAndClip(m) {
  checkInt(m.mode, 0, Mode.Isosurface, 'mode');
  checkFinite(m.isoValue, 'isoValue');
  if (m.crop != null) {
    checkFinite3(m.crop.min, 'crop.min');
    checkFinite3(m.crop.max, 'crop.max');
    for (let a = 0; a < 3; ++a) {
      if (!(m.crop.min[a] < m.crop.max[a]))
        throw new ProtocolError('OutOfRange', `crop: axis ${'xyz'[a]} is ${m.crop.min[a]}..${m.crop.max[a]}, the box needs min < max on every axis`);
    }
  }
  if (!Array.isArray(m.planes)) throw new ProtocolError('OutOfRange', `planes: expected an array of 0..${MAX_CLIP_PLANES}`);
  if (m.planes.length > MAX_CLIP_PLANES)
    throw new ProtocolError('OutOfRange', `planes: ${m.planes.length}, more than ${MAX_CLIP_PLANES}`);
  m.planes.forEach((p, i) => {
    const n = p?.normal;
    checkFinite3(n, `planes[${i}].normal`);
    // A normal whose length is zero or below what float resolves has no direction.
    if (!(Math.max(Math.abs(n[0]), Math.abs(n[1]), Math.abs(n[2])) > MIN_NORMAL_COMPONENT))
      throw new ProtocolError('OutOfRange', `planes[${i}].normal: (${n.join(', ')}) is zero (a plane needs a direction)`);
    checkFinite(p.offset, `planes[${i}].offset`);
  });
  if (typeof m.cap !== 'boolean') throw new ProtocolError('OutOfRange', `cutFlags: cap is ${m.cap}, not a boolean`);
  if (m.cap && m.mode !== Mode.Composite && m.mode !== Mode.Isosurface)
    throw new ProtocolError('OutOfRange', `cutFlags: mode ${m.mode} (${MODE_NAMES[m.mode]}) draws no surface to cap (composite and isosurface only)`);
}

/** Three finite numbers; anything else is out of range, naming the field. */
function checkFinite3(v, field) {
  if (!(Array.isArray(v) || ArrayBuffer.isView(v)) || v.length !== 3)
    throw new ProtocolError('OutOfRange', `${field}: expected 3 numbers, got ${v}`);
  for (let i = 0; i < 3; ++i) checkFinite(v[i], `${field}[${i}]`);
}

function validateFrameScale(scale, estimatedPsnrDb, code, what) {
  if (!Number.isInteger(scale) || scale < 0 || scale > MAX_FRAME_SCALE)
    throw new ProtocolError(code, `${what}scale: ${scale} is not an integer in 0..${MAX_FRAME_SCALE}`);
  if (!Number.isInteger(estimatedPsnrDb) || estimatedPsnrDb < 0 || estimatedPsnrDb > MAX_ESTIMATED_PSNR_DB)
    throw new ProtocolError(code, `${what}estimatedPsnrDb: ${estimatedPsnrDb} is not an integer in 0..${MAX_ESTIMATED_PSNR_DB}`);
}

function validateCamera(c) {
  checkInt(c.cameraId, 0, 0xffffffff, 'cameraId');
  checkVec3(c.eye, 'eye');
  checkVec3(c.target, 'target');
  checkVec3(c.up, 'up');
  checkFinite(c.fovYDeg, 'fovYDeg');
  if (!(c.fovYDeg > 0 && c.fovYDeg < 180)) throw new ProtocolError('OutOfRange', `fovYDeg: ${c.fovYDeg} outside (0, 180)`);
  checkFinite(c.orthoHeight, 'orthoHeight');
  if (c.orthographic && !(c.orthoHeight > 0)) throw new ProtocolError('OutOfRange', 'orthoHeight must be > 0 when orthographic');
}

// Per type: write(body, w) and read(r) -> body. One table keeps both directions in step.
const codecs = {
  [Type.Hello]: {
    write(m, w) {
      w.u16(m.versionMin, 'versionMin');
      w.u16(m.versionMax, 'versionMax');
      w.u32(m.capabilities, 'capabilities');
      if (m.codecs.length > 16) throw new ProtocolError('OutOfRange', `codecs: ${m.codecs.length}, over 16`);
      w.u8(m.codecs.length, 'codecCount');
      m.codecs.forEach((c, i) => w.u8(c, `codecs[${i}]`));
      w.str(m.software, 0, 64, 'software');
    },
    read(r) {
      const versionMin = r.u16('versionMin');
      const versionMax = r.u16('versionMax');
      const capabilities = r.u32('capabilities');
      const count = r.u8('codecCount');
      if (count > 16) throw new ProtocolError('BadPayload', `Hello: ${count} codecs, over 16`);
      const codecList = Array.from(r.bytes(count, 'codecs'));
      const software = r.str(64, 'software');
      return { versionMin, versionMax, capabilities, codecs: codecList, software };
    },
  },
  [Type.Auth]: {
    write(m, w) { w.str(m.token, 1, 256, 'token'); },
    read(r) {
      const token = r.str(256, 'token');
      if (token.length === 0) throw new ProtocolError('BadPayload', 'Auth: empty token');
      return { token };
    },
  },
  [Type.AuthOk]: empty(),
  [Type.ListVolumes]: empty(),
  [Type.VolumeList]: {
    write(m, w) {
      if (m.volumes.length > 1024) throw new ProtocolError('OutOfRange', `volumes: ${m.volumes.length}, over 1024`);
      w.u16(m.volumes.length, 'count');
      m.volumes.forEach((v) => writeVolumeInfo(w, v));
    },
    read(r) {
      const count = r.u16('count');
      if (count > 1024) throw new ProtocolError('BadPayload', `VolumeList: ${count} volumes, over 1024`);
      const volumes = [];
      for (let i = 0; i < count; ++i) volumes.push(readVolumeInfo(r));
      return { volumes };
    },
  },
  [Type.OpenVolume]: {
    write(m, w) {
      if (!VOLUME_NAME.test(m.name))
        throw new ProtocolError('OutOfRange', `name: '${m.name}' is not 1..64 of A-Z a-z 0-9 . _ - (not starting with .)`);
      w.str(m.name, 1, 64, 'name');
    },
    read(r) { return { name: r.str(64, 'name') }; },
  },
  [Type.VolumeOpened]: {
    write(m, w) { writeVolumeInfo(w, m); },
    read(r) { return readVolumeInfo(r); },
  },
  [Type.SetCamera]: {
    write(m, w) {
      validateCamera(m);
      w.u32(m.cameraId, 'cameraId');
      for (const k of ['eye', 'target', 'up']) for (let i = 0; i < 3; ++i) w.f64(m[k][i], `${k}[${i}]`);
      w.f64(m.fovYDeg, 'fovYDeg');
      w.bool(!!m.orthographic, 'orthographic');
      w.f64(m.orthoHeight, 'orthoHeight');
    },
    read(r) {
      const cameraId = r.u32('cameraId');
      const vec = (k) => [r.f64(`${k}[0]`), r.f64(`${k}[1]`), r.f64(`${k}[2]`)];
      const eye = vec('eye'), target = vec('target'), up = vec('up');
      const fovYDeg = r.f64('fovYDeg');
      const orthographic = r.bool('orthographic');
      const orthoHeight = r.f64('orthoHeight');
      return { cameraId, eye, target, up, fovYDeg, orthographic, orthoHeight };
    },
  },
  [Type.SetTransferFunction]: {
    write(m, w) {
      checkInt(m.kind, 0, 1, 'kind');
      w.u8(m.kind, 'kind');
      w.bool(!!m.shading, 'shading');
      w.u8(m.shadingSource ?? 0, 'shadingSource');
      if (m.shadingSource === 1 && m.kind !== 0)
        throw new ProtocolError('OutOfRange', 'shadingSource 1 (the preset\'s default) needs kind 0');
      if (m.kind === 0) {
        w.str(m.preset, 1, 64, 'preset');
      } else {
        if (!Array.isArray(m.points) || m.points.length < 1 || m.points.length > MAX_TF_POINTS)
          throw new ProtocolError('OutOfRange', `points: expected 1..${MAX_TF_POINTS}`);
        w.u16(m.points.length, 'count');
        m.points.forEach((p, i) => writePoint(w, p, i));
      }
    },
    read(r) {
      const kind = r.u8('kind');
      if (kind > 1) throw new ProtocolError('BadPayload', `SetTransferFunction: kind ${kind} unknown`);
      const shading = r.bool('shading');
      const shadingSource = r.u8('shadingSource');
      if (shadingSource > 1) throw new ProtocolError('BadPayload', `SetTransferFunction: shadingSource ${shadingSource} unknown`);
      if (kind === 0) return { kind, shading, shadingSource, preset: r.str(64, 'preset') };
      const count = r.u16('count');
      if (count < 1 || count > MAX_TF_POINTS)
        throw new ProtocolError('BadPayload', `SetTransferFunction: ${count} points, expected 1..${MAX_TF_POINTS}`);
      const points = [];
      for (let i = 0; i < count; ++i) points.push(readPoint(r, i));
      return { kind, shading, shadingSource, points };
    },
  },
  [Type.SetRenderOptions]: {
    write(m, w) {
      validateRenderOptions(m);
      w.u16(m.width, 'width');
      w.u16(m.height, 'height');
      w.f32(m.stepVoxels, 'stepVoxels');
      w.u32(m.techniques, 'techniques');
      w.f32(m.ertThreshold, 'ertThreshold');
      w.u8(m.renderer, 'renderer');
      w.u8(m.quality, 'quality');
      w.u8(m.codec, 'codec');
      w.u8(m.codecQuality, 'codecQuality');
      w.u8(m.level, 'level');
      w.u8(m.refinedCodec ?? 0, 'refinedCodec');
      w.u16(m.flags ?? 0, 'flags');
    },
    read(r) {
      const m = {
        width: r.u16('width'), height: r.u16('height'), stepVoxels: r.f32('stepVoxels'),
        techniques: r.u32('techniques'), ertThreshold: r.f32('ertThreshold'),
        renderer: r.u8('renderer'), quality: r.u8('quality'), codec: r.u8('codec'),
        codecQuality: r.u8('codecQuality'), level: r.u8('level'), refinedCodec: r.u8('refinedCodec'),
        flags: r.u16('flags'),
      };
      // As the server: an undefined flag bit is out of range, not malformed.
      if (m.flags & ~RENDER_FLAGS_ALL)
        throw new ProtocolError('OutOfRange', `RenderOptions: flags 0x${m.flags.toString(16)} has bits other than 0x${RENDER_FLAGS_ALL.toString(16)}`);
      return m;
    },
  },
  [Type.RequestFrame]: {
    write(m, w) { checkInt(m.mode, 0, 2, 'mode'); w.u8(m.mode, 'mode'); },
    read(r) {
      const mode = r.u8('mode');
      if (mode > 2) throw new ProtocolError('BadPayload', `RequestFrame: mode ${mode} unknown`);
      return { mode };
    },
  },
  [Type.Frame]: {
    write(m, w) {
      w.u32(m.frameId, 'frameId');
      w.u32(m.cameraId, 'cameraId');
      w.u16(m.width, 'width');
      w.u16(m.height, 'height');
      w.u8(m.codec, 'codec');
      w.u8(m.level, 'level');
      w.bool(m.refined, 'refined');
      w.bool(m.keyframe, 'keyframe');
      w.f32(m.queueMs, 'queueMs');
      w.f32(m.renderMs, 'renderMs');
      w.f32(m.encodeMs, 'encodeMs');
      w.u64(m.samples, 'samples');
      w.u32(m.bricksDrawn, 'bricksDrawn');
      w.u32(m.bricksSkipped, 'bricksSkipped');
      w.u64(m.bytesUploaded, 'bytesUploaded');
      w.bool(m.occlusionUsed, 'occlusionUsed');
      w.bool(m.cached ?? false, 'cached');
      // The two bytes were reserved (0) before 2026-12-06: 0 is still a valid scale and estimate.
      validateFrameScale(m.scale ?? 0, m.estimatedPsnrDb ?? 0, 'OutOfRange', '');
      w.u8(m.scale ?? 0, 'scale');
      w.u8(m.estimatedPsnrDb ?? 0, 'estimatedPsnrDb');
      w.u32(m.image.length, 'imageBytes');
      w.raw(m.image);
    },
    read(r) {
      const m = {
        frameId: r.u32('frameId'), cameraId: r.u32('cameraId'), width: r.u16('width'),
        height: r.u16('height'), codec: r.u8('codec'), level: r.u8('level'),
        refined: r.bool('refined'), keyframe: r.bool('keyframe'), queueMs: r.f32('queueMs'),
        renderMs: r.f32('renderMs'), encodeMs: r.f32('encodeMs'), samples: r.u64('samples'),
        bricksDrawn: r.u32('bricksDrawn'), bricksSkipped: r.u32('bricksSkipped'),
        bytesUploaded: r.u64('bytesUploaded'), occlusionUsed: r.bool('occlusionUsed'),
        cached: r.bool('cached'), scale: r.u8('scale'), estimatedPsnrDb: r.u8('estimatedPsnrDb'),
      };
      validateFrameScale(m.scale, m.estimatedPsnrDb, 'BadPayload', 'Frame: ');
      const imageBytes = r.u32('imageBytes');
      if (imageBytes !== r.left())
        throw new ProtocolError('BadPayload', `Frame: imageBytes ${imageBytes} but ${r.left()} bytes follow`);
      if (m.width < 1 || m.width > MAX_IMAGE_EDGE || m.height < 1 || m.height > MAX_IMAGE_EDGE)
        throw new ProtocolError('BadPayload', `Frame: size ${m.width}x${m.height} outside 1..${MAX_IMAGE_EDGE}`);
      // A view into the message, not a copy: a 4096² raw frame is 64 MiB.
      m.image = r.bytes(imageBytes, 'image');
      return m;
    },
  },
  [Type.RequestStats]: empty(),
  [Type.Stats]: {
    write(m, w) {
      if (m.counters.length > 4096) throw new ProtocolError('OutOfRange', `counters: ${m.counters.length}, over 4096`);
      w.u16(m.counters.length, 'count');
      m.counters.forEach(({ name, value }, i) => { w.str(name, 0, 128, `[${i}].name`); w.f64(value, `[${i}].value`); });
    },
    read(r) {
      const count = r.u16('count');
      if (count > 4096) throw new ProtocolError('BadPayload', `Stats: ${count} counters, over 4096`);
      const counters = [];
      for (let i = 0; i < count; ++i) counters.push({ name: r.str(128, `[${i}].name`), value: r.f64(`[${i}].value`) });
      return { counters };
    },
  },
  [Type.Error]: {
    write(m, w) {
      w.u16(m.code, 'code');
      w.bool(!!m.fatal, 'fatal');
      w.u8(m.offendingType ?? 0, 'offendingType');
      w.str(m.message ?? '', 0, 1024, 'message');
    },
    read(r) {
      const code = r.u16('code');
      const fatal = r.bool('fatal');
      const offendingType = r.u8('offendingType');
      const message = r.str(1024, 'message');
      return { code, fatal, offendingType, message };
    },
  },
  [Type.Bye]: {
    write(m, w) { w.u16(m.reason ?? 0, 'reason'); },
    read(r) { return { reason: r.u16('reason') }; },
  },
  [Type.RequestHistogram]: empty(),
  [Type.SetFrameBudget]: {
    write(m, w) {
      validateFrameBudget(m, 'OutOfRange');
      w.u16(m.interactiveMs, 'interactiveMs');
      w.u8(m.restPsnrDb, 'restPsnrDb');
    },
    read(r) {
      const m = { interactiveMs: r.u16('interactiveMs'), restPsnrDb: r.u8('restPsnrDb') };
      // As the server: a value outside its range is out of range, not malformed.
      validateFrameBudget(m, 'OutOfRange');
      return m;
    },
  },
  [Type.SetModeAndClip]: {
    write(m, w) {
      // crop, planes and cap may be left out: no crop box, no planes, no cap.
      const b = { mode: m.mode, isoValue: m.isoValue, crop: m.crop ?? null, planes: m.planes ?? [], cap: m.cap ?? false };
      validateModeAndClip(b);
      w.u8(b.mode, 'mode');
      w.f64(b.isoValue, 'isoValue');
      w.bool(b.crop !== null, 'cropped');
      // Not cropped: all six are 0.
      const min = b.crop?.min ?? [0, 0, 0], max = b.crop?.max ?? [0, 0, 0];
      for (let a = 0; a < 3; ++a) w.f64(min[a], `cropMin[${a}]`);
      for (let a = 0; a < 3; ++a) w.f64(max[a], `cropMax[${a}]`);
      w.u8(b.planes.length, 'planeCount');
      b.planes.forEach((p, i) => {
        for (let a = 0; a < 3; ++a) w.f64(p.normal[a], `planes[${i}].normal[${a}]`);
        w.f64(p.offset, `planes[${i}].offset`);
      });
      // Only when not 0: an uncapped message keeps the layout servers before 2026-12-08 read.
      if (b.cap) w.u8(CutFlags.Cap, 'cutFlags');
    },
    read(r) {
      const mode = r.u8('mode');
      const isoValue = r.f64('isoValue');
      const cropped = r.bool('cropped');
      const vec = (k) => [r.f64(`${k}[0]`), r.f64(`${k}[1]`), r.f64(`${k}[2]`)];
      const min = vec('cropMin'), max = vec('cropMax');
      // As the server: a value outside its range is out of range, not malformed.
      if (!cropped && [...min, ...max].some((v) => v !== 0))
        throw new ProtocolError('OutOfRange', `crop: not cropped, but the box is (${min.join(', ')})..(${max.join(', ')}), not all 0`);
      const count = r.u8('planeCount');
      if (count > MAX_CLIP_PLANES) throw new ProtocolError('OutOfRange', `planes: ${count}, more than ${MAX_CLIP_PLANES}`);
      const planes = [];
      for (let i = 0; i < count; ++i) planes.push({ normal: vec(`planes[${i}].normal`), offset: r.f64(`planes[${i}].offset`) });
      // Optional: a payload that ends after the planes means 0; a present 0 is refused, so
      // that a message has one encoding.
      const hasFlags = r.left() === 1; // more is left over
      const cutFlags = hasFlags ? r.u8('cutFlags') : 0;
      if (cutFlags & ~CUT_FLAGS_ALL)
        throw new ProtocolError('OutOfRange', `cutFlags: 0x${cutFlags.toString(16)} has bits other than 0x${CUT_FLAGS_ALL.toString(16)}`);
      if (hasFlags && cutFlags === 0)
        throw new ProtocolError('OutOfRange', 'cutFlags: 0 is sent by leaving the byte out');
      const m = { mode, isoValue, crop: cropped ? { min, max } : null, planes, cap: (cutFlags & CutFlags.Cap) !== 0 };
      validateModeAndClip(m);
      return m;
    },
  },
  [Type.Histogram]: {
    write(m, w) {
      const n = m.counts.length;
      if (n < 1 || n > MAX_HISTOGRAM_BINS) throw new ProtocolError('OutOfRange', `binCount: ${n}, expected 1..${MAX_HISTOGRAM_BINS}`);
      w.f64(m.valueMin, 'valueMin');
      w.f64(m.valueMax, 'valueMax');
      w.u16(n, 'binCount');
      for (let i = 0; i < n; ++i) w.u64(m.counts[i], `counts[${i}]`);
    },
    read(r) {
      const valueMin = r.f64('valueMin');
      const valueMax = r.f64('valueMax');
      const n = r.u16('binCount');
      if (n < 1 || n > MAX_HISTOGRAM_BINS)
        throw new ProtocolError('BadPayload', `Histogram: binCount ${n}, expected 1..${MAX_HISTOGRAM_BINS}`);
      if (r.left() !== 8 * n)
        throw new ProtocolError('BadPayload', `Histogram: ${n} bins need ${8 * n} bytes, ${r.left()} follow`);
      const counts = new Float64Array(n);
      for (let i = 0; i < n; ++i) counts[i] = r.u64(`counts[${i}]`);
      return { valueMin, valueMax, counts };
    },
  },
};

function empty() {
  return { write() {}, read() { return {}; } };
}

// ---- messages --------------------------------------------------------------------------

/** Encodes one message: `body` holds the type's fields; returns an ArrayBuffer of header + payload. Throws ProtocolError on a field out of range. */
export function encode(type, body = {}, request = 0, flags = 0) {
  const c = codecs[type];
  if (!c) throw new ProtocolError('UnknownType', `cannot encode type 0x${hex(type)}`);
  const w = new Writer();
  w.raw(new Uint8Array(HEADER_BYTES));
  c.write(body, w);
  const length = w.length - HEADER_BYTES;
  writeHeader(w.view, { type, flags, length, request });
  return w.bytes.buffer.slice(0, w.length);
}

function writeHeader(view, { type, flags, length, request }) {
  checkInt(request, 0, 0xffffffff, 'request');
  checkInt(flags, 0, 0xffff, 'flags');
  view.setUint32(0, MAGIC, true);
  view.setUint8(4, VERSION);
  view.setUint8(5, type);
  view.setUint16(6, flags, true);
  view.setUint32(8, length, true);
  view.setUint32(12, request, true);
}

/** Reads and checks a header (magic, version, length within maxPayload); returns {type, flags, length, request}. */
export function decodeHeader(buffer, maxPayload = MAX_SERVER_PAYLOAD) {
  const bytes = asBytes(buffer);
  if (bytes.length < HEADER_BYTES)
    throw new ProtocolError('BadPayload', `message of ${bytes.length} bytes is shorter than the 16-byte header`);
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.length);
  const magic = view.getUint32(0, true);
  if (magic !== MAGIC) throw new ProtocolError('BadMagic', `bad magic 0x${magic.toString(16).padStart(8, '0')}`);
  const version = view.getUint8(4);
  if (version !== VERSION) throw new ProtocolError('UnsupportedVersion', `header version ${version}, expected ${VERSION}`);
  const length = view.getUint32(8, true);
  if (length > maxPayload) throw new ProtocolError('TooLarge', `payload of ${length} bytes is over the limit of ${maxPayload}`);
  return { type: view.getUint8(5), flags: view.getUint16(6, true), length, request: view.getUint32(12, true) };
}

/** Decodes one whole message (one WebSocket message): returns {type, name, flags, request, body}; throws ProtocolError when it is malformed. */
export function decode(buffer, maxPayload = MAX_SERVER_PAYLOAD) {
  const bytes = asBytes(buffer);
  const h = decodeHeader(bytes, maxPayload);
  if (bytes.length !== HEADER_BYTES + h.length)
    throw new ProtocolError('BadPayload', `header says ${h.length} payload bytes, message holds ${bytes.length - HEADER_BYTES}`);
  const c = codecs[h.type];
  if (!c) throw new ProtocolError('UnknownType', `unknown message type 0x${hex(h.type)}`);
  const name = typeName(h.type);
  if (h.flags !== 0) throw new ProtocolError('BadPayload', `${name}: flags 0x${h.flags.toString(16)} undefined for this type`);
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.length);
  const r = new Reader(view, HEADER_BYTES, h.length, name);
  const body = c.read(r);
  r.done();
  return { type: h.type, name, flags: h.flags, request: h.request, body };
}

function asBytes(buffer) {
  if (buffer instanceof Uint8Array) return buffer;
  if (buffer instanceof ArrayBuffer) return new Uint8Array(buffer);
  if (ArrayBuffer.isView(buffer)) return new Uint8Array(buffer.buffer, buffer.byteOffset, buffer.byteLength);
  throw new ProtocolError('BadPayload', 'expected an ArrayBuffer or a typed array');
}

function hex(n) {
  return Number(n).toString(16).padStart(2, '0');
}

// Named encoders for the messages this client sends; each returns an ArrayBuffer.

/** Hello: {versionMin, versionMax, capabilities, codecs, software}. */
export const encodeHello = (m, request) => encode(Type.Hello, m, request);
/** Auth with a token of 1..256 UTF-8 bytes. */
export const encodeAuth = (token, request) => encode(Type.Auth, { token }, request);
/** ListVolumes (empty). */
export const encodeListVolumes = (request) => encode(Type.ListVolumes, {}, request);
/** OpenVolume of a catalog name (1..64 of A-Z a-z 0-9 . _ -, not starting with '.'). */
export const encodeOpenVolume = (name, request) => encode(Type.OpenVolume, { name }, request);
/** SetCamera: {cameraId, eye, target, up, fovYDeg, orthographic, orthoHeight}, validated as the renderer validates. */
export const encodeSetCamera = (cam, request) => encode(Type.SetCamera, cam, request);
/** SetTransferFunction: {kind 0, shading, shadingSource, preset} or {kind 1, shading, shadingSource 0, points:[{placement, position, rgba}]}. */
export const encodeSetTransferFunction = (tf, request) => encode(Type.SetTransferFunction, tf, request);
/** SetRenderOptions: the 24-byte RenderOptions, refinedCodec in byte 21, flags (u16) in bytes 22..23. */
export const encodeSetRenderOptions = (o, request) => encode(Type.SetRenderOptions, o, request);
/** RequestFrame with mode 0 once, 1 continuous on, 2 continuous off. */
export const encodeRequestFrame = (mode, request) => encode(Type.RequestFrame, { mode }, request);
/** RequestStats (empty). */
export const encodeRequestStats = (request) => encode(Type.RequestStats, {}, request);
/** RequestHistogram (empty). */
export const encodeRequestHistogram = (request) => encode(Type.RequestHistogram, {}, request);
/**
 * SetFrameBudget: {interactiveMs (u16: 0 the server's default, 1..10000 ms), restPsnrDb (u8: 0 no
 * error bound, 20..50 dB)}. Only for a server whose Hello has Capability.FrameBudget.
 */
export const encodeSetFrameBudget = (m, request) => encode(Type.SetFrameBudget, m, request);
/**
 * SetModeAndClip: {mode (Mode, u8), isoValue (f64, finite; used in mode 4, within the volume's
 * [valueMin, valueMax]), crop (null, or {min: [3], max: [3]} in world mm with min < max), planes
 * (0..6 of {normal: [3], offset}: each keeps the points x (mm) with dot(normal, x) + offset >= 0),
 * cap (boolean, default false: draw the faces the cuts make; composite and isosurface only)};
 * 59 + 32 × planes bytes, one more with cap. Only for a server whose Hello has
 * Capability.ModesAndClips, and cap true only for one that also has Capability.Capping.
 */
export const encodeSetModeAndClip = (m, request) => encode(Type.SetModeAndClip, m, request);
/** Error the client sends before it closes: {code, fatal, offendingType, message}. */
export const encodeError = (m, request = 0) => encode(Type.Error, m, request);
/** Bye with reason 0 normal, 1 shutting down, 2 idle timeout. */
export const encodeBye = (reason = 0, request = 0) => encode(Type.Bye, { reason }, request);
