// Line project page (issue 32): open a project file, export it, boot-up check of a session, concise DCF per node.
(() => {
  const db = window.drivebench;
  const _ = db.gettext;
  const el = db.el;
  const $ = (id) => document.getElementById(id);
  const api = (path) => db.url(`/api/line-projects${path}`);

  async function answer(response) {
    let data = null;
    try { data = await response.json(); } catch (e) { data = null; }
    return { status: response.status, data };
  }
  const failed = (target, { status, data }) => target.replaceChildren(db.problemBox(data, status));
  const selected = () => $("line-project").value;

  function showExports() {
    const id = selected();
    for (const link of document.querySelectorAll("#line-exports a[data-format]")) {
      link.href = id ? api(`/${id}/export?format=${link.dataset.format}`) : "#";
    }
    $("line-master-dcf").href = id ? api(`/${id}/master-dcf.bin`) : "#";
    $("line-exports").hidden = !id;
    $("line-none").hidden = Boolean(id);
    $("line-project-pick").hidden = !id;  // no empty list to choose from
    $("line-check").disabled = !id;  // both work on a project
    $("line-commission").disabled = !id;
    for (const note of document.querySelectorAll(".line-needs-project")) note.hidden = Boolean(id);
    loadNodes();
  }

  async function openFile(event) {
    event.preventDefault();
    const target = $("line-import-result");
    const file = $("line-file").files[0];
    if (!file) return;
    const response = await fetch(api(`/import?filename=${encodeURIComponent(file.name)}`),
                                 { method: "POST", body: await file.arrayBuffer() });
    const got = await answer(response);
    if (got.status !== 201) { failed(target, got); return; }
    const project = got.data;
    const option = el("option", { value: String(project.id) }, `${project.name} (${project.node_count})`);
    $("line-project").append(option);
    $("line-project").value = String(project.id);
    target.replaceChildren(
      el("p", { className: "ok", id: "line-opened" },
         _("Opened '{name}': planned network {network}, {count} nodes.",
           { name: project.name, network: project.network_id, count: project.node_count })),
      ...(project.notes.length ? [el("ul", { className: "line-notes" }, ...project.notes.map((note) => el("li", {}, note)))] : []));
    showExports();
  }

  function statusWord(node) {
    if (node.status === "ok") return [_("matches"), "line-status-ok"];
    if (node.status === "differs") return [_("differs"), "line-status-differs"];
    if (node.status === "unverified") return [_("not compared"), "line-status-unverified"];
    return node.mandatory ? [_("missing (mandatory)"), "line-status-missing-mandatory"]
                          : [_("missing (optional)"), "line-status-missing-optional"];
  }

  async function bootCheck() {
    const target = $("line-check-result");
    const id = selected();
    const session = $("line-session").value;
    if (!id || !session) {
      target.replaceChildren(db.errorBox(_("Choose a project and a session first."), ""));
      return;
    }
    target.replaceChildren(el("p", { className: "muted" }, _("Reading the identities ...")));
    const got = await answer(await fetch(api(`/${id}/boot-check?session=${encodeURIComponent(session)}`),
                                         { method: "POST" }));
    if (got.status !== 200) { failed(target, got); return; }
    const rows = got.data.nodes.map((node) => {
      const [word, className] = statusWord(node);
      return el("tr", { id: `line-check-node-${node.node_id}` },
                el("td", {}, String(node.node_id)), el("td", {}, node.name),
                el("td", {}, node.mandatory ? _("mandatory") : _("optional")),
                el("td", { className }, word), el("td", {}, node.messages.join(" ")));
    });
    const verdict = got.data.ok ? "ok" : "error";
    target.replaceChildren(
      el("p", { id: "line-check-verdict", className: verdict },
         got.data.ok ? _("The line matches its project.") : _("The line differs from its project.")),
      el("table", {}, el("thead", {}, el("tr", {}, ...[_("Node"), _("Name"), _("Needed"), _("Result"), _("Details")]
        .map((text) => el("th", {}, text)))), el("tbody", {}, ...rows)));
  }

  async function loadNodes() {
    const target = $("line-dcf-result");
    const id = selected();
    if (!id) { target.replaceChildren(); return; }
    const got = await answer(await fetch(api(`/${id}`)));
    if (got.status !== 200) { failed(target, got); return; }
    const nodes = got.data.project.nodes.filter((node) => node.profile && (node.parameter_set || Object.keys(node.pdo).length));
    if (!nodes.length) {
      target.replaceChildren(el("p", { className: "muted" }, _("No node of this project has a parameter set.")));
      return;
    }
    const buttons = nodes.map((node) => {
      const button = el("button", { type: "button", className: "small", id: `line-dcf-node-${node.node_id}` },
                        _("Node {node}: preview", { node: node.node_id }));
      button.addEventListener("click", () => preview(id, node.node_id));
      return button;
    });
    target.replaceChildren(el("p", {}, ...buttons), el("div", { id: "line-dcf-preview" }));
  }

  async function preview(id, nodeId) {
    const target = $("line-dcf-preview");
    const got = await answer(await fetch(api(`/${id}/nodes/${nodeId}/concise-dcf`)));
    if (got.status !== 200) { failed(target, got); return; }
    const hex = (value, width) => `0x${value.toString(16).toUpperCase().padStart(width, "0")}`;
    const rows = got.data.lines.map((line) => el("tr", {},
      el("td", {}, hex(line.index, 4)), el("td", {}, String(line.subindex)), el("td", {}, line.name),
      el("td", {}, line.value), el("td", { className: "mono" }, line.data)));
    const send = el("button", { type: "button", className: "primary", id: "line-dcf-send" },
                    _("Download to node {node}", { node: nodeId }));
    const result = el("div", { id: "line-dcf-sent", "aria-live": "polite" });
    send.addEventListener("click", () => download(id, nodeId, result));
    const file = api(`/${id}/nodes/${nodeId}/concise-dcf.bin`);
    target.replaceChildren(
      el("h3", {}, _("Node {node}: {count} entries, {size} bytes", { node: nodeId, count: got.data.count, size: got.data.size })),
      el("table", { id: "line-dcf-table" }, el("thead", {}, el("tr", {}, ...[_("Index"), _("Sub"), _("Name"), _("Value"), _("Bytes")]
        .map((text) => el("th", {}, text)))), el("tbody", {}, ...rows)),
      el("p", {}, el("a", { href: file, id: "line-dcf-file" }, _("Save as file")),
         " ", send),
      result);
  }

  async function download(id, nodeId, target) {
    const session = $("line-session").value;
    const got = await db.moving(async (confirmation) => answer(await fetch(
      api(`/${id}/nodes/${nodeId}/concise-dcf/download`),
      { method: "POST", headers: { "Content-Type": "application/json" },
        body: JSON.stringify({ session, ...(confirmation || {}) }) })),
      { what: _("Concise DCF to node {node}", { node: nodeId }) });
    if (got === null) return;
    if (got.status !== 200) { failed(target, got); return; }
    const done = _("{written} entries written ({transfer}).", { written: got.data.written, transfer: got.data.transfer });
    const outcome = got.data.failed.length ? "error" : "ok";
    target.replaceChildren(el("p", { className: outcome }, done),
                           ...got.data.failed.map((text) => el("p", { className: "error" }, text)));
  }

  // The "New line" wizard: a run of the chosen project on the chosen session, kept by the server (its page resumes it)
  async function commission() {
    const target = $("line-commission-result");
    const id = selected();
    const session = $("line-session").value;
    if (!id || !session) {
      target.replaceChildren(db.errorBox(_("Choose a project and a session first."), ""));
      return;
    }
    const got = await answer(await fetch(db.url(`/api/sessions/${encodeURIComponent(session)}/line-wizard`), {
      method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ project_id: Number(id) }) }));
    if (got.status !== 201) { failed(target, got); return; }
    window.location.assign(db.url(`/sessions/${encodeURIComponent(session)}/line-wizard/${got.data.id}`));
  }

  // The session's earlier runs, to resume one (the server keeps them; newest first). The page asks at its load and
  // at each change of the session: only the newest answer is shown, and a list that did not change is left as it
  // is (a link replaced between the press and the release of a click loses the click)
  let runsAsked = 0;
  async function listRuns() {
    const asked = ++runsAsked;
    const target = $("line-runs");
    const session = $("line-session").value;
    if (!session) { target.replaceChildren(); return; }
    const got = await answer(await fetch(db.url(`/api/sessions/${encodeURIComponent(session)}/line-wizard`)));
    if (asked !== runsAsked) return;  // a newer listing is on its way
    if (got.status !== 200) { target.replaceChildren(); return; }
    const items = got.data.slice(0, 10).map((run) => {
      const steps = Object.values(run.steps);
      const done = steps.filter((step) => step.state === "done").length;
      const link = el("a", {}, _("Run {run}: {project}, {done} of {count} steps done",
                                 { run: run.id, project: run.project_name, done, count: steps.length }));
      link.href = db.url(`/sessions/${encodeURIComponent(session)}/line-wizard/${run.id}`);
      return el("li", {}, link);
    });
    const same = target.children.length === items.length && items.every((item, i) => item.isEqualNode(target.children[i]));
    if (!same) target.replaceChildren(...items);
  }

  $("line-import").addEventListener("submit", openFile);
  $("line-project").addEventListener("change", showExports);
  $("line-session").addEventListener("change", listRuns);
  $("line-check").addEventListener("click", bootCheck);
  $("line-commission").addEventListener("click", commission);
  showExports();
  listRuns();
})();
