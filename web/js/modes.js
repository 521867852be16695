// The "Mode and cut" controls' arithmetic, no DOM: the SetModeAndClip the controls say, from
// fractions of the open volume's extent (its box is [0, dims[a] × spacingMm[a]] mm on each
// axis a) and the iso value's range and step (the volume's [valueMin, valueMax]). The cut
// overlay's geometry is in cutgeometry.js.

import { Mode } from './protocol.js';

/** The clip plane's axes: the normal's direction, the side of the position that is kept. */
export const CLIP_AXES = Object.freeze(['+x', '-x', '+y', '-y', '+z', '-z']);
/** The crop sliders' step: low stays at least this far below high. */
export const CROP_STEP = 0.001;
/** The modes that draw no surface, as the mode select names them. */
const SURFACELESS_MODES = Object.freeze({ [Mode.Maximum]: 'MIP', [Mode.Minimum]: 'MinIP', [Mode.Average]: 'the average' });
/** The iso slider has about this many steps across the volume's value range. */
const ISO_STEPS = 1000;

const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));

/** The volume's extent in world mm on each axis: dims[a] × spacingMm[a]. */
export function extentMm(volume) {
  return [0, 1, 2].map((a) => volume.dims[a] * volume.spacingMm[a]);
}

/**
 * One axis of the crop box as fractions 0..1 of the extent, put in order: low at least
 * CROP_STEP below high. The one the user moved (`moved` 'low' or 'high') gives way: it stops
 * CROP_STEP short of the other, which stays. Returns {low, high}.
 */
export function orderCropRange(low, high, moved = 'high') {
  let lo = clamp(Number.isFinite(low) ? low : 0, 0, 1 - CROP_STEP);
  let hi = clamp(Number.isFinite(high) ? high : 1, CROP_STEP, 1);
  if (!(lo < hi - CROP_STEP / 2)) {
    if (moved === 'low') lo = hi - CROP_STEP;
    else hi = lo + CROP_STEP;
  }
  return { low: lo, high: hi };
}

/** The crop box in world mm of per-axis fractions low[3] and high[3] (each pair put in order): {min: [3], max: [3]}, min < max. */
export function cropBoxMm(volume, low, high) {
  const e = extentMm(volume);
  const min = [], max = [];
  for (let a = 0; a < 3; ++a) {
    const r = orderCropRange(low[a], high[a]);
    min.push(r.low * e[a]);
    max.push(r.high * e[a]);
  }
  return { min, max };
}

/**
 * The clip plane of an axis of CLIP_AXES ('+x' .. '-z') at `fraction` 0..1 of the extent along
 * it: the normal is the unit axis with the sign, the offset -(sign × position in mm), so that the
 * side the normal points to is kept ('+x' at 40 mm: normal (1, 0, 0), offset -40, keeps x >= 40;
 * '-x' there: normal (-1, 0, 0), offset 40, keeps x <= 40). Returns {normal: [3], offset}.
 */
export function clipPlaneOf(volume, axis, fraction) {
  const a = 'xyz'.indexOf(axis?.[1]);
  if (!CLIP_AXES.includes(axis) || a < 0) throw new RangeError(`clip axis '${axis}' is not one of ${CLIP_AXES.join(' ')}`);
  const sign = axis[0] === '-' ? -1 : 1;
  const mm = clamp(Number.isFinite(fraction) ? fraction : 0, 0, 1) * extentMm(volume)[a];
  const normal = [0, 0, 0];
  normal[a] = sign;
  // + 0: no -0 on the wire for a plane at 0 mm.
  return { normal, offset: -sign * mm + 0 };
}

/**
 * The iso value controls' range over the volume's values: {min, max, step, middle}; step is the
 * power of ten that makes ISO_STEPS to 10 × ISO_STEPS steps across the range (1 for 0..4095,
 * 0.001 for 0..1), or 'any' for a volume of one value.
 */
