// The transfer-function editor: the volume's histogram (log scale) behind the opacity curve,
// draggable opacity points with a colour input each, presets from /presets.json, and the
// shading switch. It reports every change through onChange(tf) with tf in SetTransferFunction
// form; the page decides when to send (coalesced to one per animation frame). In the
// isosurface mode it also shows the iso value as a line on the histogram, dragged sideways to
// change it (reported through onIso(value)).

import { Placement } from './protocol.js';
import { capture } from './controls.js';
import { placePoints, evaluate, normalizePoint } from './tf.js';

const HIT_RADIUS = 9; // CSS pixels
const POINT_RADIUS = 5;
const COLOUR_BAR = 10; // CSS pixels at the bottom: the function's colour
const PAD = 8;
const ISO_COLOUR = '#f0b64a';
const ISO_LABEL_Y = 16; // CSS pixels below the plot's top: under the axis's end labels

/**
 * Opacity is drawn on a square-root axis: presets use opacities of 0.01..0.1 per voxel, which
 * a linear axis would squash into the bottom few pixels.
 */
const alphaToUnit = (a) => Math.sqrt(a);
const unitToAlpha = (u) => u * u;

const hexOf = (rgb) => '#' + rgb.slice(0, 3).map((v) => Math.round(Math.min(1, Math.max(0, v)) * 255).toString(16).padStart(2, '0')).join('');
const rgbOf = (hex) => [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16) / 255);

