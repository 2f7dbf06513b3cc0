// The live robot table: rows keyed by robot id, updated from the snapshot and the deltas; and the telemetry
// words every page shows the same way (speed, battery, link round trip, last seen, the state shown).
import { canControl, request, stateBadge, toast } from "./api.js";

const MOVING = 0.01; // m/s or rad/s: slower than this is standing

// The state a person sees: "teleop" while a robot with no instruction (ready or registered) moves under a held
// lease: nothing but a person's teleop drives it then.
export const IDLE = ["ready", "registered"];
export function shownState(robot) {
  const pose = robot.pose || {};
  const moving = Math.abs(pose.v || 0) > MOVING || Math.abs(pose.w || 0) > MOVING;
  return IDLE.includes(robot.state) && robot.holder && moving ? "teleop" : robot.state;
}

// How long ago, in words, from an ISO string or unix seconds.
export function ago(when) {
  if (when == null || when === "") return "never";
  const at = typeof when === "number" ? when * 1000 : Date.parse(when);
  if (!Number.isFinite(at)) return "never";
  const seconds = Math.max(0, Math.round((Date.now() - at) / 1000));
  if (seconds < 60) return `${seconds} s ago`;
  if (seconds < 3600) return `${Math.floor(seconds / 60)} min ago`;
  return `${Math.floor(seconds / 3600)} h ago`;
}

// How old a robot's pose is, in seconds, by the server's clock (null without one). The server's clock is
// told in each snapshot (server_time): a browser whose own clock is off still ages poses right. Computed here,
// every tick, because a frozen links process sends nothing that could say so.
export const STALE_S = 2;
let skew = 0; // our clock minus the server's, in seconds
export function serverTime(unix) { if (Number.isFinite(unix)) skew = Date.now() / 1000 - unix; }
export function poseAge(robot) {
  const t = robot.pose && robot.pose.t;
  return Number.isFinite(t) ? Math.max(0, Date.now() / 1000 - skew - t) : null;
}

// What is wrong with a robot's pose, in words: "odometry invalid: x is NaN", "stale (3.2 s)", or "".
export function poseTrouble(robot) {
  if (robot.pose && robot.pose.fault) return `odometry invalid: ${robot.pose.fault}`;
  const age = poseAge(robot);
  return age != null && age > STALE_S && robot.link_status !== "offline" ? `stale (${age.toFixed(1)} s)` : "";
}

// A pose from a tick merged into the robot's: a pose without a fault clears the one it had.
export function mergePose(robot, pose) {
  const merged = { ...(robot.pose || {}), ...pose };
  if (!pose.fault) { delete merged.fault; delete merged.fault_since; }
  return merged;
}

// Whether the robot's pose has a place (a robot refused from its first message has none).
export function placed(pose) { return Boolean(pose) && Number.isFinite(pose.x) && Number.isFinite(pose.y); }

// The freshest sign of life: the link's last_seen or the last pose's stamp.
export function lastSeen(robot) {
  const link = robot.last_seen ? Date.parse(robot.last_seen) / 1000 : 0;
  const pose = robot.pose && robot.pose.t ? robot.pose.t + skew : 0;
  const latest = Math.max(link, pose);
  return latest > 0 ? latest : null;
}

export const telemetry = {
  speed: (robot) => (robot.pose && robot.pose.v != null ? `${Math.abs(robot.pose.v).toFixed(2)} m/s` : "–"),
  battery: (robot) => (robot.pose && robot.pose.battery != null ? `${Math.round(robot.pose.battery)}%` : "–"),
  rtt: (robot) => (robot.pose && robot.pose.rtt != null ? `${robot.pose.rtt < 10 ? robot.pose.rtt.toFixed(1) : Math.round(robot.pose.rtt)} ms` : "–"),
  seen: (robot) => ago(lastSeen(robot)),
  step: (robot) => (robot.instruction && robot.instruction.step ? `step ${robot.instruction.step} of ${robot.instruction.steps}` : ""),
};

export class RobotTable {
  constructor(tbody) {
    this.tbody = tbody;
    this.robots = new Map();
    this.query = "";
    this.count = document.getElementById("robot-count");
    this.pickAll = document.getElementById("pick-all");
  }

