// Safety interlocks of a page that can start drives (Plant, Node): the tab's client id, and the keep-alive socket
// of what this tab started (NMT start, RPDOs). While the socket is open and sends a keep-alive every 500 ms, the
// nodes this tab holds keep running; closing the tab (or losing the connection) makes the server stop them.
// Loaded in <head>, before control.js: the Control tab's panel id is this tab's client id.
(() => {
  if (!window.drivebenchClientId) {
    let id = null;
    try { id = sessionStorage.getItem("drivebench.client"); } catch (e) { id = null; }
    if (!id) {
      id = Array.from(crypto.getRandomValues(new Uint8Array(8)), (b) => b.toString(16).padStart(2, "0")).join("");
      try { sessionStorage.setItem("drivebench.client", id); } catch (e) { /* one id per page load */ }
    }
    window.drivebenchClientId = id;
  }
  window.drivebenchPanelId = window.drivebenchPanelId || window.drivebenchClientId;

  const sockets = new Map();  // keep-alive path -> {socket (drivebench.liveSocket), holder}

  function show(message, entry) {
    if (message.type !== "held") return;
    const slot = entry.holder.querySelector(".keepalive-state");
    if (slot) {
      slot.hidden = !message.nodes.length;
      const _ = window.drivebench.gettext;
      const nodes = message.nodes.join(", ");
      slot.textContent = !message.nodes.length ? ""
        : message.nodes.length > 1 ? _("This tab keeps nodes {nodes} running: closing it stops them.", { nodes })
          : _("This tab keeps node {nodes} running: closing it stops it.", { nodes });
    }
  }

  function open(path, holder) {
    const entry = { holder };
    sockets.set(path, entry);
    entry.socket = window.drivebench.liveSocket(`${path}?client=${encodeURIComponent(window.drivebenchClientId)}`, {
      onMessage: (message) => show(message, entry),
      keepOpen: () => document.body.contains(entry.holder),
      onClose: () => { if (!document.body.contains(entry.holder) && sockets.get(path) === entry) sockets.delete(path); },
    });
  }

  function scan() {
    document.querySelectorAll("[data-keepalive]").forEach((holder) => {
      const entry = sockets.get(holder.dataset.keepalive);
      if (entry && !entry.socket.stopped) entry.holder = holder;  // the same part drawn again (htmx): socket stays
      else open(holder.dataset.keepalive, holder);
    });
  }

  setInterval(() => {
    for (const entry of sockets.values()) entry.socket.send({ cmd: "keepalive" });
  }, 500);
  document.addEventListener("DOMContentLoaded", scan);
  window.addEventListener("pageshow", (event) => { if (event.persisted) scan(); });  // back from the page cache
  document.addEventListener("htmx:afterSettle", scan);
  window.addEventListener("pagehide", () => { for (const entry of sockets.values()) entry.socket.close(); });
})();
