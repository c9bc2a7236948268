// Node page: the progress of read jobs, fed by the job websocket (/ws/jobs/{id}, JSON messages).
(function () {
  // One decimal as the page's language writes it (<html lang>: 2.5 or 2,5).
  const oneDecimal = new Intl.NumberFormat(document.documentElement.lang || "en",
                                           { minimumFractionDigits: 1, maximumFractionDigits: 1, useGrouping: false });
  function fmtEta(s) {
    if (s === null || s === undefined) return "";
    const _ = window.drivebench.gettext;
    return " · " + (s < 60 ? _("ETA {seconds} s", { seconds: oneDecimal.format(s) })
      : _("ETA {minutes} min", { minutes: Math.round(s / 60) }));
  }

  // Re-read the parameter rows; a refresh in flight would swap out the element a queued one belongs to, so the
  // next one waits until that swap has settled.
  function refreshRows(selector) {
    const rows = document.querySelector(selector);
    if (!rows) return;
    if (rows.classList.contains("htmx-request")) {
      document.body.addEventListener("htmx:afterSettle", () => refreshRows(selector), { once: true });
      return;
    }
    htmx.trigger(rows, "refresh");
  }

  // Boxes watched, kept here and not as a mark on the element: Back to the tab restores htmx's snapshot of the page,
  // marks included, and a marked copy of a running job's box would never move again.
  const watched = new WeakSet();

  function watch(box) {
    if (watched.has(box)) return;
    watched.add(box);
    box.dataset.refreshed = String(Date.now());
    const bar = box.querySelector("progress");
    const text = box.querySelector(".job-text");
    // reconnects while the job runs and its box is shown (the server closes the socket after the final message,
    // with 4404 for a job it does not know)
    window.drivebench.liveSocket(window.drivebench.url(`/ws/jobs/${encodeURIComponent(box.dataset.job)}`), {
      keepOpen: (event) => event.code !== 4404 && (box.dataset.state || "running") === "running" &&
        document.body.contains(box),
      onMessage: (msg) => show(box, msg, bar, text),
    });
  }

  function show(box, msg, bar, text) {
    const p = msg.progress;
    bar.max = Math.max(p.total, 1);
    bar.value = p.done - p.failed - (p.not_done || 0);  // what was done as asked: a failed read is no progress
    const _ = window.drivebench.gettext;
    // The texts first: pybabel's JavaScript extractor does not see _() inside a template literal.
    const failed = (p.failed ? " · " + _("{count} failed", { count: p.failed }) : "") +
      (p.not_done ? " · " + _("{count} not read", { count: p.not_done }) : "");
    const state = { done: _("done"), cancelled: _("cancelled"), failed: _("failed"), incomplete: _("incomplete") }[msg.state] || msg.state;
    let line = `${msg.title}: ${p.done}/${p.total} · ${oneDecimal.format(p.rate_per_s)}/s${failed}`;
    if (msg.state === "running") line += fmtEta(p.eta_s);
    else line += " · " + _("{state} in {seconds} s", { state, seconds: oneDecimal.format(p.elapsed_s) });
    if (msg.error) line += ` · ${msg.error}`;
    if (msg.state === "incomplete" && msg.notes && msg.notes.length) line += " · " + msg.notes.join(" · ");
    text.textContent = line;
    text.title = (msg.notes || []).join("\n");
    box.dataset.state = msg.state;
    const rows = document.querySelector(box.dataset.refresh);
    // Values appear while the job runs: the rows are re-read from the server at most every 2 s, never while
    // the user is in one of them (typing a new value).
    if (msg.state === "running" && rows && !rows.contains(document.activeElement) &&
        !rows.classList.contains("htmx-request") && Date.now() - Number(box.dataset.refreshed) > 2000) {
      box.dataset.refreshed = String(Date.now());
      htmx.trigger(rows, "refresh");
    }
    if (msg.state !== "running") {
      box.classList.add("finished", `state-${msg.state}`);
      refreshRows(box.dataset.refresh);
    }
  }

  // "Read shown": the rows of one group, read in one batch request (POST …/parameters:read); each row's value cell
  // gets its value or the error in words (textContent only: values come from the device).
  function groupRows(header) {
    const rows = [];
    for (let row = header.nextElementSibling; row && !row.classList.contains("group-row"); row = row.nextElementSibling) {
      if (row.dataset.ref) rows.push(row);
    }
    return rows;
  }

  function showValue(cell, item) {
    cell.replaceChildren();
    const span = document.createElement("span");
    if (item.ok) {
      const v = item.value;
      span.className = "v";
      span.textContent = v.display;
      span.title = window.drivebench.gettext("raw {raw}{text} · read now (batch)", { raw: v.raw, text: v.text ? " · " + v.text : "" });
    } else {
      span.className = "badge bad read-error";
      span.textContent = item.error.detail;
      span.title = item.error.abort_code ? `${item.error.abort_code} ${item.error.abort_text || ""}` : item.error.title;
    }
    cell.append(span);
  }

  async function readShown(button) {
    const header = button.closest("tr.group-row");
    const rows = groupRows(header);
    if (!rows.length) return;
    button.disabled = true;
    button.setAttribute("aria-busy", "true");
    try {
      const answer = await fetch(`${button.dataset.api}/parameters:read`, {
        method: "POST",
        headers: { "Content-Type": "application/json", Accept: "application/json" },
        body: JSON.stringify({ refs: rows.map((row) => row.dataset.ref) }),
      });
      const body = await answer.json();
      if (!answer.ok) throw new Error(body.detail || `HTTP ${answer.status}`);
      body.items.forEach((item, i) => showValue(rows[i].querySelector("td.val"), item));
    } catch (error) {
      const slot = document.querySelector("#job-slot");
      if (slot) {
        const box = document.createElement("div");
        box.className = "error";
        box.setAttribute("role", "alert");
        box.textContent = window.drivebench.gettext("Reading the group failed: {reason}", { reason: error.message });
        slot.replaceChildren(box);
      }
    } finally {
      button.disabled = false;
      button.removeAttribute("aria-busy");
    }
  }

  // The hex/decimal switch of a row (integers without scaling): the raw value the server sent, shown in the other
  // base; the choice is kept per parameter while the page is open, so a re-read row keeps it.
  const radixChoice = new Map();

  function inBase(span, base) {
    const size = Number(span.dataset.size) || 4;
    let raw = BigInt(span.dataset.raw);
    const unit = span.dataset.unit ? " " + span.dataset.unit : "";
    if (base === "hex") {
      if (raw < 0n) raw += 1n << BigInt(size * 8);  // two's complement in the data type's width
      return "0x" + raw.toString(16).toUpperCase().padStart(size * 2, "0") + unit;
    }
    return raw.toString() + unit;
  }

  function showBase(row, base) {
    const span = row.querySelector("td.val .v[data-raw]");
    const button = row.querySelector("button.radix");
    if (!span || !button) return;
    span.textContent = inBase(span, base);
    span.dataset.shown = base;
    const _ = window.drivebench.gettext;
    button.textContent = base === "hex" ? _("dec") : _("hex");
  }

  htmx.onLoad((root) => window.drivebench.within(root, "tr.prow").forEach((row) => {
    const base = radixChoice.get(row.dataset.ref);
    if (base) showBase(row, base);
  }));

  document.addEventListener("click", (event) => {
    const button = event.target.closest && event.target.closest("button.read-shown");
    if (button) readShown(button);
    const radix = event.target.closest && event.target.closest("button.radix");
    if (radix) {
      const row = radix.closest("tr.prow");
      const span = row && row.querySelector("td.val .v[data-raw]");
      if (!span) return;
      const base = (span.dataset.shown || span.dataset.base) === "hex" ? "dec" : "hex";
      radixChoice.set(row.dataset.ref, base);
      showBase(row, base);
    }
    const close = event.target.closest && event.target.closest("[data-close-panel]");
    if (close) {
      const panel = document.getElementById("param-panel");
      if (panel) panel.replaceChildren();
    }
  });

  htmx.onLoad((root) => window.drivebench.within(root, "[data-job]").forEach(watch));
})();

