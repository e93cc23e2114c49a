// The handrig live view: draws the rig's MuJoCo model and a human-hand skeleton from
// the frames the server sends (bodies already posed by MuJoCo in Python), and sends
// the buttons' actions back. Only the newest frame is drawn.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const token = new URLSearchParams(location.search).get('token');
const $ = (id) => document.getElementById(id);
const HAND_OFFSET_M = { ri: -0.11, le: 0.11 };  // two hands side by side
const SKELETON_CSS = '#3cc8ff';
const BACKGROUND = 0x0f1115, BACKGROUND_CSS = '#0f1115';
const TWO_HANDS_FROM = new THREE.Vector3(-0.5, 0.0, 1.0);  // the rig has two hands: the right on the right
const TWO_SKELETONS_FROM = new THREE.Vector3(-0.3, 0.0, 1.0);

// What a frame costs the machine the page runs on: where WebGL is drawn in software
// (SwiftShader, llvmpipe: a headless browser or a machine without a GPU) every
// frame is CPU time, which the rig's own processes may need (docs/view.md: what two
// such pages cost the loop on a 2-core machine). So there the page draws without
// multisampling, at one pixel per CSS pixel and at most 15 frames a second (a frame
// costs about the same CPU whatever its size: the browser's compositing of the page,
// not the pixels of the scene); `?full` in the URL draws at up to 30 a second anyway.
// Everywhere: one WebGL canvas, over the model's view only (the skeleton's lines are
// drawn on a 2D canvas: a WebGL canvas's every frame is read back or composited by
// the browser, at a cost by its size), each model one mesh (one draw call) lit at its
// vertices (buildModel), a draw only when a new frame came (or the camera moved), at
// most MAX_DRAW_HZ, nothing while the page is hidden. docs/view.md has the figures.
const FULL = new URLSearchParams(location.search).has('full');
const SOFTWARE_GL = (() => {
  const gl = document.createElement('canvas').getContext('webgl2');
  if (!gl) return false;
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
  const lose = gl.getExtension('WEBGL_lose_context');
  if (lose) lose.loseContext();
  return /swiftshader|llvmpipe|softpipe|software/i.test(name);
})();
const SAVE_CPU = SOFTWARE_GL && !FULL;
const MAX_DRAW_HZ = SAVE_CPU ? 15 : 30;
const PIXEL_RATIO = SOFTWARE_GL ? 1 : Math.min(window.devicePixelRatio, 2);

// One WebGL canvas, in the model's view, opaque (nothing under it to blend with).
// Without WebGL the page says so where the views would be; the tables and buttons work.
const viewsEl = document.querySelector('.views');
function makeRenderer() {
  try {
    const r = new THREE.WebGLRenderer({ antialias: !SOFTWARE_GL, alpha: false, stencil: false,
      powerPreference: 'low-power' });
    r.setPixelRatio(PIXEL_RATIO);
    r.setClearColor(BACKGROUND, 1);
    r.domElement.className = 'view-canvas';
    $('puppet').appendChild(r.domElement);
    return r;
  } catch (err) {
    for (const el of viewsEl.querySelectorAll('.view3d')) {
      el.textContent = 'This browser cannot draw the 3D view (WebGL 2 is off or missing); the figures below are live.';
      el.classList.add('nogl');
    }
    return null;
  }
}
const renderer = makeRenderer();
const views = [];
let viewsDirty = true;
// Drawing is driven by events (a frame came, the camera moved, the page was resized or
// shown again), not by a loop of animation frames: a page with nothing new to draw
// asks its browser for nothing.
let drawPending = false;
let drawnAt = -Infinity;
function requestDraw() {
  if (drawPending || document.hidden) return;
  drawPending = true;
  // less half a display frame: the animation frame after the timeout comes up to one later
  const wait = Math.max(0, drawnAt + 1000 / MAX_DRAW_HZ - 8 - performance.now());
  setTimeout(() => requestAnimationFrame(animate), wait);
}
function markDirty() { viewsDirty = true; requestDraw(); }

