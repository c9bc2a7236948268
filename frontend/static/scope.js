// Scope screen (frontend/templates/scope.html): pick channels, set period and trigger, start/stop a recording of the
// session, watch it live over /ws/sessions/{id}/scope, open, overlay, export and delete stored recordings.
// Names and units come from profiles: every text goes in as text (drivebench.el, textContent).
(() => {
  const root = document.getElementById("scope");
  if (!root) return;
  const drivebench = window.drivebench;
  const _ = drivebench.gettext;
  // what happens to the recording's changes when its page closes (the README's "What is restored when")
  const RECORDING_NOTE = _("The recording ends when your last page showing it closes (or at Stop): every TPDO, SYNC " +
                           "and NMT setting it changed is put back and read back.");
  const el = drivebench.el;
  const $ = (id) => document.getElementById(id);
  const session = root.dataset.session;
  const readOnly = root.dataset.readOnly === "1";  // a share link: watch and open, never start, stop or delete
  const maxChannels = Number(root.dataset.maxChannels);
  const api = drivebench.url(`/api/sessions/${encodeURIComponent(session)}/scope`);
  const form = $("scope-form");
  const COLORS = ["#0b5fa5", "#c0392b", "#1e8449", "#8e44ad", "#d35400", "#17a589", "#7f8c8d", "#b7950b"];
  const LIVE_KEPT = 4000;
  const EXPORTS = ["csv", "json"];
  const OVERLAY = _("overlay");
  const PER_S = _("samples/s");

  let chosen = [];          // [{node, ref, bit, name, unit}]
  let live = { id: null, channels: [], rows: [], markers: [] };  // the run the socket follows (its state's id)
  let shown = null;         // {title, channels, times, values, markers, overlay}
  let run = null;           // the last state message
  let cursors = [null, null];

  const fixed = (v, d) => (v == null || Number.isNaN(v) ? "–" : Number(v).toFixed(d));
  const SOURCES = { pdo: _("sampling by PDO"), "sdo-poll": _("SDO polling"), "coe-poll": _("CoE polling") };
  const sourceName = (s) => s.source_name || SOURCES[s.source] || s.source;

  // --- calls --------------------------------------------------------------------------------------------------
  async function call(method, url, body, slot) {
    try {
      const response = await fetch(url, { method, headers: body ? { "Content-Type": "application/json" } : {},
                                          body: body ? JSON.stringify(body) : undefined });
      if (!response.ok) {
        let problem = null;
        try { problem = await response.json(); } catch (e) { /* not JSON */ }
        $(slot).replaceChildren(drivebench.problemBox(problem, response.status));
        return null;
      }
      $(slot).replaceChildren();
      return response.status === 204 ? {} : response.json();
    } catch (e) {
      $(slot).replaceChildren(drivebench.errorBox(_("No answer from the DriveBench server."), _("Is it still running?")));
      return null;
    }
  }

  // --- channel picker -----------------------------------------------------------------------------------------
  let searchTimer = null;
  async function offer() {
    const node = $("channel-node").value;
    if (!node) return;
    const query = new URLSearchParams({ node, q: $("channel-search").value });
    const found = await call("GET", `${api}/channels?${query}`, null, "scope-result");
    if (!found) return;
    $("channel-offer").replaceChildren(...found.map((c) => el("li", {},
      el("button", { type: "button", className: "small secondary add-channel", title: _("Add this channel"),
                     onclick: () => add({ node: c.node, ref: c.ref, bit: null, name: c.name, unit: c.unit }) }, "+"),
      el("span", { className: "ref" }, c.ref), " ", el("span", {}, c.name),
      c.unit ? el("span", { className: "muted unit" }, `[${c.unit}]`) : "")));
  }
  function add(channel) {
    if (chosen.length >= maxChannels) {
      $("scope-result").replaceChildren(drivebench.errorBox(_("At most {most} channels", { most: maxChannels }), ""));
      return;
    }
    chosen.push(channel);
    drawChosen();
  }
  function swatch(i) {
    const box = el("span", { className: "swatch" });
    box.style.background = COLORS[i % COLORS.length];
    return box;
  }
  function drawChosen() {
    $("channel-list").replaceChildren(...chosen.map((c, i) => el("li", {},
      swatch(i),
      el("span", { className: "ref" }, `${c.node}: ${c.ref}`), " ", el("span", { className: "name" }, c.name),
      el("label", { className: "bit", title: _("Record one bit of the word (status-word bits)") }, _("bit"), " ",
         el("input", { type: "number", min: 0, max: 31, size: 2, value: c.bit ?? "",
                       onchange: (e) => { c.bit = e.target.value === "" ? null : Number(e.target.value); } })),
      el("button", { type: "button", className: "small secondary", title: _("Remove"), ariaLabel: _("Remove"),
                     onclick: () => { chosen.splice(i, 1); drawChosen(); } }, "×"))));
    const select = $("trigger-channel");
    const before = select.value;
    select.replaceChildren(...chosen.map((c, i) => el("option", { value: String(i) }, `${i + 1}: ${c.node}: ${c.ref}`)));
    if (before && Number(before) < chosen.length) select.value = before;
  }
  if (!readOnly) {
    $("channel-node").addEventListener("change", offer);
    $("channel-search").addEventListener("input", () => { clearTimeout(searchTimer); searchTimer = setTimeout(offer, 200); });

    function showTriggerFields() {
      const on = form.elements.on.value;
      for (const node of form.querySelectorAll(".for-level")) node.hidden = on !== "level";
      for (const node of form.querySelectorAll(".for-event")) node.hidden = on === "level";
    }
    form.elements.on.addEventListener("change", showTriggerFields);
    showTriggerFields();

    // --- start / stop -------------------------------------------------------------------------------------------
    function body(mode) {
      const f = form.elements;
      const length = Number(f.length_value.value);
      return {
        channels: chosen.map((c) => ({ node: c.node, ref: c.ref, bit: c.bit })),
        period_ms: Number(f.period_ms.value),
        ...(f.length_unit.value === "s" ? { length_s: length } : { length_samples: Math.round(length) }),
        name: f.name.value,
        trigger: { mode, on: f.on.value, channel: Number(f.channel.value || 0), edge: f.edge.value,
                   level: Number(f.level.value || 0), pre_percent: Number(f.pre_percent.value || 0),
                   node: f.trigger_node.value ? Number(f.trigger_node.value) : null },
      };
    }
    async function start(mode) {
      const sent = body(mode);
      // a source that moves something (SYNC, NMT start) asks first in the app's own dialog, as every moving action
      // does (drivebench.moving); polling never asks
      const send = async (confirmation) => {
        try {
          return await drivebench.requestJson("POST", `${api}/run`, confirmation ? { ...sent, ...confirmation } : sent);
        } catch (e) {
          return { status: 0, data: { detail: _("No answer from the DriveBench server.") } };
        }
      };
      const answer = await drivebench.moving(send, { what: _("Scope recording"), note: RECORDING_NOTE });
      if (!answer) return;  // the question was cancelled: nothing was sent
      if (answer.status >= 400 || answer.status === 0) {
        $("scope-result").replaceChildren(drivebench.problemBox(answer.data, answer.status));
        return;
      }
      $("scope-result").replaceChildren();
      shown = null;  // the live trace of the new run (its state message resets it, before or after this answer)
    }
    form.addEventListener("submit", (event) => { event.preventDefault(); start(form.elements.mode.value); });
    $("scope-single").addEventListener("click", () => start("single"));
    $("scope-stop").addEventListener("click", () => call("POST", `${api}/run/stop`, null, "scope-result"));
  }

  // --- plot ---------------------------------------------------------------------------------------------------
  const chartBox = $("scope-chart");
  let chart = null;
  let chartKey = "";

  function axesFor(channels) {
    // one scale per unit (channels without a unit, bits included, share "value"): a channel keeps its own unit
    const units = [...new Set(channels.map((c) => c.unit || ""))];
    return units.map((unit, i) => ({
      scale: unit || "value", label: unit || _("value"), labelSize: 16, size: 60, stroke: "#5d6b79",
      side: i % 2 ? 1 : 3, grid: { show: i === 0, stroke: "#eef1f4" },
    }));
  }

  function build(view) {
    const series = [{ label: _("t (s)"), value: (u, v) => fixed(v, 3) }];
    view.channels.forEach((c, i) => series.push({
      label: c.unit ? `${c.label} [${c.unit}]` : c.label, scale: c.unit || "value", stroke: COLORS[i % COLORS.length],
      width: 1.5, value: (u, v) => fixed(v, 2) }));
    (view.overlay ? view.overlay.channels : []).forEach((c, i) => series.push({
      label: `${OVERLAY}: ${c.label}`, scale: c.unit || "value", stroke: COLORS[i % COLORS.length], width: 1,
      dash: [6, 4], value: (u, v) => fixed(v, 2) }));
    const scales = { x: { time: false } };
    for (const c of [...view.channels, ...(view.overlay ? view.overlay.channels : [])]) scales[c.unit || "value"] = {};
    if (chart) chart.destroy();
    chart = new uPlot({
      width: Math.max(chartBox.clientWidth, 300), height: 320, scales,
      axes: [{ label: _("time (s)"), labelSize: 16, stroke: "#5d6b79", grid: { stroke: "#eef1f4" } },
             ...axesFor([...view.channels, ...(view.overlay ? view.overlay.channels : [])])],
      series, legend: { live: true },
      hooks: { draw: [drawMarks] },
    }, data(view), chartBox);
    chart.over.addEventListener("click", (event) => {
      const t = chart.posToVal(chart.cursor.left, "x");
      cursors[event.shiftKey ? 1 : 0] = t;
      chart.redraw(false);
      readCursors();
    });
    chartKey = key(view);
    window.scopeChart = chart;  // for tests and the console
  }
  new ResizeObserver(() => chart && chart.setSize({ width: Math.max(chartBox.clientWidth, 300), height: 320 }))
    .observe(chartBox);
  chartBox.addEventListener("dblclick", () => chart && draw(true));

  function key(view) {
    return JSON.stringify([view.channels.map((c) => [c.label, c.unit]),
                           view.overlay ? view.overlay.channels.map((c) => [c.label, c.unit]) : null]);
  }

  function data(view) {
    // the overlay goes on the same time axis: its values at the shown times (nearest earlier sample)
    const out = [view.times, ...view.values];
    if (view.overlay) {
      const o = view.overlay;
      for (const column of o.values) {
        let j = 0;
        out.push(view.times.map((t) => {
          while (j + 1 < o.times.length && o.times[j + 1] <= t) j += 1;
          return o.times.length && o.times[j] <= t + 1e-9 && t <= o.times[o.times.length - 1] + 1e-9 ? column[j] : null;
        }));
      }
    }
    return out;
  }

  function drawMarks(u) {
    const ctx = u.ctx;
    const view = current();
    const top = u.bbox.top;
    const height = u.bbox.height;
    ctx.save();
    for (const marker of view ? view.markers : []) {
      const x = u.valToPos(marker.t, "x", true);
      if (x < u.bbox.left || x > u.bbox.left + u.bbox.width) continue;
      ctx.strokeStyle = marker.kind === "emcy" ? "#c0392b" : marker.kind === "trigger" ? "#000" : "#8e44ad";
      ctx.setLineDash(marker.kind === "trigger" ? [] : [4, 3]);
      ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + height); ctx.stroke();
    }
    cursors.forEach((t, i) => {
      if (t == null) return;
      const x = u.valToPos(t, "x", true);
      ctx.strokeStyle = i ? "#d35400" : "#0b5fa5";
      ctx.setLineDash([2, 2]);
      ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + height); ctx.stroke();
      ctx.fillStyle = ctx.strokeStyle;
      ctx.fillText(i ? "B" : "A", x + 3, top + 12);
    });
    ctx.restore();
  }

  function valueAt(view, column, t) {
    let best = null;
    let bestGap = Infinity;
    view.times.forEach((time, i) => {
      const gap = Math.abs(time - t);
      if (gap < bestGap) { bestGap = gap; best = view.values[column][i]; }
    });
    return best;
  }

  function readCursors() {
    const view = current();
    const [a, b] = cursors;
    if (!view || a == null) { $("scope-cursors").replaceChildren(); return; }
    const parts = [el("span", {}, `A: ${fixed(a, 4)} s`)];
    if (b != null) parts.push(el("span", {}, `B: ${fixed(b, 4)} s`), el("strong", {}, `Δt = ${fixed(b - a, 4)} s`));
    view.channels.forEach((c, i) => {
      const va = valueAt(view, i, a);
      const text = b == null ? `${c.label}: ${fixed(va, 2)}` :
        `${c.label}: Δ = ${fixed(valueAt(view, i, b) - va, 2)}`;
      parts.push(el("span", { style: `color:${COLORS[i % COLORS.length]}` }, `${text}${c.unit ? ` ${c.unit}` : ""}`));
    });
    $("scope-cursors").replaceChildren(...parts);
  }

  function current() {
    if (shown) return shown;
    if (!live.channels.length) return null;
    return { title: _("live"), channels: live.channels, times: live.rows.map((r) => r[1]),
             values: live.channels.map((c, i) => live.rows.map((r) => r[2 + i])), markers: live.markers };
  }

  let drawPending = false;
  function draw(resetZoom) {
    drawPending = false;
    const view = current();
    if (!view) return;
    if (!chart || key(view) !== chartKey) build(view);
    else chart.setData(data(view), resetZoom !== false);
    $("plot-what").textContent = view.title;
    const list = view.markers.filter((m) => m.kind !== "trigger");
    $("scope-markers").replaceChildren(...list.map((m) => {
      const where = m.node ? _("node {node}", { node: m.node }) : "";
      const item = el("li", {}, `${fixed(m.t, 3)} s · ${where} ${m.text}`);
      item.classList.add(`marker-${m.kind}`);
      return item;
    }));
  }
  function schedule() {
    if (drawPending) return;
    drawPending = true;
    setTimeout(() => draw(true), 200);
  }

  // --- stored recordings --------------------------------------------------------------------------------------
  function asView(recording, title) {
    const zero = recording.trigger && recording.trigger.time_s != null ? recording.trigger.time_s : recording.times[0] || 0;
    const markers = recording.markers.map((m) => ({ ...m, t: m.time_s - zero }));
    if (recording.trigger && recording.trigger.position != null) markers.push({ kind: "trigger", t: 0, text: _("trigger") });
    return { title, id: recording.id, channels: recording.channels, times: recording.times.map((t) => t - zero),
             values: recording.values, markers, overlay: null };
  }
  async function open(id) {
    const recording = await call("GET", drivebench.url(`/api/scope/recordings/${id}`), null, "stored-result");
    if (!recording) return;
    shown = asView(recording, `${recording.name} · ${sourceName(recording)}, ${fixed(1 / recording.period_s, 1)} ${PER_S}`);
    cursors = [null, null];
    draw(true);
    readCursors();
  }
  async function overlay(id) {
    if (!shown) { await open(id); return; }
    const recording = await call("GET", drivebench.url(`/api/scope/recordings/${id}`), null, "stored-result");
    if (!recording) return;
    shown.overlay = asView(recording, recording.name);
    shown.title = `${shown.title.split(" ⇄ ")[0]} ⇄ ${recording.name}`;
    draw(true);
  }
  async function remove(id) {
    if (!window.confirm(_("Delete this recording?"))) return;
    if (await call("DELETE", drivebench.url(`/api/scope/recordings/${id}`), null, "stored-result")) listStored();
  }
  function exportLink(id, format) {
    const link = el("a", { className: "button-link small", download: "" });
    link.href = drivebench.url(`/api/scope/recordings/${id}/export?format=${format}`);
    link.textContent = format.toUpperCase();
    return link;
  }
  async function listStored() {
    const list = await call("GET", drivebench.url("/api/scope/recordings"), null, "stored-result");
    if (!list) return;
    $("scope-recordings-empty").hidden = list.length > 0;
    $("scope-recordings").tBodies[0].replaceChildren(...list.map((r) => el("tr", {},
      el("td", { className: "name" }, r.name),
      el("td", {}, new Date(r.created).toLocaleString()),
      el("td", {}, `${sourceName(r)}, ${fixed(1 / r.period_s, 1)}/s`),
      el("td", {}, String(r.count)),
      el("td", { className: "actions" },
        el("button", { type: "button", className: "small", onclick: () => open(r.id) }, _("Open")),
        el("button", { type: "button", className: "small secondary", onclick: () => overlay(r.id),
                       title: _("Show over the open recording (before/after)") }, _("Overlay")),
        ...EXPORTS.map((format) => exportLink(r.id, format)),
        readOnly ? "" : el("button", { type: "button", className: "small secondary delete-recording",
                                       onclick: () => remove(r.id) }, _("Delete"))))));
  }

  // --- live ---------------------------------------------------------------------------------------------------
  const STATES = { armed: _("armed, waiting for the trigger"), recording: _("recording"), done: _("done"),
                   stopped: _("stopped"), failed: _("failed"), none: _("no recording yet") };
  let openedFor = null;
  // ?recording=<id> (the Control tab's scope panel links a stored run): that one is opened, not the session's last
  const asked = (/^[0-9]+$/.exec(new URLSearchParams(location.search).get("recording") || "") || [null])[0];
  function onState(message) {
    run = message;
    $("scope-state").textContent = STATES[message.state] || message.state;
    $("scope-state").dataset.state = message.state;
    if (message.state === "none") return;
    const parts = message.parts && message.parts.length > 1 ? message.parts : [];
    const partText = (p) => {
      const nodes = _("nodes {nodes}", { nodes: p.nodes.join(", ") });
      return `${p.name} (${nodes}), ${fixed(p.rate, 1)} ${PER_S}`;
    };
    $("scope-source").textContent = parts.length ? parts.map(partText).join("; ")
      : `${sourceName(message)}, ${fixed(message.rate, 1)} ${PER_S}`;
    if (message.plan && message.plan.length) $("scope-source").title = message.plan.join("\n");
    $("scope-restored").replaceChildren(...(message.restored || []).map((text) => el("li", {}, text)));
    // A new run starts an empty trace when its first state comes, which the socket sends before the run's rows and
    // which may come before the start's own answer (a start that configures slow drives): never reset it after that.
    if (live.id !== message.id) live = { id: message.id, channels: message.channels, rows: [], markers: [] };
    if (message.error) $("scope-result").replaceChildren(drivebench.errorBox(_("Recording"), message.error));
    if (["done", "stopped", "failed"].includes(message.state) && message.recording_id && openedFor !== message.id) {
      openedFor = message.id;
      listStored();
      if (!asked || live.rows.length) open(message.recording_id);  // a run watched here ends: it is shown
    }
  }
  drivebench.liveSocket(drivebench.url(`/ws/sessions/${encodeURIComponent(session)}/scope`), {
    onMessage(message) {
      if (message.type === "state") onState(message);
      else if (message.type === "rows") {
        live.rows.push(...message.rows);
        if (live.rows.length > LIVE_KEPT) live.rows.splice(0, live.rows.length - LIVE_KEPT);
        if (!shown || (run && ["armed", "recording"].includes(run.state))) { shown = null; schedule(); }
      } else if (message.type === "events") {
        live.markers.push(...message.events.map((e) => ({ ...e, t: e.time_s })));
        schedule();
      }
    },
    onClose() { $("scope-state").textContent = _("connecting…"); },
  });

  const picker = $("session-picker");
  if (picker) picker.addEventListener("change", () => { location.href = drivebench.url(`/scope/${encodeURIComponent(picker.value)}`); });
  if (!readOnly) offer();
  listStored();
  if (asked) open(Number(asked));
})();
