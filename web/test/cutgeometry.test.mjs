// cutgeometry.js: the cut overlay's crop box and clip plane projected as the server casts its rays, and its drags.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import {
  screenOf, project, projectSegment, boxCorners, BOX_EDGES, faceHandles, screenAxis, dragFraction, planeBoxPolygon,
  polygonCentre, cutOverlayOf,
} from '../js/cutgeometry.js';
import { defaultCut, extentMm } from '../js/modes.js';
import { orbitCamera } from '../js/trackball.js';

// 256 × 256 × 113 voxels of 1 × 1 × 2 mm: the box is [0, 256] × [0, 256] × [0, 226] mm.
const cthead = { name: 'cthead', dims: [256, 256, 113], spacingMm: [1, 1, 2], voxelType: 1, levels: 4, valueMin: 0, valueMax: 4095, storedBytes: 0 };
const close = (a, b) => assert.ok(Math.abs(a - b) < 1e-9, `${a} != ${b}`);

// The phantom of the browser tests: 96³ voxels of 1 mm, the box [0, 96]³ mm.
const phantom = { dims: [96, 96, 96], spacingMm: [1, 1, 1] };
// Looking down -z at the box's centre, +x to the right, +y up; 192 mm tall on 256 px.
const topOrtho = { eye: [48, 48, 300], target: [48, 48, 48], up: [0, 1, 0], fovYDeg: 30, orthographic: true, orthoHeight: 192 };
// The same from 144 mm above the centre, in perspective with a 90° field: tan(45°) = 1.
const topPerspective = { eye: [48, 48, 192], target: [48, 48, 48], up: [0, 1, 0], fovYDeg: 90, orthographic: false, orthoHeight: 1 };
const nearPoint = (p, x, y, what = '') => {
  assert.ok(p && Math.abs(p.x - x) < 1e-9 && Math.abs(p.y - y) < 1e-9, `${what}: (${p?.x}, ${p?.y}) != (${x}, ${y})`);
};

test('box corners project to the pixels the server\'s rays go through (orthographic and perspective)', () => {
  const ortho = screenOf(topOrtho, 256, 256);
  // Orthographic: 4/3 px per mm about the centre pixel edge 128; y grows downwards.
  nearPoint(project(ortho, [0, 0, 0]), 64, 192, 'ortho (0,0,0)');
  nearPoint(project(ortho, [96, 96, 96]), 192, 64, 'ortho (96,96,96)');
  nearPoint(project(ortho, [96, 0, 50]), 192, 192, 'ortho (96,0,50)');
  // Perspective: the top face (96 mm from the eye) at ±64 px, the bottom (192 mm) at ±32 px.
  const persp = screenOf(topPerspective, 256, 256);
  nearPoint(project(persp, [96, 96, 96]), 192, 64, 'perspective top corner');
  nearPoint(project(persp, [0, 0, 96]), 64, 192, 'perspective top corner');
  nearPoint(project(persp, [96, 96, 0]), 160, 96, 'perspective bottom corner');
  assert.ok(Math.abs(project(persp, [96, 96, 0]).depth - 192) < 1e-9);
  assert.equal(project(persp, [48, 48, 192]), null, 'the eye itself');
  assert.equal(project(persp, [0, 0, 300]), null, 'behind the eye');
  // A frame twice as wide as tall, shown on an element of half its size: the aspect is the frame's.
  nearPoint(project(screenOf(topOrtho, 512, 256, 256, 128), [96, 96, 0]), 160, 32, 'wide frame');
  // The server's ray through pixel (i, j) passes through the centre of the square [i, i+1] × [j, j+1]:
  // pixel (191, 63)'s centre ray at 256² (render/Camera.cpp ViewBasis::ray) hits (95.625, 95.625).
  const sx = 2 * (191 + 0.5) / 256 - 1, sy = 1 - 2 * (63 + 0.5) / 256;
  nearPoint(project(ortho, [48 + sx * 96, 48 + sy * 96, 0]), 191.5, 63.5, 'pixel centre');
});