function makeView(el) {
  const scene = new THREE.Scene();  // lit at the vertices: no lights (buildModel)
  const camera = new THREE.PerspectiveCamera(40, 1, 0.005, 20);
  camera.up.set(0, 0, 1);
  camera.position.set(0.05, -0.45, 0.35);
  const controls = new OrbitControls(camera, el);
  controls.target.set(0.05, 0, 0);
  const view = { el, scene, camera, controls, fitted: false, width: 1, height: 1 };
  controls.addEventListener('change', markDirty);
  views.push(view);
  return view;
}

function layout() {
  for (const view of views) {
    const w = view.el.clientWidth, h = view.el.clientHeight;
    view.width = w; view.height = h;
    view.camera.aspect = w / Math.max(h, 1);
    view.camera.updateProjectionMatrix();
  }
  if (renderer) renderer.setSize(puppet.width, puppet.height);
  if (bonesCanvas) {
    bonesCanvas.width = Math.round(skeleton.width * PIXEL_RATIO);
    bonesCanvas.height = Math.round(skeleton.height * PIXEL_RATIO);
    bonesCanvas.style.width = `${skeleton.width}px`;
    bonesCanvas.style.height = `${skeleton.height}px`;
  }
  markDirty();
}

let modelDrawCalls = 0;  // the model view's draw calls in the last frame (for the tests)
function render() {
  if (!renderer) return;
  renderer.render(puppet.scene, puppet.camera);
  modelDrawCalls = renderer.info.render.calls;
  drawBones();
}

// The skeletons on their 2D canvas: each bone a line, each joint a white square,
// projected by the skeleton view's camera (a few dozen lines: no WebGL canvas for them).
const bonePoint = new THREE.Vector3();
function project(segs, i, shift, w, h) {
  bonePoint.set(segs[i], segs[i + 1] + shift, segs[i + 2]).project(skeleton.camera);
  return [(bonePoint.x + 1) * w / 2, (1 - bonePoint.y) * h / 2, bonePoint.z];
}

function drawBones() {
  const ctx = bonesCtx, w = bonesCanvas.width, h = bonesCanvas.height;
  ctx.fillStyle = BACKGROUND_CSS;
  ctx.fillRect(0, 0, w, h);
  skeleton.camera.updateMatrixWorld();
  const joints = [];
  ctx.strokeStyle = SKELETON_CSS;
  ctx.lineWidth = PIXEL_RATIO;
  ctx.beginPath();
  for (const b of Object.values(bones)) {
    if (!b.segs) continue;
    for (let i = 0; i + 5 < b.segs.length; i += 6) {
      const [x0, y0, z0] = project(b.segs, i, b.shift, w, h);
      const [x1, y1, z1] = project(b.segs, i + 3, b.shift, w, h);
      if (Math.abs(z0) > 1 || Math.abs(z1) > 1) continue;  // outside the camera's depth
      ctx.moveTo(x0, y0); ctx.lineTo(x1, y1);
      joints.push(x0, y0, x1, y1);
    }
  }
  ctx.stroke();
  ctx.fillStyle = '#ffffff';
  const r = 2.5 * PIXEL_RATIO;
  for (let i = 0; i < joints.length; i += 2) ctx.fillRect(joints[i] - r, joints[i + 1] - r, 2 * r, 2 * r);
}

// Aim the camera at what is in the box (the hand, not the forearm): all of it in view,
// seen from the direction ``from`` (above and in front).
function fit(view, box, from, margin) {
  if (box.isEmpty()) return;
  const sphere = box.getBoundingSphere(new THREE.Sphere());
  const halfFov = THREE.MathUtils.degToRad(view.camera.fov / 2) * Math.min(1, view.camera.aspect);
  const distance = margin * sphere.radius / Math.sin(halfFov);
  view.controls.target.copy(sphere.center);
  view.camera.position.copy(sphere.center).add(from.clone().normalize().multiplyScalar(distance));
  view.controls.update();
  view.fitted = true;
}