export class TfEditor {
  /**
   * An editor over the given elements: canvas, colour-input strip, preset select, shading
   * checkbox, readout (value/opacity inputs of the selection) and hint line. onChange(tf) on
   * every edit of the function; onIso(value) while the iso line is dragged (the value under
   * the pointer, within the volume's values), which the page answers with setIso.
   */
  constructor({ canvas, strip, presetSelect, shading, valueInput, alphaInput, hint, onChange, onIso = () => {} }) {
    Object.assign(this, { canvas, strip, presetSelect, shading, valueInput, alphaInput, hint, onChange, onIso });
    this.ctx = canvas.getContext('2d');
    this.presets = [];
    this.volume = null; // {valueMin, valueMax}
    this.histogram = null;
    this.histogramProblem = '';
    this.mode = { kind: 0, preset: null }; // what the server has: a preset by name, or points
    this.givenPoints = null; // kind 1 points as given (any placement), before the first edit
    this.points = []; // [{value, rgba}] sorted by value: what is drawn and edited
    this.selected = null;
    this.drag = null; // {id} dragging the selected point, {id, isoGrab} the iso line (grab: pointer x - line x)
    this.iso = null; // the iso value shown as a line, or null (not in the isosurface mode)
    this.bind();
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  /** Fills the preset list from /presets.json's array; the first preset is the default. */
  setPresets(presets) {
    this.presets = presets.filter((p) => p && typeof p.name === 'string' && Array.isArray(p.points));
    this.presetSelect.replaceChildren(...this.presets.map((p) => new Option(p.name, p.name)));
    this.presetSelect.append(new Option('custom (edited)', '', false, false));
    this.presetSelect.lastChild.disabled = true;
    this.presetSelect.disabled = this.presets.length === 0;
    for (const o of this.presetSelect.options) {
      const p = this.presets.find((q) => q.name === o.value);
      if (p?.description) o.title = p.description;
    }
    if (!this.mode.preset && this.mode.kind === 0 && this.presets.length) this.mode = { kind: 0, preset: this.presets[0].name };
    this.syncPresetSelect();
    this.replace();
  }

  /** A volume was opened: its value range becomes the x axis. keepEdits keeps edited points (a reconnect to the same volume). */
  setVolume(info, keepEdits) {
    this.volume = { valueMin: info.valueMin, valueMax: info.valueMax };
    this.histogram = null;
    this.histogramProblem = '';
    if (!keepEdits && this.mode.kind === 1) {
      // Value-placed points of another volume mean nothing here: back to a preset.
      this.mode = { kind: 0, preset: this.lastPreset ?? this.presets[0]?.name ?? null };
      this.givenPoints = null;
      this.syncPresetSelect();
    }
    this.replace();
  }

  /** The volume's histogram {valueMin, valueMax, counts}, or null with the reason it is missing. */
  setHistogram(hist, problem = '') {
    this.histogram = hist;
    this.histogramProblem = problem;
    this.replace();
  }

  /** Shows the iso value as a line on the histogram; null hides it. */
  setIso(value) {
    const v = Number.isFinite(value) ? value : null;
    if (v === this.iso) return;
    this.iso = v;
    this.draw();
  }

  /** Where the iso line is: {value, x} with x in CSS pixels from the canvas's left, or null while it is hidden. */
  isoMarker() {
    return this.iso === null || !this.volume ? null : { value: this.iso, x: this.xOf(this.iso) };
  }

  /** The transfer function in SetTransferFunction form, as the editor holds it (null before any preset or points). */
  current() {
    if (this.mode.kind === 0) {
      if (!this.mode.preset) return null;
      return this.mode.shadingFromUser
        ? { kind: 0, shading: this.shading.checked, shadingSource: 0, preset: this.mode.preset }
        : { kind: 0, shading: this.shading.checked, shadingSource: 1, preset: this.mode.preset };
    }
    const points = this.givenPoints ?? this.points.map((p) => ({ placement: Placement.Value, position: p.value, rgba: p.rgba.slice() }));
    return { kind: 1, shading: this.shading.checked, shadingSource: 0, points };
  }

  /** Shows and reports a preset by name (the server places its points); throws when the list lacks it. */
  choosePreset(name) {
    const p = this.presets.find((q) => q.name === name);
    if (!p) throw new Error(`no preset named '${name}' in /presets.json`);
    this.mode = { kind: 0, preset: name };
    this.lastPreset = name;
    this.givenPoints = null;
    if (typeof p.shading === 'boolean') this.shading.checked = p.shading;
    this.syncPresetSelect();
    this.replace();
    this.changed();
  }

  /** Shows and reports points given in protocol form or preset-file form, sent as given. */
  setPoints(points, shading) {
    if (!Array.isArray(points) || points.length === 0) throw new Error('points: expected a non-empty array');
    this.givenPoints = points.map(normalizePoint);
    this.mode = { kind: 1 };
    if (typeof shading === 'boolean') this.shading.checked = shading;
    this.syncPresetSelect();
    this.replace();
    this.changed();
  }

  // ---- internals ----

  changed() {
    const tf = this.current();
    if (tf) this.onChange(tf);
  }

  /** The user edited the points: from now on they go as value-placed points. */
  edited() {
    if (this.mode.kind !== 1 || this.givenPoints) {
      this.mode = { kind: 1 };
      this.givenPoints = null;
      this.syncPresetSelect();
    }
    this.points.sort((a, b) => a.value - b.value);
    if (!this.stripMatches()) this.renderStrip();
    this.draw();
    this.changed();
  }

  syncPresetSelect() {
    this.presetSelect.value = this.mode.kind === 0 && this.mode.preset ? this.mode.preset : '';
  }

  domain() {
    const lo = this.volume.valueMin;
    const hi = this.volume.valueMax > lo ? this.volume.valueMax : lo + 1; // as the server widens an empty range
    return [lo, hi];
  }

  /** Recomputes the drawn points from the mode: a preset or given points are placed here as the server places them; edited points stay. */
  replace() {
    this.selected = null;
    this.placeProblem = '';
    const src = this.mode.kind === 0 ? this.presets.find((p) => p.name === this.mode.preset)?.points : this.givenPoints;
    if (this.volume && src) {
      const [lo, hi] = this.domain();
      try {
        this.points = placePoints(src, lo, hi, this.histogram);
      } catch (e) {
        this.points = [];
        this.placeProblem = this.histogram || this.histogramProblem ? e.message : 'waiting for the histogram to place percentile points';
      }
    } else if (!this.volume || this.mode.kind === 0) {
      this.points = [];
    }
    this.renderStrip();
    this.updateReadout();
    this.draw();
  }

  editable() {
    return !!this.volume && this.points.length > 0;
  }

  // geometry: CSS pixels inside the canvas
  plot() {
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    return { x0: PAD, x1: w - PAD, y0: PAD, y1: h - PAD - COLOUR_BAR - 4, w, h };
  }
  xOf(value) {
    const [lo, hi] = this.domain();
    const g = this.plot();
    return g.x0 + (value - lo) / (hi - lo) * (g.x1 - g.x0);
  }
  valueOf(x) {
    const [lo, hi] = this.domain();
    const g = this.plot();
    return lo + Math.min(1, Math.max(0, (x - g.x0) / (g.x1 - g.x0))) * (hi - lo);
  }
  yOf(alpha) {
    const g = this.plot();
    return g.y1 - alphaToUnit(alpha) * (g.y1 - g.y0);
  }
  alphaOf(y) {
    const g = this.plot();
    return unitToAlpha(Math.min(1, Math.max(0, (g.y1 - y) / (g.y1 - g.y0))));
  }

  onIsoLine(x) {
    return this.iso !== null && !!this.volume && Math.abs(x - this.xOf(this.iso)) <= HIT_RADIUS;
  }

  hit(x, y) {
    let best = null, bestD = HIT_RADIUS;
    for (const p of this.points) {
      const d = Math.hypot(this.xOf(p.value) - x, this.yOf(p.rgba[3]) - y);
      if (d <= bestD) { best = p; bestD = d; }
    }
    return best;
  }

  bind() {
    const c = this.canvas;
    const at = (e) => { const r = c.getBoundingClientRect(); return [e.clientX - r.left, e.clientY - r.top]; };
    c.addEventListener('pointerdown', (e) => {
      if (!this.volume || e.button !== 0) return;
      const [x, y] = at(e);
      const point = this.editable() ? this.hit(x, y) : null;
      // A point on the line wins: points are small, the line is the plot's height.
      if (!point && this.onIsoLine(x)) {
        c.focus({ preventScroll: true });
        capture(c, e.pointerId);
        this.drag = { id: e.pointerId, isoGrab: x - this.xOf(this.iso) };
        return;
      }
      if (!this.editable()) return;
      c.focus({ preventScroll: true });
      this.select(point);
      if (this.selected) {
        capture(c, e.pointerId);
        this.drag = { id: e.pointerId };
      }
    });
    c.addEventListener('pointermove', (e) => {
      const [x, y] = at(e);
      if (!this.drag || this.drag.id !== e.pointerId) {
        c.style.cursor = this.editable() && this.hit(x, y) ? 'grab' : this.onIsoLine(x) ? 'ew-resize' : 'crosshair';
        return;
      }
      if (this.drag.isoGrab !== undefined) {
        this.onIso(this.valueOf(x - this.drag.isoGrab));
        return;
      }
      this.selected.value = this.valueOf(x);
      this.selected.rgba[3] = this.alphaOf(y);
      this.updateReadout();
      this.edited();
    });
    const end = (e) => { if (this.drag?.id === e.pointerId) this.drag = null; };
    c.addEventListener('pointerup', end);
    c.addEventListener('pointercancel', end);
    c.addEventListener('dblclick', (e) => {
      if (!this.editable()) return;
      const [x, y] = at(e);
      const onPoint = this.hit(x, y);
      if (onPoint) {
        this.colourInputOf(onPoint)?.click();
        return;
      }
      if (this.onIsoLine(x)) return; // a double-click while taking the iso line adds no point
      const value = this.valueOf(x);
      const rgb = evaluate(this.points, value).slice(0, 3);
      const p = { value, rgba: [...rgb, this.alphaOf(y)] };
      this.points.push(p);
      this.selected = p;
      this.edited();
      this.updateReadout();
    });
    c.addEventListener('contextmenu', (e) => {
      e.preventDefault();
      if (!this.editable()) return;
      const [x, y] = at(e);
      this.remove(this.hit(x, y));
    });
    c.addEventListener('keydown', (e) => {
      if ((e.key === 'Delete' || e.key === 'Backspace') && this.selected) {
        e.preventDefault();
        this.remove(this.selected);
      }
    });
    this.presetSelect.addEventListener('change', () => {
      if (this.presetSelect.value) this.choosePreset(this.presetSelect.value);
    });
    this.shading.addEventListener('change', () => {
      if (this.mode.kind === 0) this.mode.shadingFromUser = true;
      this.changed();
    });
    const readout = () => {
      if (!this.selected) return;
      const v = Number(this.valueInput.value), a = Number(this.alphaInput.value);
      const [lo, hi] = this.domain();
      if (Number.isFinite(v)) this.selected.value = Math.min(hi, Math.max(lo, v));
      if (Number.isFinite(a)) this.selected.rgba[3] = Math.min(1, Math.max(0, a));
      this.edited();
    };
    this.valueInput.addEventListener('change', readout);
    this.alphaInput.addEventListener('change', readout);
  }

  select(p) {
    this.selected = p;
    this.updateReadout();
    this.draw();
  }

  remove(p) {
    // The protocol needs at least one point.
    if (!p || this.points.length <= 1) return;
    this.points.splice(this.points.indexOf(p), 1);
    if (this.selected === p) this.selected = null;
    this.updateReadout();
    this.edited();
  }

  updateReadout() {
    const p = this.selected;
    this.valueInput.disabled = this.alphaInput.disabled = !p;
    this.valueInput.value = p ? formatValue(p.value) : '';
    this.alphaInput.value = p ? p.rgba[3].toFixed(4) : '';
  }

  colourInputOf(p) {
    return [...this.strip.children].find((el) => el.point === p);
  }

  /** One colour input per point, under its x position. */
  renderStrip() {
    const inputs = this.points.map((p) => {
      const input = document.createElement('input');
      input.type = 'color';
      input.value = hexOf(p.rgba);
      input.title = `colour at ${formatValue(p.value)}`;
      input.point = p;
      input.className = p === this.selected ? 'selected' : '';
      input.style.left = `${this.volume ? this.xOf(p.value) : 0}px`;
      input.addEventListener('focus', () => { if (this.selected !== p) this.select(p); });
      input.addEventListener('input', () => {
        p.rgba.splice(0, 3, ...rgbOf(input.value));
        this.edited();
      });
      return input;
    });
    this.strip.replaceChildren(...inputs);
  }

  stripMatches() {
    const inputs = [...this.strip.children];
    return inputs.length === this.points.length && inputs.every((el) => this.points.includes(el.point));
  }

  /** Repositions the colour inputs without rebuilding them (a rebuilt input would close an open picker). */
  placeStrip() {
    for (const input of this.strip.children) {
      input.style.left = `${this.xOf(input.point.value)}px`;
      input.className = input.point === this.selected ? 'selected' : '';
    }
  }

  draw() {
    const c = this.canvas, ctx = this.ctx;
    const dpr = globalThis.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(c.clientWidth * dpr)), h = Math.max(1, Math.round(c.clientHeight * dpr));
    if (c.width !== w || c.height !== h) { c.width = w; c.height = h; }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    const g = this.plot();
    ctx.fillStyle = '#15171a';
    ctx.fillRect(0, 0, g.w, g.h);
    const styles = getComputedStyle(c);
    ctx.font = `11px ${styles.fontFamily}`;
    if (!this.volume) {
      this.label('open a volume to edit its transfer function', g);
      this.hint.textContent = '';
      return;
    }
    this.drawHistogram(g);
    this.drawFunction(g);
    if (this.stripMatches()) this.placeStrip();
    const [lo, hi] = this.domain();
    ctx.fillStyle = '#8a9099';
    ctx.textBaseline = 'top';
    ctx.textAlign = 'left';
    ctx.fillText(formatValue(lo), g.x0, g.y0);
    ctx.textAlign = 'right';
    ctx.fillText(formatValue(hi), g.x1, g.y0);
    this.drawIso(g);
    this.hint.textContent = this.placeProblem || (this.histogram ? '' : this.histogramProblem || 'waiting for the histogram…');
  }

