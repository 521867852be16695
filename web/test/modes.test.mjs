// modes.js: the "Mode and cut" controls' SetModeAndClip, from fractions of the volume's extent.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import {
  CLIP_AXES, CROP_STEP, extentMm, orderCropRange, cropBoxMm, clipPlaneOf, isoRangeOf, clampIso, defaultCut, modeAndClipOf,
  formatMm, cropLabels, clipLabel, snapIso, whyNoCap,
} from '../js/modes.js';
import { Mode, decode, encodeSetModeAndClip } from '../js/protocol.js';

// 256 × 256 × 113 voxels of 1 × 1 × 2 mm: the box is [0, 256] × [0, 256] × [0, 226] mm.
const cthead = { name: 'cthead', dims: [256, 256, 113], spacingMm: [1, 1, 2], voxelType: 1, levels: 4, valueMin: 0, valueMax: 4095, storedBytes: 0 };
const close = (a, b) => assert.ok(Math.abs(a - b) < 1e-9, `${a} != ${b}`);

test('the extent is dims × spacing on each axis', () => {
  assert.deepEqual(extentMm(cthead), [256, 256, 226]);
  assert.deepEqual(extentMm({ dims: [10, 20, 30], spacingMm: [0.5, 0.25, 3] }), [5, 5, 90]);
});

test('crop fractions: low stays below high, the slider moved gives way', () => {
  assert.deepEqual(orderCropRange(0.2, 0.8, 'low'), { low: 0.2, high: 0.8 });
  // low dragged past high stops a step short of it; high dragged below low likewise.
  const a = orderCropRange(0.9, 0.6, 'low');
  assert.equal(a.high, 0.6);
  close(a.low, 0.6 - CROP_STEP);
  const b = orderCropRange(0.4, 0.1, 'high');
  assert.equal(b.low, 0.4);
  close(b.high, 0.4 + CROP_STEP);
  // Equal values, and the ends of the range.
  const c = orderCropRange(0.5, 0.5, 'low');
  assert.ok(c.low < c.high);
  assert.equal(c.high, 0.5);
  const d = orderCropRange(1, 1, 'low');
  assert.ok(d.low < d.high && d.high === 1);
  const e = orderCropRange(0, 0, 'high');
  assert.ok(e.low === 0 && e.high > 0);
  assert.deepEqual(orderCropRange(-1, 2), { low: 0, high: 1 });
  assert.deepEqual(orderCropRange(NaN, NaN), { low: 0, high: 1 });
});

test('crop box in mm from fractions of the extent', () => {
  assert.deepEqual(cropBoxMm(cthead, [0, 0, 0], [1, 1, 1]), { min: [0, 0, 0], max: [256, 256, 226] });
  assert.deepEqual(cropBoxMm(cthead, [0.25, 0.5, 0.5], [0.75, 1, 1]), { min: [64, 128, 113], max: [192, 256, 226] });
  // Out of order: still a box with min < max on every axis.
  const box = cropBoxMm(cthead, [0.6, 0.3, 1], [0.6, 0.2, 1]);
  for (let a = 0; a < 3; ++a) assert.ok(box.min[a] < box.max[a], `axis ${a}: ${box.min[a]}..${box.max[a]}`);
});

