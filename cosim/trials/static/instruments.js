// The instruments' forms of the participant pages: NASA-TLX (the six scales,
// then the 15 pairwise comparisons if the study asks its weights) and a SAGAT
// probe's questions. Dependency-free. Each form is built into a container the
// page gives, with the mouse (the cursor shows while it is asked), and resolves
// with the answer in the form the server checks (POST .../instruments); the
// server keeps the first answer of a block or probe, so posting again is safe.
// Texts come from the server (GET .../instrument, .../sagat/N) and are set as
// text, never as HTML.
"use strict";
window.CosimInstruments = (() => {
  const el = (tag, cls, text) => {
    const e = document.createElement(tag);
    if (cls) e.className = cls;
    if (text !== undefined) e.textContent = text;
    return e;
  };

  // The six scales, each a row of marks 0..max in steps of `step` (the paper
  // form's 21), none marked at first; "Next" once all six are. Resolves with
  // {key: rating}.
  function scales(box, spec) {
    return new Promise((resolve) => {
      const form = el("div", "tlx");
      form.append(el("p", "title", "Rate the task you have just done on each scale."));
      const ratings = {};
      const next = el("button", "next", "Next");
      next.type = "button";
      next.disabled = true;
      for (const s of spec.scales) {
        const row = el("div", "scale");
        row.dataset.scale = s.key;
        const head = el("div", "head");
        head.append(el("b", null, s.title), el("span", null, ` ${s.question}`));
        const marks = el("div", "marks");
        for (let v = 0; v <= spec.max; v += spec.step) {
          const m = el("button", "tick");
          m.type = "button";
          m.dataset.value = String(v);
          m.title = String(v);
          m.addEventListener("click", () => {
            for (const o of marks.children) o.classList.toggle("chosen", o === m);
            ratings[s.key] = v;
            next.disabled = Object.keys(ratings).length < spec.scales.length;
          });
          marks.append(m);
        }
        const anchors = el("div", "anchors");
        anchors.append(el("span", null, s.low), el("span", null, s.high));
        row.append(head, marks, anchors);
        form.append(row);
      }
      next.addEventListener("click", () => resolve({ ...ratings }));
      form.append(next);
      box.replaceChildren(form);
    });
  }

  // The pairs one at a time: a click on the scale that contributed more to
  // the workload of the task. Resolves with {"a/b": chosen} in the scales' order.
  function pairs(box, spec) {
    const order = spec.scales.map((s) => s.key);
    const title = Object.fromEntries(spec.scales.map((s) => [s.key, s.title]));
    const chosen = {};
    return new Promise((resolve) => {
      let k = 0;
      const ask = () => {
        if (k === spec.pairs.length) { resolve(chosen); return; }
        const [a, b] = spec.pairs[k];
        const form = el("div", "tlx pairs");
        form.dataset.pair = String(k);
        form.append(el("p", "title", `Comparison ${k + 1} of ${spec.pairs.length}`),
                    el("p", null, "Which of the two contributed more to the workload of " +
                                  "the task?"));
        const row = el("div", "choices");
        for (const key of [a, b]) {
          const btn = el("button", "choice", title[key]);
          btn.type = "button";
          btn.dataset.scale = key;
          btn.addEventListener("click", () => {
            const [x, y] = order.indexOf(a) < order.indexOf(b) ? [a, b] : [b, a];
            chosen[`${x}/${y}`] = key;
            k += 1;
            ask();
          });
          row.append(btn);
        }
        form.append(row);
        box.replaceChildren(form);
      };
      ask();
    });
  }

  // The TLX of one block (`spec`: GET .../instrument): the body to post.
  async function tlx(box, spec) {
    document.body.classList.add("asking");
    try {
      const ratings = await scales(box, spec);
      const body = { instrument: "tlx", block: spec.block, ratings };
      if (spec.pairs) body.pairs = await pairs(box, spec);
      return body;
    } finally {
      document.body.classList.remove("asking");
    }
  }

  // A SAGAT probe (`probe`: GET .../sagat/N) during trial `trialIndex`:
  // `aircraft`, the ids a choice offers; `pickPoint()`, a promise of the
  // {north_m, east_m} the participant clicks on the page's map (the live
  // console's). The body to post.
  async function sagat(box, probe, trialIndex, aircraft, pickPoint) {
    document.body.classList.add("asking");
    const answers = {};
    try {
      for (const q of probe.questions) {
        const form = el("div", "tlx sagat");
        form.dataset.question = q.id;
        form.append(el("p", "title", q.text));
        box.replaceChildren(form);
        if (q.kind === "last_target") {
          answers[q.id] = await pickPoint(q);
        } else if (q.kind === "count") {
          const input = el("input");
          input.type = "number";
          input.min = "0";
          input.step = "1";
          const ok = el("button", "next", "Next");
          ok.type = "button";
          form.append(input, ok);
          input.focus();
          answers[q.id] = await new Promise((resolve) => ok.addEventListener("click", () => {
            const n = Number(input.value);
            if (input.value !== "" && Number.isInteger(n) && n >= 0) resolve(n);
          }));
        } else {
          const row = el("div", "choices");
          form.append(row);
          answers[q.id] = await new Promise((resolve) => {
            for (const id of aircraft) {
              const btn = el("button", "choice", id);
              btn.type = "button";
              btn.addEventListener("click", () => resolve(id));
              row.append(btn);
            }
          });
        }
      }
    } finally {
      document.body.classList.remove("asking");
    }
    return { instrument: "sagat", trial_index: trialIndex, probe: probe.probe, answers };
  }

  return { tlx, sagat };
})();
