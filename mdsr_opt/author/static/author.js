// mdsr author: the page. Talks to the server over one websocket; all numbers come from the server.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const canvas = $("canvas");
  const ctx = canvas.getContext("2d");
  const MUSCLE_COLORS = ["#d62728"];  // M1's colour, for the legend; each muscle's own comes with the routing
  const GROUP_COLORS = ["#e4572e", "#7b2cbf", "#0a9396", "#c9184a", "#f4a261"];

  // ------------------------------------------------------------------ page state
  const S = {
    ws: null, sid: null, info: null,
    body: null,            // {points, triangles, edges, boundary, size, ...}
    state: null,           // last state message from the server
    anchors: new Set(),
    handles: new Map(),    // node -> {group, pos: [x, y]}
    group: 0,
    graph: null, routing: null, design: null, saved: null, confirm: null,
    muscles: [],           // the layout: routed muscles less the deleted ones (and those a design dropped)
    selected: null,        // name of the selected muscle (Delete muscle removes it)
    colors: new Map(),     // muscle name -> colour (sent by the server, as in the figures), fixed when routed
    nLive: 0, seq: 0, inflight: null, pendingDrag: false, sentAt: {}, rtts: [], lastError: null, errors: [],
    view: { s: 1, ox: 0, oy: 0 },
    pointer: null, op: null, pivot: null,
    draw: null,            // {polys: [[...], ...], cur: [[x, y], ...]}
  };

  // ------------------------------------------------------------------ websocket
  // the session's secret: in the address mdsr author opened (?token=...), kept for reloads of this tab
  const TOKEN = new URLSearchParams(location.search).get("token") || sessionStorage.getItem("mdsr-author-token");
  if (TOKEN) sessionStorage.setItem("mdsr-author-token", TOKEN);

  function connect() {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    const query = TOKEN ? `?token=${encodeURIComponent(TOKEN)}` : "";
    const ws = new WebSocket(`${proto}://${location.host}/ws${query}`);
    S.ws = ws;
    ws.onmessage = (ev) => onMessage(JSON.parse(ev.data));
    ws.onclose = (ev) => {
      if (ev.code === 1008) {  // refused (token, origin or host): trying again would not help
        status(`refused by the server: ${ev.reason}`);
        showError(`the server refused this page: ${ev.reason}`);
        return;
      }
      status(`connection closed (${ev.code}${ev.reason ? ": " + ev.reason : ""}); reconnecting...`);
      if (ev.code === 1009) showError("the last message was too large for the server and was refused");
      setTimeout(connect, 1000);
    };
  }

  function send(msg) {
    const text = JSON.stringify(msg);
    const limit = S.info ? S.info.max_message : 4 * 1024 * 1024;
    if (text.length > limit) { showError(`message too large (${text.length} characters, limit ${limit})`); return false; }
    if (!S.ws || S.ws.readyState !== 1) { showError("not connected to the server"); return false; }
    S.ws.send(text);
    return true;
  }

  function fixedPayload(type) {
    const nodes = [...S.handles.keys()];
    return { type, seq: ++S.seq, anchors: [...S.anchors], drag_nodes: nodes,
             drag_positions: nodes.map((i) => S.handles.get(i).pos) };
  }

  function request(type) {           // "fixed" (settled solve) or "drag" (live solve)
    if (!S.body) return;
    if (type === "drag" && S.inflight !== null) { S.pendingDrag = true; return; }  // keep only the latest
    const msg = fixedPayload(type);
    S.sentAt[msg.seq] = performance.now();
    S.inflight = msg.seq;
    S.pendingDrag = false;
    send(msg);
  }

  function onMessage(m) {
    if (m.type === "hello") { S.sid = m.sid; status("connected"); return; }
    if (m.type === "error") { showError(m.message); S.inflight = null; if (S.pendingDrag) request("drag"); render(); return; }
    if (m.type === "pong") { S.pong = m; return; }
    if (m.type === "body") return onBody(m);
    if (m.type === "state") return onState(m);
    if (m.type === "graph") { S.graph = m.weights; render(); return; }
    if (m.type === "routing") return onRouting(m);
    if (m.type === "design") {
      S.design = m; if (m.layout) setMuscles(m.layout);
      if (!m.success) showError(`design not verified: ${m.status}`);
      else if (m.acceptance) showError(`design too far from the target for mdsr run: ${m.acceptance}`); updateTable(); render(); return;
    }
    if (m.type === "saved") { S.saved = m; S.confirm = null; $("confirm").hidden = true; $("saved").textContent = "saved: " + m.files.join(", "); listLines("save-notes", m.notes || []); return; }
    if (m.type === "confirm") { S.confirm = m; $("confirm-text").textContent = m.message; $("confirm").hidden = false; return; }
  }

  function setMuscles(list) {
    S.muscles = list;
    if (S.selected !== null && !list.some((u) => u.name === S.selected)) S.selected = null;
    $("delete-muscle").disabled = S.selected === null;
  }
  function muscleColor(name) { return S.colors.get(name) || MUSCLE_COLORS[0]; }  // the figures' colour of the name

  function onRouting(m) {  // a new routing, or the layout after a deletion (the design is then gone)
    S.routing = m; S.design = null; S.graph = null;
    if (!m.deleted.length) { S.colors = new Map(m.muscles.map((u) => [u.name, u.color])); S.selected = null; }
    setMuscles(m.muscles);
    for (const w of m.warnings) showError(w);
    const notes = $("routing-notes"); notes.innerHTML = "";
    const lines = m.notes.slice();
    if (m.fixture_radius != null) lines.unshift(`end fixtures: radius ${fmt(m.fixture_radius)}`);
    if (m.deleted.length) { lines.push(`deleted: ${m.deleted.join(", ")}`); showHint(`${m.deleted[m.deleted.length - 1]} deleted: Design again for this layout`); }
    for (const t of lines) { const li = document.createElement("li"); li.textContent = t; notes.appendChild(li); }
    updateTable(); render();
  }
  const fmt = (v) => Number(v.toPrecision(4)).toString();
  function listLines(id, lines) {  // one list item per line of text
    const ul = $(id); ul.innerHTML = "";
    for (const t of lines) { const li = document.createElement("li"); li.textContent = t; ul.appendChild(li); }
  }

  // the fabrication fields: lengths in the body's unit (min_inset_fraction: a fraction of its diameter), empty
  // for the body's default
  const FAB = ["channel_diameter", "wall", "fixture_radius", "min_fixture_radius", "min_inset_fraction"];
  function fabrication() {
    const out = {};
    for (const k of FAB) {
      if ($(k).validity.badInput) { showError(`${k}: not a number (give a ${k === "min_inset_fraction" ? "fraction" : "length"}, or leave it empty for the default)`); return null; }
      const v = $(k).value.trim(); out[k] = v === "" ? null : Number(v);
    }
    return out;
  }

  function onBody(m) {
    S.body = m; S.graph = null; S.routing = null; S.design = null; S.saved = null; S.draw = null; S.pivot = null;
    S.muscles = []; S.selected = null; S.colors = new Map(); $("delete-muscle").disabled = true; $("routing-notes").innerHTML = "";
    for (const k of FAB) { $(k).value = m.fabrication[k] == null ? "" : m.fabrication[k]; $(k).placeholder = "default"; }
    $("fab-units").textContent = m.units ? `lengths in ${m.units}` : "lengths in body units";
    S.anchors = new Set(m.anchors);
    S.handles = new Map();
    m.drag_nodes.forEach((i, k) => S.handles.set(i, { group: 0, pos: m.drag_positions[k] }));
    S.group = 0;
    $("K_a").value = m.routing.K_a; $("K_b").value = m.routing.K_b;
    $("max_muscles").value = m.routing.max_muscles == null ? "" : m.routing.max_muscles;
    if (m.design.a_max != null) $("a_max").value = m.design.a_max;
    setSelect("method", m.design.method || "auto");  // no method named: the design chooses (the design line says which)
    if (m.design.muscle_model) setSelect("muscle_model", m.design.muscle_model);
    $("save-name").value = ""; $("save-name").placeholder = m.name;  // empty: Save uses the body's name
    showLoaded(m);
    $("saved").textContent = ""; S.confirm = null; $("confirm").hidden = true;
    listLines("kept", m.kept || []); listLines("save-notes", []); listLines("contact", m.contact || []);
    updateTable(); drawButtons(); updateDownloads();
    fit(m.points.concat(m.drag_positions, obstaclePoints(m.obstacles || [], m.size)));
    S.needFit = true;
  }

  function onState(m) {
    const t0 = S.sentAt[m.seq];
    if (t0 !== undefined) { S.rtts.push([performance.now(), performance.now() - t0]); delete S.sentAt[m.seq]; }
    if (S.rtts.length > 40) S.rtts.shift();
    S.state = m;
    if (S.needFit && m.x) { fit(S.body.points.concat(m.x, m.drag_positions, obstaclePoints(obstacles(), S.body.size))); S.needFit = false; }
    if (m.live) S.nLive += 1;
    if (m.seq == null || m.seq === S.inflight) S.inflight = null;
    // the server's fixed sets are what was solved; take them when no local edit is in progress
    if (!S.op) {
      S.anchors = new Set(m.anchors);
      const old = S.handles; S.handles = new Map();
      m.drag_nodes.forEach((i, k) => S.handles.set(i, { group: old.has(i) ? old.get(i).group : 0, pos: m.drag_positions[k] }));
    }
    if (S.routing && !m.live) { /* a new settled target invalidates muscles routed on the old one */ }
    if (S.pendingDrag && S.op) request("drag");
    else if (S.pendingDrag) { S.pendingDrag = false; }
    updateStatus(); updateDownloads(); render();
  }

  // ------------------------------------------------------------------ messages and status
  function showError(text) {
    S.lastError = text; S.errors.push(text);
    const box = document.createElement("div");
    box.className = "error";
    box.textContent = text;
    const x = document.createElement("button"); x.textContent = "\u00d7"; x.onclick = () => box.remove();
    box.appendChild(x);
    $("errors").prepend(box);
    setTimeout(() => box.remove(), 20000);
    while ($("errors").children.length > 4) $("errors").lastChild.remove();
  }
  function setSelect(id, v) {  // a value the page does not list yet (a newer default) is added, not dropped
    const sel = $(id);
    if (![...sel.options].some((o) => o.value === v)) { const o = document.createElement("option"); o.textContent = v; sel.appendChild(o); }
    sel.value = v;
  }
  function status(t) { $("status").textContent = t; }

  function updateStatus() {
    const m = S.state; if (!m) return;
    const now = performance.now();
    const recent = S.rtts.filter(([t]) => now - t < 3000);
    const rtt = recent.length ? recent[recent.length - 1][1] : NaN;
    const rate = recent.length > 1 ? (recent.length - 1) / ((recent[recent.length - 1][0] - recent[0][0]) / 1000) : NaN;
    const bits = [
      `${S.body.name}: ${S.body.n_nodes} nodes`,
      m.success ? (m.live ? "live" : "settled") : "NOT SOLVED",
      `${m.iterations} it`, `solve ${(1000 * m.solve_time).toFixed(0)} ms`,
      isNaN(rtt) ? "" : `round trip ${rtt.toFixed(0)} ms`, isNaN(rate) ? "" : `${rate.toFixed(1)} updates/s`,
      `min J ${m.min_J == null ? "-" : m.min_J.toFixed(3)}`, m.dropped ? `${m.dropped} stale drags dropped` : "",
      m.success ? "" : m.status,
    ];
    status(bits.filter(Boolean).join(" | "));
    const warn = [];
    if (!m.success) warn.push(`not an equilibrium: ${m.status}`);
    if (m.inverted.length) warn.push(`${m.inverted.length} inverted triangle(s)`);
    if (m.crossing) warn.push("the boundary crosses itself");
    $("banner").hidden = warn.length === 0;
    $("banner").textContent = warn.join("; ");
  }

  function updateTable() {
    const t = $("muscle-table");
    t.innerHTML = "";
    const rows = S.design ? S.design.muscles : (S.routing ? S.routing.stats.map((s) => ({ name: s.name, geo: s.contraction })) : []);
    $("delete-muscle").disabled = S.selected === null;
    if (!rows.length) return;
    const has = (k) => rows.some((r) => r[k] !== undefined);
    const cols = S.design
      ? [["contraction", "a"], [has("achieved") ? "achieved" : "achieved_geometric", "achieved"],
         [has("stroke") ? "stroke" : "stroke_geometric", "stroke"]].concat(has("tension") ? [["tension", "tension"]] : [])
      : [["geo", "target contraction"]];
    const head = document.createElement("tr");
    head.innerHTML = "<th>muscle</th>" + cols.map((c) => `<th>${c[1]}</th>`).join("");
    t.appendChild(head);
    rows.forEach((r) => {
      const tr = document.createElement("tr");
      tr.className = "muscle" + (r.name === S.selected ? " selected" : "");
      tr.dataset.name = r.name;
      tr.onclick = () => selectMuscle(r.name === S.selected ? null : r.name);
      const sw = `<span class="swatch" style="background:${muscleColor(r.name)}"></span>`;
      tr.innerHTML = `<td>${sw}${r.name}</td>` + cols.map((c) => `<td>${r[c[0]] == null ? "-" : r[c[0]].toFixed(4)}</td>`).join("");
      t.appendChild(tr);
    });
    if (S.design) {
      const tr = document.createElement("tr");
      const d = S.design.difference;
      tr.innerHTML = `<td colspan="${cols.length + 1}">difference ${d == null ? "-" : d.toExponential(3)} ` +
        `(${S.design.relative_difference == null ? "-" : (100 * S.design.relative_difference).toFixed(2)} % of size), ` +
        `by ${String(S.design.method).replace(/[&<>"]/g, "")}, ${S.design.success ? "verified" : "NOT verified"}` +
        (S.design.acceptance ? `; mdsr run fails it: ${S.design.acceptance}` : "") +
        designFlags(S.design) + "</td>";
      t.appendChild(tr);
    }
  }

  function designFlags(d) {  // what mdsr run's verdict adds after "ok": saturated, dropped, idle kept
    const esc = (v) => String(v).replace(/[&<>"]/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;"}[c]));
    const parts = [];
    if ((d.saturated || []).length) parts.push(`saturated ${d.saturated.map(esc).join(", ")}`);
    if ((d.dropped || []).length) parts.push(`dropped ${d.dropped.map((x) => esc(x.name)).join(", ")} (idle)`);
    if ((d.idle_kept || []).length) parts.push(`idle ${d.idle_kept.map(esc).join(", ")} kept (the design without them failed)`);
    for (const n of d.notes || []) parts.push(esc(n));  // what the obstacles changed, as mdsr run says
    return parts.length ? "; " + parts.join("; ") : "";
  }

  function updateDownloads() {
    const box = $("downloads");
    box.innerHTML = "";
    if (!S.info || !S.sid || !S.body) return;
    for (const [name, what] of Object.entries(S.info.downloads)) {
      const a = document.createElement("a");
      a.href = `/download/${S.sid}/${name}`; a.textContent = name; a.title = what; a.download = "";
      box.appendChild(a);
    }
  }

  // ------------------------------------------------------------------ geometry
  function shown() { return S.state && S.state.x ? S.state.x : (S.body ? S.body.points : []); }
  function fit(pts) {
    const r = canvas.getBoundingClientRect();
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    for (const [x, y] of pts) { x0 = Math.min(x0, x); y0 = Math.min(y0, y); x1 = Math.max(x1, x); y1 = Math.max(y1, y); }
    if (!isFinite(x0)) { x0 = 0; y0 = 0; x1 = 10; y1 = 6; }
    const w = Math.max(x1 - x0, 1e-9), h = Math.max(y1 - y0, 1e-9);
    const s = 0.8 * Math.min(r.width / w, r.height / h);
    S.view = { s, ox: r.width / 2 - s * (x0 + x1) / 2, oy: r.height / 2 + s * (y0 + y1) / 2 };
  }
  // the obstacles: as the last target placed them (a free disk moves), else as the scene gives them
  function obstacles() { return (S.state && S.state.obstacles) || (S.body && S.body.obstacles) || []; }
  function obstaclePoints(obs, size) {  // points the view keeps in sight: a disk's box, a polygon, a half-plane's point
    const out = [];
    for (const o of obs) {
      if (o.kind === "disk") out.push([o.center[0] - o.radius, o.center[1] - o.radius], [o.center[0] + o.radius, o.center[1] + o.radius]);
      else if (o.kind === "polygon") out.push(...o.points);
      else if (Math.abs(o.point[0]) < 10 * size && Math.abs(o.point[1]) < 10 * size) out.push(o.point);
    }
    return out;
  }
  function drawObstacles() {  // grey, hatched by transparency: the body may touch them, never enter
    const r = canvas.getBoundingClientRect();
    ctx.fillStyle = "rgba(90,90,90,.28)"; ctx.strokeStyle = "#555"; ctx.lineWidth = 1.5;
    for (const o of obstacles()) {
      ctx.beginPath();
      if (o.kind === "disk") {
        const c = toScreen(o.center); ctx.arc(c[0], c[1], o.radius * S.view.s, 0, 2 * Math.PI);
        if (o.free) ctx.setLineDash([5, 3]);
      } else if (o.kind === "polygon") {
        o.points.forEach((p, k) => { const q = toScreen(p); k ? ctx.lineTo(q[0], q[1]) : ctx.moveTo(q[0], q[1]); }); ctx.closePath();
      } else {  // the half-plane the normal points away from: its edge across the view, filled beyond it
        const p = toScreen(o.point), n = [o.normal[0], -o.normal[1]], L = 4 * (r.width + r.height);
        const nn = Math.hypot(n[0], n[1]), u = [n[0] / nn, n[1] / nn], t = [-u[1], u[0]];
        ctx.moveTo(p[0] + L * t[0], p[1] + L * t[1]); ctx.lineTo(p[0] - L * t[0], p[1] - L * t[1]);
        ctx.lineTo(p[0] - L * t[0] - L * u[0], p[1] - L * t[1] - L * u[1]); ctx.lineTo(p[0] + L * t[0] - L * u[0], p[1] + L * t[1] - L * u[1]);
        ctx.closePath();
      }
      ctx.fill(); ctx.stroke(); ctx.setLineDash([]);
    }
  }
  const toScreen = (p) => [S.view.ox + S.view.s * p[0], S.view.oy - S.view.s * p[1]];
  const toWorld = (q) => [(q[0] - S.view.ox) / S.view.s, (S.view.oy - q[1]) / S.view.s];
  function nodesNear(q, radius) {
    const x = shown(), out = [];
    for (let i = 0; i < x.length; i++) {
      const p = toScreen(x[i]);
      if (Math.hypot(p[0] - q[0], p[1] - q[1]) <= radius) out.push(i);
    }
    return out;
  }
  function nearestNode(q, maxPx, among) {
    const x = shown(); let best = -1, bd = maxPx;
    const ids = among || x.keys();
    for (const i of ids) {
      const p = toScreen(among ? S.handles.get(i).pos : x[i]);
      const d = Math.hypot(p[0] - q[0], p[1] - q[1]);
      if (d <= bd) { bd = d; best = i; }
    }
    return best;
  }

  // ------------------------------------------------------------------ drawing
  function resize() {
    const r = canvas.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
    canvas.width = Math.round(r.width * dpr); canvas.height = Math.round(r.height * dpr);
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  }
  function path(x, loop) {
    ctx.beginPath();
    loop.forEach((v, k) => { const p = toScreen(x[v]); k ? ctx.lineTo(p[0], p[1]) : ctx.moveTo(p[0], p[1]); });
    ctx.closePath();
  }
  function drawMesh(x, fill, stroke, alpha, triColor) {
    const T = S.body.triangles;
    ctx.globalAlpha = alpha;
    for (let k = 0; k < T.length; k++) {
      const [a, b, c] = T[k], pa = toScreen(x[a]), pb = toScreen(x[b]), pc = toScreen(x[c]);
      ctx.beginPath(); ctx.moveTo(pa[0], pa[1]); ctx.lineTo(pb[0], pb[1]); ctx.lineTo(pc[0], pc[1]); ctx.closePath();
      ctx.fillStyle = triColor ? triColor(k) : fill; ctx.fill();
      if (stroke) { ctx.strokeStyle = stroke; ctx.lineWidth = 0.5; ctx.stroke(); }
    }
    ctx.globalAlpha = 1;
  }
  function coolwarm(t) {  // t in [-1, 1]: blue (elongation) .. grey .. red (contraction)
    t = Math.max(-1, Math.min(1, t));
    const c = t > 0 ? [214, 39, 40] : [31, 119, 180], g = [200, 200, 200], a = Math.abs(t);
    return `rgb(${c.map((v, i) => Math.round(g[i] + a * (v - g[i]))).join(",")})`;
  }
  function ramp(t) {  // 0..1: pale yellow to dark red
    t = Math.max(0, Math.min(1, t));
    return `rgb(${Math.round(255 - 80 * t)},${Math.round(240 - 200 * t)},${Math.round(160 - 140 * t)})`;
  }
  function drawMuscles(x, muscles, lw) {
    muscles.forEach((m) => {
      const sel = m.name === S.selected;
      for (const [color, w] of sel ? [["#ffd23f", lw + 6], [muscleColor(m.name), lw + 1]] : [[muscleColor(m.name), lw]]) {
        ctx.beginPath();
        m.nodes.forEach((v, k) => { const p = toScreen(x[v]); k ? ctx.lineTo(p[0], p[1]) : ctx.moveTo(p[0], p[1]); });
        ctx.strokeStyle = color; ctx.lineWidth = w; ctx.lineJoin = "round"; ctx.stroke();
      }
    });
  }
  function muscleAt(q, maxPx) {  // the muscle drawn nearest the screen point q (within maxPx), or null
    const x = S.design && document.querySelector("input[name=view]:checked").value === "overlay" ? S.design.x_aligned : shown();
    let best = null, bd = maxPx;
    for (const m of S.muscles) {
      for (let k = 0; k + 1 < m.nodes.length; k++) {
        const a = toScreen(x[m.nodes[k]]), b = toScreen(x[m.nodes[k + 1]]);
        const dx = b[0] - a[0], dy = b[1] - a[1], L2 = dx * dx + dy * dy;
        const t = L2 > 0 ? Math.max(0, Math.min(1, ((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / L2)) : 0;
        const d = Math.hypot(q[0] - a[0] - t * dx, q[1] - a[1] - t * dy);
        if (d <= bd) { bd = d; best = m.name; }
      }
    }
    return best;
  }
  function selectMuscle(name) {
    S.selected = name;
    $("delete-muscle").disabled = name === null;
    if (name !== null) showHint(`${name} selected: Delete muscle (or the Delete key) takes it out of the layout`);
    updateTable(); render();
  }
  function deleteSelected() {
    if (S.selected === null) return;
    send({ type: "delete_muscle", name: S.selected });
  }

  function legend(view) {
    const items = [["#b9d0ea", "target (shown state)", "fill"], ["#9aa5b1", "rest outline (dashed)", "dash"],
                   ["#111", "anchor", "square"], [GROUP_COLORS[0], "drag node", "dot"]];
    if (S.muscles.length) items.push([MUSCLE_COLORS[0], "muscles", "line"]);
    if (obstacles().length) items.push(["rgba(90,90,90,.5)", "obstacle (touched, never entered)", "fill"]);
    if (S.design && view === "overlay") items.push(["#f4a261", S.design.held ? "driven by the design (held at its anchors)" : "driven by the design (aligned)", "fill"]);
    if (S.graph && $("show-graph").checked) items.push(["#d62728", "contracted edge", "line"], ["#1f77b4", "elongated edge", "line"]);
    if (S.design && view === "difference") items.push(["rgb(175,40,20)", "far from target", "fill"]);
    ctx.font = "12px system-ui, sans-serif";
    items.forEach(([c, t, kind], k) => {
      const y = 16 + 17 * k;
      ctx.fillStyle = c; ctx.strokeStyle = c; ctx.lineWidth = 2;
      if (kind === "fill") ctx.fillRect(10, y - 9, 14, 10);
      else if (kind === "square") ctx.fillRect(13, y - 7, 6, 6);
      else if (kind === "dot") { ctx.beginPath(); ctx.arc(17, y - 4, 4, 0, 2 * Math.PI); ctx.fill(); }
      else { ctx.setLineDash(kind === "dash" ? [4, 3] : []); ctx.beginPath(); ctx.moveTo(10, y - 4); ctx.lineTo(24, y - 4); ctx.stroke(); ctx.setLineDash([]); }
      ctx.fillStyle = "#1d2733"; ctx.fillText(t, 30, y);
    });
  }

  function render() {
    const r = canvas.getBoundingClientRect();
    ctx.clearRect(0, 0, r.width, r.height);
    if (S.body) {
      const B = S.body, x = shown(), st = S.state;
      drawObstacles();
      for (const loop of B.boundary) { path(B.points, loop); ctx.strokeStyle = "#c3cad3"; ctx.setLineDash([4, 3]); ctx.lineWidth = 1; ctx.stroke(); ctx.setLineDash([]); }
      const view = document.querySelector("input[name=view]:checked").value;
      const inv = new Set(st ? st.inverted : []);
      if (S.design && view === "difference") {
        const d = S.design.node_distance, dmax = Math.max(...d, 1e-30);
        drawMesh(x, null, null, 1, (k) => { const [a, b, c] = B.triangles[k]; return ramp((d[a] + d[b] + d[c]) / 3 / dmax); });
        ctx.fillStyle = "#333"; ctx.fillText(`node distance driven-target: max ${dmax.toExponential(2)}`, 10, r.height - 10);
      } else {
        drawMesh(x, "#b9d0ea", S.graph ? null : "#5b7ea6", 0.9, inv.size ? (k) => (inv.has(k) ? "#d62728" : "#b9d0ea") : null);
      }
      if (S.graph && $("show-graph").checked) {
        const wmax = Math.max(...S.graph.map(Math.abs), 1e-30);
        B.edges.forEach(([a, b], k) => {
          const pa = toScreen(x[a]), pb = toScreen(x[b]);
          ctx.beginPath(); ctx.moveTo(pa[0], pa[1]); ctx.lineTo(pb[0], pb[1]);
          ctx.strokeStyle = coolwarm(S.graph[k] / wmax); ctx.lineWidth = 1 + 2 * Math.max(0, S.graph[k] / wmax); ctx.stroke();
        });
      }
      for (const loop of B.boundary) { path(x, loop); ctx.strokeStyle = st && st.crossing ? "#d62728" : "#23415f"; ctx.lineWidth = st && st.crossing ? 3 : 1.5; ctx.stroke(); }
      if (S.design && view === "overlay") {
        const xd = S.design.x_aligned;
        drawMesh(xd, "#f4a261", null, 0.35);
        for (const loop of B.boundary) { path(xd, loop); ctx.strokeStyle = "#c2410c"; ctx.lineWidth = 1.5; ctx.stroke(); }
      }
      if (S.muscles.length) drawMuscles(S.design && view === "overlay" ? S.design.x_aligned : x, S.muscles, 3);
      ctx.fillStyle = "#111";
      for (const i of S.anchors) { const p = toScreen(B.points[i]); ctx.fillRect(p[0] - 3, p[1] - 3, 6, 6); }
      const groups = new Map();
      for (const [i, h] of S.handles) {
        if (!groups.has(h.group)) groups.set(h.group, { rest: [0, 0], to: [0, 0], n: 0 });
        const g = groups.get(h.group); g.n += 1;
        g.rest[0] += B.points[i][0]; g.rest[1] += B.points[i][1]; g.to[0] += h.pos[0]; g.to[1] += h.pos[1];
      }
      for (const [k, g] of groups) {  // one arrow per group: rest centroid -> where it is dragged
        const a = toScreen([g.rest[0] / g.n, g.rest[1] / g.n]), b = toScreen([g.to[0] / g.n, g.to[1] / g.n]);
        ctx.strokeStyle = GROUP_COLORS[k % GROUP_COLORS.length]; ctx.globalAlpha = 0.5; ctx.lineWidth = 1.5;
        ctx.setLineDash([5, 4]); ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
        ctx.setLineDash([]); ctx.globalAlpha = 1;
      }
      for (const [, h] of S.handles) {
        const p = toScreen(h.pos);
        ctx.beginPath(); ctx.arc(p[0], p[1], 3.5, 0, 2 * Math.PI);
        ctx.fillStyle = GROUP_COLORS[h.group % GROUP_COLORS.length]; ctx.fill();
      }
      legend(view);
      if (S.pivot) {
        const p = toScreen(S.pivot); ctx.strokeStyle = "#111"; ctx.lineWidth = 1.5;
        ctx.beginPath(); ctx.moveTo(p[0] - 7, p[1]); ctx.lineTo(p[0] + 7, p[1]); ctx.moveTo(p[0], p[1] - 7); ctx.lineTo(p[0], p[1] + 7); ctx.stroke();
      }
    }
    if (!S.body && !S.draw) {
      ctx.fillStyle = "#56657a"; ctx.font = "15px system-ui, sans-serif"; ctx.textAlign = "center";
      ctx.fillText("Load a library problem, open a scene or outline file, or draw an outline (left).", r.width / 2, r.height / 2);
      ctx.textAlign = "start";
    }
    if (S.draw) {
      ctx.strokeStyle = "#0a6"; ctx.lineWidth = 2; ctx.fillStyle = "rgba(0,170,102,.12)";
      for (const poly of S.draw.polys) { path(poly, poly.map((_, k) => k)); ctx.fill(); ctx.stroke(); }
      if (S.draw.cur.length) {
        ctx.beginPath(); S.draw.cur.forEach((p, k) => { const q = toScreen(p); k ? ctx.lineTo(q[0], q[1]) : ctx.moveTo(q[0], q[1]); });
        if (S.pointer) ctx.lineTo(S.pointer[0], S.pointer[1]);
        ctx.stroke();
        for (const p of S.draw.cur) { const q = toScreen(p); ctx.fillStyle = "#0a6"; ctx.fillRect(q[0] - 2, q[1] - 2, 4, 4); }
      }
    }
    const tool = currentTool(), br = +$("brush").value;
    if (S.pointer && !S.draw && (tool === "anchor" || tool === "handle") && br > 0) {
      ctx.beginPath(); ctx.arc(S.pointer[0], S.pointer[1], br, 0, 2 * Math.PI); ctx.strokeStyle = "rgba(0,0,0,.4)"; ctx.lineWidth = 1; ctx.stroke();
    }
  }

  // ------------------------------------------------------------------ mouse
  const currentTool = () => document.querySelector("input[name=tool]:checked").value;
  const HINTS = {
    anchor: "Click or brush nodes to anchor them at rest (Shift removes).",
    handle: "Click or brush nodes to make them drag nodes of the current group (Shift removes).",
    move: "Press near a drag node and move: its group follows; the equilibrium updates live.",
    rotate: "Shift-click sets the pivot (default: the group's centroid); press near a drag node and move to rotate its group.",
    muscle: "Click a muscle to select it (or its row in the table); Delete muscle takes it out of the layout.",
  };
  function local(ev) { const r = canvas.getBoundingClientRect(); return [ev.clientX - r.left, ev.clientY - r.top]; }

  function paint(q, tool, remove) {
    const br = +$("brush").value;
    let ids = br > 0 ? nodesNear(q, br) : [];
    if (!ids.length) { const i = nearestNode(q, 12); if (i >= 0) ids = [i]; }
    const x = shown();
    for (const i of ids) {
      if (tool === "anchor") {
        if (remove) S.anchors.delete(i); else { S.anchors.add(i); S.handles.delete(i); }
      } else {
        if (remove) S.handles.delete(i);
        else if (!S.handles.has(i)) { S.handles.set(i, { group: S.group, pos: [x[i][0], x[i][1]] }); S.anchors.delete(i); }
      }
    }
    return ids.length;
  }

  canvas.addEventListener("mousedown", (ev) => {
    if (ev.button !== 0) return;
    const q = local(ev), tool = currentTool();
    if (S.draw) { S.draw.cur.push(toWorld(q)); drawButtons(); render(); return; }
    if (!S.body) return;
    if (tool === "muscle") { selectMuscle(muscleAt(q, 10)); return; }
    if (tool === "anchor" || tool === "handle") {
      S.op = { kind: "paint", tool, remove: ev.shiftKey, changed: paint(q, tool, ev.shiftKey) };
    } else {
      if (tool === "rotate" && ev.shiftKey) { S.pivot = toWorld(q); render(); return; }
      const i = nearestNode(q, 25, [...S.handles.keys()]);
      if (i < 0) { showError("press near a drag node (mark some with the Drag nodes tool first)"); return; }
      const g = S.handles.get(i).group, members = [...S.handles.entries()].filter(([, h]) => h.group === g);
      const start = new Map(members.map(([k, h]) => [k, h.pos.slice()]));
      let pivot = S.pivot;
      if (!pivot) { pivot = [0, 0]; for (const p of start.values()) { pivot[0] += p[0] / start.size; pivot[1] += p[1] / start.size; } }
      S.op = { kind: tool, start, w0: toWorld(q), pivot };
    }
    render();
  });

  canvas.addEventListener("mousemove", (ev) => {
    const q = local(ev); S.pointer = q;
    const op = S.op;
    if (op && op.kind === "paint") op.changed += paint(q, op.tool, op.remove);
    else if (op) {
      const w = toWorld(q);
      if (op.kind === "move") {
        const dx = w[0] - op.w0[0], dy = w[1] - op.w0[1];
        for (const [k, p] of op.start) S.handles.get(k).pos = [p[0] + dx, p[1] + dy];
      } else {
        const c = op.pivot, a = Math.atan2(w[1] - c[1], w[0] - c[0]) - Math.atan2(op.w0[1] - c[1], op.w0[0] - c[0]);
        const cs = Math.cos(a), sn = Math.sin(a);
        for (const [k, p] of op.start) {
          const u = p[0] - c[0], v = p[1] - c[1];
          S.handles.get(k).pos = [c[0] + cs * u - sn * v, c[1] + sn * u + cs * v];
        }
      }
      request("drag");
    }
    render();
  });

  function endOp() {
    const op = S.op; S.op = null;
    if (!op) return;
    if (op.kind === "paint" && !op.changed) return;
    S.pendingDrag = false;
    S.inflight = null;
    request("fixed");
  }
  window.addEventListener("mouseup", endOp);
  canvas.addEventListener("mouseleave", () => { S.pointer = null; render(); });

  // ------------------------------------------------------------------ controls
  document.querySelectorAll("input[name=tool]").forEach((r) => r.addEventListener("change", () => { $("hint").textContent = HINTS[currentTool()]; render(); }));
  document.querySelectorAll("input[name=view]").forEach((r) => r.addEventListener("change", render));
  $("brush").addEventListener("input", () => { $("brush-val").textContent = $("brush").value + " px"; });
  $("new-group").onclick = () => { S.group += 1; showHint(`new drag nodes go to group ${S.group + 1}`); };
  $("clear-anchors").onclick = () => { S.anchors.clear(); request("fixed"); };
  $("clear-handles").onclick = () => { S.handles.clear(); S.pivot = null; request("fixed"); };
  function showHint(t) { $("hint").textContent = t; }
  function resolution() { return $("resolution").value.trim() || null; }

  $("load-problem").onclick = () => send({ type: "load", body: { kind: "problem", name: $("problem").value, resolution: resolution() } });
  $("file").addEventListener("change", () => {
    const f = $("file").files[0]; if (!f) return;
    const limit = S.info ? S.info.max_message - 1000 : 4e6;
    if (f.size > limit) { showError(`${f.name}: file too large (${f.size} bytes, limit ${limit})`); return; }
    f.text().then((text) => {
      const isOutline = /\.svg$/i.test(f.name) || (/\.json$/i.test(f.name) && !/"body"\s*:/.test(text));
      send({ type: "load", body: { kind: isOutline ? "outline_file" : "scene", filename: f.name, text, resolution: resolution() } });
      $("file").value = "";
    });
  });
  $("draw").onclick = () => {
    if (S.draw) { S.draw = null; } else { S.draw = { polys: [], cur: [] }; if (!S.body) fit([]); showHint("Click to place vertices; Close polygon ends it (the first is the outline, the next ones holes); Mesh builds the body."); }
    drawButtons(); render();
  };
  $("draw-close").onclick = () => { if (S.draw && S.draw.cur.length >= 3) { S.draw.polys.push(S.draw.cur); S.draw.cur = []; } drawButtons(); render(); };
  $("draw-mesh").onclick = () => {
    if (!S.draw || !S.draw.polys.length) return;
    send({ type: "load", body: { kind: "outline", outline: S.draw.polys[0], holes: S.draw.polys.slice(1), resolution: resolution() } });
  };
  function drawButtons() {
    $("draw").textContent = S.draw ? "Cancel drawing" : "Draw outline";
    $("draw-close").disabled = !S.draw || S.draw.cur.length < 3;
    $("draw-mesh").disabled = !S.draw || !S.draw.polys.length;
  }
  $("show-graph").addEventListener("change", () => { if ($("show-graph").checked && !S.graph) send({ type: "graph" }); render(); });
  $("route").onclick = () => {
    const mm = $("max_muscles").value.trim(), fab = fabrication();
    if (fab === null) return;
    send({ type: "route", K_a: Number($("K_a").value), K_b: Number($("K_b").value), max_muscles: mm === "" ? null : Number(mm),
           fabrication: fab });
  };
  $("delete-muscle").onclick = deleteSelected;
  window.addEventListener("keydown", (ev) => {
    const tag = document.activeElement ? document.activeElement.tagName : "";
    if ((ev.key === "Delete" || ev.key === "Backspace") && tag !== "INPUT" && tag !== "SELECT" && tag !== "TEXTAREA") deleteSelected();
  });
  $("design").onclick = () => send({ type: "design", method: $("method").value, muscle_model: $("muscle_model").value, a_max: Number($("a_max").value) });
  $("save").onclick = () => send({ type: "save", name: $("save-name").value.trim() || null });
  // the server asks before it replaces a file this page did not write: only the user's click confirms
  $("confirm-yes").onclick = () => { if (S.confirm) send({ type: "save", name: S.confirm.name, confirm: true }); S.confirm = null; $("confirm").hidden = true; };
  $("confirm-no").onclick = () => { S.confirm = null; $("confirm").hidden = true; $("saved").textContent = "not saved: the existing file was kept"; };

  window.addEventListener("resize", () => { resize(); render(); });

  // ------------------------------------------------------------------ for tests and scripting
  window.mdsrAuthor = {
    state: () => S.state, body: () => S.body, graph: () => S.graph, sid: () => S.sid, routing: () => S.routing, design: () => S.design, saved: () => S.saved,
    muscles: () => S.muscles, selected: () => S.selected,
    confirmation: () => S.confirm,
    errors: () => S.errors.slice(), lastError: () => S.lastError, pong: () => S.pong,
    busy: () => S.inflight !== null || S.op !== null || S.pendingDrag,
    seq: () => S.seq, nLive: () => S.nLive,
    screenOf: (i) => toScreen(S.handles.has(i) ? S.handles.get(i).pos : shown()[i]),
    worldOf: (q) => toWorld(q),
    sendRaw: (text) => S.ws.send(text),
    send: (m) => send(m),
  };

  // the body drop-down names what is loaded: a library problem is selected; a scene file or an outline of
  // the user's shows as its own entry (a library name beside it would say that problem is loaded)
  function showLoaded(m) {
    const sel = $("problem");
    let own = $("problem-own");
    if (m.library && [...sel.options].some((o) => o.value === m.name && o !== own)) {
      if (own) own.remove();
      sel.value = m.name;
    } else {
      if (!own) {
        own = document.createElement("option"); own.id = "problem-own"; own.value = ""; own.disabled = true;
        sel.insertBefore(own, sel.firstChild);
      }
      own.textContent = `${m.name} (${m.source === "outline" ? "outline" : "file"})`;
      sel.value = "";
    }
    $("load-problem").disabled = sel.value === "";
  }
  $("problem").addEventListener("change", () => { $("load-problem").disabled = $("problem").value === ""; });

  // ------------------------------------------------------------------ start
  resize();
  render();
  fetch("/api/info").then((r) => {
    if (!r.ok) return r.text().then((t) => { throw new Error(t.trim() || `HTTP ${r.status}`); });
    return r.json();
  }).then((info) => {
    S.info = info;
    const sel = $("problem");
    for (const p of info.problems) { const o = document.createElement("option"); o.textContent = p; sel.appendChild(o); }
    if (info.design.muscle_model) setSelect("muscle_model", info.design.muscle_model);
    updateDownloads();
    connect();
  }).catch((e) => { status(String(e.message || e)); showError(String(e.message || e)); });
  setInterval(() => { if (S.state) updateStatus(); }, 1000);
})();