function geometryOf(g, meshes) {
  const s = g.size;
  let geo;
  switch (g.kind) {
    case 'sphere': geo = new THREE.SphereGeometry(s[0], 20, 14); break;
    case 'ellipsoid': geo = new THREE.SphereGeometry(1, 20, 14); geo.scale(s[0], s[1], s[2]); break;
    case 'capsule': geo = new THREE.CapsuleGeometry(s[0], 2 * s[1], 6, 16); geo.rotateX(Math.PI / 2); break;
    case 'cylinder': geo = new THREE.CylinderGeometry(s[0], s[0], 2 * s[1], 20); geo.rotateX(Math.PI / 2); break;
    case 'box': geo = new THREE.BoxGeometry(2 * s[0], 2 * s[1], 2 * s[2]); break;
    case 'mesh': {
      const m = meshes[g.mesh];
      geo = new THREE.BufferGeometry();
      geo.setAttribute('position', new THREE.Float32BufferAttribute(m.vertices, 3));
      geo.setIndex(m.faces);
      geo.computeVertexNormals();
      break;
    }
    default: return null;
  }
  return geo;
}

// The light the models are lit by: a sky over a dark ground (three.js's
// HemisphereLight's, from +y) and a sun, each at LIGHT_INTENSITY, with Lambert's law,
// as three.js's MeshLambertMaterial computes them (linear colours) but at the vertices,
// in JavaScript, each frame (an unlit material then only interpolates colours: the
// least a pixel can cost where WebGL is drawn in software).
const LIGHT_INTENSITY = 1.6;
const SKY = new THREE.Color(0xffffff), GROUND = new THREE.Color(0x303040);
const SUN = new THREE.Vector3(0.3, -0.4, 1.0).normalize();

// One MuJoCo model as one mesh per opacity (the puppet hand: 1, where a mesh per geom
// took 34 draw calls): every geom's triangles in one buffer, placed in its body's frame
// once, sorted by body; each frame moves each body's vertices to where MuJoCo put the
// body and lights them (place).
function buildModel(model, ghost) {
  const root = new THREE.Group();
  const groups = new Map();  // opacity -> its geoms
  for (const g of model.geoms) {
    const geo = geometryOf(g, model.meshes);
    if (!geo) continue;
    geo.applyQuaternion(new THREE.Quaternion(g.quat[1], g.quat[2], g.quat[3], g.quat[0]));
    geo.translate(g.pos[0], g.pos[1], g.pos[2]);
    const opacity = ghost ? 0.18 : g.rgba[3];
    if (!groups.has(opacity)) groups.set(opacity, []);
    groups.get(opacity).push({ geo, body: g.body, rgba: g.rgba });
  }
  const parts = [];
  for (const [opacity, geoms] of groups) {
    geoms.sort((a, b) => a.body - b.body);  // each body's vertices in one run
    const count = (p) => p.geo.getAttribute('position').count;
    const nv = geoms.reduce((n, p) => n + count(p), 0);
    const ni = geoms.reduce((n, p) => n + (p.geo.index ? p.geo.index.count : count(p)), 0);
    const local = new Float32Array(3 * nv), localNormal = new Float32Array(3 * nv);
    const albedo = new Float32Array(3 * nv), index = new Uint32Array(ni);
    const ranges = [];  // [body, first vertex, end vertex]
    let v = 0, k = 0;
    for (const p of geoms) {
      const pos = p.geo.getAttribute('position'), nrm = p.geo.getAttribute('normal');
      const c = new THREE.Color().setRGB(p.rgba[0], p.rgba[1], p.rgba[2], THREE.SRGBColorSpace);
      for (let i = 0; i < pos.count; i++) {
        const at = 3 * (v + i);
        local[at] = pos.getX(i); local[at + 1] = pos.getY(i); local[at + 2] = pos.getZ(i);
        localNormal[at] = nrm.getX(i); localNormal[at + 1] = nrm.getY(i); localNormal[at + 2] = nrm.getZ(i);
        albedo[at] = c.r; albedo[at + 1] = c.g; albedo[at + 2] = c.b;
      }
      if (p.geo.index) for (let i = 0; i < p.geo.index.count; i++) index[k++] = v + p.geo.index.getX(i);
      else for (let i = 0; i < pos.count; i++) index[k++] = v + i;
      const last = ranges[ranges.length - 1];
      if (last && last[0] === p.body) last[2] = v + pos.count;
      else ranges.push([p.body, v, v + pos.count]);
      v += pos.count;
      p.geo.dispose();
    }
    const geo = new THREE.BufferGeometry();
    const position = new THREE.BufferAttribute(local.slice(), 3).setUsage(THREE.DynamicDrawUsage);
    geo.setAttribute('position', position);
    geo.setIndex(new THREE.BufferAttribute(index, 1));
    // the ghost is one pale colour, unlit; the model its geoms' colours, lit at the vertices
    const colour = ghost ? null : new THREE.BufferAttribute(new Float32Array(3 * nv), 3).setUsage(THREE.DynamicDrawUsage);
    if (colour) geo.setAttribute('color', colour);
    const material = ghost
      ? new THREE.MeshBasicMaterial({ color: 0x9fd0ff, transparent: true, opacity, depthWrite: false })
      : new THREE.MeshBasicMaterial({ vertexColors: true, transparent: opacity < 1, opacity });
    const mesh = new THREE.Mesh(geo, material);
    mesh.frustumCulled = false;  // its vertices move every frame: no bounds kept
    root.add(mesh);
    parts.push({ geo, local, localNormal, albedo, position, colour, ranges });
  }
  return { root, parts, nbody: model.bodies.length };
}

