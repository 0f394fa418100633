// map.html (see map_html.hpp): the page is a fixed template (style, panels, the viewer's script)
// around three data blocks: the metadata and per-scan figures as JSON, the quantised points and the
// run-length coded scan of each point as base64. Non-executing <script> elements hold the data, so
// the page stays one file and the browser parses it as fast as it reads text.
#include "minemap/report/map_html.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string_view>
#include <vector>

#include "minemap/core/atomic_file.hpp"
#include "minemap/three_js_embedded.hpp"

namespace minemap::report {
namespace {

constexpr double kQuantumSteps = 65535.0;  // uint16 per axis

// The page's frame (three.js: right-handed, y up) from the survey's; see map_html.hpp.
Eigen::Vector3d to_page_frame(const Eigen::Vector3d& p, int up_axis) {
  switch (up_axis) {
    case 0: return {p.z(), p.x(), p.y()};
    case 1: return {p.x(), p.y(), -p.z()};
    default: return {p.x(), p.z(), -p.y()};
  }
}

void put_u16(std::vector<std::uint8_t>& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v & 0xffu));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
}

void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int shift = 0; shift < 32; shift += 8) out.push_back(static_cast<std::uint8_t>((v >> shift) & 0xffu));
}

void append_base64(std::string& out, std::span<const std::uint8_t> bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  out.reserve(out.size() + (bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= bytes.size(); i += 3) {
    const std::uint32_t v = (std::uint32_t{bytes[i]} << 16) | (std::uint32_t{bytes[i + 1]} << 8) | bytes[i + 2];
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63u];
    out += kAlphabet[(v >> 6) & 63u];
    out += kAlphabet[v & 63u];
  }
  if (const std::size_t rest = bytes.size() - i; rest > 0) {
    const std::uint32_t v = (std::uint32_t{bytes[i]} << 16) | (rest == 2 ? std::uint32_t{bytes[i + 1]} << 8 : 0u);
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63u];
    out += rest == 2 ? kAlphabet[(v >> 6) & 63u] : '=';
    out += '=';
  }
}

std::string html_escaped(std::string_view text) {
  std::string out;
  for (const char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

// JSON for an inline <script>: '<' occurs only inside JSON strings, where \u003c reads the same, so
// no scan name can close the element ("</script") or open a comment ("<!--"). Invalid UTF-8 in a
// name becomes U+FFFD rather than failing the whole page.
std::string script_safe_json(const nlohmann::json& json) {
  const std::string text = json.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    if (c == '<') {
      out += "\\u003c";
    } else {
      out += c;
    }
  }
  return out;
}

template <std::size_t N>
void append_chunks(std::string& out, const char* const (&chunks)[N]) {
  for (const char* chunk : chunks) out += chunk;
}

nlohmann::json vector_json(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

// The page up to the data. @TITLE@ is replaced (HTML-escaped).
constexpr std::string_view kPageHead = R"HTML(<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>@TITLE@</title>
<style>
html, body { margin: 0; height: 100%; overflow: hidden; background: #15181c; color: #e8e8e8;
  font: 13px/1.45 system-ui, sans-serif; }
canvas { display: block; }
.box { position: absolute; background: rgba(10, 12, 15, 0.78); border-radius: 4px; padding: 8px 10px; }
#panel { top: 8px; left: 8px; max-width: 340px; }
#panel h1 { font-size: 14px; margin: 0 0 4px; }
#panel .dim, #info .dim { color: #a0a4aa; }
#panel label { margin-right: 10px; white-space: nowrap; }
#scale { left: 8px; bottom: 8px; padding: 6px 10px; }
#scale-bar { height: 5px; border: 2px solid #e8e8e8; border-top: none; min-width: 1px; }
#colour-bar { height: 10px; width: 220px; margin: 3px 0 1px; border-radius: 2px; }
#colour-ends { width: 220px; display: flex; justify-content: space-between; }
#info { right: 8px; bottom: 8px; max-width: 420px; }
#info h2 { font-size: 14px; margin: 0 0 4px; }
#info .doubt { color: #ffb347; }
#failure { top: 40%; left: 50%; transform: translate(-50%, -50%); max-width: 560px; color: #ff8a80; }
</style>
</head>
<body>
<div id="panel" class="box">
<h1 id="map-title">@TITLE@</h1>
<div id="counts" class="dim"></div>
<div>colour: <label><input type="radio" name="colour" value="height" checked> height</label><label><input type="radio" name="colour" value="scan"> scan</label><label id="intensity-choice" hidden><input type="radio" name="colour" value="intensity"> intensity</label>
point size <input id="point-size" type="range" min="1" max="6" step="1" value="2" style="width:70px;vertical-align:middle"></div>
<div id="legend" class="dim"></div>
<div id="colour-bar"></div><div id="colour-ends" class="dim"><span id="colour-lo"></span><span id="colour-hi"></span></div>
<div id="sigma-legend" class="dim"></div>
<div class="dim">drag: orbit · right drag or shift+drag: pan · wheel: zoom · click a scan position (a dot on the red line): its match</div>
<div class="dim">red line: the scans' poses in order, where the sensor stood for scans in its own frame; for map segments already in world coordinates (a SLAM map's pieces) it shows each one's correction</div>
</div>
<div id="scale" class="box" title="at the orbit centre"><div id="scale-bar"></div><span id="scale-label"></span></div>
<div id="info" class="box" hidden></div>
<div id="failure" class="box" hidden></div>
)HTML";

