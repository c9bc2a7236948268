// The Line addressing (LSS) page: fastscan, the found devices, assign node ID + bit rate + store per device. Every
// step goes through the JSON API; the steps that reach every device on the bus ask (428, app.js: drivebench.moving).
(() => {
  const _ = window.drivebench.gettext;
  const card = document.getElementById("lss");
  if (!card) return;
  const base = window.drivebench.url(`/api/sessions/${encodeURIComponent(card.dataset.session)}/lss`);
  const tbody = card.querySelector("#lss-devices tbody");
  const errorSlot = card.querySelector("#lss-error");

  function request(method, url, body) {
    return window.drivebench.requestJson(method, url, body,
                                         { headers: { "X-DriveBench-Client": window.drivebenchClientId } });
  }

  // A step that reaches every device: asked when the server answers 428, sent again confirmed
  function confirmed(url, body, what) {
    const send = (confirmation) => request("POST", url, confirmation ? { ...body, ...confirmation } : body);
    return window.drivebench.moving(send, { what });
  }

  function stepItems(steps) {
    return steps.map((step) => window.drivebench.el("li", { className: step.ok ? "step-ok" : "step-failed" }, step.text));
  }

  function rows(scan) {
    card.querySelector("#lss-note").textContent = scan.note || "";
    if (!scan.devices.length) return;
    const template = card.querySelector("#lss-row");
    tbody.replaceChildren(...scan.devices.map((device) => {
      const row = template.content.firstElementChild.cloneNode(true);
      row.dataset.serial = device.serial;
      for (const key of ["vendor", "product", "revision", "serial"]) row.querySelector(`.${key}`).textContent = device[key];
      row.querySelector(".device").textContent = device.device || device.identified;
      row.querySelector(".assign").addEventListener("click", () => assign(row, device));
      row.querySelector(".inquire").addEventListener("click", () => inquire(row, device));
      return row;
    }));
  }

  async function assign(row, device) {
    const result = row.querySelector(".steps");
    const nodeId = Number(row.querySelector(".node-id").value);
    const rate = row.querySelector(".bitrate").value;
    const body = { vendor: device.vendor, product: device.product, revision: device.revision, serial: device.serial,
                   node_id: nodeId, bitrate: rate ? Number(rate) : null, store: row.querySelector(".store").checked };
    result.replaceChildren(window.drivebench.el("li", {}, _("addressing…")));
    const answer = await confirmed(`${base}/assign`, body, _("LSS addressing"));
    if (!answer) { result.replaceChildren(window.drivebench.el("li", {}, _("Cancelled: nothing was sent."))); return; }
    if (answer.status >= 400) {
      const done = stepItems((answer.data && answer.data.steps) || []);
      result.replaceChildren(...done, window.drivebench.el("li", { className: "step-failed" },
                                                           window.drivebench.problemBox(answer.data, answer.status)));
      return;
    }
    result.replaceChildren(...stepItems(answer.data));
    row.classList.add("assigned");
  }

  // read-only: switch state selective (that device only) and the identity inquiry; no confirmation
  async function inquire(row, device) {
    const result = row.querySelector(".steps");
    const select = { vendor: device.vendor, product: device.product, revision: device.revision, serial: device.serial };
    const answer = await request("POST", `${base}/inquire`, { select });
    if (answer.status >= 400) {
      result.replaceChildren(window.drivebench.el("li", { className: "step-failed" },
                                                  window.drivebench.problemBox(answer.data, answer.status)));
      return;
    }
    const a = answer.data;
    result.replaceChildren(window.drivebench.el("li", { className: "step-ok" }, _(
      "Inquired: vendor {vendor}, product {product}, revision {revision}, serial {serial}. {text}", a)));
  }

  // activate bit timing: reaches every device (428 names "all"); the answer says who followed, in words
  const activateForm = document.getElementById("lss-activate-form");
  if (activateForm) {
    activateForm.addEventListener("submit", async (event) => {
      event.preventDefault();
      const slot = document.getElementById("lss-activate-result");
      const button = activateForm.querySelector("button[type=submit]");
      const body = { bitrate: Number(activateForm.elements.bitrate.value),
                     switch_delay_ms: Number(activateForm.elements.switch_delay_ms.value),
                     configuration_first: activateForm.elements.configuration_first.checked };
      button.disabled = true;
      slot.replaceChildren(window.drivebench.el("p", {}, _("switching…")));
      try {
        const answer = await confirmed(`${base}/activate-bit-timing`, body, _("LSS activate bit timing"));
        if (!answer) { slot.replaceChildren(window.drivebench.el("p", {}, _("Cancelled: nothing was sent."))); return; }
        if (answer.status >= 400) { slot.replaceChildren(window.drivebench.problemBox(answer.data, answer.status)); return; }
        const a = answer.data;
        const shown = window.drivebench.el("p", {}, a.text);
        shown.classList.add(a.left_behind.length || a.nodes_silent.length ? "step-failed" : "step-ok");
        slot.replaceChildren(shown);
      } finally {
        button.disabled = false;
      }
    });
  }

  const identifyForm = document.getElementById("lss-identify-form");
  if (identifyForm) {
    identifyForm.addEventListener("submit", async (event) => {
      event.preventDefault();
      const slot = document.getElementById("lss-identify-result");
      const body = Object.fromEntries(new FormData(identifyForm).entries());
      const answer = await request("POST", `${base}/identify-remote`, body);
      if (answer.status >= 400) { slot.replaceChildren(window.drivebench.problemBox(answer.data, answer.status)); return; }
      const shown = window.drivebench.el("p", {}, answer.data.text);
      shown.classList.add(answer.data.answered ? "step-ok" : "step-failed");
      slot.replaceChildren(shown);
    });
  }

  card.querySelector("#lss-fastscan").addEventListener("click", async (event) => {
    const button = event.currentTarget;
    const status = card.querySelector("#lss-scan-result");
    button.disabled = true;
    errorSlot.replaceChildren();
    status.textContent = _("scanning…");
    try {
      const answer = await confirmed(`${base}/fastscan`, { window_ms: Number(card.querySelector("#lss-window").value) },
                                     _("LSS fastscan"));
      if (!answer) { status.textContent = _("Cancelled: nothing was sent."); return; }
      if (answer.status >= 400) {
        status.textContent = "";
        errorSlot.replaceChildren(window.drivebench.problemBox(answer.data, answer.status));
        return;
      }
      status.textContent = _("{count} devices found: {frames} frames in {seconds} s", {
        count: answer.data.devices.length, frames: answer.data.frames, seconds: answer.data.seconds.toFixed(2) });
      rows(answer.data);
    } finally {
      button.disabled = false;
    }
  });

  request("GET", base).then((answer) => { if (answer.status === 200) rows(answer.data); });
})();
