// sotpy's dashboard page: the graph (dagre's layout, drawn in SVG), live plots (uPlot),
// the stack, edits. Everything it shows comes from its websocket (/ws): "graph" when
// the topology changes, "status" five times a second, binary frames of the plotted
// rows (a 4-byte header length, a JSON header, float64 values), "reply" to a request.
"use strict";

const S = {
  ws: null, nextId: 1, pending: new Map(),
  graph: null, byPath: new Map(), entityOf: new Map(), fresh: new Set(), missing: new Set(),
  status: null, open: new Set(), selected: null,
  plots: [], target: null, nextSid: 1, nextPlot: 1,
  x: [], cols: new Map(), maxRows: 10000, paused: false, windowS: 5,
  frames: 0, rowsSeen: 0, draws: 0,
};
window.sotpyDashboard = S; // for tests and the console

const $ = (id) => document.getElementById(id);
const el = (tag, attrs = {}, ...kids) => {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") e.className = v; else if (k === "text") e.textContent = v;
    else if (k.startsWith("on")) e.addEventListener(k.slice(2), v); else e.setAttribute(k, v);
  }
  for (const k of kids) e.append(k);
  return e;
};
const SVG = "http://www.w3.org/2000/svg";
const sv = (tag, attrs = {}) => {
  const e = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  return e;
};
const fmt = (v, d = 3) => (v === null || v === undefined ? "-" : (Math.abs(v) >= 1e4 || (v !== 0 && Math.abs(v) < 1e-3)) ? v.toExponential(2) : v.toFixed(d));
const us = (s) => (s === null || s === undefined ? "-" : (s * 1e6).toFixed(0) + " us");

function logLine(text, ok) {
  const line = el("div", { class: ok ? "ok" : "err", text: `${new Date().toLocaleTimeString()} ${text}` });
  const log = $("log");
  log.prepend(line);
  while (log.childNodes.length > 60) log.lastChild.remove();
}

// -- the connection ---------------------------------------------------------------------
function connect() {
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  ws.binaryType = "arraybuffer";
  S.ws = ws;
  ws.onopen = () => {
    $("conn").textContent = "connected"; $("conn").className = "badge on";
    sendSeries();
    request({ kind: "watch", entities: [...S.open] }).catch(() => {});
  };
  ws.onclose = () => {
    $("conn").textContent = "disconnected"; $("conn").className = "badge bad";
    for (const [, p] of S.pending) p.reject(new Error("disconnected"));
    S.pending.clear();
    setTimeout(connect, 2000);
  };
  ws.onmessage = (ev) => {
    if (typeof ev.data !== "string") { onFrame(ev.data); return; }
    const msg = JSON.parse(ev.data);
    if (msg.type === "graph") onGraph(msg);
    else if (msg.type === "status") onStatus(msg);
    else if (msg.type === "reply") onReply(msg);
    else if (msg.type === "plot") { const p = newPlot(); for (const path of msg.signals) addSeries(path, null, p); }
  };
}

function request(msg) {
  return new Promise((resolve, reject) => {
    if (!S.ws || S.ws.readyState !== 1) { reject(new Error("not connected")); return; }
    const id = S.nextId++;
    S.pending.set(id, { resolve, reject });
    S.ws.send(JSON.stringify({ id, ...msg }));
  });
}

function onReply(msg) {
  const p = S.pending.get(msg.id);
  if (!p) return;
  S.pending.delete(msg.id);
  p.resolve(msg);
}

// An edit: its reply is logged, a refusal in red with the sotpy.errors message.
async function edit(msg, what) {
  try {
    const r = await request(msg);
    if (r.ok) logLine(`${what}: ok${r.result ? " -> " + r.result : ""}`, true);
    else logLine(`${what}: REFUSED: ${r.error}`, false);
    return r;
  } catch (e) { logLine(`${what}: ${e.message}`, false); return { ok: false, error: e.message }; }
}

const call = (entity, command, args = []) => edit({ kind: "call", entity, command, args }, `${entity}.${command}(${args.map((a) => JSON.stringify(a)).join(", ")})`);

