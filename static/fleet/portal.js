// On every page: the stop-all button (fetch, with a plain-form fallback) and its keyboard shortcut.
import { request, toast } from "./api.js";

const form = document.getElementById("stop-all-form");
if (form) {
  const stopAll = async (event) => {
    if (event) event.preventDefault();
    try {
      const reply = await request(form.getAttribute("action"), { robots: "all" });
      toast(reply.detail);
    } catch (error) {
      toast(`Stop refused: ${error.message}`, true);
    }
  };
  form.addEventListener("submit", stopAll);
  document.addEventListener("keydown", (event) => {
    if (event.key === "Escape" && event.shiftKey) stopAll(event);
  });
}
