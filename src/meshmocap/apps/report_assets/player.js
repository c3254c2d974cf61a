/* meshmocap report player: a dependency-free canvas-2D viewer of tracked mesh sequences.
 *
 * Each <div class="mm-player"> holds a <script type="application/json"> with the data written
 * by meshmocap.apps.report (positions quantised to int16 around a shared origin,
 * base64-encoded), a <canvas> and the controls. Meshes are drawn with the painter's
 * algorithm and flat Lambert shading; hull points are depth-sorted with the triangles;
 * skeletons and ground-truth joints are drawn on top. World frame: metres, Z up.
 * Mouse: drag to orbit, shift-drag (or right-drag) to pan, wheel to zoom, double-click to
 * reset. Keys (canvas focused): space play/pause, left/right step one frame.
 * Add "?screenshot" to the page address to show only the first player at 800 x 600, and
 * "frame=N" (e.g. "?screenshot&frame=3") to open the players at their frame N (from 0).
 */
(function () {
  "use strict";

  var FOV = 35 * Math.PI / 180;
  var LEVELS = 48;
  var ZERO = [0, 0, 0];

  function bytesOf(b64) {
    var bin = atob(b64), n = bin.length, out = new Uint8Array(n);
    for (var i = 0; i < n; i++) out[i] = bin.charCodeAt(i);
    return out;
  }

  var TYPES = {
    int16: Int16Array, uint16: Uint16Array, int32: Int32Array, uint32: Uint32Array,
    float32: Float32Array
  };

  /* An encoded array {dtype, shape, data}; quantised positions {.., origin, step}. */
  function decode(enc) {
    var raw = new TYPES[enc.dtype](bytesOf(enc.data).buffer);
    if (!enc.step) return raw;
    var out = new Float32Array(raw.length), o = enc.origin, s = enc.step;
    for (var i = 0; i < raw.length; i += 3) {
      out[i] = o[0] + raw[i] * s;
      out[i + 1] = o[1] + raw[i + 1] * s;
      out[i + 2] = o[2] + raw[i + 2] * s;
    }
    return out;
  }

  function shades(rgb) {
    var out = [];
    for (var k = 0; k < LEVELS; k++) {
      var f = 0.25 + 0.75 * k / (LEVELS - 1);
      out.push("rgb(" + Math.round(rgb[0] * f) + "," + Math.round(rgb[1] * f) + "," +
        Math.round(rgb[2] * f) + ")");
    }
    return out;
  }

  function css(rgb, a) {
    return "rgba(" + rgb[0] + "," + rgb[1] + "," + rgb[2] + "," + a + ")";
  }

  function Player(root) {
    var data = JSON.parse(root.querySelector("script.mm-data").textContent);
    this.root = root;
    this.canvas = root.querySelector("canvas");
    this.ctx = this.canvas.getContext("2d");
    this.nFrames = data.frames.length;
    this.frameNumbers = data.frames;
    this.fps = data.fps;
    this.spacing = data.spacing;
    this.axis = data.axis;  // horizontal unit vector along which side-by-side copies sit
    this.tracks = data.tracks.map(function (t) {
      var faces = decode(t.faces);
      return {
        name: t.name, rgb: t.color, shade: shades(t.color), cull: t.cull,
        faces: faces, nFaces: faces.length / 3, nVerts: t.n_vertices,
        verts: decode(t.vertices), joints: decode(t.joints), nJoints: t.n_joints,
        parents: t.parents, rows: decode(t.rows),
        sx: new Float32Array(t.n_vertices), sy: new Float32Array(t.n_vertices),
        sz: new Float32Array(t.n_vertices)
      };
    });
    this.truth = data.truth ? {
      joints: decode(data.truth.joints), nJoints: data.truth.n_joints,
      parents: data.truth.parents
    } : null;
    this.hull = data.hull ? { points: decode(data.hull.points), offsets: decode(data.hull.offsets) }
      : null;
    this.center = data.center;
    this.height = data.height;
    this.floor = data.floor;
    this.frame = 0;
    this.playing = false;
    this.speed = 1;
    this.pan = [0, 0, 0];
    this.resetView();
    this.buildPrims();
    this.bindControls();
    this.resize();
    var m = /[?&]frame=(\d+)/.exec(window.location.search);
    if (m) this.setFrame(+m[1]);
  }

  Player.prototype.resetView = function () {
    this.az = this.axis ? Math.atan2(-this.axis[0], this.axis[1]) : -Math.PI / 2;
    this.el = 12 * Math.PI / 180;
    this.zoom = 1;
    this.pan = [0, 0, 0];
  };

  Player.prototype.buildPrims = function () {
    var n = 0;
    this.tracks.forEach(function (t) { n += t.nFaces; });
    var maxHull = 0;
    if (this.hull) {
      var off = this.hull.offsets;
      for (var i = 0; i + 1 < off.length; i++) maxHull = Math.max(maxHull, off[i + 1] - off[i]);
    }
    var cap = (n + maxHull) * Math.max(1, this.tracks.length);
    this.primDepth = new Float32Array(cap);
    this.primKind = new Int32Array(cap);   // track index, or -1 - slot for a hull point
    this.primIdx = new Int32Array(cap);
    this.primShade = new Uint8Array(cap);
    this.order = new Uint32Array(cap);
    this.hx = new Float32Array(maxHull);
    this.hy = new Float32Array(maxHull);
  };

  Player.prototype.el_ = function (cls) { return this.root.querySelector("." + cls); };

  Player.prototype.bindControls = function () {
    var self = this, c = this.canvas;
    var slider = this.el_("mm-slider");
    slider.max = String(this.nFrames - 1);
    slider.addEventListener("input", function () { self.setFrame(+slider.value); });
    this.el_("mm-play").addEventListener("click", function () { self.toggle(); });
    this.el_("mm-speed").addEventListener("change", function (e) { self.speed = +e.target.value; });
    Array.prototype.forEach.call(this.root.querySelectorAll("input[type=checkbox]"),
      function (box) { box.addEventListener("change", function () { self.draw(); }); });
    var drag = null;
    c.addEventListener("pointerdown", function (e) {
      drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 };
      c.setPointerCapture(e.pointerId);
    });
    c.addEventListener("pointermove", function (e) {
      if (!drag) return;
      var dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      drag.x = e.clientX; drag.y = e.clientY;
      if (drag.pan) {
        var s = self.dist * Math.tan(FOV / 2) * 2 / self.canvas.clientHeight;
        for (var k = 0; k < 3; k++) self.pan[k] += (-dx * self.r[k] + dy * self.u[k]) * s;
      } else {
        self.az -= dx * 0.01;
        self.el = Math.max(-1.5, Math.min(1.5, self.el + dy * 0.01));
      }
      self.draw();
    });
    c.addEventListener("pointerup", function () { drag = null; });
    c.addEventListener("contextmenu", function (e) { e.preventDefault(); });
    c.addEventListener("wheel", function (e) {
      e.preventDefault();
      self.zoom = Math.max(0.05, Math.min(20, self.zoom * Math.exp(e.deltaY * 0.001)));
      self.draw();
    }, { passive: false });
    c.addEventListener("dblclick", function () { self.resetView(); self.draw(); });
    c.addEventListener("keydown", function (e) {
      if (e.key === " ") { self.toggle(); e.preventDefault(); }
      else if (e.key === "ArrowRight") { self.setFrame(self.frame + 1); e.preventDefault(); }
      else if (e.key === "ArrowLeft") { self.setFrame(self.frame - 1); e.preventDefault(); }
    });
    window.addEventListener("resize", function () { self.resize(); });
  };

  Player.prototype.on = function (name) {
    var box = this.root.querySelector("input[data-layer=" + name + "]");
    return box ? box.checked : false;
  };

  Player.prototype.setFrame = function (f) {
    this.frame = Math.max(0, Math.min(this.nFrames - 1, f));
    this.el_("mm-slider").value = String(this.frame);
    this.draw();
  };

  Player.prototype.toggle = function () {
    var self = this;
    this.playing = !this.playing;
    this.el_("mm-play").textContent = this.playing ? "\u23f8 Pause" : "\u25b6 Play";
    if (!this.playing) return;
    if (this.frame >= this.nFrames - 1) this.setFrame(0);
    var last = null, acc = 0;
    function step(now) {
      if (!self.playing) return;
      if (last !== null) acc += (now - last) / 1000 * self.fps * self.speed;
      last = now;
      if (acc >= 1) {
        var f = self.frame + Math.floor(acc);
        acc -= Math.floor(acc);
        self.setFrame(f >= self.nFrames ? 0 : f);
      }
      requestAnimationFrame(step);
    }
    requestAnimationFrame(step);
  };

  Player.prototype.resize = function () {
    var dpr = window.devicePixelRatio || 1, c = this.canvas;
    c.width = Math.max(1, Math.round(c.clientWidth * dpr));
    c.height = Math.max(1, Math.round(c.clientHeight * dpr));
    this.dpr = dpr;
    this.draw();
  };

  Player.prototype.slots = function () {
    var n = this.tracks.length, side = n > 1 && this.on("side"), out = [];
    for (var i = 0; i < n; i++) {
      var s = side ? (i - (n - 1) / 2) * this.spacing : 0;
      out.push([s * this.axis[0], s * this.axis[1], 0]);
    }
    return side ? out : [[0, 0, 0]];
  };

  Player.prototype.camera = function (slots) {
    var t = this.center.slice();
    if (this.on("follow")) {
      var tr = this.tracks[0], row = tr.rows[this.frame];
      if (row >= 0) {
        var base = row * tr.nJoints * 3;
        t = [tr.joints[base], tr.joints[base + 1], this.center[2]];
      }
    }
    var w = this.canvas.clientWidth, h = this.canvas.clientHeight, aspect = w / Math.max(h, 1);
    var width = this.spacing * slots.length;
    var radius = 0.55 * Math.max(this.height, width / aspect);
    this.dist = this.zoom * radius / Math.tan(FOV / 2) + radius;
    for (var k = 0; k < 3; k++) t[k] += this.pan[k];
    var ce = Math.cos(this.el), f = [-ce * Math.cos(this.az), -ce * Math.sin(this.az),
      -Math.sin(this.el)];
    var eye = [t[0] - f[0] * this.dist, t[1] - f[1] * this.dist, t[2] - f[2] * this.dist];
    var rl = Math.hypot(f[1], f[0]) || 1, r = [f[1] / rl, -f[0] / rl, 0];
    var u = [r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]];
    this.eye = eye; this.f = f; this.r = r; this.u = u;
    this.focal = 0.5 * h / Math.tan(FOV / 2);
    this.cx = w / 2; this.cy = h / 2;
    var l = [-0.3 * r[0] + 0.5 * u[0] - 0.8 * f[0], -0.3 * r[1] + 0.5 * u[1] - 0.8 * f[1],
      -0.3 * r[2] + 0.5 * u[2] - 0.8 * f[2]];
    var ll = Math.hypot(l[0], l[1], l[2]);
    this.light = [l[0] / ll, l[1] / ll, l[2] / ll];
  };

  /* Project point (x, y, z) + offset o; returns [sx, sy, depth] (depth <= near: hidden). */
  Player.prototype.project = function (x, y, z, o) {
    var dx = x + o[0] - this.eye[0], dy = y + o[1] - this.eye[1], dz = z + o[2] - this.eye[2];
    var r = this.r, u = this.u, f = this.f;
    var d = dx * f[0] + dy * f[1] + dz * f[2];
    var k = this.focal / Math.max(d, 1e-3);
    return [this.cx + k * (dx * r[0] + dy * r[1] + dz * r[2]),
      this.cy - k * (dx * u[0] + dy * u[1] + dz * u[2]), d];
  };

  /* Draw the segment p-q (world) clipped to the near plane. */
  Player.prototype.segment = function (ctx, p, q) {
    var near = 0.05, a = this.project(p[0], p[1], p[2], ZERO),
      b = this.project(q[0], q[1], q[2], ZERO);
    if (a[2] < near && b[2] < near) return;
    if (a[2] < near || b[2] < near) {
      var s = (near - a[2]) / (b[2] - a[2]), m = [0, 0, 0];
      for (var k = 0; k < 3; k++) m[k] = p[k] + s * (q[k] - p[k]);
      var c = this.project(m[0], m[1], m[2], ZERO);
      if (a[2] < near) a = c; else b = c;
    }
    ctx.moveTo(a[0], a[1]);
    ctx.lineTo(b[0], b[1]);
  };

  Player.prototype.drawFloor = function (ctx, slots) {
    var z = this.floor, c = this.center, step = 0.5;
    var x0 = Math.round((c[0] + this.pan[0]) / step) * step;
    var y0 = Math.round((c[1] + this.pan[1]) / step) * step;
    var tr = this.tracks[0];
    if (this.on("follow") && tr.rows[this.frame] >= 0) {
      var b = tr.rows[this.frame] * tr.nJoints * 3;
      x0 = Math.round(tr.joints[b] / step) * step;
      y0 = Math.round(tr.joints[b + 1] / step) * step;
    }
    var ext = 4 + Math.ceil(this.spacing * slots.length / 2 / step) * step;
    ctx.strokeStyle = "rgba(120,130,140,0.35)";
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (var k = -ext; k <= ext + 1e-9; k += step) {
      this.segment(ctx, [x0 + k, y0 - ext, z], [x0 + k, y0 + ext, z]);
      this.segment(ctx, [x0 - ext, y0 + k, z], [x0 + ext, y0 + k, z]);
    }
    ctx.stroke();
  };

  Player.prototype.draw = function () {
    var ctx = this.ctx, c = this.canvas, w = c.clientWidth, h = c.clientHeight;
    if (!w || !h) return;
    ctx.setTransform(this.dpr, 0, 0, this.dpr, 0, 0);
    ctx.fillStyle = "#f3f5f8";
    ctx.fillRect(0, 0, w, h);
    var slots = this.slots(), side = slots.length > 1, self = this;
    this.camera(slots);
    this.drawFloor(ctx, slots);
    var n = 0, fr = this.frame, eye = this.eye, L = this.light;
    var depth = this.primDepth, kind = this.primKind, idx = this.primIdx, shade = this.primShade;
    var showMesh = this.on("mesh");
    this.tracks.forEach(function (t, ti) {
      var row = t.rows[fr];
      if (!showMesh || row < 0) return;
      var o = side ? slots[ti] : slots[0], V = t.verts, base = row * t.nVerts * 3;
      for (var v = 0; v < t.nVerts; v++) {
        var p = self.project(V[base + 3 * v], V[base + 3 * v + 1], V[base + 3 * v + 2], o);
        t.sx[v] = p[0]; t.sy[v] = p[1]; t.sz[v] = p[2];
      }
      var F = t.faces;
      for (var j = 0; j < t.nFaces; j++) {
        var a = base + 3 * F[3 * j], b = base + 3 * F[3 * j + 1], cc = base + 3 * F[3 * j + 2];
        var e1x = V[b] - V[a], e1y = V[b + 1] - V[a + 1], e1z = V[b + 2] - V[a + 2];
        var e2x = V[cc] - V[a], e2y = V[cc + 1] - V[a + 1], e2z = V[cc + 2] - V[a + 2];
        var nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
        var vis = nx * (eye[0] - V[a] - o[0]) + ny * (eye[1] - V[a + 1] - o[1]) +
          nz * (eye[2] - V[a + 2] - o[2]);
        if (t.cull && vis <= 0) continue;
        var ia = F[3 * j], ib = F[3 * j + 1], ic = F[3 * j + 2];
        var d = (t.sz[ia] + t.sz[ib] + t.sz[ic]) / 3;
        if (d < 0.05) continue;
        var nl = Math.hypot(nx, ny, nz) || 1;
        var lam = (nx * L[0] + ny * L[1] + nz * L[2]) / nl;
        if (vis < 0) lam = -lam;
        depth[n] = d; kind[n] = ti; idx[n] = j;
        shade[n] = Math.round(Math.max(0, lam) * (LEVELS - 1));
        n++;
      }
    });
    var hull = this.hull, hullOn = hull && this.on("hull");
    if (hullOn) {
      var P = hull.points, h0 = hull.offsets[fr], h1 = hull.offsets[fr + 1];
      slots.forEach(function (o, si) {
        for (var i = h0; i < h1; i++) {
          var p = self.project(P[3 * i], P[3 * i + 1], P[3 * i + 2], o);
          if (p[2] < 0.05) continue;
          depth[n] = p[2]; kind[n] = -1 - si; idx[n] = i; n++;
        }
      });
    }
    var order = this.order.subarray(0, n);
    for (var i = 0; i < n; i++) order[i] = i;
    order.sort(function (x, y) { return depth[y] - depth[x]; });
    ctx.lineWidth = 0.6;
    ctx.lineJoin = "round";
    var hullStyle = "rgba(230,140,40,0.45)", ps = 2.2;
    for (var m = 0; m < n; m++) {
      var q = order[m], k = kind[q];
      if (k < 0) {
        var pp = self.project(P[3 * idx[q]], P[3 * idx[q] + 1], P[3 * idx[q] + 2], slots[-1 - k]);
        ctx.fillStyle = hullStyle;
        ctx.fillRect(pp[0] - ps / 2, pp[1] - ps / 2, ps, ps);
        continue;
      }
      var t = this.tracks[k], F = t.faces, j = idx[q];
      var a = F[3 * j], b = F[3 * j + 1], cc = F[3 * j + 2], col = t.shade[shade[q]];
      ctx.fillStyle = col;
      ctx.strokeStyle = col;
      ctx.beginPath();
      ctx.moveTo(t.sx[a], t.sy[a]);
      ctx.lineTo(t.sx[b], t.sy[b]);
      ctx.lineTo(t.sx[cc], t.sy[cc]);
      ctx.closePath();
      ctx.fill();
      ctx.stroke();
    }
    if (this.on("skeleton")) {
      this.tracks.forEach(function (t, ti) {
        var row = t.rows[fr];
        if (row >= 0) {
          self.drawSkeleton(ctx, t.joints, row * t.nJoints * 3, t.nJoints, t.parents,
            side ? slots[ti] : slots[0], css(t.rgb.map(function (x) { return x * 0.45; }), 1));
        }
      });
    }
    if (this.truth && this.on("truth")) {
      var T = this.truth;
      slots.forEach(function (o) {
        self.drawSkeleton(ctx, T.joints, fr * T.nJoints * 3, T.nJoints, T.parents, o,
          "rgba(20,150,60,0.9)");
      });
    }
    this.el_("mm-label").textContent = "frame " + (fr + 1) + "/" + this.nFrames +
      " (capture frame " + this.frameNumbers[fr] + ")";
  };

  Player.prototype.drawSkeleton = function (ctx, J, base, K, parents, o, colour) {
    var pts = [];
    for (var k = 0; k < K; k++) {
      pts.push(this.project(J[base + 3 * k], J[base + 3 * k + 1], J[base + 3 * k + 2], o));
    }
    ctx.strokeStyle = colour;
    ctx.fillStyle = colour;
    ctx.lineWidth = 2.5;
    ctx.beginPath();
    for (k = 0; k < K; k++) {
      var p = parents ? parents[k] : -1;
      if (p < 0 || pts[k][2] < 0.05 || pts[p][2] < 0.05) continue;
      ctx.moveTo(pts[p][0], pts[p][1]);
      ctx.lineTo(pts[k][0], pts[k][1]);
    }
    ctx.stroke();
    for (k = 0; k < K; k++) {
      if (pts[k][2] < 0.05) continue;
      ctx.beginPath();
      ctx.arc(pts[k][0], pts[k][1], 3.5, 0, 2 * Math.PI);
      ctx.fill();
    }
  };

  function start() {
    if (/[?&]screenshot\b/.test(window.location.search)) {
      document.documentElement.classList.add("mm-shot");
    }
    var players = document.querySelectorAll(".mm-player");
    for (var i = 0; i < players.length; i++) {
      try {
        players[i].mmPlayer = new Player(players[i]);
      } catch (err) {
        var msg = players[i].querySelector(".mm-label");
        if (msg) msg.textContent = "player failed: " + err;
      }
    }
  }

  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
  else start();
})();
