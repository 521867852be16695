// Transfer-function math shared by the editor and the page's test API: placing points the way
// the server does (configs/tf/README.md, render/TransferFunction.cpp) so a preset is shown
// where the server puts it, and evaluating the piecewise-linear function for drawing.

import { Placement } from './protocol.js';

/**
 * Native value at `percent` (0..100) of the voxels above the histogram's most populated bin
 * (all voxels when none lie above it), linear inside a bin; as VolumeValueStats::percentile.
 * Throws when the histogram holds no voxel.
 */
export function percentileValue(hist, percent) {
  const { valueMin, valueMax, counts } = hist;
  let mode = 0;
  for (let i = 1; i < counts.length; ++i) if (counts[i] > counts[mode]) mode = i;
  let first = mode + 1;
  let total = 0;
  for (let i = first; i < counts.length; ++i) total += counts[i];
  if (total === 0) {
    first = 0;
    for (const c of counts) total += c;
  }
  if (total === 0) throw new Error('the volume\'s histogram holds no voxel');
  const binWidth = (valueMax - valueMin) / counts.length;
  const target = percent / 100 * total;
  let below = 0;
  for (let i = first; i < counts.length; ++i) {
    const count = counts[i];
    if (count === 0) continue;
    if (below + count >= target) return Math.min(valueMax, valueMin + (i + (target - below) / count) * binWidth);
    below += count;
  }
  return valueMax;
}

/**
 * A point in protocol form {placement, position, rgba} from either that form or the
 * preset-file form {value|fraction|percentile, rgba}; throws on anything else.
 */
export function normalizePoint(p) {
  if (!p || !Array.isArray(p.rgba) || p.rgba.length !== 4) throw new Error('a point needs rgba: [r, g, b, a]');
  if (Number.isInteger(p.placement) && typeof p.position === 'number')
    return { placement: p.placement, position: p.position, rgba: p.rgba.map(Number) };
  const keys = ['value', 'fraction', 'percentile'].filter((k) => typeof p[k] === 'number');
  if (keys.length !== 1) throw new Error('a point needs exactly one of value, fraction, percentile (or placement and position)');
  const placement = { value: Placement.Value, fraction: Placement.Fraction, percentile: Placement.Percentile }[keys[0]];
  return { placement, position: p[keys[0]], rgba: p.rgba.map(Number) };
}

/** Native value of a protocol-form point for a volume's range and histogram (null histogram: percentiles throw). */
export function placeValue(point, valueMin, valueMax, hist) {
  switch (point.placement) {
    case Placement.Value: return point.position;
    case Placement.Fraction: return valueMin + point.position * (valueMax - valueMin);
    case Placement.Percentile:
      if (!hist) throw new Error('percentile placement needs the volume\'s histogram');
      return percentileValue(hist, point.position);
    default: throw new Error(`placement ${point.placement} unknown`);
  }
}

/** Points {value, rgba} placed and sorted by value, stably (the server's order, which makes steps). */
export function placePoints(points, valueMin, valueMax, hist) {
  return points
    .map((p, i) => ({ value: placeValue(normalizePoint(p), valueMin, valueMax, hist), rgba: p.rgba.slice(), i }))
    .sort((a, b) => a.value - b.value || a.i - b.i)
    .map(({ value, rgba }) => ({ value, rgba }));
}

/** RGBA of sorted points at x: linear between points, the end point's RGBA beyond the ends, the later point at a step. */
export function evaluate(points, x) {
  if (points.length === 0) return [0, 0, 0, 0];
  if (x < points[0].value) return points[0].rgba.slice();
  for (let i = points.length - 1; i >= 0; --i) {
    if (points[i].value <= x) {
      const a = points[i], b = points[i + 1];
      if (!b || b.value === a.value) return a.rgba.slice();
      const t = (x - a.value) / (b.value - a.value);
      return a.rgba.map((v, c) => v + (b.rgba[c] - v) * t);
    }
  }
  return points[points.length - 1].rgba.slice();
}
