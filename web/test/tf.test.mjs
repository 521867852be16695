import { test } from 'node:test';
import assert from 'node:assert/strict';
import { percentileValue, normalizePoint, placePoints, evaluate } from '../js/tf.js';

// 10 bins over [0, 100]: the mode (bin 0, background) is left out of percentiles.
const hist = { valueMin: 0, valueMax: 100, counts: [1000, 0, 10, 10, 0, 20, 0, 0, 0, 0] };

test('percentiles count only voxels above the most populated bin, linear inside a bin', () => {
  assert.equal(percentileValue(hist, 0), 20); // lower edge of the first non-empty bin above the mode
  assert.equal(percentileValue(hist, 100), 60); // upper edge of the last non-empty bin
  assert.equal(percentileValue(hist, 25), 30); // 10 of 40 voxels: the top of bin 2
  assert.equal(percentileValue(hist, 50), 40);
  assert.equal(percentileValue(hist, 75), 55); // half-way through bin 5
});

test('percentiles count every voxel when none lies above the mode bin', () => {
  const top = { valueMin: 0, valueMax: 10, counts: [5, 0, 0, 0, 15] };
  assert.equal(percentileValue(top, 0), 0);
  assert.equal(percentileValue(top, 25), 2); // 5 voxels fill bin 0 exactly
  assert.equal(percentileValue(top, 100), 10);
  assert.throws(() => percentileValue({ valueMin: 0, valueMax: 1, counts: [0, 0] }, 50), /no voxel/);
});

test('points come in either form and are placed and sorted stably', () => {
  assert.deepEqual(normalizePoint({ fraction: 0.5, rgba: [1, 1, 1, 1] }), { placement: 1, position: 0.5, rgba: [1, 1, 1, 1] });
  assert.deepEqual(normalizePoint({ placement: 2, position: 90, rgba: [0, 0, 0, 0] }), { placement: 2, position: 90, rgba: [0, 0, 0, 0] });
  assert.throws(() => normalizePoint({ value: 1, fraction: 0.2, rgba: [0, 0, 0, 0] }), /exactly one/);
  assert.throws(() => normalizePoint({ value: 1 }), /rgba/);
  const placed = placePoints([
    { percentile: 100, rgba: [1, 1, 1, 0.9] },
    { value: 10, rgba: [0, 0, 0, 0] },
    { fraction: 0.6, rgba: [0.5, 0.5, 0.5, 0.5] },
  ], 0, 100, hist);
  assert.deepEqual(placed.map((p) => p.value), [10, 60, 60]);
  assert.deepEqual(placed.map((p) => p.rgba[3]), [0, 0.9, 0.5], 'equal values keep their input order (a step)');
});

test('evaluate: linear between points, ends held, later point wins at a step', () => {
  const pts = [{ value: 0, rgba: [0, 0, 0, 0] }, { value: 10, rgba: [1, 0, 0, 0.5] }, { value: 10, rgba: [0, 1, 0, 1] }];
  assert.deepEqual(evaluate(pts, -5), [0, 0, 0, 0]);
  assert.deepEqual(evaluate(pts, 5), [0.5, 0, 0, 0.25]);
  assert.deepEqual(evaluate(pts, 10), [0, 1, 0, 1]);
  assert.deepEqual(evaluate(pts, 50), [0, 1, 0, 1]);
});
