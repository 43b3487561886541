// The experimenter page: create sessions, start or pause them, watch progress
// and the size of each participant's page (a warning if it is not the profile's).
"use strict";
(() => {
  const form = document.getElementById("new");
  const tbody = document.getElementById("sessions");
  const err = document.getElementById("form-error");
  const dpr = window.devicePixelRatio || 1;
  form.screen_width_px.value = Math.round(screen.width * dpr);
  form.screen_height_px.value = Math.round(screen.height * dpr);

  async function post(path, body) {
    const r = await fetch(path, { method: "POST", headers: { "Content-Type": "application/json" },
                                  body: JSON.stringify(body) });
    const j = await r.json().catch(() => ({}));
    if (!r.ok) throw new Error(j.error || r.statusText);
    return j;
  }

  function cell(row, content) {
    const td = document.createElement("td");
    if (content instanceof Node) td.appendChild(content); else td.textContent = content;
    row.appendChild(td);
  }

  async function refresh() {
    const r = await fetch("/api/sessions", { cache: "no-store" });
    const list = await r.json();
    const rows = []; // put in at once: a refresh waits for live sessions' states
    for (const s of list) {
      const tr = document.createElement("tr");
      const live = s.protocol === "live";
      const v = live ? await liveState(s) : null; // a live session: its trials' runs
      cell(tr, s.participant);
      cell(tr, s.created.replace("T", " ").slice(0, 19));
      cell(tr, live ? `${v.trials.filter((t) => t.ran).length} / ${v.trials.length} run`
                    : `${s.answered} / ${s.trials}`);
      cell(tr, live ? v.state : s.state);
      const page = document.createElement("span");
      if (s.window_warning) {
        page.className = "warning";
        page.textContent = `\u26a0 ${s.window_warning}`;
      } else {
        page.textContent = s.window_px ? `${s.window_px[0]} x ${s.window_px[1]} px` : "-";
      }
      cell(tr, page);
      const a = document.createElement("a");
      a.href = `/${live ? "live" : "participant"}?session=${encodeURIComponent(s.id)}`;
      a.textContent = "open";
      a.target = "_blank";
      cell(tr, a);
      const b = document.createElement("button");
      const next = s.state === "running" ? "paused" : "running";
      b.textContent = s.state === "running" ? "Pause" : "Start";
      b.disabled = s.state === "finished";
      b.onclick = () => post(`/api/sessions/${encodeURIComponent(s.id)}/state`, { state: next })
        .then(refresh).catch((e) => alert(e.message));
      cell(tr, b);
      if (live) cell(tr, liveControl(s, v));
      rows.push(tr);
    }
    tbody.replaceChildren(...rows);
  }

  async function liveState(s) {
    const sid = encodeURIComponent(s.id);
    return (await fetch(`/api/sessions/${sid}/live`, { cache: "no-store" })).json();
  }

  // A live session's trials run one at a time: start the next, or stop the running one.
  function liveControl(s, v) {
    const sid = encodeURIComponent(s.id);
    const b = document.createElement("button");
    b.className = "live-control";
    const out = document.createElement("span");
    out.append(b);
    if (v.live && v.live.flags && v.live.flags.length) { // timing over the study's limits
      const w = document.createElement("span");
      w.className = "warning live-flags";
      w.textContent = ` \u26a0 trial ${v.live.trial_index + 1}: ${v.live.flags.join("; ")}`;
      out.append(w);
    }
    if (v.live && v.live.running) {
      if (v.live.paused) { // a SAGAT freeze: the run waits for the participant's answers
        const w = document.createElement("span");
        w.className = "live-paused";
        w.textContent = " paused: the participant is answering a SAGAT probe";
        out.append(w);
      }
      b.textContent = `Stop trial ${v.live.trial_index + 1}`;
      b.onclick = () => post(`/api/sessions/${sid}/live/stop`, {})
        .then(refresh).catch((e) => alert(e.message));
      return out;
    }
    const next = (v.trials || []).find((t) => !t.ran);
    b.textContent = next ? `Start trial ${next.index + 1} of ${v.trials.length}` : "All trials run";
    b.disabled = !next || s.state === "finished";
    if (next) {
      b.onclick = () => post(`/api/sessions/${sid}/live/start`, { trial_index: next.index })
        .then(refresh).catch((e) => alert(e.message));
    }
    return out;
  }

  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    err.textContent = "";
    const body = { participant: form.participant.value };
    for (const k of ["screen_width_px", "screen_height_px", "screen_width_mm",
                     "screen_height_mm", "viewing_distance_mm"]) body[k] = Number(form[k].value);
    try { await post("/api/sessions", body); form.participant.value = ""; await refresh(); }
    catch (e) { err.textContent = e.message; }
  });

  fetch("/api/study").then((r) => r.json()).then((s) => {
    if (s.protocol === "live") {
      document.getElementById("study").textContent =
        `Study ${s.name}: protocol live, ${s.conditions} conditions x ${s.repeats}, ` +
        `order ${s.order} (seed ${s.seed})`;
      return;
    }
    const from = s.practice_clips ? ` (from ${s.practice_clips} practice clips)` : "";
    document.getElementById("study").textContent =
      `Study ${s.name}: protocol ${s.protocol}, ${s.clips} clips x ${s.repeats}, ` +
      `${s.practice} practice${from}, break every ${s.break_every || "-"}, order ${s.order} ` +
      `(seed ${s.seed})`;
  });
  refresh();
  setInterval(refresh, 2000);
})();
