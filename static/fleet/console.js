// The instruction console: type, see the parse, answer the interpreter's question in place, watch progress.
import { request, toast } from "./api.js";

const TYPE_NAMES = { I: "plain", II: "synonym", III: "semantic issue", IV: "synonym and semantic issue", V: "not programmed" };

export class Console {
  // live: the page's socket (connectLive), when it has one: typed instructions go over it, so a typed "stop"
  // leaves as fast as the STOP button; without one (or while it is down) they go to the API.
  constructor(form, parseBox, progress, live = null) {
    this.live = live;
    this.form = form;
    this.input = form ? form.querySelector("#instruction") : null;
    this.parseBox = parseBox;
    this.progress = progress;
    if (form) form.addEventListener("submit", (event) => { event.preventDefault(); this.submit(this.input.value.trim()); });
  }

  async submit(text, answerTo = null) {
    if (!text) return null;
    return this.send(answerTo ? { text, answer_to: answerTo } : { text });
  }

  // body: { text } typed by a person, or { robot_ids, destination } from a click on the map or a location.
  async send(body) {
    const text = body.text;
    try {
      const instruction = await this.deliver(body);
      this.showParse(instruction);
      this.track(instruction);
      if (this.input && this.input.value.trim() === text) this.input.value = "";
      return instruction;
    } catch (error) {
      toast(`Instruction refused: ${error.message}`, true);
      return null;
    }
  }

  async deliver(body) {
    if (this.live && this.live.open && body.text) {
      const message = { command: "instruct", text: body.text, answer_to: body.answer_to ?? null };
      const reply = await this.live.request(message, 120000); // answered once stored and dispatched
      if (reply === null) throw new Error("no answer yet over the live connection (see History before sending again)");
      if (!reply.ok) throw new Error(reply.detail);
      return reply.instruction;
    }
    return request("/api/instructions", body);
  }

  showParse(instruction) {
    const parse = instruction.parse || {};
    const box = document.createElement("div");
    box.className = "parse";
    box.id = `parse-${instruction.id}`;
    box.dataset.needsUser = String(Boolean(parse.needs_user));
    const head = document.createElement("p");
    head.innerHTML = `<strong>#${instruction.id}</strong> · type <strong class="ptype"></strong> · <span class="badge"></span>`;
    head.querySelector(".ptype").textContent = `${instruction.type || "?"} (${TYPE_NAMES[instruction.type] || "unknown"})`;
    const badge = head.querySelector(".badge");
    badge.textContent = instruction.status;
    badge.className = `badge status-${instruction.status}`;
    box.append(head);
    const steps = document.createElement("ul");
    steps.className = "steps";
    (parse.steps || []).forEach((step) => {
      const li = document.createElement("li");
      const robots = Array.isArray(step.robots) ? step.robots.join(", ") : step.robots;
      const where = step.destination ? ` to ${step.destination.name || ""}${step.destination.x != null ? ` (${step.destination.x}, ${step.destination.y})` : ""}` : "";
      li.textContent = `${step.action || "?"} ${robots || ""}${where}${step.task ? ` then ${step.task}` : ""}${step.speed ? `, ${step.speed}` : ""}`;
      steps.append(li);
    });
    box.append(steps);
    const synonyms = Object.entries(parse.synonyms_used || {});
    if (synonyms.length) {
      const p = document.createElement("p");
      p.className = "muted";
      p.textContent = `Synonyms: ${synonyms.map(([word, canonical]) => `${word} → ${canonical}`).join(", ")}`;
      box.append(p);
    }
    if (parse.needs_user) box.append(this.question(instruction, parse));
    else if (parse.reason) { const p = document.createElement("p"); p.className = "muted"; p.textContent = parse.reason; box.append(p); }
    this.parseBox.replaceChildren(box);
  }

  question(instruction, parse) {
    const box = document.createElement("div");
    box.className = "question";
    box.setAttribute("role", "group");
    box.setAttribute("aria-labelledby", `question-${instruction.id}`);
    const asked = document.createElement("p");
    asked.id = `question-${instruction.id}`;
    asked.innerHTML = "<strong>The interpreter asks:</strong> ";
    asked.append(parse.question || parse.reason || "Please explain this instruction.");
    const form = document.createElement("form");
    form.innerHTML = `<label for="answer-${instruction.id}">Your answer</label>
      <input type="text" id="answer-${instruction.id}" class="answer" placeholder="e.g. zoom means move" required>
      <button type="submit" class="primary">Answer</button>`;
    form.addEventListener("submit", (event) => { event.preventDefault(); this.answer(instruction, form.querySelector("input").value.trim()); });
    box.append(asked, form);
    setTimeout(() => form.querySelector("input").focus(), 0);
    return box;
  }

  async answer(instruction, text) {
    if (!text) return;
    try {
      const taught = await request("/api/interpreter/teach", { answer: text, instruction_id: instruction.id });
      if (taught && taught.ok === false) {
        toast(`${taught.message}${taught.examples ? ` Try e.g. "${taught.examples[0]}".` : ""}`, true);
        return;
      }
      toast((taught && taught.message) || `Learned: ${text}`);
      await this.submit(instruction.text, instruction.id); // run it again, now that the interpreter knows
      this.track({ ...instruction, status: "answered" });
    } catch (error) {
      toast(`Answer not understood: ${error.message}`, true);
    }
  }

  track(instruction) {
    this.line(instruction.id, `#${instruction.id} ${instruction.text}`, instruction.status, instruction.outcome);
  }

  line(id, text, status, outcome) {
    let li = this.progress.querySelector(`li[data-instruction="${id}"]`);
    if (!li) {
      li = document.createElement("li");
      li.dataset.instruction = id;
      this.progress.prepend(li);
    }
    li.replaceChildren(`${text} — `);
    const badge = document.createElement("span");
    badge.className = `badge status-${status}`;
    badge.textContent = status;
    li.append(badge);
    if (outcome) li.append(` ${outcome}`);
    const parseBadge = document.querySelector(`#parse-${id} .badge`);
    if (parseBadge) { parseBadge.textContent = status; parseBadge.className = `badge status-${status}`; }
  }

  instructionUpdate(message) {
    this.line(message.id, `#${message.id} ${message.text}`, message.status, message.outcome);
  }

  transition(message) {
    if (!message.instruction) return;
    const li = document.createElement("li");
    li.className = "muted";
    li.textContent = `${new Date(message.at).toLocaleTimeString()} ${message.robot}: ${message.from_state} → ${message.to_state}${message.reason ? ` (${message.reason})` : ""}`;
    const owner = this.progress.querySelector(`li[data-instruction="${message.instruction}"]`);
    if (owner) owner.after(li); else this.progress.prepend(li);
  }
}