// -- the graph --------------------------------------------------------------------------
function onGraph(g) {
  S.graph = g;
  S.byPath.clear(); S.entityOf.clear();
  for (const e of g.entities) for (const s of e.signals) { S.byPath.set(s.path, s); S.entityOf.set(s.path, e.name); }
  S.missing = new Set(g.unplugged);
  $("unplugged").textContent = g.unplugged.length ? `unplugged, needed by ${g.control}: ${g.unplugged.join(", ")}` : "";
  renderEntities();
  renderGraph();
}

function entityNeeds(e) { return e.signals.some((s) => S.missing.has(s.path)); }

function renderEntities() {
  const box = $("entities");
  box.replaceChildren();
  const f = $("filter").value.trim().toLowerCase();
  for (const e of S.graph.entities) {
    const hit = !f || e.name.toLowerCase().includes(f) || e.className.toLowerCase().includes(f) || e.signals.some((s) => s.name.toLowerCase().includes(f));
    if (!hit) continue;
    const div = el("div", { class: `entity kind-${e.kind}${entityNeeds(e) ? " needs" : ""}${S.open.has(e.name) || f ? " open" : ""}`, "data-entity": e.name });
    const head = el("div", { class: "head", onclick: () => { toggleEntity(e.name); } }, e.name + " ", el("span", { class: "cls", text: `(${e.className})` }));
    const sigs = el("div", { class: "sigs" });
    for (const s of e.signals) {
      if (f && !e.name.toLowerCase().includes(f) && !s.name.toLowerCase().includes(f)) continue;
      sigs.append(signalRow(s));
    }
    div.append(head, sigs);
    box.append(div);
  }
  applyFresh();
}

function toggleEntity(name, open) {
  const want = open === undefined ? !S.open.has(name) : open;
  if (want) S.open.add(name); else S.open.delete(name);
  request({ kind: "watch", entities: [...S.open] }).catch(() => {});
  const div = document.querySelector(`.entity[data-entity="${CSS.escape(name)}"]`);
  if (div) div.classList.toggle("open", want);
  selectNode(name);
}

function signalRow(s) {
  const missing = S.missing.has(s.path);
  const mode = missing ? "UNPLUGGED (the control needs it)" : s.mode;
  const row = el("div", { class: `sig${missing ? " missing" : ""}`, "data-path": s.path, title: `${s.doc}\n${s.path}` });
  const acts = el("span", { class: "acts" });
  if (s.plottable) acts.append(el("button", { text: "plot", title: "add to the selected plot", onclick: (ev) => plotClicked(s, ev) }));
  row.append(
    el("span", { class: "dot" }),
    el("span", { class: "name", text: s.name }),
    el("span", { class: "meta" }, `${s.dir} ${s.type} `, el("span", { class: `mode ${s.mode}`, text: s.source ? `<- ${s.source}` : mode })),
    acts,
    el("span", { class: "val", text: s.value }),
  );
  if (s.dir === "in" && s.mode !== "plugged") {
    const input = el("input", { value: s.mode === "constant" ? s.value.replace(/\s+/g, " ") : "", spellcheck: "false", placeholder: "a value: 2.5, [0, 1], true" });
    const set = () => edit({ kind: "set", signal: s.path, text: input.value }, `set ${s.path} = ${input.value}`);
    input.addEventListener("keydown", (ev) => { if (ev.key === "Enter") set(); });
    row.append(el("span", { class: "edit" }, input, el("button", { text: "set", onclick: set })));
  }
  return row;
}

function applyFresh() {
  for (const row of document.querySelectorAll(".sig")) row.classList.toggle("fresh", S.fresh.has(row.dataset.path));
  for (const n of document.querySelectorAll("#graph .node")) {
    const e = S.graph.entities.find((x) => x.name === n.dataset.entity);
    n.classList.toggle("fresh", !!e && e.signals.some((s) => s.dir === "out" && S.fresh.has(s.path)));
  }
  for (const ed of document.querySelectorAll("#graph .edge")) ed.classList.toggle("fresh", (ed.dataset.from || "").split(" ").some((p) => S.fresh.has(p)));
}