// The viewer. It runs once the page is parsed (it is the last element), renders on demand (after a
// control change, a toggle or a resize), and is silent on the console unless something fails.
constexpr std::string_view kViewerJs = R"JS(
(function () {
  'use strict';
  function fail(message) {
    document.title = 'minemap map: failed: ' + message;
    var box = document.getElementById('failure');
    box.textContent = 'The map cannot be shown: ' + message;
    box.hidden = false;
    console.error('minemap map: ' + message);
  }
  function text(id) { return document.getElementById(id).textContent; }

  function decodeBase64(s) {
    var alphabet = 'ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/';
    var table = new Uint8Array(128);
    for (var a = 0; a < 64; ++a) table[alphabet.charCodeAt(a)] = a;
    var n = s.length;
    while (n > 0 && s.charCodeAt(n - 1) === 61) --n;  // '=' padding
    var out = new Uint8Array((n * 3) >> 2);
    var o = 0, i = 0, v;
    for (; i + 4 <= n; i += 4) {
      v = (table[s.charCodeAt(i)] << 18) | (table[s.charCodeAt(i + 1)] << 12) |
          (table[s.charCodeAt(i + 2)] << 6) | table[s.charCodeAt(i + 3)];
      out[o++] = v >> 16; out[o++] = v >> 8; out[o++] = v;
    }
    if (n - i >= 2) {
      v = (table[s.charCodeAt(i)] << 18) | (table[s.charCodeAt(i + 1)] << 12) |
          (n - i === 3 ? table[s.charCodeAt(i + 2)] << 6 : 0);
      out[o++] = v >> 16;
      if (n - i === 3) out[o++] = v >> 8;
    }
    return out;
  }

  function grouped(n) { return String(n).replace(/\B(?=(\d{3})+(?!\d))/g, ','); }

  // Height: blue to red through cyan, green and yellow, distinct on a dark background at both ends.
  // Intensity: dark to light, as laser returns are shown.
  var heightStops = [[59, 76, 192], [68, 190, 230], [120, 210, 90], [250, 210, 60], [220, 60, 40]];
  var intensityStops = [[80, 80, 92], [140, 140, 148], [200, 200, 180], [255, 250, 225]];
  function rampColour(t, out, k, stops) {
    stops = stops || heightStops;
    var x = Math.min(Math.max(t, 0), 1) * (stops.length - 1);
    var i = Math.min(Math.floor(x), stops.length - 2), f = x - i;
    var a = stops[i], b = stops[i + 1];
    out[k] = a[0] + (b[0] - a[0]) * f; out[k + 1] = a[1] + (b[1] - a[1]) * f; out[k + 2] = a[2] + (b[2] - a[2]) * f;
  }
  // The colour bar of a ramp: a CSS gradient through its stops.
  function gradientOf(stops) {
    return 'linear-gradient(to right, ' + stops.map(function (c, i) {
      return 'rgb(' + c.join(',') + ') ' + (100 * i / (stops.length - 1)).toFixed(0) + '%';
    }).join(', ') + ')';
  }
  // Scan s gets hue s * golden ratio: neighbouring scans differ, colours never run out.
  function scanColour(s, out, k) {
    var h = (s * 0.6180339887) % 1, l = 0.58, c = 0.7 * (1 - Math.abs(2 * l - 1));
    var hp = h * 6, x = c * (1 - Math.abs(hp % 2 - 1)), m = l - c / 2, r = 0, g = 0, b = 0;
    if (hp < 1) { r = c; g = x; } else if (hp < 2) { r = x; g = c; } else if (hp < 3) { g = c; b = x; }
    else if (hp < 4) { g = x; b = c; } else if (hp < 5) { r = x; b = c; } else { r = c; b = x; }
    out[k] = 255 * (r + m); out[k + 1] = 255 * (g + m); out[k + 2] = 255 * (b + m);
  }
  function finite(p) {
    return Array.isArray(p) && Number.isFinite(p[0]) && Number.isFinite(p[1]) && Number.isFinite(p[2]);
  }

  function main() {
    var meta = JSON.parse(text('minemap-meta'));
    var scans = meta.scans, n = meta.points;
    var bytes = decodeBase64(text('minemap-points'));
    if (bytes.length !== 6 * n) throw new Error('the point data is damaged (' + bytes.length + ' bytes for ' + n + ' points)');
    var runs = decodeBase64(text('minemap-runs'));

    // Points: uint16 per axis within the bounding box, back to metres.
    var positions = new Float32Array(3 * n), qHeight = new Uint16Array(n);
    var mx = meta.min_m[0], my = meta.min_m[1], mz = meta.min_m[2];
    var sx = meta.step_m[0], sy = meta.step_m[1], sz = meta.step_m[2];
    for (var i = 0, b = 0, k = 0; i < n; ++i, b += 6, k += 3) {
      var qy = bytes[b + 2] | (bytes[b + 3] << 8);
      positions[k] = mx + sx * (bytes[b] | (bytes[b + 1] << 8));
      positions[k + 1] = my + sy * qy;
      positions[k + 2] = mz + sz * (bytes[b + 4] | (bytes[b + 5] << 8));
      qHeight[i] = qy;
    }

    // The quantised coordinate of an axis that `fraction` of the points lie below and above:
    // stray points far out neither flatten the colour ramp nor shrink the first view.
    function quantiles(axis, fraction) {
      var histogram = new Uint32Array(65536), at = 2 * axis, lo = 0, hi = 65535, seen = 0, q;
      for (var p = 0; p < n; ++p, at += 6) ++histogram[bytes[at] | (bytes[at + 1] << 8)];
      for (q = 0; q < 65536; ++q) { seen += histogram[q]; if (seen > fraction * n) { lo = q; break; } }
      for (q = 65535, seen = 0; q >= 0; --q) { seen += histogram[q]; if (seen > fraction * n) { hi = q; break; } }
      return [lo, Math.max(hi, lo)];
    }
    // Colour by height: the ramp spans the 2nd to the 98th percentile.
    var heightRange = quantiles(1, 0.02), lo = heightRange[0], hi = Math.max(heightRange[1], lo + 1), q;
    var lut = new Uint8Array(3 * 65536);
    for (q = 0; q < 65536; ++q) rampColour((q - lo) / (hi - lo), lut, 3 * q);
    var heightColours = new Uint8Array(3 * n);
    for (i = 0, k = 0; i < n; ++i, k += 3) {
      var c = 3 * qHeight[i];
      heightColours[k] = lut[c]; heightColours[k + 1] = lut[c + 1]; heightColours[k + 2] = lut[c + 2];
    }
    // Intensity: one byte a point, the ramp over the 2nd to 98th percentile (meta.intensity).
    var intensityColours = null;
    if (meta.intensity) {
      var levels = decodeBase64(text('minemap-intensity'));
      if (levels.length !== n) throw new Error('the intensity data is damaged (' + levels.length + ' of ' + n + ' points)');
      intensityColours = new Uint8Array(3 * n);
      var ilut = new Uint8Array(3 * 256);
      for (q = 0; q < 256; ++q) rampColour(q / 255, ilut, 3 * q, intensityStops);
      for (i = 0, k = 0; i < n; ++i, k += 3) {
        var v = 3 * levels[i];
        intensityColours[k] = ilut[v]; intensityColours[k + 1] = ilut[v + 1]; intensityColours[k + 2] = ilut[v + 2];
      }
    }
    var scanColours = null;  // made on the first switch to "scan"
    function makeScanColours() {
      var out = new Uint8Array(3 * n), at = 0, rgb = new Uint8Array(3);
      for (var r = 0; r + 8 <= runs.length; r += 8) {
        var s = (runs[r] | (runs[r + 1] << 8) | (runs[r + 2] << 16) | (runs[r + 3] << 24)) >>> 0;
        var count = (runs[r + 4] | (runs[r + 5] << 8) | (runs[r + 6] << 16) | (runs[r + 7] << 24)) >>> 0;
        scanColour(s, rgb, 0);
        for (var e = Math.min(at + count, n); at < e; ++at) { out[3 * at] = rgb[0]; out[3 * at + 1] = rgb[1]; out[3 * at + 2] = rgb[2]; }
      }
      if (at !== n) throw new Error('the scan data is damaged (' + at + ' of ' + n + ' points)');
      return out;
    }

    var renderer;
    try {
      renderer = new THREE.WebGLRenderer({ antialias: false });
    } catch (e) {
      throw new Error('this browser has no WebGL (' + (e && e.message ? e.message : e) + ')');
    }
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.setSize(window.innerWidth, window.innerHeight);
    document.body.insertBefore(renderer.domElement, document.body.firstChild);
    var scene = new THREE.Scene();
    scene.background = new THREE.Color(0x15181c);

    var geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    var colourAttribute = new THREE.BufferAttribute(intensityColours || heightColours, 3, true);
    geometry.setAttribute('color', colourAttribute);
    var pointMaterial = new THREE.PointsMaterial({ size: 2, sizeAttenuation: false, vertexColors: THREE.VertexColors });
    if (n > 0) scene.add(new THREE.Points(geometry, pointMaterial));

    var box = new THREE.Box3();  // what the first view frames: the map less 0.5 % at each end of each axis
    if (n > 0) {
      var bx = quantiles(0, 0.005), by = quantiles(1, 0.005), bz = quantiles(2, 0.005);
      box.expandByPoint(new THREE.Vector3(mx + bx[0] * sx, my + by[0] * sy, mz + bz[0] * sz));
      box.expandByPoint(new THREE.Vector3(mx + bx[1] * sx, my + by[1] * sy, mz + bz[1] * sz));
    }
    var scanAt = [], path = [];
    var markerColours = [];
    // A map tied to control colours its trusted scans by their largest sigma, green to red over
    // 0 .. the largest; doubtful (orange) and unregistered (grey) keep their colours.
    var sigmaMax = 0;
    scans.forEach(function (s) { if (s.sigma_cm > sigmaMax) sigmaMax = s.sigma_cm; });
    function markerColour(s) {
      if (!s.registered) return [0.6, 0.6, 0.6];
      if (s.doubt) return [1.0, 0.6, 0.1];
      if (!(sigmaMax > 0)) return [0.95, 0.2, 0.2];
      var t = Math.min(Math.max((s.sigma_cm || 0) / sigmaMax, 0), 1);
      return [0.2 + 0.75 * t, 0.8 - 0.6 * t, 0.3 - 0.1 * t];
    }
    scans.forEach(function (s, index) {
      if (!finite(s.p)) return;
      var v = new THREE.Vector3(s.p[0], s.p[1], s.p[2]);
      scanAt.push({ index: index, at: v });
      path.push(v.x, v.y, v.z);
      box.expandByPoint(v);
      markerColours.push.apply(markerColours, markerColour(s));
    });
    if (sigmaMax > 0) {
      document.getElementById('sigma-legend').textContent = 'scan positions: green to red, their largest sigma 0 to ' +
          sigmaMax.toFixed(1) + ' cm (1 sigma, tied to control)';
    }
    // The trajectory and the scan positions are drawn over the map (no depth test): in a tunnel
    // the ceiling would hide them.
    function overlay(object, order) {
      object.material.depthTest = false;
      object.material.transparent = true;
      object.renderOrder = order;
      scene.add(object);
    }
    if (scanAt.length > 0) {
      var pathGeometry = new THREE.BufferGeometry();
      pathGeometry.setAttribute('position', new THREE.Float32BufferAttribute(path, 3));
      if (scanAt.length > 1) overlay(new THREE.Line(pathGeometry, new THREE.LineBasicMaterial({ color: 0xd62728 })), 1);
      pathGeometry.setAttribute('color', new THREE.Float32BufferAttribute(markerColours, 3));
      overlay(new THREE.Points(pathGeometry, new THREE.PointsMaterial({ size: 8, sizeAttenuation: false, vertexColors: THREE.VertexColors })), 2);
    }
    var selectedGeometry = new THREE.BufferGeometry();
    selectedGeometry.setAttribute('position', new THREE.Float32BufferAttribute([0, 0, 0], 3));
    var selectedMarker = new THREE.Points(selectedGeometry, new THREE.PointsMaterial({ size: 15, sizeAttenuation: false, color: 0xfff176 }));
    selectedMarker.visible = false;
    overlay(selectedMarker, 3);

    if (box.isEmpty()) box.set(new THREE.Vector3(-1, -1, -1), new THREE.Vector3(1, 1, 1));
    var centre = box.getCenter(new THREE.Vector3());
    var radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1);
    var camera = new THREE.PerspectiveCamera(50, window.innerWidth / window.innerHeight, radius * 1e-3, radius * 20);
    var sceneRadius = Math.max(radius, Math.hypot(65535 * sx, 65535 * sy, 65535 * sz) / 2);  // every point
    // From above at 55 degrees, far enough that the bounding sphere fits the height.
    var distance = radius / Math.sin(25 * Math.PI / 180);
    camera.position.set(centre.x, centre.y + distance * Math.sin(55 * Math.PI / 180), centre.z + distance * Math.cos(55 * Math.PI / 180));
    var controls = new THREE.OrbitControls(camera, renderer.domElement);
    controls.target.copy(centre);
    controls.screenSpacePanning = true;
    controls.minDistance = radius * 1e-3;
    controls.maxDistance = sceneRadius * 10;
    controls.update();

    var scaleBar = document.getElementById('scale-bar'), scaleLabel = document.getElementById('scale-label');
    function metresPerPixel() {
      var d = camera.position.distanceTo(controls.target);
      return 2 * d * Math.tan(camera.fov * Math.PI / 360) / Math.max(renderer.domElement.clientHeight, 1);
    }
    function updateScaleBar() {
      var mpp = metresPerPixel(), want = 120 * mpp;
      var p = Math.pow(10, Math.floor(Math.log10(want))), f = want / p;
      var length = (f >= 5 ? 5 : f >= 2 ? 2 : 1) * p;
      scaleBar.style.width = (length / mpp).toFixed(1) + 'px';
      scaleLabel.textContent = Number(length.toPrecision(1)) + ' m';
    }
    function render() {
      // Near and far follow the orbit distance: depth precision where the eye is.
      var d = camera.position.distanceTo(controls.target);
      camera.near = Math.max(d * 2e-3, radius * 1e-6);
      camera.far = d + 2 * sceneRadius + 4 * radius;
      camera.updateProjectionMatrix();
      renderer.render(scene, camera);
      updateScaleBar();
    }
    var pending = false;
    function requestRender() {
      if (pending) return;
      pending = true;
      requestAnimationFrame(function () { pending = false; render(); });
    }
    controls.addEventListener('change', requestRender);
    window.addEventListener('resize', function () {
      camera.aspect = window.innerWidth / window.innerHeight;
      renderer.setSize(window.innerWidth, window.innerHeight);
      requestRender();
    });

    // Panel: counts, colour toggle, point size, legend.
    document.getElementById('counts').textContent = grouped(n) + (meta.points_in > n ? ' of ' + grouped(meta.points_in) : '') +
        ' map points · ' + scans.length + (scans.length === 1 ? ' scan' : ' scans');
    var legend = document.getElementById('legend'), bar = document.getElementById('colour-bar');
    var barEnds = document.getElementById('colour-ends');
    function showLegend(mode) {
      var ramp = n > 0 && mode !== 'scan';
      legend.textContent = n === 0 ? 'no map points' : mode === 'scan' ? 'each scan its own colour'
          : mode === 'intensity' ? 'intensity (as the scans store it)' : 'height (m)';
      bar.hidden = barEnds.hidden = !ramp;
      if (!ramp) return;
      bar.style.background = gradientOf(mode === 'intensity' ? intensityStops : heightStops);
      var ends = mode === 'intensity' ? [meta.intensity.lo, meta.intensity.hi] : [my + sy * lo, my + sy * hi];
      var digits = mode === 'intensity' && Math.abs(ends[1] - ends[0]) < 10 ? 3 : 1;
      document.getElementById('colour-lo').textContent = Number(ends[0]).toFixed(digits);
      document.getElementById('colour-hi').textContent = Number(ends[1]).toFixed(digits);
    }
    if (intensityColours) {
      document.getElementById('intensity-choice').hidden = false;
      document.querySelector('input[name=colour][value=intensity]').checked = true;
    }
    showLegend(intensityColours ? 'intensity' : 'height');
    function setColouring(mode) {
      if (mode === 'scan' && !scanColours) scanColours = makeScanColours();
      colourAttribute.array = mode === 'scan' ? scanColours : mode === 'intensity' ? intensityColours : heightColours;
      colourAttribute.needsUpdate = true;
      showLegend(mode);
      requestRender();
    }
    Array.prototype.forEach.call(document.querySelectorAll('input[name=colour]'), function (input) {
      input.addEventListener('change', function () { if (input.checked) setColouring(input.value); });
    });
    document.getElementById('point-size').addEventListener('input', function (e) {
      pointMaterial.size = Number(e.target.value);
      requestRender();
    });

    // A scan's figures: clicking picks the scan position nearest the pointer on screen (within
    // 12 px), at any zoom.
    var info = document.getElementById('info');
    function line(parent, tag, content, cls) {
      var el = document.createElement(tag);
      el.textContent = content;
      if (cls) el.className = cls;
      parent.appendChild(el);
    }
    function figure(v, digits) { return Number.isFinite(v) ? v.toFixed(digits) : 'n/a'; }
    function select(index) {
      if (index < 0) { info.hidden = true; selectedMarker.visible = false; requestRender(); return; }
      var s = scans[index], digits = meta.unit === 'm' ? 4 : 2;
      info.textContent = '';
      line(info, 'h2', s.name);
      line(info, 'div', 'scan ' + (index + 1) + ' of ' + scans.length);
      line(info, 'div', 'ICP iterations ' + s.iterations + ' · pairs ' + grouped(s.pairs) + ' · rms ' + figure(s.rms, digits) + ' ' + meta.unit);
      if (finite(s.at)) {
        line(info, 'div', 'position ' + s.at.map(function (v) { return v.toFixed(meta.unit === 'm' ? 2 : 0); }).join(', ') + ' ' + meta.unit, 'dim');
      }
      if (!s.registered) line(info, 'div', 'not registered (pose from odometry)' + (s.doubt ? ': ' + s.doubt : ''), 'doubt');
      else if (s.doubt) line(info, 'div', 'doubtful: ' + s.doubt, 'doubt');
      else if (s.note) line(info, 'div', s.note, 'dim');
      if (s.sigma) line(info, 'div', 'sigma (1 sigma, tied to control): ' + s.sigma, 'dim');
      info.hidden = false;
      if (finite(s.p)) {
        selectedGeometry.attributes.position.setXYZ(0, s.p[0], s.p[1], s.p[2]);
        selectedGeometry.attributes.position.needsUpdate = true;
        selectedMarker.visible = true;
      }
      requestRender();
    }
    var down = null;
    renderer.domElement.addEventListener('mousedown', function (e) { down = [e.clientX, e.clientY]; });
    renderer.domElement.addEventListener('click', function (e) {
      if (down && Math.abs(e.clientX - down[0]) + Math.abs(e.clientY - down[1]) > 4) return;  // a drag
      var rect = renderer.domElement.getBoundingClientRect(), best = -1, bestPx2 = 12 * 12, v = new THREE.Vector3();
      scanAt.forEach(function (s) {
        v.copy(s.at).project(camera);
        if (v.z < -1 || v.z > 1) return;  // behind the camera or beyond far
        var dx = rect.left + (v.x + 1) / 2 * rect.width - e.clientX, dy = rect.top + (1 - v.y) / 2 * rect.height - e.clientY;
        if (dx * dx + dy * dy < bestPx2) { bestPx2 = dx * dx + dy * dy; best = s.index; }
      });
      select(best);
    });
    // map.html#scan=NAME opens with that scan's figures.
    function selectFromAddress() {
      var m = /^#scan=(.*)$/.exec(window.location.hash);
      if (!m) return;
      var name = decodeURIComponent(m[1]);
      for (var s = 0; s < scans.length; ++s) if (scans[s].name === name) { select(s); return; }
    }
    window.addEventListener('hashchange', selectFromAddress);

    render();
    renderer.getContext().finish();  // the time below includes the GPU's work
    document.title = 'minemap map: rendered ' + n + ' points in ' + Math.round(performance.now()) + ' ms' +
        (meta.title ? ' - ' + meta.title : '');
    selectFromAddress();
  }

  try {
    main();
  } catch (e) {
    fail(e && e.message ? e.message : String(e));
  }
})();
)JS";

}  // namespace