  // The header box: ticked when every robot shown is, half-ticked when some are.
  syncPickAll() {
    if (!this.pickAll) return;
    const boxes = [...this.tbody.querySelectorAll("tr[data-robot-id]:not([hidden]) input.pick")];
    const ticked = boxes.filter((box) => box.checked).length;
    this.pickAll.checked = boxes.length > 0 && ticked === boxes.length;
    this.pickAll.indeterminate = ticked > 0 && ticked < boxes.length;
  }

  // Show only the robots whose name, model, state or holder contains the text (case-insensitive).
  filter(text) {
    this.query = text.trim().toLowerCase();
    for (const tr of this.tbody.querySelectorAll("tr[data-robot-id]")) this.applyFilter(tr);
    this.showCount();
    this.syncPickAll();
  }

  matches(robot) {
    if (!this.query) return true;
    return [robot.name, robot.model, robot.state, robot.holder].some((value) => (value || "").toLowerCase().includes(this.query));
  }

  applyFilter(tr) {
    const robot = this.robots.get(Number(tr.dataset.robotId));
    tr.hidden = Boolean(robot) && !this.matches(robot);
    if (tr.hidden) {
      const box = tr.querySelector("input.pick");
      if (box && box.checked) { box.checked = false; tr.classList.remove("selected"); } // never act on what is not shown
    }
  }

  showCount() {
    if (!this.count) return;
    const shown = [...this.robots.values()].filter((robot) => this.matches(robot)).length;
    this.count.textContent = this.query ? `${shown} of ${this.robots.size} shown` : `${this.robots.size} robots`;
  }

  // Tick or clear every robot shown.
  selectAll(checked) {
    for (const tr of this.tbody.querySelectorAll("tr[data-robot-id]:not([hidden])")) {
      const box = tr.querySelector("input.pick");
      if (box) { box.checked = checked; tr.classList.toggle("selected", checked); }
    }
    this.syncPickAll();
  }

  // The robots ticked and shown, read from the boxes themselves: a box ticked on a row the server drew, before
  // the socket's snapshot came, counts too (the row's id and name stand in for the robot until then).
  selected() {
    return [...this.tbody.querySelectorAll("tr[data-robot-id]:not([hidden]) input.pick:checked")].map((box) => {
      const tr = box.closest("tr");
      return this.robots.get(Number(box.value)) || { id: Number(box.value), name: tr.dataset.name };
    });
  }

  load(rows) {
    // the boxes ticked so far (also on the rows the server drew, before the first snapshot came)
    const picked = new Set([...this.tbody.querySelectorAll("input.pick:checked")].map((box) => Number(box.value)));
    rows.forEach((robot) => { if (robot.waiting_for !== undefined && robot.waitingFor === undefined) robot.waitingFor = robot.waiting_for; });
    this.robots = new Map(rows.map((robot) => [robot.id, robot]));
    this.tbody.replaceChildren(...rows.map((robot) => this.row(robot, picked.has(robot.id))));
    if (!rows.length) {
      const tr = document.createElement("tr");
      tr.innerHTML = '<td colspan="7">No robots registered yet.</td>';
      this.tbody.append(tr);
    }
    this.showCount();
    this.syncPickAll();
  }

  update(id, changes) {
    const robot = this.robots.get(id);
    if (!robot) return null;
    Object.assign(robot, changes);
    const old = document.getElementById(`robot-${id}`);
    const picked = old && old.querySelector("input.pick:checked");
    if (!old) return robot;
    const fresh = this.row(robot, Boolean(picked));
    old.replaceWith(fresh);
    if (fresh.hidden !== old.hidden) this.syncPickAll(); // its new state or holder took it in or out of the filter
    return robot;
  }

  // A pose (with its battery and round trip when known): the telemetry cell and, when it changed, the badge.
  speed(id, pose) {
    const robot = this.robots.get(id);
    if (!robot) return;
    const before = shownState(robot);
    robot.pose = mergePose(robot, pose);
    const cell = document.querySelector(`#robot-${id} .c-speed`);
    if (cell) cell.replaceChildren(this.telemetryCell(robot));
    if (shownState(robot) !== before) this.update(id, {});
  }

