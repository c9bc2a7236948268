// The compact scope panel on a node's Control tab (node/control_body.html #scope-panel): a free-run recording of the
// node's chosen channels over the same run API and websocket as the Scope page (web/api/scope.py, ws/scope.py), so
// the same rules hold: sampling by PDO asks for the confirmation (drivebench.moving), holds the node's lease, and
// ends when the owner's last page (this panel counts as one) closes. The live trace is drawn small (uPlot); Stop
// stores the kept seconds and the link opens them on the Scope page. Texts go in as text (textContent).
(() => {
  // The tab brings this script again each time it is shown: one copy does the work.
  if (window.drivebenchScopePanelScan) { window.drivebenchScopePanelScan(); return; }
  const drivebench = window.drivebench;
  const _ = drivebench.gettext;
  // what happens to the recording's changes when its page closes (the README's "What is restored when")
  const RECORDING_NOTE = _("The recording ends when your last page showing it closes (or at Stop): every TPDO, SYNC " +
                           "and NMT setting it changed is put back and read back.");
  const COLORS = ["#0b5fa5", "#c0392b", "#1e8449", "#8e44ad", "#d35400", "#17a589", "#7f8c8d", "#b7950b"];
  const KEPT = 2000;
  const PER_S = _("samples/s");
  const STATES = { armed: _("armed, waiting for the trigger"), recording: _("recording"), done: _("done"),
                   stopped: _("stopped"), failed: _("failed"), none: _("no recording yet") };
  const ready = new WeakSet();

  function init(panel) {
    if (ready.has(panel)) return;
    ready.add(panel);
    const session = panel.dataset.session;
    const node = Number(panel.dataset.node);
    const api = drivebench.url(`/api/sessions/${encodeURIComponent(session)}/scope`);
    const $ = (id) => panel.querySelector(`#${id}`);
    const form = $("scope-panel-form");
    const result = $("scope-panel-result");
    const chartBox = $("scope-panel-chart");
    const openLink = $("scope-panel-open");
    let runId = null;  // the run the socket follows (its state's id)
    let channels = [];
    let rows = [];
    let chart = null;
    let chartKey = "";
    let pending = false;

    async function request(method, url, body) {
      try {
        return await drivebench.requestJson(method, url, body);
      } catch (e) {
        return { status: 0, data: { detail: _("No answer from the DriveBench server.") } };
      }
    }
    function shown(answer) {
      if (!answer) return null;  // the question was cancelled
      if (answer.status >= 400 || answer.status === 0) {
        result.replaceChildren(drivebench.problemBox(answer.data, answer.status));
        return null;
      }
      result.replaceChildren();
      return answer.data;
    }

    async function start(event) {
      event.preventDefault();
      const f = form.elements;
      const chosen = [...form.querySelectorAll("input[name=channel]:checked")].map((box) => ({ node, ref: box.value }));
      if (!chosen.length) {
        result.replaceChildren(drivebench.errorBox(_("Choose at least one channel."), ""));
        return;
      }
      const body = { channels: chosen, period_ms: Number(f.period_ms.value), length_s: Number(f.length_s.value),
                     trigger: { mode: "free" }, name: _("Node {node}, Control tab", { node }) };
      const send = (confirmation) => request("POST", `${api}/run`, confirmation ? { ...body, ...confirmation } : body);
      shown(await drivebench.moving(send, { what: _("Scope recording"), note: RECORDING_NOTE }));  // the new run's first state (maybe before this answer) resets the trace
    }
    if (form) form.addEventListener("submit", start);
    // Start comes disabled from the server: a press before this script ran would have done nothing.
    const startButton = $("scope-panel-start");
    if (startButton) startButton.disabled = false;
    const stopButton = $("scope-panel-stop");
    if (stopButton) stopButton.addEventListener("click", async () => shown(await request("POST", `${api}/run/stop`)));

    function build() {
      const units = [...new Set(channels.map((c) => c.unit || ""))];
      const scales = { x: { time: false } };
      for (const unit of units) scales[unit || "value"] = {};
      const series = [{ label: _("t (s)") }, ...channels.map((c, i) => ({
        label: c.unit ? `${c.ref} [${c.unit}]` : c.ref, scale: c.unit || "value", stroke: COLORS[i % COLORS.length],
        width: 1.5 }))];
      const axes = [{ stroke: "#5d6b79", grid: { stroke: "#eef1f4" } }, ...units.map((unit, i) => ({
        scale: unit || "value", label: unit || _("value"), labelSize: 14, size: 50, stroke: "#5d6b79",
        side: i % 2 ? 1 : 3, grid: { show: i === 0, stroke: "#eef1f4" } }))];
      if (chart) chart.destroy();
      chart = new uPlot({ width: Math.max(chartBox.clientWidth, 200), height: 160, scales, series, axes,
                          legend: { live: false } }, data(), chartBox);
      chartKey = JSON.stringify(channels.map((c) => [c.label, c.unit]));
      panel.scopeChart = chart;  // for tests and the console
    }
    function data() {
      return [rows.map((r) => r[1]), ...channels.map((c, i) => rows.map((r) => r[2 + i]))];
    }
    function draw() {
      pending = false;
      if (!channels.length || !panel.isConnected) return;
      if (!chart || chartKey !== JSON.stringify(channels.map((c) => [c.label, c.unit]))) build();
      else chart.setData(data());
    }
    function schedule() {
      if (pending) return;
      pending = true;
      setTimeout(draw, 200);
    }
    new ResizeObserver(() => chart && chart.setSize({ width: Math.max(chartBox.clientWidth, 200), height: 160 }))
      .observe(chartBox);

    function onState(message) {
      const state = $("scope-panel-state");
      state.textContent = STATES[message.state] || message.state;
      state.dataset.state = message.state;
      if (message.state === "none") return;
      $("scope-panel-source").textContent = message.rate ? `${message.source_name}, ${message.rate} ${PER_S}`
        : message.source_name;
      // the plan in words, as the Scope page has it: which TPDO carries what, which channels are polled and why
      $("scope-panel-plan").replaceChildren(...(message.plan || []).map((text) => {
        const item = document.createElement("li");
        item.textContent = text;
        return item;
      }));
      if (message.id !== runId) { runId = message.id; channels = message.channels; rows = []; }
      if (message.error) result.replaceChildren(drivebench.errorBox(_("Recording"), message.error));
      const base = `/scope/${encodeURIComponent(session)}`;
      openLink.href = drivebench.url(message.recording_id ? `${base}?recording=${message.recording_id}` : base);
      schedule();
    }
    const socket = drivebench.liveSocket(drivebench.url(`/ws/sessions/${encodeURIComponent(session)}/scope`), {
      onMessage(message) {
        if (!panel.isConnected) { socket.close(); return; }
        if (message.type === "state") onState(message);
        else if (message.type === "rows") {
          rows.push(...message.rows);
          if (rows.length > KEPT) rows.splice(0, rows.length - KEPT);
          schedule();
        }
      },
      keepOpen: () => panel.isConnected,
    });
    // Another tab shown: this panel is gone, its socket goes too (the owner's page closed, as on the Scope page).
    const watch = setInterval(() => { if (!panel.isConnected) { socket.close(); clearInterval(watch); } }, 1000);
  }

  function scan() { const panel = document.getElementById("scope-panel"); if (panel) init(panel); }
  window.drivebenchScopePanelScan = scan;
  document.body.addEventListener("htmx:afterSettle", scan);
  document.body.addEventListener("htmx:historyRestore", scan);
  scan();
})();
