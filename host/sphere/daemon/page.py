"""The 3-D page served by the stream (sphere.daemon.stream3d), with everything it loads shipped in the
package (``static/``: three.js r170 from npm, with its licence), so it works with no network.

A three.js scene: the sphere (a shaded shell with latitude rings, so a turn shows), its axes (x red
towards the screen at the reference pose, y green to the left, z blue up), a floor grid, hemisphere and
directional lighting with a shadow; the shell is see-through so the axes show inside it. The sphere turns with the orientation relative to the pose at
connection or at the last recentre, and moves with ``position`` (metres, relative to the first position
received) when a pose source sends one. The status text has ids the tests read (``status``, ``quat``,
``mode``, ``event``, ``count``, ``turn``, ``position``, ``renderer``, ``cameradiag``).

The AR view (the "camera view" box, or ``/?ar=1``; with a camera): the webcam's frames, each with a virtual
object drawn where the hybrid tracker puts the ball at the frame's exposure (a ring of the ball's size and
its three axes, orientation from the sphere through the camera's alignment) and the detector's outline
(dashed; none when the camera lost the ball: the object stays on it from the IMU). Projected with the
camera's intrinsics and OpenCV's lens distortion, as the detector measures. ``window.arLog`` keeps, per
frame drawn, the frame's index and the object's centre (px) for tests.

    static_response("/static/three.module.min.js")  # -> (body text, content type) or None
"""

from __future__ import annotations

from pathlib import Path

STATIC_DIR = Path(__file__).resolve().parent / "static"
STATIC_PREFIX = "/static/"
_TYPES = {".js": "text/javascript; charset=utf-8", ".md": "text/plain; charset=utf-8",
          ".LICENSE": "text/plain; charset=utf-8"}


def static_response(path: str) -> tuple[str, str] | None:
    """(body, content type) of a shipped static file for a request path under /static/, else None."""
    if not path.startswith(STATIC_PREFIX):
        return None
    name = path[len(STATIC_PREFIX):]
    if "/" in name or name.startswith(".") or not name:
        return None
    f = STATIC_DIR / name
    kind = _TYPES.get(f.suffix)
    if kind is None or not f.is_file():
        return None
    return f.read_text(encoding="utf-8"), kind