  label(text, g) {
    const ctx = this.ctx;
    ctx.fillStyle = '#8a9099';
    ctx.textAlign = 'center';
    ctx.textBaseline = 'middle';
    ctx.fillText(text, g.w / 2, g.h / 2);
  }

  drawHistogram(g) {
    const hist = this.histogram;
    if (!hist) return;
    const ctx = this.ctx;
    const n = hist.counts.length;
    let max = 0;
    for (const c of hist.counts) max = Math.max(max, c);
    if (max === 0) return;
    const logMax = Math.log1p(max);
    const binWidth = (hist.valueMax - hist.valueMin) / n || 1;
    // One bar per pixel column, the largest bin it covers, so narrow peaks stay visible.
    const columns = Math.max(1, Math.round(g.x1 - g.x0));
    const heights = new Float64Array(columns);
    for (let i = 0; i < n; ++i) {
      if (!hist.counts[i]) continue;
      const a = Math.floor(this.xOf(hist.valueMin + i * binWidth) - g.x0);
      const b = Math.max(a, Math.ceil(this.xOf(hist.valueMin + (i + 1) * binWidth) - g.x0) - 1);
      const v = Math.log1p(hist.counts[i]) / logMax;
      for (let x = Math.max(0, a); x <= Math.min(columns - 1, b); ++x) heights[x] = Math.max(heights[x], v);
    }
    ctx.fillStyle = '#3a4049';
    for (let x = 0; x < columns; ++x) {
      if (!heights[x]) continue;
      const top = g.y1 - heights[x] * (g.y1 - g.y0);
      ctx.fillRect(g.x0 + x, top, 1, g.y1 - top);
    }
  }

