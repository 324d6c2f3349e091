// mimica viewer: three.js scene, controls, timeline curve editor; frames stream from Python.
import * as THREE from 'three';
import { OrbitControls } from '/vendor/OrbitControls.js';

const state = { framesApplied: 0, fps: 0, version: 0, ready: false, controls: null, lastError: null,
                playing: false, time: 0, secondLoaded: false };
window.mimica = state;
let dirty = true;            // something changed since the last draw

// ---------------------------------------------------------------- scene
const view = document.getElementById('view');
// no MSAA when the page runs on a software GL (headless, no GPU): it costs more than the face
const software = new URLSearchParams(location.search).has('software');
const renderer = new THREE.WebGLRenderer({ antialias: !software, powerPreference: 'high-performance' });
renderer.setPixelRatio(window.devicePixelRatio);
view.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x3a3d44);
const camera = new THREE.PerspectiveCamera(30, 1, 0.1, 1e5);
const orbit = new OrbitControls(camera, renderer.domElement);
scene.add(new THREE.HemisphereLight(0xffffff, 0x444455, 1.2));
const key = new THREE.DirectionalLight(0xffffff, 1.6);
key.position.set(-1, 1.2, 2);
scene.add(key);
const material = software
  ? new THREE.MeshLambertMaterial({ color: 0xd8b8a0, side: THREE.DoubleSide })
  : new THREE.MeshStandardMaterial({ color: 0xd8b8a0, roughness: 0.65, side: THREE.DoubleSide });

function makeMesh() {
  const g = new THREE.BufferGeometry();
  const m = new THREE.Mesh(g, material);
  scene.add(m);
  return m;
}
const face = makeMesh();
const second = makeMesh();
// for tests and scripts: a number that changes when the face's vertices move
state.checksum = (which) => {
  const a = (which === 'second' ? second : face).geometry.getAttribute('position');
  if (!a) return 0;
  let s = 0;
  for (let i = 0; i < a.array.length; i += 7) s += a.array[i] * ((i % 13) + 1);
  return s;
};

// Interactive resolution.  A draw on a software GL (no GPU: SwiftShader, llvmpipe) costs in
// proportion to its pixels; while frames stream the canvas is drawn at the scale that keeps
// the page at 30+ draws a second, and at full resolution once the face has been still for
// 0.4 s (never below half resolution).  A GPU keeps up at full scale and never lowers it.
const MIN_SCALE = 0.5;
let scale = 1;                 // the scale drawn now
let liveScale = 1;             // the scale used while frames stream (tuned)
let lastTick = 0, gapAvg = 0, lastChange = 0, adjusted = 0;
let sharp = true;              // drawn at full resolution because the face is still
let moving = false;            // a new frame or a camera move since the last animation frame
state.scale = () => ({ scale, liveScale, gapAvg });   // for tests: the resolution drawn now
state.setScale = (s) => setScale(s);                  // for tests
function setScale(s) {
  s = Math.max(MIN_SCALE, Math.min(1, s));
  // small steps are not worth a resize, but full resolution is always reached exactly: a
  // streamed scale of 0.99 once kept a still face from ever being drawn sharp
  if (s === scale || (s < 1 && Math.abs(s - scale) < 0.02)) return;
  scale = s;
  renderer.setPixelRatio(window.devicePixelRatio * s);
  renderer.setSize(view.clientWidth, view.clientHeight, false);
  dirty = true;
}
const adaptive = !new URLSearchParams(location.search).has('fullres');   // ?fullres: always sharp
function tune(now, moved) {
  if (!adaptive) return;
  if (moved) {
    if (sharp) {                                 // moving again: back to the live scale
      sharp = false;
      setScale(liveScale);
    } else if (lastTick && now - lastTick < 250) {
      // the animation-frame gap between drawn frames: long gaps mean the draws hold the page back
      const gap = now - lastTick;
      gapAvg = gapAvg ? 0.8 * gapAvg + 0.2 * gap : gap;
      if (now - adjusted > 250) {                // adjust at most 4 times a second
        adjusted = now;
        if (gapAvg > 30) liveScale = Math.max(MIN_SCALE, liveScale * Math.sqrt(28 / gapAvg));
        else if (gapAvg < 20) liveScale = Math.min(1, liveScale * 1.1);
        setScale(liveScale);
        liveScale = scale;
      }
    }
    lastTick = now;
    lastChange = now;
  } else if (!sharp && now - lastChange > 400) {
    sharp = true;                                // still: one sharp draw
    lastTick = 0;
    setScale(1);
  }
}

