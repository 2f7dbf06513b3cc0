// On every page: the open-alerts badge in the top bar and a toast for each new alert, live; on /alerts/ the
// open table follows too, and operators acknowledge and resolve from it.
import { request, toast } from "./api.js";
import { unpack } from "./live.js";

const badge = document.getElementById("alerts-badge");
const table = document.getElementById("alerts-open");

function setCount(count) {
  if (!badge) return;
  badge.textContent = String(count);
  badge.dataset.count = String(count);
  badge.setAttribute("aria-label", `${count} open alert${count === 1 ? "" : "s"}`);
}

function cell(text) {
  const td = document.createElement("td");
  td.textContent = text;
  return td;
}

function row(alert) {
  const tr = document.createElement("tr");
  tr.dataset.alert = String(alert.id);
  const kind = document.createElement("td");
  const label = document.createElement("span");
  label.className = `sev sev-${alert.severity}`;
  label.textContent = alert.kind_label;
  kind.append(label);
  const status = alert.status === "acknowledged" ? `acknowledged by ${alert.acknowledged_by}` : alert.status;
  tr.append(cell(new Date(alert.raised_at).toLocaleString()), kind, cell(alert.robot || "fleet"), cell(alert.message), cell(String(alert.count)), cell(status));
  const actions = document.createElement("td");
  if (table.dataset.canHandle === "true") {
    for (const act of alert.status === "open" ? ["acknowledge", "resolve"] : ["resolve"]) {
      const button = document.createElement("button");
      button.type = "button";
      button.dataset.act = act;
      button.textContent = act[0].toUpperCase() + act.slice(1);
      actions.append(button, " ");
    }
  }
  tr.append(actions);
  return tr;
}

function showInTable(alert) {
  if (!table) return;
  const body = table.tBodies[0];
  const old = body.querySelector(`tr[data-alert="${alert.id}"]`);
  body.querySelector("tr.none")?.remove();
  if (alert.status === "resolved") { old?.remove(); return; }
  if (old) old.replaceWith(row(alert));
  else body.prepend(row(alert));
}

const seenKinds = new Map(); // alert id -> the kind this page last showed

function take(message) {
  setCount(message.open_count);
  if (message.type !== "alert.update") return;
  const alert = message.alert;
  showInTable(alert);
  // a toast for news: a new alert, or one whose event took a turn (a stall that ended in a failure: one alert)
  const turned = seenKinds.has(alert.id) && seenKinds.get(alert.id) !== alert.kind;
  seenKinds.set(alert.id, alert.kind);
  if (alert.status === "open" && (alert.count === 1 || turned)) toast(`${alert.kind_label}: ${alert.message}`, alert.severity !== "info");
}

function open() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const socket = new WebSocket(`${scheme}://${location.host}/ws/alerts/`);
  let delay = 1000;
  socket.addEventListener("open", () => { delay = 1000; });
  socket.addEventListener("message", (event) => { unpack(JSON.parse(event.data)).forEach(take); });
  socket.addEventListener("close", (event) => {
    if (event.code === 4401 || event.code === 4403) return;
    setTimeout(open, delay);
    delay = Math.min(delay * 2, 10000);
  });
}

if (table) {
  table.addEventListener("click", async (event) => {
    const button = event.target.closest("button[data-act]");
    if (!button) return;
    const id = button.closest("tr").dataset.alert;
    button.disabled = true;
    try {
      showInTable(await request(`/api/alerts/${id}/${button.dataset.act}`, {}));
    } catch (error) {
      toast(`Not done: ${error.message}`, true);
      button.disabled = false;
    }
  });
}

open();
