// protocol.js against the byte layouts of protocol/PROTOCOL.md; the golden bytes are those of
// tests/protocol/MessagesTest.cpp where that file has the message.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import {
  Type, ErrorCode, ProtocolError, encode, decode, decodeHeader, encodeHello, encodeSetCamera,
  encodeSetRenderOptions, encodeSetTransferFunction, encodeAuth, encodeOpenVolume,
  encodeRequestHistogram, encodeRequestFrame, encodeListVolumes, encodeRequestStats, encodeBye,
  encodeError, encodeSetFrameBudget, encodeSetModeAndClip, errorName, typeName, MAX_CLIENT_PAYLOAD, RenderFlags,
  Renderer, Capability, Mode, MAX_CLIP_PLANES, CutFlags,
} from '../js/protocol.js';

const header = (type, length, request) => [
  0x42, 0x43, 0x53, 0x54, 0x01, type, 0x00, 0x00,
  length & 0xff, (length >> 8) & 0xff, (length >> 16) & 0xff, length >>> 24,
  request & 0xff, (request >> 8) & 0xff, (request >> 16) & 0xff, request >>> 24,
];
const ascii = (s) => Array.from(s, (c) => c.charCodeAt(0));
const bytes = (buffer) => Array.from(new Uint8Array(buffer));
const f64 = (v) => { const b = new Uint8Array(8); new DataView(b.buffer).setFloat64(0, v, true); return Array.from(b); };
const u64 = (v) => { const b = new Uint8Array(8); new DataView(b.buffer).setBigUint64(0, BigInt(v), true); return Array.from(b); };
const u32 = (v) => { const b = new Uint8Array(4); new DataView(b.buffer).setUint32(0, v, true); return Array.from(b); };
const buf = (arr) => new Uint8Array(arr).buffer;
const throwsCode = (fn, code, re) => assert.throws(fn, (e) => {
  assert.ok(e instanceof ProtocolError, `expected a ProtocolError, got ${e}`);
  assert.equal(e.code, code);
  if (re) assert.match(e.message, re);
  return true;
});

test('Hello: golden bytes of MessagesTest.cpp', () => {
  const got = encode(Type.Hello, { versionMin: 1, versionMax: 1, capabilities: 0x0e, codecs: [0, 1, 2, 3], software: 'bc-0.1' }, 0);
  assert.deepEqual(bytes(got), [
    ...header(0x01, 21, 0), 0x01, 0x00, 0x01, 0x00, 0x0e, 0x00, 0x00, 0x00,
    0x04, 0x00, 0x01, 0x02, 0x03, 0x06, 0x00, ...ascii('bc-0.1'),
  ]);
});

test('Hello: the web client\'s own Hello', () => {
  const got = encodeHello({ versionMin: 1, versionMax: 1, capabilities: 0, codecs: [3, 4, 0], software: 'brickcast-web' }, 1);
  assert.deepEqual(bytes(got), [
    ...header(0x01, 27, 1), 0x01, 0x00, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x03, 0x03, 0x04, 0x00, 0x0d, 0x00, ...ascii('brickcast-web'),
  ]);
  assert.deepEqual(decode(got).body, { versionMin: 1, versionMax: 1, capabilities: 0, codecs: [3, 4, 0], software: 'brickcast-web' });
});

test('Auth, ListVolumes, OpenVolume, RequestFrame, RequestStats, Bye: golden bytes', () => {
  assert.deepEqual(bytes(encodeAuth('s3cret', 1)), [...header(0x02, 8, 1), 0x06, 0x00, ...ascii('s3cret')]);
  assert.deepEqual(bytes(encodeListVolumes(2)), header(0x04, 0, 2));
  assert.deepEqual(bytes(encodeOpenVolume('cthead', 3)), [...header(0x06, 8, 3), 0x06, 0x00, ...ascii('cthead')]);
  assert.deepEqual(bytes(encodeRequestFrame(1, 7)), [...header(0x0b, 1, 7), 0x01]);
  assert.deepEqual(bytes(encodeRequestStats(8)), header(0x0d, 0, 8));
  assert.deepEqual(bytes(encodeBye(2, 0)), [...header(0x10, 2, 0), 0x02, 0x00]);
  assert.deepEqual(bytes(encodeRequestHistogram(9)), header(0x11, 0, 9));
});

test('request id is little-endian at offset 12', () => {
  const got = bytes(encodeListVolumes(0x01020304));
  assert.deepEqual(got.slice(12), [0x04, 0x03, 0x02, 0x01]);
});

test('SetCamera: golden bytes of MessagesTest.cpp', () => {
  const cam = { cameraId: 7, eye: [0, -4, 0], target: [0, 0, 0], up: [0, 0, 1], fovYDeg: 30, orthographic: false, orthoHeight: 2 };
  const got = encodeSetCamera(cam, 4);
  assert.deepEqual(bytes(got), [
    ...header(0x08, 93, 4), 0x07, 0x00, 0x00, 0x00,
    ...f64(0), ...[0, 0, 0, 0, 0, 0, 0x10, 0xc0], ...f64(0),
    ...f64(0), ...f64(0), ...f64(0),
    ...f64(0), ...f64(0), ...[0, 0, 0, 0, 0, 0, 0xf0, 0x3f],
    ...[0, 0, 0, 0, 0, 0, 0x3e, 0x40], 0x00, ...[0, 0, 0, 0, 0, 0, 0, 0x40],
  ]);
  assert.deepEqual(decode(got), { type: Type.SetCamera, name: 'SetCamera', flags: 0, request: 4, body: cam });
});