function resize() {
  const w = view.clientWidth, h = view.clientHeight;
  renderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  dirty = true;
}
window.addEventListener('resize', resize);
resize();

function frameCamera(...meshes) {
  const box = new THREE.Box3();
  for (const m of meshes) { m.geometry.computeBoundingBox(); box.union(m.geometry.boundingBox.clone().translate(m.position)); }
  const s = box.getBoundingSphere(new THREE.Sphere());
  orbit.target.copy(s.center);
  camera.position.copy(s.center).add(new THREE.Vector3(0, 0, s.radius * 3.2));
  camera.near = s.radius / 50; camera.far = s.radius * 50;
  camera.updateProjectionMatrix();
  orbit.update();
}

// area-weighted vertex normals in one pass over the triangles (three's computeVertexNormals
// does the same through Vector3 objects: 2.9 ms against 1.1 ms on a 9,409-vertex grid in headless Chromium)
function vertexNormals(g) {
  const pos = g.getAttribute('position').array;
  if (!g.index) { g.computeVertexNormals(); return; }
  const idx = g.index.array;
  let attr = g.getAttribute('normal');
  if (!attr || attr.array.length !== pos.length) {
    attr = new THREE.BufferAttribute(new Float32Array(pos.length), 3);
    g.setAttribute('normal', attr);
  }
  const n = attr.array;
  n.fill(0);
  for (let t = 0; t < idx.length; t += 3) {
    const a = 3 * idx[t], b = 3 * idx[t + 1], c = 3 * idx[t + 2];
    const ux = pos[b] - pos[a], uy = pos[b + 1] - pos[a + 1], uz = pos[b + 2] - pos[a + 2];
    const vx = pos[c] - pos[a], vy = pos[c + 1] - pos[a + 1], vz = pos[c + 2] - pos[a + 2];
    const x = uy * vz - uz * vy, y = uz * vx - ux * vz, z = ux * vy - uy * vx;
    n[a] += x; n[a + 1] += y; n[a + 2] += z;
    n[b] += x; n[b + 1] += y; n[b + 2] += z;
    n[c] += x; n[c + 1] += y; n[c + 2] += z;
  }
  for (let i = 0; i < n.length; i += 3) {
    const l = Math.hypot(n[i], n[i + 1], n[i + 2]) || 1;
    n[i] /= l; n[i + 1] /= l; n[i + 2] /= l;
  }
  attr.needsUpdate = true;
}

function setPositions(mesh, arr, first) {
  const g = mesh.geometry;
  const attr = g.getAttribute('position');
  if (!attr || attr.array.length !== arr.length) {
    g.setAttribute('position', new THREE.BufferAttribute(arr, 3));
  } else {
    attr.array.set(arr);
    attr.needsUpdate = true;
  }
  vertexNormals(g);
  if (first) frameCamera(mesh);
  dirty = true;
}

let fpsCount = 0, fpsStart = performance.now();
function tickFps() {
  fpsCount++;
  const now = performance.now();
  if (now - fpsStart >= 500) { state.fps = fpsCount * 1000 / (now - fpsStart); fpsCount = 0; fpsStart = now; }
}

// draw only when something changed (a new frame, the camera): software GL stays cheap
orbit.addEventListener('change', () => { dirty = true; moving = true; });
renderer.setAnimationLoop((now) => {
  orbit.update();
  if (state.playing) advance();
  applyPending();
  const moved = moving;             // a new frame or camera move (each also set dirty)
  moving = false;
  if (dirty) { renderer.render(scene, camera); dirty = false; state.draws = (state.draws || 0) + 1; }
  tune(now, moved);
});