export function isoRangeOf(volume) {
  const min = volume.valueMin, max = volume.valueMax;
  const span = max - min;
  const step = span > 0 && Number.isFinite(span) ? 10 ** Math.floor(Math.log10(span / ISO_STEPS) + 1e-9) : 'any';
  return { min, max, step, middle: (min + max) / 2 };
}

/** An iso value kept within the volume's [valueMin, valueMax]; the middle for one that is not a finite number. */
export function clampIso(volume, v) {
  const r = isoRangeOf(volume);
  return Number.isFinite(v) ? clamp(v, r.min, r.max) : r.middle;
}

/**
 * What the controls show on opening a volume: composite, the iso value in the middle of the
 * volume's values, no crop (the sliders at 0 and 1), no clip plane ('+x' at the middle), the
 * cut faces not capped.
 */
export function defaultCut(volume) {
  return {
    mode: Mode.Composite, isoValue: isoRangeOf(volume).middle,
    cropped: false, low: [0, 0, 0], high: [1, 1, 1],
    clip: false, axis: '+x', position: 0.5, cap: false,
  };
}

/**
 * Why the controls' state `cut` can have no cap, or '' where it can: the maximum, minimum and
 * average draw no surface (the server refuses a cap with them); with nothing cropped or clipped
 * there is no cut face.
 */
export function whyNoCap(cut) {
  if (cut.mode !== Mode.Composite && cut.mode !== Mode.Isosurface)
    return `${SURFACELESS_MODES[cut.mode] ?? `mode ${cut.mode}`} draws no surface to cap (composite and isosurface only)`;
  if (!cut.cropped && !cut.clip) return 'nothing is cut: crop or clip first';
  return '';
}

/**
 * The SetModeAndClip body of the controls' state `cut` (defaultCut's shape) for `volume`: the
 * iso value (kept within the volume's values) in the isosurface mode only, 0 in the others;
 * the crop box in mm when cropped; the one clip plane when on; cap only where whyNoCap has
 * nothing against it (else false).
 */
export function modeAndClipOf(volume, cut) {
  return {
    mode: cut.mode,
    isoValue: cut.mode === Mode.Isosurface ? clampIso(volume, cut.isoValue) : 0,
    crop: cut.cropped ? cropBoxMm(volume, cut.low, cut.high) : null,
    planes: cut.clip ? [clipPlaneOf(volume, cut.axis, cut.position)] : [],
    cap: cut.cap === true && whyNoCap(cut) === '',
  };
}

/**
 * An iso value as the slider holds it: on its step from the volume's valueMin (isoRangeOf),
 * within [valueMin, valueMax]; what a drag on the histogram's marker sets.
 */
export function snapIso(volume, v) {
  const r = isoRangeOf(volume);
  const c = clampIso(volume, v);
  if (r.step === 'any') return c;
  const k = Math.min(Math.round((c - r.min) / r.step), Math.floor((r.max - r.min) / r.step + 1e-9));
  // toPrecision: no 0.30000000000000004 from the multiplication.
  return Number((r.min + k * r.step).toPrecision(12));
}

/** Millimetres as the controls show them: at most one decimal (64, 112.5). */
export function formatMm(v) {
  return String(Math.round(v * 10) / 10 + 0);
}

/** The crop controls' label of each axis: its box in mm, e.g. '64–192 mm'. */
export function cropLabels(volume, low, high) {
  const { min, max } = cropBoxMm(volume, low, high);
  return [0, 1, 2].map((a) => `${formatMm(min[a])}–${formatMm(max[a])} mm`);
}

/** The clip controls' label: what the plane keeps, e.g. 'x ≥ 40 mm' for '+x', 'x ≤ 40 mm' for '-x'. */
export function clipLabel(volume, axis, fraction) {
  const { normal, offset } = clipPlaneOf(volume, axis, fraction);
  const a = normal.findIndex((n) => n !== 0);
  return `${'xyz'[a]} ${normal[a] > 0 ? '≥' : '≤'} ${formatMm(normal[a] > 0 ? -offset : offset)} mm`;
}
