// The page vdyn-foxglove serves: the same WebSocket and channels as Foxglove uses (protocol
// foxglove.websocket.v1), drawn with three.js (Debian's libjs-three, served by vdyn-foxglove):
// the terrain from /vdyn/world, every vehicle from its /scene and /tf (car, wheels, force arrows
// in the viewer's colours), a camera that follows one vehicle, and live plots of its speed, yaw
// rate and wheel forces from its /state. No file from elsewhere; works on a phone or tablet.
"use strict";

// --- the protobuf wire format, read directly (only the fields drawn here) ---------------------
// Calls fn(field, wireType, view, at, end) for each field of bytes [start, end); for a
// length-delimited field [at, end) is its content, for the others `at` is where its value starts
// (varints are decoded into `at` as a Number instead).
function fields(view, start, end, fn) {
  let i = start;
  const varint = () => {
    let v = 0, m = 1, b;
    do {
      b = view.getUint8(i++);
      v += (b & 0x7f) * m;
      m *= 128;
    } while (b & 0x80);
    return v;
  };
  while (i < end) {
    const key = varint();
    const f = Math.floor(key / 8), w = key & 7;
    if (w === 0) fn(f, 0, view, varint(), 0);
    else if (w === 1) { fn(f, 1, view, i, i + 8); i += 8; }
    else if (w === 2) { const n = varint(); fn(f, 2, view, i, i + n); i += n; }
    else if (w === 5) { fn(f, 5, view, i, i + 4); i += 4; }
    else throw new Error("wire type " + w);
  }
}
const f64 = (view, at) => view.getFloat64(at, true);
function vec(view, s, e) {  // Vector3, Point3 (x 1, y 2, z 3) and Quaternion (w 4)
  const v = { x: 0, y: 0, z: 0, w: 0 };
  fields(view, s, e, (f, w, _, a) => { if (w === 1) v["?xyzw"[f]] = f64(view, a); });
  return v;
}
function color(view, s, e) {
  const c = { r: 0, g: 0, b: 0, a: 0 };
  fields(view, s, e, (f, w, _, a) => { if (w === 1) c["?rgba"[f]] = f64(view, a); });
  return c;
}
function pose(view, s, e) {
  const p = { p: { x: 0, y: 0, z: 0 }, q: { x: 0, y: 0, z: 0, w: 1 } };
  fields(view, s, e, (f, w, _, a, b) => {
    if (f === 1) p.p = vec(view, a, b);
    if (f === 2) { p.q = vec(view, a, b); }
  });
  return p;
}
const text = (view, s, e) => new TextDecoder().decode(new Uint8Array(view.buffer, view.byteOffset + s, e - s));

// foxglove.SceneUpdate: the entities and the primitives drawn here.
function decodeScene(view) {
  const entities = [];
  fields(view, 0, view.byteLength, (f, w, _, s, e) => {
    if (f !== 2) return;
    const ent = { id: "", frame: "", locked: false, arrows: [], cubes: [], cylinders: [], triangles: [] };
    fields(view, s, e, (g, w2, _2, a, b) => {
      if (g === 2) ent.frame = text(view, a, b);
      else if (g === 3) ent.id = text(view, a, b);
      else if (g === 5) ent.locked = a !== 0;
      else if (g === 7) {
        const ar = { pose: null, shaft: 0, shaftD: 0, head: 0, headD: 0, color: null };
        fields(view, a, b, (h, w3, _3, c, d) => {
          if (h === 1) ar.pose = pose(view, c, d);
          else if (h === 2) ar.shaft = f64(view, c);
          else if (h === 3) ar.shaftD = f64(view, c);
          else if (h === 4) ar.head = f64(view, c);
          else if (h === 5) ar.headD = f64(view, c);
          else if (h === 6) ar.color = color(view, c, d);
        });
        ent.arrows.push(ar);
      } else if (g === 8 || g === 10) {
        const p = { pose: null, size: null, color: null };
        fields(view, a, b, (h, w3, _3, c, d) => {
          if (h === 1) p.pose = pose(view, c, d);
          else if (h === 2) p.size = vec(view, c, d);
          else if ((g === 8 && h === 3) || (g === 10 && h === 5)) p.color = color(view, c, d);
        });
        (g === 8 ? ent.cubes : ent.cylinders).push(p);
      } else if (g === 12) {
        const t = { points: [], indices: [], color: null };
        fields(view, a, b, (h, w3, _3, c, d) => {
          if (h === 2) { const v = vec(view, c, d); t.points.push(v.x, v.y, v.z); }
          else if (h === 3) t.color = color(view, c, d);
          else if (h === 5 && w3 === 2) for (let k = c; k < d; k += 4) t.indices.push(view.getUint32(k, true));
          else if (h === 5 && w3 === 5) t.indices.push(view.getUint32(c, true));
        });
        ent.triangles.push(t);
      }
    });
    entities.push(ent);
  });
  return entities;
}