test('SetCamera: invalid cameras are refused before sending', () => {
  const cam = { cameraId: 1, eye: [0, -4, 0], target: [0, 0, 0], up: [0, 0, 1], fovYDeg: 30, orthographic: false, orthoHeight: 2 };
  throwsCode(() => encodeSetCamera({ ...cam, fovYDeg: 180 }), 'OutOfRange', /fovYDeg/);
  throwsCode(() => encodeSetCamera({ ...cam, eye: [NaN, 0, 0] }), 'OutOfRange', /eye\[0\]/);
  throwsCode(() => encodeSetCamera({ ...cam, orthographic: true, orthoHeight: 0 }), 'OutOfRange', /orthoHeight/);
});

test('SetTransferFunction: golden bytes for a preset and for points', () => {
  const preset = { kind: 0, shading: true, shadingSource: 1, preset: 'ct-bone' };
  const a = encodeSetTransferFunction(preset, 5);
  assert.deepEqual(bytes(a), [...header(0x09, 12, 5), 0x00, 0x01, 0x01, 0x07, 0x00, ...ascii('ct-bone')]);
  assert.deepEqual(decode(a).body, preset);

  const points = {
    kind: 1, shading: false, shadingSource: 0, points: [
      { placement: 0, position: 100, rgba: [1, 0.5, 0.25, 0] },
      { placement: 1, position: 0.5, rgba: [1, 1, 1, 0.75] },
    ],
  };
  const b = encodeSetTransferFunction(points, 5);
  assert.deepEqual(bytes(b), [
    ...header(0x09, 55, 5), 0x01, 0x00, 0x00, 0x02, 0x00,
    0x00, ...[0, 0, 0, 0, 0, 0, 0x59, 0x40],
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x3f, 0x00, 0x00, 0x80, 0x3e, 0x00, 0x00, 0x00, 0x00,
    0x01, ...[0, 0, 0, 0, 0, 0, 0xe0, 0x3f],
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x40, 0x3f,
  ]);
  assert.deepEqual(decode(b).body, points);
});

test('SetTransferFunction: out-of-range points are refused', () => {
  const p = { placement: 0, position: 1, rgba: [0, 0, 0, 0] };
  throwsCode(() => encodeSetTransferFunction({ kind: 1, shading: false, points: [] }), 'OutOfRange', /points/);
  throwsCode(() => encodeSetTransferFunction({ kind: 1, shading: false, points: Array(257).fill(p) }), 'OutOfRange', /points/);
  throwsCode(() => encodeSetTransferFunction({ kind: 1, shading: false, points: [{ ...p, rgba: [0, 0, 1.5, 0] }] }), 'OutOfRange', /rgba\[2\]/);
  throwsCode(() => encodeSetTransferFunction({ kind: 1, shading: false, points: [{ ...p, position: Infinity }] }), 'OutOfRange', /position/);
  // 256 points is the largest legal request and still fits the client's payload limit.
  const big = encodeSetTransferFunction({ kind: 1, shading: true, points: Array(256).fill(p) });
  assert.ok(big.byteLength - 16 <= MAX_CLIENT_PAYLOAD);
});

test('SetRenderOptions: golden bytes of MessagesTest.cpp, refinedCodec at byte 21', () => {
  const o = {
    width: 640, height: 480, stepVoxels: 0.5, techniques: 0x7f, ertThreshold: 0.99, renderer: 1,
    quality: 1, codec: 3, codecQuality: 90, level: 255, refinedCodec: 0,
  };
  const got = encodeSetRenderOptions(o, 6);
  assert.deepEqual(bytes(got), [
    ...header(0x0a, 24, 6), 0x80, 0x02, 0xe0, 0x01, 0x00, 0x00, 0x00, 0x3f, 0x7f, 0x00, 0x00, 0x00,
    0xa4, 0x70, 0x7d, 0x3f, 0x01, 0x01, 0x03, 0x5a, 0xff, 0x00, 0x00, 0x00,
  ]);
  const withPng = bytes(encodeSetRenderOptions({ ...o, quality: 0, refinedCodec: 5 }, 6));
  assert.equal(withPng[16 + 21], 5);
  assert.equal(withPng[16 + 17], 0);
  const back = decode(got).body;
  assert.equal(back.width, 640);
  assert.equal(back.refinedCodec, 0);
  assert.ok(Math.abs(back.ertThreshold - 0.99) < 1e-6);
});