// Which bodies of the ghost (the goals) are away from the model's (the present
// positions): more than GHOST_APART_M or GHOST_APART_DEG. Only those are drawn (the
// others would lie inside the model: a pale tint over it, at the cost of drawing the
// hand's pixels once more, about a sixth of a frame in software WebGL).
const GHOST_APART_M = 0.001, GHOST_APART_DEG = 1.0;
const GHOST_APART_DOT = Math.cos(THREE.MathUtils.degToRad(GHOST_APART_DEG) / 2);
function apart(goal, now) {
  const n = goal.pos.length / 3;
  if (!now || now.pos.length !== goal.pos.length) return new Array(n).fill(true);
  const out = new Array(n);
  for (let b = 0; b < n; b++) {
    const dx = goal.pos[3 * b] - now.pos[3 * b], dy = goal.pos[3 * b + 1] - now.pos[3 * b + 1];
    const dz = goal.pos[3 * b + 2] - now.pos[3 * b + 2];
    let dot = 0;
    for (let k = 0; k < 4; k++) dot += goal.quat[4 * b + k] * now.quat[4 * b + k];
    out[b] = dx * dx + dy * dy + dz * dz > GHOST_APART_M ** 2 || Math.abs(dot) < GHOST_APART_DOT;
  }
  return out;
}

// Each body's vertices to where MuJoCo put the body (world position, quaternion w x y z),
// and (the model, not the ghost) their colours lit as they face now. A body that is not
// ``shown`` (when given) has its vertices all at its origin: no pixel drawn.
function place(built, posed, shown = null) {
  const p = posed.pos, q = posed.quat;
  const k = LIGHT_INTENSITY / Math.PI;  // three.js's Lambert: albedo / pi times irradiance
  for (const part of built.parts) {
    const { local, localNormal, albedo, ranges } = part;
    const out = part.position.array, lit = part.colour ? part.colour.array : null;
    for (const [b, first, end] of ranges) {
      const w = q[4 * b], x = q[4 * b + 1], y = q[4 * b + 2], z = q[4 * b + 3];
      const r00 = 1 - 2 * (y * y + z * z), r01 = 2 * (x * y - w * z), r02 = 2 * (x * z + w * y);
      const r10 = 2 * (x * y + w * z), r11 = 1 - 2 * (x * x + z * z), r12 = 2 * (y * z - w * x);
      const r20 = 2 * (x * z - w * y), r21 = 2 * (y * z + w * x), r22 = 1 - 2 * (x * x + y * y);
      const tx = p[3 * b], ty = p[3 * b + 1], tz = p[3 * b + 2];
      if (shown && !shown[b]) {
        for (let i = 3 * first; i < 3 * end; i += 3) { out[i] = tx; out[i + 1] = ty; out[i + 2] = tz; }
        continue;
      }
      for (let i = 3 * first; i < 3 * end; i += 3) {
        const vx = local[i], vy = local[i + 1], vz = local[i + 2];
        out[i] = r00 * vx + r01 * vy + r02 * vz + tx;
        out[i + 1] = r10 * vx + r11 * vy + r12 * vz + ty;
        out[i + 2] = r20 * vx + r21 * vy + r22 * vz + tz;
        if (!lit) continue;
        const nx = localNormal[i], ny = localNormal[i + 1], nz = localNormal[i + 2];
        const wx = r00 * nx + r01 * ny + r02 * nz;
        const wy = r10 * nx + r11 * ny + r12 * nz;
        const wz = r20 * nx + r21 * ny + r22 * nz;
        const sky = 0.5 * wy + 0.5;  // the hemisphere light's weight (its sky is +y)
        const sun = Math.max(0, wx * SUN.x + wy * SUN.y + wz * SUN.z);
        lit[i] = albedo[i] * k * (GROUND.r + (SKY.r - GROUND.r) * sky + SKY.r * sun);
        lit[i + 1] = albedo[i + 1] * k * (GROUND.g + (SKY.g - GROUND.g) * sky + SKY.g * sun);
        lit[i + 2] = albedo[i + 2] * k * (GROUND.b + (SKY.b - GROUND.b) * sky + SKY.b * sun);
      }
    }
    part.position.needsUpdate = true;
    if (part.colour) part.colour.needsUpdate = true;
    part.geo.boundingBox = null;  // recomputed when asked for (handScreenX)
    part.geo.boundingSphere = null;
  }
}

