// Monitor screen: one websocket (/ws/sessions/{id}/monitor, schema in web/ws/monitor.py), rendering throttled to
// animation frames (only the newest counters are drawn; trace rows and load points accumulate in between).
// Filter and pause are this window's own: they travel over the socket as a "view" message and change nothing for
// other viewers. The trace length kept here is the user's choice, remembered in localStorage.
(() => {
  const root = document.getElementById("monitor");
  if (!root) return;
  const sessionId = root.dataset.session;
  const api = window.drivebench.url(`/api/sessions/${encodeURIComponent(sessionId)}/monitor`);
  const $ = (id) => document.getElementById(id);
  const TRACE_LENGTHS = [500, 2000, 10000];
  const HELLO_ROWS_MAX = 2000;  // the server sends at most this many rows in a hello (web/ws/monitor.py)
  const storedLength = Number(localStorage.getItem("drivebench.monitor.traceRows"));
  let TRACE_ROWS = TRACE_LENGTHS.includes(storedLength) ? storedLength : 500;
  let socket = null;
  let paused = root.dataset.paused === "true";
  let view = null;  // this window's own view once the user changed it (re-sent after a reconnect)
  let errorSlot = "filter-result";
  const HISTORY_S = 600;
  const MIN_SPAN_S = 60;
  let latest = null;
  let pendingTrace = [];
  let drawScheduled = false;
  const loadPoints = { t: [], v: [] };
  let zoomed = false;

  const esc = window.drivebench.escape;
  const _ = window.drivebench.gettext;  // every value put into the tables' HTML (names come from profiles)
  // Numbers as the page's language writes them (<html lang>, chosen by the server: 12.5 % or 12,5 %).
  const lang = document.documentElement.lang || "en";
  const formats = new Map();
  const fixed = (value, digits) => {
    if (!formats.has(digits)) {
      formats.set(digits, new Intl.NumberFormat(lang, { minimumFractionDigits: digits, maximumFractionDigits: digits,
                                                         useGrouping: false }));
    }
    return formats.get(digits).format(value);
  };
  const num = (value) => Number(value).toLocaleString(lang);
  const rate = (value) => `${value >= 100 ? fixed(value, 0) : fixed(value, 1)}/s`;
  const pct = (value) => `${fixed(value, value >= 10 ? 1 : 2)} %`;
  const clock = (epoch, ms) => {
    const d = new Date(epoch * 1000);
    const text = d.toLocaleTimeString("en-GB", { hour12: false });
    return ms ? `${text}.${String(d.getMilliseconds()).padStart(3, "0")}` : text;
  };

  // --- chart ---------------------------------------------------------------------------------------------
  const chartBox = $("load-chart");
  const chart = new uPlot({
    width: Math.max(chartBox.clientWidth, 300), height: 240,
    // Both scales are set by drawChart (not auto-ranged), so a drag-zoom stays put while points arrive.
    scales: { x: { time: true, auto: false }, y: { auto: false } },
    axes: [
      // uPlot's own tick texts are American (2:02am, 11/26/26); a 24-hour clock and an ISO date read alike in both
      // languages. Rows: tick step (s), its text, then the text when the year, month, day, hour, minute changes.
      { label: _("time (local)"), labelSize: 18, space: 90, stroke: "#5d6b79", grid: { stroke: "#eef1f4" },
        values: [[3600, "{HH}:{mm}", "\n{YYYY}-{MM}-{DD}", null, "\n{YYYY}-{MM}-{DD}", null, null, null, 1],
                 [60, "{HH}:{mm}", "\n{YYYY}-{MM}-{DD}", null, "\n{YYYY}-{MM}-{DD}", null, null, null, 1],
                 [1, ":{ss}", "\n{YYYY}-{MM}-{DD} {HH}:{mm}", null, "\n{YYYY}-{MM}-{DD} {HH}:{mm}", null,
                  "\n{HH}:{mm}", null, 1]] },
      { label: _("bus load (%)"), labelSize: 18, stroke: "#5d6b79", grid: { stroke: "#eef1f4" }, size: 56,
        values: (u, ticks) => ticks.map((v) => `${num(v)} %`) },
    ],
    series: [
      { label: _("Time"), value: (u, v) => (v == null ? "–" : clock(v)) },
      { label: _("Bus load"), stroke: "#0b5fa5", width: 1.5, fill: "rgba(11,95,165,0.12)",
        value: (u, v) => (v == null ? "–" : `${fixed(v, 2)} %`) },
    ],
    legend: { live: true },
    // A drag selects a time span and zooms into it; the zoom stays while new points arrive, until a double-click.
    hooks: { setSelect: [(u) => { if (u.select.width > 0) zoomed = true; }] },
  }, [[], []], chartBox);
  chartBox.addEventListener("dblclick", () => { zoomed = false; drawChart(); });

  // The x axis spans the history there is (at least a minute, at most 10 minutes, ending at the newest point);
  // the y axis starts at 0 % and leaves room above the highest point (1 % at least).
  function drawChart() {
    chart.setData([loadPoints.t, loadPoints.v], false);
    if (zoomed) return;
    const times = loadPoints.t;
    const now = Date.now() / 1000;
    const newest = times.length ? times[times.length - 1] : now;
    const oldest = times.length ? times[0] : now;
    chart.batch(() => {
      chart.setScale("x", { min: newest - Math.min(HISTORY_S, Math.max(MIN_SPAN_S, newest - oldest)), max: newest });
      chart.setScale("y", { min: 0, max: Math.max(1, Math.ceil(Math.max(0, ...loadPoints.v) * 1.2)) });
    });
  }
  window.monitorChart = chart;  // for tests and the console
  new ResizeObserver(() => chart.setSize({ width: Math.max(chartBox.clientWidth, 300), height: 240 })).observe(chartBox);

  function addHistory(points, replace) {
    if (replace) { loadPoints.t = []; loadPoints.v = []; }
    for (const [t, v] of points) {
      if (loadPoints.t.length && t <= loadPoints.t[loadPoints.t.length - 1]) continue;
      loadPoints.t.push(t); loadPoints.v.push(v);
    }
    const excess = loadPoints.t.length - HISTORY_S;
    if (excess > 0) { loadPoints.t.splice(0, excess); loadPoints.v.splice(0, excess); }
  }

  // --- tables --------------------------------------------------------------------------------------------
  function renderStats(s) {
    $("stat-load").textContent = pct(s.load.percent);
    $("stat-peak").textContent = pct(s.load.peak_percent);
    $("stat-peak-time").textContent = s.load.peak_time ? _("at {time}", { time: clock(s.load.peak_time) }) : "";
    $("stat-avg").textContent = pct(s.load.average_percent);
    $("stat-since").textContent = _("since {time}", { time: clock(s.since) });
    $("stat-frames").textContent = num(s.totals.frames);
    $("stat-rate").textContent = rate(s.totals.rate);
    $("stat-errors").textContent = num(s.totals.errors);
    $("stat-error-rate").textContent = s.totals.errors
      ? _("{rate}, last {age} s ago", { rate: rate(s.totals.error_rate), age: fixed(s.totals.last_error_age_s, 0) })
      : _("none");
    $("stat-bits").textContent = num(s.totals.bits);
  }

  function renderTables(s) {
    // The texts first: pybabel's JavaScript extractor does not see _() inside a template literal.
    const notInSession = _("not in session"), noNodes = _("No node telegrams yet.");
    const noTelegrams = _("No telegrams (or none passes the filter).");
    const unanswered = (count) => _("SDO requests to {count} node ids that never answered (a scan)", { count: num(count) });
    const lastSeen = (age) => _("last {age} s ago", { age: fixed(age, 1) });
    // A scan's requests to node ids that never answered: one COB-ID row for them all (``ids``, ``text`` the range).
    const scanRow = (r) => r[col.node] === null && r[col.ids] > 1;
    $("services-body").innerHTML = s.services.map((r) =>
      `<tr class="${r.rate ? "" : "silent"}"><td>${esc(r.label)}</td><td class="num">${num(r.total)}</td><td class="num">${rate(r.rate)}</td></tr>`).join("");
    $("nodes-body").innerHTML = s.nodes.length ? s.nodes.map((r) =>
      `<tr class="${r.rate ? "" : "silent"}${r.node === null ? " unanswered" : ""}"><td class="num">${esc(r.node ?? "–")}</td><td class="device" title="${esc(r.name || "")}">${esc(r.node === null ? unanswered(r.unanswered_ids) : r.name || notInSession)}</td>` +
      `<td class="num">${num(r.total)}</td><td class="num">${rate(r.rate)}</td><td class="num">${pct(r.share_percent)}</td></tr>`).join("")
      : `<tr><td colspan="5" class="empty">${esc(noNodes)}</td></tr>`;
    const col = Object.fromEntries(s.cob_columns.map((name, i) => [name, i]));
    $("cobs-body").innerHTML = s.cob_ids.length ? s.cob_ids.map((r) =>
      `<tr class="${r[col.rate] ? "" : "silent"}" title="${esc(lastSeen(r[col.last_age_s]))}"><td class="mono">${esc(r[col.text])}</td>` +
      (scanRow(r) ? `<td class="scan-ids">${esc(unanswered(r[col.ids]))}</td>` : `<td>${esc(r[col.service])}</td>`) +
      `<td class="num">${esc(r[col.node] ?? "–")}</td><td class="num">${num(r[col.total])}</td><td class="num">${rate(r[col.rate])}</td><td class="num">${pct(r[col.share_percent])}</td></tr>`).join("")
      : `<tr><td colspan="6" class="empty">${esc(noTelegrams)}</td></tr>`;
    $("cob-note").textContent = s.cob_ids_cut ? _("busiest {shown} of {all}", { shown: s.cob_ids.length, all: s.cob_ids_cut }) : "";
  }

  const gapRows = $("trace-body").getElementsByClassName("gap");  // live collection
  const showCount = () => {
    $("trace-count").textContent = _("{shown} of {all} rows", { shown: num($("trace-body").rows.length - gapRows.length), all: num(TRACE_ROWS) });
  };
  // More telegrams came in one update than the server sends (TRACE_PER_UPDATE in web/ws/monitor.py): say so in
  // the trace instead of letting it look complete.
  const GAP_ROW = '<tr class="gap"><td colspan="6">' + esc(_("… more telegrams than the trace shows (it keeps up to " +
    "500 a second); the counters and a recording have every one")) + "</td></tr>";

  function renderTrace() {
    if (!pendingTrace.length) { showCount(); return; }
    const body = $("trace-body");
    const rows = pendingTrace.slice(-TRACE_ROWS);
    pendingTrace = [];
    const noData = _("(no data)");  // outside the template literal: pybabel's extractor does not look inside
    body.insertAdjacentHTML("beforeend", rows.map((r) => r.gap ? GAP_ROW :
      `<tr class="svc-${esc(r.group).replace(/ /g, "-")}" data-seq="${esc(r.seq)}"><td class="time">${clock(r.time, true)}</td><td class="cob">${esc(r.cob_id)}</td>` +
      `<td>${esc(r.service)}</td><td class="num">${esc(r.node ?? "–")}</td><td class="num">${esc(r.dlc)}</td>` +
      `<td class="decoded" title="${esc(r.cob_id)} [${esc(r.dlc)}] ${esc(r.hex || noData)}">${esc(r.summary || r.service)}</td></tr>`).join(""));
    while (body.rows.length > TRACE_ROWS) body.deleteRow(0);
    showCount();
    if ($("trace-follow").checked) { const box = $("trace-scroll"); box.scrollTop = box.scrollHeight; }
  }

  const BUS_STATES = { active: _("active"), warning: _("warning"), passive: _("error passive"),
                       "bus-off": _("bus-off") };
  function renderBus(bus) {
    if (!bus) return;
    const badge = $("bus-state");
    const counters = bus.tx_errors == null ? "" : ` · TEC ${bus.tx_errors} · REC ${bus.rx_errors}`;
    badge.className = `badge bus-${bus.state}`;
    const label = BUS_STATES[bus.state] || bus.state;
    badge.textContent = (bus.state === "bus-off" ? label : _("bus {state}", { state: label })) + counters;
    badge.title = _("Adapter reports: {state}", { state: BUS_STATES[bus.adapter_state] || bus.adapter_state }) +
      (bus.reported_age_s == null ? _("; no error frame with a controller state yet")
        : _("; last controller state from an error frame {age} s ago", { age: fixed(bus.reported_age_s, 0) })) +
      _(". Warning at 96, error passive at 128 errors (TEC: transmit, REC: receive error counter).");
  }

  function renderBusText(text) {
    // Adapter lost, bus-off, a babbling node, a duplicate node id: the session's bus trouble in words.
    const line = $("bus-alert");
    if (!line || line.textContent === (text || "")) return;
    line.textContent = text || "";
    line.hidden = !text;
  }

  function draw() {
    drawScheduled = false;
    if (!latest) return;
    const s = latest.snapshot;
    renderStats(s);
    renderBus(s.bus);
    renderBusText([s.bus_text, s.flood && s.flood.text].filter(Boolean).join(" "));
    renderTables(s);
    renderTrace();
    drawChart();
    setLive(paused ? "paused" : "live");
    setPaused(paused);
  }

  function schedule() {
    if (!drawScheduled) { drawScheduled = true; requestAnimationFrame(draw); }
  }

  // --- socket --------------------------------------------------------------------------------------------
  function setLive(state) {
    const badge = $("live-state");
    badge.className = `badge ${state}`;
    badge.textContent = { live: _("live"), paused: _("paused"), down: _("disconnected, retrying…"),
                          connecting: _("connecting…") }[state];
  }

  const helloRows = () => Math.min(TRACE_ROWS, HELLO_ROWS_MAX);

  function sendView(change, slot) {
    view = { ...(view || {}), ...change };
    errorSlot = slot;
    $(slot).innerHTML = "";
    if (!socket || !socket.send({ type: "view", ...change, rows: helloRows() })) {
      $(slot).replaceChildren(window.drivebench.errorBox(_("Not connected."), _("The change is sent when the connection is back.")));
    }
  }

  function connect() {
    socket = window.drivebench.liveSocket(
      () => window.drivebench.url(`/ws/sessions/${encodeURIComponent(sessionId)}/monitor?rows=${helloRows()}`),
      { onOpen: () => { if (view) socket.send({ type: "view", ...view, rows: helloRows() }); },
        onMessage: receive, onClose: () => setLive("down"), keepOpen: (event) => event.code !== 4404 });
  }

  function receive(message) {
    if (message.type === "error") {
      $(errorSlot).replaceChildren(window.drivebench.errorBox(null, message.detail));
      return;
    }
    if (message.type === "view") {
      paused = message.view.paused; setPaused(paused); setLive(paused ? "paused" : "live");
      return;
    }
    if (message.type === "hello") {
      $("trace-body").innerHTML = ""; pendingTrace = [];
      paused = message.view.paused;
      if (view) view = { ...message.view };  // what the server took (a rejected filter is not re-sent)
    } else if (paused) {
      return;  // sent before the server took our pause
    }
    addHistory(message.history, message.type === "hello");
    const names = message.trace_columns;
    if (message.trace_more && message.type === "update") pendingTrace.push({ gap: true });
    for (const row of message.trace) pendingTrace.push(Object.fromEntries(names.map((name, i) => [name, row[i]])));
    if (pendingTrace.length > TRACE_ROWS) pendingTrace = pendingTrace.slice(-TRACE_ROWS);
    latest = message;
    schedule();
  }

  // --- controls ------------------------------------------------------------------------------------------
  async function call(method, path, body, slot) {
    try {
      const response = await fetch(api + path, { method, headers: body ? { "Content-Type": "application/json" } : {},
                                                 body: body ? JSON.stringify(body) : undefined });
      if (!response.ok) {
        let problem = null;
        try { problem = await response.json(); } catch (e) { /* not JSON */ }
        $(slot).replaceChildren(window.drivebench.problemBox(problem, response.status));
        return null;
      }
      $(slot).innerHTML = "";
      return response.json();
    } catch (e) {
      $(slot).replaceChildren(window.drivebench.errorBox(_("No answer from the DriveBench server."), _("Is it still running?")));
      return null;
    }
  }

  function setPaused(paused) {
    const button = $("pause");
    button.dataset.paused = paused ? "true" : "false";
    button.textContent = paused ? _("Resume") : _("Pause");
  }

  $("pause").addEventListener("click", () => {
    paused = !paused;  // at once: updates already on their way are not drawn
    setPaused(paused); setLive(paused ? "paused" : "live");
    sendView({ paused }, "control-result");
  });
  $("reset").addEventListener("click", async () => {
    if (await call("POST", "/reset", null, "control-result")) {
      $("trace-body").innerHTML = ""; pendingTrace = []; addHistory([], true); showCount();
    }
  });

  const parseId = (text, fallback) => {
    const value = text.trim();
    if (!value) return fallback;
    const parsed = /^0x/i.test(value) ? parseInt(value, 16) : parseInt(value, 10);
    return Number.isNaN(parsed) ? NaN : parsed;
  };
  $("filter-form").addEventListener("submit", async (event) => {
    event.preventDefault();
    const form = event.target;
    const nodes = form.nodes.value.split(/[\s,;]+/).filter(Boolean).map(Number);
    const body = {
      nodes, services: [...form.querySelectorAll("input[name=services]:checked")].map((box) => box.value),
      cob_min: parseId(form.cob_min.value, 0), cob_max: parseId(form.cob_max.value, 0x1FFFFFFF),
    };
    if (nodes.some(Number.isNaN) || Number.isNaN(body.cob_min) || Number.isNaN(body.cob_max)) {
      $("filter-result").replaceChildren(window.drivebench.errorBox(null, _("Nodes are numbers 1…127; COB-IDs decimal or 0x-hex.")));
      return;
    }
    sendView({ filter: body }, "filter-result");  // the answer is a hello: the newest matching rows, filtered tables
  });
  $("filter-clear").addEventListener("click", () => {
    const form = $("filter-form");
    form.nodes.value = ""; form.cob_min.value = "0x000"; form.cob_max.value = "0x1FFFFFFF";
    form.querySelectorAll("input[name=services]").forEach((box) => { box.checked = false; });
    form.requestSubmit();
  });

  // Trace length kept in this browser (remembered); the server re-sends up to HELLO_ROWS_MAX rows at once.
  const lengthPicker = $("trace-length");
  lengthPicker.value = String(TRACE_ROWS);
  lengthPicker.addEventListener("change", () => {
    TRACE_ROWS = Number(lengthPicker.value);
    localStorage.setItem("drivebench.monitor.traceRows", String(TRACE_ROWS));
    const body = $("trace-body");
    while (body.rows.length > TRACE_ROWS) body.deleteRow(0);
    showCount();
    if (!paused && body.rows.length < helloRows()) sendView({}, "control-result");  // fill up from the ring
  });

  const picker = $("session-picker");  // more than one session: the choice opens the other one's monitor
  if (picker) picker.addEventListener("change", () => { location.href = window.drivebench.url(`/monitor/${encodeURIComponent(picker.value)}`); });

  setLive("connecting");
  connect();
})();