// foxglove.FrameTransforms.
function decodeTransforms(view) {
  const out = [];
  fields(view, 0, view.byteLength, (f, w, _, s, e) => {
    if (f !== 1) return;
    const t = { parent: "", child: "", p: { x: 0, y: 0, z: 0 }, q: { x: 0, y: 0, z: 0, w: 1 } };
    fields(view, s, e, (g, w2, _2, a, b) => {
      if (g === 2) t.parent = text(view, a, b);
      else if (g === 3) t.child = text(view, a, b);
      else if (g === 4) t.p = vec(view, a, b);
      else if (g === 5) t.q = vec(view, a, b);
    });
    out.push(t);
  });
  return out;
}

// vdyn.pb.VehicleState: what the plots show.
function decodeState(view) {
  const s = { id: 0, simNs: 0, speed: 0, yawRate: 0, fp: [0, 0, 0, 0], fy: [0, 0, 0, 0] };
  let wheel = 0;
  fields(view, 0, view.byteLength, (f, w, _, a, b) => {
    if (f === 1 && w === 0) s.id = a;
    else if (f === 4 && w === 0) s.simNs = a;
    else if (f === 23 && w === 1) s.speed = f64(view, a);
    else if (f === 11 && w === 2) s.yawRate = vec(view, a, b).z;
    else if (f === 18 && w === 2) {
      const k = wheel++;
      fields(view, a, b, (g, w2, _2, c) => {
        if (g === 2 && w2 === 1) s.fp[k] = f64(view, c);
        else if (g === 5 && w2 === 1) s.fy[k] = f64(view, c);
      });
    }
  });
  return s;
}

// --- the scene ------------------------------------------------------------------------------
const view3d = document.getElementById("view");
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
view3d.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x9cc4e4);
scene.fog = new THREE.Fog(0x9cc4e4, 250, 900);
const camera = new THREE.PerspectiveCamera(55, 1, 0.1, 3000);
camera.up.set(0, 0, 1);
camera.position.set(-30, -30, 25);
scene.add(new THREE.HemisphereLight(0xe8f0ff, 0x4a5038, 0.75));
const sun = new THREE.DirectionalLight(0xffffff, 0.7);
sun.position.set(0.4, -0.6, 1);
scene.add(sun);

const unitBox = new THREE.BoxBufferGeometry(1, 1, 1);
const unitCylinder = new THREE.CylinderBufferGeometry(0.5, 0.5, 1, 24).rotateX(Math.PI / 2);  // axis Z
const shaftGeometry = new THREE.CylinderBufferGeometry(0.5, 0.5, 1, 10).rotateZ(-Math.PI / 2).translate(0.5, 0, 0);
const headGeometry = new THREE.ConeBufferGeometry(0.5, 1, 14).rotateZ(-Math.PI / 2).translate(0.5, 0, 0);
const materials = new Map();
function material(c, lit = true) {
  const key = [c.r, c.g, c.b, c.a, lit].join();
  let m = materials.get(key);
  if (!m) {
    const opts = { color: new THREE.Color(c.r, c.g, c.b), transparent: c.a < 1, opacity: c.a };
    // Arrows are unlit and no body hides them (as in vdyn-viewer: the forces are the point).
    m = lit ? new THREE.MeshLambertMaterial(opts) : new THREE.MeshBasicMaterial({ ...opts, depthTest: false });
    materials.set(key, m);
  }
  return m;
}

