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

  const sockets = new Map();  // keep-alive path -> socket

  function open(path, holder) {
    const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${path}?client=${window.drivebenchClientId}`;
    const socket = new WebSocket(url);
    sockets.set(path, socket);
    socket.onmessage = (event) => {
      const message = JSON.parse(event.data);
      if (message.type !== "held") return;
      const slot = holder.querySelector(".keepalive-state");
      if (slot) {
        slot.hidden = !message.nodes.length;
        slot.textContent = message.nodes.length ? `This tab keeps node${message.nodes.length > 1 ? "s" : ""} ` +
          `${message.nodes.join(", ")} running: closing it stops ${message.nodes.length > 1 ? "them" : "it"}.` : "";
      }
    };
    socket.onclose = () => {
      sockets.delete(path);
      if (document.body.contains(holder)) setTimeout(() => { if (!sockets.has(path)) open(path, holder); }, 1000);
    };
  }

  function scan() {
    document.querySelectorAll("[data-keepalive]").forEach((holder) => {
      if (!sockets.has(holder.dataset.keepalive)) open(holder.dataset.keepalive, holder);
    });
  }

  setInterval(() => {
    for (const socket of sockets.values()) {
      if (socket.readyState === WebSocket.OPEN) socket.send('{"cmd": "keepalive"}');
    }
  }, 500);
  document.addEventListener("DOMContentLoaded", scan);
  document.addEventListener("htmx:afterSettle", scan);
  window.addEventListener("pagehide", () => { for (const socket of sockets.values()) socket.close(); });
})();
