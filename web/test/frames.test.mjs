import { test } from 'node:test';
import assert from 'node:assert/strict';
import { frameSize, formatBytes, volumeLabel, FrameStats } from '../js/frames.js';

test('frame size follows the canvas, capped by the configured max and 4096, aspect kept', () => {
  assert.deepEqual(frameSize(800, 600, 1024), { width: 800, height: 600 });
  assert.deepEqual(frameSize(3840, 2160, 1024), { width: 1024, height: 576 });
  assert.deepEqual(frameSize(2160, 3840, 1024), { width: 576, height: 1024 });
  assert.deepEqual(frameSize(10000, 100, 8192), { width: 4096, height: 41 });
  assert.deepEqual(frameSize(5000, 1, 1024), { width: 1024, height: 1 });
  assert.deepEqual(frameSize(0, 300, 1024), { width: 0, height: 0 });
  assert.deepEqual(frameSize(300.4, 200.6, 1024), { width: 300, height: 201 });
});

test('human-readable sizes and picker labels', () => {
  assert.equal(formatBytes(512), '512 B');
  assert.equal(formatBytes(14811136), '14.1 MiB');
  assert.equal(formatBytes(1024), '1.00 KiB');
  assert.equal(volumeLabel({ name: 'cthead', dims: [256, 256, 113], voxelType: 1, storedBytes: 14811136 }), 'cthead — 256×256×113 u16, 14.1 MiB');
});

test('fps counts the frames of the last second; latency keeps the last measured', () => {
  const s = new FrameStats();
  for (let t = 0; t < 2000; t += 40) s.frameDrawn(t, t === 0 ? 55 : null);
  assert.equal(s.fps(1960), 25);
  assert.equal(s.latencyMs, 55);
  assert.equal(s.fps(5000), 0);
});
