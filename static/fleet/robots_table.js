// The live robot table: rows keyed by robot id, updated from the snapshot and the deltas.
import { canControl, stateBadge } from "./api.js";

export class RobotTable {
  constructor(tbody) {
    this.tbody = tbody;
    this.robots = new Map();
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
  }

  update(id, changes) {
    const robot = this.robots.get(id);
    if (!robot) return null;
    Object.assign(robot, changes);
    const old = document.getElementById(`robot-${id}`);
    const picked = old && old.querySelector("input.pick:checked");
    if (old) old.replaceWith(this.row(robot, Boolean(picked)));
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
      box.addEventListener("change", () => tr.classList.toggle("selected", box.checked));
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
