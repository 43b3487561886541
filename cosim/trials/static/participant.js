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
"use strict";
(() => {
  const READY_MS = 1000; // fixation before each clip starts
  const sid = new URLSearchParams(location.search).get("session");
  const video = document.getElementById("clip");
  const fixation = document.getElementById("fixation");
  const arrow = document.getElementById("arrow");
  const tracker = document.getElementById("tracker");
  const message = document.getElementById("message");
  const status = document.getElementById("status");
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  const phase = (p) => { document.body.dataset.phase = p; };

  const startedKey = `cosim.started.${sid}`;

  function show(html) { message.innerHTML = html; message.hidden = false; }
  function hide() { message.hidden = true; }

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

  // Plays the loaded clip. Resolves at the first key in `codes` with the
  // mediaTime of the frame on screen then, or with mediaTime null at its end.
  function playClip(trial, codes) {
    return new Promise((resolve, reject) => {
      const shown = []; // recently presented frames: {mediaTime, t (display time, ms)}
      let onset = null; // when media time 0 was (or would have been) on screen
      let done = false;
      let handle = null;
      const onFrame = (now, meta) => {
        if (done) return;
        const t = meta.expectedDisplayTime ?? now;
        if (onset === null) onset = t - meta.mediaTime * 1000;
        shown.push({ mediaTime: meta.mediaTime, t });
        if (shown.length > 32) shown.shift();
        document.body.dataset.frame = String(Math.round(meta.mediaTime * trial.rate_hz));
        handle = video.requestVideoFrameCallback(onFrame);
      };
      const onKey = (e) => {
        if (done || e.repeat || !codes.includes(e.code)) return;
        e.preventDefault();
        if (!shown.length) return; // no frame on screen yet
        let f = shown[0]; // the last frame whose display time is not after the key press
        for (const s of shown) if (s.t <= e.timeStamp) f = s;
        // The onset is when the first frame is expected on screen, which is a
        // little after its callback ran: a press in between (as the clip starts)
        // is stamped before the onset. The clip was on its way: 0, never negative
        // (the server refuses a negative reaction time).
        finish({ code: e.code, mediaTime: f.mediaTime, rtMs: Math.max(0, e.timeStamp - onset) });
      };
      const onEnded = () => finish({ code: null, mediaTime: null, rtMs: null });
      const onError = () => { cleanup(); reject(new Error(`cannot play ${trial.video}`)); };
      function cleanup() {
        done = true;
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
  async function trackTrial(t, display, post) {
    hide();
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
        const go = await waitKey(["Space"]);
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
      tracker.hidden = true;
      video.classList.remove("still");
      delete document.body.dataset.direction;
    }
  }

  async function runTrial(t, protocol) {
    document.body.dataset.trial = String(t.index);
    delete document.body.dataset.frame;
    await load(t);
    if (protocol === "recognise") {
      phase("start");
      show(`<p>${t.practice ? "Practice trial. " : ""}Follow the arrow.<br>` +
           "Press the space bar to start; press it again when you recognise the target.</p>");
      await waitKey(["Space"]);
      hide();
      arrow.hidden = false;
      const reshown = started(`${t.index}:recognise`);
      const r = await playClip(t, ["Space"]);
      arrow.hidden = true;
      phase("answer");
      show("<p>Did you recognise the target?<br><b>Y</b> yes &nbsp; <b>N</b> no</p>");
      const e = await waitKey(["KeyY", "KeyN"]);
      return { trial_index: t.index, kind: "recognise", key: e.code === "KeyY" ? "y" : "n",
               recognised: e.code === "KeyY", media_time_s: r.mediaTime,
               reaction_time_ms: r.rtMs, reshown, ...windowPx() };
    }
    phase("fixation");
    hide();
    fixation.hidden = false;
    await sleep(READY_MS);
    const reshown = started(`${t.index}:disappear`);
    const r = await playClip(t, ["Space"]);
    fixation.hidden = true;
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
    const instruction = s.protocol === "disappear"
      ? "Look at the red cross in the centre. Press the space bar as soon as the target disappears."
      : s.protocol === "track"
        ? "Press the space bar to start the red dot, follow it with your eyes, and press " +
          "again as soon as the target disappears."
        : "Follow the arrow. Answer whether you recognised the target.";
    phase("begin");
    show(`<p>${instruction}</p><p>Press the space bar to begin.</p>`);
    await waitKey(["Space"]);
    if (document.documentElement.requestFullscreen) {
      document.documentElement.requestFullscreen().catch(() => {});
    }
    let last = null; // the previous trial run in this page
    let breakShown = null;
    for (;;) {
      s = await api(base);
      if (s.next_trial === null) {
        phase("finished");
        show("<p>Finished. Thank you!</p>");
        return;
      }
      if (s.state !== "running") {
        phase("waiting");
        show(s.state === "paused" ? "<p>Paused by the experimenter.</p>"
                                  : "<p>Waiting for the experimenter to start.</p>");
        await sleep(500);
        continue;
      }
      const t = s.trials[s.next_trial];
      if (t.break_before && breakShown !== t.index) {
        breakShown = t.index;
        phase("break");
        show("<p>Break. Press the space bar when you are ready to go on.</p>");
        await waitKey(["Space"]);
        continue;
      }
      if (t.practice && last === null) {
        phase("practice");
        show("<p>First some practice trials. Press the space bar.</p>");
        await waitKey(["Space"]);
      } else if (!t.practice && last !== null && last.practice) {
        phase("practice-over");
        show("<p>Practice over: the experiment starts now. Press the space bar.</p>");
        await waitKey(["Space"]);
      }
      last = t;
      if (s.protocol === "track") {
        await load(t);
        document.body.dataset.trial = String(t.index);
        await trackTrial(t, s.display, (b) => api(`${base}/responses`, b));
        continue;
      }
      const body = await runTrial(t, s.protocol);
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