const frames = new Map();  // child frame -> {parent, p, q}
function worldMatrix(frame, out, depth = 0) {
  if (frame === "world" || depth > 8) return out.identity();
  const t = frames.get(frame);
  if (!t) return null;
  if (!worldMatrix(t.parent, out, depth + 1)) return null;
  const m = new THREE.Matrix4().compose(new THREE.Vector3(t.p.x, t.p.y, t.p.z),
                                        new THREE.Quaternion(t.q.x, t.q.y, t.q.z, t.q.w), new THREE.Vector3(1, 1, 1));
  return out.multiply(m);
}

// One group per entity (by topic and id), its meshes reused from update to update.
const entities = new Map();
function placed(obj, p) {
  obj.position.set(p.p.x, p.p.y, p.p.z);
  obj.quaternion.set(p.q.x, p.q.y, p.q.z, p.q.w);
}
function updateEntity(key, ent) {
  let g = entities.get(key);
  if (!g) {
    g = { group: new THREE.Group(), ent: null, meshes: [] };
    g.group.matrixAutoUpdate = false;
    scene.add(g.group);
    entities.set(key, g);
  }
  g.ent = ent;
  let k = 0;
  const mesh = (geometry, mat) => {
    let m = g.meshes[k];
    if (!m) { m = new THREE.Object3D(); g.group.add(m); g.meshes.push(m); }
    k++;
    if (m.userData.geometry !== geometry) {
      m.clear ? m.clear() : m.children.slice().forEach((c) => m.remove(c));
      m.userData.geometry = geometry;
      m.userData.parts = geometry.map((geo) => { const x = new THREE.Mesh(geo, mat); m.add(x); return x; });
    }
    for (const x of m.userData.parts) {
      x.material = mat;
      x.renderOrder = mat.depthTest ? 0 : 10;
    }
    m.visible = true;
    return m;
  };
  for (const c of ent.cubes) {
    const m = mesh([unitBox], material(c.color));
    placed(m, c.pose);
    m.scale.set(c.size.x, c.size.y, c.size.z);
  }
  for (const c of ent.cylinders) {
    const m = mesh([unitCylinder], material(c.color));
    placed(m, c.pose);
    m.scale.set(c.size.x, c.size.y, c.size.z);
  }
  for (const a of ent.arrows) {
    const m = mesh([shaftGeometry, headGeometry], material(a.color, false));
    placed(m, a.pose);
    m.scale.set(1, 1, 1);
    const [shaft, head] = m.userData.parts;
    shaft.scale.set(Math.max(a.shaft, 1e-6), a.shaftD, a.shaftD);
    head.position.set(a.shaft, 0, 0);
    head.scale.set(Math.max(a.head, 1e-6), a.headD, a.headD);
    m.visible = a.shaft + a.head > 0.01;
  }
  for (; k < g.meshes.length; ++k) g.meshes[k].visible = false;
}

function addTerrain(ent) {
  for (const t of ent.triangles) {
    const geo = new THREE.BufferGeometry();
    geo.setAttribute("position", new THREE.Float32BufferAttribute(t.points, 3));
    if (t.indices.length) geo.setIndex(t.indices);
    geo.computeVertexNormals();
    const mat = new THREE.MeshLambertMaterial({ color: new THREE.Color(t.color.r, t.color.g, t.color.b),
                                                transparent: t.color.a < 1, opacity: t.color.a, side: THREE.DoubleSide });
    const mesh = new THREE.Mesh(geo, mat);
    mesh.userData.world = true;
    scene.add(mesh);
    stats.worldTriangles += (t.indices.length || t.points.length / 3) / 3;
  }
}