function renderGraph() {
  const g = new dagre.graphlib.Graph({ multigraph: false, compound: false });
  g.setGraph({ rankdir: "LR", nodesep: 14, ranksep: 70, edgesep: 8, marginx: 10, marginy: 10 });
  g.setDefaultEdgeLabel(() => ({}));
  for (const e of S.graph.entities) {
    const w = Math.max(e.name.length * 6.6, e.className.length * 6 + 8, 60) + 14;
    g.setNode(e.name, { width: w, height: 34, entity: e });
  }
  const pairs = new Map();
  for (const ed of S.graph.edges) {
    const a = S.entityOf.get(ed.from), b = S.entityOf.get(ed.to);
    if (a === undefined || b === undefined || a === b) continue;
    const key = a + "\u0000" + b;
    if (!pairs.has(key)) pairs.set(key, { a, b, labels: [], from: [] });
    const p = pairs.get(key);
    p.labels.push(`${S.byPath.get(ed.from).name}→${S.byPath.get(ed.to).name}`);
    p.from.push(ed.from);
  }
  for (const p of pairs.values()) {
    const label = p.labels.length > 2 ? `${p.labels[0]} +${p.labels.length - 1}` : p.labels.join(", ");
    g.setEdge(p.a, p.b, { label, width: label.length * 5, height: 10, labelpos: "c", from: p.from, all: p.labels });
  }
  dagre.layout(g);
  const root = $("graphRoot");
  root.replaceChildren();
  const defs = sv("defs");
  const marker = sv("marker", { id: "arrow", viewBox: "0 0 10 10", refX: 9, refY: 5, markerWidth: 6, markerHeight: 6, orient: "auto-start-reverse" });
  marker.append(sv("path", { d: "M 0 0 L 10 5 L 0 10 z", fill: "#8a949c" }));
  defs.append(marker);
  root.append(defs);
  for (const c of S.graph.clusters) {
    const ns = c.members.map((m) => g.node(m)).filter(Boolean);
    if (!ns.length) continue;
    const x0 = Math.min(...ns.map((n) => n.x - n.width / 2)) - 6, x1 = Math.max(...ns.map((n) => n.x + n.width / 2)) + 6;
    const y0 = Math.min(...ns.map((n) => n.y - n.height / 2)) - 14, y1 = Math.max(...ns.map((n) => n.y + n.height / 2)) + 6;
    root.append(sv("rect", { class: "cluster", x: x0, y: y0, width: x1 - x0, height: y1 - y0, rx: 6 }));
    const t = sv("text", { x: x0 + 4, y: y0 + 10, "font-size": 10, fill: "#c2185b" });
    t.textContent = `${c.owner}: ${c.label}`;
    root.append(t);
  }
  for (const id of g.edges()) {
    const ed = g.edge(id);
    const grp = sv("g", { class: "edge", "data-from": ed.from.join(" ") });
    const pts = ed.points;
    grp.append(sv("path", { d: "M" + pts.map((p) => `${p.x},${p.y}`).join(" L") }));
    const t = sv("text", { x: ed.x, y: ed.y, "text-anchor": "middle" });
    t.textContent = ed.label;
    const title = sv("title");
    title.textContent = ed.all.join("\n");
    grp.append(t, title);
    root.append(grp);
  }
  for (const name of g.nodes()) {
    const n = g.node(name), e = n.entity;
    const grp = sv("g", { class: `node kind-${e.kind}${entityNeeds(e) ? " needs" : ""}`, "data-entity": name, transform: `translate(${n.x - n.width / 2},${n.y - n.height / 2})` });
    grp.append(sv("rect", { width: n.width, height: n.height, rx: 4 }));
    const t1 = sv("text", { x: 6, y: 14 }); t1.textContent = name;
    const t2 = sv("text", { x: 6, y: 27, class: "cls" }); t2.textContent = e.className;
    grp.append(t1, t2);
    grp.addEventListener("click", () => { toggleEntity(name, true); const d = document.querySelector(`.entity[data-entity="${CSS.escape(name)}"]`); if (d) d.scrollIntoView({ block: "nearest" }); });
    root.append(grp);
  }
  const gg = g.graph();
  S.view = { x: 0, y: 0, w: Math.max(gg.width, 100), h: Math.max(gg.height, 60) };
  setView();
  applyFresh();
  if (S.selected) selectNode(S.selected);
}

