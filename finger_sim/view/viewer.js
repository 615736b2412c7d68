// finger_sim viewer: draws the frames computed in Python (finger_sim/view/frames.py) and moves
// plotly's time cursor. Nothing here computes kinematics: every position is read from the data.
// Drawn positions are exposed as data-x / data-y (m, model plane) for tests; the drawing is in mm,
// SVG's y downward = the model's +Y (the palmar side), so the finger flexes downwards.
(function () {
  "use strict";
  const MM = 1000;  // drawing units per m
  const NS = "http://www.w3.org/2000/svg";
  const ZOOM_STEP = 1.15;  // view box scale per wheel notch
  const data = JSON.parse(document.getElementById("view-data").textContent);
  const figure = JSON.parse(document.getElementById("plot-data").textContent);
  const times = data.times;
  const slider = document.getElementById("slider");
  const timeOut = document.getElementById("time");
  const playButton = document.getElementById("play");
  const speedSelect = document.getElementById("speed");
  const plots = document.getElementById("plots");
  let frame = 0;
  let playing = false;
  let simTime = times[0];
  let lastWall = 0;

  function svgEl(name, attrs, parent) {
    const e = document.createElementNS(NS, name);
    for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
    if (parent) parent.appendChild(e);
    return e;
  }

  function format(v) {
    if (v === null || v === undefined) return "–";
    if (typeof v === "string") return v;
    return Math.abs(v) >= 1e4 || (Math.abs(v) < 1e-3 && v !== 0) ? v.toExponential(4) : v.toPrecision(5);
  }

  function buildFinger(f) {
    const panel = document.createElement("div");
    panel.className = "finger-panel";
    const left = document.createElement("div");
    const title = document.createElement("h2");
    title.textContent = f.label === f.scene ? f.label : f.label + " (" + f.scene + ")";
    left.appendChild(title);
    const box = f.viewBox.map(function (v) { return v * MM; });
    const svg = svgEl("svg", {class: "linkage", viewBox: box.join(" "), "data-finger": f.label}, left);
    const root = svgEl("g", {class: "finger", "data-finger": f.label}, svg);
    for (const o of f.objects) {
      if (o.type === "circle") {
        svgEl("circle", {class: "object", cx: o.center[0] * MM, cy: o.center[1] * MM, r: o.radius * MM,
                         "data-object": o.name}, root);
      } else {
        svgEl("polygon", {class: "object", points: o.polygon.map(function (p) { return p[0] * MM + "," + p[1] * MM; }).join(" "),
                          "data-object": o.name}, root);
      }
    }
    const path = svgEl("polyline", {class: "tip-path"}, root);
    const capsules = [
      svgEl("line", {class: "capsule", "stroke-width": 2 * f.radii[0] * MM, "data-phalanx": "proximal"}, root),
      svgEl("line", {class: "capsule", "stroke-width": 2 * f.radii[1] * MM, "data-phalanx": "distal"}, root),
    ];
    const links = {
      ground: svgEl("line", {class: "ground", "data-link": "r4"}, root),
      r1: svgEl("line", {class: "link", "data-link": "r1"}, root),
      r2: svgEl("line", {class: "link", "data-link": "r2"}, root),
      r3: svgEl("line", {class: "link", "data-link": "r3"}, root),
      distal: svgEl("line", {class: "link", "data-link": "L3"}, root),
    };
    const contacts = svgEl("g", {class: "contacts"}, root);
    const joints = {};
    for (const name of ["A", "B", "C", "D", "tip"]) {
      joints[name] = svgEl("circle", {class: name === "tip" ? "tip joint-point" : "joint joint-point", r: 1.3,
                                      "data-point": name}, root);
    }
    const table = document.createElement("table");
    table.className = "readout";
    const cells = {};
    for (const name of Object.keys(f.frames.values).sort(readoutOrder)) {
      const row = table.insertRow();
      row.insertCell().textContent = name;
      const cell = row.insertCell();
      cell.className = "value";
      cell.dataset.column = name;
      cells[name] = cell;
      row.insertCell().textContent = data.units[name] || "";
    }
    panel.appendChild(left);
    panel.appendChild(table);
    document.getElementById("stage").appendChild(panel);
    enableZoom(svg, box);
    return {f: f, root: root, path: path, capsules: capsules, links: links, contacts: contacts, joints: joints, cells: cells};
  }

  function readoutOrder(a, b) {  // the joint angles first, then by name
    const ka = a.endsWith("_angle") ? 0 : 1, kb = b.endsWith("_angle") ? 0 : 1;
    return ka - kb || (a < b ? -1 : a > b ? 1 : 0);
  }

  function setLine(line, p, q) {
    line.setAttribute("x1", p[0] * MM); line.setAttribute("y1", p[1] * MM);
    line.setAttribute("x2", q[0] * MM); line.setAttribute("y2", q[1] * MM);
  }

  function drawFinger(d, k) {
    const P = d.f.frames.points;
    const at = function (name) { return P[name][k]; };
    d.root.dataset.t = d.f.frames.t[k];
    d.root.dataset.frame = k;
    for (const [name, el] of Object.entries(d.joints)) {
      const p = at(name);
      el.setAttribute("cx", p[0] * MM); el.setAttribute("cy", p[1] * MM);
      el.dataset.x = p[0]; el.dataset.y = p[1];
    }
    setLine(d.capsules[0], at("A"), at("B"));
    setLine(d.capsules[1], at("B"), at("tip"));
    setLine(d.links.ground, at("D"), at("A"));
    setLine(d.links.r1, at("A"), at("B"));
    setLine(d.links.r2, at("D"), at("C"));
    setLine(d.links.r3, at("C"), at("B"));
    setLine(d.links.distal, at("B"), at("tip"));
    d.path.setAttribute("points", P.tip.slice(0, k + 1).map(function (p) { return p[0] * MM + "," + p[1] * MM; }).join(" "));
    d.contacts.replaceChildren();
    for (const c of d.f.frames.contacts[k]) {
      const g = svgEl("g", {class: "contact-force", "data-x": c[0], "data-y": c[1], "data-fx": c[2], "data-fy": c[3]}, d.contacts);
      svgEl("circle", {class: "contact", cx: c[0] * MM, cy: c[1] * MM, r: 1.0}, g);
      const tip = [c[0] + c[2] * d.f.arrowScale, c[1] + c[3] * d.f.arrowScale];
      setLine(svgEl("line", {class: "force"}, g), [c[0], c[1]], tip);
      const ang = Math.atan2(tip[1] - c[1], tip[0] - c[0]), head = 2.0;
      svgEl("polygon", {class: "contact", points: [
        [tip[0] * MM, tip[1] * MM],
        [tip[0] * MM - head * Math.cos(ang - 0.4), tip[1] * MM - head * Math.sin(ang - 0.4)],
        [tip[0] * MM - head * Math.cos(ang + 0.4), tip[1] * MM - head * Math.sin(ang + 0.4)],
      ].map(function (p) { return p.join(","); }).join(" ")}, g);
    }
    for (const [name, cell] of Object.entries(d.cells)) {
      const v = d.f.frames.values[name][k];
      cell.textContent = format(v);
      cell.dataset.value = v === null ? "" : String(v);
    }
  }

  function enableZoom(svg, home) {
    let box = home.slice();
    let drag = null;
    const apply = function () { svg.setAttribute("viewBox", box.join(" ")); };
    const toUser = function (ev) {
      const r = svg.getBoundingClientRect();
      return [box[0] + (ev.clientX - r.left) / r.width * box[2], box[1] + (ev.clientY - r.top) / r.height * box[3]];
    };
    svg.addEventListener("wheel", function (ev) {
      ev.preventDefault();
      const s = ev.deltaY > 0 ? ZOOM_STEP : 1 / ZOOM_STEP, p = toUser(ev);
      box = [p[0] - (p[0] - box[0]) * s, p[1] - (p[1] - box[1]) * s, box[2] * s, box[3] * s];
      apply();
    }, {passive: false});
    svg.addEventListener("pointerdown", function (ev) { drag = [ev.clientX, ev.clientY, box.slice()]; svg.setPointerCapture(ev.pointerId); });
    svg.addEventListener("pointermove", function (ev) {
      if (!drag) return;
      const r = svg.getBoundingClientRect();
      box = [drag[2][0] - (ev.clientX - drag[0]) / r.width * box[2], drag[2][1] - (ev.clientY - drag[1]) / r.height * box[3], box[2], box[3]];
      apply();
    });
    svg.addEventListener("pointerup", function () { drag = null; });
    svg.addEventListener("dblclick", function () { box = home.slice(); apply(); });
  }

  const fingers = data.fingers.map(buildFinger);
  slider.max = String(times.length - 1);

  let cursorPending = false;
  function moveCursor() {  // at most one relayout per animation frame
    if (cursorPending) return;
    cursorPending = true;
    requestAnimationFrame(function () {
      cursorPending = false;
      const t = times[frame];
      Plotly.relayout(plots, {"shapes[0].x0": t, "shapes[0].x1": t});
    });
  }

  function setFrame(k) {
    frame = Math.max(0, Math.min(times.length - 1, k));
    slider.value = String(frame);
    timeOut.textContent = "t = " + times[frame].toFixed(4) + " s  (frame " + (frame + 1) + "/" + times.length + ")";
    for (const d of fingers) drawFinger(d, frame);
    moveCursor();
  }

  function frameAt(t) {  // the last frame at or before t
    let lo = 0, hi = times.length - 1;
    while (lo < hi) {
      const mid = (lo + hi + 1) >> 1;
      if (times[mid] <= t) lo = mid; else hi = mid - 1;
    }
    return lo;
  }

  function tick(now) {
    if (!playing) return;
    simTime += (now - lastWall) / 1000 * Number(speedSelect.value);
    lastWall = now;
    if (simTime >= times[times.length - 1]) { setFrame(times.length - 1); pause(); return; }
    const k = frameAt(simTime);
    if (k !== frame) setFrame(k);
    requestAnimationFrame(tick);
  }

  function play() {
    if (frame >= times.length - 1) setFrame(0);
    playing = true;
    simTime = times[frame];
    lastWall = performance.now();
    playButton.textContent = "⏸";
    requestAnimationFrame(tick);
  }

  function pause() { playing = false; playButton.textContent = "▶"; }

  slider.addEventListener("input", function () { pause(); setFrame(Number(slider.value)); });
  playButton.addEventListener("click", function () { if (playing) pause(); else play(); });
  document.getElementById("prev").addEventListener("click", function () { pause(); setFrame(frame - 1); });
  document.getElementById("next").addEventListener("click", function () { pause(); setFrame(frame + 1); });
  document.addEventListener("keydown", function (ev) {
    if (ev.target.tagName === "SELECT") return;
    if (ev.key === "ArrowLeft") { pause(); setFrame(frame - 1); ev.preventDefault(); }
    else if (ev.key === "ArrowRight") { pause(); setFrame(frame + 1); ev.preventDefault(); }
    else if (ev.key === " ") { if (playing) pause(); else play(); ev.preventDefault(); }
  });

  Plotly.newPlot(plots, figure.data, figure.layout, {responsive: true, displaylogo: false, scrollZoom: false})
    .then(function () {
      plots.on("plotly_click", function (ev) {
        if (ev.points && ev.points.length) { pause(); setFrame(frameAt(ev.points[0].x + 5e-10)); }
      });
      setFrame(0);
      document.body.dataset.ready = "true";
    });
  window.fingerView = {setFrame: setFrame, frameAt: frameAt, times: times};
})();