// The bounds (in the scene) of a placed model's bodies from ``fromBody`` on.
function bodiesBox(built, fromBody, box) {
  const v = new THREE.Vector3();
  for (const part of built.parts) {
    const a = part.position.array;
    for (const [b, first, end] of part.ranges) {
      if (b < fromBody) continue;
      for (let i = 3 * first; i < 3 * end; i += 3) {
        box.expandByPoint(v.set(a[i], a[i + 1], a[i + 2]).add(built.root.position));
      }
    }
  }
  return box;
}

const puppet = makeView($('puppet'));
const skeleton = makeView($('skeleton'));
const bonesCanvas = renderer ? document.createElement('canvas') : null;
const bonesCtx = bonesCanvas ? bonesCanvas.getContext('2d', { alpha: false }) : null;
if (bonesCanvas) { bonesCanvas.className = 'view-canvas'; skeleton.el.appendChild(bonesCanvas); }
new ResizeObserver(layout).observe(viewsEl);
layout();
let models = {}, ghosts = {}, bones = {}, twoHands = false;
// the newest frame's text: parsed only when it is drawn (a frame that a newer one
// replaced before the next draw, or that came while the page was hidden, costs nothing)
let latest = null, socket = null, received = 0, drawn = 0, drawnTotal = 0;
const actions = new Set();

function onScene(msg) {
  for (const child of [...puppet.scene.children]) puppet.scene.remove(child);
  puppet.fitted = false;
  skeleton.fitted = false;
  models = {}; ghosts = {}; bones = {};
  const hands = Object.keys(msg.models);
  twoHands = hands.length > 1;
  for (const hand of hands) {
    const shift = hands.length > 1 ? HAND_OFFSET_M[hand] || 0 : 0;
    for (const [store, ghost] of [[models, false], [ghosts, true]]) {
      const built = buildModel(msg.models[hand], ghost);
      built.root.position.y = shift;
      built.root.visible = !ghost;
      puppet.scene.add(built.root);
      store[hand] = built;
    }
  }
  // each hand's bones: segments (x0 y0 z0 x1 y1 z1 ...), shifted along y as the hands are
  for (const hand of msg.skeleton_hands) bones[hand] = { segs: null, shift: HAND_OFFSET_M[hand] || 0 };
  // the camera is aimed at the hand at rest (not the forearm), with room for it to move
  for (const [hand, posed] of Object.entries(msg.rest)) place(models[hand], posed);
  // the hand's bodies: all but the world and the forearm (the first two) where there are more
  const handBox = new THREE.Box3();
  for (const m of Object.values(models)) bodiesBox(m, m.nbody > 2 ? 2 : 0, handBox);
  // two hands (side by side along y) are seen from above and behind the wrists, as
  // the puppeteer sees their own: the right hand on the right
  fit(puppet, handBox, twoHands ? TWO_HANDS_FROM : new THREE.Vector3(0.15, -0.75, 0.85), 1.6);
  $('title').textContent = msg.title;
  actions.clear();
  for (const a of msg.actions) actions.add(a);
  for (const id of ['relax', 'stop', 'estop']) $(id).disabled = !actions.has(id);
}

