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