function selectNode(name) {
  S.selected = name;
  for (const n of document.querySelectorAll("#graph .node")) n.classList.toggle("selected", n.dataset.entity === name);
}

function setView() { $("graph").setAttribute("viewBox", `${S.view.x} ${S.view.y} ${S.view.w} ${S.view.h}`); }

function panZoom() {
  const svg = $("graph");
  svg.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    const r = svg.getBoundingClientRect(), k = ev.deltaY > 0 ? 1.15 : 1 / 1.15;
    const fx = (ev.clientX - r.left) / r.width, fy = (ev.clientY - r.top) / r.height;
    const v = S.view, w = v.w * k, h = v.h * k;
    S.view = { x: v.x + (v.w - w) * fx, y: v.y + (v.h - h) * fy, w, h };
    setView();
  }, { passive: false });
  let drag = null;
  svg.addEventListener("mousedown", (ev) => { drag = { x: ev.clientX, y: ev.clientY, v: { ...S.view } }; });
  window.addEventListener("mouseup", () => { drag = null; });
  window.addEventListener("mousemove", (ev) => {
    if (!drag) return;
    const r = svg.getBoundingClientRect(), sx = drag.v.w / r.width, sy = drag.v.h / r.height, s = Math.max(sx, sy);
    S.view = { ...drag.v, x: drag.v.x - (ev.clientX - drag.x) * s, y: drag.v.y - (ev.clientY - drag.y) * s };
    setView();
  });
}

// -- the status -------------------------------------------------------------------------
function onStatus(st) {
  S.status = st;
  if (S.graph && st.version !== S.graph.version) return; // a new graph is on its way
  S.fresh = new Set(st.fresh.map((i) => S.graph.signals[i]));
  applyFresh();
  const lp = st.loop;
  if (lp) {
    const state = lp.fault ? "FAULT" : lp.running ? "running" : "paused";
    $("loopState").textContent = `${lp.name}: ${state}`;
    $("loopState").className = `badge ${lp.fault ? "bad" : lp.running ? "on" : "off"}`;
    $("stats").textContent = `${(1 / lp.dt).toFixed(0)} Hz, achieved ${lp.rate ? lp.rate.toFixed(0) : "-"} Hz | tick mean ${us(lp.tickMean)} p99 ${us(lp.tickP99)} max ${us(lp.tickMax)} | misses ${lp.misses}, skipped ${lp.skipped}`;
    $("fault").textContent = lp.fault || "";
    document.body.classList.toggle("faulted", !!lp.fault);
    $("clock").textContent = `tick ${st.tick}, t = ${(st.tick * lp.dt).toFixed(3)} s`;
  } else $("clock").textContent = `tick ${st.tick}`;
  if (st.values) for (const [path, text] of Object.entries(st.values)) {
    const row = document.querySelector(`.sig[data-path="${CSS.escape(path)}"] .val`);
    if (row) row.textContent = text;
  }
  $("view3d").disabled = !st.viewerAvailable;
  if (st.recording && Object.keys(st.recording.errors).length) {
    for (const [p, e] of Object.entries(st.recording.errors)) if (!S.reported?.has(p)) { (S.reported ??= new Set()).add(p); logLine(`stopped plotting ${p}: ${e}`, false); }
  }
  if (st.recording) S.maxRows = Math.max(2, Math.round(st.recording.seconds / (lp ? lp.dt : 1e-3)));
  renderStack(st);
}

