// The viewer's page: HTML, CSS and the script that draws the run with three.js (WebGL through the library, no
// WebGL by hand) and the per-frame plots on a 2D canvas. `#status` says "ready" once the scene is drawn (with
// where the middle of the trajectory projects, for the browser test) or the error that stopped it.
#include <string>

#include "apps/viewer.h"

namespace mcslam::apps {

namespace {

constexpr const char* kHead = R"HTML(<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>mcslam viewer</title>
<style>
  html, body { margin: 0; height: 100%; background: #15181c; color: #d8dde3; font: 13px sans-serif; overflow: hidden; }
  #view { position: absolute; left: 0; top: 0; right: 0; bottom: 190px; }
  #panel { position: absolute; left: 0; right: 0; bottom: 0; height: 190px; background: #1d2127; }
  #bar { display: flex; align-items: center; gap: 12px; padding: 6px 10px; }
  #slider { flex: 1; }
  #plot { width: 100%; height: 140px; display: block; }
  #info { position: absolute; left: 10px; top: 8px; pointer-events: none; text-shadow: 0 0 3px #000; }
  #status { position: absolute; right: 10px; top: 8px; font-size: 11px; color: #8a939c; }
  .legend span { margin-right: 12px; }
</style></head>
<body>
<div id="view"></div>
<div id="info"></div>
<div id="status">loading</div>
<div id="panel">
  <div id="bar"><button id="play">play</button><input id="slider" type="range" min="0" max="0" value="0"><span id="frame"></span></div>
  <canvas id="plot"></canvas>
</div>
<script>)HTML";

constexpr const char* kApp = R"JS(
(function () {
  const status = document.getElementById('status');
  window.onerror = function (msg, src, line) { status.textContent = 'error: ' + msg + ' (line ' + line + ')'; };
  const D = JSON.parse(document.getElementById('data').textContent);
  const T = D.trajectory, N = T.frames.length;
  const colours = { est: 0x35d07f, gt: 0xe0503a, frustum: 0x6d7885, current: 0xffd23f, seen: 0xffd23f };

  const view = document.getElementById('view');
  // ?w=W&h=H: a view of that many pixels whatever the window (the browser test's screenshots and DOM reads
  // then see the same scene: a headless window's viewport is not the same in the two).
  const query = new URLSearchParams(location.search);
  if (query.has('w') && query.has('h')) {
    Object.assign(view.style, { width: query.get('w') + 'px', height: query.get('h') + 'px', right: 'auto', bottom: 'auto' });
  }
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setClearColor(0x15181c);
  view.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(50, 1, 0.001, 1e6);
  const up = new THREE.Vector3(D.up[0], D.up[1], D.up[2]);
  camera.up.copy(up);

  const vec = (a, i) => new THREE.Vector3(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
  // The scene's extent: the trajectory and the middle 90 % of the points (a few far ones do not shrink the view).
  const box = new THREE.Box3();
  for (let i = 0; i < N; ++i) box.expandByPoint(vec(T.positions, i));
  const npts = D.points.length / 3;
  if (npts > 0) {
    const along = [[], [], []];
    for (let i = 0; i < npts; ++i) for (let k = 0; k < 3; ++k) along[k].push(D.points[3 * i + k]);
    along.forEach(a => a.sort((x, y) => x - y));
    const q = f => along.map(a => a[Math.min(a.length - 1, Math.floor(f * a.length))]);
    box.expandByPoint(new THREE.Vector3(...q(0.05)));
    box.expandByPoint(new THREE.Vector3(...q(0.95)));
  }
  const centre = box.getCenter(new THREE.Vector3());
  const size = Math.max(box.getSize(new THREE.Vector3()).length(), 1e-6);

  // Map points, coloured by height (along the cameras' mean up) from blue to orange.
  if (npts > 0) {
    const h = [];
    for (let i = 0; i < npts; ++i) h.push(vec(D.points, i).dot(up));
    const hs = h.slice().sort((x, y) => x - y);
    const lo = hs[Math.floor(0.05 * (npts - 1))], hi = hs[Math.floor(0.95 * (npts - 1))];
    const col = new Float32Array(3 * npts), c = new THREE.Color();
    for (let i = 0; i < npts; ++i) {
      const t = Math.min(1, Math.max(0, (h[i] - lo) / Math.max(hi - lo, 1e-9)));
      c.setHSL(0.62 - 0.55 * t, 0.75, 0.55);
      col[3 * i] = c.r; col[3 * i + 1] = c.g; col[3 * i + 2] = c.b;
    }
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(D.points, 3));
    g.setAttribute('color', new THREE.BufferAttribute(col, 3));
    scene.add(new THREE.Points(g, new THREE.PointsMaterial({ size: 3, sizeAttenuation: false, vertexColors: true })));
  }
  const line = (positions, colour) => {
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(positions, 3));
    const l = new THREE.Line(g, new THREE.LineBasicMaterial({ color: colour }));
    scene.add(l);
    return l;
  };

  // Frusta: a camera's image rectangle at depth s and its centre, drawn in the world.
  const s = 0.012 * size;
  const corners = [[-0.64, -0.48, 1], [0.64, -0.48, 1], [0.64, 0.48, 1], [-0.64, 0.48, 1]].map(c => new THREE.Vector3(...c).multiplyScalar(s));
  const frustum = i => {
    const p = vec(T.positions, i);
    const q = new THREE.Quaternion(T.quaternions[4 * i], T.quaternions[4 * i + 1], T.quaternions[4 * i + 2], T.quaternions[4 * i + 3]);
    const w = corners.map(c => c.clone().applyQuaternion(q).add(p));
    const out = [];
    for (let k = 0; k < 4; ++k) out.push(p, w[k], w[k], w[(k + 1) % 4]);
    return out.flatMap(v => [v.x, v.y, v.z]);
  };
  const kf = T.keyframes.length ? T.keyframes : [...Array(N).keys()];
  const step = Math.max(1, Math.ceil(kf.length / 60));
  let segs = [];
  for (let k = 0; k < kf.length; k += step) segs = segs.concat(frustum(kf[k]));
  if (segs.length) {
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(segs, 3));
    scene.add(new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: colours.frustum, transparent: true, opacity: 0.45 })));
  }
  if (D.ground_truth) line(D.ground_truth, colours.gt);
  const est = line(T.positions, colours.est);
  // The estimate over what lies about it (the aligned ground truth along the same path, the keyframes' frusta):
  // drawn last and whatever the depth, it is never hidden by the lines it nearly coincides with.
  est.material.depthTest = false;
  est.renderOrder = 1;
  const currentGeom = new THREE.BufferGeometry();
  currentGeom.setAttribute('position', new THREE.Float32BufferAttribute(new Array(48).fill(0), 3));
  // These two change geometry as the slider moves: their bounding spheres would be stale, so never culled.
  const currentLines = new THREE.LineSegments(currentGeom, new THREE.LineBasicMaterial({ color: colours.current }));
  currentLines.frustumCulled = false;
  scene.add(currentLines);
  const seenGeom = new THREE.BufferGeometry();
  seenGeom.setAttribute('position', new THREE.Float32BufferAttribute([], 3));
  const seenPoints = new THREE.Points(seenGeom, new THREE.PointsMaterial({ size: 5, sizeAttenuation: false, color: colours.seen }));
  seenPoints.frustumCulled = false;
  scene.add(seenPoints);

  // Seen from above and behind the start, looking at the middle.
  const controls = new THREE.OrbitControls(camera, renderer.domElement);
  controls.target.copy(centre);
  const side = new THREE.Vector3(1, 0, 0);
  if (Math.abs(side.dot(up)) > 0.9) side.set(0, 0, 1);
  side.sub(up.clone().multiplyScalar(side.dot(up))).normalize();
  camera.position.copy(centre).add(up.clone().multiplyScalar(0.9 * size)).add(side.multiplyScalar(0.6 * size));
  camera.near = size * 1e-3; camera.far = size * 100;
  controls.update();

  const info = document.getElementById('info');
  info.innerHTML = '<b></b><br>' + N + ' poses, ' + npts + ' map points; ' + D.units +
    '<div class="legend"><span style="color:#35d07f">estimate</span>' + (D.ground_truth ? '<span style="color:#e0503a">ground truth</span>' : '') +
    '<span style="color:#ffd23f">current frame</span><span style="color:#6d7885">keyframes</span></div>';
  info.querySelector('b').textContent = D.title;  // a path, as text (it may hold < or &)

  // Per-frame figures of frames.csv: each series scaled to its own range; the current frame marked.
  const S = D.stats, rows = S.index ? S.index.length : 0;
  const series = [['inliers', '#35d07f'], ['reproj_median_px', '#e0a03a'], ['frame_ms', '#5aa9e6']].filter(([k]) => S[k]);
  const plot = document.getElementById('plot');
  const rowOfFrame = {};
  for (let r = 0; r < rows; ++r) rowOfFrame[S.index[r]] = r;
  function drawPlot(frame) {
    const w = plot.clientWidth, h = plot.clientHeight;
    plot.width = w; plot.height = h;
    const g = plot.getContext('2d');
    g.fillStyle = '#1d2127'; g.fillRect(0, 0, w, h);
    if (!rows) { g.fillStyle = '#8a939c'; g.fillText('no frames.csv', 10, 20); return; }
    series.forEach(([key, colour], n) => {
      const v = S[key], finite = v.filter(x => x !== null);
      if (!finite.length) return;
      const lo = Math.min(...finite), hi = Math.max(...finite);
      g.strokeStyle = colour; g.beginPath();
      let started = false;
      for (let r = 0; r < rows; ++r) {
        if (v[r] === null) { started = false; continue; }
        const x = 40 + (w - 50) * r / Math.max(rows - 1, 1), y = h - 12 - (h - 30) * (v[r] - lo) / Math.max(hi - lo, 1e-9);
        if (started) g.lineTo(x, y); else g.moveTo(x, y);
        started = true;
      }
      g.stroke();
      g.fillStyle = colour;
      g.fillText(key + ' ' + lo.toFixed(2) + '-' + hi.toFixed(2), 40 + 170 * n, 12);
    });
    const r = rowOfFrame[frame];
    if (r !== undefined) {
      const x = 40 + (w - 50) * r / Math.max(rows - 1, 1);
      g.strokeStyle = '#ffd23f'; g.beginPath(); g.moveTo(x, 16); g.lineTo(x, h); g.stroke();
    }
  }

  const slider = document.getElementById('slider'), label = document.getElementById('frame');
  slider.max = Math.max(N - 1, 0);
  slider.value = slider.max;
  function show(i) {
    if (!N) return;
    currentGeom.setAttribute('position', new THREE.Float32BufferAttribute(frustum(i), 3));
    est.geometry.setDrawRange(0, i + 1);
    const frame = T.frames[i];
    const seen = (D.observed[String(frame)] || []).flatMap(k => [D.points[3 * k], D.points[3 * k + 1], D.points[3 * k + 2]]);
    seenGeom.setAttribute('position', new THREE.Float32BufferAttribute(seen, 3));
    const r = rowOfFrame[frame];
    label.textContent = 'frame ' + frame + (r !== undefined && S.status ? ' (' + S.status[r] + (S.inliers && S.inliers[r] !== null ? ', ' + S.inliers[r] + ' inliers' : '') + ')' : '') +
      (D.observed[String(frame)] ? ', ' + seen.length / 3 + ' map points seen' : '');
    drawPlot(frame);
  }
  slider.oninput = () => show(+slider.value);
  let timer = null;
  document.getElementById('play').onclick = function () {
    if (timer) { clearInterval(timer); timer = null; this.textContent = 'play'; return; }
    if (+slider.value >= N - 1) slider.value = 0;
    this.textContent = 'pause';
    timer = setInterval(() => { slider.value = Math.min(N - 1, +slider.value + 1); show(+slider.value); if (+slider.value >= N - 1) this.click(); }, 33);
  };

  function resize() {
    const w = view.clientWidth, h = view.clientHeight;
    renderer.setSize(w, h);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
  }
  // For the browser test: where the middle pose of the trajectory is drawn, in page pixels, as of the last
  // render at the page's current size (a resize moves it).
  function report() {
    const mid = N ? vec(T.positions, Math.floor(N / 2)).project(camera) : new THREE.Vector3();
    const px = [Math.round((mid.x + 1) / 2 * view.clientWidth), Math.round((1 - mid.y) / 2 * view.clientHeight)];
    status.textContent = 'ready ' + JSON.stringify({ poses: N, points: npts, middle_px: px, view: [view.clientWidth, view.clientHeight] });
  }
  window.addEventListener('resize', () => { resize(); drawPlot(T.frames[+slider.value]); renderer.render(scene, camera); report(); });
  resize();
  show(+slider.value);
  renderer.render(scene, camera);
  report();
  (function loop() { requestAnimationFrame(loop); controls.update(); renderer.render(scene, camera); })();
})();
</script></body></html>
)JS";

}  // namespace

std::string ViewerPage(const std::string& three_js, const std::string& orbit_js, const std::string& data_json) {
  // Inside a <script> element "</script" would end it and "<!--" change how it ends: every '<' (only ever in
  // a JSON string) is written as the escape \u003c, which JSON.parse reads back as '<'.
  std::string data;
  data.reserve(data_json.size());
  for (const char c : data_json) {
    if (c == '<')
      data += "\\u003c";
    else
      data += c;
  }
  std::string page = kHead;
  page += three_js;
  page += "\n</script>\n<script>\n";
  page += orbit_js;
  page += "\n</script>\n<script id=\"data\" type=\"application/json\">";
  page += data;
  page += "</script>\n<script>";
  page += kApp;
  return page;
}

}  // namespace mcslam::apps
