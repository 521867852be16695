import { test } from 'node:test';
import assert from 'node:assert/strict';
import {
  Trackball, orbitCamera, zoomLimits, arcballVector, arcballRotate, orbitBy, zoom, pan,
  volumeBounds, sub, dot, length, normalize, cross,
} from '../js/trackball.js';

const cthead = { dims: [256, 256, 113], spacingMm: [1, 1, 2] };
const near = (a, b, eps = 1e-9) => Math.abs(a - b) <= eps * Math.max(1, Math.abs(a), Math.abs(b));
const nearVec = (a, b, eps = 1e-9) => a.every((v, i) => near(v, b[i], eps));
const distance = (cam) => length(sub(cam.eye, cam.target));

function assertOrthonormalUp(cam) {
  const view = normalize(sub(cam.target, cam.eye));
  assert.ok(near(length(cam.up), 1, 1e-12), `|up| = ${length(cam.up)}`);
  assert.ok(Math.abs(dot(cam.up, view)) < 1e-12, `up·view = ${dot(cam.up, view)}`);
}

test('default camera is the native client\'s orbit (client/Orbit.cpp)', () => {
  const cam = orbitCamera(cthead);
  const { centre, radius } = volumeBounds(cthead);
  assert.deepEqual(cam.target, [128, 128, 113]);
  assert.deepEqual(centre, [128, 128, 113]);
  const fit = radius / Math.sin(15 * Math.PI / 180);
  assert.ok(near(distance(cam), fit));
  // azimuth 0, elevation 20: in the x-z plane, 20° above the centre
  const dir = normalize(sub(cam.eye, cam.target));
  assert.ok(nearVec(dir, [Math.cos(20 * Math.PI / 180), 0, Math.sin(20 * Math.PI / 180)]));
  assert.deepEqual(cam.up, [0, 0, 1]);
  assert.equal(cam.fovYDeg, 30);
  assert.equal(cam.orthographic, false);
  assert.deepEqual(orbitCamera(cthead, 0, 90).up, [0, 1, 0]);
});

test('arcball vectors are unit length, centre is the view axis', () => {
  assert.ok(nearVec(arcballVector(50, 50, 100, 100), [0, 0, 1]));
  for (const [x, y] of [[0, 0], [100, 100], [-300, 40], [99, 3], [50, 0]])
    assert.ok(near(length(arcballVector(x, y, 100, 100)), 1));
  assert.ok(arcballVector(100, 50, 100, 100)[0] > 0, 'right of centre is +x');
  assert.ok(arcballVector(50, 0, 100, 100)[1] > 0, 'top is +y');
});

test('orbit keeps the distance to the target and the target itself', () => {
  const tb = new Trackball(cthead);
  const d0 = distance(tb.camera);
  tb.beginRotate(200, 150, 400, 300);
  for (const [x, y] of [[260, 150], [320, 90], [10, 290], [-500, 40], [200, 151]]) {
    const cam = tb.rotateTo(x, y);
    assert.ok(near(distance(cam), d0, 1e-9), `distance ${distance(cam)} != ${d0}`);
    assert.deepEqual(cam.target, [128, 128, 113]);
    assertOrthonormalUp(cam);
  }
  tb.end();
  let cam = tb.camera;
  for (let i = 0; i < 1000; ++i) cam = orbitBy(cam, 7, -3);
  assert.ok(near(distance(cam), d0, 1e-9));
  assertOrthonormalUp(cam);
});

test('arcball is path-independent and turns the right way', () => {
  const tb = new Trackball(cthead);
  tb.beginRotate(200, 150, 400, 300);
  tb.rotateTo(380, 20);
  const back = tb.rotateTo(200, 150);
  assert.ok(nearVec(back.eye, tb.home.eye, 1e-9));
  // dragging right turns the volume right: the camera moves to the volume's left (−right)
  const start = tb.home;
  const right = normalize(cross(start.up, sub(start.eye, start.target)));
  const after = arcballRotate(start, arcballVector(200, 150, 400, 300), arcballVector(240, 150, 400, 300));
  assert.ok(dot(sub(after.eye, start.eye), right) < 0);
});

test('up stays orthonormal through rotation, zoom and pan', () => {
  const tb = new Trackball(cthead);
  assertOrthonormalUp(tb.orbitBy(30, 10));
  assertOrthonormalUp(tb.zoomBy(0.5));
  assertOrthonormalUp(tb.panBy(10, -20, 600));
  tb.beginRotate(10, 10, 100, 100);
  assertOrthonormalUp(tb.rotateTo(90, 80));
});

test('zoom scales the distance and clamps to the limits', () => {
  const limits = zoomLimits(cthead);
  const cam = orbitCamera(cthead);
  const d0 = distance(cam);
  assert.ok(near(distance(zoom(cam, 0.5, limits)), d0 / 2));
  assert.ok(near(distance(zoom(cam, 1e-6, limits)), limits.minDistance));
  assert.ok(near(distance(zoom(cam, 1e6, limits)), limits.maxDistance));
  assert.ok(limits.minDistance > 0 && limits.minDistance < d0 && limits.maxDistance > d0);
  const ortho = { ...cam, orthographic: true };
  assert.ok(near(zoom(ortho, 0.5, limits).orthoHeight, cam.orthoHeight / 2));
  assert.ok(near(zoom(ortho, 1e-9, limits).orthoHeight, limits.minOrthoHeight));
  // zooming keeps the view direction
  const z = zoom(cam, 0.3, limits);
  assert.ok(nearVec(normalize(sub(z.eye, z.target)), normalize(sub(cam.eye, cam.target))));
});

test('pan moves eye and target together by the view height per pixel', () => {
  const cam = orbitCamera(cthead);
  const d = distance(cam);
  const p = pan(cam, 100, 0, 1000);
  const moved = sub(p.target, cam.target);
  assert.ok(nearVec(sub(p.eye, cam.eye), moved));
  const viewHeight = 2 * d * Math.tan(15 * Math.PI / 180);
  assert.ok(near(length(moved), viewHeight * 0.1));
  assert.ok(near(distance(p), d));
});

test('reset returns the default camera', () => {
  const tb = new Trackball(cthead);
  tb.orbitBy(40, 25);
  tb.zoomBy(0.3);
  tb.panBy(5, 5, 300);
  assert.notDeepEqual(tb.camera, orbitCamera(cthead));
  assert.deepEqual(tb.reset(), orbitCamera(cthead));
  assert.deepEqual(tb.camera, orbitCamera(cthead));
});