test('SetRenderOptions: renderer 5 is auto, golden bytes of MessagesTest.cpp (the default options)', () => {
  const o = {
    width: 256, height: 256, stepVoxels: 1, techniques: 0x7f, ertThreshold: 0.99, renderer: Renderer.Auto,
    quality: 0, codec: 1, codecQuality: 0, level: 255, refinedCodec: 0, flags: 0,
  };
  const got = encodeSetRenderOptions(o, 8);
  assert.deepEqual(bytes(got), [
    ...header(0x0a, 24, 8), 0x00, 0x01, 0x00, 0x01, 0x00, 0x00, 0x80, 0x3f, 0x7f, 0x00, 0x00, 0x00,
    0xa4, 0x70, 0x7d, 0x3f, 0x05, 0x00, 0x01, 0x00, 0xff, 0x00, 0x00, 0x00,
  ]);
  assert.equal(decode(got).body.renderer, Renderer.Auto);
  throwsCode(() => encodeSetRenderOptions({ ...o, renderer: 6 }), 'OutOfRange', /renderer/);
});

test('SetRenderOptions: flags (u16 at bytes 22..23), bit 0 unscaled interactive', () => {
  const o = {
    width: 640, height: 480, stepVoxels: 0.5, techniques: 0x7f, ertThreshold: 0.99, renderer: 1,
    quality: 0, codec: 3, codecQuality: 80, level: 255, refinedCodec: 5, flags: RenderFlags.UnscaledInteractive,
  };
  const got = bytes(encodeSetRenderOptions(o, 7));
  assert.equal(got.length, 16 + 24);
  assert.deepEqual(got.slice(16 + 20, 16 + 24), [0xff, 0x05, 0x01, 0x00], 'level, refinedCodec, flags 1 (little-endian)');
  assert.deepEqual(decode(buf(got)).body.flags, 1);
  // Left out: 0, as the two bytes were reserved.
  const { flags, ...old } = o;
  assert.deepEqual(bytes(encodeSetRenderOptions(old, 7)).slice(16 + 22), [0x00, 0x00]);
  assert.equal(decode(encodeSetRenderOptions(old, 7)).body.flags, 0);
  // Other bits: refused when encoding and when decoding (OutOfRange, as the server answers).
  throwsCode(() => encodeSetRenderOptions({ ...o, flags: 2 }), 'OutOfRange', /flags/);
  throwsCode(() => encodeSetRenderOptions({ ...o, flags: 0x10000 }), 'OutOfRange', /flags/);
  throwsCode(() => encodeSetRenderOptions({ ...o, flags: 0.5 }), 'OutOfRange', /flags/);
  for (const [lo, hi] of [[0x02, 0x00], [0x03, 0x00], [0x00, 0x01], [0x01, 0x80]]) {
    const bad = got.slice();
    bad[16 + 22] = lo;
    bad[16 + 23] = hi;
    throwsCode(() => decode(buf(bad)), 'OutOfRange', /flags/);
  }
});

test('SetRenderOptions: ranges', () => {
  const o = { width: 64, height: 64, stepVoxels: 1, techniques: 127, ertThreshold: 0.99, renderer: 0, quality: 0, codec: 3, codecQuality: 80, level: 255, refinedCodec: 5 };
  throwsCode(() => encodeSetRenderOptions({ ...o, width: 4097 }), 'OutOfRange', /width/);
  throwsCode(() => encodeSetRenderOptions({ ...o, height: 0 }), 'OutOfRange', /height/);
  throwsCode(() => encodeSetRenderOptions({ ...o, stepVoxels: 0 }), 'OutOfRange', /stepVoxels/);
  throwsCode(() => encodeSetRenderOptions({ ...o, techniques: 128 }), 'OutOfRange', /techniques/);
  throwsCode(() => encodeSetRenderOptions({ ...o, level: 16 }), 'OutOfRange', /level/);
  throwsCode(() => encodeSetRenderOptions({ ...o, renderer: 6 }), 'OutOfRange', /renderer/);
});

test('OpenVolume: names that are not catalog names are refused', () => {
  throwsCode(() => encodeOpenVolume('../etc'), 'OutOfRange', /name/);
  throwsCode(() => encodeOpenVolume('.hidden'), 'OutOfRange');
  throwsCode(() => encodeOpenVolume(''), 'OutOfRange');
  throwsCode(() => encodeOpenVolume('a'.repeat(65)), 'OutOfRange');
  assert.equal(decode(encodeOpenVolume('CT_AVM-1.v2')).body.name, 'CT_AVM-1.v2');
});

const volumeBytes = [
  0x06, 0x00, ...ascii('cthead'), ...u32(256), ...u32(256), ...u32(113),
  ...f64(1), ...f64(1), ...f64(2), 0x01, 0x04, ...f64(0), ...f64(4095), ...u64(14811136),
];

test('VolumeList: decodes the golden bytes of MessagesTest.cpp', () => {
  const m = decode(buf([...header(0x05, 72, 2), 0x01, 0x00, ...volumeBytes]));
  assert.equal(m.name, 'VolumeList');
  assert.equal(m.request, 2);
  assert.deepEqual(m.body.volumes, [{
    name: 'cthead', dims: [256, 256, 113], spacingMm: [1, 1, 2], voxelType: 1, levels: 4,
    valueMin: 0, valueMax: 4095, storedBytes: 14811136,
  }]);
  assert.deepEqual(decode(buf([...header(0x05, 2, 2), 0, 0])).body.volumes, []);
  assert.deepEqual(bytes(encode(Type.VolumeList, m.body, 2)), [...header(0x05, 72, 2), 0x01, 0x00, ...volumeBytes]);
});

