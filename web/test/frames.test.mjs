import { test } from 'node:test';
import assert from 'node:assert/strict';
import {
  frameSize, formatBytes, volumeLabel, FrameStats, isInteractiveSizeOf, residencyLine, autoRendererOf,
  scaleLabel, psnrLabel, frameDetailLabel,
} from '../js/frames.js';

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

test('unscaled interactive frames are each edge over a divisor, rounded up', () => {
  assert.ok(isInteractiveSizeOf(480, 381, 960, 762));
  assert.ok(isInteractiveSizeOf(481, 1, 961, 1));
  assert.ok(isInteractiveSizeOf(1, 1, 1, 1));
  assert.ok(!isInteractiveSizeOf(480, 382, 960, 762));
  // Under a frame-time budget: each edge over 1, 2, 3, 4, 6 or 8, rounded up, and nothing else.
  assert.ok(isInteractiveSizeOf(65, 47, 65, 47));
  assert.ok(isInteractiveSizeOf(33, 24, 65, 47));
  assert.ok(isInteractiveSizeOf(22, 16, 65, 47));
  assert.ok(isInteractiveSizeOf(9, 6, 65, 47));
  assert.ok(!isInteractiveSizeOf(13, 10, 65, 47), 'divisor 5 is not one of them');
  assert.ok(!isInteractiveSizeOf(33, 16, 65, 47), 'both edges over the same divisor');
});

test('the residency line shows the open volume only', () => {
  const c = (name, value, volume) => ({ name: volume ? `${name}{volume="${volume}"}` : name, value });
  const counters = [
    c('frames_total', 3),
    c('host_cache_hits_total', 30, 'phantom'), c('host_cache_misses_total', 10, 'phantom'),
    c('host_cache_resident_bytes', 0, 'phantom'), c('host_cache_budget_bytes', 0, 'phantom'),
    c('host_cache_hits_total', 0, 'vessels'), c('host_cache_misses_total', 1, 'vessels'),
    c('host_cache_resident_bytes', 314432, 'vessels'), c('host_cache_budget_bytes', 1073741824, 'vessels'),
    c('gpu_pool_hits_total', 95, 'vessels'), c('gpu_pool_uploads_total', 5, 'vessels'),
    c('gpu_pool_budget_bytes', 512 * 1024 * 1024, 'vessels'),
  ];
  assert.equal(residencyLine(counters, 'vessels'), 'cache 0.3 / 1024 MiB, hits 0%  GPU pool 512 MiB, hits 95%');
  assert.equal(residencyLine(counters, 'phantom'), 'cache 0 MiB, hits 75%');
  assert.equal(residencyLine(counters, 'other'), '');
  // A pool that has done nothing yet is left out; no lookups yet is a dash, not NaN.
  const idle = [c('host_cache_resident_bytes', 12.5 * 1024 * 1024, 'ct'), c('host_cache_budget_bytes', 64 * 1024 * 1024, 'ct'),
    c('gpu_pool_hits_total', 0, 'ct'), c('gpu_pool_uploads_total', 0, 'ct'), c('gpu_pool_budget_bytes', 0, 'ct')];
  assert.equal(residencyLine(idle, 'ct'), 'cache 13 / 64 MiB, hits —');
  // A name that is a suffix of another is not confused with it.
  assert.equal(residencyLine([c('host_cache_resident_bytes', 0, 'xct'), c('host_cache_hits_total', 1, 'xct')], 'ct'), '');
});

test("the server's auto renderer and why, from its Stats counters", () => {
  const reason = "auto: cpu (GL_RENDERER 'llvmpipe (LLVM 15.0.6, 256 bits)' is a software rasteriser)";
  const counters = [
    { name: 'frames_total{renderer="cpu"}', value: 3 },
    { name: `auto_renderer{renderer="cpu",reason="${reason}"}`, value: 1 },
  ];
  assert.deepEqual(autoRendererOf(counters), { renderer: 'cpu', reason });
  assert.equal(autoRendererOf(counters.slice(0, 1)), null, 'not decided yet');
  // Cut at 128 bytes by the protocol: the reason ends in an ellipsis.
  const cut = { name: `auto_renderer{renderer="gpu",reason="auto: gpu (GL_RENDERER '${'X'.repeat(200)}`.slice(0, 128), value: 1 };
  const got = autoRendererOf([cut]);
  assert.equal(got.renderer, 'gpu');
  assert.ok(got.reason.startsWith('auto: gpu (GL_RENDERER') && got.reason.endsWith('…'));
  assert.deepEqual(autoRendererOf([{ name: 'auto_renderer{renderer="cpu",reason="say \\"hi\\""}', value: 1 }]),
    { renderer: 'cpu', reason: 'say "hi"' });
});

test("a frame's scale, estimated PSNR and level for the overlay", () => {
  assert.equal(scaleLabel(1), 'full');
  assert.equal(scaleLabel(2), '1/2');
  assert.equal(scaleLabel(8), '1/8');
  assert.equal(scaleLabel(0), '', 'a server before 2026-12-06 does not say');
  assert.equal(psnrLabel(43), '≈ 43 dB');
  assert.equal(psnrLabel(50), '≈ 50 dB');
  assert.equal(psnrLabel(0), '—', 'no estimate');
  assert.equal(frameDetailLabel({ level: 1, scale: 3, estimatedPsnrDb: 0 }), 'level 1  scale 1/3  PSNR —');
  assert.equal(frameDetailLabel({ level: 0, scale: 1, estimatedPsnrDb: 41 }), 'level 0  scale full  PSNR ≈ 41 dB');
  assert.equal(frameDetailLabel({ level: 2, scale: 0, estimatedPsnrDb: 0 }), 'level 2  PSNR —', 'an older server: no scale');
});
