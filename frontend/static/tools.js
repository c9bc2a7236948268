// Tools page helpers: Enter in a calculator field acts like leaving it; export the plan being edited as a file.
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
  const response = await fetch("/ui/tools/planner/export", { method: "POST", headers: { "HX-Request": "true" }, body: new URLSearchParams(new FormData(form)) });
  if (!response.ok) {
    slot.innerHTML = await response.text();
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
