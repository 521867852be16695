// Small pure helpers of the frame pipeline and the picker: frame size from the canvas,
// frame-rate and latency bookkeeping, and human-readable sizes.

import { MAX_IMAGE_EDGE, VOXEL_TYPE_NAMES } from './protocol.js';

const FPS_WINDOW_MS = 1000;

/** Frame size for a canvas of width × height device pixels: aspect kept, longest edge ≤ maxEdge (and ≤ 4096), each edge ≥ 1; {0, 0} for an empty canvas. */
export function frameSize(width, height, maxEdge) {
  if (!(width >= 1 && height >= 1)) return { width: 0, height: 0 };
  const cap = Math.min(MAX_IMAGE_EDGE, Math.max(1, Math.floor(maxEdge)));
  const s = Math.min(1, cap / Math.max(width, height));
  const edge = (v) => Math.min(cap, Math.max(1, Math.round(v * s)));
  return { width: edge(width), height: edge(height) };
}

/** Bytes as B, KiB, MiB or GiB with three significant digits. */
export function formatBytes(n) {
  const units = ['B', 'KiB', 'MiB', 'GiB', 'TiB'];
  let i = 0;
  while (n >= 1024 && i < units.length - 1) { n /= 1024; i += 1; }
  return i === 0 ? `${n} B` : `${n.toPrecision(3)} ${units[i]}`;
}

/** The picker's line for a VolumeInfo: name, dims, voxel type and stored size. */
export function volumeLabel(v) {
  return `${v.name} — ${v.dims.join('×')} ${VOXEL_TYPE_NAMES[v.voxelType] ?? '?'}, ${formatBytes(v.storedBytes)}`;
}

/** Frames drawn per second over the last second, and the latest input-to-screen latency. */
export class FrameStats {
  constructor() {
    this.times = [];
    this.latencyMs = null;
  }

  /** Records a frame drawn at `now` (ms); latencyMs is null for a frame that answers no new input. */
  frameDrawn(now, latencyMs) {
    this.times.push(now);
    this.trim(now);
    if (latencyMs !== null) this.latencyMs = latencyMs;
  }

  /** Frames drawn in the second before `now`. */
  fps(now) {
    this.trim(now);
    return this.times.length * 1000 / FPS_WINDOW_MS;
  }

  trim(now) {
    while (this.times.length && this.times[0] <= now - FPS_WINDOW_MS) this.times.shift();
  }
}

/**
 * Divisors of the edges of an interactive frame the server sends unscaled (RenderOptions flags
 * bit 0): 2 (half of each edge, rounded up) without a frame-time budget, any of them under one
 * (frames.interactive_ms, server/InteractiveBudget.h).
 */
export const INTERACTIVE_DIVISORS = Object.freeze([1, 2, 3, 4, 6, 8]);

/** Whether a frame of fw x fh is an interactive frame for options of width x height: each edge over one divisor, rounded up. */
export function isInteractiveSizeOf(fw, fh, width, height) {
  return INTERACTIVE_DIVISORS.some((d) => fw === Math.ceil(width / d) && fh === Math.ceil(height / d));
}

/**
 * A FrameHeader's scale for people: 'full' for 1, '1/n' for an interactive frame drawn at each
 * edge over n, '' for 0 (a server from before 2026-12-06 does not say).
 */
export function scaleLabel(scale) {
  if (!scale) return '';
  return scale === 1 ? 'full' : `1/${scale}`;
}

/** A FrameHeader's estimatedPsnrDb for people: '≈ 43 dB', or '—' when the server has no estimate (0). */
export function psnrLabel(db) {
  return db > 0 ? `≈ ${db} dB` : '—';
}

/**
 * The overlay's words for a frame's level, scale and estimated PSNR against the converged image
 * (its error: higher is closer): 'level 1  scale 1/2  PSNR ≈ 43 dB', 'level 0  scale full  PSNR —'.
 * A server from before 2026-12-06 sends scale 0 (the two bytes were reserved): no scale then.
 */
export function frameDetailLabel(f) {
  const scale = scaleLabel(f.scale);
  return [`level ${f.level}`, ...(scale ? [`scale ${scale}`] : []), `PSNR ${psnrLabel(f.estimatedPsnrDb)}`].join('  ');
}

const MIB = 1024 * 1024;

function mib(bytes) {
  const v = bytes / MIB;
  return v === 0 ? '0' : v < 10 ? v.toFixed(1) : v.toFixed(0);
}

function ratio(hits, misses) {
  const n = hits + misses;
  return n > 0 ? `${Math.round((100 * hits) / n)}%` : '—';
}

/**
 * The overlay's one residency line for volume `name` from a Stats reply's counters (those
 * labelled volume="NAME"): the host cache's resident and budget bytes and hit ratio, and the
 * GPU brick pool's hit ratio and budget where the server reports a pool for it. '' when the
 * server reports nothing for the volume.
 */
export function residencyLine(counters, name) {
  const label = `{volume=${JSON.stringify(name)}}`;
  const v = new Map();
  for (const c of counters) {
    if (c.name.endsWith(label)) v.set(c.name.slice(0, -label.length), c.value);
  }
  const parts = [];
  if (v.has('host_cache_resident_bytes')) {
    const budget = v.get('host_cache_budget_bytes');
    parts.push(`cache ${mib(v.get('host_cache_resident_bytes'))}${budget ? ` / ${mib(budget)}` : ''} MiB, ` +
      `hits ${ratio(v.get('host_cache_hits_total') ?? 0, v.get('host_cache_misses_total') ?? 0)}`);
  }
  if (v.has('gpu_pool_hits_total')) {
    const hits = v.get('gpu_pool_hits_total'), uploads = v.get('gpu_pool_uploads_total') ?? 0;
    const budget = v.get('gpu_pool_budget_bytes') ?? 0;
    if (hits + uploads > 0 || budget > 0) {
      parts.push(`GPU pool ${budget ? `${mib(budget)} MiB, ` : ''}hits ${ratio(hits, uploads)}`);
    }
  }
  return parts.join('  ');
}

/**
 * What the server's `auto` renderer draws with, from its Stats counters (the gauge
 * auto_renderer{renderer="cpu",reason="auto: cpu (GL_RENDERER '…' is a software rasteriser)"}):
 * {renderer, reason}, or null before the server has decided. The reason may be cut short: the
 * protocol cuts counter names at 128 bytes.
 */
export function autoRendererOf(counters) {
  const prefix = 'auto_renderer{renderer="';
  const c = counters.find(({ name }) => name.startsWith(prefix));
  if (!c) return null;
  const rest = c.name.slice(prefix.length);
  const end = rest.indexOf('"');
  if (end < 0) return null;
  const at = rest.indexOf('reason="', end);
  let reason = at < 0 ? '' : rest.slice(at + 'reason="'.length);
  reason = reason.endsWith('"}') ? reason.slice(0, -2) : `${reason}…`;
  return { renderer: rest.slice(0, end), reason: reason.replace(/\\(["\\])/g, '$1') };
}
