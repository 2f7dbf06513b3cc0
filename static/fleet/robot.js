// A robot's page: live state, pose, lease and history; teleop over the page's WebSocket.
import { STATE_GLYPH, request, toast } from "./api.js";
import { connectLive } from "./live.js";

const panel = document.getElementById("control");
const robotId = Number(panel.dataset.robotId);
const linear = document.getElementById("linear-speed");
const angular = document.getElementById("angular-speed");
const holder = document.getElementById("holder");
const REPEAT_MS = 200;

function showState(state) {
  const badge = document.getElementById("robot-state");
  badge.dataset.state = state;
  badge.textContent = `${STATE_GLYPH[state] || "•"} ${state}`;
}
function showHolder(name) {
  holder.dataset.holder = name || "";
  holder.textContent = name ? `held by ${name}` : "free: nobody holds control";
}
function showPose(pose) {
  document.getElementById("pose").textContent =
    `x ${pose.x.toFixed(2)} m, y ${pose.y.toFixed(2)} m, heading ${pose.yaw.toFixed(2)} rad, ${pose.v.toFixed(2)} m/s`;
}
function addTransition(record) {
  const list = document.getElementById("transitions");
  const li = document.createElement("li");
  li.textContent = `${new Date(record.at).toLocaleTimeString()} ${record.from_state} → ${record.to_state}${record.reason ? ` (${record.reason})` : ""}${record.instruction ? ` · #${record.instruction}` : ""}`;
  list.querySelector(".muted")?.remove();
  list.prepend(li);
}

const live = connectLive(`/ws/robots/${robotId}/`, {
  snapshot(message) {
    const robot = message.robots[0];
    showState(robot.state);
    showHolder(robot.holder);
    if (robot.pose) showPose(robot.pose);
  },
  "robot.status"(message) { showState(message.state); },
  "robot.transition"(message) { showState(message.to_state); addTransition(message); },
  "lease.update"(message) { showHolder(message.holder); },
  "fleet.poses"(message) { message.poses.forEach(showPose); },
  "command.result"(message) { if (!message.ok) toast(message.detail, true); },
});

// Control lease: fetch with the CSRF token; the forms still work without JS.
document.querySelectorAll(".lease-form").forEach((form) => form.addEventListener("submit", async (event) => {
  event.preventDefault();
  try {
    const reply = await request(form.getAttribute("action"), { action: form.querySelector("[name=action]").value });
    showHolder(reply.holder);
    toast(reply.detail);
  } catch (error) { toast(error.message, true); }
}));

// Teleop: hold to drive (repeat while held), release stops.
if (linear && angular) {
  const outputs = () => {
    document.getElementById("linear-out").textContent = Number(linear.value).toFixed(2);
    document.getElementById("angular-out").textContent = Number(angular.value).toFixed(2);
  };
  linear.addEventListener("input", outputs);
  angular.addEventListener("input", outputs);
  outputs();
  let timer = null;
  const drive = (direction) => {
    const [forward, turn] = direction;
    live.send({ command: "teleop", robot: robotId, linear: forward * Number(linear.value), angular: turn * Number(angular.value) });
  };
  const start = (direction) => {
    clearInterval(timer);
    drive(direction);
    if (direction[0] || direction[1]) timer = setInterval(() => drive(direction), REPEAT_MS);
  };
  const halt = () => { if (timer) { clearInterval(timer); timer = null; drive([0, 0]); } };
  document.querySelectorAll("[data-drive]").forEach((button) => {
    const direction = button.dataset.drive.split(",").map(Number);
    button.addEventListener("pointerdown", () => start(direction));
    button.addEventListener("pointerup", halt);
    button.addEventListener("pointerleave", halt);
    button.addEventListener("keydown", (event) => { if ((event.key === "Enter" || event.key === " ") && !event.repeat) { event.preventDefault(); start(direction); } });
    button.addEventListener("keyup", (event) => { if (event.key === "Enter" || event.key === " ") halt(); });
    if (!direction[0] && !direction[1]) button.addEventListener("click", () => { clearInterval(timer); timer = null; drive([0, 0]); });
  });
  const keys = { ArrowUp: [1, 0], ArrowDown: [-1, 0], ArrowLeft: [0, 1], ArrowRight: [0, -1] };
  const pad = document.getElementById("teleop");
  pad.addEventListener("keydown", (event) => {
    if (keys[event.key]) { event.preventDefault(); if (!event.repeat) start(keys[event.key]); }
    if (event.key === " " && event.target === pad) { event.preventDefault(); clearInterval(timer); timer = null; drive([0, 0]); }
  });
  pad.addEventListener("keyup", (event) => { if (keys[event.key]) halt(); });
}