// ---------------------------------------------------------------- socket
const status = document.getElementById('status');
function say(msg, err) { status.textContent = msg; status.className = err ? 'err' : ''; if (err) state.lastError = msg; }
const token = new URLSearchParams(location.search).get('token') || '';   // the server's per-run secret
const ws = new WebSocket(`ws://${location.host}/ws?token=${encodeURIComponent(token)}`);
ws.binaryType = 'arraybuffer';
let faceFramed = false;
ws.onopen = () => say('connected');
ws.onclose = () => say('disconnected', true);
ws.onmessage = (ev) => {
  if (typeof ev.data === 'string') {
    const m = JSON.parse(ev.data);
    if (m.type === 'init') init(m);
    else if (m.type === 'error') say(m.message, true);
    else if (m.type === 'loaded') { say(`second face: ${m.name} (${m.n_vertices} vertices)`); }
    else if (m.type === 'made') making(m.made, m.of);
    return;
  }
  const kind = new Uint32Array(ev.data, 0, 1)[0];
  if (kind === 2) face.geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(ev.data, 4), 1));
  else if (kind === 3) second.geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(ev.data, 4), 1));
  else if (kind === 0) pendingFace = new Float32Array(ev.data, 4);    // shown at the next animation frame
  else if (kind === 1) pendingSecond = new Float32Array(ev.data, 4);
};
// frames that arrive faster than the page draws are coalesced: the newest one is shown
let pendingFace = null, pendingSecond = null;
function applyPending() {
  if (pendingFace) {
    setPositions(face, pendingFace, !faceFramed);
    faceFramed = true;
    pendingFace = null;
    state.framesApplied++; state.version++; tickFps();
    moving = true;
    send({ type: 'ack' });
  }
  if (pendingSecond) {
    const arr = pendingSecond;
    pendingSecond = null;
    if (!state.secondLoaded) {
      face.geometry.computeBoundingBox();
      const bb = face.geometry.boundingBox;
      second.position.x = (bb.max.x - bb.min.x) * 1.25;
    }
    const firstTime = !state.secondLoaded;
    setPositions(second, arr, false);
    if (firstTime) frameCamera(face, second);
    state.secondLoaded = true;
  }
}
function send(m) { if (ws.readyState === 1) ws.send(JSON.stringify(m)); }
state.send = send;

// ---------------------------------------------------------------- controls
const sliders = {};
function slider(parent, name, min, max, step, value, onInput) {
  const label = document.createElement('label');
  label.textContent = name.replace(/_/g, ' ');
  const input = document.createElement('input');
  Object.assign(input, { type: 'range', min, max, step, value });
  input.dataset.name = name;
  const out = document.createElement('output');
  out.textContent = Number(value).toFixed(2);
  input.addEventListener('input', () => { out.textContent = Number(input.value).toFixed(2); onInput(Number(input.value)); });
  label.append(input, out);
  parent.appendChild(label);
  sliders[name] = { input, out };
  return input;
}
function setSlider(name, v) { const s = sliders[name]; if (s) { s.input.value = v; s.out.textContent = Number(v).toFixed(2); } }

