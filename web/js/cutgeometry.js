// The cut overlay's geometry, no DOM: the crop box and the clip plane of the "Mode and cut"
// controls projected onto the view as the server casts its rays (render/Camera.h ViewBasis),
// their handles, and where dragging a handle along its axis moves it. Points are world mm (the
// volume's box is [0, dims × spacingMm] mm); screen points are pixels from the view's top left.

import { clipPlaneOf, cropBoxMm, extentMm } from './modes.js';
import { add, cross, dot, length, normalize, scale, sub } from './trackball.js';

/** A handle whose axis spans fewer screen pixels than this across the volume does not move: the axis points (nearly) at the viewer. */
export const MIN_AXIS_PIXELS = 4;
/** The clip plane's normal arrow on the view: this fraction of the volume's largest extent. */
const CLIP_ARROW_FRACTION = 0.15;

const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));

/**
 * The screen of a frame: the camera's view basis as the server builds it for a frameWidth ×
 * frameHeight image (render/Camera.cpp ViewBasis: right = forward × up, the half height
 * tan(fovY / 2) or orthoHeight / 2, the half width that × the frame's aspect), shown on an
 * element width × height pixels (the frame stretched over it; by default the frame's size).
 */
export function screenOf(camera, frameWidth, frameHeight, width = frameWidth, height = frameHeight) {
  const forward = normalize(sub(camera.target, camera.eye));
  const right = normalize(cross(forward, camera.up));
  const halfH = camera.orthographic ? 0.5 * camera.orthoHeight : Math.tan((0.5 * camera.fovYDeg * Math.PI) / 180);
  return {
    eye: camera.eye.slice(), forward, right, up: cross(right, forward), orthographic: !!camera.orthographic,
    halfW: halfH * (frameWidth / frameHeight), halfH, width, height,
    // Lines are cut this far in front of the eye: nothing behind it is projected.
    near: 1e-3 * length(sub(camera.target, camera.eye)),
  };
}

/**
 * Where a world point (mm) is on the screen: {x, y} pixels from the element's top left (the
 * server's pixel (i, j) is the square [i, i + 1] × [j, j + 1]) and its depth along the view
 * (mm); null for a point at or behind the eye of a perspective camera.
 */
export function project(screen, p) {
  const d = sub(p, screen.eye);
  const depth = dot(d, screen.forward);
  if (!screen.orthographic && !(depth > 0)) return null;
  const z = screen.orthographic ? 1 : depth;
  const sx = dot(d, screen.right) / (z * screen.halfW), sy = dot(d, screen.up) / (z * screen.halfH);
  return { x: ((sx + 1) / 2) * screen.width, y: ((1 - sy) / 2) * screen.height, depth };
}

/** A world segment cut to the part in front of the near plane, projected: [x0, y0, x1, y1], or null when none is. */
export function projectSegment(screen, a, b) {
  if (!screen.orthographic) {
    const da = dot(sub(a, screen.eye), screen.forward) - screen.near;
    const db = dot(sub(b, screen.eye), screen.forward) - screen.near;
    if (da < 0 && db < 0) return null;
    if (da < 0) a = add(a, scale(sub(b, a), da / (da - db)));
    else if (db < 0) b = add(b, scale(sub(a, b), db / (db - da)));
  }
  const p = project(screen, a), q = project(screen, b);
  return p && q ? [p.x, p.y, q.x, q.y] : null;
}

/** The 8 corners of a box {min, max}: corner i takes max on axis a where bit a of i is set. */
export function boxCorners(box) {
  return [0, 1, 2, 3, 4, 5, 6, 7].map((i) => [0, 1, 2].map((a) => (i & (1 << a) ? box.max[a] : box.min[a])));
}

/** The 12 edges of a box as pairs of corner indices (boxCorners). */
export const BOX_EDGES = Object.freeze([0, 1, 2, 3, 4, 5, 6, 7].flatMap((i) =>
  [0, 1, 2].filter((a) => !(i & (1 << a))).map((a) => Object.freeze([i, i | (1 << a)]))));

/** The centre of each face of a box: [{axis, side ('low' | 'high'), point}], x low first, z high last. */
export function faceHandles(box) {
  const centre = [0, 1, 2].map((a) => (box.min[a] + box.max[a]) / 2);
  return [0, 1, 2].flatMap((axis) => ['low', 'high'].map((side) => {
    const point = centre.slice();
    point[axis] = side === 'low' ? box.min[axis] : box.max[axis];
    return { axis, side, point };
  }));
}

/** Screen pixels per mm along world axis `axis` (0 x .. 2 z) at world point p: [dx, dy], the projection's derivative there. */
export function screenAxis(screen, p, axis) {
  const d = sub(p, screen.eye);
  const z = screen.orthographic ? 1 : dot(d, screen.forward);
  // d/dt of dot(d + t e, r) / z(t) with e the unit axis: (e·r z - d·r e·forward) / z².
  const dz = screen.orthographic ? 0 : screen.forward[axis];
  const rate = (v) => (v[axis] * z - dot(d, v) * dz) / (z * z);
  return [(rate(screen.right) / screen.halfW) * (screen.width / 2), (-rate(screen.up) / screen.halfH) * (screen.height / 2)];
}