function fmt(x, unit = '', nd = 1) { return x === null || x === undefined ? '–' : `${x.toFixed(nd)}${unit}`; }

function rows(tbody, n) {
  while (tbody.rows.length > n) tbody.deleteRow(-1);
  while (tbody.rows.length < n) tbody.insertRow();
  return tbody.rows;
}

function cells(row, values) {
  while (row.cells.length < values.length) row.insertCell();
  values.forEach((v, i) => { if (row.cells[i].textContent !== v) row.cells[i].textContent = v; });
}

// A hand's name before its figures when the run has several ("right running · left
// relaxing"); nothing when one loop drives the whole rig.
function named(f, h, text) {
  return f.hands.length > 1 ? `${h.label} ${text}` : text;
}

function drawMode(f) {
  const mode = f.hands.map((h) => named(f, h, h.mode)).join(' · ');
  if ($('mode').textContent !== mode) $('mode').textContent = mode;
  const why = f.hands.filter((h) => h.mode_reason).map((h) => (f.hands.length > 1 ? `${h.label}: ${h.mode_reason}` : h.mode_reason)).join('; ');
  const reason = why ? `(${why})` : '';
  if ($('reason').textContent !== reason) $('reason').textContent = reason;
  const layers = (f.layers || []).length ? `layers: ${f.layers.join('; ')}` : '';
  if ($('layers').textContent !== layers) $('layers').textContent = layers;
}

// The figures change every frame but nobody reads them 20 times a second; redrawing
// the tables (layout and paint) costs the browser more than the 3D view.
const TABLES_EVERY_MS = 250;
let tablesAt = -Infinity, tablesTimer = null, tablesFrame = null;

// The tables at most every TABLES_EVERY_MS, and always with the newest frame in the end:
// a frame that comes within that time of the last update is drawn when it is over (the
// run's last figures, or a view that sends one frame, are never left undrawn).
function scheduleTables(f) {
  tablesFrame = f;
  const wait = tablesAt + TABLES_EVERY_MS - performance.now();
  if (wait <= 0) { flushTables(); return; }
  if (tablesTimer === null) tablesTimer = setTimeout(flushTables, wait);
}

function flushTables() {
  tablesTimer = null;
  if (tablesFrame === null) return;
  const f = tablesFrame;
  tablesFrame = null;
  tablesAt = performance.now();
  drawTables(f);
}

const SOURCES = { positions: 'the servos\' present positions', goals: 'the goals (no readings)', pose: 'the pipeline\'s pose (no readings)' };

// A table with a heading row per hand (none when the run has one), then its rows.
// ``groups``: per hand {title, bad, rows: [{values, className, errCell}]}.
function groupRows(tbody, groups, width) {
  const titled = groups.length > 1;
  const all = rows(tbody, groups.reduce((n, g) => n + (titled ? 1 : 0) + g.rows.length, 0));
  let i = 0;
  for (const g of groups) {
    if (!titled) { i = fillRows(all, i, g.rows); continue; }
    const head = all[i++];
    while (head.cells.length > 1) head.deleteCell(-1);
    cells(head, [g.title]);
    head.cells[0].colSpan = width;
    head.className = g.bad ? 'hand bad' : 'hand';
    i = fillRows(all, i, g.rows);
  }
}

function fillRows(all, i, groupRowsList) {
  for (const r of groupRowsList) {
    const row = all[i++];
    if (row.cells.length && row.cells[0].colSpan !== 1) row.cells[0].colSpan = 1;
    cells(row, r.values);
    row.className = r.className || '';
    if (r.errCell !== undefined) row.cells[r.errCell.at].className = r.errCell.bad ? 'err' : '';
  }
  return i;
}