// --- the connection -------------------------------------------------------------------------
const stats = { connected: false, states: 0, scenes: 0, transforms: 0, worldTriangles: 0, followed: 0,
                pose: null, plotted: 0, speedKmh: 0, status: [] };
window.vdyn = stats;
const channels = new Map(), subscriptions = new Map();
let nextSub = 1, ws = null, stateSub = null;
const params = new URLSearchParams(location.search);
let follow = Number(params.get("follow")) || 0;

function send(o) { if (ws && ws.readyState === 1) ws.send(JSON.stringify(o)); }
function subscribe(ch) {
  const id = nextSub++;
  subscriptions.set(id, ch);
  send({ op: "subscribe", subscriptions: [{ id, channelId: ch.id }] });
  return id;
}
function vehicleIds() {
  return [...channels.values()].map((c) => (c.topic.match(/^\/vehicle\/(\d+)\/state$/) || [])[1])
    .filter(Boolean).map(Number).sort((a, b) => a - b);
}
function followVehicle(id) {
  follow = id;
  stats.followed = id;
  if (stateSub !== null) { send({ op: "unsubscribe", subscriptionIds: [stateSub] }); subscriptions.delete(stateSub); stateSub = null; }
  for (const p of plots) p.clear();
  const ch = [...channels.values()].find((c) => c.topic === `/vehicle/${id}/state`);
  if (ch) stateSub = subscribe(ch);
  drawButtons();
}
function drawButtons() {
  const box = document.getElementById("vehicles");
  box.textContent = "";
  for (const id of vehicleIds()) {
    const b = document.createElement("button");
    b.textContent = "vehicle " + id;
    b.className = id === follow ? "on" : "";
    b.onclick = () => followVehicle(id);
    box.appendChild(b);
  }
}
let statusTimer = null;
function setStatus(t, seconds = 0) {
  const el = document.getElementById("status");
  el.textContent = t;
  clearTimeout(statusTimer);
  if (seconds) statusTimer = setTimeout(() => (el.textContent = "connected"), seconds * 1000);
}

function onJson(m) {
  if (m.op === "serverInfo") setStatus(`${m.name}: connected`);
  else if (m.op === "status") { stats.status.push(m); setStatus(m.message, 6); }
  else if (m.op === "advertise") {
    for (const ch of m.channels) {
      channels.set(ch.id, ch);
      if (ch.topic === "/vdyn/world" || /^\/vehicle\/\d+\/(scene|tf)$/.test(ch.topic)) subscribe(ch);
    }
    const ids = vehicleIds();
    if (ids.length && (!follow || !ids.includes(follow) || stateSub === null)) followVehicle(ids.includes(follow) ? follow : ids[0]);
    drawButtons();
  } else if (m.op === "unadvertise") {
    for (const id of m.channelIds) {
      const ch = channels.get(id);
      channels.delete(id);
      if (ch) for (const [key, g] of entities) if (key.startsWith(ch.topic + "#")) { scene.remove(g.group); entities.delete(key); }
    }
    for (const [sid, ch] of subscriptions) if (!channels.has(ch.id)) subscriptions.delete(sid);
    drawButtons();
  }
}

function onBinary(buf) {
  const view = new DataView(buf);
  if (view.getUint8(0) !== 1) return;  // time messages: the states carry the clock here
  const ch = subscriptions.get(view.getUint32(1, true));
  if (!ch) return;
  const payload = new DataView(buf, 13);
  if (ch.topic === "/vdyn/world") {
    for (const ent of decodeScene(payload)) addTerrain(ent);
  } else if (ch.topic.endsWith("/scene")) {
    stats.scenes++;
    for (const ent of decodeScene(payload)) updateEntity(ch.topic + "#" + ent.id, ent);
  } else if (ch.topic.endsWith("/tf")) {
    stats.transforms++;
    for (const t of decodeTransforms(payload)) frames.set(t.child, t);
  } else if (ch.topic.endsWith("/state")) {
    const s = decodeState(payload);
    stats.states++;
    stats.speedKmh = s.speed;
    plots[0].add(s.simNs, [s.speed]);
    plots[1].add(s.simNs, [s.yawRate * 180 / Math.PI]);
    plots[2].add(s.simNs, s.fp.map((x) => x / 1000));
    plots[3].add(s.simNs, s.fy.map((x) => x / 1000));
  }
}