test('a box\'s 12 edges and 6 face handles; edges behind the eye are cut at its near plane', () => {
  const box = { min: [0, 0, 0], max: [96, 96, 96] };
  assert.equal(BOX_EDGES.length, 12);
  const corners = boxCorners(box);
  for (const [i, j] of BOX_EDGES) {
    const differ = [0, 1, 2].filter((a) => corners[i][a] !== corners[j][a]);
    assert.equal(differ.length, 1, `edge ${i}-${j} is not along one axis`);
  }
  const handles = faceHandles({ min: [10, 20, 30], max: [50, 60, 90] });
  assert.deepEqual(handles.map((h) => [h.axis, h.side, h.point]), [
    [0, 'low', [10, 40, 60]], [0, 'high', [50, 40, 60]], [1, 'low', [30, 20, 60]],
    [1, 'high', [30, 60, 60]], [2, 'low', [30, 40, 30]], [2, 'high', [30, 40, 90]],
  ]);
  // An eye at the box's centre looking down: the top face's 4 edges are behind it, the 4
  // vertical edges cut short, the bottom face's 4 whole.
  const inside = screenOf({ ...topPerspective, eye: [48, 48, 48], target: [48, 48, 0] }, 256, 256);
  const edges = BOX_EDGES.map(([i, j]) => projectSegment(inside, corners[i], corners[j])).filter(Boolean);
  assert.equal(edges.length, 8);
  for (const e of edges) assert.ok(e.every(Number.isFinite), `edge ${e}`);
  const persp = screenOf(topPerspective, 256, 256);
  assert.deepEqual(projectSegment(persp, [96, 96, 96], [96, 96, 0]).map((v) => Math.round(v * 1e9) / 1e9), [192, 64, 160, 96]);
});

test('a drag projected on the axis\'s screen direction moves a face by the pixels\' mm', () => {
  const ortho = screenOf(topOrtho, 256, 256);
  const xHigh = [96, 48, 48], yHigh = [48, 96, 48], zHigh = [48, 48, 96];
  assert.deepEqual(screenAxis(ortho, xHigh, 0).map((v) => v + 0), [256 / 192, 0]);
  assert.deepEqual(screenAxis(ortho, yHigh, 1).map((v) => v + 0), [0, -256 / 192]);
  // 64 px left is 48 mm: the x high face from 96 to 48 mm, half the extent; the drag's y part moves nothing.
  close(dragFraction(ortho, xHigh, 0, 96, 1, -64, 10), 0.5);
  // 32 px down is 24 mm down y.
  close(dragFraction(ortho, yHigh, 1, 96, 1, 0, 32), 0.75);
  // Clamped to the extent.
  assert.equal(dragFraction(ortho, xHigh, 0, 96, 1, 500, 0), 1);
  assert.equal(dragFraction(ortho, xHigh, 0, 96, 0.2, -500, 0), 0);
  // z points at the viewer: a z handle does not move, however far it is dragged.
  assert.equal(dragFraction(ortho, zHigh, 2, 96, 0.7, 40, -40), 0.7);

  // Perspective: the x high face's centre is 144 mm deep, 128 px / 144 mm there.
  const persp = screenOf(topPerspective, 256, 256);
  nearPoint(project(persp, xHigh), 128 + 128 / 3, 128, 'x high handle');
  close(screenAxis(persp, xHigh, 0)[0], 128 / 144);
  close(dragFraction(persp, xHigh, 0, 96, 1, -32, 0), 1 - 36 / 96);
  assert.equal(dragFraction(persp, zHigh, 2, 96, 1, 0, 50), 1);

  // An oblique camera: the derivative is the projection's (central differences), and a drag of
  // N px along the axis's screen direction moves N / |d| mm.
  const cam = orbitCamera(cthead, 35, 25);
  const s = screenOf(cam, 640, 480);
  const p = [200, 128, 113];
  for (let axis = 0; axis < 3; ++axis) {
    const d = screenAxis(s, p, axis);
    const h = 1e-3, e = [0, 0, 0];
    e[axis] = h;
    const a = project(s, sub3(p, e)), b = project(s, add3(p, e));
    assert.ok(Math.abs(d[0] - (b.x - a.x) / (2 * h)) < 1e-6 && Math.abs(d[1] - (b.y - a.y) / (2 * h)) < 1e-6, `axis ${axis}: ${d}`);
    const len = Math.hypot(d[0], d[1]);
    const extent = extentMm(cthead)[axis];
    close(dragFraction(s, p, axis, extent, 0.5, 10 * d[0] / len, 10 * d[1] / len), 0.5 + 10 / len / extent);
  }
});
const add3 = (a, b) => a.map((v, i) => v + b[i]);
const sub3 = (a, b) => a.map((v, i) => v - b[i]);

