// The instruction console: type, see the parse, answer the interpreter's question in place, watch progress.
import { canControl, request, toast } from "./api.js";
import { cancelInstruction } from "./tasklist.js";

const OPEN = ["received", "queued", "running", "needs_user"]; // an instruction that can still be cancelled

function cancelButton(id) {
  const b = document.createElement("button");
  b.type = "button";
  b.className = "small";
  b.textContent = "Cancel";
  b.setAttribute("aria-label", `Cancel #${id}`);
  b.addEventListener("click", () => cancelInstruction(id));
  return b;
}

// A photo a robot took for the instruction (the photograph action): a thumbnail that opens the frame itself.
function photoLink(url) {
  const link = document.createElement("a");
  link.href = url;
  const img = document.createElement("img");
  img.src = url;
  img.alt = "photo";
  img.className = "thumb";
  link.append(img);
  return link;
}

// The robots of a step in words: names; "all" -> "every robot"; none named ("any") -> "a robot the portal
// chooses" (its answer says whom and why); a subject chosen by kind: {"any": true, "model": "turtlebot"} ->
// "a turtlebot the portal chooses", {"all": true, "except": ["husky"]} -> "every robot except husky".
function robotsInWords(robots) {
  if (Array.isArray(robots) && robots.length) return robots.join(", ");
  if (robots === "all") return "every robot";
  if (!robots || typeof robots !== "object") return "a robot the portal chooses";
  const kind = robots.model || "robot";
  const words = [robots.all ? `every ${kind}` : `a ${kind} the portal chooses`];
  if (robots.except) words.push(`except ${robots.except.join(", ")}`);
  return words.join(" ");
}

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
    const body = answerTo ? { text, answer_to: answerTo } : { text };
    const selected = this.selectedIds();
    if (selected.length) body.robot_ids = selected; // a text that names no robot goes to the ones selected
    return this.send(body);
  }

  // The robots ticked in the page's robot table (dashboard), by id; none on pages without one.
  selectedIds() {
    const boxes = document.querySelectorAll("#robot-table tr[data-robot-id]:not([hidden]) input.pick:checked");
    return [...boxes].map((box) => Number(box.value));
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
      if (body.robot_ids) message.robot_ids = body.robot_ids;
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
    // Each step in the interpreter's words (interpreter/forms.py read_back): "rotate tiago 3 times".
    (parse.steps || []).forEach((step, index) => {
      const li = document.createElement("li");
      li.textContent = (parse.read_back || [])[index] || `${step.action || "?"} ${robotsInWords(step.robots)}`;
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
      <input type="text" id="answer-${instruction.id}" class="answer" required>
      <button type="submit" class="primary">Answer</button>`;
    // The example fits the question: about the word asked ("zoom means move"), or the instruction said again
    // with what was missing ("move husky 1 meter forward").
    form.querySelector("input").placeholder = `e.g. ${parse.answer_example || "zoom means move"}`;
    const rephrase = parse.type === "III" || parse.type === "IV"; // a semantic issue: answered by a new instruction
    form.addEventListener("submit", (event) => {
      event.preventDefault();
      const text = form.querySelector("input").value.trim();
      if (rephrase) this.submit(text, instruction.id); else this.answer(instruction, text);
    });
    box.append(asked, form);
    setTimeout(() => form.querySelector("input").focus(), 0);
    return box;
  }

  async answer(instruction, text) {
    if (!text) return;
    try {
      const taught = await request("/api/interpreter/teach", { answer: text, instruction_id: instruction.id });
      if (taught && taught.ok === false) {
        toast(taught.message, true); // it ends with an example about the word asked
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
    this.line(instruction.id, `#${instruction.id} ${instruction.text}`, instruction.status, instruction.outcome, instruction.photos);
  }

  line(id, text, status, outcome, photos = []) {
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
    for (const url of photos || []) li.append(" ", photoLink(url));
    if (OPEN.includes(status) && canControl()) li.append(" ", cancelButton(id)); // the task list's cancel, here too
    const parseBadge = document.querySelector(`#parse-${id} .badge`);
    if (parseBadge) { parseBadge.textContent = status; parseBadge.className = `badge status-${status}`; }
  }

  instructionUpdate(message) {
    if (message.expired) { this.expire(message); return; }
    this.line(message.id, `#${message.id} ${message.text}`, message.status, message.outcome, message.photos);
  }

  // A question nobody answered in time (execution/sweeps.py): gone from Progress with its robots' lines; its
  // answer box, if still shown, gives way to the note ("expired: no answer within 10 min").
  expire(message) {
    this.progress.querySelectorAll(`li[data-instruction="${message.id}"], li[data-of="${message.id}"]`).forEach((li) => li.remove());
    const question = document.querySelector(`#parse-${message.id} .question`);
    if (!question) return;
    const note = document.createElement("p");
    note.className = "muted";
    note.textContent = message.outcome;
    question.replaceWith(note);
    const badge = document.querySelector(`#parse-${message.id} .badge`);
    if (badge) { badge.textContent = "expired"; badge.className = `badge status-${message.status}`; }
  }

  transition(message) {
    if (!message.instruction) return;
    const li = document.createElement("li");
    li.className = "muted";
    li.dataset.of = String(message.instruction);
    li.textContent = `${new Date(message.at).toLocaleTimeString()} ${message.robot}: ${message.from_state} → ${message.to_state}${message.reason ? ` (${message.reason})` : ""}`;
    const owner = this.progress.querySelector(`li[data-instruction="${message.instruction}"]`);
    if (owner) owner.after(li); else this.progress.prepend(li);
  }
}