function renderStack(st) {
  const box = $("stack");
  const focus = document.activeElement && box.contains(document.activeElement);
  if (focus) return; // do not replace a field being typed in
  box.replaceChildren();
  const tasks = S.graph ? S.graph.entities.filter((e) => e.kind === "task").map((e) => e.name) : [];
  for (const sot of st.sots) {
    const t = el("table", { "data-sot": sot.name });
    const extra = ["status", "solved", "iterations", "method"].filter((k) => sot[k] !== undefined).map((k) => `${k} ${sot[k]}`).join(", ");
    t.append(el("caption", { text: `SOT ${sot.name}${extra ? " (" + extra + ")" : ""}` }));
    t.append(el("tr", {}, ...["level", "task", "kind", "rows", "gain", "residual", "rank", "active rows", ""].map((h) => el("th", { text: h }))));
    for (const lv of sot.levels || []) {
      const tr = el("tr", { "data-task": lv.task });
      const bad = lv.satisfied === false;
      const gain = el("td", { class: "num" });
      if (lv.gainPath && S.byPath.get(lv.gainPath) && S.byPath.get(lv.gainPath).mode !== "plugged") {
        const inp = el("input", { value: lv.gain ?? "", title: `${lv.gainPath} (a constant)` });
        inp.addEventListener("keydown", (ev) => { if (ev.key === "Enter") edit({ kind: "set", signal: lv.gainPath, text: inp.value }, `set ${lv.gainPath} = ${inp.value}`); });
        gain.append(inp);
      } else gain.textContent = lv.gain === null ? (lv.gainPath ? "plugged" : "") : fmt(lv.gain);
      const acts = el("td");
      if (lv.kind !== "hard") {
        acts.append(
          el("button", { text: "↑", title: "up", onclick: () => call(sot.name, "up", [lv.task]) }),
          el("button", { text: "↓", title: "down", onclick: () => call(sot.name, "down", [lv.task]) }),
          el("button", { text: "✕", title: "remove", onclick: () => call(sot.name, "remove", [lv.task]) }),
        );
      }
      tr.append(el("td", { text: lv.level }), el("td", { text: lv.task }), el("td", { text: lv.kind }), el("td", { class: "num", text: lv.rows ?? "" }), gain,
        el("td", { class: `num${bad ? " bad" : ""}`, text: fmt(lv.residual, 6) }), el("td", { class: "num", text: lv.rank ?? "" }),
        el("td", { class: "num", text: lv.active === undefined ? "n/a" : `${lv.active}${lv.activeRows && lv.activeRows.length ? " (" + lv.activeRows.join(",") + ")" : ""}` }), acts);
      t.append(tr);
    }
    const free = tasks.filter((n) => !(sot.levels || []).some((l) => l.task === n));
    if (free.length) {
      const sel = el("select", {}, ...free.map((n) => el("option", { value: n, text: n })));
      t.append(el("tr", {}, el("td", { colspan: 9 }, "push ", sel, " ", el("button", { text: "push", onclick: () => call(sot.name, "push", [sel.value]) }))));
    }
    box.append(t);
  }
  for (const c of st.controllers) {
    const t = el("table", { "data-controller": c.name });
    t.append(el("caption", { text: `Controller ${c.name} (${c.strategy || "-"}; solution ${c.solutionFound === null ? "-" : c.solutionFound ? "found" : "NOT found"})` }));
    t.append(el("tr", {}, ...["task", "kind", "level", "weight", "ramp", "state", "ramp s", ""].map((h) => el("th", { text: h }))));
    for (const k of c.tasks || []) {
      const w = el("input", { value: k.weight ?? "" });
      w.addEventListener("keydown", (ev) => { if (ev.key === "Enter") call(c.name, "setTaskWeight", [k.name, Number(w.value)]); });
      t.append(el("tr", { "data-task": k.name }, el("td", { text: k.name }), el("td", { text: k.kind }), el("td", { class: "num", text: k.level ?? "" }), el("td", {}, w),
        el("td", {}, el("span", { class: "ramp", style: `width:${Math.round(40 * (k.ramp || 0))}px` }), ` ${fmt(k.ramp, 2)}`), el("td", { text: k.state || "" }), el("td", { class: "num", text: fmt(k.rampDuration, 3) }),
        el("td", {}, el("button", { text: "on", onclick: () => call(c.name, "activate", [k.name]) }), el("button", { text: "off", onclick: () => call(c.name, "deactivate", [k.name]) }))));
    }
    for (const k of c.constraints || []) t.append(el("tr", {}, el("td", { text: k.name }), el("td", { text: k.kind }), el("td", {}), el("td", { text: "constraint" }), el("td", { text: fmt(k.ramp, 2) }), el("td", { text: k.state || "" }), el("td", {}), el("td", {})));
    box.append(t);
  }
}

