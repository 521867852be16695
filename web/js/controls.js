// Pointer, wheel and keyboard input on the view, turned into Trackball calls. Mouse: left-drag
// orbits, right- or shift-drag (or middle-drag) pans, wheel zooms, double-click resets.
// Touch: one finger orbits, two fingers pinch-zoom and pan. Keys: arrows orbit, + and - zoom.

const WHEEL_ZOOM_PER_PIXEL = 0.0015;
const KEY_ORBIT_DEG = 5;
const KEY_ZOOM = 0.9;
const LINE_PIXELS = 16;

/** Captures a pointer so a drag continues outside the element; a pointer the browser no longer tracks (released already, or synthetic) is left uncaptured. */
export function capture(el, pointerId) {
  try {
    el.setPointerCapture(pointerId);
  } catch {
    // NotFoundError: nothing to capture; the drag still works while the pointer stays inside.
  }
}

/**
 * Binds input on `el` to the trackball returned by getTrackball() (null while no volume is
 * open); calls onCamera(camera, inputTime) after every change, inputTime on the
 * performance.now() clock. Returns a function that unbinds everything.
 */
export function attachControls(el, getTrackball, onCamera) {
  const pointers = new Map(); // pointerId -> {x, y}
  let mode = null; // 'rotate' | 'pan' | 'pinch'
  let pinch = null;

  const local = (e) => {
    const r = el.getBoundingClientRect();
    return { x: e.clientX - r.left, y: e.clientY - r.top, width: r.width, height: r.height };
  };
  const changed = (cam, e) => onCamera(cam, e.timeStamp || performance.now());

  function startSingle(e, p) {
    const tb = getTrackball();
    if (!tb) return;
    const panning = e.pointerType === 'mouse' && (e.button === 2 || e.button === 1 || e.shiftKey);
    mode = panning ? 'pan' : 'rotate';
    if (mode === 'rotate') tb.beginRotate(p.x, p.y, p.width, p.height);
  }

  function startPinch() {
    const [a, b] = [...pointers.values()];
    getTrackball()?.end();
    mode = 'pinch';
    pinch = { distance: Math.hypot(a.x - b.x, a.y - b.y), mid: { x: (a.x + b.x) / 2, y: (a.y + b.y) / 2 } };
  }

  function onDown(e) {
    if (!getTrackball()) return;
    el.focus({ preventScroll: true });
    capture(el, e.pointerId);
    const p = local(e);
    pointers.set(e.pointerId, p);
    if (pointers.size === 1) startSingle(e, p);
    else if (pointers.size === 2) startPinch();
    e.preventDefault();
  }

  function onMove(e) {
    const prev = pointers.get(e.pointerId);
    const tb = getTrackball();
    if (!prev || !tb) return;
    const p = local(e);
    pointers.set(e.pointerId, p);
    if (mode === 'rotate') {
      changed(tb.rotateTo(p.x, p.y), e);
    } else if (mode === 'pan') {
      changed(tb.panBy(p.x - prev.x, p.y - prev.y, p.height), e);
    } else if (mode === 'pinch' && pointers.size >= 2) {
      const [a, b] = [...pointers.values()];
      const distance = Math.hypot(a.x - b.x, a.y - b.y);
      const mid = { x: (a.x + b.x) / 2, y: (a.y + b.y) / 2 };
      if (distance > 0 && pinch.distance > 0) tb.zoomBy(pinch.distance / distance);
      changed(tb.panBy(mid.x - pinch.mid.x, mid.y - pinch.mid.y, p.height), e);
      pinch = { distance, mid };
    }
  }

  function onUp(e) {
    if (!pointers.delete(e.pointerId)) return;
    const tb = getTrackball();
    tb?.end();
    if (pointers.size === 1 && tb) {
      // Lifting one finger of a pinch continues as a one-finger orbit from where it is.
      const [p] = pointers.values();
      mode = 'rotate';
      tb.beginRotate(p.x, p.y, p.width, p.height);
    } else if (pointers.size === 0) {
      mode = null;
    }
  }

  function onWheel(e) {
    const tb = getTrackball();
    if (!tb) return;
    e.preventDefault();
    const unit = e.deltaMode === 1 ? LINE_PIXELS : e.deltaMode === 2 ? el.clientHeight : 1;
    changed(tb.zoomBy(Math.exp(e.deltaY * unit * WHEEL_ZOOM_PER_PIXEL)), e);
  }

  function onDoubleClick(e) {
    const tb = getTrackball();
    if (tb) changed(tb.reset(), e);
  }

  function onKey(e) {
    const tb = getTrackball();
    if (!tb || e.altKey || e.ctrlKey || e.metaKey) return;
    const step = e.shiftKey ? KEY_ORBIT_DEG / 5 : KEY_ORBIT_DEG;
    let cam = null;
    switch (e.key) {
      case 'ArrowLeft': cam = tb.orbitBy(-step, 0); break;
      case 'ArrowRight': cam = tb.orbitBy(step, 0); break;
      case 'ArrowUp': cam = tb.orbitBy(0, step); break;
      case 'ArrowDown': cam = tb.orbitBy(0, -step); break;
      case '+': case '=': cam = tb.zoomBy(KEY_ZOOM); break;
      case '-': case '_': cam = tb.zoomBy(1 / KEY_ZOOM); break;
      default: return;
    }
    e.preventDefault();
    changed(cam, e);
  }

  const noMenu = (e) => e.preventDefault();
  const listeners = [
    ['pointerdown', onDown], ['pointermove', onMove], ['pointerup', onUp], ['pointercancel', onUp],
    ['wheel', onWheel, { passive: false }], ['dblclick', onDoubleClick], ['keydown', onKey],
    ['contextmenu', noMenu],
  ];
  for (const [type, fn, opts] of listeners) el.addEventListener(type, fn, opts);
  return () => { for (const [type, fn, opts] of listeners) el.removeEventListener(type, fn, opts); };
}