function init(m) {
  state.controls = m;
  document.getElementById('title').textContent = m.title;
  const mus = document.getElementById('muscles');
  for (const n of m.muscles) slider(mus, n, -1, 1, 0.01, 0, (v) => send({ type: 'set', name: n, value: v }));
  const act = document.getElementById('actions');
  for (const n of m.actions) slider(act, n, 0, 1, 0.01, 0, (v) => send({ type: 'set', name: n, value: v }));
  const pre = document.getElementById('presets');
  for (const n of ['neutral', ...m.presets.filter((x) => x !== 'neutral')]) {
    const b = document.createElement('button');
    b.textContent = n;
    b.onclick = () => { send({ type: 'preset', name: n }); for (const k of m.muscles) setSlider(k, 0); };
    pre.appendChild(b);
  }
  if (m.age) {
    document.getElementById('age-box').hidden = false;
    const a = document.getElementById('age');
    if (typeof m.age_value === 'number') { a.value = m.age_value; document.getElementById('age-out').textContent = a.value; }
    a.addEventListener('input', () => { document.getElementById('age-out').textContent = a.value; send({ type: 'set', name: 'age', value: Number(a.value) }); });
  }
  const sel = document.getElementById('channel');
  for (const n of [...m.muscles, ...m.actions, ...(m.age ? ['age'] : [])]) {
    const o = document.createElement('option'); o.value = o.textContent = n; sel.appendChild(o);
  }
  timeline.format = m.timeline_format;
  drawCurve();
  state.ready = true;
  if (m.of > 0 && m.made < m.of) making(m.made, m.of); else say('ready');
}
// the face's force systems made beside the page: the ones moved first; it plays as they come
function making(k, n) {
  state.made = [k, n];
  if (k >= n) say('ready');
  else say(`making the muscles: ${k} of ${n} (those you move come first)`);
}

document.getElementById('second').addEventListener('change', async (ev) => {
  const f = ev.target.files[0];
  if (!f) return;
  say(`transferring onto ${f.name}…`);
  send({ type: 'load', name: f.name, obj: await f.text() });
});

// ---------------------------------------------------------------- timeline
const timeline = { duration: 2, channels: {}, format: 'mimica-timeline/1' };
state.timeline = timeline;
const canvas = document.getElementById('curve');
const ctx = canvas.getContext('2d');
const chanSel = document.getElementById('channel');
const durIn = document.getElementById('duration');
const scrub = document.getElementById('scrub');
const timeOut = document.getElementById('time');
durIn.addEventListener('change', () => { timeline.duration = Math.max(0.2, Number(durIn.value) || 2); drawCurve(); });
chanSel.addEventListener('change', drawCurve);

function range(name) { return name === 'age' ? [15, 95] : (name.startsWith('AU') ? [0, 1] : [-1, 1]); }
function evalChannel(keys, t) {
  if (!keys.length) return 0;
  if (t <= keys[0][0]) return keys[0][1];
  for (let i = 1; i < keys.length; i++) {
    if (t <= keys[i][0]) {
      const [t0, v0] = keys[i - 1], [t1, v1] = keys[i];
      const u = (t - t0) / Math.max(t1 - t0, 1e-9);
      return v0 + (v1 - v0) * u;
    }
  }
  return keys[keys.length - 1][1];
}
function pose(t) {
  const values = {};
  for (const [n, c] of Object.entries(timeline.channels)) if (c.keys.length) values[n] = evalChannel(c.keys, t);
  return values;
}
function applyTime(t) {
  state.time = t;
  timeOut.textContent = `${t.toFixed(2)} s`;
  scrub.value = Math.round(1000 * t / timeline.duration);
  const values = pose(t);
  if (Object.keys(values).length) {
    send({ type: 'pose', values });
    for (const [n, v] of Object.entries(values)) setSlider(n, v);
  }
  drawCurve();
}
let playStart = 0;
function advance() {
  let t = (performance.now() - playStart) / 1000;
  if (t > timeline.duration) { playStart = performance.now(); t = 0; }
  applyTime(t);
}
document.getElementById('play').addEventListener('click', (ev) => {
  state.playing = !state.playing;
  ev.target.textContent = state.playing ? '❚❚ pause' : '▶ play';
  playStart = performance.now() - state.time * 1000;
});
scrub.addEventListener('input', () => { state.playing = false; document.getElementById('play').textContent = '▶ play'; applyTime(timeline.duration * scrub.value / 1000); });

