// MotionGAN demo page: draw a path on the floor, choose styles, watch the skeletons walk it; or
// steer one walker live with the keys or a gamepad (the server generates it as it goes).
// Stick figures in plain Canvas 2-D with a perspective projection; the character (the GLB that
// /api/export writes) through character.js and three.js, installed beside this page by npm.
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);

  // ------------------------------------------------------------------------------------------
  // State
  // ------------------------------------------------------------------------------------------
  const S = {
    model: null,          // /api/model
    strokes: [],          // drawn path: list of strokes, each a list of [x, z] (metres)
    panels: [],           // one style editor per panel: {mode, label, mix: {name: weight}, expr}
    active: 0,            // the panel the style editor edits
    result: null,         // last /api/generate answer
    request: null,        // the request that produced it (for downloads)
    selected: 0,          // motion for BVH / NPZ
    playing: true,
    time: 0,              // seconds into the motion
    rate: 1,
    camera: "follow",
    orbit: { yaw: -0.6, pitch: 0.32, dist: 7.5 },
    follow: { yaw: 0.6, pitch: 0.2, dist: 3.4, smoothYaw: [] },  // smoothYaw: per panel
    inflight: null,       // AbortController of the running generate
    seq: 0,
    frameCount: 0,        // frames drawn (tests read it)
    exprTimer: null,
    look: "character",    // "character" (three.js, when installed) or "stick"
    rig: "",              // a built-in rig's name, "" for the model's skeleton
    three: null,          // character.js's view, null without three.js or WebGL
    char: { seq: 0, loaded: false, info: null, bytes: 0 },  // the GLB shown
    mode: "draw",         // "draw" (a drawn path, every panel) or "steer" (one walker, live)
    clip: null,           // last /api/clip answer: an uploaded clip's recovered style
  };

  // ------------------------------------------------------------------------------------------
  // API
  // ------------------------------------------------------------------------------------------
  async function api(path, body, signal) {
    const opts = body === undefined ? {} : {
      method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body), signal,
    };
    const r = await fetch(path, opts);
    if (!r.ok) {
      let msg = `${r.status} ${r.statusText}`;
      try { msg = (await r.json()).error || msg; } catch (e) { /* not JSON */ }
      const err = new Error(msg);
      err.status = r.status;
      throw err;
    }
    return r;
  }

  function showError(msg) {
    const el = $("error");
    if (!msg) { el.hidden = true; el.textContent = ""; return; }
    el.textContent = msg;
    el.hidden = false;
  }

  function setStatus(msg) { $("status").textContent = msg || ""; }

  // ------------------------------------------------------------------------------------------
  // The path: floor canvas, strokes, presets
  // ------------------------------------------------------------------------------------------
  const floor = { canvas: $("floor"), cx: 0, cz: 0, half: 8, drawing: null };

  function pathPoints() {
    const pts = [];
    for (const s of S.strokes) for (const p of s) pts.push(p);
    return pts;
  }

  function polyLength(pts) {
    let L = 0;
    for (let i = 1; i < pts.length; i++) L += Math.hypot(pts[i][0] - pts[i - 1][0], pts[i][1] - pts[i - 1][1]);
    return L;
  }

  // equal spacing along a polyline (metres), ends kept
  function resample(pts, step) {
    if (pts.length < 2) return pts.slice();
    const out = [pts[0]];
    let carry = 0;
    for (let i = 1; i < pts.length; i++) {
      const [ax, az] = pts[i - 1], [bx, bz] = pts[i];
      const seg = Math.hypot(bx - ax, bz - az);
      let d = step - carry;
      while (d <= seg) {
        const t = d / seg;
        out.push([ax + (bx - ax) * t, az + (bz - az) * t]);
        d += step;
      }
      carry = seg - (d - step);
    }
    const last = pts[pts.length - 1], end = out[out.length - 1];
    if (Math.hypot(last[0] - end[0], last[1] - end[1]) > 1e-6) out.push(last);
    return out;
  }

  // a hand-drawn stroke, evened out: 5 cm spacing, then a moving average over +-0.3 m
  // (the generator was trained on smooth spline paths; hand jitter would show in the gait)
  function smoothStroke(raw) {
    const pts = resample(raw, 0.05);
    const k = 6, out = [];
    for (let i = 0; i < pts.length; i++) {
      const r = Math.min(k, i, pts.length - 1 - i);
      let sx = 0, sz = 0;
      for (let j = i - r; j <= i + r; j++) { sx += pts[j][0]; sz += pts[j][1]; }
      out.push([sx / (2 * r + 1), sz / (2 * r + 1)]);
    }
    return out;
  }

  // the floor canvas in CSS pixels (its bitmap is finer, for sharp lines)
  const floorSize = () => floor.canvas.clientWidth || 300;
  function floorScale() { return floorSize() / (2 * floor.half); }

  function toFloor(ev) {
    const r = floor.canvas.getBoundingClientRect(), W = floorSize(), s = floorScale();
    const px = (ev.clientX - r.left) * W / r.width, py = (ev.clientY - r.top) * W / r.height;
    return [floor.cx + (px - W / 2) / s, floor.cz + (py - W / 2) / s];
  }

  function fitFloor(pts) {
    if (!pts.length) { floor.cx = 0; floor.cz = 0; floor.half = 8; return; }
    let x0 = Infinity, x1 = -Infinity, z0 = Infinity, z1 = -Infinity;
    for (const [x, z] of pts) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); z0 = Math.min(z0, z); z1 = Math.max(z1, z); }
    floor.cx = (x0 + x1) / 2; floor.cz = (z0 + z1) / 2;
    floor.half = Math.max(4, 0.6 * Math.max(x1 - x0, z1 - z0) + 1);
  }

  function drawFloor() {
    const c = floor.canvas, g = c.getContext("2d"), W = floorSize(), H = W, s = floorScale();
    g.setTransform(c.width / W, 0, 0, c.height / H, 0, 0);
    g.fillStyle = "#0b0f17";
    g.fillRect(0, 0, W, H);
    const X = (x) => W / 2 + (x - floor.cx) * s, Z = (z) => H / 2 + (z - floor.cz) * s;
    const x0 = Math.floor(floor.cx - floor.half), x1 = Math.ceil(floor.cx + floor.half);
    const z0 = Math.floor(floor.cz - floor.half), z1 = Math.ceil(floor.cz + floor.half);
    for (let i = x0; i <= x1; i++) {
      g.strokeStyle = i % 5 === 0 ? "#2c3850" : "#182030";
      g.lineWidth = i === 0 ? 1.6 : 1;
      g.beginPath(); g.moveTo(X(i), 0); g.lineTo(X(i), H); g.stroke();
    }
    for (let i = z0; i <= z1; i++) {
      g.strokeStyle = i % 5 === 0 ? "#2c3850" : "#182030";
      g.lineWidth = i === 0 ? 1.6 : 1;
      g.beginPath(); g.moveTo(0, Z(i)); g.lineTo(W, Z(i)); g.stroke();
    }
    // scale bar
    g.fillStyle = "#8a96ad"; g.font = "11px system-ui, sans-serif";
    g.fillRect(10, H - 14, s, 2); g.fillText("1 m", 14 + s, H - 10);
    const line = (pts, color, width) => {
      if (pts.length < 2) return;
      g.strokeStyle = color; g.lineWidth = width; g.lineJoin = g.lineCap = "round";
      g.beginPath(); g.moveTo(X(pts[0][0]), Z(pts[0][1]));
      for (const p of pts) g.lineTo(X(p[0]), Z(p[1]));
      g.stroke();
    };
    if (S.mode === "steer") {
      // the walked trail, the predicted path ahead, the walker
      line(ST.curve, "#ff7a59", 2);
      line(ST.ahead, "rgba(255,209,194,0.55)", 1.5);
      const pose = steerPose();
      if (pose) {
        g.fillStyle = "#5ec8ff";
        g.beginPath(); g.arc(X(pose[0][0]), Z(pose[0][2]), 4.5, 0, 2 * Math.PI); g.fill();
      }
      $("path-length").textContent = `${(ST.walked).toFixed(1)} m walked`;
      return;
    }
    const pts = pathPoints();
    line(pts, "rgba(255,122,89,0.35)", 6);
    line(pts, "#ff7a59", 2);
    if (floor.drawing) line(floor.drawing, "#ffd1c2", 2);
    if (S.result) line(S.result.curve, "rgba(94,200,255,0.9)", 1.3);
    if (pts.length) {
      g.fillStyle = "#7bd88f";
      g.beginPath(); g.arc(X(pts[0][0]), Z(pts[0][1]), 5, 0, 2 * Math.PI); g.fill();
      const a = pts[Math.max(0, pts.length - 4)], b = pts[pts.length - 1];
      const ang = Math.atan2(Z(b[1]) - Z(a[1]), X(b[0]) - X(a[0]));
      g.fillStyle = "#ff7a59";
      g.beginPath();
      g.moveTo(X(b[0]) + 9 * Math.cos(ang), Z(b[1]) + 9 * Math.sin(ang));
      g.lineTo(X(b[0]) + 6 * Math.cos(ang + 2.4), Z(b[1]) + 6 * Math.sin(ang + 2.4));
      g.lineTo(X(b[0]) + 6 * Math.cos(ang - 2.4), Z(b[1]) + 6 * Math.sin(ang - 2.4));
      g.fill();
    }
    // where the selected walker is now
    if (S.result) {
      const m = S.result.motions[Math.min(S.selected, S.result.motions.length - 1)];
      const p = samplePose(m.positions, currentFrame())[0];
      g.fillStyle = "#5ec8ff";
      g.beginPath(); g.arc(X(p[0]), Z(p[2]), 4.5, 0, 2 * Math.PI); g.fill();
    }
    const L = polyLength(pts);
    const speed = parseFloat($("speed").value);
    $("path-length").textContent = pts.length ? `${L.toFixed(1)} m · ${(L / speed).toFixed(1)} s` : "";
  }

  floor.canvas.addEventListener("pointerdown", (ev) => {
    if (S.mode === "steer") return;  // the floor shows the steered walk's trail
    floor.canvas.setPointerCapture(ev.pointerId);
    const p = toFloor(ev);
    const pts = pathPoints();
    // a new stroke continues the path from where it ends
    floor.drawing = pts.length ? [pts[pts.length - 1], p] : [p];
    drawFloor();
  });
  floor.canvas.addEventListener("pointermove", (ev) => {
    if (!floor.drawing) return;
    const p = toFloor(ev), last = floor.drawing[floor.drawing.length - 1];
    if (Math.hypot(p[0] - last[0], p[1] - last[1]) >= 0.02) floor.drawing.push(p);
    drawFloor();
  });
  const endStroke = () => {
    if (!floor.drawing) return;
    const raw = floor.drawing;
    floor.drawing = null;
    if (polyLength(raw) >= 0.1) {
      const sm = smoothStroke(raw);
      S.strokes.push(S.strokes.length ? sm.slice(1) : sm);
      changed();
    }
    drawFloor();
  };
  floor.canvas.addEventListener("pointerup", endStroke);
  floor.canvas.addEventListener("pointercancel", endStroke);
  floor.canvas.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    floor.half = Math.min(40, Math.max(2, floor.half * Math.exp(ev.deltaY * 0.001)));
    drawFloor();
  }, { passive: false });

  function clearWalk() {
    // the walk shown belongs to a path that is gone: stop it (and any request for it)
    if (S.inflight) { S.inflight.abort(); S.inflight = null; }
    S.seq++;
    S.result = null; S.request = null; refreshMotions(); setStatus("");
    $("hint").hidden = false;
  }
  $("undo").onclick = () => {
    S.strokes.pop();
    clearWalk();  // with "regenerate on change" the shorter path's walk follows at once
    changed(true); drawFloor();
  };
  $("clear").onclick = () => { S.strokes = []; clearWalk(); fitFloor([]); drawFloor(); };

  async function preset(name) {
    const length = parseFloat($("preset-length").value) || 10;
    try {
      // no scale: the server makes one whole shape of this length (a circle of this circumference, ...)
      const r = await api(`/api/shape?name=${encodeURIComponent(name)}&length=${length}`);
      const pts = (await r.json()).points;
      S.strokes = [pts];
      fitFloor(pts);
      showError(null);
      changed(true);
      drawFloor();
    } catch (e) { showError(e.message); }
  }

  // ------------------------------------------------------------------------------------------
  // Styles: panels, each edited as a label, a mix or an expression
  // ------------------------------------------------------------------------------------------
  function newPanel(label) { return { mode: "label", label, mix: {}, expr: "" }; }

  function styleString(p) {
    if (p.mode === "label") return p.label;
    if (p.mode === "mix") {
      const parts = Object.entries(p.mix).filter(([, w]) => w > 0).map(([n, w]) => `${n}:${+w.toFixed(3)}`);
      return parts.length ? parts.join(",") : "";
    }
    return p.expr.trim();
  }

  function renderPanels() {
    const box = $("panels");
    box.innerHTML = "";
    S.panels.forEach((p, i) => {
      const chip = document.createElement("span");
      chip.className = "panel-chip" + (i === S.active ? " active" : "");
      const b = document.createElement("button");
      b.className = "label"; b.style.border = "none"; b.style.background = "none"; b.style.padding = "0";
      b.textContent = styleString(p) || "(empty)";
      b.title = "edit this panel's style";
      b.onclick = () => { S.active = i; renderStyle(); };
      chip.appendChild(b);
      if (S.panels.length > 1) {
        const x = document.createElement("button");
        x.className = "x"; x.textContent = "×"; x.title = "remove this panel";
        x.onclick = () => {
          S.panels.splice(i, 1);
          S.active = Math.min(S.active, S.panels.length - 1);
          renderStyle(); changed();
        };
        chip.appendChild(x);
      }
      box.appendChild(chip);
    });
    const max = S.model ? S.model.limits.max_styles : 6;
    if (S.panels.length < max) {
      const add = document.createElement("button");
      add.className = "add-panel"; add.id = "add-panel";
      add.textContent = "+ side by side";
      add.title = "another panel on the same path (the paper's Fig. 4)";
      add.onclick = () => {
        const names = S.model.style_names;
        const used = new Set(S.panels.map((p) => p.label));
        S.panels.push(newPanel(names.find((n) => !used.has(n)) || names[0]));
        S.active = S.panels.length - 1;
        renderStyle(); changed();
      };
      box.appendChild(add);
    }
  }

  function renderStyle() {
    const p = S.panels[S.active];
    document.querySelectorAll(".tab").forEach((t) => t.classList.toggle("active", t.dataset.mode === p.mode));
    for (const m of ["label", "mix", "expr"]) $("mode-" + m).classList.toggle("active", p.mode === m);
    $("mode-label").querySelectorAll(".chip").forEach((c) => c.classList.toggle("on", c.dataset.name === p.label));
    $("mode-mix").querySelectorAll(".mixrow").forEach((row) => {
      const w = p.mix[row.dataset.name] || 0;
      row.querySelector("input").value = w;
      row.querySelector(".mono").textContent = w.toFixed(2);
      row.classList.toggle("on", w > 0);
    });
    if (document.activeElement !== $("expr")) $("expr").value = p.expr;
    $("style-string").textContent = styleString(p) ? "style: " + styleString(p) : "";
    renderPanels();
  }

  function buildStyleControls() {
    const names = S.model.style_names;
    const chips = $("mode-label");
    for (const n of names) {
      const b = document.createElement("button");
      b.className = "chip"; b.textContent = n; b.dataset.name = n;
      b.onclick = () => { S.panels[S.active].label = n; renderStyle(); changed(); };
      chips.appendChild(b);
    }
    const mix = $("mode-mix");
    for (const n of names) {
      const row = document.createElement("div");
      row.className = "mixrow"; row.dataset.name = n;
      row.innerHTML = `<span>${n}</span><input type="range" min="0" max="1" step="0.05" value="0"
        aria-label="weight of ${n}"><span class="mono">0.00</span>`;
      row.querySelector("input").addEventListener("input", (ev) => {
        S.panels[S.active].mix[n] = parseFloat(ev.target.value);
        renderStyle(); changed();
      });
      mix.appendChild(row);
    }
    document.querySelectorAll(".tab").forEach((t) => {
      t.onclick = () => {
        const p = S.panels[S.active];
        p.mode = t.dataset.mode;
        if (p.mode === "mix" && !Object.values(p.mix).some((w) => w > 0)) p.mix = { [p.label]: 1 };
        if (p.mode === "expr" && !p.expr) p.expr = p.label;
        renderStyle(); checkExpr(); changed();
      };
    });
    $("expr").addEventListener("input", (ev) => {
      S.panels[S.active].expr = ev.target.value;
      $("style-string").textContent = ev.target.value.trim() ? "style: " + ev.target.value.trim() : "";
      renderPanels();
      clearTimeout(S.exprTimer);
      S.exprTimer = setTimeout(() => { checkExpr(); changed(); }, 250);
    });
  }

  // the expression checked by the server with generate.py's parser and messages
  async function checkExpr() {
    const p = S.panels[S.active], el = $("expr-check");
    if (p.mode !== "expr") return;
    if (!p.expr.trim()) { el.className = "check muted"; el.textContent = "type an expression"; return; }
    try {
      const r = await (await api("/api/style", { style: p.expr })).json();
      el.className = "check ok";
      el.textContent = "✓ " + r.text;
    } catch (e) {
      el.className = "check bad";
      el.textContent = e.message;
    }
  }

  // ------------------------------------------------------------------------------------------
  // Walk like this clip: a dropped BVH file's style, as a mix of the known styles, on the path
  // ------------------------------------------------------------------------------------------
  async function uploadClip(file) {
    const box = $("clip-result");
    if (!file) return;
    box.className = "clip-result muted";
    box.textContent = `reading ${file.name}…`;
    try {
      const r = await fetch("/api/clip?name=" + encodeURIComponent(file.name), {
        method: "POST", headers: { "Content-Type": "application/octet-stream" }, body: file,
      });
      const res = await r.json().catch(() => ({ error: `${r.status} ${r.statusText}` }));
      if (!r.ok) throw new Error(res.error || `${r.status} ${r.statusText}`);
      S.clip = res;
      showClip(res);
      // the active panel walks the recovered mix, at the clip's speed, on the drawn path
      const p = S.panels[S.active];
      p.mode = "mix";
      p.mix = Object.fromEntries(res.mix);
      const speed = $("speed");
      speed.value = Math.min(parseFloat(speed.max), Math.max(parseFloat(speed.min), res.speed));
      $("speed-value").textContent = `${parseFloat(speed.value).toFixed(2)} m/s`;
      renderStyle(); drawFloor(); changed(true);
    } catch (e) {
      S.clip = null;
      box.className = "clip-result bad";
      box.textContent = e.message;
    }
  }

  function showClip(res) {
    const box = $("clip-result");
    box.className = "clip-result";
    box.innerHTML = "";
    const head = document.createElement("div");
    head.className = "muted";
    head.textContent = `${res.name}: ${res.seconds.toFixed(1)} s at ${res.speed.toFixed(2)} m/s · nearest ` +
      res.nearest.map(([n]) => n).join(", ") + ` · found in ${(res.search_ms / 1000).toFixed(1)} s`;
    box.appendChild(head);
    const bars = document.createElement("div");
    bars.className = "bars"; bars.id = "clip-mix";
    for (const [n, w] of res.mix) {
      const name = document.createElement("span"); name.textContent = n;
      const track = document.createElement("span");
      const fill = document.createElement("div"); fill.className = "bar-fill"; fill.style.width = `${100 * w}%`;
      track.appendChild(fill);
      const pct = document.createElement("span"); pct.className = "mono"; pct.textContent = `${Math.round(100 * w)}%`;
      bars.append(name, track, pct);
    }
    box.appendChild(bars);
  }

  const drop = $("clip-drop");
  drop.addEventListener("dragover", (ev) => { ev.preventDefault(); drop.classList.add("over"); });
  drop.addEventListener("dragleave", () => drop.classList.remove("over"));
  drop.addEventListener("drop", (ev) => {
    ev.preventDefault(); drop.classList.remove("over");
    uploadClip(ev.dataTransfer.files[0]);
  });
  drop.addEventListener("keydown", (ev) => {
    if (ev.key === "Enter" || ev.key === " ") { ev.preventDefault(); ev.stopPropagation(); $("clip-file").click(); }
  });
  drop.addEventListener("click", (ev) => { if (!ev.target.closest("label")) $("clip-file").click(); });
  $("clip-file").addEventListener("change", (ev) => { uploadClip(ev.target.files[0]); ev.target.value = ""; });

  // ------------------------------------------------------------------------------------------
  // Generate
  // ------------------------------------------------------------------------------------------
  function zValue() {
    const m = $("z-mode").value;
    return m === "k" ? Math.max(1, Math.min(4, parseInt($("z-k").value, 10) || 1)) : m;
  }

  function buildRequest() {
    const pts = pathPoints();
    // at most ~5000 points: thin long paths (the server allows more, drawing never needs it)
    const step = Math.max(1, Math.ceil(pts.length / 5000));
    const thin = pts.filter((_, i) => i % step === 0 || i === pts.length - 1);
    return {
      points: thin.map(([x, z]) => [+x.toFixed(4), +z.toFixed(4)]),
      styles: S.panels.map(styleString),
      z: zValue(),
      seed: Math.min(2147483647, Math.max(0, parseInt($("seed").value, 10) || 0)),
      speed: parseFloat($("speed").value),
    };
  }

  let autoTimer = null;
  function changed(now) {
    if (S.mode === "steer") { steerStyle(); return; }  // the walker blends to the edited style
    if (!$("auto").checked || !pathPoints().length) return;
    clearTimeout(autoTimer);
    autoTimer = setTimeout(generate, now ? 0 : 120);
  }

  async function generate() {
    if (pathPoints().length < 2) { showError("draw a path first (or pick a shape)"); return; }
    const req = buildRequest();
    if (S.inflight) S.inflight.abort();
    const ctl = new AbortController();
    S.inflight = ctl;
    const seq = ++S.seq;
    setStatus("generating…");
    const t0 = performance.now();
    const slow = setTimeout(() => explainWait(req, seq), 700);
    try {
      const res = await (await api("/api/generate", req, ctl.signal)).json();
      if (seq !== S.seq) return;
      const keepTime = S.result ? S.time : 0;
      S.result = res; S.request = req;
      S.time = keepTime % (res.frames / res.fps);
      S.selected = Math.min(S.selected, res.motions.length - 1);
      showError(null);
      $("hint").hidden = true;
      refreshMotions();
      loadCharacter();
      const ms = performance.now() - t0;
      setStatus(`${res.frames} frames · ${res.length_m.toFixed(1)} m · server ${res.server_ms.total.toFixed(0)} ms · ` +
                `round trip ${ms.toFixed(0)} ms`);
    } catch (e) {
      if (e.name === "AbortError") return;
      if (seq !== S.seq) return;
      showError(e.message);
      setStatus("");
    } finally {
      clearTimeout(slow);
      if (S.inflight === ctl) S.inflight = null;
    }
  }

  // A request taking long: say what it waits for (G compiling for a new path length or number of
  // walks, which the server's background warm-up has not reached yet) and how long that takes.
  async function explainWait(req, seq) {
    let info;
    try { info = await (await api("/api/model")).json(); } catch (e) { return; }
    if (seq !== S.seq || !S.inflight) return;
    const bucket = (n, sizes) => sizes.find((s) => n <= s) || sizes[sizes.length - 1];
    const samples = Math.floor(polyLength(req.points) / (req.speed / info.fps)) + 1;
    const walks = req.styles.length * (typeof req.z === "number" ? req.z : 1);
    const T = bucket(samples, info.buckets.samples), B = bucket(walks, info.buckets.batch);
    const ready = info.compiled.length, total = info.programs;
    const about = info.compile_s ? `about ${Math.ceil(info.compile_s)} s` : "a few seconds";
    const compiled = info.compiled.some(([t, b]) => t === T && b === B);
    setStatus(compiled
      ? `generating… waiting for the server (another generation is running)`
      : `generating… compiling the generator for paths of ${T} samples × ${B} walk${B > 1 ? "s" : ""}, ` +
        `once (${about}); warmed up ${ready} of ${total}`);
  }

  // the steered walker's character: the model's body from a GLB of a short walk (its animation
  // unused), posed live from each step's rotations; the rig picker applies to downloads only
  async function loadSteerCharacter() {
    if (!S.three || !ST.joints) return;
    const seq = ++ST.char.seq;
    ST.char.loaded = false;
    try {
      const body = { points: [[0, 0], [2, 0]], styles: [ST.style], z: "zero", seed: 0, format: "glb" };
      const buf = await (await api("/api/export", body)).arrayBuffer();
      if (seq !== ST.char.seq) return;
      await S.three.loadPosed(buf, ST.joints);
      S.char.seq++; S.char.loaded = false;  // the view now holds the steered walker, not the drawn walks
      if (seq !== ST.char.seq) return;
      ST.char.loaded = true;
      S.three.setPath(ST.curve.concat(ST.ahead));
    } catch (e) {
      if (seq === ST.char.seq) showError("character: " + e.message);
    }
  }

  // the character: the GLB of the same request (every motion, one animation each, on the chosen rig)
  async function loadCharacter() {
    if (!S.three || !S.request) return;
    const seq = ++S.char.seq;
    S.char.loaded = false;
    try {
      const body = { ...S.request, format: "glb" };
      if (S.rig) body.rig = S.rig;
      const buf = await (await api("/api/export", body)).arrayBuffer();
      if (seq !== S.char.seq) return;
      S.three.setPath(S.result.curve);
      const info = await S.three.load(buf);
      ST.char.seq++; ST.char.loaded = false;  // the view now holds these walks, not the steered one
      if (seq !== S.char.seq) return;
      S.char = { seq, loaded: true, info, bytes: buf.byteLength };
    } catch (e) {
      if (seq === S.char.seq) showError("character: " + e.message);
    }
  }

  function refreshMotions() {
    const sel = $("motion");
    sel.innerHTML = "";
    const ms = S.result ? S.result.motions : [];
    ms.forEach((m, i) => {
      const o = document.createElement("option");
      o.value = i; o.textContent = m.title;
      sel.appendChild(o);
    });
    sel.value = String(S.selected);
    const T = S.result ? S.result.frames : 1;
    $("scrub").max = Math.max(0, T - 1);
    document.querySelectorAll(".dl").forEach((b) => { b.disabled = !S.result; });
  }

  async function download(fmt) {
    if (!S.request) return;
    const btn = $("dl-" + fmt), label = btn.textContent;
    btn.disabled = true; btn.textContent = fmt === "gif" ? "drawing…" : "…";
    if (fmt === "gif" && S.result) {
      // matplotlib draws every frame of every panel, the shaded body: about 0.15 s each on one core
      const n = S.result.frames * S.result.motions.length;
      setStatus(`drawing the GIF: ${S.result.frames} frames × ${S.result.motions.length} panel(s), ` +
                `about ${Math.max(1, Math.round(n * 0.15))} s`);
    }
    try {
      const body = { ...S.request, format: fmt, index: S.selected };
      if (S.rig && (fmt === "bvh" || fmt === "glb")) body.rig = S.rig;
      const r = await api("/api/export", body);
      const blob = await r.blob();
      const cd = r.headers.get("Content-Disposition") || "";
      const m = /filename="([^"]+)"/.exec(cd);
      const a = document.createElement("a");
      a.href = URL.createObjectURL(blob);
      a.download = m ? m[1] : `motiongan.${fmt}`;
      document.body.appendChild(a); a.click(); a.remove();
      setTimeout(() => URL.revokeObjectURL(a.href), 10000);
      showError(null);
    } catch (e) { showError(e.message); }
    finally {
      btn.disabled = false; btn.textContent = label;
      if (fmt === "gif") setStatus("");
    }
  }

  // ------------------------------------------------------------------------------------------
  // 3-D view: a perspective camera drawn with Canvas 2-D
  // ------------------------------------------------------------------------------------------
  const view = $("view");
  const LEFT = /^(Left|L(?=[A-Z_]))/, RIGHT = /^(Right|R(?=[A-Z_]))/;

  function currentFrame() {
    if (!S.result) return 0;
    return Math.min(S.time * S.result.fps, S.result.frames - 1);
  }

  // joint positions at a fractional frame (linear between the 15 Hz samples: smooth at 60 Hz)
  function samplePose(positions, f) {
    const a = Math.floor(f), b = Math.min(a + 1, positions.length - 1), t = f - a;
    const A = positions[a], B = positions[b];
    if (t === 0 || a === b) return A;
    return A.map((p, j) => [p[0] + (B[j][0] - p[0]) * t, p[1] + (B[j][1] - p[1]) * t, p[2] + (B[j][2] - p[2]) * t]);
  }

  function makeCamera(target, yaw, pitch, dist, vw, vh) {
    const cp = Math.cos(pitch);
    const eye = [target[0] + dist * cp * Math.sin(yaw), target[1] + dist * Math.sin(pitch),
                 target[2] + dist * cp * Math.cos(yaw)];
    let f = [target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]];
    const fl = Math.hypot(...f); f = f.map((v) => v / fl);
    let r = [-f[2], 0, f[0]];  // f x up (up = +y): screen right
    const rl = Math.hypot(...r) || 1; r = r.map((v) => v / rl);
    const u = [r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]];
    // 40 degrees across the panel's shorter side, so a narrow panel still holds the body
    const focal = (Math.min(vw, vh) / 2) / Math.tan((40 * Math.PI / 180) / 2);
    return {
      eye, f, r, u, focal, vw, vh,
      // camera coordinates of a world point: (right, up, depth)
      cam(p) {
        const d = [p[0] - eye[0], p[1] - eye[1], p[2] - eye[2]];
        return [d[0] * r[0] + d[1] * r[1] + d[2] * r[2], d[0] * u[0] + d[1] * u[1] + d[2] * u[2],
                d[0] * f[0] + d[1] * f[1] + d[2] * f[2]];
      },
      screen(c) { return [vw / 2 + focal * c[0] / c[2], vh / 2 - focal * c[1] / c[2]]; },
    };
  }

  const NEAR = 0.1;
  // a world segment clipped to the near plane, in screen pixels (null when behind the camera)
  function segment(cam, a, b) {
    let ca = cam.cam(a), cb = cam.cam(b);
    if (ca[2] < NEAR && cb[2] < NEAR) return null;
    if (ca[2] < NEAR || cb[2] < NEAR) {
      const t = (NEAR - ca[2]) / (cb[2] - ca[2]);
      const m = [ca[0] + (cb[0] - ca[0]) * t, ca[1] + (cb[1] - ca[1]) * t, NEAR];
      if (ca[2] < NEAR) ca = m; else cb = m;
    }
    return [cam.screen(ca), cam.screen(cb), (ca[2] + cb[2]) / 2];
  }

  function heading(root, f) {
    const T = root.length, a = Math.max(0, Math.floor(f) - 6), b = Math.min(T - 1, Math.floor(f) + 6);
    const dx = root[b][0] - root[a][0], dz = root[b][2] - root[a][2];
    return Math.hypot(dx, dz) > 1e-6 ? Math.atan2(dx, dz) : null;
  }

  function lerpAngle(a, b, t) {
    let d = b - a;
    while (d > Math.PI) d -= 2 * Math.PI;
    while (d < -Math.PI) d += 2 * Math.PI;
    return a + d * t;
  }

  function pathBounds() {
    const pts = S.mode === "steer" ? ST.curve : S.result ? S.result.curve : pathPoints();
    let x0 = Infinity, x1 = -Infinity, z0 = Infinity, z1 = -Infinity;
    for (const [x, z] of pts) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); z0 = Math.min(z0, z); z1 = Math.max(z1, z); }
    if (!isFinite(x0)) return { c: [0, 0.9, 0], size: 4 };
    return { c: [(x0 + x1) / 2, 0.9, (z0 + z1) / 2], size: Math.max(x1 - x0, z1 - z0, 3) };
  }

  function drawPanel(g, m, index, vx, vy, vw, vh, f, dt, character) {
    const title = m ? m.title : "";
    g.save();
    g.beginPath(); g.rect(vx, vy, vw, vh); g.clip();
    g.translate(vx, vy);
    if (character) return drawCharacterPanel(g, m, index, vx, vy, vw, vh, f, dt, character, title);
    const sky = g.createLinearGradient(0, 0, 0, vh);
    sky.addColorStop(0, "#1d2536"); sky.addColorStop(0.55, "#121826"); sky.addColorStop(1, "#0b0e16");
    g.fillStyle = sky; g.fillRect(0, 0, vw, vh);

    const pose = m ? samplePose(m.positions, f) : null;
    const { cam, target } = panelCamera(m, pose, index, vw, vh, f, dt);
    drawScene(g, cam, target, pose, f);
    drawTitle(g, title);
    g.restore();
  }

  // the camera of a panel: following the walker (its hips) or orbiting the path
  function panelCamera(m, pose, index, vw, vh, f, dt) {
    const root = m ? m.positions.map((p) => p[0]) : null;
    let cam, target;
    if (S.camera === "follow" && pose) {
      const st = S.follow;
      target = [pose[0][0], Math.max(0.3, pose[0][1] - 0.1), pose[0][2]];  // the hips, a little lower
      const h = heading(root, f);
      // the camera trails the walker at a three-quarter angle; yaw eases to changes of heading
      const prev = st.smoothYaw[index];
      const want = h === null ? (prev ?? st.yaw) : h + Math.PI + st.yaw;
      st.smoothYaw[index] = prev === undefined ? want : lerpAngle(prev, want, Math.min(1, dt * 2.5));
      cam = makeCamera(target, st.smoothYaw[index], st.pitch, st.dist, vw, vh);
    } else {
      const b = pathBounds();
      target = b.c;
      cam = makeCamera(target, S.orbit.yaw, S.orbit.pitch, S.orbit.dist * Math.max(1, b.size / 5), vw, vh);
    }
    if (index === 0) S.camera0 = { eye: cam.eye, target };  // what the first panel looks at (tests)
    return { cam, target };
  }

  // a character panel: three.js draws the scene under this canvas; here only the title
  function drawCharacterPanel(g, m, index, vx, vy, vw, vh, f, dt, character, title) {
    const pose = m ? samplePose(m.positions, f) : null;
    const { cam, target } = panelCamera(m, pose, index, vw, vh, f, dt);
    character.push({ x: vx, y: vy, w: vw, h: vh, index, eye: cam.eye, target });
    drawTitle(g, title);
    g.restore();
  }

  function drawTitle(g, title) {
    if (!title) return;
    g.font = "600 13px system-ui, sans-serif";
    const tw = g.measureText(title).width;
    g.fillStyle = "rgba(14,18,27,0.7)";
    g.fillRect(10, 10, tw + 18, 24);
    g.fillStyle = "#e6ebf4";
    g.fillText(title, 19, 27);
  }

  // the path drawn in the 3-D view and how much of it is walked at frame f
  function scenePath(f) {
    if (S.mode === "steer") return { curve: ST.curve.concat(ST.ahead), k: Math.floor(f) };
    if (S.result) return { curve: S.result.curve, k: Math.floor(f) };
    return { curve: pathPoints(), k: 0 };
  }

  function drawScene(g, cam, target, pose, f) {

    // floor grid, fading with distance from what the camera looks at
    const R = S.camera === "follow" ? 9 : Math.ceil(pathBounds().size * 0.75 + 4);
    const gx = Math.round(target[0]), gz = Math.round(target[2]);
    g.lineWidth = 1;
    for (let i = -R; i <= R; i++) {
      for (let j = -R; j < R; j++) {
        for (const [a, b] of [[[gx + i, 0, gz + j], [gx + i, 0, gz + j + 1]], [[gx + j, 0, gz + i], [gx + j + 1, 0, gz + i]]]) {
          const s = segment(cam, a, b);
          if (!s) continue;
          const dist = Math.hypot((a[0] + b[0]) / 2 - target[0], (a[2] + b[2]) / 2 - target[2]);
          const alpha = Math.max(0, 1 - dist / R) * 0.55;
          if (alpha <= 0.01) continue;
          const major = (a[0] === b[0] ? a[0] : a[2]) % 5 === 0;
          g.strokeStyle = major ? `rgba(120,140,180,${alpha})` : `rgba(80,96,130,${alpha * 0.8})`;
          g.beginPath(); g.moveTo(...s[0]); g.lineTo(...s[1]); g.stroke();
        }
      }
    }

    // the path on the floor: walked part brighter
    const { curve, k } = scenePath(f);
    if (curve.length) {
      g.lineCap = "round";
      for (let i = 1; i < curve.length; i++) {
        const s = segment(cam, [curve[i - 1][0], 0.002, curve[i - 1][1]], [curve[i][0], 0.002, curve[i][1]]);
        if (!s) continue;
        g.strokeStyle = i <= k ? "rgba(255,122,89,0.95)" : "rgba(255,122,89,0.45)";
        g.lineWidth = Math.max(1.2, Math.min(5, cam.focal * 0.025 / s[2]));
        g.beginPath(); g.moveTo(...s[0]); g.lineTo(...s[1]); g.stroke();
      }
    }

    if (pose) {
      const parents = S.model.parents, names = S.model.joint_names;
      // shadow: the bones pressed onto the floor, one path so that overlaps do not darken
      const rootCam = cam.cam([pose[0][0], 0, pose[0][2]]);
      if (rootCam[2] > NEAR) {
        g.strokeStyle = "rgba(0,0,0,0.42)";
        g.lineCap = g.lineJoin = "round";
        g.lineWidth = Math.max(1, cam.focal * 0.05 / rootCam[2]);
        g.beginPath();
        for (let j = 1; j < pose.length; j++) {
          const p = pose[parents[j]], c = pose[j];
          const s = segment(cam, [p[0], 0.001, p[2]], [c[0], 0.001, c[2]]);
          if (s) { g.moveTo(...s[0]); g.lineTo(...s[1]); }
        }
        g.stroke();
      }
      // bones far to near
      const segs = [];
      for (let j = 1; j < pose.length; j++) {
        const s = segment(cam, pose[parents[j]], pose[j]);
        if (s) segs.push([s, j]);
      }
      segs.sort((a, b) => b[0][2] - a[0][2]);
      for (const [s, j] of segs) {
        const n = names[j];
        const side = LEFT.test(n) ? "left" : RIGHT.test(n) ? "right" : "mid";
        const shade = Math.max(0.55, Math.min(1, 1.25 - s[2] * 0.06));
        const col = side === "left" ? [94, 200, 255] : side === "right" ? [255, 176, 103] : [232, 237, 245];
        const w = Math.max(1.5, cam.focal * 0.036 / s[2]);
        g.strokeStyle = `rgba(${col.map((v) => Math.round(v * shade)).join(",")},1)`;
        g.lineWidth = w;
        g.beginPath(); g.moveTo(...s[0]); g.lineTo(...s[1]); g.stroke();
        const e = cam.cam(pose[j]);
        if (e[2] > NEAR) {
          const [sx, sy] = cam.screen(e);
          const rad = /Head/.test(n) && !/End/.test(n) ? cam.focal * 0.085 / e[2] : w * 0.6;
          g.fillStyle = /Head/.test(n) && !/End/.test(n) ? "#f3f6fb" : g.strokeStyle;
          g.beginPath(); g.arc(sx, sy, rad, 0, 2 * Math.PI); g.fill();
        }
      }
    }
  }

  let last = performance.now();
  function frame(now) {
    const dt = Math.min(0.1, (now - last) / 1000);
    last = now;
    const dpr = window.devicePixelRatio || 1;
    const W = Math.round(view.clientWidth * dpr), H = Math.round(view.clientHeight * dpr);
    if (view.width !== W || view.height !== H) { view.width = W; view.height = H; }
    const g = view.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    const w = view.clientWidth, h = view.clientHeight;
    const steer = S.mode === "steer";
    if (steer) steerFrame(dt);
    const res = steer ? null : S.result;
    if (res && S.playing) {
      S.time = (S.time + dt * S.rate) % (res.frames / res.fps);
    }
    const f = steer ? steerFrameIndex() : currentFrame();
    const ms = steer ? [steerMotion()] : res ? res.motions : [null];
    const n = ms.length, cols = n <= 3 ? n : Math.ceil(n / 2), rows = Math.ceil(n / cols);
    const cw = w / cols, ch = h / rows;
    // the steered walker's character is posed sample by sample (character.js's pose); in draw mode
    // it plays the downloaded animation
    const steerChar = steer && S.look === "character" && S.three && ST.char.loaded && ST.samples.length > 0 &&
      ST.rots.length === ST.samples.length;
    const character = steerChar || (!steer && S.look === "character" && S.three && S.char.loaded && res &&
      S.three.count === n) ? [] : null;
    g.clearRect(0, 0, w, h);
    for (let i = 0; i < n; i++) {
      const cx = (i % cols) * cw, cy = Math.floor(i / cols) * ch;
      drawPanel(g, ms[i], i, cx, cy, cw, ch, f, dt, character);
      if (n > 1) {
        g.strokeStyle = i === S.selected ? "rgba(94,200,255,0.75)" : "#283248";
        g.lineWidth = i === S.selected ? 2 : 1;
        g.strokeRect(cx + 0.5, cy + 0.5, cw - 1, ch - 1);
      }
    }
    const v3 = $("view3d");
    v3.style.display = character ? "block" : "none";
    if (character) {
      Object.assign(v3.style, { left: view.offsetLeft + "px", top: view.offsetTop + "px", width: w + "px", height: h + "px" });
      if (steer) {
        const i = Math.floor(f), j = Math.min(i + 1, ST.rots.length - 1);
        S.three.pose(ST.rots[i], ST.rots[j], f - i, ST.samples[i][0], ST.samples[j][0]);
      }
      S.three.render(character, steer ? 0 : f / res.fps, w, h, dpr);
    }
    if (res) {
      $("scrub").value = String(Math.floor(f));
      $("time").textContent = `${(f / res.fps).toFixed(1)} / ${(res.frames / res.fps).toFixed(1)} s`;
      drawFloor();
    }
    if (steer) {
      if (S.camera0) ST.cam = { clock: ST.base + steerFrameIndex(), ...S.camera0 };  // the clock as drawn
      $("time").textContent = `${(ST.clock / ST.fps).toFixed(1)} s`;
      drawFloor();
      if (S.frameCount % 6 === 0) renderSteerInfo();
    }
    S.frameCount++;
    requestAnimationFrame(frame);
  }

  // camera by mouse: drag to turn, wheel to zoom; a click on a panel selects its motion
  let drag = null;
  view.addEventListener("pointerdown", (ev) => {
    view.setPointerCapture(ev.pointerId);
    drag = { x: ev.clientX, y: ev.clientY, moved: false };
  });
  view.addEventListener("pointermove", (ev) => {
    if (!drag) return;
    const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
    drag.x = ev.clientX; drag.y = ev.clientY;
    const c = S.camera === "follow" ? S.follow : S.orbit;
    c.yaw -= dx * 0.008;
    c.pitch = Math.max(0.03, Math.min(1.45, c.pitch + dy * 0.006));
  });
  view.addEventListener("pointerup", (ev) => {
    if (drag && !drag.moved && S.result && S.result.motions.length > 1) {
      const r = view.getBoundingClientRect(), n = S.result.motions.length;
      const cols = n <= 3 ? n : Math.ceil(n / 2), rows = Math.ceil(n / cols);
      const i = Math.floor((ev.clientY - r.top) / (r.height / rows)) * cols + Math.floor((ev.clientX - r.left) / (r.width / cols));
      if (i < n) { S.selected = i; $("motion").value = String(i); }
    }
    drag = null;
  });
  view.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    const c = S.camera === "follow" ? S.follow : S.orbit;
    c.dist = Math.max(1.5, Math.min(60, c.dist * Math.exp(ev.deltaY * 0.001)));
  }, { passive: false });

  // ------------------------------------------------------------------------------------------
  // Steer: one walker generated as it goes (the server's demo/steer.py), turned and sped up live
  // ------------------------------------------------------------------------------------------
  // The page owns the path: it predicts it from the input now (turn rate and speed held
  // constant for the lookahead) and sends it with every step, so a key reaches the generator at the
  // next step. Steps are short polls, each for the few samples that keep a small buffer ahead
  // of the clock (its size follows the round trip), so the walker never waits and a key shows soon.
  const TURN_RATE = 1.2;     // rad/s with a turn key held: a 1 m radius at 1.2 m/s
  const TURN_EASE_S = 0.1;   // the turn rate eases in and out, so the path's curvature never jumps
  const ACCEL = 0.8;         // m/s per second with a speed key held
  const KEEP = 240;          // samples kept for drawing (16 s at 15 Hz): the page's memory stays flat
  const MIN_STEP = 4;        // samples a step asks for at least: a step costs the server one G call,
                             // whatever its size, so fewer, larger steps let it hold more walkers
  const DEADZONE = 0.15;     // of a gamepad's stick
  const KEYS = { ArrowLeft: "left", KeyA: "left", ArrowRight: "right", KeyD: "right",
                 ArrowUp: "faster", KeyW: "faster", ArrowDown: "slower", KeyS: "slower" };
  const ST = {
    session: null, starting: false, inflight: null, retryAt: 0, styleBusy: false, styleKey: "",
    fps: 15, lookahead: 32, maxSamples: 16,
    next: 1, lastPoint: [0, 0], psi: 0,  // the path's frontier: the next step's first sample, the point and heading before it
    speed: 1.2, omega: 0,                // the input now: m/s along the path, rad/s of turning (+: to the right)
    held: new Set(),
    samples: [], curve: [], base: 0,     // the last KEEP samples' joints and path points; base: the first's index
    ahead: [],                           // the path predicted beyond them (drawn ahead of the walker)
    clock: 0,                            // the display time in samples since the walker started
    driven: false,                       // tests: the clock moves only by tick(), not with real time
    rtt: 0.15, serverMs: 0, stalls: 0, walked: 0, style: "", blend: 1,
    record: null,                        // tests: every step's answer
    cam: null,
    rots: [],                            // the kept samples' local joint rotations (the character), with samples
    joints: null,                        // their joints' names (the GLB's), from the start's answer
    char: { seq: 0, loaded: false },     // the character posed live: the GLB's body, its joints turned by rots
  };
  const emitted = () => ST.base + ST.samples.length;
  const clamp = (v, lo, hi) => Math.max(lo, Math.min(hi, v));

  function steerFrameIndex() { return clamp(ST.clock - ST.base, 0, Math.max(0, ST.samples.length - 1)); }
  function steerPose() { return ST.samples.length ? samplePose(ST.samples, steerFrameIndex()) : null; }
  function steerMotion() {
    if (!ST.samples.length) return null;
    const title = ST.blend < 1 ? `${ST.style} (blending in, ${Math.round(100 * ST.blend)} %)` : ST.style;
    return { title, positions: ST.samples };
  }

  // samples to keep ahead of the clock: the round trip and a little, within one step's worth
  function bufferTarget() { return clamp(Math.ceil(ST.fps * (0.05 + 1.5 * ST.rtt)), 2, ST.maxSamples); }

  function steerZ() {
    return { z: $("z-mode").value === "zero" ? "zero" : "seed",
             seed: Math.min(2147483647, Math.max(0, parseInt($("seed").value, 10) || 0)) };
  }

  function gamepad() {
    const pads = navigator.getGamepads ? navigator.getGamepads() : [];
    for (const p of pads) {
      if (!p || !p.connected) continue;
      const dz = (v) => (Math.abs(v || 0) < DEADZONE ? 0 : v);
      const trig = (i) => (p.buttons[i] ? p.buttons[i].value : 0);
      return { turn: dz(p.axes[0]), accel: clamp(-dz(p.axes[1]) + trig(7) - trig(6), -1, 1) };
    }
    return null;
  }

  // the input over dt seconds: keys held and a gamepad
  function steerInput(dt) {
    let turn = (ST.held.has("right") ? 1 : 0) - (ST.held.has("left") ? 1 : 0);
    let accel = (ST.held.has("faster") ? 1 : 0) - (ST.held.has("slower") ? 1 : 0);
    const pad = gamepad();
    if (pad) { turn += pad.turn; accel += pad.accel; }
    ST.omega += (TURN_RATE * clamp(turn, -1, 1) - ST.omega) * Math.min(1, dt / TURN_EASE_S);
    const [lo, hi] = S.model.limits.speed_m_per_s;
    ST.speed = clamp(ST.speed + ACCEL * clamp(accel, -1, 1) * dt, lo, hi);
  }

  // the path from the frontier on, the input now held: count points, one a sample
  function predict(count) {
    const pts = [], psis = [];
    let [x, z] = ST.lastPoint, psi = ST.psi;
    const step = ST.speed / ST.fps, turn = ST.omega / ST.fps;
    for (let i = 0; i < count; i++) {
      psi += turn; x += step * Math.cos(psi); z += step * Math.sin(psi);
      pts.push([+x.toFixed(4), +z.toFixed(4)]); psis.push(psi);
    }
    return { pts, psis };
  }

  function steerStep(n) {
    const session = ST.session, from = ST.next;
    const { pts, psis } = predict(n + ST.lookahead);
    const t0 = performance.now(), sentAt = ST.clock;
    ST.inflight = (async () => {
      try {
        const r = await (await api("/api/steer/step", { session, from, samples: n, ahead: pts })).json();
        if (session !== ST.session) return;
        for (let i = 0; i < r.positions.length; i++) {
          const c = r.curve[i], prev = ST.curve[ST.curve.length - 1];
          if (prev) ST.walked += Math.hypot(c[0] - prev[0], c[1] - prev[1]);
          ST.samples.push(r.positions[i]); ST.curve.push(c);
          if (r.rotations) ST.rots.push(r.rotations[i]);
        }
        const drop = ST.samples.length - KEEP;
        if (drop > 0) {
          ST.samples.splice(0, drop); ST.curve.splice(0, drop); ST.base += drop;
          ST.rots.splice(0, ST.rots.length - ST.samples.length);
        }
        const used = r.next - from;  // predicted points now walked
        if (used > 0) ST.psi = psis[used - 1];
        ST.next = r.next; ST.lastPoint = r.last_point; ST.ahead = pts.slice(Math.max(0, used));
        if (ST.char.loaded) S.three.setPath(ST.curve.concat(ST.ahead));
        ST.style = r.style; ST.blend = r.blend[r.blend.length - 1];
        ST.serverMs = r.server_ms.total;
        // the first step compiles (once per server): not a round trip to plan by
        if (r.index0 > 0) ST.rtt = 0.8 * ST.rtt + 0.2 * Math.min(1, (performance.now() - t0) / 1000);
        if (ST.record) ST.record.push({ index0: r.index0, positions: r.positions, curve: r.curve, blend: r.blend,
                                        style: r.style, sentAt, answeredAt: ST.clock, omega: ST.omega });
      } catch (e) {
        if (session !== ST.session) return;
        ST.retryAt = performance.now() + 500;
        if (e.status === 404) {  // dropped by the server (idle too long, or restarted): a new walker from here
          ST.session = null;
          setStatus("the server had dropped this walker; walking on with a new one");
          startSteer();
        } else showError("steer: " + e.message);
      } finally {
        if (session === ST.session || !ST.session) ST.inflight = null;
      }
    })();
    return ST.inflight;
  }

  // a step when the buffer runs low (one at a time); returns the step running, if any
  function pump() {
    if (!ST.session || ST.starting) return null;
    if (ST.inflight || performance.now() < ST.retryAt) return ST.inflight;
    const buffered = emitted() - 1 - ST.clock;
    if (buffered >= bufferTarget()) return null;
    return steerStep(clamp(Math.ceil(bufferTarget() - buffered) + 1, MIN_STEP, ST.maxSamples));
  }

  // the edited style (the style panel's, as in draw mode) to the walker, which blends to it
  async function steerStyle() {
    const style = styleString(S.panels[S.active]), { z, seed } = steerZ();
    const key = `${style}|${z}|${seed}`;
    if (!ST.session || ST.styleBusy || !style || key === ST.styleKey) return;
    ST.styleBusy = true;
    const session = ST.session;
    try {
      await api("/api/steer/style", { session, style, z, seed });
      if (session === ST.session) showError(null);
    } catch (e) {
      if (session === ST.session) showError(e.message);  // walking on in the style it had
    } finally {
      ST.styleKey = key;  // not sent again until edited
      ST.styleBusy = false;
    }
    steerStyle();  // edited meanwhile
  }

  async function startSteer() {
    if (ST.session || ST.starting) return;
    const style = styleString(S.panels[S.active]), { z, seed } = steerZ();
    if (!style) { showError("pick a style first"); return; }
    ST.starting = true;
    renderSteer();
    const slow = setTimeout(() => setStatus("starting… the first walker compiles the generator for its window, once"), 700);
    try {
      const r = await (await api("/api/steer/start", {
        style, z, seed, start: ST.lastPoint, heading: [Math.cos(ST.psi), Math.sin(ST.psi)], speed: ST.speed,
        rotations: !!S.three,
      })).json();
      Object.assign(ST, { session: r.session, fps: r.fps, lookahead: r.lookahead, maxSamples: r.max_samples,
                          next: r.next, lastPoint: r.last_point, samples: [], curve: [], ahead: [], base: 0,
                          clock: 0, style: r.style, blend: 1, styleKey: `${style}|${z}|${seed}`, retryAt: 0,
                          rots: [], joints: r.joints || null });
      if (ST.joints && !ST.char.loaded) loadSteerCharacter();
      showError(null); setStatus("");
      $("hint").hidden = true;
    } catch (e) {
      showError(e.message); setStatus("");
    } finally {
      clearTimeout(slow);
      ST.starting = false;
      renderSteer();
    }
  }

  function stopSteer() {
    const session = ST.session;
    ST.session = null; ST.inflight = null; ST.held.clear();
    if (session) api("/api/steer/stop", { session }).catch(() => {});
    renderSteer();
  }

  // the clock: real time (tests: tick), never past the samples that are here
  function steerFrame(dt) {
    if (!ST.driven) {
      steerInput(dt);
      if (S.playing && ST.session && ST.samples.length) {
        const end = emitted() - 1, to = ST.clock + dt * ST.fps;
        if (to > end) ST.stalls++;
        ST.clock = Math.max(ST.clock, Math.min(to, end));
      }
    }
    pump();
    const pose = steerPose();
    if (pose) { floor.cx = pose[0][0]; floor.cz = pose[0][2]; floor.half = 6; }
  }

  // tests: moves the clock by dt seconds (the input too) once the samples under it are here
  async function tick(dt) {
    if (!ST.session) throw new Error("no walker: start one first");
    steerInput(dt);
    ST.clock += dt * ST.fps;
    const t0 = performance.now();
    while (emitted() - 1 < ST.clock) {
      const p = pump();
      if (p) await p; else await new Promise((res) => setTimeout(res, 20));
      if (!ST.session) throw new Error("the walker stopped");
      if (performance.now() - t0 > 60000) throw new Error("no samples for 60 s");
    }
    pump();
    return steerView();
  }

  function steerView() {
    const pose = steerPose();
    return { clock: ST.clock, emitted: emitted(), root: pose && pose[0], speed: ST.speed, omega: ST.omega,
             buffered: emitted() - 1 - ST.clock, target: bufferTarget(), rtt: ST.rtt, stalls: ST.stalls,
             style: ST.style, blend: ST.blend, drawn: S.frameCount, camera: ST.cam, session: !!ST.session };
  }

  function renderSteer() {
    const go = $("steer-go");
    go.textContent = ST.session ? "Stop" : ST.starting ? "Starting…" : "Start walking";
    go.disabled = ST.starting;
    if (S.mode === "steer" && !ST.session) {
      $("hint").textContent = "Start walking, then steer with the arrow keys (or WASD, or a gamepad).";
      $("hint").hidden = false;
    }
    renderSteerInfo();
  }

  function renderSteerInfo() {
    const deg = Math.round(((ST.psi * 180 / Math.PI) % 360 + 360) % 360);
    $("steer-info").textContent = ST.session
      ? `${ST.speed.toFixed(2)} m/s · ${deg}° · ${ST.serverMs.toFixed(0)} ms` : "";
    if (S.mode === "steer") {
      $("speed").value = ST.speed;
      $("speed-value").textContent = `${ST.speed.toFixed(2)} m/s`;
    }
  }

  function setWalkMode(mode) {
    if (mode === S.mode) return;
    S.mode = mode;
    document.body.classList.toggle("steer-mode", mode === "steer");
    $("walk-draw").classList.toggle("active", mode === "draw");
    $("walk-steer").classList.toggle("active", mode === "steer");
    S.follow.smoothYaw = [];
    if (mode === "steer") {
      ST.speed = parseFloat($("speed").value);
    } else {
      stopSteer();
      if (S.result && !S.char.loaded) loadCharacter();  // the view held the steered walker
      $("hint").textContent = HINT;
      $("hint").hidden = !!S.result;
      fitFloor(S.result ? S.result.curve : pathPoints());
    }
    renderSteer();
    drawFloor();
  }

  const HINT = $("hint").textContent;
  $("walk-draw").onclick = () => setWalkMode("draw");
  $("walk-steer").onclick = () => setWalkMode("steer");
  $("steer-go").onclick = () => {
    $("steer-go").blur();  // the keys steer, they do not press the button
    if (ST.session) stopSteer(); else startSteer();
  };
  const typing = () => ["INPUT", "SELECT", "TEXTAREA"].includes(document.activeElement.tagName);
  document.addEventListener("keydown", (ev) => {
    const a = KEYS[ev.code];
    if (S.mode !== "steer" || !a || typing() || ev.ctrlKey || ev.metaKey || ev.altKey) return;
    ev.preventDefault();  // no scrolling
    ST.held.add(a);
  });
  document.addEventListener("keyup", (ev) => { const a = KEYS[ev.code]; if (a) ST.held.delete(a); });
  window.addEventListener("blur", () => ST.held.clear());  // a key released elsewhere is not held
  window.addEventListener("pagehide", () => {
    if (ST.session) {
      navigator.sendBeacon("/api/steer/stop", new Blob([JSON.stringify({ session: ST.session })],
                                                       { type: "application/json" }));
    }
  });

  // ------------------------------------------------------------------------------------------
  // Controls
  // ------------------------------------------------------------------------------------------
  function setPlaying(on) { S.playing = on; $("play").textContent = on ? "❚❚" : "▶"; }
  $("play").onclick = () => setPlaying(!S.playing);
  document.addEventListener("keydown", (ev) => {
    if (ev.code === "Space" && !["INPUT", "SELECT", "TEXTAREA"].includes(document.activeElement.tagName)) {
      ev.preventDefault(); setPlaying(!S.playing);
    }
  });
  $("scrub").addEventListener("input", (ev) => {
    if (!S.result) return;
    setPlaying(false);
    S.time = parseInt(ev.target.value, 10) / S.result.fps;
  });
  $("rate").onchange = (ev) => { S.rate = parseFloat(ev.target.value); };
  $("camera").onchange = (ev) => { S.camera = ev.target.value; S.follow.smoothYaw = []; };
  $("look").onchange = (ev) => { S.look = ev.target.value; };
  $("rig").onchange = (ev) => { S.rig = ev.target.value; loadCharacter(); };
  $("motion").onchange = (ev) => { S.selected = parseInt(ev.target.value, 10) || 0; };
  $("speed").addEventListener("input", (ev) => {
    $("speed-value").textContent = `${parseFloat(ev.target.value).toFixed(2)} m/s`;
    if (S.mode === "steer") ST.speed = parseFloat(ev.target.value);
    drawFloor(); changed();
  });
  $("z-mode").onchange = () => { $("k-wrap").style.display = $("z-mode").value === "k" ? "" : "none"; changed(); };
  $("z-k").addEventListener("input", () => changed());
  $("seed").addEventListener("input", () => changed());
  $("generate").onclick = generate;
  document.querySelectorAll(".dl").forEach((b) => { b.onclick = () => download(b.dataset.format); });

  async function init() {
    try {
      S.model = await (await api("/api/model")).json();
    } catch (e) { showError("cannot reach the demo server: " + e.message); return; }
    $("model-info").textContent = S.model.model;
    $("model-info").title = S.model.model_details;
    const names = S.model.style_names;
    S.panels = [newPanel(names.includes("Normal") ? "Normal" : names[0])];
    buildStyleControls();
    const shapeNames = { line: "Line", circle: "Circle", s_curve: "S-curve", figure8: "Figure-8", corner: "Corner" };
    for (const s of S.model.shapes) {
      const b = document.createElement("button");
      b.textContent = shapeNames[s] || s; b.dataset.shape = s;
      b.onclick = () => preset(s);
      $("presets").appendChild(b);
    }
    $("speed").min = S.model.limits.speed_m_per_s[0];
    $("speed").max = S.model.limits.speed_m_per_s[1];
    $("speed").value = S.model.default_speed;
    $("speed-value").textContent = `${S.model.default_speed.toFixed(2)} m/s`;
    $("z-k").max = S.model.limits.max_samples_z;
    $("k-wrap").style.display = "none";
    for (const [name, desc] of Object.entries(S.model.rigs || {})) {
      const o = document.createElement("option");
      o.value = name; o.textContent = name; o.title = desc;
      $("rig").appendChild(o);
    }
    renderStyle();
    refreshMotions();
    ST.speed = S.model.default_speed;
    renderSteer();
    drawFloor();
    await characterReady;
    try {
      if (window.demoCharacter) S.three = window.demoCharacter.createView($("view3d"));
    } catch (e) { S.three = null; window.demoCharacterError = String(e); }
    if (!S.three) {
      // three.js not installed (or no WebGL): stick figures, and a one-line hint
      S.look = "stick"; $("look").value = "stick"; $("look").disabled = true; $("rig").disabled = true;
      $("three-hint").hidden = false;
    }
    requestAnimationFrame(frame);
  }

  // character.js is an ES module loaded by index.html; it says when it is in (or failed)
  const characterReady = new Promise((resolve) => {
    if ("demoCharacter" in window) resolve();
    else window.addEventListener("character-ready", () => resolve(), { once: true });
  });

  // for tests and the console
  window.demo = {
    get state() { return S; },
    get frames() { return S.result ? S.result.frames : 0; },
    get drawn() { return S.frameCount; },
    get character() { return S.char.loaded ? { ...S.char.info, bytes: S.char.bytes, rig: S.rig } : null; },
    generate,
    steer: {
      get state() { return ST; },
      view: steerView,
      tick,
      start: startSteer,
      stop: stopSteer,
      drive(on) { ST.driven = !!on; },  // the clock moves only by tick()
      record(on) { ST.record = on ? [] : null; },
      drain() { const r = ST.record || []; if (ST.record) ST.record = []; return r; },
    },
  };
  init();
})();