test('a plane cuts a box in a polygon, its corners in order around it', () => {
  const box = { min: [0, 0, 0], max: [100, 50, 10] };
  const rect = planeBoxPolygon({ normal: [1, 0, 0], offset: -40 }, box);
  assert.equal(rect.length, 4);
  const key = (p) => p.join(',');
  assert.deepEqual(rect.map(key).sort(), ['40,0,0', '40,0,10', '40,50,0', '40,50,10']);
  // In order: neighbours differ along one axis (the rectangle's sides, not its diagonals).
  rect.forEach((p, i) => {
    const q = rect[(i + 1) % 4];
    assert.equal([0, 1, 2].filter((a) => p[a] !== q[a]).length, 1, `${key(p)} -> ${key(q)}`);
  });
  assert.deepEqual(polygonCentre(rect), [40, 25, 5]);
  // On a face: its 4 corners once each.
  assert.deepEqual(planeBoxPolygon({ normal: [0, 0, -1], offset: 10 }, box).map(key).sort(), ['0,0,10', '0,50,10', '100,0,10', '100,50,10']);
  // Oblique through the unit cube's middle: a regular hexagon, convex, in the plane.
  const cube = { min: [0, 0, 0], max: [1, 1, 1] };
  const hex = planeBoxPolygon({ normal: [1, 1, 1], offset: -1.5 }, cube);
  assert.equal(hex.length, 6);
  for (const p of hex) close(p[0] + p[1] + p[2], 1.5);
  const turns = hex.map((p, i) => {
    const q = hex[(i + 1) % 6], r = hex[(i + 2) % 6];
    const u = sub3(q, p), v = sub3(r, q);
    return (u[1] * v[2] - u[2] * v[1]) + (u[2] * v[0] - u[0] * v[2]) + (u[0] * v[1] - u[1] * v[0]);
  });
  assert.ok(turns.every((t) => t > 0) || turns.every((t) => t < 0), `not convex in order: ${turns}`);
  // Missing the box, touching a corner or an edge only: nothing.
  assert.deepEqual(planeBoxPolygon({ normal: [1, 0, 0], offset: -200 }, box), []);
  assert.deepEqual(planeBoxPolygon({ normal: [1, 1, 1], offset: 0 }, cube), []);
  assert.deepEqual(planeBoxPolygon({ normal: [1, 1, 0], offset: 0 }, cube), []);
});

test('the cut overlay: the crop box\'s edges and face handles, the clip plane\'s outline, handle and arrow', () => {
  const ortho = screenOf(topOrtho, 256, 256);
  assert.deepEqual(cutOverlayOf(phantom, defaultCut({ ...phantom, valueMin: 0, valueMax: 1 }), ortho), { edges: [], handles: [], clip: null });
  const cut = { ...defaultCut({ ...phantom, valueMin: 0, valueMax: 1 }), cropped: true, low: [0.25, 0, 0], high: [0.75, 1, 0.5] };
  const o = cutOverlayOf(phantom, cut, ortho);
  assert.equal(o.edges.length, 12);
  assert.equal(o.clip, null);
  const byName = Object.fromEntries(o.handles.map((h) => [h.name, h]));
  assert.deepEqual(Object.keys(byName), ['x-low', 'x-high', 'y-low', 'y-high', 'z-low', 'z-high']);
  // x from 24 to 72 mm: 96 and 160 px; z from 0 to 48 mm, both faces seen at the centre.
  nearPoint(byName['x-low'], 96, 128, 'x-low');
  nearPoint(byName['x-high'], 160, 128, 'x-high');
  nearPoint(byName['y-high'], 128, 64, 'y-high');
  nearPoint(byName['z-high'], 128, 128, 'z-high');
  assert.equal(byName['x-low'].mm, 24);
  assert.equal(byName['z-high'].mm, 48);
  // The clip plane y = 24 mm keeping y ≥ 24: seen edge-on from above, its handle on the line y = 160 px, the arrow up the screen.
  const c = cutOverlayOf(phantom, { ...cut, cropped: false, clip: true, axis: '+y', position: 0.25 }, ortho);
  assert.equal(c.edges.length, 0);
  assert.equal(c.clip.outline.length, 4);
  assert.equal(c.clip.polygon.length, 4);
  for (const [, y] of c.clip.polygon) close(y, 160);
  const [h] = c.handles;
  assert.equal(h.name, 'clip');
  assert.equal(h.axis, 1);
  nearPoint(h, 128, 160, 'clip handle');
  assert.deepEqual(h.point, [48, 24, 48]);
  const [x0, y0, x1, y1] = c.clip.arrow;
  assert.deepEqual([x0, y0, x1].map((v) => Math.round(v * 1e9) / 1e9), [128, 160, 128]);
  close(y1, 160 - 0.15 * 96 * 256 / 192);
  // Looking down -x (+y to the right, +z up), the clip plane x = 48 mm shows as a square; its handle is its centre.
  const side = screenOf({ eye: [300, 48, 48], target: [48, 48, 48], up: [0, 0, 1], fovYDeg: 30, orthographic: true, orthoHeight: 192 }, 256, 256);
  const s = cutOverlayOf(phantom, { ...cut, cropped: false, clip: true, axis: '-x', position: 0.5 }, side);
  nearPoint(s.handles[0], 128, 128, 'clip handle from the side');
  const square = s.clip.polygon.map(([x, y]) => [Math.round(x * 1e9) / 1e9, Math.round(y * 1e9) / 1e9]);
  assert.deepEqual(square.map(String).sort(), ['192,192', '192,64', '64,192', '64,64']);
});