PAGE_HTML = r"""<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>MARG sphere — 3-D view</title>
<style>
  body { margin: 0; background: #15171c; color: #ddd; font: 14px system-ui, sans-serif; overflow: hidden; }
  #hud { position: absolute; left: 12px; top: 10px; line-height: 1.5; background: rgba(0,0,0,.35);
         padding: 6px 10px; border-radius: 6px; }
  #hud b { color: #fff; }
  #view { display: block; width: 100vw; height: 100vh; }
  #legend span { display: inline-block; width: 10px; height: 10px; margin: 0 3px 0 8px; }
  button { margin-top: 6px; }
  #ar { position: absolute; right: 10px; bottom: 10px; max-width: 60vw; max-height: 70vh; display: none;
        border: 1px solid #444; background: #000; }
</style>
<script type="importmap">{"imports": {"three": "/static/three.module.min.js"}}</script>
</head>
<body>
<div id="view"></div>
<canvas id="ar" width="640" height="480"></canvas>
<div id="hud">
  <div><b>MARG sphere</b> · <span id="status">connecting…</span> · <span id="renderer">starting</span></div>
  <div>mode <span id="mode">?</span> · messages <span id="count">0</span></div>
  <div>quat <span id="quat">–</span> · turned <span id="turn">0.0</span>° from the reference pose</div>
  <div>position <span id="position">–</span></div>
  <div>camera <span id="cameradiag">–</span> · <label><input type="checkbox" id="arbox"> camera view (AR)</label></div>
  <div>last event <span id="event">–</span></div>
  <div id="legend"><span style="background:#f44"></span>x <span style="background:#4d4"></span>y
       <span style="background:#48f"></span>z</div>
  <button id="recentre">recentre view</button>
</div>
<script type="module">
"use strict";
const $ = (id) => document.getElementById(id);
let q = [1, 0, 0, 0], ref = null, pos0 = null, count = 0, pending = false;  // one render per frame at most

function mul(a, b) {
  return [a[0]*b[0] - a[1]*b[1] - a[2]*b[2] - a[3]*b[3],
          a[0]*b[1] + a[1]*b[0] + a[2]*b[3] - a[3]*b[2],
          a[0]*b[2] - a[1]*b[3] + a[2]*b[0] + a[3]*b[1],
          a[0]*b[3] + a[1]*b[2] - a[2]*b[1] + a[3]*b[0]];
}
const conj = (a) => [a[0], -a[1], -a[2], -a[3]];
function rotate(a, v) { return mul(mul(a, [0, v[0], v[1], v[2]]), conj(a)).slice(1); }

// The sphere's reference frame (x into the screen, y left, z up) in three.js's (x right, y up, z towards
// the viewer): (x, y, z) -> (-y, z, -x), a proper rotation, so a quaternion's vector part maps the same way.
const toScene = (v) => [-v[1], v[2], -v[0]];
const SCENE_UNITS_PER_M = 10;  // the shell's radius is 1 unit: a 10 cm move is one radius

let view = null;
try {
  const THREE = await import("three");
  const host = $("view");
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(devicePixelRatio);
  renderer.shadowMap.enabled = true;
  host.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x15171c);
  const camera = new THREE.PerspectiveCamera(40, 1, 0.1, 100);
  camera.position.set(3.4, 2.9, 5.8);  // above, to the right and behind the sphere, as its holder sees it
  camera.lookAt(-0.9, 0.5, 0);  // the sphere a little right of centre, clear of the status text

  scene.add(new THREE.HemisphereLight(0xdde6ff, 0x30281f, 0.9));
  const sun = new THREE.DirectionalLight(0xffffff, 2.2);
  sun.position.set(4, 7, 5);
  sun.castShadow = true;
  sun.shadow.mapSize.set(1024, 1024);
  scene.add(sun);

  const floor = new THREE.Mesh(new THREE.PlaneGeometry(30, 30), new THREE.ShadowMaterial({ opacity: 0.35 }));
  floor.rotation.x = -Math.PI / 2;
  floor.position.y = -1.6;
  floor.receiveShadow = true;
  scene.add(floor);
  const grid = new THREE.GridHelper(30, 30, 0x556070, 0x2a3038);
  grid.position.y = -1.599;
  scene.add(grid);

  const sphere = new THREE.Group();
  const shell = new THREE.Mesh(new THREE.SphereGeometry(1, 64, 32),
    new THREE.MeshStandardMaterial({ color: 0xd8d2c4, roughness: 0.45, metalness: 0.05, transparent: true,
                                     opacity: 0.55, depthWrite: false }));  // see-through: the axes show inside
  shell.castShadow = true;
  sphere.add(shell);
  // latitude rings about the sphere's z and a band about its x, so every turn is visible
  const ring = (radius, colour) => new THREE.Mesh(new THREE.TorusGeometry(radius, 0.018, 8, 96),
                                                  new THREE.MeshStandardMaterial({ color: colour, roughness: 0.6 }));
  for (const lat of [-0.5, 0, 0.5]) {
    const r = ring(Math.sqrt(1 - lat * lat) * 1.003, lat === 0 ? 0x3355cc : 0x7a8090);
    r.rotation.x = Math.PI / 2;  // in the sphere's x-y plane (scene x-z)
    r.position.y = lat;
    sphere.add(r);
  }
  const band = ring(1.004, 0xd0a030);
  band.rotation.y = Math.PI / 2;  // the plane containing the sphere's y and z axes
  sphere.add(band);
  // the sphere's axes
  for (const [axis, colour] of [[[1, 0, 0], 0xff4444], [[0, 1, 0], 0x44dd44], [[0, 0, 1], 0x4488ff]]) {
    const d = new THREE.Vector3(...toScene(axis));
    sphere.add(new THREE.ArrowHelper(d, new THREE.Vector3(0, 0, 0), 1.9, colour, 0.32, 0.17));
  }
  scene.add(sphere);

  function resize() {
    const w = host.clientWidth || innerWidth, h = host.clientHeight || innerHeight;
    renderer.setSize(w, h, false);
    renderer.domElement.style.width = "100%";
    renderer.domElement.style.height = "100%";
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
  }
  addEventListener("resize", () => { resize(); render(); });
  function render() { renderer.render(scene, camera); }
  resize();
  view = { THREE, renderer, scene, camera, sphere, render };
  window.sphereView = view;
  $("renderer").textContent = "three.js r" + THREE.REVISION + " (WebGL)";
  document.body.dataset.renderer = "webgl";
} catch (e) {
  $("renderer").textContent = "no 3-D view: " + e.message + " (this browser has no WebGL?)";
  document.body.dataset.renderer = "none";
}

function draw(position) {
  const rel = ref ? mul(conj(ref), q) : q;
  $("turn").textContent = (2 * Math.acos(Math.min(1, Math.abs(rel[0]))) * 180 / Math.PI).toFixed(1);
  if (!view) return;
  const v = toScene(rel.slice(1));
  view.sphere.quaternion.set(v[0], v[1], v[2], rel[0]);
  if (position) {
    if (!pos0) pos0 = position.slice();
    // earth-frame displacement, seen in the reference pose's frame
    const d = rotate(ref ? conj(ref) : [1, 0, 0, 0], position.map((p, i) => p - pos0[i]));
    const s = toScene(d).map((c) => c * SCENE_UNITS_PER_M);
    view.sphere.position.set(s[0], s[1], s[2]);
  }
  if (!pending) { pending = true; requestAnimationFrame(() => { pending = false; view.render(); }); }
}

// -- the AR view: the webcam's frame, the ball's pose drawn on it, the detector's outline --
window.arLog = [];
let socket = null, arOn = new URLSearchParams(location.search).get("ar") === "1", arBusy = false;
$("arbox").checked = arOn;
function project(c, p) {  // camera frame (m) -> pixels, OpenCV's model (k1, k2, p1, p2, k3)
  const x = p[0] / p[2], y = p[1] / p[2], [k1, k2, p1, p2, k3] = c.dist, r2 = x * x + y * y;
  const radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3));
  const xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x);
  const yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y;
  return [c.fx * xd + c.cx, c.fy * yd + c.cy];
}
function drawAR(m, img) {
  const cv = $("ar"), g = cv.getContext("2d"), c = m.camera;
  if (cv.width !== c.width || cv.height !== c.height) { cv.width = c.width; cv.height = c.height; }
  g.drawImage(img, 0, 0);
  let entry = { index: m.index, centre: null, outline: m.outline ? m.outline.centre : null };
  if (m.position && m.position[2] > 0.05) {
    const p = m.position, ctr = project(c, p), r = c.fx * m.radius_m / p[2];
    g.lineWidth = 2; g.strokeStyle = "rgba(255,255,255,0.9)";
    g.beginPath(); g.arc(ctr[0], ctr[1], r * 1.15, 0, 2 * Math.PI); g.stroke();  // a ring around the ball
    if (m.rotation) {  // its axes (x red, y green, z blue), 1.8 radii long, from the sphere's orientation
      [["#ff4444", 0], ["#44dd44", 1], ["#4488ff", 2]].forEach(([colour, i]) => {
        const R = m.rotation, L = 1.8 * m.radius_m;
        const tip = project(c, [p[0] + R[0][i] * L, p[1] + R[1][i] * L, p[2] + R[2][i] * L]);
        g.strokeStyle = colour; g.beginPath(); g.moveTo(ctr[0], ctr[1]); g.lineTo(tip[0], tip[1]); g.stroke();
      });
    }
    g.fillStyle = "#ffdd33"; g.beginPath(); g.arc(ctr[0], ctr[1], 2.5, 0, 2 * Math.PI); g.fill();
    entry.centre = ctr; entry.radius = r;
  }
  if (m.outline) {  // the detector's outline
    g.setLineDash([5, 4]); g.strokeStyle = "#33ddff"; g.lineWidth = 1.5;
    g.beginPath(); g.arc(m.outline.centre[0], m.outline.centre[1], m.outline.radius, 0, 2 * Math.PI); g.stroke();
    g.setLineDash([]);
  }
  window.arLog.push(entry);
}
function onFrame(m) {
  if (!arOn || !m.jpeg || arBusy) return;  // a frame still decoding: this one is skipped
  arBusy = true;
  const img = new Image();
  img.onload = () => { drawAR(m, img); arBusy = false; };
  img.onerror = () => { arBusy = false; };
  img.src = "data:image/jpeg;base64," + m.jpeg;
}
function setAR(on) {
  arOn = on; $("ar").style.display = on ? "block" : "none";
  if (on && socket && socket.readyState === 1) socket.send(JSON.stringify({ subscribe: "frames" }));
}
$("arbox").onchange = () => setAR($("arbox").checked);

function connect() {
  const ws = new WebSocket("ws://" + location.host + "/ws");
  socket = ws;
  ws.onopen = () => { $("status").textContent = "connected"; document.body.dataset.connected = "1"; setAR(arOn); };
  ws.onclose = () => { $("status").textContent = "disconnected (retrying)"; setTimeout(connect, 1000); };
  ws.onmessage = (msg) => {
    const m = JSON.parse(msg.data);
    count++; $("count").textContent = count;
    let position = null;
    if (m.type === "orientation") {
      q = m.quat; if (!ref) ref = q.slice();
      $("quat").textContent = q.map((v) => v.toFixed(3)).join(" ");
      if (m.mode) $("mode").textContent = m.mode;
      if (m.position) {
        position = m.position;
        $("position").textContent = m.position.map((v) => v.toFixed(3)).join(" ") + " m";
      }
      if (m.camera) {
        const d = m.camera;
        $("cameradiag").textContent = d.found + "/" + d.frames + " frames with the ball, " + d.gated +
          " fixes rejected" + (d.alignment ? "" : ", learning how the camera stands");
      }
    } else if (m.type === "frame") { onFrame(m); return; }
    else if (m.type === "mode") { $("mode").textContent = m.mode; }
    else if (m.type === "event") { $("event").textContent = m.event; }
    else if (m.type === "recentre" && m.quat) { ref = m.quat; pos0 = null; }
    draw(position);
  };
}
$("recentre").onclick = () => { ref = q.slice(); pos0 = null; draw(null); };
draw(null);
connect();
</script>
</body>
</html>
"""