test('VolumeOpened: decodes', () => {
  const m = decode(buf([...header(0x07, 70, 3), ...volumeBytes]));
  assert.equal(m.body.name, 'cthead');
  assert.deepEqual(m.body.spacingMm, [1, 1, 2]);
});

const frameBytes = [
  ...header(0x0c, 68, 7),
  0x2a, 0, 0, 0, 0x07, 0, 0, 0, 0x02, 0x00, 0x01, 0x00, 0x00, 0x01, 0x01, 0x00,
  0x00, 0x00, 0x00, 0x3f, 0x00, 0x00, 0x48, 0x41, 0x00, 0x00, 0x80, 0x3e,
  0xe8, 0x03, 0, 0, 0, 0, 0, 0, 0x03, 0, 0, 0, 0x05, 0, 0, 0,
  0x00, 0x00, 0x01, 0, 0, 0, 0, 0, 0x01, 0x01, 0, 0, 0x08, 0, 0, 0,
  0xff, 0x00, 0x00, 0xff, 0x00, 0x80, 0x00, 0x80,
];

test('Frame: decodes a hand-built frame (golden bytes of MessagesTest.cpp)', () => {
  const m = decode(buf(frameBytes));
  const { image, ...h } = m.body;
  assert.deepEqual(h, {
    frameId: 42, cameraId: 7, width: 2, height: 1, codec: 0, level: 1, refined: true, keyframe: false,
    queueMs: 0.5, renderMs: 12.5, encodeMs: 0.25, samples: 1000, bricksDrawn: 3, bricksSkipped: 5,
    bytesUploaded: 65536, occlusionUsed: true, cached: true, scale: 0, estimatedPsnrDb: 0,
  });
  assert.deepEqual(Array.from(image), [0xff, 0, 0, 0xff, 0, 0x80, 0, 0x80]);
  assert.deepEqual(bytes(encode(Type.Frame, m.body, 7)), frameBytes);
});

test('Frame: imageBytes must equal what is left of the payload', () => {
  const tooFew = frameBytes.slice();
  tooFew[16 + 56] = 0x09; // imageBytes 9, 8 follow
  throwsCode(() => decode(buf(tooFew)), 'BadPayload', /imageBytes 9/);
  const bad = frameBytes.slice();
  bad[16 + 14] = 2; // refined = 2 is no bool
  throwsCode(() => decode(buf(bad)), 'BadPayload', /refined/);
});

test('Frame: scale (byte 54) and estimatedPsnrDb (byte 55), 0 from servers before 2026-12-06', () => {
  // The golden frame has 0 in both, as the two reserved bytes of an older server.
  const old = decode(buf(frameBytes)).body;
  assert.equal(old.scale, 0);
  assert.equal(old.estimatedPsnrDb, 0);
  const withBudget = frameBytes.slice();
  withBudget[16 + 54] = 2;
  withBudget[16 + 55] = 43;
  const m = decode(buf(withBudget)).body;
  assert.equal(m.scale, 2);
  assert.equal(m.estimatedPsnrDb, 43);
  assert.equal(m.cached, true, 'cached (byte 53) is unchanged');
  assert.equal(m.image.length, 8, 'imageBytes (bytes 56..59) is unchanged');
  assert.deepEqual(bytes(encode(Type.Frame, m, 7)), withBudget);
  // Every scale of the protocol, and the estimate's bounds.
  for (const scale of [0, 1, 2, 3, 4, 6, 8]) {
    const b = withBudget.slice();
    b[16 + 54] = scale;
    assert.equal(decode(buf(b)).body.scale, scale);
  }
  for (const db of [0, 1, 50]) {
    const b = withBudget.slice();
    b[16 + 55] = db;
    assert.equal(decode(buf(b)).body.estimatedPsnrDb, db);
  }
  // Encoding without the fields writes 0 and 0, as an older server did.
  const { scale, estimatedPsnrDb, ...noFields } = m;
  assert.deepEqual(bytes(encode(Type.Frame, noFields, 7)).slice(16 + 54, 16 + 56), [0, 0]);
});

test('Frame: a scale or estimatedPsnrDb outside the protocol is refused', () => {
  // 0..8, as the server's own decoder checks (PROTOCOL.md names 1, 2, 3, 4, 6 and 8).
  for (const scale of [9, 16, 255]) {
    const b = frameBytes.slice();
    b[16 + 54] = scale;
    throwsCode(() => decode(buf(b)), 'BadPayload', /scale/);
  }
  for (const db of [51, 255]) {
    const b = frameBytes.slice();
    b[16 + 55] = db;
    throwsCode(() => decode(buf(b)), 'BadPayload', /estimatedPsnrDb/);
  }
  const m = decode(buf(frameBytes)).body;
  throwsCode(() => encode(Type.Frame, { ...m, scale: 9 }), 'OutOfRange', /scale/);
  throwsCode(() => encode(Type.Frame, { ...m, scale: 1.5 }), 'OutOfRange', /scale/);
  throwsCode(() => encode(Type.Frame, { ...m, estimatedPsnrDb: 51 }), 'OutOfRange', /estimatedPsnrDb/);
  throwsCode(() => encode(Type.Frame, { ...m, estimatedPsnrDb: 40.5 }), 'OutOfRange', /estimatedPsnrDb/);
});

