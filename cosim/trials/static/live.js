// The live console's participant page (protocol: live). Dependency-free.
// Waits for the experimenter to start a trial, then follows its run through the
// server's event stream: the feeds drawn in a grid (each with its id), the map
// of the aircraft (north up, a scale bar, ids, tracks). Each frame is drawn in a
// requestAnimationFrame callback; the page remembers, per feed, which frame it
// drew and when (the callback's time). A click on a feed posts that feed, the
// frame drawn there, the pixel in the frame's own coordinates (scaled from the
// displayed size) and the click's time (both on the page's clock,
// performance.now()). Each refresh draws the oldest waiting frame of each feed:
// frames that arrive together (a burst) are drawn one a refresh, and a feed
// keeps at most MAX_WAITING waiting (a newer one replaces the oldest: the page
// keeps up by skipping, never by falling further behind).
// Timing: the page estimates the offset between its clock and the server's
// (the quickest of a few round trips) and, for every frame drawn, the time
// from the run making it (its made_ms, the server's clock) to the page drawing
// it (glass-to-glass, up to the display's own delay); every 2 s, and at the
// end, it posts the frames received and drawn and those latencies' median,
// 95th percentile and maximum over the trial.
// Tasking (where the condition allows it): a click on an aircraft on the map
// selects it (ringed, its id shown below the map); a click on the ground then
// opens a small menu there of the commands allowed (Go here, Orbit here, Look
// here, for an aircraft with a gimbal camera; keys G, O, L; Escape closes
// it), posted with the point in metres north and east of the scenario's
// origin. Each aircraft's last command (as the server's stream says, so a
// reloaded page has them again) is marked on the map until its next one; a
// refusal is shown for a few seconds.
// Reports are clicks on the feeds, tasking is clicks on the map.
"use strict";
(() => {
  const sid = new URLSearchParams(location.search).get("session");
  const feedsEl = document.getElementById("feeds");
  const map = document.getElementById("map");
  const clock = document.getElementById("clock");
  const message = document.getElementById("message");
  const menu = document.getElementById("taskmenu");
  const taskLine = document.getElementById("tasking");
  const ACTIONS = { go: ["Go here", "G"], orbit: ["Orbit here", "O"], look: ["Look here", "L"] };
  const PICK_PX = 14;      // how near (map px) a click must be to an aircraft to select it
  const TRACK_POINTS = 600;
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  const esc = (text) => String(text).replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);
  const phase = (p) => { document.body.dataset.phase = p; };

  let trialIndex = null;
  let feeds = [];          // [{feed, name, width_px, height_px, canvas, cell}]
  const due = new Map();   // feed -> [{frame, bitmap}, ...]: waiting to be drawn, oldest first
  const MAX_WAITING = 3;
  const drawn = new Map(); // feed -> {frame, time_ms}: what is on screen
  const tracks = new Map(); // vehicle id -> [[north_m, east_m], ...]
  let last = null;         // the last states message
  let layers = [];         // what the map shows: tracks, footprints, targets
  let targets = [];        // [{id, north_m, east_m}] when the map shows targets
  let rafPending = false;
  let tasking = { actions: [], vehicles: [], orbit_radius_m: 0 };
  let selected = null;     // the aircraft selected on the map
  let view = null;         // the map's last transform: {cn, ce, s, w, h}
  const sent = new Map();  // vehicle id -> {action, north_m, east_m}: its last command
  let errorTimer = null;
  let offsetMs = 0;        // the server's clock minus the page's (ms)
  let rttMs = null;        // the round trip that estimate came from
  let received = 0;
  let drawnCount = 0;
  let mismatches = 0;      // frames whose pixels carry another number than said
  const latencies = [];    // glass-to-glass of every frame drawn (ms)
  const MAX_LATENCIES = 100000;
  // for a test's eyes: every frame drawn and every report posted
  window.live = { drawn: [], reports: [], commands: [] };

  function say(html) { message.innerHTML = html; message.hidden = false; }

  function layout() {
    const k = feeds.length;
    if (!k) return;
    const cols = Math.ceil(Math.sqrt(k));
    const rows = Math.ceil(k / cols);
    feedsEl.style.gridTemplateColumns = `repeat(${cols}, minmax(0, 1fr))`;
    feedsEl.style.gridTemplateRows = `repeat(${rows}, minmax(0, 1fr))`;
    for (const f of feeds) {
      const box = f.cell.getBoundingClientRect();
      const s = Math.min(box.width / f.width_px, box.height / f.height_px);
      f.canvas.style.width = `${f.width_px * s}px`;
      f.canvas.style.height = `${f.height_px * s}px`;
    }
  }

  function build(hello) {
    layers = hello.map || [];
    targets = hello.targets || [];
    tasking = hello.tasking || { actions: [], vehicles: [], orbit_radius_m: 0 };
    showTasking();
    feedsEl.innerHTML = "";
    feeds = hello.feeds.map((f) => {
      const cell = document.createElement("div");
      cell.className = "cell";
      const canvas = document.createElement("canvas");
      canvas.width = f.width_px;
      canvas.height = f.height_px;
      canvas.dataset.feed = String(f.feed);
      const id = document.createElement("div");
      id.className = "id";
      id.textContent = `${f.feed + 1} ${f.name}`; // its number on the map's footprint
      const on = document.createElement("div"); // the frame and its id, as large as drawn
      on.className = "frame";
      on.append(canvas, id);
      cell.append(on);
      feedsEl.append(cell);
      const out = { ...f, canvas, cell, on };
      canvas.addEventListener("pointerdown", (e) => report(out, e));
      return out;
    });
    layout();
  }

  function draw(now) {
    rafPending = false;
    for (const [k, q] of due) {
      const d = q.shift();
      const f = feeds[k];
      if (!f) { d.bitmap.close(); continue; }
      f.canvas.getContext("2d").drawImage(d.bitmap, 0, 0, d.bitmap.width,
                                          d.bitmap.height - COUNTER_ROWS, 0, 0,
                                          f.width_px, f.height_px);
      d.bitmap.close();
      drawn.set(k, { frame: d.frame, time_ms: now });
      drawnCount += 1;
      if (latencies.length < MAX_LATENCIES) {
        // the clock now, not the animation frame's time (`now`: when this
        // display frame began, which can precede the frame's arrival)
        latencies.push(performance.timeOrigin + performance.now() + offsetMs - d.made_ms);
      }
      window.live.drawn.push([k, d.frame, now, d.counter]);
      if (window.live.drawn.length > 10000) window.live.drawn.splice(0, 5000);
    }
    for (const [k, q] of due) if (!q.length) due.delete(k);
    if (due.size) { rafPending = true; requestAnimationFrame(draw); }
    document.body.dataset.drawn = String(drawn.size);
  }

  // The frame number written in the rows below the picture (the server's
  // with_counter): bit b white or black at the centre of block b % 8 of band b / 8.
  const COUNTER_ROWS = 32;
  const strip = document.createElement("canvas");
  const stripCtx = strip.getContext("2d", { willReadFrequently: true });
  function readCounter(bitmap) {
    const w = bitmap.width, bw = Math.floor(w / 8);
    strip.width = w;
    strip.height = COUNTER_ROWS;
    stripCtx.drawImage(bitmap, 0, bitmap.height - COUNTER_ROWS, w, COUNTER_ROWS,
                       0, 0, w, COUNTER_ROWS);
    const px = stripCtx.getImageData(0, 0, w, COUNTER_ROWS).data;
    let value = 0;
    for (let b = 0; b < 16; b++) {
      const i = ((16 * Math.floor(b / 8) + 8) * w + (b % 8) * bw + Math.floor(bw / 2)) * 4;
      if ((px[i] + px[i + 1] + px[i + 2]) / 3 >= 128) value |= 1 << b;
    }
    return value;
  }

  async function frame(msg) {
    // a plain loop: Uint8Array.from with a function a character cost the page's
    // main thread 8 to 10 ms a 640 x 360 frame, the loop 1 to 5
    const text = atob(msg.jpeg), bytes = new Uint8Array(text.length);
    for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
    const bitmap = await createImageBitmap(new Blob([bytes], { type: "image/jpeg" }));
    const counter = readCounter(bitmap);
    if (counter !== msg.frame % 65536) mismatches += 1;
    received += 1;
    const on = drawn.get(msg.feed); // never back to a frame older than the one shown
    if (on && on.frame >= msg.frame) { bitmap.close(); return; }
    const q = due.get(msg.feed) || [];
    q.push({ frame: msg.frame, bitmap, made_ms: msg.made_ms, counter });
    q.sort((a, b) => a.frame - b.frame); // decodes may end out of order
    while (q.length > MAX_WAITING) q.shift().bitmap.close();
    due.set(msg.feed, q);
    if (!rafPending) { rafPending = true; requestAnimationFrame(draw); }
  }

  function report(f, e) {
    const on = drawn.get(f.feed);
    if (!on || trialIndex === null) return; // nothing drawn there yet
    const r = f.canvas.getBoundingClientRect();
    // in the frame's pixels, 0 at its left and top edges
    const x = ((e.clientX - r.left) * f.width_px) / r.width;
    const y = ((e.clientY - r.top) * f.height_px) / r.height;
    const body = {
      trial_index: trialIndex, report_key: crypto.randomUUID(), feed: f.feed,
      frame: on.frame, x_px: x, y_px: y, click_time_ms: e.timeStamp,
      drawn_time_ms: on.time_ms,
    };
    window.live.reports.push(body);
    const mark = document.createElement("div");
    mark.className = "mark";
    mark.style.left = `${e.clientX - r.left}px`;
    mark.style.top = `${e.clientY - r.top}px`;
    f.on.append(mark);
    setTimeout(() => mark.remove(), 600);
    post(body);
  }

  async function post(body) {
    for (let attempt = 0; attempt < 5; attempt++) { // the same key: stored once
      try {
        const r = await fetch(`/api/sessions/${sid}/live/reports`, {
          method: "POST", headers: { "Content-Type": "application/json" },
          body: JSON.stringify(body) });
        body.status = r.status;
        if (r.status < 500) return;
      } catch (err) { body.status = String(err); }
      await sleep(500 * (attempt + 1));
    }
  }

  function drawMap() {
    const ctx = map.getContext("2d");
    const w = map.width, h = map.height;
    ctx.fillStyle = "#1d2a1d";
    ctx.fillRect(0, 0, w, h);
    let pts = [];
    for (const tr of tracks.values()) pts = pts.concat(tr);
    const prints = (last && last.footprints) || [];
    for (const f of prints) pts = pts.concat(f.corners_ne_m);
    for (const t of targets) pts.push([t.north_m, t.east_m]);
    for (const c of sent.values()) { // each command's point, an orbit's whole circle
      const r = c.action === "orbit" ? tasking.orbit_radius_m : 0;
      pts.push([c.north_m - r, c.east_m - r], [c.north_m + r, c.east_m + r]);
    }
    if (!pts.length) return;
    const ns = pts.map((p) => p[0]), es = pts.map((p) => p[1]);
    const cn = (Math.max(...ns) + Math.min(...ns)) / 2;
    const ce = (Math.max(...es) + Math.min(...es)) / 2;
    const span = Math.max(200, Math.max(...ns) - Math.min(...ns), Math.max(...es) - Math.min(...es));
    const s = (0.8 * Math.min(w, h)) / span; // px per metre, the same both ways
    const at = (p) => [w / 2 + (p[1] - ce) * s, h / 2 - (p[0] - cn) * s];
    view = { cn, ce, s, w, h };
    window.live.view = view; // for a test's eyes: the map's scale and centre
    const path = (ps) => {
      ctx.beginPath();
      ps.forEach((p, i) => { const [x, y] = at(p); if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
    };
    ctx.font = "12px monospace";
    ctx.lineWidth = 1;
    for (const f of prints) { // each feed's ground footprint, its number at its middle
      path(f.corners_ne_m);
      ctx.closePath();
      ctx.fillStyle = "rgba(255, 255, 255, 0.08)";
      ctx.strokeStyle = "rgba(255, 255, 255, 0.5)";
      ctx.fill();
      ctx.stroke();
      const mid = f.corners_ne_m.reduce((a, p) => [a[0] + p[0] / 4, a[1] + p[1] / 4], [0, 0]);
      const [x, y] = at(mid);
      ctx.fillStyle = "rgba(255, 255, 255, 0.7)";
      ctx.fillText(String(f.feed + 1), x - 3, y + 4);
    }
    if (layers.includes("tracks")) {
      ctx.lineWidth = 1.5;
      ctx.strokeStyle = "#7ab";
      for (const tr of tracks.values()) { path(tr); ctx.stroke(); }
    }
    for (const t of targets) { // a red cross and the target's id
      const [x, y] = at([t.north_m, t.east_m]);
      ctx.strokeStyle = "#f55";
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.moveTo(x - 4, y - 4); ctx.lineTo(x + 4, y + 4);
      ctx.moveTo(x - 4, y + 4); ctx.lineTo(x + 4, y - 4);
      ctx.stroke();
      ctx.fillStyle = "#f99";
      ctx.fillText(t.id, x + 6, y + 4);
    }
    for (const [id, c] of sent) { // each aircraft's last command: a ring and a line to it
      const [x, y] = at([c.north_m, c.east_m]);
      const v = last && last.vehicles.find((u) => u.id === id);
      ctx.strokeStyle = id === selected ? "#6cf" : "rgba(102, 204, 255, 0.6)";
      ctx.lineWidth = 2;
      ctx.setLineDash([4, 3]);
      if (v) { path([[v.north_m, v.east_m], [c.north_m, c.east_m]]); ctx.stroke(); }
      ctx.setLineDash([]);
      ctx.beginPath();
      const r = c.action === "orbit" ? Math.max(6, tasking.orbit_radius_m * s) : 6;
      ctx.arc(x, y, r, 0, 2 * Math.PI);
      ctx.stroke();
      ctx.fillStyle = "#6cf";
      ctx.fillText(`${ACTIONS[c.action][1]} ${id}`, x + 8, y + 14);
    }
    for (const v of (last ? last.vehicles : [])) {
      const [x, y] = at([v.north_m, v.east_m]);
      const a = (v.yaw_deg * Math.PI) / 180;
      if (v.id === selected) { // the selected aircraft: ringed
        ctx.strokeStyle = "#6cf";
        ctx.lineWidth = 2;
        ctx.beginPath();
        ctx.arc(x, y, 11, 0, 2 * Math.PI);
        ctx.stroke();
      }
      ctx.fillStyle = "#fc3";
      ctx.beginPath(); // a triangle pointing along the heading (north up)
      ctx.moveTo(x + 8 * Math.sin(a), y - 8 * Math.cos(a));
      ctx.lineTo(x + 5 * Math.sin(a + 2.5), y - 5 * Math.cos(a + 2.5));
      ctx.lineTo(x + 5 * Math.sin(a - 2.5), y - 5 * Math.cos(a - 2.5));
      ctx.fill();
      ctx.fillStyle = "#fff";
      ctx.fillText(v.id, x + 9, y - 6);
    }
    // north arrow and a scale bar of a round length
    ctx.fillStyle = "#fff";
    ctx.fillText("N \u2191", w - 34, 16);
    const target = (w * 0.3) / s;
    const pow = 10 ** Math.floor(Math.log10(target));
    const len = [5, 2, 1].map((m) => m * pow).find((l) => l <= target) || pow;
    ctx.fillRect(10, h - 14, len * s, 3);
    ctx.fillText(len >= 1000 ? `${len / 1000} km` : `${len} m`, 10, h - 20);
  }

  // --- tasking ---
  function showTasking(text, error = false) {
    if (!tasking.actions.length) { taskLine.hidden = true; return; }
    taskLine.hidden = false;
    taskLine.classList.toggle("error", error);
    taskLine.textContent = text || (selected
      ? `${selected} selected: click the map where it should go`
      : "Click an aircraft on the map to task it");
  }

  function failed(text) {
    showTasking(text, true);
    clearTimeout(errorTimer);
    errorTimer = setTimeout(() => showTasking(), 4000);
  }

  // A click on the map in its own pixels and in metres (north, east).
  function mapPoint(e) {
    const r = map.getBoundingClientRect();
    const x = ((e.clientX - r.left) * map.width) / r.width;
    const y = ((e.clientY - r.top) * map.height) / r.height;
    return { x, y, north_m: view.cn - (y - view.h / 2) / view.s,
             east_m: view.ce + (x - view.w / 2) / view.s };
  }

  function closeMenu() { menu.hidden = true; menu.innerHTML = ""; }

  function mapClick(e) {
    if (!tasking.actions.length || !view || trialIndex === null) return;
    const p = mapPoint(e);
    let near = null, best = PICK_PX;
    for (const v of (last ? last.vehicles : [])) {
      if (!tasking.vehicles.includes(v.id)) continue;
      const d = Math.hypot(view.w / 2 + (v.east_m - view.ce) * view.s - p.x,
                           view.h / 2 - (v.north_m - view.cn) * view.s - p.y);
      if (d <= best) { near = v.id; best = d; }
    }
    closeMenu();
    if (near !== null) { selected = near; showTasking(); drawMap(); return; }
    if (selected === null) { failed("Click an aircraft first, then where it should go"); return; }
    const lookers = tasking.look_vehicles || [];
    for (const a of tasking.actions.filter((x) => x !== "look" || lookers.includes(selected))) {
      const b = document.createElement("button");
      b.dataset.action = a;
      b.textContent = `${ACTIONS[a][0]} (${ACTIONS[a][1]})`;
      b.addEventListener("click", (ev) => { ev.stopPropagation(); task(a, p, ev.timeStamp); });
      menu.append(b);
    }
    menu.hidden = false;
    // at the click, kept inside the side panel
    const side = map.parentElement.getBoundingClientRect(), box = menu.getBoundingClientRect();
    menu.style.left = `${Math.min(e.clientX - side.left, side.width - box.width - 2)}px`;
    menu.style.top = `${Math.min(e.clientY - side.top, side.height - box.height - 2)}px`;
    menu.dataset.north_m = String(p.north_m);
    menu.dataset.east_m = String(p.east_m);
  }

  async function task(action, p, timeMs) {
    closeMenu();
    const body = { trial_index: trialIndex, vehicle: selected, action,
                   north_m: p.north_m, east_m: p.east_m, client_time_ms: timeMs };
    window.live.commands.push(body);
    try {
      const r = await fetch(`/api/sessions/${sid}/live/command`, {
        method: "POST", headers: { "Content-Type": "application/json" },
        body: JSON.stringify(body) });
      const out = await r.json();
      body.status = r.status;
      if (r.status !== 201) { failed(out.error || `refused (${r.status})`); return; }
      body.seq = out.seq;
      commanded({ vehicle: body.vehicle, action, north_m: p.north_m, east_m: p.east_m });
      showTasking(`${ACTIONS[action][0]}: sent to ${body.vehicle}`);
      clearTimeout(errorTimer);
      errorTimer = setTimeout(() => showTasking(), 2000);
    } catch (err) { body.status = String(err); failed("not sent: the server did not answer"); }
  }

  // An aircraft's last command, marked on the map.
  function commanded(c) {
    sent.set(c.vehicle, { action: c.action, north_m: c.north_m, east_m: c.east_m });
    window.live.marked = [...sent.keys()];
    drawMap();
  }

  function taskKey(e) {
    if (menu.hidden) return;
    if (e.key === "Escape") { closeMenu(); return; }
    const a = Object.keys(ACTIONS).find((k) => ACTIONS[k][1] === e.key.toUpperCase());
    if (a && menu.querySelector(`button[data-action="${a}"]`)) {
      task(a, { north_m: Number(menu.dataset.north_m), east_m: Number(menu.dataset.east_m) },
           e.timeStamp);
    }
  }

  function states(msg) {
    last = msg;
    window.live.vehicles = msg.vehicles;
    for (const v of msg.vehicles) {
      if (!tracks.has(v.id)) tracks.set(v.id, []);
      const tr = tracks.get(v.id);
      tr.push([v.north_m, v.east_m]);
      if (tr.length > TRACK_POINTS) tr.shift();
    }
    clock.textContent = `t = ${msg.time_s.toFixed(1)} s`;
    drawMap();
  }

  async function syncClock() {
    for (let i = 0; i < 5; i++) {
      const t0 = performance.now();
      const r = await fetch(`/api/sessions/${sid}/live/clock`, { cache: "no-store" });
      const t1 = performance.now();
      const server = (await r.json()).server_ms;
      if (rttMs === null || t1 - t0 < rttMs) {
        rttMs = t1 - t0;
        offsetMs = server - (performance.timeOrigin + (t0 + t1) / 2);
      }
    }
  }

  function quantile(sorted, q) {
    if (!sorted.length) return null;
    const i = (sorted.length - 1) * q, lo = Math.floor(i), hi = Math.ceil(i);
    return sorted[lo] + (sorted[hi] - sorted[lo]) * (i - lo);
  }

  function timing() {
    const s = [...latencies].sort((a, b) => a - b);
    const body = {
      trial_index: trialIndex, frames_received: received, frames_drawn: drawnCount,
      latency_samples: s.length, latency_ms_p50: quantile(s, 0.5),
      latency_ms_p95: quantile(s, 0.95), latency_ms_max: s.length ? s[s.length - 1] : null,
      clock_rtt_ms: rttMs, counter_mismatches: mismatches,
    };
    window.live.timing = body;
    return fetch(`/api/sessions/${sid}/live/timing`, {
      method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify(body) }).catch(() => {});
  }

  // Follow the running trial's stream; resolved at its end.
  function follow() {
    let ended;
    const over = new Promise((resolve) => { ended = resolve; });
    const es = new EventSource(`/api/sessions/${sid}/live/stream`);
    const every = setInterval(timing, 2000);
    es.addEventListener("hello", (e) => {
      build(JSON.parse(e.data));
      message.hidden = true;
      phase("live");
    });
    es.addEventListener("frame", (e) => { frame(JSON.parse(e.data)); });
    es.addEventListener("states", (e) => states(JSON.parse(e.data)));
    es.addEventListener("command", (e) => commanded(JSON.parse(e.data)));
    es.addEventListener("end", async () => {
      es.close();
      clearInterval(every);
      await timing();
      ended();
    });
    return over;
  }

  // A new trial's page state: nothing drawn, received or reported yet.
  function reset() {
    for (const q of due.values()) for (const d of q) d.bitmap.close();
    due.clear();
    drawn.clear();
    tracks.clear();
    last = null;
    received = drawnCount = mismatches = 0;
    latencies.length = 0;
    selected = null;
    view = null;
    sent.clear();
    closeMenu();
    window.live = { drawn: [], reports: [], commands: [] };
  }

  // Each trial the experimenter starts, followed to its end; between trials
  // the page waits (after one, it says so, and whether the session is over).
  async function main() {
    let done = null; // the trial followed last
    phase("waiting");
    say("<p>Please wait: the experimenter will start the trial.</p>");
    for (;;) {
      const r = await fetch(`/api/sessions/${sid}/live`);
      if (r.status !== 200) { say(`<p>${esc((await r.json()).error || r.status)}</p>`); return; }
      const s = await r.json();
      if (s.live && s.live.running && s.live.trial_index !== done) {
        trialIndex = s.live.trial_index;
        reset();
        await syncClock();
        await follow();
        done = trialIndex;
        say("<p>This trial is over. Thank you.</p>");
        phase("ended");
        continue;
      }
      if (done !== null) {
        const left = (s.trials || []).some((t) => !t.ran);
        say(left ? "<p>This trial is over. Thank you.</p><p>Please wait for the next one.</p>"
                 : "<p>This trial is over, and the session with it. Thank you.</p>");
      }
      await sleep(300);
    }
  }

  window.addEventListener("resize", layout);
  map.addEventListener("pointerdown", mapClick);
  window.addEventListener("keydown", taskKey);
  main();
})();
