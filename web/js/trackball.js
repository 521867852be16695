// Camera math for the viewer: the native client's default orbit, a virtual trackball
// (arcball), zoom and pan. Pure functions on plain camera objects
// {eye, target, up, fovYDeg, orthographic, orthoHeight} (world mm), no DOM, so Node tests it.

export const DEFAULT_FOV_Y_DEG = 30;
export const DEFAULT_AZIMUTH_DEG = 0;
export const DEFAULT_ELEVATION_DEG = 20;
// A full drag across the trackball's diameter turns the volume about 180°, as in ParaView.
const ARCBALL_GAIN = 2;
// Zoom range as multiples of the distance that fits the whole volume.
const MIN_DISTANCE_FACTOR = 0.1;
const MAX_DISTANCE_FACTOR = 10;

const deg = Math.PI / 180;

export const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
export const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
export const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
export const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
export const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
export const length = (a) => Math.hypot(a[0], a[1], a[2]);
export const normalize = (a) => scale(a, 1 / length(a));

/** Rotates vector v about the unit axis by angle radians (Rodrigues). */
export function rotate(v, axis, angle) {
  const c = Math.cos(angle), s = Math.sin(angle);
  return add(add(scale(v, c), scale(cross(axis, v), s)), scale(axis, dot(axis, v) * (1 - c)));
}

/** Centre and half diagonal (mm) of the box [0, dims[i]*spacingMm[i]] a volume occupies. */
export function volumeBounds(info) {
  const extent = [0, 1, 2].map((i) => info.dims[i] * info.spacingMm[i]);
  return { centre: scale(extent, 0.5), radius: 0.5 * length(extent) };
}

/** The native client's orbit camera (client/Orbit.cpp): distance 1 shows the whole volume. */
export function orbitCamera(info, azimuthDeg = DEFAULT_AZIMUTH_DEG, elevationDeg = DEFAULT_ELEVATION_DEG, distance = 1) {
  const { centre, radius } = volumeBounds(info);
  const az = azimuthDeg * deg, el = elevationDeg * deg;
  const dir = [Math.cos(el) * Math.cos(az), Math.cos(el) * Math.sin(az), Math.sin(el)];
  const fit = radius / Math.sin(0.5 * DEFAULT_FOV_Y_DEG * deg) * distance;
  return {
    eye: add(centre, scale(dir, fit)),
    target: centre.slice(),
    up: Math.abs(Math.sin(el)) > 0.999 ? [0, 1, 0] : [0, 0, 1],
    fovYDeg: DEFAULT_FOV_Y_DEG,
    orthographic: false,
    orthoHeight: 2 * radius * distance,
  };
}

/** Zoom limits for a volume: eye-to-target distance and ortho height ranges. */
export function zoomLimits(info) {
  const { radius } = volumeBounds(info);
  const fit = radius / Math.sin(0.5 * DEFAULT_FOV_Y_DEG * deg);
  return {
    minDistance: fit * MIN_DISTANCE_FACTOR, maxDistance: fit * MAX_DISTANCE_FACTOR,
    minOrthoHeight: 2 * radius * MIN_DISTANCE_FACTOR, maxOrthoHeight: 2 * radius * MAX_DISTANCE_FACTOR,
  };
}

/** The camera's orthonormal frame: right, up, and back (from target towards eye). */
export function cameraFrame(cam) {
  const back = normalize(sub(cam.eye, cam.target));
  const right = normalize(cross(cam.up, back));
  return { right, up: cross(back, right), back };
}

/** A copy of cam whose up is unit length and perpendicular to the view direction. */
export function orthonormalized(cam) {
  return { ...cam, eye: cam.eye.slice(), target: cam.target.slice(), up: cameraFrame(cam).up };
}

/**
 * Trackball point for a pointer at (x, y) CSS pixels in a width × height element: a unit
 * vector in camera space (x right, y up, z towards the viewer), on a sphere near the centre
 * and on a hyperbolic sheet outside it (Bell), so dragging past the rim keeps turning smoothly.
 */
export function arcballVector(x, y, width, height) {
  const s = Math.max(1, Math.min(width, height));
  const px = (2 * x - width) / s, py = (height - 2 * y) / s;
  const r2 = px * px + py * py;
  const pz = r2 <= 0.5 ? Math.sqrt(1 - r2) : 0.5 / Math.sqrt(r2);
  return normalize([px, py, pz]);
}