test('SetFrameBudget: type 0x13, u16 interactiveMs then u8 restPsnrDb, little-endian', () => {
  const got = encodeSetFrameBudget({ interactiveMs: 66, restPsnrDb: 40 }, 9);
  assert.deepEqual(bytes(got), [...header(0x13, 3, 9), 0x42, 0x00, 0x28]);
  assert.deepEqual(decode(got), { type: Type.SetFrameBudget, name: 'SetFrameBudget', flags: 0, request: 9, body: { interactiveMs: 66, restPsnrDb: 40 } });
  assert.deepEqual(bytes(encodeSetFrameBudget({ interactiveMs: 0, restPsnrDb: 0 }, 1)), [...header(0x13, 3, 1), 0x00, 0x00, 0x00]);
  assert.deepEqual(bytes(encodeSetFrameBudget({ interactiveMs: 10000, restPsnrDb: 50 }, 2)), [...header(0x13, 3, 2), 0x10, 0x27, 0x32]);
  assert.deepEqual(bytes(encodeSetFrameBudget({ interactiveMs: 1, restPsnrDb: 20 }, 3)), [...header(0x13, 3, 3), 0x01, 0x00, 0x14]);
  assert.deepEqual(bytes(encodeSetFrameBudget({ interactiveMs: 1000, restPsnrDb: 0 }, 4)).slice(16), [0xe8, 0x03, 0x00]);
  assert.equal(Type.SetFrameBudget, 0x13);
  assert.equal(typeName(0x13), 'SetFrameBudget');
  assert.equal(Capability.FrameBudget, 1 << 4);
});

test('SetFrameBudget: values out of range are refused, naming the field', () => {
  const ok = { interactiveMs: 66, restPsnrDb: 0 };
  for (const interactiveMs of [10001, 65535, -1, 33.5, NaN, Infinity, '66', undefined, null]) {
    throwsCode(() => encodeSetFrameBudget({ ...ok, interactiveMs }), 'OutOfRange', /interactiveMs/);
  }
  for (const restPsnrDb of [1, 10, 19, 51, 100, 255, 256, -1, 40.5, NaN, '40', undefined]) {
    throwsCode(() => encodeSetFrameBudget({ ...ok, restPsnrDb }), 'OutOfRange', /restPsnrDb/);
  }
  for (const restPsnrDb of [0, 20, 30, 35, 40, 45, 50]) {
    assert.equal(decode(encodeSetFrameBudget({ ...ok, restPsnrDb })).body.restPsnrDb, restPsnrDb);
  }
  // Decoding as the server does: out of range, not malformed; a payload of another size is malformed.
  throwsCode(() => decode(buf([...header(0x13, 3, 0), 0x11, 0x27, 0x00])), 'OutOfRange', /interactiveMs/);
  throwsCode(() => decode(buf([...header(0x13, 3, 0), 0x42, 0x00, 0x13])), 'OutOfRange', /restPsnrDb/);
  throwsCode(() => decode(buf([...header(0x13, 3, 0), 0x42, 0x00, 0x33])), 'OutOfRange', /restPsnrDb/);
  throwsCode(() => decode(buf([...header(0x13, 2, 0), 0x42, 0x00])), 'BadPayload', /too short/);
  throwsCode(() => decode(buf([...header(0x13, 4, 0), 0x42, 0x00, 0x28, 0x00])), 'BadPayload', /left over/);
});

// The example of PROTOCOL.md: MIP, cropped to (0, 10, 20)..(100, 110, 120) mm, keeping x >= 50 mm.
const modeAndClip = {
  mode: Mode.Maximum, isoValue: 0, crop: { min: [0, 10, 20], max: [100, 110, 120] },
  planes: [{ normal: [1, 0, 0], offset: -50 }], cap: false,
};
const modeAndClipBytes = [
  ...header(0x14, 91, 7), 0x01, ...f64(0), 0x01,
  ...f64(0), ...[0, 0, 0, 0, 0, 0, 0x24, 0x40], ...f64(20), ...f64(100), ...f64(110), ...f64(120),
  0x01, ...[0, 0, 0, 0, 0, 0, 0xf0, 0x3f], ...f64(0), ...f64(0), ...[0, 0, 0, 0, 0, 0, 0x49, 0xc0],
];