/**
 * The fraction of the extent (0..1) a handle on world axis `axis` at world point `point` moves
 * to when dragged by (dx, dy) pixels from `fraction`: the drag projected onto the axis's
 * direction on the screen there, in mm over the axis's extentMm. A handle whose axis points
 * (nearly) at the viewer (the whole extent under MIN_AXIS_PIXELS) stays.
 */
export function dragFraction(screen, point, axis, extentMm, fraction, dx, dy) {
  const [sx, sy] = screenAxis(screen, point, axis);
  const s2 = sx * sx + sy * sy;
  if (!(Math.sqrt(s2) * extentMm >= MIN_AXIS_PIXELS)) return fraction;
  const mm = (dx * sx + dy * sy) / s2;
  return clamp(fraction + mm / extentMm, 0, 1);
}

/**
 * The polygon where the plane dot(normal, x) + offset = 0 cuts a box {min, max}: its corners
 * (world mm) in order around it, 3 to 6 of them; [] when the plane misses the box or only
 * touches it at an edge or a corner.
 */
export function planeBoxPolygon({ normal, offset }, box) {
  const corners = boxCorners(box);
  const side = corners.map((c) => dot(normal, c) + offset);
  const size = length(sub(box.max, box.min));
  const eps = 1e-9 * Math.max(1, size);
  const points = [];
  const addPoint = (p) => { if (!points.some((q) => length(sub(p, q)) <= eps)) points.push(p); };
  for (const [i, j] of BOX_EDGES) {
    const si = Math.abs(side[i]) <= eps * length(normal) ? 0 : side[i];
    const sj = Math.abs(side[j]) <= eps * length(normal) ? 0 : side[j];
    if (si === 0) addPoint(corners[i]);
    if (sj === 0) addPoint(corners[j]);
    if (si * sj < 0) addPoint(add(corners[i], scale(sub(corners[j], corners[i]), si / (si - sj))));
  }
  if (points.length < 3) return [];
  // Around the centre, by angle in a basis of the plane.
  const centre = polygonCentre(points);
  const n = normalize(normal);
  const u = normalize(sub(points[0], centre));
  const v = cross(n, u);
  const angle = (p) => Math.atan2(dot(sub(p, centre), v), dot(sub(p, centre), u));
  return points.map((p) => ({ p, a: angle(p) })).sort((x, y) => x.a - y.a).map(({ p }) => p);
}

/** The mean of a polygon's corners: its centre for a rectangle (an axis-aligned plane through a box). */
export function polygonCentre(points) {
  return scale(points.reduce((s, p) => add(s, p), [0, 0, 0]), 1 / points.length);
}

/** A crop handle's name: its axis and side, e.g. 'x-low', 'z-high'. */
export const handleName = (axis, side) => `${'xyz'[axis]}-${side}`;

/**
 * What the cut overlay draws for the controls' state `cut` (defaultCut's shape) on a screen
 * (screenOf). With cropping on: the crop box's edges and a handle at the centre of each face.
 * With the clip plane on, where it cuts the volume's box: its outline, its corners (null when
 * one is at or behind the eye), and a handle at its centre with an arrow towards the side kept.
 * Segments are [x0, y0, x1, y1] screen pixels, cut in front of the eye. A handle is {name
 * ('x-low' .. 'z-high', or 'clip'), axis (0 x .. 2 z), point (world mm), mm (its position on
 * its axis), x, y}; one at or behind a perspective camera's eye is left out. Returns {edges,
 * handles, clip: {outline, polygon, arrow} | null}.
 */
export function cutOverlayOf(volume, cut, screen) {
  const edges = [], handles = [];
  let clip = null;
  const at = (name, axis, point) => {
    const s = project(screen, point);
    if (s) handles.push({ name, axis, point, mm: point[axis], x: s.x, y: s.y });
  };
  const segments = (points, pairs) => pairs.map(([i, j]) => projectSegment(screen, points[i], points[j])).filter(Boolean);
  if (cut.cropped) {
    const box = cropBoxMm(volume, cut.low, cut.high);
    edges.push(...segments(boxCorners(box), BOX_EDGES));
    for (const h of faceHandles(box)) at(handleName(h.axis, h.side), h.axis, h.point);
  }
  if (cut.clip) {
    const plane = clipPlaneOf(volume, cut.axis, cut.position);
    const e = extentMm(volume);
    const corners = planeBoxPolygon(plane, { min: [0, 0, 0], max: e });
    if (corners.length) {
      const centre = polygonCentre(corners);
      const tip = add(centre, scale(plane.normal, CLIP_ARROW_FRACTION * Math.max(...e)));
      const projected = corners.map((p) => project(screen, p));
      clip = {
        outline: segments(corners, corners.map((_, i) => [i, (i + 1) % corners.length])),
        polygon: projected.every(Boolean) ? projected.map((p) => [p.x, p.y]) : null,
        arrow: projectSegment(screen, centre, tip),
      };
      at('clip', 'xyz'.indexOf(cut.axis[1]), centre);
    }
  }
  return { edges, handles, clip };
}