test('a clip plane from an axis and a position keeps the side its normal points to', () => {
  // +x at 40 mm of a 100 mm extent: keeps x >= 40.
  const vol = { dims: [100, 50, 20], spacingMm: [1, 2, 0.5] };
  assert.deepEqual(clipPlaneOf(vol, '+x', 0.4), { normal: [1, 0, 0], offset: -40 });
  assert.deepEqual(clipPlaneOf(vol, '-x', 0.4), { normal: [-1, 0, 0], offset: 40 });
  assert.deepEqual(clipPlaneOf(vol, '+y', 0.5), { normal: [0, 1, 0], offset: -50 });
  assert.deepEqual(clipPlaneOf(vol, '-z', 1), { normal: [0, 0, -1], offset: 10 });
  const keeps = ({ normal, offset }, x) => normal[0] * x[0] + normal[1] * x[1] + normal[2] * x[2] + offset >= 0;
  for (const axis of CLIP_AXES) {
    const p = clipPlaneOf(vol, axis, 0.3);
    const a = 'xyz'.indexOf(axis[1]);
    const at = (mm) => { const x = [1, 1, 1]; x[a] = mm; return x; };
    const pos = 0.3 * extentMm(vol)[a];
    assert.equal(keeps(p, at(pos + 1)), axis[0] === '+', `${axis}: above`);
    assert.equal(keeps(p, at(pos - 1)), axis[0] === '-', `${axis}: below`);
  }
  // At 0 mm: offset 0, not -0; the position is kept within the extent.
  assert.ok(Object.is(clipPlaneOf(vol, '+x', 0).offset, 0));
  assert.ok(Object.is(clipPlaneOf(vol, '-x', 0).offset, 0));
  assert.deepEqual(clipPlaneOf(vol, '+x', 2), { normal: [1, 0, 0], offset: -100 });
  assert.throws(() => clipPlaneOf(vol, 'x', 0.5), RangeError);
  assert.throws(() => clipPlaneOf(vol, '+w', 0.5), RangeError);
});

test('iso value range: the volume\'s values, a power-of-ten step, the middle by default', () => {
  assert.deepEqual(isoRangeOf(cthead), { min: 0, max: 4095, step: 1, middle: 2047.5 });
  assert.deepEqual(isoRangeOf({ valueMin: 0, valueMax: 1 }), { min: 0, max: 1, step: 0.001, middle: 0.5 });
  assert.deepEqual(isoRangeOf({ valueMin: -1024, valueMax: 3071 }), { min: -1024, max: 3071, step: 1, middle: 1023.5 });
  assert.equal(isoRangeOf({ valueMin: 7, valueMax: 7 }).step, 'any');
  assert.equal(clampIso(cthead, 5000), 4095);
  assert.equal(clampIso(cthead, -3), 0);
  assert.equal(clampIso(cthead, 300.25), 300.25);
  assert.equal(clampIso(cthead, NaN), 2047.5);
});

test('the controls\' SetModeAndClip: composite and nothing cut by default', () => {
  const cut = defaultCut(cthead);
  assert.deepEqual(cut, { mode: Mode.Composite, isoValue: 2047.5, cropped: false, low: [0, 0, 0], high: [1, 1, 1], clip: false, axis: '+x', position: 0.5, cap: false });
  const m = modeAndClipOf(cthead, cut);
  assert.deepEqual(m, { mode: 0, isoValue: 0, crop: null, planes: [], cap: false });
  // That is the all-zero message of PROTOCOL.md.
  assert.deepEqual(Array.from(new Uint8Array(encodeSetModeAndClip(m, 1))).slice(16), Array(59).fill(0));
});

test('the controls\' SetModeAndClip: iso value in isosurface mode only, crop box and plane in mm', () => {
  const cut = {
    mode: Mode.Isosurface, isoValue: 9999, cropped: true, low: [0.25, 0, 0.5], high: [0.75, 1, 1],
    clip: true, axis: '-y', position: 0.25,
  };
  const m = modeAndClipOf(cthead, cut);
  assert.deepEqual(m, {
    mode: 4, isoValue: 4095, crop: { min: [64, 0, 113], max: [192, 256, 226] },
    planes: [{ normal: [0, -1, 0], offset: 64 }], cap: false,
  });
  assert.deepEqual(decode(encodeSetModeAndClip(m, 2)).body, m);
  assert.equal(modeAndClipOf(cthead, { ...cut, mode: Mode.Maximum }).isoValue, 0);
  assert.equal(modeAndClipOf(cthead, { ...cut, isoValue: 1200 }).isoValue, 1200);
  // Every mode, crop, plane and cap the controls can make encodes.
  for (const mode of Object.values(Mode)) {
    for (const axis of CLIP_AXES) {
      for (const [lo, hi] of [[0, 1], [0.5, 0.5], [1, 0], [0.999, 1]]) {
        for (const cap of [false, true]) {
          encodeSetModeAndClip(modeAndClipOf(cthead, { ...cut, mode, axis, low: [lo, lo, lo], high: [hi, hi, hi], cap }));
        }
      }
    }
  }
});

