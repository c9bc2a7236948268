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

    async function request(method, url, body) {
      const headers = { "Content-Type": "application/json", "X-Drive-Panel": panelId,
                        "X-Drive-Operator": encodeURIComponent(operator()) };
      const response = await fetch(url, { method, headers,
                                         body: body === undefined ? undefined : JSON.stringify(body) });
      let data = null;
      try { data = await response.json(); } catch (e) { data = null; }
      return { status: response.status, data };
    }

    function shown(answer, slot = result) {
      if (!answer) return null;  // the question was cancelled
      if (answer.status >= 400) { showError(window.drivebench.problemBox(answer.data, answer.status), slot); return null; }
      freshUntil = performance.now() + 600;
      clearError(slot);
      return answer.data;
    }

    // Safety interlocks: whatever can make the motor turn is refused (428) with the node and the values the server
    // would send; the dialog shows them and, confirmed, the same request goes again with both (app.js: moving).
    async function call(method, url, body, slot = result, what = "") {
      const send = (confirmation) => request(method, url, confirmation ? { ...(body || {}), ...confirmation } : body);
      return shown(await window.drivebench.moving(send, { host: dialog, what }), slot);
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
      renderFault(status.present_fault);
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

    // The present fault in the manual's words (device/drive/faults.py; the same markup as node/_fault_words.html)
    function renderFault(fault) {
      const box = panel.querySelector("#ctl-fault");
      if (!box) return;
      box.hidden = !fault;
      const slot = box.querySelector("#ctl-fault-text");
      slot.replaceChildren();
      if (!fault) return;
      const add = (tag, text, cls) => {
        const el = document.createElement(tag);
        el.textContent = text;
        if (cls) el.className = cls;
        slot.append(el, " ");
        return el;
      };
      add("code", fault.code);
      const own = fault.fault;
      const label = own ? own.label : fault.vendor_error;
      if (label) add("strong", label, "fault-label");
      add("span", own && own.text ? own.text : fault.vendor_text || fault.class_text, "fault-text");
      const noText = _("this fault number has no text in the device profile");
      if (own && !own.text) add("span", "(" + noText + ")", "muted");
      if (own && own.fields.length) add("span", `[${own.fields.join(", ")}]`, "muted small-text");
      const remedy = own ? own.remedy : fault.remedy;
      if (remedy) {
        slot.append(document.createElement("br"));
        const line = add("span", "", "fault-remedy");
        const head = document.createElement("strong");
        head.textContent = _("Remedy:");
        line.append(head, " " + remedy);
      }
      if (own && own.source) {
        slot.append(document.createElement("br"));
        const sourceWord = _("Source:");
        add("span", sourceWord + " " + own.source, "muted small-text fault-source");
      }
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
      const status = await call("POST", `${api}/commands/${key}`, {}, result, moving.has(key) ? label : "");
      if (status) {
        render(status);
        const note = panel.querySelector("#ctl-command-note");  // why the command may do nothing (P0700 ...)
        note.hidden = !status.command_note;
        note.textContent = status.command_note || "";
      }
    }

    panel.querySelectorAll("[data-command]").forEach((button) =>
      button.addEventListener("click", () => command(button.dataset.command, button.textContent.trim())));

    const setpointForm = panel.querySelector("#ctl-setpoint");
    if (setpointForm) setpointForm.addEventListener("submit", async (event) => {
      event.preventDefault();
      const value = parseFloat(event.target.value.value);
      if (Number.isNaN(value)) { showError(window.drivebench.errorBox(_("Setpoint"), _("enter a number"))); return; }
      const status = await call("PUT", `${api}/setpoint`, { value }, result, _("Setpoint"));
      if (status) render(status);
    });

    // Jog is hold-to-run. A press asks the server, which names what it would send (428); the dialog lists it and its
    // confirm button is the hold-to-run button for exactly that jog: the motor turns while it is held and stops on
    // release (the keep-alive stops it too if the page goes away mid-jog). Every press asks again, so a changed
    // speed is always what the dialog shows.
    let jogQueue = Promise.resolve();  // start and stop go out in the order pressed and released
    const jogSend = (body) => (jogQueue = jogQueue.then(() => request("POST", `${api}/jog`, body)));
    panel.querySelectorAll("[data-jog]").forEach((button) => {
      const direction = Number(button.dataset.jog);
      button.addEventListener("pointerdown", async (event) => {
        event.preventDefault();
        const speedInput = panel.querySelector("#ctl-jog-speed");
        const speed = speedInput ? parseFloat(speedInput.value) : NaN;
        const body = { direction, ...(Number.isNaN(speed) ? {} : { speed }) };
        const asked = await jogSend(body);
        if (asked.status !== 428 || !asked.data || !("confirm_node" in asked.data)) {
          if (shown(asked)) await jogSend({ direction: 0 });  // never runs unconfirmed: stopped at once
          return;
        }
        const how = panel.querySelector("#ctl-jog-how");
        const way = direction > 0 ? _("forward") : _("reverse");
        const okLabel = _("Hold to jog {way} at {value} {unit}", { way,
          value: Number.isNaN(speed) ? how.dataset.value : speed, unit: how.dataset.unit });
        const confirmation = { confirm: asked.data.confirm_node, confirm_values: asked.data.confirm_values };
        await window.drivebench.askMoving(asked.data, { host: dialog, what: button.textContent.trim(), okLabel, hold: {
          press: async () => {
            const answer = await jogSend({ ...body, ...confirmation });
            if (answer.status === 428) dialog.close();  // it would send something else now: press Jog again
            const status = shown(answer);
            if (status) render(status);
          },
          release: async () => { const status = shown(await jogSend({ direction: 0 })); if (status) render(status); },
        } });
      });
    });

    panel.querySelectorAll("input[name=ctl-mode]").forEach((radio) => radio.addEventListener("change", async () => {
      const status = await call("PUT", `${api}/mode`, { mode: Number(radio.value) });
      if (status) render(status);
    }));

    // --- CiA 402 motion (a drive without a vendor control section): profile position, profile velocity, homing ---
    const motion = panel.querySelector("#ctl-motion");
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
        const status = await call("POST", `${api}/move`, { target, relative: form.relative.checked,
          immediate: form.immediate.checked, ...(Number.isNaN(velocity) ? {} : { velocity }) }, result, move);
        if (status) render(status);
      });
      motion.querySelectorAll("form[data-mode]").forEach((form) => form.addEventListener("submit", async (event) => {
        event.preventDefault();  // profile velocity (3) or torque (4): the mode first, then its setpoint
        const mode = Number(form.dataset.mode);
        const value = parseFloat(form.value.value);
        if (Number.isNaN(value)) { showError(window.drivebench.errorBox(_("Target"), _("enter a number"))); return; }
        if (currentMode !== mode && !await call("PUT", `${api}/mode`, { mode })) return;
        const status = await call("PUT", `${api}/setpoint`, { value }, result, _("Target (mode {mode})", { mode }));
        if (status) render(status);
      }));
      const cyclicForm = motion.querySelector("#ctl-cyclic");
      if (cyclicForm) {
        cyclicForm.addEventListener("submit", async (event) => {
          event.preventDefault();
          const value = parseFloat(event.target.value.value);
          if (Number.isNaN(value)) { showError(window.drivebench.errorBox(_("Target"), _("enter a number"))); return; }
          const sent = await call("POST", `${api}/cyclic`, { value }, result, _("Cyclic synchronous setpoint"));
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
        const status = await call("POST", `${api}/home`, { method: Number(select.value) }, result,
                                  _("Homing, method {method}", { method: select.options[select.selectedIndex].text }));
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
               `${step.printed ? `<div class="muted mono small-text">${esc(_("manual: {steps}", { steps: step.printed }))}</div>` : ""}` +
               `${step.note ? `<div class="muted small-text step-note">${esc(step.note)}</div>` : ""}</td>` +
               `<td>${telegrams}</td><td>${r ? esc(r.message) : ""}</td></tr>`;
      }).join("");
      const pre = run.preconditions.map((p) => `<li>${esc(p)}</li>`).join("");
      const gaps = (run.missing || []).map((m) => `<li>${esc(m)}</li>`).join("");
      // The texts first: pybabel's JavaScript extractor does not see _() inside a template literal.
      const allAnswered = _("All {count} steps answered as the manual expects.", { count: run.steps.length });
      const beforeStarting = _("Before starting (not sent over CAN):");
      const notOffered = _("Not offered by this profile (no step writes it):");
      const [stepHead, telegramsHead, answerHead] = [_("Step"), _("Telegrams"), _("Answer")];
      const banner = run.failed ? `<div class="error" role="alert">${esc(run.failed)}</div>`
        : run.finished ? `<div class="ok-note">${esc(allAnswered)}</div>` : "";
      const next = run.finished ? null : run.steps[run.position];
      runBox.innerHTML = `<p><strong>${esc(run.title)}</strong> · ${esc(run.source)}</p>` +
        (pre ? `<p class="muted">${esc(beforeStarting)}</p><ul class="muted">${pre}</ul>` : "") +
        (gaps ? `<p class="muted">${esc(notOffered)}</p><ul class="muted ctl-missing">${gaps}</ul>` : "") + banner +
        `<div class="ctl-run-scroll"><table class="ctl-run"><thead><tr><th>#</th><th>${esc(stepHead)}</th>` +
        `<th>${esc(telegramsHead)}</th><th>${esc(answerHead)}</th></tr></thead><tbody>${rows}</tbody></table></div>` +
        (next && next.field ? stepForm(next) : "");
      if (next && next.field) showPresent(next.field);
      runOpen = !run.finished;
      nextButton.disabled = refused || watching || !runOpen;
      const row = runBox.querySelector("tr.next, tr.failed");
      const scroller = runBox.querySelector(".ctl-run-scroll");
      if (row && scroller) scroller.scrollTop = Math.max(0, row.offsetTop - scroller.clientHeight / 2);  // not the page
    }

    // A parameter step is a form: the parameter with its unit, range, present value and the profile's proposal;
    // "Next step" writes what the field holds (checked against the range before anything is sent, read back).
    function stepForm(step) {
      const f = step.field;
      const unit = f.unit ? ` ${f.unit}` : "";
      const known = f.min !== null || f.max !== null;
      const range = known ? _("Range {min} … {max}{unit}", { min: f.min === null ? "–" : f.min,
                                                              max: f.max === null ? "–" : f.max, unit })
        : _("Range: no source read gives one (see the source below)");
      const label = `${f.ref} ${f.name}`;
      const presentLabel = _("Present value:");
      const sourceLabel = _("Source:");
      const proposal = f.proposal === null ? "" : String(f.proposal);
      const options = Object.entries(f.selection);
      const input = options.length
        ? `<select id="ctl-step-value" name="value">${options.map(([value, text]) =>
            `<option value="${esc(value)}"${value === proposal ? " selected" : ""}>${esc(value)} = ${esc(text)}</option>`).join("")}</select>`
        : `<input id="ctl-step-value" name="value" type="number" step="any" value="${esc(proposal)}"` +
          `${f.min !== null ? ` min="${esc(f.min)}"` : ""}${f.max !== null ? ` max="${esc(f.max)}"` : ""}>`;
      return `<div id="ctl-step-form" class="ctl-step-form" data-ref="${esc(f.ref)}">` +
        `<label for="ctl-step-value"><strong>${esc(label)}</strong></label> ${input} <span>${esc(unit)}</span>` +
        `<div class="muted"><span id="ctl-step-range">${esc(range)}</span> · ${esc(presentLabel)} ` +
        `<span id="ctl-step-present" class="mono">…</span></div>` +
        (f.help ? `<div class="small-text">${esc(f.help)}</div>` : "") +
        (f.source ? `<div class="muted small-text">${esc(sourceLabel)} ${esc(f.source)}</div>` : "") + `</div>`;
    }

    async function showPresent(field) {
      const answer = await request("GET", `${api.replace(/\/control$/, "")}/parameters/${encodeURIComponent(field.ref)}`);
      const slot = runBox.querySelector("#ctl-step-present");
      if (!slot || runBox.querySelector("#ctl-step-form").dataset.ref !== field.ref) return;
      slot.textContent = answer.status === 200 ? answer.data.display
        : _("not read ({reason})", { reason: (answer.data && answer.data.detail) || answer.status });
    }

    function stepValue() {
      const input = runBox.querySelector("#ctl-step-value");
      if (!input || input.value.trim() === "") return {};
      const number = Number(input.value);
      return { value: Number.isFinite(number) ? number : input.value };
    }

    async function showRun(found) {  // a reload shows where this node's last run stands
      if (!found) return;
      runId = found.id;
      renderRun(found);
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
        nextButton.disabled = true;
        const slot = document.createElement("div");
        const what = step ? _("Step {number}: {title}", { number: step.number, title: step.title }) : "";
        const run = await call("POST", `${api}/runs/${runId}/next`, stepValue(), slot, what);
        if (run) renderRun(run); else { runBox.prepend(slot); nextButton.disabled = refused || watching; }
      });
      request("GET", `${api}/runs`).then((answer) => {
        if (answer.status === 200 && !runId) showRun(answer.data.find((r) => !r.finished) || answer.data[0]);
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
