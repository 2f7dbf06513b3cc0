// The robot page's diagnostics panel and topic inspector. Everything a robot sends is shown as text
// (textContent), never as markup: a robot is untrusted input.

const LEVELS = ["OK", "WARN", "ERROR", "STALE"];

// /diagnostics (robot.diagnostics): one row per component with its level; a component not heard from in the
// table's data-stale-s seconds is STALE (aged by this page's clock: a robot that went quiet sends nothing).
export class Diagnostics {
  constructor(table) {
    this.table = table;
    this.staleS = Number(table?.dataset.staleS) || 5;
    this.components = new Map(); // name -> {status, at}
    if (table) setInterval(() => this.render(), 1000);
  }

  update(message) {
    const now = Date.now();
    (message.statuses || []).forEach((status) => this.components.set(status.name, { status, at: now }));
    this.render();
  }

  render() {
    if (!this.table || !this.components.size) return;
    const now = Date.now();
    const rows = [...this.components.entries()].sort(([a], [b]) => a.localeCompare(b)).map(([name, { status, at }]) => {
      const stale = now - at > this.staleS * 1000;
      const level = stale ? "STALE" : LEVELS[status.level] || "STALE";
      const row = document.createElement("tr");
      row.dataset.component = name;
      row.dataset.level = level;
      const badge = document.createElement("span");
      badge.className = `badge diag-${level.toLowerCase()}`;
      badge.textContent = level;
      const message = stale ? `not heard from for ${Math.round((now - at) / 1000)} s (last: ${status.message})` : status.message;
      row.append(cell(name), cell(badge), cell(message));
      row.title = (status.values || []).map(([key, value]) => `${key}: ${value}`).join("\n");
      return row;
    });
    this.table.tBodies[0].replaceChildren(...rows);
  }
}

function cell(content) {
  const td = document.createElement("td");
  td.append(content);
  return td;
}

// The topic inspector: the page names a topic over its socket ({command: "inspect"}); the server checks it is
// the robot's, subscribes (throttled by rosbridge) and sends robot.topic at most twice a second.
export class Inspector {
  constructor(live, form) {
    this.live = live;
    this.form = form;
    this.info = document.getElementById("inspect-info");
    this.out = document.getElementById("inspect-message");
    this.topic = null;
    if (!form) return;
    form.addEventListener("submit", (event) => { event.preventDefault(); this.inspect(form.elements.topic.value.trim()); });
    document.getElementById("inspect-off").addEventListener("click", () => this.inspect(""));
  }

  async inspect(topic) {
    this.topic = topic || null;
    this.out.hidden = true;
    this.out.textContent = "";
    this.info.textContent = topic ? `subscribing to ${topic}…` : "inspector off";
    const answer = await this.live.request({ command: "inspect", topic });
    if (answer && !answer.ok) { this.topic = null; this.info.textContent = answer.detail; }
    else if (answer && this.topic === (topic || null)) this.info.textContent = answer.detail;
  }

  // after a reconnect the server has forgotten: ask again
  resume() { if (this.topic) this.inspect(this.topic); }

  show(message) {
    if (message.topic !== this.topic) return;
    const rate = message.rate_hz == null ? "rate: measuring" : `${message.capped ? "≥ " : ""}${message.rate_hz.toFixed(1)} Hz`;
    this.info.textContent = `${message.topic} · ${message.msg_type} · ${rate} · ${message.count} received · ${new Date().toLocaleTimeString([], { hour12: false })}`;
    this.info.dataset.rate = message.rate_hz == null ? "" : String(message.rate_hz);
    this.out.textContent = message.text;
    this.out.hidden = false;
  }
}
