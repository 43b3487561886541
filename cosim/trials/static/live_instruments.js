// The live console's instruments (loaded by live.html after live.js and
// instruments.js). Dependency-free. It talks to live.js only through the
// page's body: live.js sets document.body.dataset.phase ("waiting", "live",
// "ended"); this script sets document.body.dataset.freeze while a SAGAT probe
// is asked, and its own full-page panel (#instrument) covers the feeds and
// the map (they are blank to the participant: nothing of them shows, and
// clicks cannot reach them).
// - SAGAT: while a trial is live it asks the server every 250 ms what to ask
//   (GET .../live/freeze). When the run is frozen at a probe (the server
//   paused it at the probe's time), the panel asks the probe's questions
//   (instruments.js's forms) beside a blank map of the area (north up, a
//   grid and a scale bar; a count question's sector and a distance question's
//   point drawn on it): a last-target question is answered by a click on it,
//   turned into {north_m, east_m}. The blank map shows the area the live map
//   showed last (live.js's window.live.view: its centre and scale), grown to
//   hold the questions' sectors and points; without it (a page reloaded
//   during the freeze), the server's extent (the aircraft, the sectors). The
//   answers are posted (POST .../instruments); the server lets the run go on.
// - NASA-TLX: whenever no trial is live it asks the server whether a TLX is
//   due (GET .../instrument: after each block of live trials, or after the
//   session, as the study says) and, if so, asks it (the six scales and, if
//   the study asks them, the 15 pairs) and posts it.
// For a test's eyes: window.liveInstruments = {asked: [...], posted: [...],
// toPixel(north_m, east_m) -> [x, y] on the page (the blank map's)}.
"use strict";
(() => {
  const sid = new URLSearchParams(location.search).get("session");
  const api = `/api/sessions/${sid}`;
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  const el = (tag, cls, text) => {
    const e = document.createElement(tag);
    if (cls) e.className = cls;
    if (text !== undefined) e.textContent = text;
    return e;
  };
  const state = { asked: [], posted: [], toPixel: null };
  window.liveInstruments = state;

  const panel = el("div");
  panel.id = "instrument";
  panel.hidden = true;
  const blank = el("canvas", "blank");
  blank.width = 420;
  blank.height = 420;
  const side = el("div", "side"); // what the panel says, then the form
  const note = el("p", "note");
  const box = el("div", "questions");
  side.append(note, box);
  panel.append(blank, side);
  document.body.append(panel);

  async function post(body) {
    for (let attempt = 0; attempt < 5; attempt++) { // stored once: posting again is safe
      try {
        const r = await fetch(`${api}/instruments`, {
          method: "POST", headers: { "Content-Type": "application/json" },
          body: JSON.stringify(body) });
        state.posted.push({ body, status: r.status });
        if (r.status < 500) return r.status;
      } catch (err) { state.posted.push({ body, status: String(err) }); }
      await sleep(500 * (attempt + 1));
    }
    return null;
  }

  // The blank map of a freeze: `extent` [n0, n1, e0, e1] (m) fills the canvas
  // (the same scale both ways); `q` the question asked (its sector or point).
  function drawBlank(extent, q) {
    const [n0, n1, e0, e1] = extent;
    const w = blank.width, h = blank.height;
    const s = Math.min(w / (e1 - e0), h / (n1 - n0)); // px per metre
    const cn = (n0 + n1) / 2, ce = (e0 + e1) / 2;
    const at = (n, e) => [w / 2 + (e - ce) * s, h / 2 - (n - cn) * s];
    const ctx = blank.getContext("2d");
    ctx.fillStyle = "#1d2a1d";
    ctx.fillRect(0, 0, w, h);
    const pow = 10 ** Math.floor(Math.log10((w * 0.25) / s));
    const step = [5, 2, 1].map((m) => m * pow).find((l) => l * s <= w * 0.25) || pow;
    ctx.strokeStyle = "rgba(255, 255, 255, 0.12)";
    ctx.lineWidth = 1;
    for (let n = Math.ceil(n0 / step) * step; n <= n1; n += step) {
      const [, y] = at(n, e0);
      ctx.beginPath(); ctx.moveTo(0, y); ctx.lineTo(w, y); ctx.stroke();
    }
    for (let e = Math.ceil(e0 / step) * step; e <= e1; e += step) {
      const [x] = at(n0, e);
      ctx.beginPath(); ctx.moveTo(x, 0); ctx.lineTo(x, h); ctx.stroke();
    }
    ctx.font = "12px monospace";
    if (q && q.sector) { // the sector asked about
      ctx.beginPath();
      q.sector.forEach(([n, e], i) => { const [x, y] = at(n, e); if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
      ctx.closePath();
      ctx.fillStyle = "rgba(255, 200, 60, 0.18)";
      ctx.strokeStyle = "#fc3";
      ctx.lineWidth = 2;
      ctx.fill();
      ctx.stroke();
    }
    if (q && q.point) { // the point a distance is from
      const [x, y] = at(q.point[0], q.point[1]);
      ctx.fillStyle = "#fc3";
      ctx.beginPath(); ctx.arc(x, y, 5, 0, 2 * Math.PI); ctx.fill();
    }
    ctx.fillStyle = "#fff";
    ctx.fillText("N \u2191", w - 34, 16);
    ctx.fillRect(10, h - 14, step * s, 3);
    ctx.fillText(step >= 1000 ? `${step / 1000} km` : `${step} m`, 10, h - 20);
    // page pixels <-> metres, for the clicks (and a test's eyes)
    state.toPixel = (n, e) => {
      const r = blank.getBoundingClientRect();
      const [x, y] = at(n, e);
      return [r.left + (x * r.width) / w, r.top + (y * r.height) / h];
    };
    return (clientX, clientY) => {
      const r = blank.getBoundingClientRect();
      const x = ((clientX - r.left) * w) / r.width, y = ((clientY - r.top) * h) / r.height;
      return { north_m: Math.round((cn - (y - h / 2) / s) * 10) / 10,
               east_m: Math.round((ce + (x - w / 2) / s) * 10) / 10 };
    };
  }

  // [n0, n1, e0, e1] (m): the live map's last view with the probe's sectors
  // and points in it, else the server's extent.
  function extentOf(f) {
    const v = window.live && window.live.view;
    if (!v || !v.s) return f.extent_ne_m;
    const hn = v.h / 2 / v.s, he = v.w / 2 / v.s;
    const ns = [v.cn - hn, v.cn + hn], es = [v.ce - he, v.ce + he];
    for (const q of f.questions) {
      for (const [n, e] of (q.sector || []).concat(q.point ? [q.point] : [])) {
        ns.push(n);
        es.push(e);
      }
    }
    const n0 = Math.min(...ns), n1 = Math.max(...ns), e0 = Math.min(...es), e1 = Math.max(...es);
    const half = Math.max(n1 - n0, e1 - e0) / 2; // square, as the canvas
    const cn = (n0 + n1) / 2, ce = (e0 + e1) / 2;
    return [cn - half, cn + half, ce - half, ce + half];
  }

  function show(kind) {
    panel.hidden = false;
    panel.dataset.kind = kind;
    blank.hidden = kind !== "sagat";
  }
  function hide() {
    panel.hidden = true;
    note.textContent = "";
    box.replaceChildren();
    delete document.body.dataset.freeze;
  }

  // One frozen probe, asked and answered (the run waits for the answer).
  async function freeze(f) {
    document.body.dataset.freeze = String(f.probe);
    const extent = extentOf(f);
    state.asked.push({ instrument: "sagat", trial_index: f.trial_index, probe: f.probe,
                       time_s: f.time_s, extent_ne_m: extent });
    show("sagat");
    const byId = Object.fromEntries(f.questions.map((q) => [q.id, q]));
    let toMap = drawBlank(extent, null);
    const say = (k) => {
      note.textContent = `The trial is paused. Question ${k + 1} of ${f.questions.length}: ` +
        "answer from what you remember.";
    };
    say(0);
    const watch = new MutationObserver(() => { // redraw for the question shown
      const form = box.querySelector("[data-question]");
      toMap = drawBlank(extent, form ? byId[form.dataset.question] : null);
      if (form) say(f.questions.indexOf(byId[form.dataset.question]));
    });
    watch.observe(box, { childList: true });
    blank.classList.remove("pick");
    const pickPoint = () => new Promise((resolve) => {
      blank.classList.add("pick");
      blank.addEventListener("click", (e) => {
        blank.classList.remove("pick");
        resolve(toMap(e.clientX, e.clientY));
      }, { once: true });
    });
    try {
      const body = await CosimInstruments.sagat(box, f, f.trial_index, f.aircraft, pickPoint);
      note.textContent = "";
      box.replaceChildren(el("p", "title", "Thank you. The trial goes on."));
      await post(body);
    } finally {
      watch.disconnect();
      hide();
    }
  }

  // The TLX due now, if any, asked and posted.
  async function tlx() {
    const r = await fetch(`${api}/instrument`, { cache: "no-store" });
    if (r.status !== 200) return;
    const due = await r.json();
    if (due.instrument !== "tlx") return;
    state.asked.push({ instrument: "tlx", block: due.block });
    show("tlx");
    try {
      const body = await CosimInstruments.tlx(box, due);
      await post(body);
    } finally {
      hide();
    }
  }

  async function main() {
    const done = new Set(); // "trial/probe" asked already
    for (;;) {
      const phase = document.body.dataset.phase;
      try {
        if (phase === "live") {
          const r = await fetch(`${api}/live/freeze`, { cache: "no-store" });
          const f = r.status === 200 ? (await r.json()).freeze : null;
          if (f && !done.has(`${f.trial_index}/${f.probe}`)) {
            done.add(`${f.trial_index}/${f.probe}`);
            await freeze(f);
            continue;
          }
        } else if (phase === "ended" || phase === "waiting") {
          await tlx();
        }
      } catch (err) { /* the server is busy or gone: asked again shortly */ }
      await sleep(phase === "live" ? 250 : 1000);
    }
  }
  main();
})();
