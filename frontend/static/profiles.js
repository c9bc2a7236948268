// Profiles page, one profile: a click (or Enter) on an entry row shows its details row below it.
document.addEventListener("click", (event) => toggleEntry(event.target.closest("tr.entry")));
document.addEventListener("keydown", (event) => {
  if (event.key === "Enter" && event.target.matches("tr.entry")) toggleEntry(event.target);
});
function toggleEntry(row) {
  const details = row && row.nextElementSibling;
  if (!details || !details.classList.contains("entry-detail")) return;
  details.hidden = !details.hidden;
  row.setAttribute("aria-expanded", String(!details.hidden));
}

// Many files at once: the upload's progress in the form's bar (htmx reports it per form; no inline handler under the
// Content-Security-Policy).
document.body.addEventListener("htmx:xhr:progress", (event) => {
  const form = event.target.closest && event.target.closest("form[data-upload-progress]");
  const bar = form && form.querySelector("progress");
  if (!bar) return;
  bar.hidden = false;
  if (event.detail.total) bar.value = (100 * event.detail.loaded) / event.detail.total;
});

// An uploaded EDS/DCF, one value edited in place (issue 34): the value goes to PATCH /api/profiles/{id}/objects/..,
// which checks it against the object's data type and writes only that key into the stored file; a refusal comes
// back in words and changes nothing.
(() => {
  const db = window.drivebench;
  const _ = db.gettext;
  const KEYS = { default: "DefaultValue", parameter_value: "ParameterValue", min: "LowLimit", max: "HighLimit" };
  const FILLED = { default: "default", min: "min", max: "max" };

  function typed(form, text) {
    const trimmed = text.trim();
    if (trimmed === "") return null;
    if (/STRING|DOMAIN/.test(form.dataset.type)) return text;
    const number = Number(trimmed);
    return Number.isFinite(number) ? number : trimmed; // not a number: the server says why in words
  }

  document.addEventListener("change", (event) => {
    const form = event.target.closest && event.target.closest("form[data-object-edit]");
    if (!form || event.target.name !== "field") return;
    form.elements.value.value = form.dataset[FILLED[event.target.value]] ?? "";
  });

  document.addEventListener("submit", async (event) => {
    const form = event.target.closest && event.target.closest("form[data-object-edit]");
    if (!form) return;
    event.preventDefault();
    const result = form.querySelector(".object-edit-result");
    const field = form.elements.field.value;
    const value = typed(form, form.elements.value.value);
    const url = db.url(`/api/profiles/${encodeURIComponent(form.dataset.profile)}/objects/`
                       + `${form.dataset.index}/${form.dataset.subindex}`);
    let response = null;
    let data = null;
    try {
      response = await fetch(url, { method: "PATCH", headers: { "Content-Type": "application/json" },
                                    body: JSON.stringify({ [field]: value }) });
      data = await response.json();
    } catch (error) {
      result.replaceChildren(db.errorBox(_("No answer from the DriveBench server."), _("Is it still running?")));
      return;
    }
    if (!response.ok) {
      result.replaceChildren(db.problemBox(data, response.status));
      return;
    }
    if (FILLED[field]) form.dataset[FILLED[field]] = value === null ? "" : String(value);
    if (field === "default") {
      const cell = form.closest("tr.entry-detail").previousElementSibling.querySelectorAll("td")[7];
      if (cell) { cell.textContent = value === null ? "" : String(value); cell.title = cell.textContent; }
    }
    result.replaceChildren(db.el("p", { className: "ok", role: "status" },
      value === null ? _("Saved: {key} removed from the file.", { key: KEYS[field] })
                     : _("Saved: {key} is now {value} in the file.", { key: KEYS[field], value: String(value) })));
  });
})();