/** Turns the volume by `angle` radians about an axis given in camera space: the camera orbits the other way. */
export function rotateView(cam, axisCamera, angle) {
  if (!(Math.abs(angle) > 1e-12) || !(length(axisCamera) > 1e-12)) return orthonormalized(cam);
  const f = cameraFrame(cam);
  const a = normalize([0, 1, 2].map((i) => axisCamera[0] * f.right[i] + axisCamera[1] * f.up[i] + axisCamera[2] * f.back[i]));
  const offset = rotate(sub(cam.eye, cam.target), a, -angle);
  return { ...cam, eye: add(cam.target, offset), target: cam.target.slice(), up: normalize(rotate(f.up, a, -angle)) };
}

/** The camera after a trackball drag from trackball point `from` to `to` (both from arcballVector), starting at cam. */
export function arcballRotate(cam, from, to) {
  const c = Math.min(1, Math.max(-1, dot(from, to)));
  return rotateView(cam, cross(from, to), Math.acos(c) * ARCBALL_GAIN);
}

/** Turns the volume right by yawDeg and up by pitchDeg about the view's axes (arrow keys). */
export function orbitBy(cam, yawDeg, pitchDeg) {
  return rotateView(rotateView(cam, [0, 1, 0], yawDeg * deg), [-1, 0, 0], pitchDeg * deg);
}

/** Moves the eye towards the target by factor (< 1 zooms in), within limits; scales orthoHeight likewise. */
export function zoom(cam, factor, limits) {
  const offset = sub(cam.eye, cam.target);
  const d = length(offset);
  const nd = clamp(d * factor, limits.minDistance, limits.maxDistance);
  const h = clamp(cam.orthoHeight * factor, limits.minOrthoHeight, limits.maxOrthoHeight);
  return { ...orthonormalized(cam), eye: add(cam.target, scale(offset, nd / d)), orthoHeight: cam.orthographic ? h : cam.orthoHeight };
}

/** Slides eye and target so the content under the pointer follows a drag of (dx, dy) CSS pixels in a view viewportHeight pixels tall. */
export function pan(cam, dx, dy, viewportHeight) {
  const f = cameraFrame(cam);
  const d = length(sub(cam.eye, cam.target));
  const viewHeight = cam.orthographic ? cam.orthoHeight : 2 * d * Math.tan(0.5 * cam.fovYDeg * deg);
  const mmPerPixel = viewHeight / Math.max(1, viewportHeight);
  const delta = add(scale(f.right, -dx * mmPerPixel), scale(f.up, dy * mmPerPixel));
  return { ...cam, eye: add(cam.eye, delta), target: add(cam.target, delta), up: f.up };
}

function clamp(v, lo, hi) {
  return Math.min(hi, Math.max(lo, v));
}

/**
 * The viewer's camera state for one volume: a current camera, the default it resets to and
 * the drag in progress. Methods return the new camera; the DOM binding lives in controls.js.
 */
export class Trackball {
  /** A trackball at the volume's default orbit. */
  constructor(info) {
    this.home = orbitCamera(info);
    this.limits = zoomLimits(info);
    this.camera = this.home;
    this.drag = null;
  }

  /** Back to the default camera. */
  reset() {
    this.camera = this.home;
    this.drag = null;
    return this.camera;
  }

  /** Replaces the current camera (e.g. one a test or a reconnect sets). */
  set(cam) {
    this.camera = { ...this.camera, ...cam };
    return this.camera;
  }

  /** Starts a rotation at (x, y) in a width × height element. */
  beginRotate(x, y, width, height) {
    this.drag = { start: this.camera, from: arcballVector(x, y, width, height), width, height };
  }

  /** Continues the rotation begun by beginRotate; path-independent (depends on the start and here only). */
  rotateTo(x, y) {
    if (!this.drag) return this.camera;
    const { start, from, width, height } = this.drag;
    this.camera = arcballRotate(start, from, arcballVector(x, y, width, height));
    return this.camera;
  }

  /** Ends a drag. */
  end() {
    this.drag = null;
  }

  /** Zooms by factor (< 1 in), clamped. */
  zoomBy(factor) {
    this.camera = zoom(this.camera, factor, this.limits);
    return this.camera;
  }

  /** Pans by a drag of (dx, dy) CSS pixels in a view viewportHeight pixels tall. */
  panBy(dx, dy, viewportHeight) {
    this.camera = pan(this.camera, dx, dy, viewportHeight);
    return this.camera;
  }

  /** Turns the volume by yaw/pitch degrees about the view's axes. */
  orbitBy(yawDeg, pitchDeg) {
    this.camera = orbitBy(this.camera, yawDeg, pitchDeg);
    return this.camera;
  }
}
