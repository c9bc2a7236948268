// Node page: the progress of read jobs, fed by the job websocket (/ws/jobs/{id}, JSON messages).
(function () {
  function fmtEta(s) {
    if (s === null || s === undefined) return "";
    return s < 60 ? ` · ETA ${s.toFixed(1)} s` : ` · ETA ${Math.round(s / 60)} min`;
  }

  function watch(box) {
    if (box.dataset.watching) return;
    box.dataset.watching = "1";
    const bar = box.querySelector("progress");
    const text = box.querySelector(".job-text");
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    const socket = new WebSocket(`${scheme}://${location.host}/ws/jobs/${box.dataset.job}`);
    socket.onmessage = (event) => {
      const msg = JSON.parse(event.data);
      const p = msg.progress;
      bar.max = Math.max(p.total, 1);
      bar.value = p.done;
      const failed = p.failed ? ` · ${p.failed} failed` : "";
      let line = `${msg.title}: ${p.done}/${p.total} · ${p.rate_per_s.toFixed(1)}/s${failed}`;
      if (msg.state === "running") line += fmtEta(p.eta_s);
      else line += ` · ${msg.state} in ${p.elapsed_s.toFixed(1)} s`;
      if (msg.error) line += ` · ${msg.error}`;
      text.textContent = line;
      text.title = (msg.notes || []).join("\n");
      box.dataset.state = msg.state;
      if (msg.state !== "running") {
        box.classList.add("finished", `state-${msg.state}`);
        const rows = document.querySelector(box.dataset.refresh);
        if (rows) htmx.trigger(rows, "refresh");
      }
    };
  }

  htmx.onLoad((root) => {
    const boxes = root.matches && root.matches("[data-job]") ? [root] : [];
    root.querySelectorAll && boxes.push(...root.querySelectorAll("[data-job]"));
    boxes.forEach(watch);
  });
})();
