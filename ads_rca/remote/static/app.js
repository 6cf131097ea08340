// ads-rca dashboard page: runs from the server's event stream (/events), drawn with DOM
// calls only. Every string from the wire (run names, actor ids, metric names, reasons...)
// comes from a log and is inserted as text (textContent / createTextNode), never as markup.
"use strict";

(function () {
  const SVG = "http://www.w3.org/2000/svg";
  const MODULES = ["perception", "prediction", "planning", "controller"];
  const TIMELINE_LIMIT = 5000;
  const TIMELINE_GAP_MS = 500;

  const runs = new Map(); // run name -> {digest, verdict, timeline: {points, margin, last, busy, at}}
  let selected = null;
  let serverSkew = 0; // server time - local time (s)
  let header = null;

  const $ = (id) => document.getElementById(id);

  // An element with text attributes set one by one and children appended: strings become
  // text nodes, so nothing from the wire is ever parsed as HTML.
  function el(tag, attrs, ...children) {
    const node = document.createElement(tag);
    for (const [name, value] of Object.entries(attrs || {})) {
      node.setAttribute(name, String(value));
    }
    for (const child of children) {
      node.append(child instanceof Node ? child : document.createTextNode(String(child)));
    }
    return node;
  }

  function svg(tag, attrs) {
    const node = document.createElementNS(SVG, tag);
    for (const [name, value] of Object.entries(attrs || {})) {
      node.setAttribute(name, String(value));
    }
    return node;
  }

  function pointerToken(key) {
    return String(key).replace(/~/g, "~0").replace(/\//g, "~1");
  }

  // A value as text: numbers rounded, null as the strict-JSON annotation says (nan, inf)
  // when it points there, objects as compact JSON.
  function fmt(value, nonfinite, pointer) {
    if (value === null || value === undefined) {
      if (nonfinite && pointer && Object.prototype.hasOwnProperty.call(nonfinite, pointer)) {
        return String(nonfinite[pointer]);
      }
      return "—";
    }
    if (typeof value === "number") {
      if (Number.isInteger(value)) return String(value);
      if (Math.abs(value) >= 1e4) return value.toFixed(1);
      return String(Number(value.toPrecision(4)));
    }
    if (typeof value === "string") return value;
    if (typeof value === "boolean") return value ? "yes" : "no";
    const text = JSON.stringify(value);
    return text.length > 300 ? text.slice(0, 300) + "…" : text;
  }

  // A run is its prefix and the run id its documents name (two graphs may share a
  // prefix): the label shows both.
  function runLabel(digest) {
    const prefix = digest.run === "" ? "(no prefix)" : String(digest.run);
    return digest.run_id ? prefix + " · run " + digest.run_id : prefix;
  }

  function runSegment(digest) {
    return encodeURIComponent(digest.id);
  }

  function factRows(tbody, rows) {
    tbody.replaceChildren(...rows.map(([name, value]) => el("tr", {}, el("th", {}, name), el("td", {}, value))));
  }

  // --- the stream -------------------------------------------------------------------------

  function onRuns(event) {
    let message;
    try {
      message = JSON.parse(event.data);
    } catch (error) {
      return;
    }
    header = message;
    serverSkew = message.now - Date.now() / 1000;
    const names = new Set(message.names);
    for (const name of Array.from(runs.keys())) {
      if (!names.has(name)) runs.delete(name);
    }
    for (const entry of message.runs) {
      const state = runs.get(entry.id) || { digest: null, verdict: null, timeline: newTimeline() };
      if (Object.prototype.hasOwnProperty.call(entry, "verdict")) state.verdict = entry.verdict;
      state.digest = entry;
      runs.set(entry.id, state);
    }
    if (selected === null || !runs.has(selected)) {
      selected = runs.size ? Array.from(runs.keys()).sort()[0] : null;
    }
    render();
  }

  // The stream to the dashboard server, and through it each Zenoh link's state: "live"
  // (green) only while the stream is open and every link reaches its peer. A stream the
  // browser gave up on (a refusal, or no event for STALE_MS) is opened afresh, so the page
  // recovers from outages of any length.
  const STALE_MS = 40000;
  const REOPEN_MS = 2000;
  let source = null;
  let streamOpen = false;
  let lastEvent = 0;

  function connect() {
    source = new EventSource("/events");
    lastEvent = Date.now();
    source.addEventListener("runs", (event) => {
      lastEvent = Date.now();
      onRuns(event);
    });
    source.addEventListener("ping", () => {
      lastEvent = Date.now();
    });
    source.addEventListener("open", () => {
      streamOpen = true;
      lastEvent = Date.now();
      renderConnection();
    });
    source.addEventListener("error", () => {
      streamOpen = false;
      renderConnection();
      if (source.readyState === EventSource.CLOSED) reopen();
    });
  }

  function reopen() {
    if (source) source.close();
    source = null;
    setTimeout(() => {
      if (source === null) connect();
    }, REOPEN_MS);
  }

  function watchStream() {
    if (source !== null && Date.now() - lastEvent > STALE_MS) {
      streamOpen = false;
      renderConnection();
      reopen();
    }
  }

  function linkText(link) {
    let text = String(link.endpoint) + " " + String(link.state);
    if (link.state !== "connected") {
      if (typeof link.since === "number" && link.since > 0) {
        text += " since " + new Date(link.since * 1000).toLocaleTimeString();
      }
      text += link.state === "not connected" ? " (reconnecting)" : " (retrying)";
      if (link.error) text += ": " + String(link.error);
    }
    return text;
  }

  function renderConnection() {
    const node = $("connection");
    const links = header && Array.isArray(header.zenoh) ? header.zenoh : [];
    const up = links.filter((link) => link && link.state === "connected").length;
    let kind;
    let text;
    if (!streamOpen) {
      kind = "down";
      text = "dashboard server not reached: retrying";
    } else if (links.length && up === links.length) {
      kind = "live";
      text = "live";
    } else if (up > 0) {
      kind = "partial";
      text = "live · zenoh " + up + " of " + links.length + " connected";
    } else {
      kind = "down";
      text = "zenoh not connected: no results can arrive";
    }
    node.className = "connection " + kind;
    node.textContent = text;
    $("zenoh").replaceChildren(
      ...links.map((link) => el("span", { class: "link link-" + String(link.state).replace(/ /g, "-") }, linkText(link)))
    );
    $("zenoh").hidden = !streamOpen;
  }

  // --- drawing ----------------------------------------------------------------------------

  function render() {
    renderConnection();
    $("problems").textContent = header ? String(header.problems) : "0";
    const notes = [];
    if (header && header.last_problem) notes.push("last wire problem: " + header.last_problem);
    if (header && header.dropped) notes.push(header.dropped + " samples dropped before decoding (too big, or the queue full)");
    if (header && header.catch_up_error) notes.push("catch-up failed: " + header.catch_up_error);
    $("problem-line").textContent = notes.join(" · ");
    renderRunList();
    const state = selected === null ? null : runs.get(selected);
    $("run-view").hidden = !state;
    if (state) renderRun(state);
  }

  function renderRunList() {
    const select = $("run-select");
    const names = Array.from(runs.keys()).sort();
    $("no-runs").hidden = names.length > 0;
    select.replaceChildren(
      ...names.map((name) => {
        const option = el("option", {}, runLabel(runs.get(name).digest));
        option.value = name;
        return option;
      })
    );
    if (selected !== null) select.value = selected;
    const rows = names.map((name) => {
      const state = runs.get(name);
      const d = state.digest;
      const row = el(
        "tr",
        {},
        el("td", {}, runLabel(d)),
        el("td", {}, stateText(d)),
        el("td", {}, fmt(d.last_frame)),
        el("td", {}, fmt(d.rate)),
        el("td", {}, String(d.near_misses.length)),
        el("td", {}, state.verdict ? verdictLabel(state.verdict) : "—")
      );
      row.dataset.run = name;
      if (name === selected) row.className = "selected";
      row.addEventListener("click", () => select_(name));
      return row;
    });
    $("runs").tBodies[0].replaceChildren(...rows);
  }

  function stateText(digest) {
    if (digest.status && typeof digest.status.state === "string") return digest.status.state;
    return digest.has_verdict ? "verdict" : digest.last_index >= 0 ? "running" : "waiting";
  }

  function select_(name) {
    if (name === selected) return;
    selected = name;
    render();
  }

  // How a verdict reads, as the server decided it (docs/verdicts.md): an inconclusive
  // verdict is never "no fault found", and one that does not say is not conclusive.
  function outcomeOf(v) {
    const o = v && v.outcome && typeof v.outcome === "object" ? v.outcome : {};
    return {
      kind: typeof o.kind === "string" ? o.kind : "inconclusive",
      conclusive: o.conclusive === true,
      stated: o.stated === true,
      reasons: Array.isArray(o.reasons) ? o.reasons : [],
      collision: typeof o.collision === "string" ? o.collision : "unknown",
      text: typeof o.text === "string" ? o.text : "inconclusive",
    };
  }

  function verdictLabel(v) {
    const o = outcomeOf(v);
    if (o.kind === "root cause") return fmt(v.primary_root_cause) + (o.conclusive ? "" : "; inconclusive");
    return o.kind === "no fault found" && o.conclusive ? "no fault found" : "inconclusive";
  }

  // A module's state and why, as the server decided it (view.module_state).
  function moduleStatus(m) {
    const state = typeof m.state === "string" ? m.state : "waiting";
    const detail = typeof m.detail === "string" ? m.detail : "";
    // The detail is the status in words ("not judged (no detections_2d)"); a skip's is
    // only its reason. A provisional result (the collision partner not known yet) says so.
    const text = state === "skipped" ? "skipped: " + detail : detail || state;
    return { state: state, text: m.provisional === true ? text + " (provisional)" : text };
  }

  function renderRun(state) {
    const d = state.digest;
    $("run-name").textContent = runLabel(d);
    $("frame").textContent = fmt(d.last_frame);
    $("index").textContent = String(d.last_index);
    $("rate").textContent = fmt(d.rate);
    $("state").textContent = stateText(d);
    const age = Date.now() / 1000 + serverSkew - d.updated;
    $("age").textContent = d.updated ? Math.max(0, age).toFixed(1) + " s ago" : "–";

    const rows = MODULES.map((module) => {
      const m = d.modules[module] || { judged: 0, failed_frames: 0, latest: null, nonfinite: {} };
      const status = moduleStatus(m);
      // The key metrics in the cell (view.key_metric_names), every one in its tooltip.
      const metrics = [];
      const all = [];
      const shown = Array.isArray(m.key_metrics) ? m.key_metrics : [];
      if (m.latest && m.latest.metrics && typeof m.latest.metrics === "object") {
        for (const [key, value] of Object.entries(m.latest.metrics)) {
          const text = key + " " + fmt(value, m.nonfinite, "/metrics/" + pointerToken(key));
          all.push(text);
          if (shown.includes(key)) metrics.push(text);
        }
      }
      const row = el(
        "tr",
        {},
        el("td", {}, module),
        el("td", { class: "status status-" + status.state.replace(/[^a-z]+/g, "-") }, status.text),
        el("td", { class: "judged" }, String(m.judged)),
        el("td", { class: "failed" }, String(m.failed_frames)),
        el("td", {}, m.latest ? fmt(m.latest.frame) : "—"),
        el("td", { class: "metrics", title: all.join("\n") }, metrics.join(" · "))
      );
      row.dataset.module = module;
      return row;
    });
    $("modules").tBodies[0].replaceChildren(...rows);

    $("near-misses").replaceChildren(
      ...d.near_misses
        .slice(-10)
        .reverse()
        .map((n) =>
          el("li", {}, "frame " + fmt(n.frame) + ": clearance " + fmt(n.clearance) + " m < margin " + fmt(n.margin) + " m")
        )
    );
    if (!d.near_misses.length) $("near-misses").replaceChildren(el("li", {}, "none"));

    const status = d.status && typeof d.status === "object" ? d.status : {};
    factRows(
      $("status").tBodies[0],
      Object.entries(status).map(([key, value]) => [
        key,
        key === "time" && typeof value === "number" ? new Date(value * 1000).toLocaleTimeString() : fmt(value),
      ])
    );

    renderVerdict(state);
    updateTimeline(state);
    drawTimeline(state);
  }

  function renderVerdict(state) {
    const v = state.verdict;
    $("verdict-none").hidden = !!v;
    $("verdict").hidden = !v;
    if (!v) return;
    const nf = v.nonfinite || {};
    const o = outcomeOf(v);
    const outcome = $("verdict-outcome");
    outcome.textContent = o.text;
    outcome.className = "outcome outcome-" + (o.conclusive || o.kind === "root cause" ? o.kind : "inconclusive").replace(/[^a-z]+/g, "-");
    $("verdict-conclusive").textContent = o.conclusive ? "yes" : o.stated ? "no" : "not stated: read as no";
    $("verdict-reasons").replaceChildren(...o.reasons.map((reason) => el("li", {}, fmt(reason))));
    // No primary is an answer too: none, as conclusive or not as the verdict is.
    const primary = v.primary_root_cause;
    $("verdict-primary").textContent =
      primary === null || primary === undefined
        ? o.conclusive ? "none (no fault found)" : "none found (inconclusive)"
        : fmt(primary);
    $("download").setAttribute("href", "/api/runs/" + runSegment(state.digest) + "/verdict.json");
    // A document let go to bound the dashboard's memory (docs/dashboard.md) cannot be had.
    $("download").hidden = v.downloadable === false;
    $("verdict-semantics").textContent = fmt(v.semantics);
    const list = (value) => (Array.isArray(value) ? (value.length ? value.map((x) => fmt(x)).join(", ") : "none") : fmt(value));
    const judged = v.modules_judged && typeof v.modules_judged === "object" ? v.modules_judged : {};
    factRows($("verdict-facts").tBodies[0], [
      ["contributing", list(v.contributing)],
      ["root causes", list(v.root_causes)],
      ["attribution basis", fmt(v.attribution_basis)],
      ["reason", fmt(v.reason)],
      ["conclusive", o.conclusive ? "yes" : "no"],
      ["collision", o.collision],
      ["collision frame", fmt(v.collision_frame)],
      ["partner", fmt(v.partner_id)],
      ["ego", fmt(v.ego_id)],
      ["semantics mode", fmt(v.semantics)],
      ["effect window", fmt(v.window_frames) + " frames"],
      ["modules judged", Object.entries(judged).map(([k, x]) => k + ": " + fmt(x)).join(", ")],
      ["frames", fmt(v.frames_count)],
      ["input problems", fmt(v.input_problems)],
      ["source", fmt(v.source)],
    ]);
    const thresholds = v.thresholds && typeof v.thresholds === "object" ? v.thresholds : {};
    factRows(
      $("verdict-thresholds").tBodies[0],
      Object.entries(thresholds).map(([k, x]) => [k, fmt(x, nf, "/thresholds/" + pointerToken(k))])
    );
    const evidence = v.evidence && typeof v.evidence === "object" ? v.evidence : {};
    $("evidence").replaceChildren(
      ...Object.entries(evidence).map(([module, entry]) => {
        const base = "/evidence/" + pointerToken(module) + "/";
        const rows = [];
        if (entry && typeof entry === "object" && !Array.isArray(entry)) {
          for (const [key, value] of Object.entries(entry)) {
            if (key === "metrics" && value && typeof value === "object" && !Array.isArray(value)) {
              for (const [mk, mv] of Object.entries(value)) {
                rows.push(["metrics." + mk, fmt(mv, nf, base + "metrics/" + pointerToken(mk))]);
              }
            } else {
              rows.push([key, fmt(value, nf, base + pointerToken(key))]);
            }
          }
        } else {
          rows.push(["", fmt(entry)]);
        }
        const table = el("table", { class: "facts" }, el("tbody"));
        factRows(table.tBodies[0], rows);
        const box = el("div", { class: "evidence-module" }, el("h4", {}, module), table);
        box.dataset.module = module;
        return box;
      })
    );
    if (!Object.keys(evidence).length) $("evidence").replaceChildren(el("p", { class: "note" }, "none"));
  }

  // --- the clearance timeline ---------------------------------------------------------------

  function newTimeline() {
    return { points: [], margin: null, last: -1, busy: false, scheduled: false, at: 0 };
  }

  function updateTimeline(state) {
    const t = state.timeline;
    const d = state.digest;
    if (t.busy || t.scheduled || d.timeline_last === null || d.timeline_last <= t.last) return;
    const wait = t.at + TIMELINE_GAP_MS - Date.now();
    if (wait > 0) {
      t.scheduled = true;
      setTimeout(() => {
        t.scheduled = false;
        if (runs.get(d.id) === state) updateTimeline(state);
      }, wait);
      return;
    }
    t.busy = true;
    t.at = Date.now();
    fetch("/api/runs/" + runSegment(d) + "/timeline?after=" + t.last)
      .then((r) => (r.ok ? r.json() : null))
      .then((doc) => {
        t.busy = false;
        if (!doc || !Array.isArray(doc.points)) return;
        for (const [index, clearance] of doc.points) {
          if (typeof index === "number" && typeof clearance === "number" && index > t.last) {
            t.points.push([index, clearance]);
            t.last = index;
          }
        }
        if (t.points.length > TIMELINE_LIMIT) t.points.splice(0, t.points.length - TIMELINE_LIMIT);
        t.margin = typeof doc.margin === "number" ? doc.margin : null;
        if (runs.get(d.id) === state && selected === d.id) {
          drawTimeline(state);
          updateTimeline(state);
        }
      })
      .catch(() => {
        t.busy = false;
      });
  }

  function drawTimeline(state) {
    const t = state.timeline;
    const box = $("timeline-box");
    const W = 640, H = 220, L = 48, R = 12, T = 10, B = 28;
    const root = svg("svg", { viewBox: "0 0 " + W + " " + H, role: "img", "aria-label": "clearance timeline" });
    if (!t.points.length) {
      box.replaceChildren(root);
      $("timeline-note").textContent = "No clearance reported yet.";
      return;
    }
    const xs = t.points.map((p) => p[0]);
    const ys = t.points.map((p) => p[1]);
    if (t.margin !== null) ys.push(t.margin);
    const x0 = Math.min(...xs), x1 = Math.max(...xs, x0 + 1);
    let y0 = Math.min(0, ...ys), y1 = Math.max(...ys);
    if (y1 <= y0) y1 = y0 + 1;
    const sx = (x) => L + ((x - x0) / (x1 - x0)) * (W - L - R);
    const sy = (y) => H - B - ((y - y0) / (y1 - y0)) * (H - T - B);
    root.append(svg("line", { class: "axis", x1: L, y1: H - B, x2: W - R, y2: H - B }));
    root.append(svg("line", { class: "axis", x1: L, y1: T, x2: L, y2: H - B }));
    const label = (x, y, text, anchor) => {
      const node = svg("text", { x: x, y: y, "text-anchor": anchor });
      node.textContent = text;
      root.append(node);
    };
    label(L - 4, sy(y1) + 4, fmt(y1), "end");
    label(L - 4, sy(y0) + 4, fmt(y0), "end");
    label(L, H - 8, String(x0), "start");
    label(W - R, H - 8, String(x1), "end");
    if (t.margin !== null) {
      root.append(svg("line", { class: "margin", x1: L, y1: sy(t.margin), x2: W - R, y2: sy(t.margin) }));
      label(W - R, sy(t.margin) - 3, "margin " + fmt(t.margin) + " m", "end");
    }
    const path = t.points.map((p) => sx(p[0]).toFixed(1) + "," + sy(p[1]).toFixed(1)).join(" ");
    root.append(svg("polyline", { class: "series", points: path }));
    if (t.margin !== null) {
      for (const [x, y] of t.points) {
        if (y < t.margin) root.append(svg("circle", { class: "near", cx: sx(x).toFixed(1), cy: sy(y).toFixed(1), r: 2.5 }));
      }
    }
    box.replaceChildren(root);
    const last = t.points[t.points.length - 1];
    $("timeline-note").textContent =
      t.points.length + " points; latest " + fmt(last[1]) + " m at index " + last[0] + (t.margin !== null ? "; dots: below the safety margin" : "");
  }

  document.addEventListener("DOMContentLoaded", () => {
    $("run-select").addEventListener("change", (event) => select_(event.target.value));
    connect();
    setInterval(watchStream, 5000);
  });
})();
