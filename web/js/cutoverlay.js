// The cut overlay: the crop box and the clip plane drawn over the view in an SVG the size of
// the canvas (index.html #cut-overlay), projected with the camera of the frame shown, with a
// handle on each crop face and on the plane that drags it along its axis. The geometry is
// cutgeometry.js's; the page owns the controls' state and hears of a drag through onDrag, as it
// hears of its sliders. Only the handles take the pointer (style.css): elsewhere the view's own
// input (controls.js) works, and the wheel over a handle is passed on to the canvas.

import { capture } from './controls.js';
import { clipLabel, cropLabels, extentMm } from './modes.js';
import { cutOverlayOf, dragFraction, screenOf } from './cutgeometry.js';

const SVG_NS = 'http://www.w3.org/2000/svg';
const HANDLE_NAMES = ['x-low', 'x-high', 'y-low', 'y-high', 'z-low', 'z-high', 'clip'];
const LABEL_OFFSET = 12; // CSS pixels from the dragged handle's centre

const fixed = (v) => v.toFixed(2);
const pathOf = (segments) => segments.map((s) => `M${s.slice(0, 2).map(fixed)}L${s.slice(2).map(fixed)}`).join('');

export class CutOverlay {
  /**
   * An overlay in `svg` (#cut-overlay, holding #crop-edges, #clip-fill, #clip-outline,
   * #clip-arrow, #cut-handles and #cut-label) laid over `canvas`. canDrag() says whether a
   * handle may be grabbed now; onDrag({name, axis, side, fraction}) while one is dragged: the
   * handle ('x-low' .. 'z-high', or 'clip'), its axis (0 x .. 2 z), the crop face's side ('low'
   * or 'high'; 'high' for the plane) and the fraction 0..1 of the extent it is dragged to. The
   * page answers by changing its cut and calling update.
   */
  constructor({ svg, canvas, canDrag = () => true, onDrag }) {
    Object.assign(this, { svg, canvas, canDrag, onDrag });
    const part = (id) => svg.querySelector(`#${id}`);
    this.parts = {
      edges: part('crop-edges'), fill: part('clip-fill'), outline: part('clip-outline'),
      arrow: part('clip-arrow'), handles: part('cut-handles'), label: part('cut-label'),
    };
    this.handleEls = new Map(HANDLE_NAMES.map((name) => [name, this.makeHandle(name)]));
    this.frame = null;
    this.volume = null;
    this.cut = null;
    this.shown = null; // {screen, handles} as last drawn: what a drag starts from
    this.drag = null; // the handle being dragged: {name, side, axis, point, screen, pointerId, x, y, fraction}
    this.bind();
  }

  /**
   * Draws the crop box (when the cut's cropping is on) and the clip plane's outline (when it is
   * on) for `volume`, projected with the camera and size of `frame`, the frame shown ({camera:
   * its SetCamera, width, height}). Hidden while frame or volume is null or nothing is cut.
   */
  update(frame, volume, cut) {
    this.frame = frame;
    this.volume = volume;
    this.cut = cut;
    const on = !!volume && !!frame && (cut.cropped || cut.clip);
    this.svg.toggleAttribute('hidden', !on);
    if (!on) {
      this.shown = null;
      return;
    }
    const el = this.canvas;
    const width = el.clientWidth, height = el.clientHeight;
    Object.assign(this.svg.style, { left: `${el.offsetLeft}px`, top: `${el.offsetTop}px`, width: `${width}px`, height: `${height}px` });
    this.svg.setAttribute('viewBox', `0 0 ${width} ${height}`);
    const screen = screenOf(frame.camera, frame.width, frame.height, width, height);
    const o = cutOverlayOf(volume, cut, screen);
    this.drawLines(o);
    this.drawHandles(o.handles);
    this.drawLabel(o.handles, width);
    this.shown = { screen, handles: o.handles };
  }

  /**
   * The overlay as drawn: {handles: [{name, x, y (CSS px from the view's top left), mm (the
   * handle's position on its axis)}], edges (the number of the crop box's segments drawn)}, or
   * null while it is hidden.
   */
  drawn() {
    if (!this.shown) return null;
    const edges = (this.parts.edges.getAttribute('d') || '').split('M').length - 1;
    return { handles: this.shown.handles.map(({ name, x, y, mm }) => ({ name, x, y, mm })), edges };
  }

