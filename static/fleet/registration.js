// Registration: start it through the API, watch its progress live; when done, the robots, the choices to make and
// the records are fetched again and swapped in, so the progress log stays.
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

// The parts of the page a registration changes, replaced by the same parts of a fresh copy of the page.
const REFRESHED = ["#pending", "#reg-robots tbody", "#reg-records tbody"];

async function refreshSections() {
  try {
    const response = await fetch(location.pathname, { headers: { Accept: "text/html" }, credentials: "same-origin" });
    if (!response.ok) throw new Error(`HTTP ${response.status}`);
    const fresh = new DOMParser().parseFromString(await response.text(), "text/html");
    for (const selector of REFRESHED) {
      const here = document.querySelector(selector), there = fresh.querySelector(selector);
      if (here && there) here.replaceWith(document.adoptNode(there));
    }
  } catch (error) {
    say(`could not refresh the lists (${error.message}); reload the page to see them`, true);
  }
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
      await refreshSections();
      say("done: the robots, the choices to make and the records below are up to date");
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
