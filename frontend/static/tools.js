// Tools page helpers: Enter in a calculator field acts like leaving it; export the plan being edited as a file.
// Enter in a field also fires "enter" on it (bubbling): htmx triggers name that event instead of a
// keyup[key=='Enter'] filter, which htmx would have to eval (the Content-Security-Policy allows no eval).
document.addEventListener("keyup", (event) => {
  if (event.key === "Enter" && event.target instanceof Element) event.target.dispatchEvent(new Event("enter", { bubbles: true }));
});
document.addEventListener("keydown", (event) => {
  const field = event.target.closest && event.target.closest("[data-enter-change]");
  if (field && event.key === "Enter") {
    event.preventDefault();
    field.dispatchEvent(new Event("change", { bubbles: true }));
  }
});

document.addEventListener("click", async (event) => {
  const button = event.target.closest && event.target.closest("[data-export-plan]");
  if (!button) return;
  const form = document.getElementById("planner-form");
  const slot = document.getElementById("planner-errors");
  const response = await fetch(window.drivebench.url("/ui/tools/planner/export"), { method: "POST", headers: { "HX-Request": "true" }, body: new URLSearchParams(new FormData(form)) });
  if (!response.ok) {
    slot.innerHTML = await response.text();  // the error fragment the server rendered (Jinja escapes every value)
    return;
  }
  const name = (/filename="([^"]+)"/.exec(response.headers.get("Content-Disposition") || "") || [])[1] || "network.json";
  const link = document.createElement("a");
  link.href = URL.createObjectURL(await response.blob());
  link.download = name;
  document.body.appendChild(link);
  link.click();
  link.remove();
  URL.revokeObjectURL(link.href);
  slot.innerHTML = "";
});
