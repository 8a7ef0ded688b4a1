// eddie dashboard front end: one WebSocket, one <canvas>; the 3D view (three.js, vendored)
// is loaded only when opened. No external resources.
"use strict";
(() => {
  const $ = (id) => document.getElementById(id);
  const canvas = $("view");
  const ctx = canvas.getContext("2d");
  const LAYERS = ["map", "vslam_map", "global_costmap", "local_costmap"];
  const RANGE_COLOURS = { ir: "rgba(255,80,80,0.35)", ping: "rgba(80,160,255,0.35)" };
  const COLOURS = {
    plan: "#3c3", local_plan: "#fa0", lookahead: "#ff5", goal: "#e040e0", scan: "#ff3030",
    particles: "#30e0b0", footprint: "#40a0ff", grid: "rgba(70,130,255,0.35)",
  };
  // the legend: one row per layer, with its toggle (id show-<key>) and its colours
  const LEGEND = [
    ["map", "map (/map)", true, [["#fff", "free"], ["#000", "occupied"], ["#808080", "unknown"]]],
    ["vslam_map", "vSLAM map (/rtabmap/map)", true, [["#fff", "free"], ["#000", "occupied"]]],
    ["global_costmap", "global costmap", false, [["#5000ff", "low"], ["#ff0098", "high"], ["#0ff", "inscribed"], ["#f0f", "lethal"]]],
    ["local_costmap", "local costmap", true, [["#5000ff", "low"], ["#ff0098", "high"], ["#0ff", "inscribed"], ["#f0f", "lethal"]]],
    ["grid", "metric grid", true, [["rgba(70,130,255,0.6)", "lines"]]],
    ["scan", "laser scan", true, [[COLOURS.scan, "/scan"]]],
    ["ranges", "IR / PING", true, [["#ff5050", "IR"], ["#50a0ff", "PING"]]],
    ["particles", "AMCL particles", true, [[COLOURS.particles, "/particle_cloud"]]],
    ["plans", "plans", true, [[COLOURS.plan, "global path"], [COLOURS.local_plan, "local plan"], [COLOURS.lookahead, "lookahead"], [COLOURS.goal, "goal"]]],
    ["footprint", "footprint", true, [[COLOURS.footprint, "URDF"], ["#ffffff", "costmap"]]],
    ["slam_graph", "SLAM graph", true, [["#3a6bff", "nodes"], ["#2fbf4f", "edges"], ["#ffb000", "staged moves"]]],
    ["graph", "vSLAM graph", true, [["#ff8000", "nodes"], ["#0099ff", "links"], ["#ff0000", "loop closures"]]],
    ["tf", "TF frames", false, [["#f44", "x"], ["#4f4", "y"]]],
    ["frontiers", "frontiers (explore)", true, [["#2f7bff", "open"], ["#ff3030", "abandoned"], ["#30e030", "centroid"]]],
  ];
  const state = {
    view: { cx: 0, cy: 0, scale: 40 },
    follow: true, mode: "pan", readOnly: true, footprint: 0.2245, footprintSource: "",
    pose: null, scan: null, ranges: {}, paths: {}, goal: null, goalStatus: "",
    grids: {}, status: null, estop: false, connected: false,
    particles: null, lookahead: null, footprintPoly: null, tf: null, graph: null, mux: null,
    drag: null, tilesDrawn: 0, lastError: null, lastAck: null, cursor: null,
    drawn: { particles: 0, graphNodes: 0, loops: 0, tfFrames: 0, gridStep: 0 },
    view3d: null, clouds: {},
    // 2D SLAM graph editing: the graph (node i at nodes[2i], nodes[2i+1]), interactive mode
    // as the page last switched it, and the moves staged since (node id → [x, y])
    slamGraph: null, slamEdit: false, staged: {},
  };
  let ws = null;
  let dirty = true;

  // -- palettes ----------------------------------------------------------------------
  function mapColour(v) {
    if (v === 255) return [128, 128, 128, 255];
    if (v > 100) return [128, 128, 128, 255];
    const g = Math.round(255 - v * 2.55);
    return [g, g, g, 255];
  }
  function costColour(v) {
    if (v === 255 || v === 0) return [0, 0, 0, 0];
    if (v >= 100) return [255, 0, 255, 190];       // lethal
    if (v >= 99) return [0, 255, 255, 170];        // inscribed
    const t = v / 98;
    return [Math.round(255 * t), Math.round(60 * (1 - t)), Math.round(255 * (1 - t)), Math.round(60 + 100 * t)];
  }
  const PALETTES = {};
  function palette(layer) {
    if (!PALETTES[layer]) {
      const f = layer.endsWith("map") && !layer.endsWith("costmap") ? mapColour : costColour;
      const p = new Uint8ClampedArray(256 * 4);
      for (let v = 0; v < 256; v++) p.set(f(v), v * 4);
      PALETTES[layer] = p;
    }
    return PALETTES[layer];
  }

  // -- geometry ------------------------------------------------------------------------
  function size() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; dirty = true; }
  }
  function worldToScreen(x, y) {
    const v = state.view;
    return [canvas.width / 2 + (x - v.cx) * v.scale, canvas.height / 2 - (y - v.cy) * v.scale];
  }
  function screenToWorld(sx, sy) {
    const v = state.view;
    return [v.cx + (sx - canvas.width / 2) / v.scale, v.cy - (sy - canvas.height / 2) / v.scale];
  }
  function baseTransform() {
    const v = state.view;
    ctx.setTransform(v.scale, 0, 0, -v.scale, canvas.width / 2 - v.cx * v.scale, canvas.height / 2 + v.cy * v.scale);
  }

  // -- frames from the server -----------------------------------------------------------
  function onText(m) {
    switch (m.t) {
      case "hello":
        state.readOnly = m.read_only; state.footprint = m.footprint;
        for (const v of ["tf", "cloud"]) if (state.views && state.views.has(v)) sendView(v, true);
        document.querySelectorAll(".control").forEach((e) => e.classList.toggle("hidden", m.read_only));
        break;
      case "pose":
        state.pose = m;
        if (state.follow) { state.view.cx = m.x; state.view.cy = m.y; }
        break;
      case "grid": {
        const g = { gen: m.gen, w: m.w, h: m.h, res: m.res, tile: m.tile, origin: m.origin, frame: m.frame };
        const old = state.grids[m.layer];
        if (old && old.gen === m.gen) { old.origin = m.origin; break; }
        g.canvas = document.createElement("canvas");
        g.canvas.width = m.w; g.canvas.height = m.h;
        g.ctx = g.canvas.getContext("2d");
        state.grids[m.layer] = g;
        if (m.layer === "map" && !state.pose && m.origin) {
          state.view.cx = m.origin[0] + m.w * m.res / 2; state.view.cy = m.origin[1] + m.h * m.res / 2;
        }
        break;
      }
      case "range": state.ranges[m.name] = m; break;
      case "robot": state.footprint = m.radius; state.footprintSource = m.source; break;
      case "lookahead": state.lookahead = m; break;
      case "footprint": state.footprintPoly = m.pts; break;
      case "tf": state.tf = m.frames; break;
      case "slam_graph": state.slamGraph = m; $("slam-count").textContent = `${m.count} nodes${state.slamEdit ? ", editing" : ""}`; break;
      case "graph": state.graph = m; $("graph-count").textContent = `${m.nodes} nodes, ${m.loops} loop closures`; break;
      case "path": state.paths[m.name] = m.pts; break;
      case "goal": state.goal = m.pose; state.goalStatus = m.status; showGoal(); break;
      case "status": state.status = m; showStatus(m); break;
      case "explore": state.explore = m; showExplore(m); break;
      case "frontiers": state.frontiers = m; break;
      case "log": lastLog = m.lines; showLog(m.lines); break;
      case "estop":
        state.estop = m.locked;
        $("estop").classList.toggle("locked", m.locked);
        $("estop").textContent = m.locked ? "E-STOP ENGAGED — click to release" : "EMERGENCY STOP";
        break;
      case "ack":
        state.lastAck = m;
        if (m.op === "slam") slamAcked(m.action);
        if (m.op !== "view") notice(m.msg, false);
        break;
      case "error": state.lastError = m; notice(m.msg, true); break;
      default: break;
    }
    dirty = true;
  }
  function onBinary(buf) {
    const dv = new DataView(buf);
    const n = dv.getUint32(0, true);
    const head = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
    const payload = buf.slice(4 + n);
    if (head.t === "tile") {
      const g = state.grids[head.layer];
      if (!g || g.gen !== head.gen) return;
      const cells = new Uint8Array(payload);
      const img = g.ctx.createImageData(head.w, head.h);
      const pal = palette(head.layer);
      const px = img.data;
      for (let i = 0; i < cells.length; i++) {
        const o = cells[i] * 4, j = i * 4;
        px[j] = pal[o]; px[j + 1] = pal[o + 1]; px[j + 2] = pal[o + 2]; px[j + 3] = pal[o + 3];
      }
      g.ctx.putImageData(img, head.tx * head.tile, head.ty * head.tile);
      state.tilesDrawn++;
    } else if (head.t === "particles") {
      state.particles = { head, data: new Float32Array(payload) };
    } else if (head.t === "cloud") {
      state.clouds[head.name] = head;
      if (state.view3d) state.view3d.setCloud(head, payload);
      $("cloud-count").textContent = Object.values(state.clouds).map((c) => `${c.name}: ${c.n} of ${c.total} points`).join(", ");
    } else if (head.t === "scan") {
      state.scan = { head, ranges: new Float32Array(payload) };
    } else if (head.t === "image") {
      const el = $("img-" + head.name);
      const url = URL.createObjectURL(new Blob([payload], { type: "image/jpeg" }));
      const old = el.dataset.url;
      el.src = url; el.dataset.url = url;
      if (old) URL.revokeObjectURL(old);
    }
    dirty = true;
  }

  // -- panels --------------------------------------------------------------------------
  let noticeTimer = null;
  function notice(text, isError) {
    const el = $("notice");
    el.textContent = text; el.className = isError ? "err" : "ok"; el.style.display = "block";
    clearTimeout(noticeTimer);
    noticeTimer = setTimeout(() => { el.style.display = "none"; }, 4000);
  }
  function fmt(v, unit, nd) { return v === null || v === undefined ? "–" : v.toFixed(nd) + unit; }
  function showGoal() {
    const g = state.goal;
    $("goal").textContent = g ? `(${g.x.toFixed(2)}, ${g.y.toFixed(2)}, ${(g.yaw * 180 / Math.PI).toFixed(0)}°) ${state.goalStatus}` : "–";
  }
  function panelAge(topic, capId, label) {
    const a = state.status.age[topic];
    const cap = $(capId);
    if (a === null || a === undefined) cap.textContent = `${label}: no data on ${topic}`;
    else if (a > 3) cap.textContent = `${label}: stale (${a.toFixed(0)} s) ${topic}`;
    else cap.textContent = `${label} ${topic}`;
  }
  function showStatus(m) {
    $("battery").textContent = m.battery === null ? "no data on /eddie/battery_level" : m.battery.toFixed(2);
    $("speed").textContent = m.linear === null ? "no data on /odom" : `${fmt(m.linear, " m/s", 2)}, ${fmt(m.angular, " rad/s", 2)}`;
    $("collisions").textContent = m.collisions === null ? "no data on /sim/collisions" : String(m.collisions);
    $("frame").textContent = m.frame + (m.nav_server ? " · nav server up" : "");
    state.mux = m.mux;
    const mux = m.mux;
    $("mux").textContent = mux.active ? `${mux.active} (${mux.topic})` : (mux.locks.length ? `none: locked by ${mux.locks.join(", ")}` : "none (no source active)");
    $("mux").title = `worked out from ${mux.table}`;
    panelAge("/image_raw", "cap-camera", "camera");
    panelAge("/depth/image_raw", "cap-depth", "depth");
    const body = $("rates").querySelector("tbody");
    body.textContent = "";
    for (const [topic, hz] of Object.entries(m.rates)) {
      const tr = document.createElement("tr");
      if (m.age[topic] === null) tr.className = "missing";
      const a = document.createElement("td"); a.textContent = topic;
      const b = document.createElement("td"); b.textContent = m.age[topic] === null ? "missing" : hz.toFixed(1);
      tr.append(a, b); body.append(tr);
    }
    const lines = [];
    if (!state.grids.map) lines.push(m.age["/map"] === null ? "no map on /map" : "map not placed (TF?)");
    if (!state.pose) lines.push("no robot pose (TF " + m.frame + " → base_footprint)");
    if (m.age["/scan"] === null) lines.push("no data on /scan");
    for (const [t, p] of Object.entries(m.problems)) lines.push(`${t}: ${p}`);
    $("view-status").textContent = lines.join("\n");
  }
  const LEVELS = { 10: "DEBUG", 20: "INFO", 30: "WARN", 40: "ERROR", 50: "FATAL" };
  function showLog(lines) {
    const el = $("log");
    const min = Number($("log-level").value);
    el.textContent = "";
    for (const l of lines) {
      if (l.level < min) continue;
      const div = document.createElement("div");
      div.className = "lvl" + l.level;
      div.textContent = `[${LEVELS[l.level] || l.level}] [${l.name}] ${l.msg}`;
      el.append(div);
    }
    el.scrollTop = el.scrollHeight;
  }
  let lastLog = [];

  // -- drawing -------------------------------------------------------------------------
  function shown(id) { return $(id).checked; }
  function arrow(x, y, yaw, len, colour) {
    const ex = x + len * Math.cos(yaw), ey = y + len * Math.sin(yaw);
    ctx.strokeStyle = colour; ctx.fillStyle = colour; ctx.lineWidth = 3 / state.view.scale;
    ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(ex, ey); ctx.stroke();
    const h = Math.min(0.15, len * 0.4);
    ctx.beginPath(); ctx.moveTo(ex, ey);
    ctx.lineTo(ex - h * Math.cos(yaw - 0.4), ey - h * Math.sin(yaw - 0.4));
    ctx.lineTo(ex - h * Math.cos(yaw + 0.4), ey - h * Math.sin(yaw + 0.4));
    ctx.closePath(); ctx.fill();
  }
  function draw() {
    size();
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#2b2d30"; ctx.fillRect(0, 0, canvas.width, canvas.height);
    ctx.imageSmoothingEnabled = false;
    for (const layer of LAYERS) {
      const g = state.grids[layer];
      if (!g || !g.origin || !shown("show-" + layer)) continue;
      baseTransform();
      ctx.translate(g.origin[0], g.origin[1]); ctx.rotate(g.origin[2]); ctx.scale(g.res, g.res);
      ctx.drawImage(g.canvas, 0, 0);
    }
    baseTransform();
    const px = 1 / state.view.scale;
    if (shown("show-grid")) drawGrid(px);
    if (shown("show-graph") && state.graph) drawGraph(px);
    if (shown("show-slam_graph") && state.slamGraph) drawSlamGraph(px);
    if (shown("show-frontiers") && state.frontiers) drawFrontiers(px);
    if (shown("show-particles") && state.particles) drawParticles(px);
    else state.drawn.particles = 0;
    if (shown("show-plans")) {
      for (const [name, colour] of [["plan", "#3c3"], ["local_plan", "#fa0"]]) {
        const pts = state.paths[name];
        if (!pts || pts.length < 2) continue;
        ctx.strokeStyle = colour; ctx.lineWidth = 2 * px; ctx.beginPath();
        ctx.moveTo(pts[0][0], pts[0][1]);
        for (const p of pts) ctx.lineTo(p[0], p[1]);
        ctx.stroke();
      }
    }
    if (shown("show-ranges")) {
      for (const r of Object.values(state.ranges)) {
        const len = Math.min(Math.max(r.range, 0), r.max || r.range);
        const [x, y, yaw] = r.pose;
        ctx.fillStyle = RANGE_COLOURS[r.name.split("/")[0]] || "rgba(255,255,0,0.3)";
        ctx.beginPath(); ctx.moveTo(x, y);
        ctx.arc(x, y, len, yaw - r.fov / 2, yaw + r.fov / 2); ctx.closePath(); ctx.fill();
      }
    }
    if (shown("show-scan") && state.scan) {
      const { head, ranges } = state.scan;
      const [sx, sy, syaw] = head.pose;
      ctx.fillStyle = "#ff3030";
      const d = 3 * px;
      for (let i = 0; i < ranges.length; i++) {
        const r = ranges[i];
        if (!(r >= head.rmin && r <= head.rmax)) continue;
        const a = syaw + head.amin + i * head.ainc;
        ctx.fillRect(sx + r * Math.cos(a) - d / 2, sy + r * Math.sin(a) - d / 2, d, d);
      }
    }
    if (shown("show-plans") && state.lookahead) {
      const l = state.lookahead;
      ctx.strokeStyle = COLOURS.lookahead; ctx.lineWidth = 2 * px;
      ctx.beginPath(); ctx.arc(l.x, l.y, 6 * px, 0, 2 * Math.PI); ctx.stroke();
      if (state.pose) { ctx.setLineDash([4 * px, 4 * px]); ctx.beginPath(); ctx.moveTo(state.pose.x, state.pose.y); ctx.lineTo(l.x, l.y); ctx.stroke(); ctx.setLineDash([]); }
    }
    if (state.goal && shown("show-plans")) arrow(state.goal.x, state.goal.y, state.goal.yaw, 0.5, COLOURS.goal);
    if (state.pose && shown("show-footprint")) {
      const p = state.pose;
      ctx.strokeStyle = COLOURS.footprint; ctx.fillStyle = "rgba(64,160,255,0.35)"; ctx.lineWidth = 2 * px;
      ctx.beginPath(); ctx.arc(p.x, p.y, state.footprint, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
      arrow(p.x, p.y, p.yaw, state.footprint * 1.4, "#ffffff");
      const fp = state.footprintPoly;
      if (fp && fp.length > 2) {
        ctx.strokeStyle = "#ffffff"; ctx.lineWidth = 1 * px; ctx.beginPath(); ctx.moveTo(fp[0][0], fp[0][1]);
        for (const q of fp) ctx.lineTo(q[0], q[1]);
        ctx.closePath(); ctx.stroke();
      }
    }
    if (shown("show-tf") && state.tf) drawFrames(px);
    else state.drawn.tfFrames = 0;
    if (state.drag && state.drag.kind === "keepout") {
      const d = state.drag;
      ctx.fillStyle = "rgba(230,40,40,0.35)"; ctx.strokeStyle = "#e02828"; ctx.lineWidth = 2 * px;
      ctx.fillRect(d.x0, d.y0, d.x1 - d.x0, d.y1 - d.y0);
      ctx.strokeRect(d.x0, d.y0, d.x1 - d.x0, d.y1 - d.y0);
    } else if (state.drag && state.drag.kind !== "pan") {
      const d = state.drag;
      const yaw = Math.atan2(d.y1 - d.y0, d.x1 - d.x0);
      arrow(d.x0, d.y0, yaw, Math.max(0.3, Math.hypot(d.x1 - d.x0, d.y1 - d.y0)), d.kind === "goal" ? "#e040e0" : "#30e030");
    }
  }
  // a "nice" step (1, 2 or 5 × 10^k m) at least minPx pixels long
  function niceStep(minPx) {
    const raw = minPx / state.view.scale;
    const k = Math.pow(10, Math.floor(Math.log10(raw)));
    for (const m of [1, 2, 5, 10]) if (m * k >= raw) return m * k;
    return 10 * k;
  }
  function drawGrid(px) {
    const step = niceStep(60);
    state.drawn.gridStep = step;
    const [x0, y1] = screenToWorld(0, 0), [x1, y0] = screenToWorld(canvas.width, canvas.height);
    ctx.lineWidth = px; ctx.strokeStyle = COLOURS.grid; ctx.beginPath();
    for (let x = Math.ceil(x0 / step) * step; x <= x1; x += step) { ctx.moveTo(x, y0); ctx.lineTo(x, y1); }
    for (let y = Math.ceil(y0 / step) * step; y <= y1; y += step) { ctx.moveTo(x0, y); ctx.lineTo(x1, y); }
    ctx.stroke();
    ctx.strokeStyle = "rgba(255,255,255,0.3)"; ctx.beginPath();  // the frame's axes
    ctx.moveTo(x0, 0); ctx.lineTo(x1, 0); ctx.moveTo(0, y0); ctx.lineTo(0, y1); ctx.stroke();
  }
  function drawScaleBar() {
    const step = niceStep(80);
    const len = step * state.view.scale;
    const x = canvas.width - 20 - len, y = canvas.height - 20;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.strokeStyle = "#eee"; ctx.lineWidth = 2; ctx.beginPath();
    ctx.moveTo(x, y - 5); ctx.lineTo(x, y); ctx.lineTo(x + len, y); ctx.lineTo(x + len, y - 5); ctx.stroke();
    ctx.fillStyle = "#eee"; ctx.font = "12px system-ui, sans-serif"; ctx.textAlign = "center";
    ctx.fillText(step >= 1 ? `${step} m` : `${Math.round(step * 100)} cm`, x + len / 2, y - 6);
    $("scale").textContent = `${len.toFixed(0)} px = ${step} m`;
  }
  function drawParticles(px) {
    const { head, data } = state.particles;
    const len = Math.max(0.08, 8 * px);
    ctx.strokeStyle = COLOURS.particles; ctx.lineWidth = px; ctx.beginPath();
    for (let i = 0; i < head.n; i++) {
      const x = data[i * 4], y = data[i * 4 + 1], a = data[i * 4 + 2];
      ctx.moveTo(x, y); ctx.lineTo(x + len * Math.cos(a), y + len * Math.sin(a));
    }
    ctx.stroke();
    state.drawn.particles = head.n;
  }
  function drawGraph(px) {
    let nodes = 0, loops = 0;
    for (const l of state.graph.layers) {
      const p = l.pts;
      if (l.kind === "points") {
        ctx.fillStyle = l.colour;
        const d = Math.max(0.04, 4 * px);
        for (let i = 0; i + 1 < p.length; i += 2) ctx.fillRect(p[i] - d / 2, p[i + 1] - d / 2, d, d);
        nodes += p.length / 2;
      } else {
        ctx.strokeStyle = l.colour; ctx.lineWidth = (l.loop ? 2 : 1) * px; ctx.beginPath();
        for (let i = 0; i + 3 < p.length; i += 4) { ctx.moveTo(p[i], p[i + 1]); ctx.lineTo(p[i + 2], p[i + 3]); }
        ctx.stroke();
        if (l.loop) loops += Math.floor(p.length / 4);
      }
    }
    state.drawn.graphNodes = nodes; state.drawn.loops = loops;
  }
  function drawFrontiers(px) {
    const f = state.frontiers, d = Math.max(0.05, 2 * px);
    for (const [key, colour] of [["open", "#2f7bff"], ["abandoned", "#ff3030"]]) {
      const p = f[key];
      ctx.fillStyle = colour;
      for (let i = 0; i + 1 < p.length; i += 2) ctx.fillRect(p[i] - d / 2, p[i + 1] - d / 2, d, d);
    }
    ctx.fillStyle = "#30e030";
    const r = Math.max(0.08, 4 * px);
    for (let i = 0; i + 1 < f.centroids.length; i += 2) {
      ctx.beginPath(); ctx.arc(f.centroids[i], f.centroids[i + 1], r, 0, 2 * Math.PI); ctx.fill();
    }
  }
  function drawSlamGraph(px) {
    const g = state.slamGraph, e = g.edges, n = g.nodes;
    ctx.strokeStyle = "#2fbf4f"; ctx.lineWidth = 1 * px; ctx.beginPath();
    for (let i = 0; i + 3 < e.length; i += 4) { ctx.moveTo(e[i], e[i + 1]); ctx.lineTo(e[i + 2], e[i + 3]); }
    ctx.stroke();
    const d = Math.max(0.05, (state.slamEdit ? 7 : 4) * px);
    ctx.fillStyle = "#3a6bff";
    for (let i = 0; i + 1 < n.length; i += 2) ctx.fillRect(n[i] - d / 2, n[i + 1] - d / 2, d, d);
    const moves = Object.entries(state.staged);
    const dr = state.drag && state.drag.kind === "slamnode" ? state.drag : null;
    if (dr) moves.push([String(dr.node), [dr.x1, dr.y1]]);
    ctx.strokeStyle = "#ffb000"; ctx.fillStyle = "#ffb000"; ctx.lineWidth = 2 * px;
    for (const [id, [x, y]] of moves) {
      const k = 2 * Number(id);
      if (k + 1 >= n.length) continue;
      ctx.setLineDash([4 * px, 4 * px]); ctx.beginPath(); ctx.moveTo(n[k], n[k + 1]); ctx.lineTo(x, y); ctx.stroke();
      ctx.setLineDash([]); ctx.fillRect(x - d / 2, y - d / 2, d, d);
    }
    state.drawn.slamNodes = n.length / 2; state.drawn.staged = Object.keys(state.staged).length;
  }
  // the graph node within 8 px of a screen point, or -1
  function slamNodeAt(sx, sy) {
    const n = state.slamGraph ? state.slamGraph.nodes : [];
    let best = -1, bestD = 8;
    for (let i = 0; i + 1 < n.length; i += 2) {
      const [px, py] = worldToScreen(n[i], n[i + 1]);
      const dd = Math.hypot(px - sx, py - sy);
      if (dd <= bestD) { best = i / 2; bestD = dd; }
    }
    return best;
  }
  function slamAcked(action) {
    if (action === "interactive") {
      state.slamEdit = !state.slamEdit; state.staged = {};
      $("slam-interactive").classList.toggle("active", state.slamEdit);
    } else if (action === "close_loop" || action === "clear") {
      state.staged = {};
    }
  }
  function drawFrames(px) {
    const len = Math.max(0.2, 25 * px);
    for (const [name, x, y, yaw] of state.tf) {
      arrowLine(x, y, x + len * Math.cos(yaw), y + len * Math.sin(yaw), "#f44", px);
      arrowLine(x, y, x - len * Math.sin(yaw), y + len * Math.cos(yaw), "#4f4", px);
    }
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#ddd"; ctx.font = "11px system-ui, sans-serif"; ctx.textAlign = "left";
    for (const [name, x, y] of state.tf) { const [sx, sy] = worldToScreen(x, y); ctx.fillText(name, sx + 4, sy - 4); }
    baseTransform();
    state.drawn.tfFrames = state.tf.length;
  }
  function arrowLine(x0, y0, x1, y1, colour, px) {
    ctx.strokeStyle = colour; ctx.lineWidth = 2 * px; ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
  }
  function frame() {
    if (dirty) { dirty = false; draw(); drawScaleBar(); }
    requestAnimationFrame(frame);
  }

  // -- exploration -----------------------------------------------------------------------
  function showExplore(m) {
    const done = m.state === "done";
    $("explore-state").textContent = m.message || m.state;
    $("explore-state").className = m.level > 0 ? "bad" : "";
    $("explore-frontiers").textContent = m.frontiers === null || m.frontiers === undefined ? "–"
      : `${m.frontiers} left · ${m.goals_reached} reached · ${m.abandoned} abandoned`;
    $("explore-known").textContent = `${m.known_m2.toFixed(1)} m² known, ${m.free_m2.toFixed(1)} m² free`;
    $("explore-time").textContent = m.elapsed_s === null || m.elapsed_s === undefined ? "–" : `${Math.round(m.elapsed_s)} s`;
    $("explore-start").disabled = done || !m.paused;
    $("explore-pause").disabled = done;
    $("explore-pause").textContent = m.paused && !done ? "Resume" : "Pause";
    drawExploreChart(m.history || []);
  }
  // known area (white, left scale) and frontiers left (blue, own scale) against time
  function drawExploreChart(points) {
    const c = $("explore-chart"), g = c.getContext("2d");
    g.clearRect(0, 0, c.width, c.height);
    if (points.length < 2) return;
    const t0 = points[0][0], t1 = Math.max(points[points.length - 1][0], t0 + 1);
    const kmax = Math.max(1, ...points.map((p) => p[1]));
    const fmax = Math.max(1, ...points.map((p) => p[3] || 0));
    const x = (t) => 2 + (c.width - 4) * (t - t0) / (t1 - t0);
    const line = (colour, value, top) => {
      g.strokeStyle = colour; g.lineWidth = 2; g.beginPath();
      points.forEach((p, i) => {
        const y = c.height - 2 - (c.height - 4) * value(p) / top;
        if (i === 0) g.moveTo(x(p[0]), y); else g.lineTo(x(p[0]), y);
      });
      g.stroke();
    };
    line("#6af", (p) => p[3] || 0, fmax);
    line("#fff", (p) => p[1], kmax);
    g.fillStyle = "#aaa"; g.font = "10px system-ui";
    g.fillText(`${kmax.toFixed(0)} m²`, 4, 11);
  }

  // -- commands ------------------------------------------------------------------------
  function send(obj) {
    if (state.readOnly || !ws || ws.readyState !== WebSocket.OPEN) return false;
    ws.send(JSON.stringify(obj));
    return true;
  }
  // views change only what this page receives, so a read-only page may open them
  state.views = new Set();
  function sendView(name, on) {
    if (on) state.views.add(name); else state.views.delete(name);
    if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ op: "view", name, engage: on }));
  }
  async function toggle3d() {
    const wrap = $("view3d-wrap");
    if (state.view3d) {
      sendView("cloud", false);
      state.view3d.close(); state.view3d = null;
      wrap.classList.add("hidden"); $("open-3d").classList.remove("active");
      return;
    }
    wrap.classList.remove("hidden"); $("open-3d").classList.add("active");
    const mod = await import("/static/view3d.js");
    state.view3d = mod.open($("view3d"), () => state.pose);
    sendView("cloud", true);
  }
  $("open-3d").addEventListener("click", toggle3d);
  $("log-level").addEventListener("change", () => showLog(lastLog));

  // -- legend and layer toggles ------------------------------------------------------------
  for (const [key, label, on, swatches] of LEGEND) {
    const row = document.createElement("label");
    row.className = "legend-row"; row.dataset.layer = key;
    const box = document.createElement("input");
    box.type = "checkbox"; box.id = "show-" + key; box.checked = on;
    const name = document.createElement("span"); name.className = "legend-name"; name.textContent = label;
    row.append(box, name);
    for (const [colour, what] of swatches) {
      const sw = document.createElement("span"); sw.className = "swatch"; sw.style.background = colour; sw.title = what;
      const txt = document.createElement("span"); txt.className = "swatch-label"; txt.textContent = what;
      row.append(sw, txt);
    }
    $("legend").append(row);
  }
  $("show-tf").addEventListener("change", (e) => sendView("tf", e.target.checked));
  function setMode(mode) {
    state.mode = state.mode === mode ? "pan" : mode;
    document.querySelectorAll("[data-mode]").forEach((b) => b.classList.toggle("active", b.dataset.mode === state.mode));
    canvas.classList.toggle("placing", state.mode !== "pan");
  }
  $("mode-goal").addEventListener("click", () => setMode("goal"));
  $("mode-initialpose").addEventListener("click", () => setMode("initialpose"));
  $("mode-keepout").addEventListener("click", () => setMode("keepout"));
  $("clear-keepout").addEventListener("click", () => send({ op: "keepout", clear: true }));
  $("cancel").addEventListener("click", () => send({ op: "cancel" }));
  $("estop").addEventListener("click", () => { releaseKeys(false); send({ op: "estop" }); });
  $("save-map").addEventListener("click", () => send({ op: "save_map", name: $("map-name").value.trim() }));
  $("follow").addEventListener("change", (e) => { state.follow = e.target.checked; dirty = true; });
  $("explore-start").addEventListener("click", () => send({ op: "explore", action: "start" }));
  $("explore-pause").addEventListener("click", () =>
    send({ op: "explore", action: state.explore && state.explore.paused ? "resume" : "pause" }));
  $("slam-interactive").addEventListener("click", () => send({ op: "slam", action: "interactive" }));
  $("slam-close").addEventListener("click", () => send({ op: "slam", action: "close_loop" }));
  $("slam-clear").addEventListener("click", () => send({ op: "slam", action: "clear" }));
  $("slam-merge").addEventListener("click", () => {
    const path = $("slam-session").value.trim();
    if (path) send({ op: "slam", action: "merge", path }); else notice("merge: give the session file's path", true);
  });
  document.querySelectorAll("input[type=checkbox]").forEach((c) => c.addEventListener("change", () => { dirty = true; }));

  canvas.addEventListener("mousedown", (e) => {
    const [x, y] = screenToWorld(e.offsetX, e.offsetY);
    let kind = state.mode === "pan" ? "pan" : state.mode;
    // in interactive mode a press on a SLAM graph node drags that node
    const node = kind === "pan" && state.slamEdit && shown("show-slam_graph") ? slamNodeAt(e.offsetX, e.offsetY) : -1;
    if (node >= 0) kind = "slamnode";
    state.drag = { kind, node, x0: x, y0: y, x1: x, y1: y, sx: e.offsetX, sy: e.offsetY, cx: state.view.cx, cy: state.view.cy };
    canvas.focus();
    e.preventDefault();
  });
  canvas.addEventListener("mousemove", (e) => {
    const [cx, cy] = screenToWorld(e.offsetX, e.offsetY);
    state.cursor = [cx, cy];
    $("cursor").textContent = `${cx.toFixed(2)}, ${cy.toFixed(2)} m (${state.status ? state.status.frame : "–"})`;
    const d = state.drag;
    if (!d) return;
    if (d.kind === "pan") {
      state.follow = false; $("follow").checked = false;
      state.view.cx = d.cx - (e.offsetX - d.sx) / state.view.scale;
      state.view.cy = d.cy + (e.offsetY - d.sy) / state.view.scale;
    } else {
      [d.x1, d.y1] = screenToWorld(e.offsetX, e.offsetY);
    }
    dirty = true;
  });
  window.addEventListener("mouseup", (e) => {
    const d = state.drag;
    state.drag = null;
    if (!d || d.kind === "pan") return;
    if (e.target === canvas) [d.x1, d.y1] = screenToWorld(e.offsetX, e.offsetY);
    if (d.kind === "slamnode") {
      if (Math.hypot(d.x1 - d.x0, d.y1 - d.y0) * state.view.scale > 3) {
        state.staged[d.node] = [d.x1, d.y1];
        send({ op: "slam", action: "move", node: d.node, x: d.x1, y: d.y1 });
      }
      dirty = true;
      return;
    }
    if (d.kind === "keepout") {
      if (d.x1 !== d.x0 && d.y1 !== d.y0) send({ op: "keepout", x0: d.x0, y0: d.y0, x1: d.x1, y1: d.y1 });
      setMode(d.kind);
      dirty = true;
      return;
    }
    const moved = Math.hypot(d.x1 - d.x0, d.y1 - d.y0) * state.view.scale > 3;
    const yaw = moved ? Math.atan2(d.y1 - d.y0, d.x1 - d.x0) : (state.pose ? state.pose.yaw : 0);
    send({ op: d.kind, x: d.x0, y: d.y0, yaw });
    setMode(d.kind);
    dirty = true;
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    const [wx, wy] = screenToWorld(e.offsetX, e.offsetY);
    const f = Math.exp(-e.deltaY * 0.0015);
    state.view.scale = Math.min(400, Math.max(2, state.view.scale * f));
    if (!state.follow) {
      const [nx, ny] = screenToWorld(e.offsetX, e.offsetY);
      state.view.cx += wx - nx; state.view.cy += wy - ny;
    }
    dirty = true;
  }, { passive: false });

  // -- keyboard teleop (10 Hz while a key is held, zero on release) ------------------------
  const KEYS = {
    ArrowUp: [1, 0], w: [1, 0], i: [1, 0],
    ArrowDown: [-1, 0], s: [-1, 0], ",": [-1, 0],
    ArrowLeft: [0, 1], a: [0, 1], j: [0, 1],
    ArrowRight: [0, -1], d: [0, -1], l: [0, -1],
    u: [1, 1], o: [1, -1], m: [-1, -1], ".": [-1, 1],
  };
  const speed = { linear: 0.3, angular: 1.0 };
  const held = new Set();
  let teleopTimer = null;
  function twist() {
    let lx = 0, az = 0;
    for (const k of held) { lx += KEYS[k][0]; az += KEYS[k][1]; }
    lx = Math.max(-1, Math.min(1, lx)); az = Math.max(-1, Math.min(1, az));
    return { op: "teleop", linear: lx * speed.linear, angular: az * speed.angular };
  }
  function teleopSend() {
    if (held.size) send(twist());
  }
  function releaseKeys(sendZero) {
    const was = held.size > 0;
    held.clear();
    clearInterval(teleopTimer); teleopTimer = null;
    if (was && sendZero) send({ op: "teleop", linear: 0, angular: 0 });
    $("teleop-state").textContent = "";
  }
  function showSpeed() { $("teleop-speed").textContent = `${speed.linear.toFixed(2)} m/s, ${speed.angular.toFixed(2)} rad/s`; }
  function typing(e) { return e.target && (e.target.tagName === "INPUT" || e.target.tagName === "TEXTAREA"); }
  window.addEventListener("keydown", (e) => {
    if (typing(e) || state.readOnly || e.ctrlKey || e.metaKey || e.altKey) return;
    const k = e.key.length === 1 ? e.key.toLowerCase() : e.key;
    if (k === "k" || k === " ") { e.preventDefault(); releaseKeys(true); return; }
    if (k === "q" || k === "z") {
      const f = k === "q" ? 1.1 : 1 / 1.1;
      speed.linear = Math.min(1.0, speed.linear * f); speed.angular = Math.min(3.0, speed.angular * f);
      showSpeed(); return;
    }
    if (!(k in KEYS)) return;
    e.preventDefault();
    if (held.has(k)) return;  // auto-repeat: the interval keeps sending
    held.add(k);
    $("teleop-state").textContent = "driving";
    teleopSend();
    if (!teleopTimer) teleopTimer = setInterval(teleopSend, 100);
  });
  window.addEventListener("keyup", (e) => {
    const k = e.key.length === 1 ? e.key.toLowerCase() : e.key;
    if (!held.has(k)) return;
    held.delete(k);
    if (held.size === 0) { releaseKeys(false); send({ op: "teleop", linear: 0, angular: 0 }); } else teleopSend();
  });
  window.addEventListener("blur", () => releaseKeys(true));

  // -- connection ----------------------------------------------------------------------
  function connect() {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    ws = new WebSocket(`${proto}://${location.host}/ws`);
    ws.binaryType = "arraybuffer";
    ws.onopen = () => { state.connected = true; $("conn").textContent = "live"; $("conn").className = "good"; };
    ws.onclose = () => {
      state.connected = false; $("conn").textContent = "disconnected — retrying"; $("conn").className = "bad";
      releaseKeys(false);
      setTimeout(connect, 1000);
    };
    ws.onmessage = (ev) => {
      if (typeof ev.data === "string") onText(JSON.parse(ev.data)); else onBinary(ev.data);
    };
  }
  canvas.addEventListener("mouseleave", () => { state.cursor = null; $("cursor").textContent = "–"; });
  window.eddie = { state, worldToScreen, screenToWorld, setMode, send, sendView };
  connect();
  requestAnimationFrame(frame);
})();
