// The task list: each robot's queue (execution/queues.py, pushed as robot.queue): what runs now with its step,
// the distance left and an ETA (aged with each pose), what waits behind it; cancel any of them, move waiting
// ones up or down. Every button is one API call (/api/instructions/{id}/cancel, /api/robots/{name}/queue/...).
import { canControl, request, toast } from "./api.js";

export async function cancelInstruction(id) {
  try {
    const done = await request(`/api/instructions/${id}/cancel`);
    toast(`#${id}: ${done.status}`);
  } catch (error) { toast(`Cancel refused: ${error.message}`, true); }
}

export class TaskList {
  constructor(box, single = false) {
    this.box = box;
    this.single = single; // a robot's page: that robot's queue only, and "nothing queued" when empty
    this.queues = new Map(); // robot id -> its queue
  }

  load(queues) { (queues || []).forEach((queue) => this.queues.set(queue.id, queue)); this.render(); }

  update(queue) { this.queues.set(queue.id, queue); this.render(); }

  // The distance left from the robot's new pose, the ETA at the step's speed (the same sum as queues.progress).
  pose(pose) {
    const entry = this.queues.get(pose.id)?.running;
    if (!entry || !entry.goal) return;
    entry.distance_left = Math.hypot(entry.goal.x - pose.x, entry.goal.y - pose.y);
    entry.eta_s = entry.speed ? entry.distance_left / entry.speed : null;
    const line = this.box.querySelector(`[data-progress="${entry.instruction}"]`);
    if (line) line.textContent = progressWords(entry);
  }

  render() {
    if (!this.box) return;
    const busy = [...this.queues.values()].filter((queue) => queue.running || queue.queued.length);
    this.box.replaceChildren(...busy.map((queue) => this.robot(queue)));
    if (!busy.length) this.box.append(Object.assign(document.createElement("p"), { className: "muted", textContent: "Nothing running or queued." }));
  }

  robot(queue) {
    const block = document.createElement("div");
    block.className = "tasklist-robot";
    block.dataset.robot = queue.robot;
    if (!this.single) block.append(Object.assign(document.createElement("h3"), { textContent: queue.robot }));
    const list = document.createElement("ol");
    list.className = "progress";
    if (queue.running) list.append(this.entry(queue, queue.running, 0));
    queue.queued.forEach((entry, i) => list.append(this.entry(queue, entry, i + 1)));
    block.append(list);
    return block;
  }

  entry(queue, entry, index) {
    const li = document.createElement("li");
    li.dataset.taskInstruction = entry.instruction;
    const what = entry.status === "running" ? `running · step ${entry.step} of ${entry.steps}` : `queued ${index}`;
    li.append(`#${entry.instruction} ${entry.text} — ${what}`);
    if (entry.user) li.append(` (${entry.user})`);
    if (entry.status === "running") {
      const line = document.createElement("span");
      line.className = "muted";
      line.dataset.progress = entry.instruction;
      line.textContent = progressWords(entry);
      li.append(" ", line);
    }
    if (!canControl()) return li;
    if (entry.status !== "running") {
      li.append(" ", button("↑", `Move #${entry.instruction} up`, () => this.move(queue, entry, "up"), index === 1));
      li.append(button("↓", `Move #${entry.instruction} down`, () => this.move(queue, entry, "down"), index === queue.queued.length));
    }
    li.append(" ", button("Cancel", `Cancel #${entry.instruction}`, () => cancelInstruction(entry.instruction)));
    return li;
  }

  async move(queue, entry, direction) {
    try { this.update(await request(`/api/robots/${encodeURIComponent(queue.robot)}/queue/${entry.instruction}/move`, { direction })); }
    catch (error) { toast(`Not moved: ${error.message}`, true); }
  }
}

function progressWords(entry) {
  if (entry.distance_left == null) return entry.doing || "";
  const eta = entry.eta_s == null ? "" : ` · ETA ${Math.round(entry.eta_s)} s`;
  return `${entry.doing} · ${entry.distance_left.toFixed(1)} m left${eta}`;
}

function button(text, label, onClick, disabled = false) {
  const b = document.createElement("button");
  b.type = "button";
  b.className = "small";
  b.textContent = text;
  b.setAttribute("aria-label", label);
  b.disabled = disabled;
  b.addEventListener("click", onClick);
  return b;
}
