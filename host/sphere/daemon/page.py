"""The built-in 3-D page served by the stream (sphere.daemon.stream3d): no external files, no network.

It draws a shaded cube with the sphere's axes (x red towards the screen, y green to the left, z blue
up), turned by the orientation relative to the pose at connection or at the last recentre; the
status text has ids the tests read (``status``, ``quat``, ``mode``, ``event``, ``count``).
"""

PAGE_HTML = r"""<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>MARG sphere — 3-D view</title>
<style>
  body { margin: 0; background: #111; color: #ddd; font: 14px system-ui, sans-serif; }
  #hud { position: absolute; left: 12px; top: 10px; line-height: 1.5; }
  #hud b { color: #fff; }
  canvas { display: block; width: 100vw; height: 100vh; }
  button { margin-top: 6px; }
</style>
</head>
<body>
<canvas id="view"></canvas>
<div id="hud">
  <div><b>MARG sphere</b> · <span id="status">connecting…</span></div>
  <div>mode <span id="mode">?</span> · messages <span id="count">0</span></div>
  <div>quat <span id="quat">–</span> · turned <span id="turn">0.0</span>° from the reference pose</div>
  <div>last event <span id="event">–</span></div>
  <button id="recentre">recentre view</button>
</div>
<script>
"use strict";
const $ = (id) => document.getElementById(id);
let q = [1, 0, 0, 0], ref = null, count = 0;

function mul(a, b) {
  return [a[0]*b[0] - a[1]*b[1] - a[2]*b[2] - a[3]*b[3],
          a[0]*b[1] + a[1]*b[0] + a[2]*b[3] - a[3]*b[2],
          a[0]*b[2] - a[1]*b[3] + a[2]*b[0] + a[3]*b[1],
          a[0]*b[3] + a[1]*b[2] - a[2]*b[1] + a[3]*b[0]];
}
const conj = (a) => [a[0], -a[1], -a[2], -a[3]];
function rotate(a, v) { return mul(mul(a, [0, v[0], v[1], v[2]]), conj(a)).slice(1); }

// Body-frame cube; the reference pose's frame is x into the screen, y left, z up.
const V = [];
for (const x of [-1, 1]) for (const y of [-1, 1]) for (const z of [-1, 1]) V.push([x * 1.0, y * 0.8, z * 0.6]);
const FACES = [[0,1,3,2,"#553"],[4,6,7,5,"#c33"],[0,4,5,1,"#363"],[2,3,7,6,"#3b3"],[0,2,6,4,"#335"],[1,5,7,3,"#36c"]];

function draw() {
  const c = $("view"), g = c.getContext("2d");
  c.width = innerWidth; c.height = innerHeight;
  g.fillStyle = "#111"; g.fillRect(0, 0, c.width, c.height);
  const rel = ref ? mul(conj(ref), q) : q;
  $("turn").textContent = (2 * Math.acos(Math.min(1, Math.abs(rel[0]))) * 180 / Math.PI).toFixed(1);
  // seen from a little above and to the right, so the object looks solid
  const h1 = 35 * Math.PI / 360, h2 = 20 * Math.PI / 360;
  const view = mul([Math.cos(h2), 0, -Math.sin(h2), 0], [Math.cos(h1), 0, 0, Math.sin(h1)]);
  const shown = mul(view, rel);
  const s = Math.min(c.width, c.height) / 5, cx = c.width / 2, cy = c.height / 2;
  // reference frame → screen: right = -y, up = z, towards the viewer = -x
  const P = V.map((v) => { const w = rotate(shown, v); const d = 6 + w[0];
                           return [cx + (-w[1]) * s * 6 / d, cy - w[2] * s * 6 / d, w[0]]; });
  const faces = FACES.map((f) => ({ f, depth: (P[f[0]][2] + P[f[1]][2] + P[f[2]][2] + P[f[3]][2]) / 4 }));
  faces.sort((a, b) => b.depth - a.depth);  // far (large x, into the screen) first
  for (const { f } of faces) {
    g.beginPath(); g.moveTo(P[f[0]][0], P[f[0]][1]);
    for (let i = 1; i < 4; i++) g.lineTo(P[f[i]][0], P[f[i]][1]);
    g.closePath(); g.fillStyle = f[4]; g.fill();
    g.strokeStyle = "#eee"; g.stroke();
  }
  // the sphere's axes: x red (towards the screen at the reference pose), y green (left), z blue (up)
  const O = rotate(shown, [0, 0, 0]);
  for (const [axis, colour] of [[[1.8, 0, 0], "#f44"], [[0, 1.6, 0], "#4f4"], [[0, 0, 1.4], "#48f"]]) {
    const w = rotate(shown, axis), d = 6 + w[0];
    g.beginPath(); g.moveTo(cx, cy); g.lineTo(cx - w[1] * s * 6 / d, cy - w[2] * s * 6 / d);
    g.strokeStyle = colour; g.lineWidth = 3; g.stroke(); g.lineWidth = 1;
  }
}

function connect() {
  const ws = new WebSocket("ws://" + location.host + "/ws");
  ws.onopen = () => { $("status").textContent = "connected"; document.body.dataset.connected = "1"; };
  ws.onclose = () => { $("status").textContent = "disconnected (retrying)"; setTimeout(connect, 1000); };
  ws.onmessage = (msg) => {
    const m = JSON.parse(msg.data);
    count++; $("count").textContent = count;
    if (m.type === "orientation") {
      q = m.quat; if (!ref) ref = q.slice();
      $("quat").textContent = q.map((v) => v.toFixed(3)).join(" ");
      if (m.mode) $("mode").textContent = m.mode;
    } else if (m.type === "mode") { $("mode").textContent = m.mode; }
    else if (m.type === "event") { $("event").textContent = m.event; }
    else if (m.type === "recentre" && m.quat) { ref = m.quat; }
    draw();
  };
}
$("recentre").onclick = () => { ref = q.slice(); draw(); };
addEventListener("resize", draw);
draw();
connect();
</script>
</body>
</html>
"""
