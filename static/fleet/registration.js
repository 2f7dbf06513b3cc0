// Registration: start it through the API, watch its progress live, reload to show new choices when done.
import { request, toast } from "./api.js";
import { connectLive } from "./live.js";

const progress = document.getElementById("reg-progress");
const form = document.getElementById("register-form");
let waiting = 0;

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
      const reply = await request("/api/robots/register", { urls, endpoints: urls });
      waiting = urls.length;
      const robots = Array.isArray(reply) ? reply : (reply && (reply.robots || reply.results)) || [];
      if (robots.length) say(`registered: ${robots.map((robot) => robot.name || robot).join(", ")}`);
      if (reply && reply.detail) say(reply.detail);
      setTimeout(() => location.reload(), robots.length ? 1200 : 6000);
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
    if (["done", "failed"].includes(message.stage)) {
      waiting -= 1;
      if (waiting <= 0) setTimeout(() => location.reload(), 800);
    }
  },
  "robot.status"(message) {
    say(`${message.robot}: ${message.link_status}, ${message.state}`);
    const cell = document.querySelector(`#reg-robots tr[data-robot-id="${message.id}"] .link`);
    if (cell) { cell.dataset.link = message.link_status; cell.textContent = message.link_status; }
  },
});