function connect() {
  const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/";
  ws = new WebSocket(url, ["foxglove.websocket.v1"]);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => { stats.connected = true; };
  ws.onmessage = (e) => (typeof e.data === "string" ? onJson(JSON.parse(e.data)) : onBinary(e.data));
  ws.onclose = () => {
    stats.connected = false;
    setStatus("disconnected: reconnecting…");
    channels.clear();
    subscriptions.clear();
    stateSub = null;
    setTimeout(connect, 1500);
  };
}

// --- plots: the last 10 s of the followed vehicle's states ------------------------------------
class Plot {
  constructor(canvas, title, unit, names, colours) {
    Object.assign(this, { canvas, title, unit, names, colours, t: [], v: [] });
  }
  clear() { this.t = []; this.v = []; }
  add(ns, values) {
    // One point per 10 ms of simulation time is plenty for a screen.
    if (this.t.length && ns - this.t[this.t.length - 1] < 10e6 && ns >= this.t[this.t.length - 1]) return;
    if (this.t.length && ns < this.t[this.t.length - 1]) this.clear();  // a reset or another vehicle
    this.t.push(ns);
    this.v.push(values);
    while (this.t.length && ns - this.t[0] > 10e9) { this.t.shift(); this.v.shift(); }
    stats.plotted++;
  }
  draw() {
    const c = this.canvas, dpr = window.devicePixelRatio || 1;
    const w = Math.round(c.clientWidth * dpr), h = Math.round(c.clientHeight * dpr);
    if (c.width !== w || c.height !== h) { c.width = w; c.height = h; }
    const g = c.getContext("2d");
    g.clearRect(0, 0, w, h);
    g.font = `${12 * dpr}px system-ui, sans-serif`;
    g.fillStyle = "#aab4c0";
    const last = this.v.length ? this.v[this.v.length - 1] : null;
    g.fillText(`${this.title} (${this.unit})` + (last && last.length === 1 ? `  ${last[0].toFixed(1)}` : ""), 6 * dpr, 14 * dpr);
    if (this.t.length < 2) return;
    let lo = Infinity, hi = -Infinity;
    for (const vs of this.v) for (const x of vs) { lo = Math.min(lo, x); hi = Math.max(hi, x); }
    if (hi - lo < 1e-6) { hi += 1; lo -= 1; }
    const pad = 0.08 * (hi - lo); lo -= pad; hi += pad;
    const t1 = this.t[this.t.length - 1], t0 = t1 - 10e9;
    const X = (t) => 40 * dpr + (w - 46 * dpr) * (t - t0) / 10e9;
    const Y = (v) => 20 * dpr + (h - 26 * dpr) * (hi - v) / (hi - lo);
    g.strokeStyle = "#2c3642";
    g.beginPath(); g.moveTo(X(t0), Y(0)); g.lineTo(X(t1), Y(0)); g.stroke();
    g.fillText(hi.toFixed(hi - lo < 10 ? 1 : 0), 2 * dpr, Y(hi) + 10 * dpr);
    g.fillText(lo.toFixed(hi - lo < 10 ? 1 : 0), 2 * dpr, Y(lo));
    g.lineWidth = 1.5 * dpr;
    for (let k = 0; k < this.v[0].length; ++k) {
      g.strokeStyle = this.colours[k];
      g.beginPath();
      this.t.forEach((t, i) => (i ? g.lineTo(X(t), Y(this.v[i][k])) : g.moveTo(X(t), Y(this.v[i][k]))));
      g.stroke();
    }
    this.names.forEach((n, k) => { g.fillStyle = this.colours[k]; g.fillText(n, w - (this.names.length - k) * 28 * dpr, 14 * dpr); });
  }
}
const wheelColours = ["#5aa0e0", "#e0a05a", "#7ed07e", "#d07ec8"];  // LF, RF, LR, RR
const wheels = ["LF", "RF", "LR", "RR"];
const plots = [
  new Plot(document.getElementById("plot-speed"), "speed", "km/h", [], ["#5aa0e0"]),
  new Plot(document.getElementById("plot-yaw"), "yaw rate", "deg/s", [], ["#e0a05a"]),
  new Plot(document.getElementById("plot-fp"), "wheel load Fp", "kN", wheels, wheelColours),
  new Plot(document.getElementById("plot-fy"), "side force Fy", "kN", wheels, wheelColours),
];

