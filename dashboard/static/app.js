// trustfg dashboard: draws the snapshots the server pushes over /ws (see dashboard/server.py).
// Plain DOM and SVG; elements are created once and updated in place, so 10 Hz with many
// cars stays smooth.
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const svg = document.getElementById("map");
let map = null;          // {bounds, obstacles, cars, breach_distance (per pair, ids order), low_trust}
let selected = null;     // the car whose epsilon circles are shown
let drill = null;        // [truster, trustee] of the trust cell being inspected
let latest = null;       // the last snapshot
let socket = null;
// Render timing, for benchmarks/bench_dashboard.py: how long each snapshot takes to draw.
window.trustfgStats = {snapshots: 0, renders: 0, renderMs: []};
const layers = {};
const carShapes = {};    // id -> {body, heading, label, plan, goal}

function el(name, attrs = {}, parent = null) {
  const node = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  if (parent) parent.appendChild(node);
  return node;
}

function drawMap(m) {
  map = m;
  document.getElementById("fleet").textContent = `${m.fleet} · ${m.scenario}`;
  svg.replaceChildren();
  const [x0, y0, x1, y1] = m.bounds;
  svg.setAttribute("viewBox", `${x0 - 0.05} ${-y1 - 0.05} ${x1 - x0 + 0.1} ${y1 - y0 + 0.1}`);
  const world = el("g", {transform: "scale(1,-1)"}, svg);   // y up, like the ground plane
  el("rect", {x: x0, y: y0, width: x1 - x0, height: y1 - y0, fill: "none", stroke: "#333", "stroke-width": 0.02}, world);
  for (const o of m.obstacles) {
    if (o.kind === "rect") {
      el("rect", {x: o.min[0], y: o.min[1], width: o.max[0] - o.min[0], height: o.max[1] - o.min[1],
                  fill: "#90a4ae", class: "obstacle"}, world);
    } else {
      el("polygon", {points: o.points.map(p => p.join(",")).join(" "), fill: "#90a4ae", class: "obstacle"}, world);
    }
  }
  for (const name of ["sight", "plans", "goals", "epsilon", "cars"]) layers[name] = el("g", {id: `layer-${name}`}, world);
  for (const c of m.cars) {
    const goal = el("path", {d: star(c.goal[0], c.goal[1], 0.09), fill: c.color, opacity: 0.8,
                             class: "goal", "data-car": c.id}, layers.goals);
    const plan = el("polyline", {fill: "none", stroke: c.color, "stroke-width": 0.02, opacity: 0.7,
                                 class: "plan", "data-car": c.id}, layers.plans);
    const group = el("g", {class: "car", "data-car": c.id}, layers.cars);
    const body = el("circle", {r: c.radius, fill: c.color, stroke: "#111", "stroke-width": 0.01,
                               class: "car-body", "data-car": c.id}, group);
    const heading = el("line", {stroke: "#111", "stroke-width": 0.02}, group);
    const label = el("text", {"font-size": 0.12, "text-anchor": "middle", transform: "scale(1,-1)",
                              fill: "#fff", "pointer-events": "none"}, group);
    label.textContent = c.id;
    group.addEventListener("click", () => { selected = selected === c.id ? null : c.id; render(); });
    carShapes[c.id] = {group, body, heading, label, plan, goal};
  }
}

function star(x, y, r) {
  let d = "";
  for (let k = 0; k < 10; k++) {
    const a = Math.PI / 2 + k * Math.PI / 5, rr = k % 2 ? r * 0.45 : r;
    d += `${k ? "L" : "M"}${(x + rr * Math.cos(a)).toFixed(4)},${(y + rr * Math.sin(a)).toFixed(4)}`;
  }
  return d + "Z";
}

function render() {
  const started = performance.now();
  draw();
  const stats = window.trustfgStats;
  stats.renders += 1;
  stats.renderMs.push(performance.now() - started);
  if (stats.renderMs.length > 5000) stats.renderMs.shift();
}

function draw() {
  const s = latest;
  if (!s || !map) return;
  document.getElementById("clock").textContent = s.t > 0 ? new Date(s.t * 1000).toLocaleTimeString() : "";
  renderSource(s.source || {});
  for (const car of s.cars) {
    const shape = carShapes[car.id];
    if (!shape) continue;
    if (car.pose) {
      const {x, y, yaw, valid} = car.pose;
      shape.group.style.display = "";
      shape.body.setAttribute("cx", x); shape.body.setAttribute("cy", y);
      shape.body.setAttribute("data-x", x.toFixed(4)); shape.body.setAttribute("data-y", y.toFixed(4));
      shape.body.setAttribute("opacity", valid && car.pose.age_s < 0.5 ? 1 : 0.35);
      shape.heading.setAttribute("x1", x); shape.heading.setAttribute("y1", y);
      shape.heading.setAttribute("x2", x + 0.18 * Math.cos(yaw)); shape.heading.setAttribute("y2", y + 0.18 * Math.sin(yaw));
      shape.label.setAttribute("x", x); shape.label.setAttribute("y", -y + 0.04);
    } else {
      shape.group.style.display = "none";
    }
    shape.plan.setAttribute("points", car.plan ? car.plan.map(p => p.join(",")).join(" ") : "");
    shape.body.setAttribute("stroke-width", selected === car.id ? 0.04 : 0.01);
  }
  renderSight(s);
  renderEpsilon(s);
  renderAlerts(s.alerts);
  renderTrust(s);
  renderDistances(s.min_distance);
  renderCars(s.cars);
}