  // Twice a second: "last seen" words age, and a pose too old (or refused) says so.
  tick() {
    this.robots.forEach((robot) => {
      const seen = document.querySelector(`#robot-${robot.id} .t-seen`);
      if (seen) seen.textContent = telemetry.seen(robot);
      const trouble = document.querySelector(`#robot-${robot.id} .t-trouble`);
      const words = poseTrouble(robot);
      if (trouble && trouble.textContent !== words) { trouble.textContent = words; trouble.hidden = !words; }
    });
  }

  telemetryCell(robot) {
    const box = document.createElement("span");
    box.className = "telemetry-cell";
    const part = (className, text, title) => {
      const span = document.createElement("span");
      span.className = className;
      span.textContent = text;
      span.title = title;
      return span;
    };
    box.append(part("t-speed", telemetry.speed(robot), "speed"));
    if (robot.pose && robot.pose.battery != null) box.append(" · ", part("t-battery", telemetry.battery(robot), "battery"));
    box.append(document.createElement("br"));
    const muted = document.createElement("span");
    muted.className = "muted";
    muted.append(part("t-rtt", telemetry.rtt(robot), "link round trip"), " · ", part("t-seen", telemetry.seen(robot), "last seen"));
    const trouble = part("t-trouble", poseTrouble(robot), "its pose");
    trouble.hidden = !trouble.textContent;
    box.append(muted, trouble);
    return box;
  }

  row(robot, picked) {
    const tr = document.createElement("tr");
    tr.id = `robot-${robot.id}`;
    tr.dataset.robotId = robot.id;
    tr.dataset.name = robot.name;
    tr.dataset.state = robot.state;
    tr.hidden = !this.matches(robot);
    picked = picked && !tr.hidden; // never act on what is not shown
    if (picked) tr.classList.add("selected");
    const cell = (className, ...children) => {
      const td = document.createElement("td");
      if (className) td.className = className;
      td.append(...children);
      tr.append(td);
      return td;
    };
    if (canControl()) {
      const box = document.createElement("input");
      box.type = "checkbox";
      box.className = "pick";
      box.value = robot.id;
      box.checked = picked;
      box.setAttribute("aria-label", `Select ${robot.name}`);
      box.addEventListener("change", () => { tr.classList.toggle("selected", box.checked); this.syncPickAll(); });
      cell("", box);
    }
    const link = document.createElement("a");
    link.href = `/robots/${robot.id}/`;
    link.textContent = robot.name;
    const model = document.createElement("span");
    model.className = "muted hide-narrow";
    model.textContent = robot.model || "";
    cell("", link, document.createElement("br"), model);
    const status = document.createElement("span");
    status.className = "link";
    status.dataset.link = robot.link_status;
    status.textContent = robot.link_status;
    cell("c-link", status);
    cell("c-state", stateBadge(shownState(robot)));
    const step = telemetry.step(robot);
    const doing = robot.instruction ? `#${robot.instruction.id} ${robot.instruction.text}${step ? ` · ${step}` : ""}` : "none";
    const waiting = robot.waitingFor ? ` · ‖ waiting for ${robot.waitingFor}` : "";
    cell("c-instruction", doing + waiting);
    cell("c-speed", this.telemetryCell(robot));
    const held = document.createElement("span");
    held.className = "held";
    held.dataset.holder = robot.holder || "";
    held.textContent = robot.holder ? `held by ${robot.holder}` : "free";
    cell("c-held", held, ...this.stopHold(robot));
    return tr;
  }

  // A person's stop holds the robot: its words, and a button that releases it (nothing automatic moves it).
  stopHold(robot) {
    if (!robot.stop_hold) return [];
    const words = document.createElement("span");
    words.className = "stop-hold";
    words.title = "nothing automatic moves it until a person releases it or names it";
    words.textContent = `‖ ${robot.stop_hold}`;
    if (!canControl()) return [document.createElement("br"), words];
    const button = document.createElement("button");
    button.type = "button";
    button.className = "release-hold";
    button.textContent = "Release";
    button.setAttribute("aria-label", `Release ${robot.name} from its stop`);
    button.addEventListener("click", async () => {
      try {
        toast((await request(`/robots/${robot.id}/release/`, {})).detail);
        this.update(robot.id, { stop_hold: null });
      } catch (error) { toast(`${robot.name}: ${error.message}`, true); }
    });
    return [document.createElement("br"), words, " ", button];
  }
}
