// The "New line" wizard page: the run from /api/sessions/{s}/line-wizard/{run}, each step's button runs that step
// (a 428 asks the confirmation dialog: app.js drivebench.moving), the found devices dragged (or chosen) onto the
// planned nodes, firmware files checked per node. The run is the server's: a reload shows where it stood, and while
// a step runs (this page's request or another tab's, or another DriveBench server's: the run's claim) the run is read
// again every two seconds until it has ended.
(() => {
  const db = window.drivebench;
  const _ = db.gettext;
  const el = db.el;
  const card = document.getElementById("wizard");
  if (!card) return;
  const base = db.url(`/api/sessions/${encodeURIComponent(card.dataset.session)}/line-wizard/${card.dataset.run}`);
  const errorSlot = document.getElementById("wizard-error");
  const STATES = { pending: _("pending"), running: _("running"), done: _("done"), failed: _("failed"),
                   interrupted: _("interrupted") };
  const WHAT = { scan: _("LSS fastscan"), assign: _("LSS addressing"), store: _("LSS store configuration"),
                 sets: _("Parameter-set downloads"), program: _("Program downloads") };
  let run = null;
  let sending = false;
  let rereading = null;
  const REREAD_MS = 2000;

  function request(method, url, body, isForm = false) {
    return db.requestJson(method, url, body, { headers: { "X-DriveBench-Client": window.drivebenchClientId },
                                                form: isForm });
  }

  function showError(answer) {
    errorSlot.replaceChildren(db.problemBox(answer.data, answer.status));
    errorSlot.scrollIntoView({ block: "nearest" });
  }

  function deviceText(device) {
    return `${device.serial} · ${device.device || _("unknown device")}`;
  }

  function renderFound() {
    const list = document.getElementById("found-devices");
    const assignedTo = Object.fromEntries(Object.entries(run.assignments).map(([node, serial]) => [serial, node]));
    if (!run.found.length) {
      list.replaceChildren(el("li", { className: "empty muted" }, _("No devices found yet: run the scan.")));
    } else {
      list.replaceChildren(...run.found.map((device) => {
        const item = el("li", { className: "found-device", draggable: true },
                        el("strong", { className: "mono" }, device.serial), " ",
                        el("span", {}, device.device || _("unknown device")),
                        el("div", { className: "muted mono" },
                           _("vendor {vendor}, product {product}, revision {revision}", device)),
                        el("div", { className: "found-target muted" },
                           assignedTo[device.serial] ? _("→ node {node}", { node: assignedTo[device.serial] }) : ""));
        item.dataset.serial = device.serial;
        item.id = ["found", device.serial].join("-");
        item.addEventListener("dragstart", (event) => {
          event.dataTransfer.setData("text/plain", device.serial);
          event.dataTransfer.effectAllowed = "move";
        });
        return item;
      }));
    }
    for (const select of document.querySelectorAll(".assign-choice")) {
      const node = select.dataset.node;
      select.replaceChildren(el("option", { value: "" }, _("none")),
                             ...run.found.map((device) => el("option", { value: device.serial }, deviceText(device))));
      select.value = run.assignments[node] || "";
      const zone = document.querySelector(`.drop-zone[data-node="${node}"]`);
      const serial = run.assignments[node];
      const device = run.found.find((found) => found.serial === serial);
      zone.textContent = device ? deviceText(device) : _("drop a device here");
      zone.classList.toggle("filled", Boolean(device));
      const done = run.assigned[node];
      zone.classList.toggle("addressed", Boolean(done));
    }
  }

  function renderFirmware() {
    for (const item of document.querySelectorAll(".firmware-node")) {
      const chosen = run.firmware[item.dataset.node];
      item.querySelector(".firmware-chosen").textContent = chosen
        ? _("{file} checked: {size} bytes, CRC32 {crc}", { file: chosen.name, size: chosen.size, crc: chosen.crc32 }) : "";
    }
  }

  function claimText(claim) {
    const at = claim.server.lastIndexOf(":");
    return _("on {host} (process {pid}) since {since}", { host: claim.server.slice(0, at),
      pid: claim.server.slice(at + 1), since: new Date(claim.since).toLocaleTimeString("en-GB", { hour12: false }) });
  }

  function rereadWhileRunning() {
    clearTimeout(rereading);
    if (!run || !run.claim || sending) return;
    rereading = setTimeout(async () => {
      const answer = await request("GET", base);
      if (answer.status === 200 && !sending) render(answer.data);
      else if (!sending) rereadWhileRunning();
    }, REREAD_MS);
  }

  function render(data) {
    run = data;
    for (const [name, step] of Object.entries(run.steps)) {
      const badge = document.getElementById(`state-${name}`);
      if (!badge) continue;
      badge.textContent = STATES[step.state] || step.state;
      badge.className = `badge step-state state-${step.state}`;
      document.getElementById(`claim-${name}`).textContent =
        run.claim && run.claim.step === name && step.state === "running" ? claimText(run.claim) : "";
      const failed = step.state === "failed";
      document.getElementById(`lines-${name}`).replaceChildren(...step.lines.map((line) => {
        const item = el("li", {}, line);
        item.classList.toggle("line-failed", failed);
        return item;
      }));
      const button = document.querySelector(`.run-step[data-step="${name}"]`);
      if (button && !button.dataset.label) button.dataset.label = button.textContent;
      if (button && step.runs > 0) button.textContent = _("{action} again", { action: button.dataset.label });
    }
    const steps = Object.values(run.steps);
    const verdict = document.getElementById("wizard-verdict");
    const complete = steps.every((step) => step.state === "done");
    verdict.textContent = complete ? _("every step done") : _("{done} of {count} steps done", {
      done: steps.filter((step) => step.state === "done").length, count: steps.length });
    verdict.className = complete ? "badge good" : "badge";
    renderFound();
    renderFirmware();
    rereadWhileRunning();
  }

  async function saveAssignments(assignments) {
    const answer = await request("PUT", `${base}/assignments`, assignments);
    if (answer.status !== 200) { showError(answer); renderFound(); return; }
    errorSlot.replaceChildren();
    render(answer.data);
  }

  function assign(node, serial) {
    const next = { ...run.assignments };
    for (const [other, given] of Object.entries(next)) if (given === serial) delete next[other];
    if (serial) next[node] = serial; else delete next[node];
    return saveAssignments(next);
  }

  for (const zone of document.querySelectorAll(".drop-zone")) {
    zone.addEventListener("dragover", (event) => { event.preventDefault(); zone.classList.add("over"); });
    zone.addEventListener("dragleave", () => zone.classList.remove("over"));
    zone.addEventListener("drop", (event) => {
      event.preventDefault();
      zone.classList.remove("over");
      const serial = event.dataTransfer.getData("text/plain");
      if (serial) assign(zone.dataset.node, serial);
    });
  }
  for (const select of document.querySelectorAll(".assign-choice")) {
    select.addEventListener("change", () => assign(select.dataset.node, select.value));
  }

  for (const input of document.querySelectorAll(".firmware-file")) {
    input.addEventListener("change", async () => {
      const file = input.files[0];
      if (!file) return;
      const form = new FormData();
      form.set("file", file);
      const answer = await request("POST", `${base}/firmware/${input.dataset.node}`, form, true);
      if (answer.status !== 200) { showError(answer); return; }
      errorSlot.replaceChildren();
      render(answer.data);
    });
  }

  for (const button of document.querySelectorAll(".run-step")) {
    button.addEventListener("click", async () => {
      const name = button.dataset.step;
      const body = name === "scan" ? { window_ms: Number(document.getElementById("wizard-window").value) } : {};
      const badge = document.getElementById(`state-${name}`);
      errorSlot.replaceChildren();
      for (const other of document.querySelectorAll(".run-step")) other.disabled = true;
      badge.textContent = STATES.running;
      sending = true;
      clearTimeout(rereading);
      try {
        const send = (confirmation) => request("POST", `${base}/steps/${name}`,
                                               confirmation ? { ...body, ...confirmation } : body);
        const answer = await db.moving(send, { what: WHAT[name] || "" });
        if (!answer) {
          badge.textContent = STATES[run.steps[name].state];
          errorSlot.replaceChildren(el("p", { className: "muted" }, _("Cancelled: nothing was sent.")));
          return;
        }
        if (answer.status !== 200) {
          badge.textContent = STATES[run.steps[name].state];
          showError(answer);
          return;
        }
        render(answer.data);
      } finally {
        sending = false;
        for (const other of document.querySelectorAll(".run-step")) other.disabled = false;
        rereadWhileRunning();
      }
    });
    // the page sends the steps' buttons disabled: a press before this script bound them would do nothing (a deferred
    // script on a loaded machine) and leave the user waiting for a question that never comes
    button.disabled = false;
  }

  request("GET", base).then((answer) => { if (answer.status === 200) render(answer.data); else showError(answer); });
})();
