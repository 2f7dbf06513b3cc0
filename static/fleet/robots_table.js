// The live robot table: rows keyed by robot id, updated from the snapshot and the deltas.
import { canControl, stateBadge } from "./api.js";

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

  selected() {
    return [...this.tbody.querySelectorAll("input.pick:checked")].map((box) => this.robots.get(Number(box.value))).filter(Boolean);
  }

  load(rows) {
    const picked = new Set(this.selected().map((robot) => robot.id));
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

  speed(id, pose) {
    const robot = this.robots.get(id);
    if (!robot) return;
    robot.pose = pose;
    const cell = document.querySelector(`#robot-${id} .c-speed`);
    if (cell) cell.textContent = `${Math.abs(pose.v).toFixed(2)} m/s`;
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
    cell("c-state", stateBadge(robot.state));
    const instruction = robot.instruction ? `#${robot.instruction.id} ${robot.instruction.text}` : "none";
    cell("c-instruction", instruction);
    cell("c-speed", robot.pose ? `${Math.abs(robot.pose.v).toFixed(2)} m/s` : "–");
    const held = document.createElement("span");
    held.className = "held";
    held.dataset.holder = robot.holder || "";
    held.textContent = robot.holder ? `held by ${robot.holder}` : "free";
    cell("c-held", held);
    return tr;
  }
}