// A row of the loop's table with a cell per hand (and a heading row naming them when
// there are several).
function handCells(id, values) {
  const row = $(id).parentElement;
  while (row.cells.length > values.length + 1) row.deleteCell(-1);
  while (row.cells.length < values.length + 1) row.insertCell();
  values.forEach((v, i) => { if (row.cells[i + 1].textContent !== v) row.cells[i + 1].textContent = v; });
}

// The loop table's heading row: the hands' names when there are several, none for one
// (redrawn when a page reconnects to a run with another number of hands).
function loopHeads(hands) {
  const labels = hands.length > 1 ? ['', ...hands.map((h) => h.label)] : [];
  const table = $('loop');
  if ((table.dataset.heads || '') === labels.join('|')) return;
  table.dataset.heads = labels.join('|');
  if (table.tHead) table.deleteTHead();
  if (labels.length) table.createTHead().insertRow().replaceChildren(...labels.map((label) => { const th = document.createElement('th'); th.textContent = label; return th; }));
}

function servoRow(s, i) {
  const err = s.errors[i];
  return { values: [String(s.ids[i]), s.joints[i], fmt(s.goal_deg[i]), fmt(s.position_deg[i]),
    fmt(s.temperature_c[i], '', 0), err ? `0x${err.toString(16).padStart(2, '0')}` : '–'],
  className: s.stale[i] ? 'stale' : '', errCell: { at: 5, bad: Boolean(err) } };
}

// The tables, one code path for any number of hands: a column (loop) or a group of
// rows (glove, servos) per hand.
function drawTables(f) {
  const hands = f.hands;
  const sources = [...new Set(hands.map((h) => h.source))];
  $('source').textContent = sources.length === 1 ? SOURCES[sources[0]]
    : hands.map((h) => `${h.label}: ${SOURCES[h.source]}`).join('; ');
  loopHeads(hands);
  handCells('rate', hands.map((h) => fmt(h.rate_hz, ' Hz')));
  handCells('latency', hands.map((h) => `${fmt(h.latency_p50_us, ' µs', 0)} / ${fmt(h.latency_p99_us, ' µs', 0)}`));
  handCells('lost', hands.map((h) => String(h.frames_lost)));
  handCells('cycles', hands.map((h) => `${h.cycles} / ${h.overruns}`));
  const lost = hands.filter((h) => !h.glove.connected).map((h) => h.label);
  $('glovelink').textContent = lost.length ? `(${hands.length > 1 ? `${lost.join(' and ')} ` : ''}not connected)` : '';
  $('glovelink').className = lost.length ? 'bad' : '';
  $('incl').textContent = hands.map((h) => named(f, h, fmt(h.glove.inclination_deg, '°'))).join(', ');
  $('rot').textContent = hands.map((h) => named(f, h, fmt(h.glove.rotation_deg, '°'))).join(', ');
  groupRows($('glove').tBodies[0], hands.map((h) => ({
    title: `${h.label} glove${h.glove.connected ? '' : ' (not connected)'}`, bad: !h.glove.connected,
    rows: h.glove.names.map((n, i) => ({ values: [n, fmt(h.glove.controls[i], '', 3), fmt(h.glove.raw[i], '', 0)] })),
  })), 3);
  groupRows($('servos').tBodies[0], hands.map((h) => ({
    title: `${h.label} hand`, rows: h.servos.ids.map((_, i) => servoRow(h.servos, i)),
  })), 6);
  drawOutputs(f);
  drawCues(f);
}

// The last cues taken (OSC, MIDI, the r key), newest first, each naming its source.
function drawCues(f) {
  const list = $('cues');
  const text = (f.cues || []).slice().reverse();
  if (list.dataset.text !== JSON.stringify(text)) {
    list.dataset.text = JSON.stringify(text);
    list.replaceChildren(...(text.length ? text : ['none']).map((t) => { const li = document.createElement('li'); li.textContent = t; return li; }));
  }
}

function drawOutputs(f) {
  const outs = $('outputs');
  const text = f.outputs.map((o) => (typeof o === 'object' && o !== null
    ? Object.entries(o).map(([k, v]) => `${k}: ${JSON.stringify(v)}`).join(', ') : String(o)));
  if (outs.dataset.text !== JSON.stringify(text)) {
    outs.dataset.text = JSON.stringify(text);
    outs.replaceChildren(...(text.length ? text : ['none']).map((t) => { const li = document.createElement('li'); li.textContent = t; return li; }));
  }
}