// -- plots ------------------------------------------------------------------------------
const COLORS = ["#1565c0", "#c62828", "#2e7d32", "#ef6c00", "#6a1b9a", "#00838f", "#5d4037", "#ad1457", "#9e9d24", "#37474f"];

function plotClicked(s, ev) {
  const width = s.width || 1;
  if (width <= 1) { addSeries(s.path, [0]); return; }
  const old = document.querySelector(".picker");
  if (old) old.remove();
  const picker = el("div", { class: "picker" });
  const boxes = (s.components || []).map((name, k) => { const b = el("input", { type: "checkbox" }); if (k < 3 && width <= 6) b.checked = true; picker.append(el("label", {}, b, ` ${k} ${name}`)); return b; });
  picker.append(el("button", { text: "add", onclick: () => { const ks = boxes.map((b, k) => (b.checked ? k : -1)).filter((k) => k >= 0); if (ks.length) addSeries(s.path, ks); picker.remove(); } }),
    el("button", { text: "all", onclick: () => { addSeries(s.path, boxes.map((_, k) => k)); picker.remove(); } }),
    el("button", { text: "cancel", onclick: () => picker.remove() }));
  picker.style.left = `${ev.pageX}px`; picker.style.top = `${ev.pageY}px`;
  document.body.append(picker);
}

function newPlot() {
  const p = { id: S.nextPlot++, series: [], u: null, div: null };
  p.div = el("div", { class: "plot", "data-plot": p.id, onclick: () => setTarget(p) });
  p.names = el("span", { class: "names" });
  p.chart = el("div", { class: "chart" });
  p.div.append(el("div", { class: "ptitle" }, p.names, el("button", { text: "✕", title: "remove this plot", onclick: (ev) => { ev.stopPropagation(); removePlot(p); } })), p.chart);
  $("plots").append(p.div);
  S.plots.push(p);
  setTarget(p);
  return p;
}

function setTarget(p) { S.target = p; for (const q of S.plots) q.div.classList.toggle("target", q === p); }

async function addSeries(path, comps, plot) {
  const p = plot || S.target || newPlot();
  if (!S.plots.includes(p)) return;
  const r = await edit({ kind: "plot", signal: path }, `plot ${path}`);
  if (!r.ok) return;
  const s = S.byPath.get(path);
  p.series.push({ sid: S.nextSid++, path, comps, labels: s && s.components && comps ? comps.map((k) => s.components[k]) : null });
  sendSeries();
}

function removePlot(p) {
  S.plots = S.plots.filter((q) => q !== p);
  if (p.u) p.u.destroy();
  p.div.remove();
  if (S.target === p) S.target = S.plots[S.plots.length - 1] || null;
  if (S.target) setTarget(S.target);
  const still = new Set(S.plots.flatMap((q) => q.series.map((s) => s.path)));
  for (const s of p.series) if (!still.has(s.path)) edit({ kind: "unplot", signal: s.path }, `unplot ${s.path}`);
  sendSeries();
}

function sendSeries() {
  if (!S.ws || S.ws.readyState !== 1) return;
  const series = S.plots.flatMap((p) => p.series.map((s) => [s.sid, s.path, s.comps]));
  S.x = []; S.cols = new Map(); // the server sends the whole ring again
  for (const p of S.plots) buildPlot(p);
  request({ kind: "series", series }).catch(() => {});
}

