// Registration: start it through the API, watch its progress live, reload to show new choices when done.
import { request, toast } from "./api.js";
import { connectLive } from "./live.js";

const progress = document.getElementById("reg-progress");
const form = document.getElementById("register-form");

function say(text, bad = false) {
  const li = document.createElement("li");
  li.textContent = `${new Date().toLocaleTimeString()} ${text}`;
  if (bad) li.className = "error";
  progress.prepend(li);
}

if (form) {
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    const urls = form.endpoints.value.split(/\s+/).map((url) => url.trim()).filter(Boolean);
    if (!urls.length) return;
    form.querySelector("button").disabled = true;
    say(`registering ${urls.length} endpoint(s)…`);
    try {
      const reply = await request("/api/robots/register", { endpoints: urls, wait: true });
      (reply.results || []).forEach((result) => say(result.ok
        ? `${result.url}: registered ${result.robots.join(", ") || "no robot"}`
        : `${result.url}: failed: ${result.error}`, !result.ok));
      say("done; reloading to show the robots and any choices to make");
      setTimeout(() => location.reload(), 1500);
    } catch (error) {
      say(`registration refused: ${error.message}`, true);
      toast(error.message, true);
    } finally {
      form.querySelector("button").disabled = false;
    }
  });
}

connectLive("/ws/fleet/", {
  "registration.progress"(message) {
    say(`${message.endpoint}: ${message.stage}${message.message ? ` (${message.message})` : ""}${message.robots && message.robots.length ? `: ${message.robots.join(", ")}` : ""}`, message.ok === false);
  },
  "robot.status"(message) {
    say(`${message.robot}: ${message.link_status}, ${message.state}`);
    const cell = document.querySelector(`#reg-robots tr[data-robot-id="${message.id}"] .link`);
    if (cell) { cell.dataset.link = message.link_status; cell.textContent = message.link_status; }
  },
});
