// Controls this role may not use (the rules come from the page's #refused-rules JSON block, web/access.py): greyed
// out, a tooltip names the role needed. The server refuses them anyway.
(() => {
  const _ = window.drivebench.gettext;
  const rules = JSON.parse(document.getElementById("refused-rules").textContent)
    .map((r) => ({ ...r, re: new RegExp(r.pattern) }));
  const verbs = ["post", "put", "patch", "delete"];
  function mark(root) {
    verbs.forEach((verb) => window.drivebench.within(root, `[hx-${verb}]`).forEach((elt) => {
      const url = window.drivebench.appPath(new URL(elt.getAttribute(`hx-${verb}`), location.href).pathname);
      const rule = rules.find((r) => r.method === verb.toUpperCase() && r.re.test(url));
      if (!rule) return;
      const controls = elt.matches("form") ? elt.querySelectorAll("button, input, select, textarea") : [elt];
      const needs = _("{what} needs the {role} role.", { what: rule.what, role: rule.role });
      controls.forEach((c) => { c.disabled = true; c.dataset.needsRole = rule.role; c.title = needs; });
      elt.dataset.needsRole = rule.role;
      elt.title = needs;
    }));
  }
  mark(document.body);
  document.body.addEventListener("htmx:load", (event) => mark(event.detail.elt));
})();