function lines(p) {
  const out = [];
  for (const s of p.series) {
    const cols = S.cols.get(s.sid);
    const n = cols ? cols.length : (s.comps ? s.comps.length : 1);
    for (let k = 0; k < n; k++) out.push({ s, k, label: `${s.path}${s.labels ? s.labels[k] : "[" + k + "]"}` });
  }
  return out;
}

function buildPlot(p) {
  if (p.u) { p.u.destroy(); p.u = null; }
  const ls = lines(p);
  p.lineCount = ls.length;
  p.names.textContent = p.series.length ? p.series.map((s) => s.path).join(", ") : "empty plot: click 'plot' on a signal";
  if (!ls.length) return;
  const width = Math.max(200, $("plots").clientWidth - 12);
  const opts = {
    width, height: 170,
    scales: { x: { time: false, range: (u, min, max) => xRange(min, max) } },
    axes: [{ label: "t [s] (tick x dt)", size: 30 }, { size: 50 }],
    series: [{ label: "t" }, ...ls.map((l, i) => ({ label: l.label, stroke: COLORS[i % COLORS.length], width: 1.2, spanGaps: false }))],
    cursor: { drag: { x: true, y: false } },
    hooks: { setSelect: [(u) => { if (u.select.width > 4) { setPaused(true); S.zoom = [u.posToVal(u.select.left, "x"), u.posToVal(u.select.left + u.select.width, "x")]; redraw(); } }] },
    legend: { live: true },
  };
  p.u = new uPlot(opts, plotData(p, ls), p.chart);
}

function xRange(min, max) {
  if (S.zoom) return S.zoom;
  if (!S.x.length) return [0, 1];
  const last = S.viewEnd !== undefined && S.paused ? S.viewEnd : S.x[S.x.length - 1];
  return [last - S.windowS, last];
}

// The visible rows only, at most two points a pixel: each bucket of rows gives its
// minimum and its maximum (the envelope a pixel column shows), so a 1 kHz signal over
// 5 s costs the browser about as much as a 30 Hz one.
function lowerBound(a, v) { let lo = 0, hi = a.length; while (lo < hi) { const m = (lo + hi) >> 1; if (a[m] < v) lo = m + 1; else hi = m; } return lo; }

function plotData(p, ls) {
  const [x0, x1] = xRange(S.x[0], S.x[S.x.length - 1]);
  const i0 = Math.max(0, lowerBound(S.x, x0) - 1), i1 = Math.min(S.x.length, lowerBound(S.x, x1) + 1);
  const ys = ls.map((l) => { const cols = S.cols.get(l.s.sid); return cols && cols[l.k] ? cols[l.k] : null; });
  const n = i1 - i0, px = Math.max(100, p.u ? p.u.bbox.width / devicePixelRatio : 600);
  const step = Math.ceil(n / px);
  if (step <= 2) return [S.x.slice(i0, i1), ...ys.map((y) => (y ? y.slice(i0, i1) : new Array(n).fill(null)))];
  const xs = [], out = ys.map(() => []);
  for (let a = i0; a < i1; a += step) {
    const b = Math.min(i1, a + step);
    xs.push(S.x[a], S.x[Math.min(b - 1, a + (step >> 1))]);
    ys.forEach((y, j) => {
      if (!y) { out[j].push(null, null); return; }
      let lo = null, hi = null;
      for (let i = a; i < b; i++) { const v = y[i]; if (v === null) continue; if (lo === null || v < lo) lo = v; if (hi === null || v > hi) hi = v; }
      out[j].push(lo, hi);
    });
  }
  return [xs, ...out];
}