// With a sensing range: a thin line from each car to every peer it sees (both ways: solid;
// one way, a car with the longer range: dashed). Nothing without a range: all see all.
function renderSight(s) {
  layers.sight.replaceChildren();
  if (!s.sight) return;
  const at = Object.fromEntries(s.cars.filter(c => c.pose).map(c => [c.id, c.pose]));
  const pairs = new Set(s.sight.map(([a, b]) => `${a},${b}`));
  for (const [a, b] of s.sight) {
    const both = pairs.has(`${b},${a}`);
    if ((both && a > b) || !at[a] || !at[b]) continue;
    el("line", {x1: at[a].x, y1: at[a].y, x2: at[b].x, y2: at[b].y, stroke: "#78909c", "stroke-width": 0.01,
                "stroke-dasharray": both ? "" : "0.04 0.03", class: "sight", "data-cars": `${a},${b}`},
       layers.sight);
  }
}

function renderEpsilon(s) {
  layers.epsilon.replaceChildren();
  document.getElementById("selected").textContent = selected === null ? "none" : `car ${selected}`;
  if (selected === null) return;
  const keeps = (s.trust[String(selected)] || {});
  for (const car of s.cars) {
    const entry = keeps[String(car.id)];
    if (car.id === selected || !car.pose || !entry) continue;
    el("circle", {cx: car.pose.x, cy: car.pose.y, r: entry.epsilon, fill: "none", stroke: "#c62828",
                  "stroke-width": 0.015, "stroke-dasharray": "0.05 0.03", class: "epsilon",
                  "data-car": car.id, "data-epsilon": entry.epsilon}, layers.epsilon);
  }
}

function renderAlerts(alerts) {
  const list = document.getElementById("alerts");
  document.getElementById("alert-count").textContent = alerts.length;
  list.replaceChildren(...alerts.map(a => {
    const li = document.createElement("li");
    li.className = "alert"; li.dataset.kind = a.kind; li.dataset.cars = a.cars.join(",");
    li.textContent = `${a.kind.replace("_", " ")}: ${a.text}`;
    return li;
  }));
}

function renderTrust(s) {
  const ids = s.cars.map(c => c.id);
  const table = document.getElementById("trust");
  if (table.dataset.ids !== ids.join(",")) {
    table.dataset.ids = ids.join(",");
    table.replaceChildren();
    const head = table.insertRow();
    head.appendChild(th("truster \\ trustee"));
    for (const b of ids) head.appendChild(th(b));
    for (const a of ids) {
      const row = table.insertRow();
      row.appendChild(th(a));
      for (const b of ids) {
        const cell = row.insertCell();
        cell.dataset.truster = a; cell.dataset.trustee = b;
        cell.addEventListener("click", () => { drill = a === b ? null : [a, b]; renderDrill(); });
      }
    }
  }
  for (const cell of table.querySelectorAll("td")) {
    const a = cell.dataset.truster, b = cell.dataset.trustee;
    const entry = (s.trust[a] || {})[b];
    if (a === b) { cell.textContent = "·"; continue; }
    cell.textContent = entry ? entry.trust.toFixed(2) + (entry.source === "witnesses" ? "*" : "") : "–";
    cell.dataset.trust = entry ? entry.trust : "";
    cell.dataset.source = entry ? entry.source : "";
    cell.title = entry ? {own: "from its own eyes", witnesses: "witnesses' testimonies moved it (*)",
                          none: "no evidence yet: a stranger"}[entry.source] || "" : "";
    cell.classList.toggle("low", !!entry && entry.trust < map.low_trust);
  }
  renderDrill();
}

function renderDrill() {
  const box = document.getElementById("drill");
  if (!drill || !latest) { box.hidden = true; return; }
  const entry = (latest.trust[String(drill[0])] || {})[String(drill[1])];
  box.hidden = false;
  box.textContent = entry
    ? `car ${drill[0]} → car ${drill[1]}: safety ${entry.tau[0].toFixed(2)}, consistency ${entry.tau[1].toFixed(2)}, ` +
      `transparency ${entry.tau[2].toFixed(2)}; overall ${entry.trust.toFixed(2)}; keeps ε = ${entry.epsilon.toFixed(2)} m; ` +
      {own: "from its own eyes", witnesses: "testimonies moved it", none: "no evidence yet"}[entry.source] +
      (latest.sight ? (latest.sight.some(([a, b]) => a === drill[0] && b === drill[1]) ? ", in sight" : ", out of sight") : "")
    : `car ${drill[0]} has not reported on car ${drill[1]} yet`;
}

