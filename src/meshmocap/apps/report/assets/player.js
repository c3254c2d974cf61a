/* meshmocap report player: the exported glTF of each track, played with three.js.
 *
 * Each div.mm-player holds a JSON script element of class mm-data
 * written by meshmocap.apps.report.player (per track: the GLB that `meshmocap export` writes,
 * base64; tracked joints; the truth and hull points quantised to int16), a <canvas> and the
 * controls. three.js comes from the vendored bundle inlined before this file (MMTHREE).
 * World frame: glTF's, metres, Y up. Mouse: drag to orbit, right-drag to pan, wheel to
 * zoom. Keys (canvas focused): space play/pause, left/right step one frame.
 * Add "?screenshot" to the page address to show only the first player at 800 x 600, and
 * "frame=N" (e.g. "?screenshot&frame=3") to open the players at their frame N (from 0).
 * Errors are collected in <html data-mm-errors> (JSON); a player that has drawn its first
 * frame sets data-mm-ready="1".
 */
(function () {
  "use strict";

  var THREE = window.MMTHREE;
  var errors = [];
  function report(msg) {
    errors.push(String(msg));
    document.documentElement.setAttribute("data-mm-errors", JSON.stringify(errors));
  }
  window.addEventListener("error", function (e) { report(e.message); });
  window.addEventListener("unhandledrejection", function (e) { report(e.reason); });

  function bytesOf(b64) {
    var bin = atob(b64), n = bin.length, out = new Uint8Array(n);
    for (var i = 0; i < n; i++) out[i] = bin.charCodeAt(i);
    return out;
  }

  var TYPES = { int16: Int16Array, int32: Int32Array, uint32: Uint32Array, float32: Float32Array };

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

  function color(rgb, f) {
    f = f || 1;
    return new THREE.Color(rgb[0] * f / 255, rgb[1] * f / 255, rgb[2] * f / 255);
  }

  /* A skeleton drawn over everything (the higher `order`, the later): bones as lines,
   * joints as dots of `size` pixels, in a darker shade of `rgb`. */
  function Skeleton(parents, nJoints, rgb, size, order) {
    this.order = order;
    var pairs = [];
    for (var k = 0; k < nJoints; k++) if (parents && parents[k] >= 0) pairs.push(parents[k], k);
    this.pairs = pairs;
    this.nJoints = nJoints;
    this.lineGeom = new THREE.BufferGeometry();
    this.lineGeom.setAttribute("position", new THREE.BufferAttribute(new Float32Array(pairs.length * 3), 3));
    this.dotGeom = new THREE.BufferGeometry();
    this.dotGeom.setAttribute("position", new THREE.BufferAttribute(new Float32Array(nJoints * 3), 3));
    // transparent, like the meshes, so that they draw after them (renderOrder), on top
    var over = { color: color(rgb, 0.6), depthTest: false, depthWrite: false, transparent: true };
    this.lineMat = new THREE.LineBasicMaterial(over);
    this.dotMat = new THREE.PointsMaterial(Object.assign({ size: size, sizeAttenuation: false }, over));
  }
  Skeleton.prototype.object = function () {
    var g = new THREE.Group();
    var lines = new THREE.LineSegments(this.lineGeom, this.lineMat), dots = new THREE.Points(this.dotGeom, this.dotMat);
    lines.renderOrder = dots.renderOrder = this.order;
    lines.frustumCulled = dots.frustumCulled = false;
    g.add(lines, dots);
    return g;
  };
  Skeleton.prototype.set = function (J, row) {
    var lp = this.lineGeom.attributes.position, dp = this.dotGeom.attributes.position;
    var base = row * this.nJoints * 3;
    for (var k = 0; k < this.nJoints * 3; k++) dp.array[k] = J[base + k];
    for (var p = 0; p < this.pairs.length; p++) {
      var j = this.pairs[p];
      for (var c = 0; c < 3; c++) lp.array[3 * p + c] = J[base + 3 * j + c];
    }
    lp.needsUpdate = dp.needsUpdate = true;
  };

  function Player(root) {
    var self = this;
    var data = JSON.parse(root.querySelector("script.mm-data").textContent);
    this.root = root;
    this.data = data;
    this.canvas = root.querySelector("canvas");
    this.nFrames = data.frames.length;
    this.frame = 0;
    this.playing = false;
    this.speed = 1;
    var m = /[?&]frame=(\d+)/.exec(window.location.search);
    if (m) this.frame = Math.min(+m[1], this.nFrames - 1);
    try {
      this.renderer = new THREE.WebGLRenderer({ canvas: this.canvas, antialias: true, preserveDrawingBuffer: true });
    } catch (e) {
      var note = document.createElement("p");
      note.textContent = "This browser cannot show the 3D player (WebGL is unavailable).";
      this.canvas.replaceWith(note);
      return;
    }
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    var scene = this.scene = new THREE.Scene();
    scene.background = new THREE.Color(0xf3f5f8);
    scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8d8d, 2.2));
    var sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(2, 4, 3);
    scene.add(sun);
    var c = data.center, ext = Math.max(data.extent, 1.5);
    this.camera = new THREE.PerspectiveCamera(35, 4 / 3, 0.01, 200);
    this.controls = new THREE.OrbitControls(this.camera, this.canvas);
    this.controls.addEventListener("change", function () { self.render(); });
    var grid = new THREE.GridHelper(Math.ceil(ext * 3), Math.ceil(ext * 6), 0xb8c0cc, 0xd8dde4);
    grid.position.set(c[0], data.floor, c[2]);
    scene.add(grid);

    this.truth = data.truth ? { J: decode(data.truth.joints), skel: new Skeleton(data.truth.parents, data.truth.n_joints, data.colors.truth, 5, 10) } : null;
    if (data.hull) {
      this.hullOffsets = decode(data.hull.offsets);
      this.hullGeom = new THREE.BufferGeometry();
      this.hullGeom.setAttribute("position", new THREE.BufferAttribute(decode(data.hull.points), 3));
      this.hullMat = new THREE.PointsMaterial({ color: color(data.colors.hull), size: 2.5, sizeAttenuation: false, transparent: true, opacity: 0.55 });
    }
    this.lanes = [];
    this.pending = 0;
    var loader = new THREE.GLTFLoader();
    data.tracks.forEach(function (t, k) {
      var lane = { group: new THREE.Group(), track: t, rows: decode(t.rows), J: decode(t.joints), model: null, mixer: null };
      lane.skel = new Skeleton(t.parents, t.n_joints, t.color, 7, 11);
      lane.skelObj = lane.skel.object();
      lane.group.add(lane.skelObj);
      if (self.truth) { lane.truthObj = self.truth.skel.object(); lane.group.add(lane.truthObj); }
      if (self.hullGeom) {
        lane.hull = new THREE.Points(self.hullGeom, self.hullMat);
        lane.hull.frustumCulled = false;
        lane.group.add(lane.hull);
      }
      scene.add(lane.group);
      self.lanes.push(lane);
      if (!t.glb) return;
      self.pending++;
      loader.parse(bytesOf(t.glb).buffer, "", function (gltf) {
        lane.model = gltf.scene;
        lane.model.traverse(function (o) {
          if (o.isMesh) {
            // a morph-target mesh has no normals: shade it from its faces
            o.material = new THREE.MeshStandardMaterial({ color: color(t.color), roughness: 0.75, metalness: 0, transparent: true, opacity: 0.85, flatShading: !o.geometry.attributes.normal });
            o.frustumCulled = false;
          }
        });
        lane.mixer = new THREE.AnimationMixer(lane.model);
        lane.mixer.clipAction(gltf.animations[0]).play();
        lane.group.add(lane.model);
        self.loaded();
      }, function (e) { report("track " + t.name + ": " + (e && e.message ? e.message : e)); self.loaded(); });
    });

    var slider = this.el_("mm-slider");
    slider.addEventListener("input", function () { self.pause(); self.setFrame(+slider.value); });
    this.el_("mm-play").addEventListener("click", function () { self.toggle(); });
    this.el_("mm-speed").addEventListener("change", function (e) { self.speed = +e.target.value; });
    root.querySelectorAll("input[data-layer]").forEach(function (box) {
      box.addEventListener("change", function () {
        self.layout();
        if (box.getAttribute("data-layer") === "side" || box.getAttribute("data-layer") === "follow") self.resetView();
        self.setFrame(self.frame);
      });
    });
    this.canvas.addEventListener("keydown", function (e) {
      if (e.key === " ") { self.toggle(); e.preventDefault(); }
      else if (e.key === "ArrowRight") { self.pause(); self.setFrame((self.frame + 1) % self.nFrames); }
      else if (e.key === "ArrowLeft") { self.pause(); self.setFrame((self.frame - 1 + self.nFrames) % self.nFrames); }
    });
    this.canvas.addEventListener("dblclick", function () { self.resetView(); });
    window.addEventListener("resize", function () { self.resize(); self.render(); });
    this.resize();
    this.resetView();
    this.layout();
    if (this.pending === 0) this.loaded(true);
  }

  Player.prototype.el_ = function (cls) { return this.root.querySelector("." + cls); };

  Player.prototype.layer = function (name) {
    var box = this.root.querySelector("input[data-layer=" + name + "]");
    return box ? box.checked : name !== "side" && name !== "follow";
  };

  Player.prototype.loaded = function (none) {
    if (!none && --this.pending > 0) return;
    this.setFrame(this.frame);
    this.root.setAttribute("data-mm-ready", "1");
  };

  Player.prototype.resize = function () {
    var w = this.canvas.clientWidth || 800, h = this.canvas.clientHeight || 600;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
  };

  /* The home view: the first track's pelvis at the current frame when following it (else
   * the scene's centre), the lanes side by side in view, seen from the front right. */
  Player.prototype.resetView = function () {
    var d = this.data, c = d.center, l = d.lane, s = this.spacing();
    var lanes = this.layer("side") ? this.lanes.length : 1, first = this.lanes[0];
    var tx = c[0], tz = c[2], ty = d.floor + 0.9, dist = 2.8 + 1.1 * (lanes - 1);
    if (this.layer("follow") && first && first.rows[this.frame] >= 0) {
      var b = 3 * first.track.n_joints * first.rows[this.frame];
      tx = first.J[b]; tz = first.J[b + 2];
    } else {
      dist = Math.max(dist, 1.2 * d.extent);
    }
    tx += l[0] * s * (lanes - 1) / 2; tz += l[1] * s * (lanes - 1) / 2;
    this.controls.target.set(tx, ty, tz);
    this.camera.position.set(tx + 0.45 * dist, ty + 0.25 * dist, tz + 0.85 * dist);
    this.controls.update();
  };

  Player.prototype.spacing = function () { return 1.1; };

  /* Lanes side by side (across the direction of travel) or overlaid; layer switches. */
  Player.prototype.layout = function () {
    var side = this.layer("side"), s = this.spacing(), l = this.data.lane, self = this;
    this.lanes.forEach(function (lane, k) {
      var off = side ? k * s : 0;
      lane.group.position.set(l[0] * off, 0, l[1] * off);
      var extra = side || k === 0;  // one copy of the truth and hull when overlaid
      if (lane.truthObj) lane.truthObj.visible = self.layer("truth") && extra;
      if (lane.hull) lane.hull.visible = self.layer("hull") && extra;
    });
  };

  Player.prototype.setFrame = function (i) {
    var d = this.data, self = this;
    var prev = this.frame;
    this.frame = i;
    var f = d.frames[i];
    this.lanes.forEach(function (lane) {
      var row = lane.rows[i], on = row >= 0;
      if (lane.model) {
        lane.model.visible = on && self.layer("mesh");
        if (on) lane.mixer.setTime((f - lane.track.first) / d.capture_fps);
      }
      lane.skelObj.visible = on && self.layer("skeleton");
      if (on) lane.skel.set(lane.J, row);
    });
    if (this.truth) this.truth.skel.set(this.truth.J, i);
    if (this.hullGeom) this.hullGeom.setDrawRange(this.hullOffsets[i], this.hullOffsets[i + 1] - this.hullOffsets[i]);
    if (this.layer("follow") && this.lanes.length && this.lanes[0].rows[i] >= 0 && this.lanes[0].rows[prev] >= 0) {
      var J = this.lanes[0].J, n = this.lanes[0].track.n_joints, a = 3 * n * this.lanes[0].rows[prev], b = 3 * n * this.lanes[0].rows[i];
      var dx = J[b] - J[a], dz = J[b + 2] - J[a + 2];
      this.controls.target.x += dx; this.controls.target.z += dz;
      this.camera.position.x += dx; this.camera.position.z += dz;
      this.controls.update();
    }
    this.el_("mm-slider").value = String(i);
    this.el_("mm-label").textContent = "frame " + f + " (" + (i + 1) + "/" + this.nFrames + "; " + (d.note || "") + ")";
    this.render();
  };

  Player.prototype.render = function () { this.renderer.render(this.scene, this.camera); };

  Player.prototype.toggle = function () { if (this.playing) this.pause(); else this.play(); };
  Player.prototype.pause = function () {
    this.playing = false;
    this.el_("mm-play").textContent = "\u25b6 Play";
  };
  Player.prototype.play = function () {
    var self = this, last = null, acc = 0;
    this.playing = true;
    this.el_("mm-play").textContent = "\u23f8 Pause";
    function tick(now) {
      if (!self.playing) return;
      if (last !== null) acc += (now - last) / 1000 * self.data.fps * self.speed;
      last = now;
      if (acc >= 1) {
        var step = Math.floor(acc);
        acc -= step;
        self.setFrame((self.frame + step) % self.nFrames);
      }
      requestAnimationFrame(tick);
    }
    requestAnimationFrame(tick);
  };

  function start() {
    if (/[?&]screenshot/.test(window.location.search)) document.documentElement.classList.add("mm-shot");
    if (!THREE) { report("three.js is missing from the page"); return; }
    document.querySelectorAll(".mm-player").forEach(function (el) {
      try { new Player(el); } catch (e) { report(e && e.stack ? e.stack : e); }
    });
  }
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
  else start();
})();
