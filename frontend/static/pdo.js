// PDO tab: the mapping editor (picker, reorder, live byte layout, limits) and the live process data socket.
(() => {
  if (window.drivebenchPdo) { window.drivebenchPdo(); return; }
  const el = window.drivebench.el;  // names and units come from profiles: elements with text, never markup
  const _ = window.drivebench.gettext;
  const MAX_BITS = 64;
  const COLORS = 8;

  function layout(el, entries) {
    el.innerHTML = "";
    let offset = 0;
    entries.forEach((e, i) => {
      const bytes = Math.max(1, Math.round(e.bits / 8));
      const cell = document.createElement("span");
      cell.className = `byte-cell c${i % COLORS}` + (offset + e.bits > MAX_BITS ? " over" : "");
      cell.style.flexGrow = bytes;
      cell.title = _("{ref} {name}: byte {bytes}, {bits} bits", { ref: e.ref, name: e.name, bits: e.bits,
        bytes: `${offset / 8}${bytes > 1 ? "…" + (offset / 8 + bytes - 1) : ""}` });
      cell.textContent = `${e.ref}`;
      el.appendChild(cell);
      offset += e.bits;
    });
    for (let b = Math.ceil(offset / 8); b < 8; b++) {
      const free = document.createElement("span");
      free.className = "byte-cell free";
      free.textContent = `${b}`;
      free.title = _("byte {byte}: free", { byte: b });
      el.appendChild(free);
    }
  }

  // Same words as drivebench.services.pdos.pdo.transmission_text (CiA 301 table of transmission types).
  function transmissionText(t, direction) {
    if (!Number.isInteger(t) || t < 0 || t > 255) return _("not a transmission type (0 ... 255)");
    if (t === 0) return direction === "tpdo" ? _("synchronous, acyclic (sent on SYNC after a change)") : _("synchronous, acyclic");
    if (t <= 240) return t === 1 ? _("synchronous, every SYNC") : _("synchronous, every {n}. SYNC", { n: t });
    if (t === 252 || t === 253) return t === 252 ? _("RTR only, synchronous") : _("RTR only, event-driven");
    if (t === 254) return _("event-driven (manufacturer-specific)");
    if (t === 255) return _("event-driven (device profile)");
    return _("reserved");
  }

  // Cards set up, kept here and not as a mark on the element: Back to this tab restores htmx's snapshot of the page,
  // marks included, and a marked copy would get no editor.
  const ready = new WeakSet();

  function initCard(card) {
    if (ready.has(card)) return;
    ready.add(card);
    const applied = JSON.parse(card.dataset.entries || "[]");
    const current = card.querySelector('.byte-layout[data-layout="current"]');
    if (current) layout(current, applied);
    const form = card.querySelector(".pdo-apply");
    if (!form) return;
    const mappable = JSON.parse(card.dataset.mappable || "[]");
    const maxEntries = Number(card.dataset.maxEntries);
    let entries = applied.map((e) => ({ ...e }));
    const list = form.querySelector(".pdo-entries");
    const picker = form.querySelector(".pdo-picker");
    const search = form.querySelector(".pdo-search");
    const total = form.querySelector(".pdo-total");
    const limit = form.querySelector(".pdo-limit");
    const field = form.querySelector(".pdo-entries-field");
    const submit = form.querySelector("button[type=submit]");
    const bits = () => entries.reduce((sum, e) => sum + e.bits, 0);

    let dragged = -1;

    function render() {
      list.innerHTML = "";
      entries.forEach((e, i) => {
        const li = document.createElement("li");
        li.draggable = true;  // drag to reorder (the arrows do the same from the keyboard)
        li.dataset.position = i;
        li.addEventListener("dragstart", (ev) => { dragged = i; li.classList.add("dragging"); ev.dataTransfer.effectAllowed = "move"; ev.dataTransfer.setData("text/plain", String(i)); });
        li.addEventListener("dragend", () => li.classList.remove("dragging"));
        li.addEventListener("dragover", (ev) => { ev.preventDefault(); li.classList.add("drop-here"); });
        li.addEventListener("dragleave", () => li.classList.remove("drop-here"));
        li.addEventListener("drop", (ev) => {
          ev.preventDefault();
          const from = dragged >= 0 ? dragged : Number(ev.dataTransfer.getData("text/plain"));
          dragged = -1;
          if (Number.isNaN(from) || from === i) { render(); return; }
          const [moved] = entries.splice(from, 1);
          entries.splice(i, 0, moved);
          render();
        });
        const buttons = [["up", _("Move up"), "↑", i === 0], ["down", _("Move down"), "↓", i === entries.length - 1],
                         ["remove", _("Remove"), "✕", false]].map(([act, title, text, disabled]) => {
          const b = el("button", { type: "button", className: "icon", title, disabled }, text);
          b.dataset.act = act;
          return b;
        });
        li.append(el("span", { className: "name" }, e.name), " ", el("span", { className: "mono muted" }, e.ref), " ",
                  el("span", { className: "muted" }, _("{bits} bit", { bits: e.bits })), " ", el("span", { className: "entry-buttons" }, ...buttons));
        buttons.forEach((b) => b.addEventListener("click", () => {
          if (b.dataset.act === "remove") entries.splice(i, 1);
          else {
            const j = b.dataset.act === "up" ? i - 1 : i + 1;
            [entries[i], entries[j]] = [entries[j], entries[i]];
          }
          render();
        }));
        list.appendChild(li);
      });
      if (!entries.length) list.replaceChildren(el("li", { className: "empty" }, _("No entries: the PDO carries nothing.")));
      const used = bits();
      total.textContent = _("{used} / 8 bytes · {count} / {max} entries", { used: used / 8, count: entries.length, max: maxEntries });
      total.classList.toggle("over", used > MAX_BITS || entries.length > maxEntries);
      layout(form.querySelector('.byte-layout[data-layout="edit"]'), entries);
      const problems = [];
      if (used > MAX_BITS) problems.push(_("{used} bytes: a PDO carries at most 8.", { used: used / 8 }));
      if (entries.length > maxEntries) problems.push(_("{count} entries: this PDO takes at most {max}.", { count: entries.length, max: maxEntries }));
      limit.textContent = problems.join(" ");
      submit.disabled = problems.length > 0;
      field.value = entries.map((e) => `0x${e.index.toString(16).toUpperCase().padStart(4, "0")}.${e.subindex}`).join(",");
      renderPicker();
    }

    function renderPicker() {
      const query = search.value.trim().toLowerCase();
      picker.innerHTML = "";
      const used = bits();
      mappable.filter((m) => !query || `${m.name} ${m.ref} 0x${m.index.toString(16)}`.toLowerCase().includes(query))
        .forEach((m) => {
          const li = document.createElement("li");
          const full = entries.length >= maxEntries;
          const tooLong = used + m.bits > MAX_BITS;
          const button = el("button", { type: "button", className: "small secondary" }, _("Add"));
          li.append(button, " ", el("span", { className: "name" }, m.name), " ", el("span", { className: "mono muted" }, m.ref), " ",
                    el("span", { className: "muted" }, _("{bits} bit", { bits: m.bits }) + (m.unit ? ", " + m.unit : "")), " ",
                    el("span", { className: "why warn-text" }));
          button.setAttribute("aria-label", _("Add {ref} {name}", { ref: m.ref, name: m.name }));
          if (full || tooLong) {
            button.disabled = true;
            li.querySelector(".why").textContent = full ? _("no entry left") : _("would need {bytes} bytes", { bytes: (used + m.bits) / 8 });
          }
          button.addEventListener("click", () => { entries.push({ ...m }); render(); });
          picker.appendChild(li);
        });
      if (!mappable.length) picker.replaceChildren(el("li", { className: "empty" }, _("The profile lists no PDO-mappable object for this direction.")));
    }

    search.addEventListener("input", renderPicker);
    const typeInput = form.querySelector('input[name="transmission_type"]');
    const typeText = form.querySelector(".pdo-type-text");
    if (typeInput && typeText) {
      const typeNotes = JSON.parse(card.dataset.typeNotes || "{}");
      const showType = () => {
        const t = Number(typeInput.value);
        const note = typeNotes[t];
        typeText.textContent = typeInput.value === "" ? "" : transmissionText(t, card.dataset.direction) + (note ? ` - ${note}` : "");
        typeText.classList.toggle("warn-text", Boolean(note));
      };
      typeInput.addEventListener("input", showType);
      showType();
    }
    render();
  }

  // A failed apply answers 502 with the card (its step report): show it in place of the card.
  document.body.addEventListener("htmx:beforeSwap", (event) => {
    const xhr = event.detail.xhr;
    if (xhr.status >= 400 && xhr.getResponseHeader("X-PDO-Report")) {
      event.detail.shouldSwap = true;
      event.detail.isError = false;
      event.detail.target = event.detail.requestConfig.elt.closest(".pdo-card");
      event.detail.swapOverride = "outerHTML";
      event.detail.serverResponse = xhr.responseText;
    }
  });

  let socket = null;  // drivebench.liveSocket of the PDO tab shown (socketTab)
  let socketTab = null;
  let clientId = "";

  function receive(msg, state) {
    if (msg.type === "hello") {
      clientId = msg.client_id;
      document.querySelectorAll(".client-id").forEach((input) => { input.value = clientId; });
    } else if (msg.type === "samples") {
      msg.samples.forEach((sample) => sample.signals.forEach((sig) => {
        document.querySelectorAll(`.live[data-cob="${CSS.escape(String(sample.cob_id))}"][data-ref="${CSS.escape(sig.ref)}"]`).forEach((cell) => {
          // a word (status word, COB-ID) in hex with its bit names, an amount in decimal with its unit
          let text = sig.value === null ? "–" : sig.hex ? sig.hex : `${sig.value}${sig.unit ? " " + sig.unit : ""}`;
          if (sig.text) text += ` (${sig.text})`;
          if (sample.direction === "rpdo") text = _("sent {value}", { value: text });
          cell.textContent = text;
          cell.title = `${text}\n` + _("raw {raw} · frame {frame} · {time}", { raw: sig.raw, frame: sample.data,
            time: new Date(sample.t * 1000).toLocaleTimeString() });
          cell.classList.add("fresh");
          setTimeout(() => cell.classList.remove("fresh"), 300);
        });
      }));
    } else if (msg.type === "state") {
      const nmt = document.getElementById("pdo-nmt");
      if (nmt) nmt.textContent = msg.nmt_state;
      document.querySelectorAll('.pdo-card[data-direction="rpdo"]').forEach((card) => {
        const badge = card.querySelector(".pdo-cyclic-badge");
        if (badge) badge.hidden = !msg.cyclic.includes(Number(card.dataset.cobId));
      });
    } else if (msg.type === "error") {
      state.textContent = msg.detail; state.className = "badge warn";
    }
  }

  function connect(tab) {
    if (socket && !socket.stopped && socketTab === tab) return;
    // (the socket of a replaced tab element is left as it was: it closes with the page)
    const state = document.getElementById("pdo-ws-state");
    socketTab = tab;
    socket = window.drivebench.liveSocket(tab.dataset.ws, {
      onOpen: () => { state.textContent = _("connected"); state.className = "badge good"; },
      onClose: () => { state.textContent = _("disconnected"); state.className = "badge warn"; },
      keepOpen: () => document.body.contains(tab), retryMs: 2000,
      onMessage: (msg) => receive(msg, state),
    });
  }

  function init() {
    const tab = document.getElementById("pdo-tab");
    if (!tab) { if (socket) { socket.close(); socket = null; socketTab = null; } return; }
    document.querySelectorAll(".pdo-card").forEach(initCard);
    document.querySelectorAll(".client-id").forEach((input) => { input.value = clientId; });
    connect(tab);
  }

  document.body.addEventListener("htmx:afterSettle", (event) => {
    init();
    const target = event.detail.elt;
    if (socket && target && (target.classList?.contains("pdo-card") || target.id === "pdo-list")) {
      socket.send({ cmd: "reload" });  // the mapping may have changed: decode with the new one (when connected)
    }
  });
  document.body.addEventListener("htmx:historyRestore", init);
  window.drivebenchPdo = init;
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", init);
  else init();
})();