function renderDistances(d) {
  const table = document.getElementById("distance");
  document.getElementById("distance-source").textContent = `(from ${d.source}, centre to centre, m)`;
  table.replaceChildren();
  const head = table.insertRow();
  head.appendChild(th(""));
  for (const b of d.ids) head.appendChild(th(b));
  d.matrix.forEach((row, i) => {
    const tr = table.insertRow();
    tr.appendChild(th(d.ids[i]));
    row.forEach((v, j) => {
      const cell = tr.insertCell();
      cell.dataset.a = d.ids[i]; cell.dataset.b = d.ids[j];
      cell.textContent = i === j ? "·" : v === null ? "–" : v.toFixed(2);
      cell.classList.toggle("breach", i !== j && v !== null && v < map.breach_distance[i][j]);
    });
  });
}

function renderCars(cars) {
  const body = document.querySelector("#cars tbody");
  body.replaceChildren(...cars.map(c => {
    const tr = document.createElement("tr");
    tr.dataset.car = c.id;
    const rate = k => (c.rates[k] ?? 0).toFixed(1);
    const clock = c.clock_offset_ms === null || c.clock_offset_ms === undefined ? "–"
      : `${c.clock_offset_ms >= 0 ? "+" : ""}${c.clock_offset_ms.toFixed(0)}`;
    for (const v of [c.id, c.at_goal ? "arrived" : (c.state ?? "–"), c.replan_ms ?? "–", rate("plan"), rate("pose"),
                     rate("trust"), clock, c.last_heard_s === null ? "never" : `${c.last_heard_s.toFixed(1)} s ago`,
                     outcomes(c.outcomes)]) {
      tr.insertCell().textContent = v;
    }
    return tr;
  }));
}

function outcomes(o) {
  if (!o) return "–";
  const kept = o.kept ? ` (+${o.kept} kept)` : "";
  return `${o.first}/${o.retry}/${o.fallback}${kept} · ${o.deadlocks}/${o.aside ?? 0}`;
}

// Operator mode (trustfg dashboard --operator): the session's token comes with the page's
// address (?token=...), is kept for this tab only and sent with every button press.
const params = new URLSearchParams(location.search);
if (params.has("token")) {
  sessionStorage.setItem("trustfg-token", params.get("token"));
  history.replaceState(null, "", location.pathname);  // not left in the address bar or history
}

async function operate(action) {
  const status = document.getElementById("operator-status");
  try {
    const response = await fetch("/api/operator", {
      method: "POST", headers: {"Content-Type": "application/json",
                                "Authorization": `Bearer ${sessionStorage.getItem("trustfg-token") || ""}`},
      body: JSON.stringify({action, cars: []})});
    const answer = await response.json();
    status.textContent = answer.ok ? answer.did : `refused: ${answer.error}`;
    status.dataset.result = answer.ok ? "ok" : "refused";
  } catch (error) {
    status.textContent = `failed: ${error}`;
    status.dataset.result = "failed";
  }
}
for (const action of ["estop", "release", "abort"]) {
  document.getElementById(action).addEventListener("click", () => operate(action));
}

function renderSource(src) {
  document.getElementById("operator").hidden = !(src.operator && src.operator.enabled);
  document.getElementById("mode").textContent = src.mode === "replay" ? "replay" : `live · ${(src.alive || []).length} alive`;
  const box = document.getElementById("replay");
  box.hidden = src.mode !== "replay";
  if (src.mode === "replay") {
    const slider = document.getElementById("slider");
    if (document.activeElement !== slider) {
      slider.value = Math.round(1000 * (src.position - src.start) / Math.max(src.end - src.start, 1e-9));
    }
    document.getElementById("position").textContent = `${(src.position - src.start).toFixed(1)} / ${(src.end - src.start).toFixed(1)} s`;
    document.getElementById("play").textContent = src.playing ? "pause" : "play";
    slider.dataset.start = src.start; slider.dataset.end = src.end;
  }
}

function th(text) { const h = document.createElement("th"); h.textContent = text; return h; }

function send(command) { if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(command)); }

document.getElementById("play").addEventListener("click", () =>
  send({type: latest && latest.source && latest.source.playing ? "pause" : "play"}));
document.getElementById("speed").addEventListener("change", e => send({type: "speed", value: Number(e.target.value)}));
document.getElementById("slider").addEventListener("input", e => {
  const s = Number(e.target.dataset.start), end = Number(e.target.dataset.end);
  send({type: "seek", t: s + (end - s) * Number(e.target.value) / 1000});
});

function connect() {
  const badge = document.getElementById("connection");
  socket = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  socket.onopen = () => { badge.textContent = "connected"; badge.className = "badge on"; badge.dataset.state = "connected"; };
  socket.onclose = () => {
    badge.textContent = "disconnected – retrying"; badge.className = "badge off"; badge.dataset.state = "disconnected";
    setTimeout(connect, 1000);
  };
  socket.onmessage = event => {
    const message = JSON.parse(event.data);
    if (message.type === "map") drawMap(message);
    else if (message.type === "snapshot") {
      latest = message; window.trustfgStats.snapshots += 1; requestAnimationFrame(render);
    }
  };
}
connect();
