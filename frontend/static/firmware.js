// Info tab, Firmware card: program download (CiA 302-3) through the JSON API (web/api/program.py). A file is checked
// first (nothing is sent), Download asks the confirmation dialog with what the server will send (app.js: moving),
// the progress (bytes, rate, ETA) comes over the job websocket, Cancel aborts the transfer, the result shows the
// software identification the device reports after the start.
(function () {
  const _ = window.drivebench.gettext;
  const el = window.drivebench.el;
  const kib = (bytes) => `${(bytes / 1024).toFixed(1)} KiB`;

  // the tab's panel id, as every page script sends it: the node lease the download takes names this tab (Firmware
  // card), not "the API" of whoever shares the host
  const tab = () => ({ "X-DriveBench-Client": window.drivebenchClientId });

  async function answer(response) {
    let data = null;
    try { data = await response.json(); } catch (e) { data = null; }
    return { status: response.status, data };
  }

  // cards bound, kept here and not as a mark on the element: Back to the tab restores htmx's snapshot, marks included
  const bound = new WeakSet();

  function bind(card) {
    if (bound.has(card)) return;
    bound.add(card);
    const api = card.dataset.api;
    const form = card.querySelector("#firmware-form");
    const check = card.querySelector("#firmware-check");
    const download = card.querySelector("#firmware-download");
    const progressBox = card.querySelector("#firmware-progress");
    const bar = progressBox.querySelector("progress");
    const figures = progressBox.querySelector(".firmware-figures");
    const cancel = card.querySelector("#firmware-cancel");
    const result = card.querySelector("#firmware-result");
    let fileId = null;
    let jobId = null;

    form.addEventListener("submit", async (event) => {
      event.preventDefault();
      download.hidden = true;
      result.replaceChildren();
      check.replaceChildren(el("p", { className: "muted" }, _("Checking the file…")));
      const got = await answer(await fetch(api + "/check", { method: "POST", headers: tab(), body: new FormData(form) }));
      if (got.status >= 400) { check.replaceChildren(window.drivebench.problemBox(got.data, got.status)); return; }
      const body = got.data;
      const file = body.file;
      const binary = _("binary");
      const kind = file.kind === "hex" ? "Intel HEX" : binary;
      const lines = [el("li", {}, _("{name}: {kind}, {bytes} bytes, CRC32 {crc}",
                                      { name: file.name, kind, bytes: file.bytes, crc: file.crc32 }))];
      if (file.start_address) lines.push(el("li", {}, _("Start address {address}", { address: file.start_address })));
      for (const note of body.notes) lines.push(el("li", { className: "muted" }, note));
      check.replaceChildren(el("ul", { className: "firmware-check-lines" }, ...lines));
      if (!body.ok) { check.append(window.drivebench.errorBox(_("Refused"), body.refused)); return; }
      fileId = body.file_id;
      download.hidden = false;
    });

    download.addEventListener("click", async () => {
      if (!fileId) return;
      const send = async (confirmation) => answer(await fetch(api + "/download", {
        method: "POST", headers: { "Content-Type": "application/json", ...tab() },
        body: JSON.stringify({ file_id: fileId, ...(confirmation || {}) }) }));
      const got = await window.drivebench.moving(send, { what: _("Program download"), note: _(
        "The device's program is stopped, the file written to its flash and the new program started: the drive " +
        "may run once it starts. The download goes on when this page closes; Cancel ends it.") });
      if (!got) return;
      if (got.status >= 400) { result.replaceChildren(window.drivebench.problemBox(got.data, got.status)); return; }
      follow(got.data);
    });

    cancel.addEventListener("click", async () => {
      if (jobId) await fetch(window.drivebench.url(`/api/jobs/${encodeURIComponent(jobId)}`), { method: "DELETE", headers: tab() });
    });

    function follow(job) {
      jobId = job.id;
      download.disabled = true;
      progressBox.hidden = false;
      cancel.hidden = false;
      result.replaceChildren();
      let state = "running";
      window.drivebench.liveSocket(window.drivebench.url(`/ws/jobs/${encodeURIComponent(job.id)}`), {
        keepOpen: (event) => event.code !== 4404 && state === "running" && document.body.contains(card),
        onMessage: (msg) => {
          const p = msg.progress;
          bar.max = Math.max(p.total, 1);
          bar.value = p.done;
          const eta = p.eta_s === null ? "" : " · " + _("ETA {seconds} s", { seconds: p.eta_s.toFixed(1) });
          figures.textContent = _("{done} of {total}", { done: kib(p.done), total: kib(p.total) }) +
            ` · ${kib(p.rate_per_s)}/s${eta}`;
          state = msg.state;
          if (state !== "running") finished();
        },
      });
    }

    async function finished() {
      download.disabled = false;
      cancel.hidden = true;
      const got = await answer(await fetch(`${api}/jobs/${encodeURIComponent(jobId)}`));
      const job = got.data || {};
      const res = job.result || {};
      const box = el("div", { className: job.state === "done" ? "ok" : "error", id: "firmware-outcome" });
      box.setAttribute("role", job.state === "done" ? "status" : "alert");
      if (job.state === "done") {
        box.append(el("strong", {}, _("Program downloaded and started.")), " ",
                   _("Software identification (0x1F56): {id}", { id: res.software_id || "–" }));
      } else {
        box.append(el("strong", {}, job.state === "cancelled" ? _("Cancelled") : _("Failed")), " ",
                   job.error || res.outcome || "");
      }
      result.replaceChildren(box);
    }
  }

  function scan(root) { window.drivebench.within(root, "#firmware-card").forEach(bind); }
  document.addEventListener("DOMContentLoaded", () => scan(document.body));
  document.body.addEventListener("htmx:load", (event) => scan(event.target));
  scan(document.body);
})();