std::string map_html(const MapHtmlInput& input, const MapHtmlSettings& settings) {
  if (settings.up_axis < 0 || settings.up_axis > 2) {
    throw std::invalid_argument("map.html: up_axis must be 0, 1 or 2, not " + std::to_string(settings.up_axis));
  }
  if (input.point_scans.size() != input.points_cm.size()) {
    throw std::invalid_argument("map.html: " + std::to_string(input.point_scans.size()) + " scan indices for " +
                                std::to_string(input.points_cm.size()) + " points");
  }
  if (!input.point_intensity.empty() && input.point_intensity.size() != input.points_cm.size()) {
    throw std::invalid_argument("map.html: " + std::to_string(input.point_intensity.size()) + " intensities for " +
                                std::to_string(input.points_cm.size()) + " points");
  }
  for (const std::uint32_t scan : input.point_scans) {
    if (scan >= input.scans.size()) {
      throw std::invalid_argument("map.html: a point of scan " + std::to_string(scan) + " in a survey of " +
                                  std::to_string(input.scans.size()) + " scans");
    }
  }

  // Kept point k is input point floor(k * n_in / n_keep): a fixed fractional stride over the whole
  // input, so every scan keeps its share and the same input keeps the same points. Computed as
  // k * (n_in / n_keep) + k * (n_in % n_keep) / n_keep, which cannot overflow while n_keep < 2^32.
  const std::size_t n_in = input.points_cm.size();
  const std::size_t n_keep = settings.max_points == 0 ? n_in : std::min(n_in, settings.max_points);
  const auto kept_index = [&](std::size_t k) { return k * (n_in / n_keep) + k * (n_in % n_keep) / n_keep; };
  const auto page_point = [&](std::size_t i) { return to_page_frame(input.points_cm[i].cast<double>(), settings.up_axis); };

  Eigen::Vector3d min_cm = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d max_cm = -min_cm;
  std::size_t n_finite = 0;
  for (std::size_t k = 0; k < n_keep; ++k) {
    const std::size_t i = kept_index(k);
    if (!input.points_cm[i].allFinite()) continue;
    const Eigen::Vector3d p = page_point(i);
    min_cm = min_cm.cwiseMin(p);
    max_cm = max_cm.cwiseMax(p);
    ++n_finite;
  }
  if (n_finite == 0) min_cm = max_cm = Eigen::Vector3d::Zero();
  const Eigen::Vector3d step_cm = (max_cm - min_cm) / kQuantumSteps;  // 0 on a flat axis: every q is 0

  std::vector<std::uint8_t> point_bytes, run_bytes;
  point_bytes.reserve(6 * n_finite);
  std::uint32_t run_scan = 0, run_length = 0;
  for (std::size_t k = 0; k < n_keep; ++k) {
    const std::size_t i = kept_index(k);
    if (!input.points_cm[i].allFinite()) continue;
    const Eigen::Vector3d p = page_point(i);
    for (int axis = 0; axis < 3; ++axis) {
      const double q = step_cm[axis] > 0 ? std::round((p[axis] - min_cm[axis]) / step_cm[axis]) : 0.0;
      put_u16(point_bytes, static_cast<std::uint16_t>(std::clamp(q, 0.0, kQuantumSteps)));
    }
    const std::uint32_t scan = input.point_scans[i];
    if (run_length > 0 && scan != run_scan) {
      put_u32(run_bytes, run_scan);
      put_u32(run_bytes, run_length);
      run_length = 0;
    }
    run_scan = scan;
    ++run_length;
  }
  if (run_length > 0) {
    put_u32(run_bytes, run_scan);
    put_u32(run_bytes, run_length);
  }
  // Intensity, one byte a kept point: 0..255 over the kept points' 2nd to 98th percentile.
  std::vector<std::uint8_t> intensity_bytes;
  double intensity_lo = 0.0, intensity_hi = 0.0;
  if (!input.point_intensity.empty()) {
    std::vector<float> kept;
    for (std::size_t k = 0; k < n_keep; ++k) {
      const std::size_t i = kept_index(k);
      if (input.points_cm[i].allFinite()) kept.push_back(input.point_intensity[i]);
    }
    if (!kept.empty()) {
      std::vector<float> sorted = kept;
      const auto at = [&](double fraction) {
        const auto nth = sorted.begin() + static_cast<std::ptrdiff_t>(fraction * static_cast<double>(sorted.size() - 1));
        std::nth_element(sorted.begin(), nth, sorted.end());
        return static_cast<double>(*nth);
      };
      intensity_lo = at(0.02);
      intensity_hi = std::max(at(0.98), intensity_lo);
      const double span = intensity_hi > intensity_lo ? intensity_hi - intensity_lo : 1.0;
      intensity_bytes.reserve(kept.size());
      for (const float v : kept) {
        const double level = std::round(255.0 * (static_cast<double>(v) - intensity_lo) / span);
        intensity_bytes.push_back(static_cast<std::uint8_t>(std::clamp(std::isfinite(level) ? level : 0.0, 0.0, 255.0)));
      }
    }
  }

  const double unit_per_cm = 1.0 / centimetres_per(settings.unit);
  nlohmann::json scans = nlohmann::json::array();
  for (const MapHtmlScan& scan : input.scans) {
    scans.push_back({{"name", scan.name},
                     {"p", vector_json(to_page_frame(scan.position_cm, settings.up_axis) / 100.0)},
                     {"at", vector_json(scan.position_cm * unit_per_cm)},
                     {"iterations", scan.iterations},
                     {"pairs", scan.pairs},
                     {"rms", scan.rms_cm * unit_per_cm},
                     {"registered", scan.registered},
                     {"doubt", scan.doubt},
                     {"note", scan.note}});
    if (!scan.sigma.empty()) {
      scans.back()["sigma"] = scan.sigma;
      scans.back()["sigma_cm"] = scan.sigma_cm;
    }
  }
  nlohmann::json meta = {{"format", "minemap map.html 1"},
                               {"title", settings.title},
                               {"unit", to_string(settings.unit)},
                               {"up_axis", settings.up_axis},
                               {"points", n_finite},
                               {"points_in", n_in},
                               {"min_m", vector_json(min_cm / 100.0)},
                               {"step_m", vector_json(step_cm / 100.0)},
                               {"scans", scans}};
  if (!intensity_bytes.empty()) meta["intensity"] = {{"lo", intensity_lo}, {"hi", intensity_hi}};

  const std::string title = settings.title.empty() ? std::string("minemap map") : settings.title;
  std::string head{kPageHead};
  for (std::size_t at; (at = head.find("@TITLE@")) != std::string::npos;) head.replace(at, 7, html_escaped(title));

  std::string page;
  page.reserve(head.size() + point_bytes.size() * 4 / 3 + run_bytes.size() * 4 / 3 + 2'000'000);
  page += head;
  page += "<script type=\"application/json\" id=\"minemap-meta\">";
  page += script_safe_json(meta);
  page += "</script>\n<script type=\"application/octet-stream\" id=\"minemap-points\">";
  append_base64(page, point_bytes);
  page += "</script>\n<script type=\"application/octet-stream\" id=\"minemap-runs\">";
  append_base64(page, run_bytes);
  if (!intensity_bytes.empty()) {
    page += "</script>\n<script type=\"application/octet-stream\" id=\"minemap-intensity\">";
    append_base64(page, intensity_bytes);
  }
  page += "</script>\n<script id=\"three-js\">\n";
  append_chunks(page, embedded::kThreeJsChunks);
  page += "\n</script>\n<script id=\"three-orbit-controls\">\n";
  append_chunks(page, embedded::kOrbitControlsJsChunks);
  page += "\n</script>\n<script>";
  page += kViewerJs;
  page += "</script>\n</body>\n</html>\n";
  return page;
}

void write_map_html(const std::filesystem::path& path, const MapHtmlInput& input, const MapHtmlSettings& settings) {
  write_file_atomically(path, map_html(input, settings));
}

}  // namespace minemap::report