test('the controls\' SetModeAndClip: cap only with a cut, in composite or isosurface mode', () => {
  const cut = { ...defaultCut(cthead), cropped: true, low: [0.25, 0, 0.5], high: [0.75, 1, 1], cap: true };
  assert.equal(whyNoCap(cut), '');
  const m = modeAndClipOf(cthead, cut);
  assert.equal(m.cap, true);
  assert.deepEqual(decode(encodeSetModeAndClip(m, 1)).body, m);
  assert.equal(modeAndClipOf(cthead, { ...cut, mode: Mode.Isosurface }).cap, true);
  assert.equal(modeAndClipOf(cthead, { ...cut, cropped: false, clip: true }).cap, true);
  // Nothing cut: no face to cap.
  const uncut = { ...cut, cropped: false, clip: false };
  assert.equal(modeAndClipOf(cthead, uncut).cap, false);
  assert.match(whyNoCap(uncut), /nothing is cut/);
  // MIP, MinIP and average draw no surface (the server would refuse the cap): the cap is left off.
  for (const [mode, name] of [[Mode.Maximum, 'MIP'], [Mode.Minimum, 'MinIP'], [Mode.Average, 'average']]) {
    assert.equal(modeAndClipOf(cthead, { ...cut, mode }).cap, false);
    assert.match(whyNoCap({ ...cut, mode }), new RegExp(`${name} draws no surface to cap`));
    encodeSetModeAndClip(modeAndClipOf(cthead, { ...cut, mode, clip: true }));
  }
  // Not asked for: off, whatever the cut; only true asks for it.
  assert.equal(modeAndClipOf(cthead, { ...cut, cap: false }).cap, false);
  assert.equal(modeAndClipOf(cthead, { ...cut, cap: undefined }).cap, false);
  assert.equal(modeAndClipOf(cthead, { ...cut, cap: 1 }).cap, false);
});

test('labels: the crop box and what the plane keeps, in mm', () => {
  assert.equal(formatMm(64), '64');
  assert.equal(formatMm(112.54), '112.5');
  assert.equal(formatMm(-0.01), '0');
  assert.deepEqual(cropLabels(cthead, [0.25, 0, 0.5], [0.75, 1, 1]), ['64–192 mm', '0–256 mm', '113–226 mm']);
  assert.equal(clipLabel(cthead, '+x', 0.25), 'x ≥ 64 mm');
  assert.equal(clipLabel(cthead, '-z', 0.5), 'z ≤ 113 mm');
  assert.equal(clipLabel(cthead, '+y', 0), 'y ≥ 0 mm');
});

test('an iso value from the histogram\'s marker lands on the slider\'s step, within the values', () => {
  assert.equal(snapIso(cthead, 1234.4), 1234);
  assert.equal(snapIso(cthead, 1234.5), 1235);
  assert.equal(snapIso(cthead, 5000), 4095);
  assert.equal(snapIso(cthead, -7), 0);
  assert.equal(snapIso({ valueMin: 0, valueMax: 1 }, 0.12345), 0.123);
  // Steps count from valueMin, as an <input type=range> counts them; the last one fits under valueMax.
  const odd = { valueMin: -0.0137, valueMax: 1 };
  assert.equal(snapIso(odd, 0.5), 0.5003);
  assert.equal(snapIso(odd, 1), 0.9993);
  assert.equal(snapIso({ valueMin: 7, valueMax: 7 }, 3), 7);
});