function onFrame(buf) {
  const dv = new DataView(buf);
  const hlen = dv.getUint32(0, true);
  const head = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, hlen)));
  let off = 4 + hlen; off += (8 - (off % 8)) % 8;
  const n = head.n;
  const vals = new Float64Array(buf, off, (buf.byteLength - off) / 8);
  let at = 0;
  for (let i = 0; i < n; i++) S.x.push(vals[at + i]);
  at += n;
  for (const [sid, w] of head.series) {
    if (!w) { let cols = S.cols.get(sid); if (cols) for (const c of cols) for (let i = 0; i < n; i++) c.push(null); continue; }
    let cols = S.cols.get(sid);
    if (!cols || cols.length !== w) { cols = Array.from({ length: w }, () => new Array(S.x.length - n).fill(null)); S.cols.set(sid, cols); }
    for (let i = 0; i < n; i++) for (let k = 0; k < w; k++) { const v = vals[at + i * w + k]; cols[k].push(Number.isNaN(v) ? null : v); }
    at += n * w;
  }
  for (const cols of S.cols.values()) for (const c of cols) while (c.length < S.x.length) c.push(null);
  const extra = S.x.length - S.maxRows;
  if (extra > 0) { S.x.splice(0, extra); for (const cols of S.cols.values()) for (const c of cols) c.splice(0, extra); }
  S.frames++; S.rowsSeen += n;
  if (!S.paused) drawSoon();
}

// The plots are drawn at the browser's next display frame, once for however many frames
// arrived since: a hidden tab (no display frames) stores the rows and draws nothing.
let drawPending = false;
function drawSoon() {
  if (drawPending) return;
  drawPending = true;
  requestAnimationFrame(() => { drawPending = false; if (!S.paused) { S.draws++; redraw(); } });
}

function redraw() {
  for (const p of S.plots) {
    const ls = lines(p);
    if (ls.length !== p.lineCount) { buildPlot(p); continue; }
    if (p.u) p.u.setData(plotData(p, ls));
  }
}

function setPaused(v) {
  S.paused = v;
  $("pause").textContent = v ? "Live" : "Pause";
  $("rewindBox").classList.toggle("hidden", !v);
  if (!v) { S.zoom = null; S.viewEnd = undefined; $("rewind").value = 1000; redraw(); }
  else S.viewEnd = S.x[S.x.length - 1];
}

// -- controls ---------------------------------------------------------------------------
function loopName() { return S.status && S.status.loop ? S.status.loop.name : "loop"; }

function setup() {
  $("filter").addEventListener("input", () => S.graph && renderEntities());
  $("start").onclick = () => call(loopName(), "start");
  $("stop").onclick = () => call(loopName(), "stop");
  $("step").onclick = () => call(loopName(), "step", [Math.max(1, parseInt($("stepN").value, 10) || 1)]);
  $("recover").onclick = () => call(loopName(), "recover");
  $("clearFault").onclick = () => call(loopName(), "clearFault");
  $("newPlot").onclick = () => newPlot();
  $("pause").onclick = () => setPaused(!S.paused);
  $("window").onchange = () => { S.windowS = Math.max(0.01, Number($("window").value) || 5); redraw(); };
  $("rewind").oninput = () => {
    if (!S.x.length) return;
    const first = S.x[0], last = S.x[S.x.length - 1], f = Number($("rewind").value) / 1000;
    S.zoom = null; S.viewEnd = Math.min(last, first + S.windowS + f * Math.max(0, last - first - S.windowS));
    for (const p of S.plots) if (p.u) p.u.setData(plotData(p, lines(p)));
  };
  for (const b of document.querySelectorAll(".tabs button[data-tab]")) b.onclick = () => showTab(b.dataset.tab);
  $("view3d").onclick = async () => {
    logLine("starting the 3-D view (a few seconds)...", true);
    const r = await edit({ kind: "viewer" }, "3-D view");
    if (!r.ok) return;
    const pane = $("viewerPane");
    if (!pane.querySelector("iframe")) pane.append(el("iframe", { src: r.result, title: "the robot (meshcat)" }));
    $("viewerTab").disabled = false;
    showTab("viewer");
  };
  panZoom();
  newPlot();
  connect();
}

function showTab(name) {
  for (const b of document.querySelectorAll(".tabs button[data-tab]")) b.classList.toggle("active", b.dataset.tab === name);
  $("graphPane").classList.toggle("hidden", name !== "graph");
  $("viewerPane").classList.toggle("hidden", name !== "viewer");
}

setup();