test('SetModeAndClip: type 0x14, u8 mode, f64 isoValue, bool cropped, f64 cropMin[3], f64 cropMax[3], u8 planeCount, planes', () => {
  const got = encodeSetModeAndClip(modeAndClip, 7);
  assert.deepEqual(bytes(got), modeAndClipBytes);
  assert.deepEqual(decode(got), { type: Type.SetModeAndClip, name: 'SetModeAndClip', flags: 0, request: 7, body: modeAndClip });
  // Composite, no crop, no planes: 59 bytes, all 0.
  const none = { mode: Mode.Composite, isoValue: 0, crop: null, planes: [], cap: false };
  assert.deepEqual(bytes(encodeSetModeAndClip(none, 1)), [...header(0x14, 59, 1), ...Array(59).fill(0)]);
  assert.deepEqual(decode(encodeSetModeAndClip(none, 1)).body, none);
  // crop and planes left out: none.
  assert.deepEqual(bytes(encodeSetModeAndClip({ mode: 0, isoValue: 0 }, 1)), [...header(0x14, 59, 1), ...Array(59).fill(0)]);
  // 59 + 32 bytes a plane, up to six.
  const six = { mode: Mode.Isosurface, isoValue: 1200.5, crop: null, planes: Array.from({ length: 6 }, (_, i) => ({ normal: [0, 0, i % 2 ? -1 : 1], offset: i })), cap: false };
  const b = encodeSetModeAndClip(six, 3);
  assert.equal(b.byteLength, 16 + 59 + 32 * 6);
  assert.deepEqual(decode(b).body, six);
  assert.deepEqual(bytes(b).slice(16 + 1, 16 + 9), f64(1200.5));
  assert.equal(Type.SetModeAndClip, 0x14);
  assert.equal(typeName(0x14), 'SetModeAndClip');
  assert.equal(Capability.ModesAndClips, 1 << 5);
  assert.deepEqual(Mode, { Composite: 0, Maximum: 1, Minimum: 2, Average: 3, Isosurface: 4 });
  assert.equal(MAX_CLIP_PLANES, 6);
});

test('SetModeAndClip: values out of range are refused, naming the field', () => {
  const ok = modeAndClip;
  for (const mode of [5, 255, -1, 1.5, NaN, '1', undefined, null]) {
    throwsCode(() => encodeSetModeAndClip({ ...ok, mode }), 'OutOfRange', /mode/);
  }
  for (const isoValue of [NaN, Infinity, -Infinity, '0', undefined, null]) {
    throwsCode(() => encodeSetModeAndClip({ ...ok, isoValue }), 'OutOfRange', /isoValue/);
  }
  const crops = [
    { min: [0, 10, 20], max: [100, 10, 120] }, // empty on y
    { min: [0, 10, 130], max: [100, 110, 120] }, // inverted on z
    { min: [NaN, 10, 20], max: [100, 110, 120] },
    { min: [0, 10, 20], max: [100, Infinity, 120] },
    { min: [0, 10], max: [100, 110, 120] },
    { max: [100, 110, 120] },
  ];
  for (const crop of crops) throwsCode(() => encodeSetModeAndClip({ ...ok, crop }), 'OutOfRange', /crop/);
  const plane = ok.planes[0];
  throwsCode(() => encodeSetModeAndClip({ ...ok, planes: Array(7).fill(plane) }), 'OutOfRange', /planes: 7, more than 6/);
  throwsCode(() => encodeSetModeAndClip({ ...ok, planes: plane }), 'OutOfRange', /planes/);
  for (const normal of [[0, 0, 0], [1e-31, 0, -1e-31], [NaN, 1, 0], [0, Infinity, 0], [1, 0], undefined]) {
    throwsCode(() => encodeSetModeAndClip({ ...ok, planes: [plane, { normal, offset: 0 }] }), 'OutOfRange', /planes\[1\]\.normal/);
  }
  for (const offset of [NaN, Infinity, undefined, '0']) {
    throwsCode(() => encodeSetModeAndClip({ ...ok, planes: [{ ...plane, offset }] }), 'OutOfRange', /planes\[0\]\.offset/);
  }
  // The smallest normal that has a direction, and a crop box anywhere (in or out of the volume).
  assert.deepEqual(decode(encodeSetModeAndClip({ ...ok, planes: [{ normal: [0, -1e-29, 0], offset: 3 }] })).body.planes,
    [{ normal: [0, -1e-29, 0], offset: 3 }]);
  assert.deepEqual(decode(encodeSetModeAndClip({ ...ok, crop: { min: [-5, -5, -5], max: [1e9, -4, 0] } })).body.crop,
    { min: [-5, -5, -5], max: [1e9, -4, 0] });
});

