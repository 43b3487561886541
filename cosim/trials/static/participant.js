// The participant page: plays the session's clips in order and posts one
// response per trial. Dependency-free. The server computes every measure; this
// page only reports which key was pressed and the mediaTime of the video frame
// that was on screen at that moment (requestVideoFrameCallback metadata).
// Resumes after a reload at the first trial without a response: the server
// keeps the first response of a trial, so posting again never duplicates one.
// A trial that had started playing before the reload is shown again from its
// start and its response says so ("reshown": true).
// The page's size goes to the server (which warns the experimenter if it is not
// the session's display profile); the participant never sees such a warning.
// The instructions show a picture of each target (/target/N: cut from a clip by
// the server); practice trials are labelled as such; a clip starts only when the
// participant presses the space bar for it.
// After each block (or the session) the study's NASA-TLX, if it asks one, is
// filled in with the mouse (instruments.js) before the page goes on.
"use strict";
(() => {
  const READY_MS = 1000; // fixation before each clip starts
  // how long past two frames after a key press a stalled clip is waited for before
  // the frame is taken from the frames reported by then
  const PRESS_WAIT_MS = 500;
  const sid = new URLSearchParams(location.search).get("session");
  const video = document.getElementById("clip");
  const fixation = document.getElementById("fixation");
  const arrow = document.getElementById("arrow");
  const tracker = document.getElementById("tracker");
  const message = document.getElementById("message");
  const status = document.getElementById("status");
  const label = document.getElementById("label");
  const hint = document.getElementById("hint");
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  const phase = (p) => { document.body.dataset.phase = p; };

  const startedKey = `cosim.started.${sid}`;

  function show(html) {
    message.innerHTML = html;
    message.hidden = false;
    for (const img of message.querySelectorAll("img.target")) {
      img.onerror = () => { img.closest("figure").hidden = true; }; // no picture: no box
      // enlarged: its pixels kept sharp; made smaller: smoothed (not every n-th pixel)
      img.onload = () => img.classList.toggle("enlarged", img.naturalWidth <
        img.getBoundingClientRect().width * (window.devicePixelRatio || 1));
    }
  }
  function hide() { message.hidden = true; }
  const esc = (text) => String(text).replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);
  // each line a paragraph of its own
  const paragraphs = (lines) => lines.map((l) => `<p>${l}</p>`).join("");
  const plural = (n, one, many) => `${n} ${n === 1 ? one : many}`;

  // What the participant is told first, by protocol: one instruction a line.
  const INSTRUCTIONS = {
    disappear: ["Look at the red cross in the centre of the screen while each clip plays.",
                "Press the space bar as soon as the target disappears."],
    track: ["Each clip stands still. Press the space bar to start the red dot, and " +
            "follow the dot with your eyes.",
            "Press the space bar again as soon as the target disappears."],
    recognise: ["Follow the arrow while each clip plays.",
                "Press the space bar as soon as you recognise the target; then answer " +
                "whether you recognised it."],
  };

  // The pictures of `targets` (trials' {target, target_picture}, one per target),
  // each with its name; `small` for the reminder before a clip.
  function pictures(targets, small) {
    const seen = new Map();
    for (const t of targets) seen.set(t.target, t.target_picture);
    const figs = [...seen].map(([name, src]) =>
      `<figure><img class="target" src="${esc(src)}" alt="the target: ${esc(name)}">` +
      `<figcaption>${esc(name.replace(/_/g, " "))}</figcaption></figure>`);
    return `<div class="targets${small ? " small" : ""}">${figs.join("")}</div>`;
  }

  // "Practice clip 1 of 2" or "Clip 3 of 12": the trial `t` among its kind.
  function title(s, t) {
    const same = s.trials.filter((x) => x.practice === t.practice);
    const k = same.filter((x) => x.index <= t.index).length;
    return `${t.practice ? "Practice clip" : "Clip"} ${k} of ${same.length}`;
  }

  // A screen before trial `t` (phase `p`): `heading` (the trial's title),
  // `lines`, its target's picture and `key`, the press it waits for.
  async function ask(p, s, t, lines, key = "Press the space bar for the next clip.",
                     heading = title(s, t)) {
    phase(p);
    show(`<p class="title">${heading}</p>${paragraphs(lines)}${pictures([t], true)}` +
         `<p class="key">${key}</p>`);
    await waitKey(["Space"]);
  }

  // "Practice" in a corner of the screen while practice trial `t` runs
  function practiceLabel(t) {
    label.textContent = "Practice";
    label.hidden = !t.practice;
  }

  // Marks `mark` (a trial and its kind) as started in this tab; whether this
  // tab had started that very trial before (a reload while it played), or
  // null if the browser keeps no sessionStorage. Kept over reloads, per tab.
  function started(mark) {
    try {
      const before = sessionStorage.getItem(startedKey);
      sessionStorage.setItem(startedKey, mark);
      return before === mark;
    } catch (e) { return null; }
  }

  // GET (body undefined) or POST JSON. Network errors and 5xx are retried until
  // they succeed (a response must never be lost); a 4xx is an error to show.
  async function api(path, body) {
    for (let attempt = 0; ; attempt++) {
      let r = null;
      try {
        r = await fetch(path, body === undefined ? { cache: "no-store" } : {
          method: "POST", headers: { "Content-Type": "application/json" },
          body: JSON.stringify(body),
        });
      } catch (e) { r = null; }
      if (r && r.ok) { status.textContent = ""; return r.json(); }
      if (r && r.status >= 400 && r.status < 500) {
        const j = await r.json().catch(() => ({}));
        throw new Error(j.error || r.statusText);
      }
      status.textContent = "connection lost; retrying\u2026";
      await sleep(Math.min(5000, 250 * 2 ** attempt));
    }
  }

  function waitKey(codes) {
    return new Promise((resolve) => {
      const h = (e) => {
        if (e.repeat || !codes.includes(e.code)) return;
        e.preventDefault();
        removeEventListener("keydown", h, true);
        resolve(e);
      };
      addEventListener("keydown", h, true);
    });
  }

  function load(trial) {
    return new Promise((resolve, reject) => {
      video.oncanplay = () => { video.oncanplay = video.onerror = null; resolve(); };
      video.onerror = () => { video.oncanplay = video.onerror = null;
        reject(new Error(`cannot load ${trial.video}`)); };
      video.src = trial.video;
      video.load();
    });
  }

  // The mediaTime of the frame on screen at `at` (ms, a key event's clock) among
  // `shown`, the frames reported in order ({mediaTime, t: when due on screen, n:
  // presentedFrames}): the last one due by then, or the first if none was yet
  // (the clip was on its way). A busy page is reported only the latest of the
  // frames presented since its last report (presentedFrames jumps): if the press
  // fell in such a gap, the frame is the one the media clock had reached then
  // (it runs at the clip's speed), among those not yet reported.
  function frameAt(shown, at, rateHz) {
    let i = 0;
    while (i + 1 < shown.length && shown[i + 1].t <= at) i++;
    const a = shown[i], b = shown[i + 1];
    if (a.t > at || !b || b.n - a.n <= 1) return a.mediaTime;
    const ka = Math.round(a.mediaTime * rateHz), kb = Math.round(b.mediaTime * rateHz);
    const k = Math.floor((a.mediaTime + (at - a.t) / 1000) * rateHz + 1e-6);
    return Math.min(Math.max(k, ka), kb - 1) / rateHz;
  }

  // Plays the loaded clip. Resolves at the first key in `codes` with the
  // mediaTime of the frame on screen at that press, or with mediaTime null at
  // its end. A frame is reported (requestVideoFrameCallback) after it went to
  // the compositor, and on a busy page a key event can be handled before the
  // report of a frame already on screen: the frame is chosen once a frame due
  // after the press is reported (the clip plays on until then: at most a frame
  // more), at its end, or PRESS_WAIT_MS after a later frame was due.
  function playClip(trial, codes) {
    return new Promise((resolve, reject) => {
      const shown = []; // recently reported frames: {mediaTime, t (due on screen, ms), n}
      const frameMs = 1000 / trial.rate_hz;
      let onset = null; // when media time 0 was (or would have been) on screen
      let press = null; // a key pressed, waiting for its frame: {code, at (ms)}
      let done = false;
      let handle = null;
      let timer = null;
      const decide = () => {
        if (done) return;
        // The onset is when the first frame is expected on screen, which is a
        // little after its callback ran: a press in between (as the clip starts)
        // is stamped before the onset. The clip was on its way: 0, never negative
        // (the server refuses a negative reaction time).
        finish({ code: press.code, mediaTime: frameAt(shown, press.at, trial.rate_hz),
                 rtMs: Math.max(0, press.at - onset) });
      };
      const onFrame = (now, meta) => {
        if (done) return;
        const t = meta.expectedDisplayTime ?? now;
        if (onset === null) onset = t - meta.mediaTime * 1000;
        shown.push({ mediaTime: meta.mediaTime, t, n: meta.presentedFrames });
        if (shown.length > 32) shown.shift();
        document.body.dataset.frame = String(Math.round(meta.mediaTime * trial.rate_hz));
        handle = video.requestVideoFrameCallback(onFrame);
        if (press !== null && t > press.at) decide(); // every frame up to the press is known
      };
      const onKey = (e) => {
        if (done || e.repeat || !codes.includes(e.code)) return;
        e.preventDefault();
        if (press !== null || !shown.length) return; // one press; none before a frame
        press = { code: e.code, at: e.timeStamp };
        if (shown[shown.length - 1].t > press.at) { decide(); return; }
        timer = setTimeout(decide, Math.max(0, press.at + 2 * frameMs - performance.now()) +
                                   PRESS_WAIT_MS);
      };
      // at the clip's end, a press waiting for its frame is decided at the next
      // animation frame (a report still due runs before its callbacks)
      const onEnded = () => {
        if (press === null) finish({ code: null, mediaTime: null, rtMs: null });
        else requestAnimationFrame(decide);
      };
      const onError = () => { cleanup(); reject(new Error(`cannot play ${trial.video}`)); };
      function cleanup() {
        done = true;
        clearTimeout(timer);
        removeEventListener("keydown", onKey, true);
        video.removeEventListener("ended", onEnded);
        video.removeEventListener("error", onError);
        if (handle !== null) video.cancelVideoFrameCallback(handle);
        video.pause();
        video.classList.remove("playing");
      }
      function finish(r) { cleanup(); resolve(r); }
      addEventListener("keydown", onKey, true);
      video.addEventListener("ended", onEnded);
      video.addEventListener("error", onError);
      handle = video.requestVideoFrameCallback(onFrame);
      video.classList.add("playing");
      phase("playing");
      video.play().catch(onError);
    });
  }

  // A "track" trial: the clip still at its frame; per direction, a key starts a
  // dot that leaves the target at the study's angular speed, the eyes on it; a
  // key when the target is gone posts the time since that start (the server
  // works out where the dot was). Sub-trials already stored are skipped.
  async function trackTrial(session, t, display, post) {
    hide();
    practiceLabel(t);
    await new Promise((resolve) => {
      video.onseeked = () => { video.onseeked = null; resolve(); };
      video.currentTime = t.still_time_s;
    });
    video.classList.add("still");
    const dpr = window.devicePixelRatio || 1;
    const mmX = display.screen_width_mm / display.screen_width_px; // mm a device pixel
    const mmY = display.screen_height_mm / display.screen_height_px;
    const W = innerWidth * dpr, H = innerHeight * dpr; // the page, device px
    const s = Math.min(W / t.width_px, H / t.height_px);
    const [cx, cy] = t.still_center_px || [(t.width_px - 1) / 2, (t.height_px - 1) / 2];
    const x0 = W / 2 + (cx - (t.width_px - 1) / 2) * s; // the target, device px
    const y0 = H / 2 + (cy - (t.height_px - 1) / 2) * s;
    const dirs = { right: [1, 0], left: [-1, 0], up: [0, -1], down: [0, 1] };
    try {
      for (const d of t.directions) {
        const kind = `track-${d}`;
        if (t.done.includes(kind)) continue;
        phase("track-start");
        document.body.dataset.direction = d;
        tracker.style.left = `${x0 / dpr}px`;
        tracker.style.top = `${y0 / dpr}px`;
        tracker.hidden = false;
        hint.textContent = `${title(session, t)}: press the space bar to start the dot.`;
        hint.hidden = false;
        const go = await waitKey(["Space"]);
        hint.hidden = true;
        const start = go.timeStamp;
        const reshown = started(`${t.index}:${kind}`); // the dot leaves: the sub-trial runs
        phase("tracking");
        let raf = null;
        const move = (now) => {
          const a = Math.min(t.arrow_speed_deg_s * (now - start) / 1000, 89) * Math.PI / 180;
          const r = display.viewing_distance_mm * Math.tan(Math.max(a, 0)); // mm
          tracker.style.left = `${(x0 + dirs[d][0] * r / mmX) / dpr}px`;
          tracker.style.top = `${(y0 + dirs[d][1] * r / mmY) / dpr}px`;
          raf = requestAnimationFrame(move);
        };
        raf = requestAnimationFrame(move);
        const e = await waitKey(["Space"]);
        cancelAnimationFrame(raf);
        tracker.hidden = true;
        phase("saving");
        // both times are key events' of one clock, in order: clamped only so that
        // a clock quirk can never send a negative time
        await post({ trial_index: t.index, kind, key: "space", reshown,
                     reaction_time_ms: Math.max(0, e.timeStamp - start), ...windowPx() });
      }
    } finally {
      tracker.hidden = hint.hidden = label.hidden = true;
      video.classList.remove("still");
      delete document.body.dataset.direction;
    }
  }

  async function runTrial(s, t) {
    document.body.dataset.trial = String(t.index);
    delete document.body.dataset.frame;
    await load(t);
    if (s.protocol === "recognise") {
      await ask("start", s, t, ["Follow the arrow; press the space bar again as soon as you " +
                                "recognise the target."], "Press the space bar to start.");
      hide();
      practiceLabel(t);
      arrow.hidden = false;
      const reshown = started(`${t.index}:recognise`);
      const r = await playClip(t, ["Space"]);
      arrow.hidden = label.hidden = true;
      phase("answer");
      show(paragraphs(["Did you recognise the target?", "<b>Y</b> yes &nbsp; <b>N</b> no"]));
      const e = await waitKey(["KeyY", "KeyN"]);
      return { trial_index: t.index, kind: "recognise", key: e.code === "KeyY" ? "y" : "n",
               recognised: e.code === "KeyY", media_time_s: r.mediaTime,
               reaction_time_ms: r.rtMs, reshown, ...windowPx() };
    }
    phase("fixation");
    hide();
    practiceLabel(t);
    fixation.hidden = false;
    await sleep(READY_MS);
    const reshown = started(`${t.index}:disappear`);
    const r = await playClip(t, ["Space"]);
    fixation.hidden = label.hidden = true;
    return { trial_index: t.index, kind: "disappear", key: r.code ? "space" : "none",
             media_time_s: r.mediaTime, reaction_time_ms: r.rtMs, recognised: null, reshown,
             ...windowPx() };
  }

  // the page's size in device pixels as the clip was drawn: the server measures
  // with it (the video fits this, not the profile's screen, if they differ)
  function windowPx() {
    const dpr = window.devicePixelRatio || 1;
    return { window_width_px: Math.round(innerWidth * dpr),
             window_height_px: Math.round(innerHeight * dpr) };
  }

  // Tells the server the page's size (for the experimenter's page), now and
  // after each resize settles; a lost report is not worth a retry or a message.
  function reportWindow(base) {
    const send = () => fetch(`${base}/window`, {
      method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify(windowPx()),
    }).catch(() => {});
    let timer = null;
    addEventListener("resize", () => { clearTimeout(timer); timer = setTimeout(send, 250); });
    return send();
  }

  async function main() {
    if (!sid) { show("<p>No session: open this page from the experimenter page.</p>"); return; }
    if (!("requestVideoFrameCallback" in HTMLVideoElement.prototype)) {
      show("<p>This browser cannot time video frames (no requestVideoFrameCallback).<br>" +
           "Use a current Chromium, Chrome, Edge or Safari.</p>");
      return;
    }
    let s = await api(`/api/sessions/${encodeURIComponent(sid)}`);
    const base = `/api/sessions/${encodeURIComponent(s.id)}`;
    reportWindow(base);
    phase("begin");
    show(paragraphs(INSTRUCTIONS[s.protocol] || []) +
         `<p>${s.trials.some((t) => t.target !== s.trials[0].target) ? "The targets look"
                                                                      : "The target looks"} ` +
         "like this, in the middle of the picture:</p>" +
         pictures(s.trials, false) + '<p class="key">Press the space bar to begin.</p>');
    await waitKey(["Space"]);
    if (document.documentElement.requestFullscreen) {
      document.documentElement.requestFullscreen().catch(() => {});
    }
    let last = null; // the previous trial run in this page
    let breakShown = null;
    let asked = true; // the participant has just pressed for what comes next
    for (;;) {
      s = await api(base);
      // a block's NASA-TLX, when its trials are done (before the next block or the end)
      const due = await api(`${base}/instrument`);
      if (due.instrument === "tlx") {
        phase("tlx");
        show("");
        const body = await CosimInstruments.tlx(message, due);
        phase("saving");
        show("<p>\u2026</p>");
        await api(`${base}/instruments`, body);
        asked = false;
        continue;
      }
      if (s.next_trial === null) {
        phase("finished");
        show("<p>Finished. Thank you!</p>");
        return;
      }
      if (s.state !== "running") {
        phase("waiting");
        show(s.state === "paused" ? "<p>Paused by the experimenter.</p>"
                                  : "<p>Waiting for the experimenter to start.</p>");
        asked = false;
        await sleep(500);
        continue;
      }
      const t = s.trials[s.next_trial];
      if (t.break_before && breakShown !== t.index) {
        breakShown = t.index;
        await ask("break", s, t, [`Next: ${title(s, t).toLowerCase()}.`],
                  "Press the space bar when you are ready for it.", "Break");
        asked = true;
        continue;
      }
      if (t.practice && last === null) {
        const n = s.trials.filter((x) => x.practice).length;
        await ask("practice", s, t, [`First, ${plural(n, "practice clip", "practice clips")} ` +
                                     `to get used to the task: ${n === 1 ? "it does" : "they do"}` +
                                     " not count."],
                  "Press the space bar to start.");
      } else if (!t.practice && last !== null && last.practice) {
        await ask("practice-over", s, t, ["Practice over: the experiment starts now."],
                  "Press the space bar for the first clip.");
      } else if (!asked && s.protocol === "disappear") {
        // (recognise asks before each clip, track before each dot, on their own)
        await ask("next", s, t, []);
      }
      asked = false;
      last = t;
      if (s.protocol === "track") {
        await load(t);
        document.body.dataset.trial = String(t.index);
        await trackTrial(s, t, s.display, (b) => api(`${base}/responses`, b));
        continue;
      }
      const body = await runTrial(s, t);
      phase("saving");
      show("<p>\u2026</p>");
      await api(`${base}/responses`, body);
    }
  }

  main().catch((e) => {
    phase("error");
    show(`<p class="error">${String(e.message || e).replace(/[<&]/g, "")}</p>`);
  });
})();