  /** The iso value: a line across the plot, labelled with its value on the side with more room. */
  drawIso(g) {
    if (this.iso === null) return;
    const ctx = this.ctx;
    const x = this.xOf(this.iso);
    ctx.strokeStyle = ISO_COLOUR;
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.moveTo(x, g.y0);
    ctx.lineTo(x, g.y1);
    ctx.stroke();
    const text = `iso ${formatValue(this.iso)}`;
    const left = x > (g.x0 + g.x1) / 2;
    const width = ctx.measureText(text).width;
    const tx = left ? x - 4 - width : x + 4;
    ctx.fillStyle = 'rgba(21, 23, 26, 0.8)';
    ctx.fillRect(tx - 2, g.y0 + ISO_LABEL_Y - 1, width + 4, 14);
    ctx.fillStyle = ISO_COLOUR;
    ctx.textAlign = 'left';
    ctx.textBaseline = 'top';
    ctx.fillText(text, tx, g.y0 + ISO_LABEL_Y);
  }

  drawFunction(g) {
    const ctx = this.ctx;
    const pts = this.points;
    if (pts.length === 0) return;
    const columns = Math.max(1, Math.round(g.x1 - g.x0));
    // colour bar and a tinted fill under the opacity curve
    for (let x = 0; x < columns; x += 1) {
      const rgba = evaluate(pts, this.valueOf(g.x0 + x + 0.5));
      const rgb = rgba.slice(0, 3).map((v) => Math.round(v * 255)).join(',');
      ctx.fillStyle = `rgb(${rgb})`;
      ctx.fillRect(g.x0 + x, g.h - PAD - COLOUR_BAR, 1, COLOUR_BAR);
      const top = this.yOf(rgba[3]);
      ctx.fillStyle = `rgba(${rgb},0.35)`;
      ctx.fillRect(g.x0 + x, top, 1, g.y1 - top);
    }
    ctx.strokeStyle = '#e8eaed';
    ctx.lineWidth = 1.25;
    ctx.beginPath();
    ctx.moveTo(g.x0, this.yOf(pts[0].rgba[3]));
    for (const p of pts) ctx.lineTo(this.xOf(p.value), this.yOf(p.rgba[3]));
    ctx.lineTo(g.x1, this.yOf(pts[pts.length - 1].rgba[3]));
    ctx.stroke();
    for (const p of pts) {
      ctx.beginPath();
      ctx.arc(this.xOf(p.value), this.yOf(p.rgba[3]), p === this.selected ? POINT_RADIUS + 2 : POINT_RADIUS, 0, 2 * Math.PI);
      ctx.fillStyle = hexOf(p.rgba);
      ctx.fill();
      ctx.strokeStyle = p === this.selected ? '#4da3ff' : '#e8eaed';
      ctx.lineWidth = p === this.selected ? 2 : 1.25;
      ctx.stroke();
    }
  }
}

/** A value for labels: integers as such, others to 4 significant digits. */
export function formatValue(v) {
  return Number.isInteger(v) ? String(v) : Number(v.toPrecision(4)).toString();
}