test('SetModeAndClip: decoding as the server does', () => {
  const at = (offset, values) => { const b = modeAndClipBytes.slice(); b.splice(16 + offset, values.length, ...values); return buf(b); };
  throwsCode(() => decode(at(0, [5])), 'OutOfRange', /mode/);
  throwsCode(() => decode(at(1, f64(NaN))), 'OutOfRange', /isoValue/);
  throwsCode(() => decode(at(10 + 8, f64(110))), 'OutOfRange', /crop: axis y/); // cropMin.y == cropMax.y
  throwsCode(() => decode(at(10 + 40, f64(-Infinity))), 'OutOfRange', /crop/);
  throwsCode(() => decode(at(9, [2])), 'BadPayload', /cropped/);
  // Not cropped: the six must be 0.
  throwsCode(() => decode(at(9, [0])), 'OutOfRange', /crop: not cropped/);
  const uncropped = [...header(0x14, 59, 1), ...Array(59).fill(0)];
  assert.equal(decode(buf(uncropped)).body.crop, null);
  throwsCode(() => decode(at(59, f64(0))), 'OutOfRange', /planes\[0\]\.normal/); // normal (0, 0, 0)
  throwsCode(() => decode(at(59 + 24, f64(NaN))), 'OutOfRange', /planes\[0\]\.offset/);
  // planeCount over 6, and a count its bytes do not match.
  const seven = [...header(0x14, 59 + 32 * 7, 0), ...modeAndClipBytes.slice(16, 16 + 58), 7];
  for (let i = 0; i < 7; ++i) seven.push(...modeAndClipBytes.slice(16 + 59));
  throwsCode(() => decode(buf(seven)), 'OutOfRange', /planes: 7, more than 6/);
  const two = modeAndClipBytes.slice(); two[16 + 58] = 2;
  throwsCode(() => decode(buf(two)), 'BadPayload', /too short/);
  const noPlanes = [...header(0x14, 91, 7), ...modeAndClipBytes.slice(16, 16 + 58), 0, ...modeAndClipBytes.slice(16 + 59)];
  throwsCode(() => decode(buf(noPlanes)), 'BadPayload', /left over/);
});

// The capped example: the one above in composite, cap on: the same body, then cutFlags 0x01.
const cappedBytes = [...header(0x14, 92, 7), 0x00, ...modeAndClipBytes.slice(16 + 1), 0x01];

test('SetModeAndClip: an optional u8 cutFlags after the planes, bit 0 cap, written only when not 0', () => {
  const capped = { ...modeAndClip, mode: Mode.Composite, cap: true };
  const got = encodeSetModeAndClip(capped, 7);
  assert.deepEqual(bytes(got), cappedBytes);
  assert.deepEqual(decode(got).body, capped);
  // cap false or left out: no flags byte, the 91 bytes servers before 2026-12-08 read.
  assert.deepEqual(bytes(encodeSetModeAndClip({ ...capped, cap: false }, 7)), [...header(0x14, 91, 7), 0x00, ...modeAndClipBytes.slice(16 + 1)]);
  const { cap, ...noCap } = capped;
  assert.equal(encodeSetModeAndClip(noCap, 7).byteLength, 16 + 91);
  // Decoding: no byte is no cap; a present 0 is refused (a message has one encoding: no cap
  // leaves the byte out).
  assert.equal(decode(buf(modeAndClipBytes)).body.cap, false);
  const zero = [...header(0x14, 92, 7), ...modeAndClipBytes.slice(16), 0x00];
  throwsCode(() => decode(buf(zero)), 'OutOfRange', /cutFlags/);
  // The isosurface caps too.
  const iso = { ...capped, mode: Mode.Isosurface, isoValue: 1200 };
  assert.deepEqual(decode(encodeSetModeAndClip(iso, 1)).body, iso);
  assert.equal(CutFlags.Cap, 1);
  assert.equal(Capability.Capping, 1 << 6);
});

test('SetModeAndClip: cutFlags with other bits, or a cap with MIP, MinIP or average, is out of range', () => {
  for (const flags of [0x02, 0x03, 0x80, 0xff]) {
    const b = cappedBytes.slice(); b[b.length - 1] = flags;
    throwsCode(() => decode(buf(b)), 'OutOfRange', /cutFlags/);
  }
  for (const mode of [Mode.Maximum, Mode.Minimum, Mode.Average]) {
    throwsCode(() => encodeSetModeAndClip({ ...modeAndClip, mode, cap: true }), 'OutOfRange', /cutFlags: mode \d \(\w+\) draws no surface to cap/);
    const b = cappedBytes.slice(); b[16] = mode;
    throwsCode(() => decode(buf(b)), 'OutOfRange', /cutFlags/);
  }
  throwsCode(() => encodeSetModeAndClip({ ...modeAndClip, mode: Mode.Maximum, cap: true }), 'OutOfRange', /mode 1 \(maximum\)/);
  for (const cap of [1, 'true']) throwsCode(() => encodeSetModeAndClip({ ...modeAndClip, mode: 0, cap }), 'OutOfRange', /cutFlags/);
  // A byte after the flags is left over.
  throwsCode(() => decode(buf([...header(0x14, 93, 7), ...cappedBytes.slice(16), 0x00])), 'BadPayload', /left over/);
});

test('Stats: decodes the golden bytes of MessagesTest.cpp', () => {
  const m = decode(buf([
    ...header(0x0e, 32, 8), 0x02, 0x00, 0x06, 0x00, ...ascii('frames'), ...f64(12),
    0x04, 0x00, ...ascii('hits'), ...f64(0.75),
  ]));
  assert.deepEqual(m.body.counters, [{ name: 'frames', value: 12 }, { name: 'hits', value: 0.75 }]);
});