function toCanvas(t, v, name) {
  const [lo, hi] = range(name);
  return [t / timeline.duration * canvas.width, canvas.height - (v - lo) / (hi - lo) * canvas.height];
}
function fromCanvas(x, y, name) {
  const [lo, hi] = range(name);
  return [Math.min(Math.max(x / canvas.width * timeline.duration, 0), timeline.duration),
          Math.min(Math.max(lo + (canvas.height - y) / canvas.height * (hi - lo), lo), hi)];
}
function drawCurve() {
  const name = chanSel.value;
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.strokeStyle = '#444'; ctx.beginPath();
  const [, zy] = toCanvas(0, 0, name || 'x'); ctx.moveTo(0, zy); ctx.lineTo(canvas.width, zy); ctx.stroke();
  const x = state.time / timeline.duration * canvas.width;
  ctx.strokeStyle = '#c84'; ctx.beginPath(); ctx.moveTo(x, 0); ctx.lineTo(x, canvas.height); ctx.stroke();
  for (const [n, c] of Object.entries(timeline.channels)) {
    if (!c.keys.length) continue;
    ctx.strokeStyle = n === name ? '#7cf' : '#567';
    ctx.beginPath();
    for (let i = 0; i <= 200; i++) {
      const t = timeline.duration * i / 200;
      const [px, py] = toCanvas(t, evalChannel(c.keys, t), n);
      if (i) ctx.lineTo(px, py); else ctx.moveTo(px, py);
    }
    ctx.stroke();
    if (n === name) for (const [t, v] of c.keys) { const [px, py] = toCanvas(t, v, n); ctx.fillStyle = '#fff'; ctx.fillRect(px - 3, py - 3, 6, 6); }
  }
}
let dragging = null;
function canvasXY(ev) { const r = canvas.getBoundingClientRect(); return [(ev.clientX - r.left) * canvas.width / r.width, (ev.clientY - r.top) * canvas.height / r.height]; }
canvas.addEventListener('mousedown', (ev) => {
  const name = chanSel.value;
  if (!name) return;
  const c = timeline.channels[name] || (timeline.channels[name] = { interp: 'linear', keys: [] });
  const [x, y] = canvasXY(ev);
  const hit = c.keys.findIndex(([t, v]) => { const [px, py] = toCanvas(t, v, name); return Math.hypot(px - x, py - y) < 8; });
  if (ev.shiftKey) { if (hit >= 0) c.keys.splice(hit, 1); drawCurve(); return; }
  if (hit >= 0) { dragging = c.keys[hit]; return; }
  const k = fromCanvas(x, y, name);
  c.keys.push(k); c.keys.sort((a, b) => a[0] - b[0]); dragging = k; drawCurve();
});
canvas.addEventListener('mousemove', (ev) => {
  if (!dragging) return;
  const [x, y] = canvasXY(ev);
  const k = fromCanvas(x, y, chanSel.value);
  dragging[0] = k[0]; dragging[1] = k[1];
  timeline.channels[chanSel.value].keys.sort((a, b) => a[0] - b[0]);
  drawCurve();
});
window.addEventListener('mouseup', () => { dragging = null; });

document.getElementById('save').addEventListener('click', () => {
  const doc = { format: timeline.format, duration: timeline.duration, channels: {} };
  for (const [n, c] of Object.entries(timeline.channels)) if (c.keys.length) doc.channels[n] = { interp: 'linear', keys: c.keys };
  const a = document.createElement('a');
  a.href = URL.createObjectURL(new Blob([JSON.stringify(doc, null, 1)], { type: 'application/json' }));
  a.download = 'timeline.json';
  a.click();
});
document.getElementById('load').addEventListener('change', async (ev) => {
  const f = ev.target.files[0];
  if (!f) return;
  try {
    const doc = JSON.parse(await f.text());
    if (doc.format !== timeline.format) throw new Error(`expected format ${timeline.format}`);
    timeline.duration = doc.duration || 2; durIn.value = timeline.duration;
    timeline.channels = {};
    for (const [n, c] of Object.entries(doc.channels || {})) timeline.channels[n] = { interp: 'linear', keys: c.keys.map((k) => [Number(k[0]), Number(k[1])]) };
    drawCurve();
    say(`timeline: ${f.name}`);
  } catch (e) { say(`${f.name}: ${e.message}`, true); }
});