// The bounds of the skeletons as they are now (the skeleton view's camera is aimed once).
function bonesBox() {
  const box = new THREE.Box3(), v = new THREE.Vector3();
  for (const b of Object.values(bones)) {
    if (!b.segs) continue;
    for (let i = 0; i + 2 < b.segs.length; i += 3) box.expandByPoint(v.set(b.segs[i], b.segs[i + 1] + b.shift, b.segs[i + 2]));
  }
  return box;
}

function drawFrame(f) {
  for (const [hand, posed] of Object.entries(f.bodies)) if (models[hand]) place(models[hand], posed);
  for (const [hand, built] of Object.entries(ghosts)) {
    const goal = f.ghost && f.ghost[hand], now = f.bodies[hand];
    const away = goal ? apart(goal, now) : null;
    built.root.visible = Boolean(away && away.some(Boolean));
    if (built.root.visible) place(built, goal, away);
  }
  for (const [hand, b] of Object.entries(bones)) {
    const segs = f.skeleton[hand];
    b.segs = segs && segs.length ? segs : null;
  }
  if (!skeleton.fitted) fit(skeleton, bonesBox(), twoHands ? TWO_SKELETONS_FROM : new THREE.Vector3(0.0, -0.45, 1.45), 1.15);
  viewsDirty = true;
  drawMode(f);
  scheduleTables(f);
}

function animate() {
  drawPending = false;
  if (document.hidden) return;
  if (latest) {
    drawFrame(JSON.parse(latest));
    latest = null; drawn += 1; drawnTotal += 1;
  }
  if (viewsDirty) { render(); viewsDirty = false; drawnAt = performance.now(); }
}
document.addEventListener('visibilitychange', requestDraw);

function connect() {
  const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
  socket = new WebSocket(`${scheme}://${location.host}/ws${token ? `?token=${encodeURIComponent(token)}` : ''}`);
  socket.onopen = () => { $('link').textContent = 'live'; $('link').className = 'ok'; };
  socket.onmessage = (ev) => {
    if (ev.data.startsWith('{"type":"frame"')) { latest = ev.data; received += 1; requestDraw(); return; }
    const msg = JSON.parse(ev.data);
    if (msg.type === 'scene') { onScene(msg); latest = null; markDirty(); }
  };
  socket.onclose = () => {
    $('link').textContent = 'not connected (the run may have ended)';
    $('link').className = 'bad';
    setTimeout(connect, 1000);
  };
}

function send(action) {
  if (socket && socket.readyState === WebSocket.OPEN && actions.has(action)) {
    socket.send(JSON.stringify({ action }));
  }
}

// the e-stop acts when the button goes down, not when it is released
$('estop').addEventListener('pointerdown', () => send('estop'));
$('estop').addEventListener('keydown', (ev) => { if (ev.key === 'Enter' || ev.key === ' ') send('estop'); });
$('relax').addEventListener('click', () => send('relax'));
$('stop').addEventListener('click', () => send('stop'));
const SAVING_NOTE = SAVE_CPU ? ` (WebGL in software: at most ${MAX_DRAW_HZ}/s to spare the rig's CPU; add ?full to the URL for 30/s)` : '';
setInterval(() => { $('viewfps').textContent = `${received} frames/s received, ${drawn} drawn${SAVING_NOTE}`; received = 0; drawn = 0; }, 1000);
// Where each hand of the model is on screen: the centre of its drawn bodies, projected
// by the model view's camera, from -1 (left edge) to 1 (right edge) (for the tests).
function handScreenX(hand) {
  const built = models[hand];
  if (!built) return null;
  const box = new THREE.Box3().setFromObject(built.root);
  if (box.isEmpty()) return null;
  return box.getCenter(new THREE.Vector3()).project(puppet.camera).x;
}
window.handrigView = { framesDrawn: () => drawnTotal, modelDrawCalls: () => modelDrawCalls, softwareGL: SOFTWARE_GL, maxDrawHz: MAX_DRAW_HZ, pixelRatio: PIXEL_RATIO, handScreenX };
connect();
requestDraw();