test('Error: decodes the golden bytes of MessagesTest.cpp and round-trips', () => {
  const raw = [...header(0x0f, 15, 6), 0x06, 0x00, 0x00, 0x0a, 0x09, 0x00, ...ascii('bad width')];
  const m = decode(buf(raw));
  assert.deepEqual(m.body, { code: ErrorCode.OutOfRange, fatal: false, offendingType: 0x0a, message: 'bad width' });
  assert.deepEqual(bytes(encodeError(m.body, 6)), raw);
  assert.equal(errorName(17), 'NotFound');
  assert.equal(errorName(99), 'error 99');
  assert.equal(typeName(0x0a), 'SetRenderOptions');
  assert.equal(typeName(0x42), 'unknown');
});

test('Histogram: decodes f64 min, f64 max, u16 binCount, u64 counts', () => {
  const m = decode(buf([...header(0x12, 18 + 24, 0), ...f64(-1024), ...f64(3071), 0x03, 0x00, ...u64(5), ...u64(0), ...u64(2 ** 40)]));
  assert.equal(m.name, 'Histogram');
  assert.equal(m.body.valueMin, -1024);
  assert.equal(m.body.valueMax, 3071);
  assert.deepEqual(Array.from(m.body.counts), [5, 0, 2 ** 40]);
  throwsCode(() => decode(buf([...header(0x12, 18 + 16, 0), ...f64(0), ...f64(1), 0x03, 0x00, ...u64(1), ...u64(1)])), 'BadPayload', /3 bins/);
  throwsCode(() => decode(buf([...header(0x12, 18, 0), ...f64(0), ...f64(1), 0x00, 0x00])), 'BadPayload', /binCount 0/);
});

test('round trips: every type decodes to what was encoded', () => {
  const cases = [
    [Type.AuthOk, {}], [Type.ListVolumes, {}], [Type.RequestStats, {}], [Type.RequestHistogram, {}],
    [Type.Auth, { token: 'tøken' }], [Type.RequestFrame, { mode: 2 }], [Type.Bye, { reason: 1 }],
    [Type.SetFrameBudget, { interactiveMs: 200, restPsnrDb: 45 }],
    [Type.SetModeAndClip, { mode: Mode.Average, isoValue: -3.25, crop: null, planes: [{ normal: [0.6, 0.8, 0], offset: 12 }], cap: false }],
    [Type.SetModeAndClip, { mode: Mode.Isosurface, isoValue: 7, crop: { min: [1, 2, 3], max: [4, 5, 6] }, planes: [], cap: true }],
    [Type.Stats, { counters: [{ name: 'bricks resident', value: 3 }] }],
    [Type.Histogram, { valueMin: 0, valueMax: 255, counts: new Float64Array([1, 2, 3, 4]) }],
    [Type.Error, { code: 13, fatal: false, offendingType: 0x0b, message: 'no OpenGL' }],
  ];
  for (const [type, body] of cases) {
    const m = decode(encode(type, body, 11));
    assert.equal(m.type, type);
    assert.equal(m.request, 11);
    assert.deepEqual(m.body, body);
  }
});

test('malformed input: wrong magic, wrong version, too large, short header', () => {
  const ok = bytes(encodeListVolumes(1));
  const badMagic = ok.slice(); badMagic[0] = 0x41;
  throwsCode(() => decode(buf(badMagic)), 'BadMagic');
  const badVersion = ok.slice(); badVersion[4] = 2;
  throwsCode(() => decode(buf(badVersion)), 'UnsupportedVersion');
  throwsCode(() => decodeHeader(buf(header(0x0c, 2 ** 31, 0))), 'TooLarge');
  throwsCode(() => decode(buf(ok.slice(0, 10))), 'BadPayload', /shorter than the 16-byte header/);
});

test('malformed input: length mismatch, short payload, bytes left over, unknown type, flags', () => {
  // the header claims more than the message holds
  throwsCode(() => decode(buf([...header(0x10, 4, 0), 0x00, 0x00])), 'BadPayload', /4 payload bytes/);
  // a payload too short for its type
  throwsCode(() => decode(buf([...header(0x10, 1, 0), 0x00])), 'BadPayload', /too short/);
  // a payload too long for its type
  throwsCode(() => decode(buf([...header(0x03, 1, 0), 0x00])), 'BadPayload', /left over/);
  throwsCode(() => decode(buf([...header(0x07, 69, 3), ...volumeBytes.slice(0, 69)])), 'BadPayload', /too short/);
  throwsCode(() => decode(buf(header(0x42, 0, 0))), 'UnknownType');
  const flagged = header(0x03, 0, 0); flagged[6] = 1;
  throwsCode(() => decode(buf(flagged)), 'BadPayload', /flags/);
  // strings over their limit and invalid UTF-8
  throwsCode(() => decode(buf([...header(0x0f, 6, 0), 0x05, 0x00, 0x00, 0x00, 0x01, 0x04])), 'BadPayload', /1025 bytes, over 1024/);
  throwsCode(() => decode(buf([...header(0x02, 3, 0), 0x01, 0x00, 0xff])), 'BadPayload', /UTF-8/);
});

test('decode accepts typed-array views at an offset', () => {
  const raw = new Uint8Array([0xaa, ...bytes(encodeBye(1))]);
  assert.deepEqual(decode(raw.subarray(1)).body, { reason: 1 });
});