  makeHandle(name) {
    const el = document.createElementNS(SVG_NS, 'circle');
    el.dataset.handle = name;
    el.setAttribute('class', `cut-handle ${name === 'clip' ? 'clip' : `axis-${name[0]}`}`);
    el.setAttribute('r', name === 'clip' ? '7' : '6');
    el.append(document.createElementNS(SVG_NS, 'title'));
    this.parts.handles.append(el);
    return el;
  }

  /** What a handle's drag moves, in the controls' words: an axis of the crop box in mm, or what the plane keeps. */
  handleLabel(name) {
    const c = this.cut, v = this.volume;
    if (name === 'clip') return `clip plane: ${clipLabel(v, c.axis, c.position)}`;
    const a = 'xyz'.indexOf(name[0]);
    return `crop ${name[0]} ${cropLabels(v, c.low, c.high)[a]}`;
  }

  drawLines(o) {
    const { edges, fill, outline, arrow } = this.parts;
    edges.setAttribute('d', pathOf(o.edges));
    outline.setAttribute('d', o.clip ? pathOf(o.clip.outline) : '');
    fill.setAttribute('points', o.clip?.polygon ? o.clip.polygon.map((p) => p.map(fixed).join(',')).join(' ') : '');
    arrow.toggleAttribute('hidden', !o.clip?.arrow);
    if (o.clip?.arrow) ['x1', 'y1', 'x2', 'y2'].forEach((k, i) => arrow.setAttribute(k, fixed(o.clip.arrow[i])));
  }

  drawHandles(handles) {
    for (const [name, el] of this.handleEls) {
      const h = handles.find((q) => q.name === name);
      el.toggleAttribute('hidden', !h);
      if (!h) continue;
      el.setAttribute('cx', fixed(h.x));
      el.setAttribute('cy', fixed(h.y));
      el.firstChild.textContent = `${this.handleLabel(name)} — drag to move it along ${name[0] === 'c' ? this.cut.axis.slice(1) : name[0]}`;
    }
  }

  /** The dragged handle's label, beside it on the side towards the view's middle. */
  drawLabel(handles, width) {
    const label = this.parts.label;
    const dragged = this.drag && handles.find((q) => q.name === this.drag.name);
    label.toggleAttribute('hidden', !dragged);
    if (!dragged) return;
    label.textContent = this.handleLabel(dragged.name);
    const right = dragged.x < width / 2;
    label.setAttribute('x', fixed(dragged.x + (right ? LABEL_OFFSET : -LABEL_OFFSET)));
    label.setAttribute('y', fixed(dragged.y - LABEL_OFFSET));
    label.setAttribute('text-anchor', right ? 'start' : 'end');
  }

  /** Redraws as last updated: a drag's start and end show or hide its label. */
  redraw() {
    this.update(this.frame, this.volume, this.cut);
  }

  bind() {
    const svg = this.svg;
    svg.addEventListener('pointerdown', (e) => this.onPointerDown(e));
    svg.addEventListener('pointermove', (e) => this.onPointerMove(e));
    for (const type of ['pointerup', 'pointercancel']) {
      svg.addEventListener(type, (e) => {
        if (this.drag?.pointerId !== e.pointerId) return;
        this.drag = null;
        this.redraw();
      });
    }
    // The wheel over a handle still zooms the view.
    svg.addEventListener('wheel', (e) => {
      e.preventDefault();
      this.canvas.dispatchEvent(new WheelEvent(e.type, e));
    }, { passive: false });
  }

  onPointerDown(e) {
    const name = e.target.dataset?.handle;
    const h = name && this.shown?.handles.find((q) => q.name === name);
    if (!h || e.button !== 0 || !this.canDrag()) return;
    e.preventDefault();
    capture(e.target, e.pointerId);
    const c = this.cut, side = name.endsWith('low') ? 'low' : 'high';
    this.drag = {
      name, side, axis: h.axis, point: h.point, screen: this.shown.screen, pointerId: e.pointerId,
      x: e.clientX, y: e.clientY, fraction: name === 'clip' ? c.position : c[side][h.axis],
    };
    this.redraw();
  }

  onPointerMove(e) {
    const d = this.drag;
    if (!d || d.pointerId !== e.pointerId || !this.volume) return;
    // Path-independent: from the handle's place and the screen at the drag's start.
    const fraction = dragFraction(d.screen, d.point, d.axis, extentMm(this.volume)[d.axis], d.fraction, e.clientX - d.x, e.clientY - d.y);
    this.onDrag({ name: d.name, axis: d.axis, side: d.side, fraction });
  }
}