const legend = [["spring Fp", "#28c83c"], ["drive Fh", "#286eff"], ["brake Fb", "#eb2828"], ["side Fy", "#ffd200"],
                ["drag", "#dc3cdc"], ["wall", "#ff8200"]];
document.getElementById("legend").innerHTML = legend.map(([n, c]) => `<span style="background:${c}"></span>${n}`).join("");

// --- the camera: behind the followed vehicle, turned and zoomed by drag, pinch or wheel ------
let orbit = 0.6, distance = 8;  // behind the car and to its left
const pointers = new Map();
view3d.addEventListener("pointerdown", (e) => { pointers.set(e.pointerId, e); view3d.setPointerCapture(e.pointerId); });
view3d.addEventListener("pointerup", (e) => pointers.delete(e.pointerId));
view3d.addEventListener("pointercancel", (e) => pointers.delete(e.pointerId));
view3d.addEventListener("pointermove", (e) => {
  const old = pointers.get(e.pointerId);
  if (!old) return;
  if (pointers.size === 1) orbit -= (e.clientX - old.clientX) * 0.01;
  else if (pointers.size === 2) {
    const other = [...pointers.values()].find((p) => p.pointerId !== e.pointerId);
    const before = Math.hypot(old.clientX - other.clientX, old.clientY - other.clientY);
    const now = Math.hypot(e.clientX - other.clientX, e.clientY - other.clientY);
    if (before > 0) distance = Math.min(80, Math.max(3, distance * before / now));
  }
  pointers.set(e.pointerId, e);
});
view3d.addEventListener("wheel", (e) => { e.preventDefault(); distance = Math.min(80, Math.max(3, distance * Math.exp(e.deltaY * 0.001))); }, { passive: false });

const m4 = new THREE.Matrix4();
function frame() {
  requestAnimationFrame(frame);
  const w = view3d.clientWidth, h = view3d.clientHeight;
  if (renderer.domElement.width !== Math.round(w * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
  }
  for (const g of entities.values()) {
    if (g.ent.locked) {
      const m = worldMatrix(g.ent.frame, m4);
      g.group.visible = !!m;
      if (m) g.group.matrix.copy(m);
    } else {
      g.group.matrix.identity();
    }
    g.group.matrixWorldNeedsUpdate = true;
  }
  const body = worldMatrix(`vehicle/${follow}/body`, m4);
  if (body) {
    const p = new THREE.Vector3().setFromMatrixPosition(body);
    const x = new THREE.Vector3(1, 0, 0).transformDirection(body);
    const yaw = Math.atan2(x.y, x.x) + Math.PI + orbit;
    const want = new THREE.Vector3(p.x + distance * Math.cos(yaw), p.y + distance * Math.sin(yaw), p.z + 0.35 * distance + 1);
    camera.position.lerp(want, 0.15);
    camera.lookAt(p.x, p.y, p.z + 0.5);
    stats.pose = { x: p.x, y: p.y, z: p.z };
    document.getElementById("hud").textContent = `vehicle ${follow}  ${stats.speedKmh.toFixed(0)} km/h`;
  }
  renderer.render(scene, camera);
  for (const p of plots) p.draw();
}

connect();
frame();
