// Control tab: live status over the control websocket (its messages are the keep-alive), commands to the JSON API,
// confirmation for anything that can make the motor turn, live plots of the actual values, guided commissioning.
// Each page load is one panel (X-Drive-Panel / ?panel=): the panel that arms a drive holds it; other panels on the
// node watch - their moving controls are disabled, stopping ones stay.
(() => {
  // The tab brings this script again each time it is shown: one copy does the work.
  if (window.drivebenchControlScan) { window.drivebenchControlScan(); return; }
  const HISTORY_S = 30;
  const WHOLE_SECONDS = [1, 2, 5, 10, 15, 30, 60];  // time axis ticks: never the milliseconds uPlot picks by itself
  const clockLabels = (u, splits) => splits.map((t) => new Date(t * 1000).toLocaleTimeString("en-GB", { hour12: false }));
  window.drivebenchClockLabels = clockLabels;  // the axis is drawn on a canvas: tests read its labels here
  const STOPPING = new Set(["shutdown", "disable_voltage", "quick_stop", "disable_operation"]);
  const OPERATOR_KEY = "drivebench.operator";
  window.drivebenchPanelId = window.drivebenchPanelId ||
    Array.from(crypto.getRandomValues(new Uint8Array(8)), (b) => b.toString(16).padStart(2, "0")).join("");
  const panelId = window.drivebenchPanelId;

  function operator() {
    try { return (localStorage.getItem(OPERATOR_KEY) || "").trim(); } catch (e) { return ""; }
  }

  const esc = window.drivebench.escape;  // problem texts name lease holders and operators: text, never markup
  const _ = window.drivebench.gettext;

  // Panels set up, kept here and not as a mark on the element: Back to this tab restores htmx's snapshot of the
  // page, marks included, and a marked copy would get no socket and no button handlers (a dead Quick stop).
  const ready = new WeakSet();

  function init(panel) {
    if (ready.has(panel)) return;
    ready.add(panel);
    const api = panel.dataset.api;
    const moving = new Set(panel.dataset.moving.split(",").filter(Boolean));
    const result = panel.querySelector("#ctl-result");
    const dialog = panel.querySelector("#ctl-confirm");
    const plots = new Map();  // ref -> {u, data}
    let socket = null;
    let closed = false;
    let runId = null;
    const runBox = panel.querySelector("#ctl-run");
    const nextButton = panel.querySelector("#ctl-seq-next");
    let freshUntil = 0;  // a command's answer is newer than a websocket status read before it
    let watching = false;  // another panel holds the armed drive
    const refused = Boolean(panel.dataset.refused);  // this user's role may watch the drive, not control it
    let runOpen = false;  // a commissioning run has steps left
    let currentMode = null;  // CiA 402 modes of operation display (0x6061), from the last status
    const nameInput = panel.querySelector("#ctl-operator");
    nameInput.value = operator();
    nameInput.addEventListener("change", () => {
      try { localStorage.setItem(OPERATOR_KEY, nameInput.value.trim()); } catch (e) { /* private mode */ }
    });

    // The pages' error box (app.js): titles and details are text nodes, never markup.
    function showError(box, slot = result) { slot.replaceChildren(box); }
    function clearError(slot = result) { slot.innerHTML = ""; }

    function confirmMove(text) {
      return new Promise((resolve) => {
        panel.querySelector("#ctl-confirm-text").textContent = text;
        dialog.returnValue = "";
        dialog.addEventListener("close", () => resolve(dialog.returnValue === "ok"), { once: true });
        dialog.showModal();
      });
    }

    async function call(method, url, body, slot = result) {
      const headers = { "Content-Type": "application/json", "X-Drive-Panel": panelId,
                        "X-Drive-Operator": encodeURIComponent(operator()) };
      // safety interlocks: a confirmed command names its node (the server answers 428 to a bare true)
      if (body && body.confirm === true) body = { ...body, confirm: api.split("/nodes/")[1].split("/")[0] };
      const response = await fetch(url, { method, headers,
                                         body: body === undefined ? undefined : JSON.stringify(body) });
      let data = null;
      try { data = await response.json(); } catch (e) { data = null; }
      if (!response.ok) { showError(window.drivebench.problemBox(data, response.status), slot); return null; }
      freshUntil = performance.now() + 600;
      clearError(slot);
      return data;
    }

    function render(status) {
      panel.querySelectorAll(".ctl-state").forEach((g) => g.classList.toggle("current", g.dataset.state === status.state));
      const label = panel.querySelector("#ctl-state-label");
      label.textContent = status.state_label;
      label.dataset.state = status.state;
      panel.querySelector("#ctl-sw").textContent = "0x" + status.status_word.toString(16).toUpperCase().padStart(4, "0");
      panel.querySelector("#ctl-cw").textContent = status.control_word === null ? "–"
        : "0x" + status.control_word.toString(16).toUpperCase().padStart(4, "0");
      for (const [table, bits] of [["#ctl-sw-bits", status.status_bits], ["#ctl-cw-bits", status.control_bits]]) {
        const rows = panel.querySelectorAll(`${table} tr`);
        bits.forEach((bit, i) => rows[i] && rows[i].classList.toggle("on", bit.set));
      }
      const armed = panel.querySelector("#ctl-armed");
      armed.textContent = !status.armed ? _("not armed") : status.you_hold ? _("armed by this panel: keep-alive running")
        : _("armed by another panel");
      armed.classList.toggle("armed", status.armed);
      renderHolder(status);
      const trip = panel.querySelector("#ctl-trip");
      trip.hidden = !status.last_trip;
      trip.textContent = status.last_trip || "";
      const limitNote = panel.querySelector("#ctl-limit-note");  // how a motion ended at 0x607D (soft_limits.py)
      if (limitNote) {
        limitNote.hidden = !status.limit_note;
        limitNote.textContent = status.limit_note || "";
      }
      const limitBit = panel.querySelector("#ctl-limit");  // CiA 402 status bit 11 internal limit active
      if (limitBit) limitBit.hidden = !(status.status_bits[11] && status.status_bits[11].set);
      const display = panel.querySelector("#ctl-mode-display");
      if (display && status.mode !== null) display.textContent = `${status.mode_label} (${status.mode})`;
      currentMode = status.mode;
      panel.querySelectorAll("input[name=ctl-mode]").forEach((radio) => { radio.checked = Number(radio.value) === status.mode; });
      const spRef = panel.querySelector("#ctl-sp-ref");
      if (spRef) spRef.textContent = status.setpoint_ref;
      const spUnit = panel.querySelector("#ctl-sp-unit");
      if (spUnit) spUnit.textContent = status.setpoint_unit;
      const inputs = panel.querySelectorAll("#ctl-inputs tr");
      (status.inputs || []).forEach((bit, i) => inputs[i] && inputs[i].classList.toggle("on", bit.set));
      const error = panel.querySelector("#ctl-error-code");
      if (error) error.textContent = status.error_code === null ? "–"
        : `0x${status.error_code.toString(16).toUpperCase().padStart(4, "0")} ${status.error_text || ""}`;
    }

    function renderHolder(status) {
      const box = panel.querySelector("#ctl-holder");
      const panels = panel.querySelector("#ctl-panels");
      panels.textContent = status.panels === 1 ? _("1 panel open") : _("{count} panels open", { count: status.panels });
      watching = Boolean(status.armed && status.holder && !status.you_hold);
      box.hidden = !status.holder;
      box.classList.toggle("watching", watching);
      box.textContent = !status.holder ? ""
        : watching ? _("Held by {holder}. This panel watches: it can stop the drive (Quick stop, Disable, " +
                       "Shutdown) but not move it until the drive is disarmed.", { holder: status.holder })
        : _("This panel holds the drive ({holder}): only it moves the drive; closing it sends quick stop.",
            { holder: status.holder });
      panel.classList.toggle("watching", watching);
      panel.querySelectorAll("[data-command]").forEach((button) => {
        button.disabled = refused || (watching && !STOPPING.has(button.dataset.command));
      });
      panel.querySelectorAll("#ctl-setpoint input, #ctl-setpoint button, [data-jog], input[name=ctl-mode], #ctl-seq-start, " +
                             "#ctl-motion form input, #ctl-motion form select, #ctl-motion form button, #ctl-jog-speed")
        .forEach((control) => { control.disabled = refused || watching; });
      if (nextButton) nextButton.disabled = refused || watching || !runOpen;
    }

    function plot(actuals, t) {
      const holder = panel.querySelector("#ctl-actuals");
      if (!plots.size) holder.innerHTML = "";
      for (const value of actuals) {
        let entry = plots.get(value.ref);
        if (!entry) {
          const box = document.createElement("div");
          box.className = "ctl-plot";
          box.innerHTML = `<div class="ctl-plot-head"><span>${esc(value.label)} <span class="muted mono">${esc(value.ref)}</span></span>` +
                          `<strong class="ctl-value" data-ref="${esc(value.ref)}"></strong></div>`;
          holder.appendChild(box);
          const data = [[], []];
          const width = Math.max(240, holder.clientWidth - 8);
          const u = window.uPlot ? new uPlot({ width, height: 90, legend: { show: false }, cursor: { show: false },
            scales: { x: { time: true } }, series: [{}, { stroke: "#0b5fa5", width: 1.5 }],
            axes: [{ size: 24, font: "10px sans-serif", space: 56, incrs: WHOLE_SECONDS, values: clockLabels }, { size: 46, font: "10px sans-serif", label: value.unit || "", labelSize: 12, labelFont: "10px sans-serif" }] },
            data, box) : null;
          entry = { u, data, box };
          plots.set(value.ref, entry);
        }
        const text = value.error ? _("read error") : value.value === null ? "–" : `${value.value} ${value.unit || ""}`;
        entry.box.querySelector(".ctl-value").textContent = text;
        if (value.value !== null && entry.u) {
          entry.data[0].push(t);
          entry.data[1].push(value.value);
          while (entry.data[0].length && entry.data[0][0] < t - HISTORY_S) { entry.data[0].shift(); entry.data[1].shift(); }
          entry.u.setData(entry.data);
          const shown = entry.box.dataset;  // what the chart holds, for a reader that cannot see the canvas
          [shown.samples, shown.min, shown.max] = [entry.data[1].length, Math.min(...entry.data[1]), Math.max(...entry.data[1])];
        }
      }
    }

    function connect() {
      const state = panel.querySelector("#ctl-ws");
      socket = window.drivebench.liveSocket(
        () => `${panel.dataset.ws}?panel=${panelId}&operator=${encodeURIComponent(operator())}`, {
          onOpen: () => { state.textContent = _("live"); state.className = "badge good"; },
          onClose: () => { state.textContent = _("disconnected"); state.className = "badge bad"; },
          keepOpen: () => !closed && document.body.contains(panel),
          onMessage: (message) => {
            if (message.type === "status") {
              if (performance.now() > freshUntil) render(message.status);
              plot(message.actuals, message.t);
            }
            else if (message.type === "error") showError(window.drivebench.errorBox(null, message.detail));
          },
        });
    }

    const keepalive = setInterval(() => {
      if (!document.body.contains(panel)) {  // tab left: closing the socket quick-stops an armed drive
        closed = true;
        clearInterval(keepalive);
        if (socket) socket.close();
        return;
      }
      if (socket) socket.send({ cmd: "keepalive" });
    }, 500);

    async function command(key, label) {
      let confirm = false;
      if (moving.has(key)) {
        confirm = await confirmMove(_("{command}: after this command the motor may turn.", { command: label }));
        if (!confirm) return;
      }
      const status = await call("POST", `${api}/commands/${key}`, { confirm });
      if (status) render(status);
    }

    panel.querySelectorAll("[data-command]").forEach((button) =>
      button.addEventListener("click", () => command(button.dataset.command, button.textContent.trim())));

    const setpointForm = panel.querySelector("#ctl-setpoint");
    if (setpointForm) setpointForm.addEventListener("submit", async (event) => {
      event.preventDefault();
      const value = parseFloat(event.target.value.value);
      if (Number.isNaN(value)) { showError(window.drivebench.errorBox(_("Setpoint"), _("enter a number"))); return; }
      let confirm = false;
      if (value !== 0) {
        confirm = await confirmMove(_("Setpoint {value} {unit}: the motor may turn.",
                                        { value, unit: panel.querySelector("#ctl-sp-unit").textContent }));
        if (!confirm) return;
      }
      const status = await call("PUT", `${api}/setpoint`, { value, confirm });
      if (status) render(status);
    });

    // Jog is hold-to-run: confirmed once for this page, then it turns while the button is held (pointer down)
    // and stops on release; the keep-alive stops it too if the page goes away mid-jog.
    let jogConfirmed = false;
    panel.querySelectorAll("[data-jog]").forEach((button) => {
      let jogging = false;
      const start = async (event) => {
        event.preventDefault();
        if (!jogConfirmed) {
          const how = panel.querySelector("#ctl-jog-how");
          jogConfirmed = await confirmMove(_("Jog: the motor turns at {value} {unit} while a jog button is held.",
                                             { value: how.dataset.value, unit: how.dataset.unit }));
          return;  // the next press jogs
        }
        jogging = true;
        button.classList.add("held");
        // held means held: a line appearing on the page (internal limit, how a jog ended) must not move the button
        // from under the pointer and end the jog; the capture keeps the pointer on it until it is released
        try { button.setPointerCapture(event.pointerId); } catch (e) { /* not a pointer event (keyboard) */ }
        const speedInput = panel.querySelector("#ctl-jog-speed");
        const speed = speedInput ? parseFloat(speedInput.value) : NaN;
        await call("POST", `${api}/jog`, { direction: Number(button.dataset.jog), confirm: true,
                                           ...(Number.isNaN(speed) ? {} : { speed }) });
      };
      const stop = async () => {
        if (!jogging) return;
        jogging = false;
        button.classList.remove("held");
        await call("POST", `${api}/jog`, { direction: 0, confirm: false });
      };
      button.addEventListener("pointerdown", start);
      for (const name of ["pointerup", "pointerleave", "pointercancel"]) button.addEventListener(name, stop);
    });

    panel.querySelectorAll("input[name=ctl-mode]").forEach((radio) => radio.addEventListener("change", async () => {
      const status = await call("PUT", `${api}/mode`, { mode: Number(radio.value), confirm: false });
      if (status) render(status);
    }));

    // --- CiA 402 motion (a drive without a vendor control section): profile position, profile velocity, homing ---
    const motion = panel.querySelector("#ctl-motion");
    async function confirmed(text) { return await confirmMove(_("{what}: the motor may turn.", { what: text })); }
    if (motion) {
      const { positionUnit } = motion.dataset;
      motion.querySelector("#ctl-move").addEventListener("submit", async (event) => {
        event.preventDefault();
        const form = event.target;
        const target = parseFloat(form.target.value);
        const velocity = parseFloat(form.velocity.value);
        if (Number.isNaN(target)) { showError(window.drivebench.errorBox(_("Target"), _("enter a number"))); return; }
        const move = form.relative.checked ? _("Move by {target} {unit}", { target, unit: positionUnit })
          : _("Move to {target} {unit}", { target, unit: positionUnit });
        if (!await confirmed(move)) return;
        const status = await call("POST", `${api}/move`, { target, relative: form.relative.checked,
          immediate: form.immediate.checked, confirm: true, ...(Number.isNaN(velocity) ? {} : { velocity }) });
        if (status) render(status);
      });
      motion.querySelectorAll("form[data-mode]").forEach((form) => form.addEventListener("submit", async (event) => {
        event.preventDefault();  // profile velocity (3) or torque (4): the mode first, then its setpoint
        const mode = Number(form.dataset.mode);
        const value = parseFloat(form.value.value);
        if (Number.isNaN(value)) { showError(window.drivebench.errorBox(_("Target"), _("enter a number"))); return; }
        if (value !== 0 && !await confirmed(_("Target {value} {unit} (mode {mode})", { value, unit: form.dataset.unit, mode }))) return;
        if (currentMode !== mode && !await call("PUT", `${api}/mode`, { mode, confirm: true })) return;
        const status = await call("PUT", `${api}/setpoint`, { value, confirm: value !== 0 });
        if (status) render(status);
      }));
      const cyclicForm = motion.querySelector("#ctl-cyclic");
      if (cyclicForm) {
        cyclicForm.addEventListener("submit", async (event) => {
          event.preventDefault();
          const value = parseFloat(event.target.value.value);
          if (Number.isNaN(value)) { showError(window.drivebench.errorBox(_("Target"), _("enter a number"))); return; }
          if (!await confirmed(_("Cyclic synchronous setpoint {value}", { value }))) return;
          const sent = await call("POST", `${api}/cyclic`, { value, confirm: true });
          if (sent) result.textContent = _("RPDO{rpdo} ({cob_id}) every {period} ms with SYNC: {data}", { rpdo: sent.rpdo,
            cob_id: `0x${sent.cob_id.toString(16).toUpperCase()}`, period: sent.period_ms, data: sent.data });
        });
        motion.querySelector("#ctl-cyclic-stop").addEventListener("click", async () => {
          const stopped = await call("DELETE", `${api}/cyclic`);
          if (stopped) result.textContent = _("Cyclic RPDOs stopped: {stopped}", { stopped: stopped.stopped });
        });
      }
      const homeForm = motion.querySelector("#ctl-home");
      if (homeForm) homeForm.addEventListener("submit", async (event) => {
        event.preventDefault();
        const select = event.target.method;
        if (!await confirmed(_("Homing, method {method}", { method: select.options[select.selectedIndex].text }))) return;
        const status = await call("POST", `${api}/home`, { method: Number(select.value), confirm: true });
        if (status) render(status);
      });
    }

    // --- guided commissioning ---

    function renderRun(run) {
      const results = new Map(run.results.map((r) => [r.number, r]));
      const rows = run.steps.map((step) => {
        const r = results.get(step.number);
        const cls = r ? (r.ok ? "done" : "failed") : step.number === run.position + 1 && !run.finished ? "next" : "";
        const telegrams = r ? r.telegrams.map((t) => `<div class="mono tg ${esc(t.direction)}">${t.direction === "T" ? "→" : "←"} ${esc(t.cob_id)} ${esc(t.data)}</div>`).join("") : "";
        return `<tr class="${cls}"><td>${esc(step.number)}</td><td>${esc(step.title)}${step.moves ? ` <span class="badge warn">${esc(_("moves"))}</span>` : ""}` +
               `${step.printed ? `<div class="muted mono small-text">${esc(_("manual: {steps}", { steps: step.printed }))}</div>` : ""}</td>` +
               `<td>${telegrams}</td><td>${r ? esc(r.message) : ""}</td></tr>`;
      }).join("");
      const pre = run.preconditions.map((p) => `<li>${esc(p)}</li>`).join("");
      // The texts first: pybabel's JavaScript extractor does not see _() inside a template literal.
      const allAnswered = _("All {count} steps answered as the manual expects.", { count: run.steps.length });
      const beforeStarting = _("Before starting (not sent over CAN):");
      const [stepHead, telegramsHead, answerHead] = [_("Step"), _("Telegrams"), _("Answer")];
      const banner = run.failed ? `<div class="error" role="alert">${esc(run.failed)}</div>`
        : run.finished ? `<div class="ok-note">${esc(allAnswered)}</div>` : "";
      runBox.innerHTML = `<p><strong>${esc(run.title)}</strong> · ${esc(run.source)}</p>` +
        (pre ? `<p class="muted">${esc(beforeStarting)}</p><ul class="muted">${pre}</ul>` : "") + banner +
        `<div class="ctl-run-scroll"><table class="ctl-run"><thead><tr><th>#</th><th>${esc(stepHead)}</th>` +
        `<th>${esc(telegramsHead)}</th><th>${esc(answerHead)}</th></tr></thead><tbody>${rows}</tbody></table></div>`;
      runOpen = !run.finished;
      nextButton.disabled = refused || watching || !runOpen;
      const row = runBox.querySelector("tr.next, tr.failed");
      const scroller = runBox.querySelector(".ctl-run-scroll");
      if (row && scroller) scroller.scrollTop = Math.max(0, row.offsetTop - scroller.clientHeight / 2);  // not the page
    }

    const startButton = panel.querySelector("#ctl-seq-start");
    if (startButton) {
      startButton.addEventListener("click", async () => {
        const key = panel.querySelector("#ctl-seq").value;
        const run = await call("POST", `${api}/sequences/${key}/runs`, undefined, runBox);
        if (run) { runId = run.id; renderRun(run); }
      });
      nextButton.addEventListener("click", async () => {
        if (!runId) return;
        const current = await call("GET", `${api}/runs/${runId}`);
        if (!current) return;
        const step = current.steps[current.position];
        let confirm = false;
        if (step && step.moves) {
          confirm = await confirmMove(_("Step {number}: {title}.", { number: step.number, title: step.title }));
          if (!confirm) return;
        }
        nextButton.disabled = true;
        const slot = document.createElement("div");
        const run = await call("POST", `${api}/runs/${runId}/next`, { confirm }, slot);
        if (run) renderRun(run); else { runBox.prepend(slot); nextButton.disabled = refused || watching; }
      });
    }

    connect();
  }

  function scan() { const panel = document.getElementById("control-panel"); if (panel) init(panel); }
  scan();
  window.drivebenchControlScan = scan;
  document.body.addEventListener("htmx:afterSettle", scan);
  document.body.addEventListener("htmx:historyRestore", scan);
})();
