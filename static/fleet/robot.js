// A robot's page: its map (goal, reserved route, laser scan), camera, telemetry with small live plots, lease
// and history; teleop over the page's WebSocket from buttons, arrow keys, a touch joystick or a gamepad.
import { STATE_GLYPH, request, toast } from "./api.js";
import { connectLive } from "./live.js";
import { FleetMap } from "./map.js";
import { TaskList } from "./tasklist.js";
import { Diagnostics, Inspector } from "./telemetry.js";
import { IDLE, mergePose, placed, poseTrouble, serverTime, shownState, telemetry } from "./robots_table.js";

const panel = document.getElementById("control");
const robotId = Number(panel.dataset.robotId);
const me = document.body.dataset.user;
const linear = document.getElementById("linear-speed");
const angular = document.getElementById("angular-speed");
const holder = document.getElementById("holder");
const REPEAT_MS = 200; // a held command is repeated at 5 Hz (the server's teleop grant expects it)
const PLOT_S = 120; // seconds of history in the plots
const robot = { id: robotId, state: panel.closest("main").querySelector("#robot-state").dataset.state, pose: null };

// ---- the map ------------------------------------------------------------------------------------------------
const mapData = JSON.parse(document.getElementById("map-data").textContent);
const canvas = document.getElementById("fleet-map");
const map = canvas && mapData.map ? new FleetMap(canvas, mapData) : null;

// ---- state, lease, telemetry ----------------------------------------------------------------------------------
let driving = false; // this page is sending a non-zero command

function showState() {
  const badge = document.getElementById("robot-state");
  const state = driving && IDLE.includes(robot.state) ? "teleop" : shownState(robot);
  badge.dataset.state = state;
  badge.textContent = `${STATE_GLYPH[state] || "•"} ${state}`;
}

function showHolder(name, until) {
  robot.holder = name || null;
  robot.held_until = until || null;
  holder.dataset.holder = name || "";
  holder.textContent = name ? `held by ${name}${until ? ` until ${new Date(until).toLocaleTimeString()}` : ""}` : "free: nobody holds control";
  pad.refresh();
}

// A person's stop holds the robot: nothing automatic moves it until released (the button, "release <name>").
function showStopHold(words) {
  robot.stop_hold = words || null;
  const box = document.getElementById("stop-hold");
  box.hidden = !words;
  document.getElementById("stop-hold-words").textContent = words ? `‖ ${words}` : "";
}

function showTelemetry() {
  const pose = robot.pose;
  const trouble = poseTrouble(robot);
  if (placed(pose)) {
    document.getElementById("pose").textContent = `x ${pose.x.toFixed(2)} m, y ${pose.y.toFixed(2)} m, heading ${(pose.yaw || 0).toFixed(2)} rad${trouble ? ` (${trouble})` : ""}`;
  } else if (trouble) {
    document.getElementById("pose").textContent = trouble;
  }
  document.getElementById("t-speed").textContent = pose ? `${telemetry.speed(robot)}, turning ${Math.abs(pose.w || 0).toFixed(2)} rad/s` : "–";
  if (pose && pose.battery != null) document.getElementById("t-battery").textContent = telemetry.battery(robot);
  if (pose && pose.rtt != null) document.getElementById("t-rtt").textContent = telemetry.rtt(robot);
  document.getElementById("t-seen").textContent = telemetry.seen(robot);
}

function showDoing(reason) {
  const instruction = robot.instruction;
  const step = telemetry.step(robot);
  const parts = instruction ? [`#${instruction.id} ${instruction.text}`, step, reason].filter(Boolean) : [reason || "nothing"];
  if (robot.waitingFor) parts.push(`‖ waiting for ${robot.waitingFor}`);
  document.getElementById("t-step").textContent = parts.join(" · ");
}

function addTransition(record) {
  const list = document.getElementById("transitions");
  const li = document.createElement("li");
  li.textContent = `${new Date(record.at).toLocaleTimeString()} ${record.from_state} → ${record.to_state}${record.reason ? ` (${record.reason})` : ""}${record.instruction ? ` · #${record.instruction}` : ""}`;
  list.querySelector(".muted")?.remove();
  list.prepend(li);
}

// Small live plots (uPlot, vendored in static/vendor/uplot): speed and battery over the last two minutes.
// The time axis always spans those two minutes (ending at the newest point), ticked at whole 15 s, 30 s or
// minutes as the width allows and labelled hh:mm:ss: never every 0.5 s of the first few seconds' points.
const TICK_S = [15, 30, 60, 120, 300];
const timeWindow = (u, min, max) => [(max ?? Date.now() / 1000) - PLOT_S, max ?? Date.now() / 1000];
const TIME_AXIS = {
  space: 70, // px between ticks at least: uPlot picks the first of TICK_S that leaves this much room
  incrs: TICK_S,
  values: (u, ticks) => ticks.map((t) => new Date(t * 1000).toLocaleTimeString([], { hour12: false })),
};
const plots = (() => {
  if (!window.uPlot) return null;
  const series = { t: [], speed: [], battery: [] };
  const make = (id, label, unit, color, range) => {
    const box = document.getElementById(id);
    if (!box) return null;
    const options = {
      width: Math.max(200, box.clientWidth), height: 120, legend: { show: true },
      scales: { x: { time: true, range: timeWindow }, y: range ? { range } : {} },
      axes: [TIME_AXIS, { label: unit, size: 50 }],
      series: [{}, { label, stroke: color, width: 2, value: (u, v) => (v == null ? "–" : `${v.toFixed(unit === "%" ? 0 : 2)} ${unit}`) }],
    };
    const plot = new window.uPlot(options, [[], []], box);
    new ResizeObserver(() => plot.setSize({ width: Math.max(200, box.clientWidth), height: 120 })).observe(box);
    return plot;
  };
  const top = Number(panel.dataset.maxLinear) || 1;
  const speed = make("plot-speed", "speed", "m/s", "#1565c0", (u, min, max) => [0, Math.max(top, max || 0)]);
  const battery = make("plot-battery", "battery", "%", "#2e7d32", [0, 100]);
  let queued = false;
  return {
    series,
    speed,
    battery,
    add(pose) {
      const t = pose.t || Date.now() / 1000;
      if (series.t.length && t <= series.t[series.t.length - 1]) return;
      series.t.push(t);
      series.speed.push(Math.abs(pose.v || 0));
      series.battery.push(pose.battery != null ? pose.battery : null);
      while (series.t.length && series.t[0] < t - PLOT_S) { series.t.shift(); series.speed.shift(); series.battery.shift(); }
      if (queued) return;
      queued = true;
      setTimeout(() => { // at most twice a second
        queued = false;
        if (speed) speed.setData([series.t, series.speed]);
        if (battery) battery.setData([series.t, series.battery]);
      }, 500);
    },
  };
})();

function onPose(pose) {
  robot.pose = mergePose(robot, pose);
  showTelemetry();
  showState();
  if (map) map.pose(robot.pose);
  if (plots) plots.add(robot.pose);
}

// A camera frame (sensor_msgs/CompressedImage, base64 as rosbridge sends it): shown as it comes.
function onCamera(message) {
  const image = document.getElementById("camera");
  if (!image) return;
  const kind = /png/i.test(message.format || "") ? "png" : "jpeg";
  image.src = `data:image/${kind};base64,${message.data}`;
  image.hidden = false;
  image.dataset.frames = String(Number(image.dataset.frames || 0) + 1);
  document.getElementById("camera-note").textContent = `${message.topic} · ${kind.toUpperCase()} · ${new Date().toLocaleTimeString()}`;
}

const tasks = new TaskList(document.getElementById("tasklist"), true);
const diagnostics = new Diagnostics(document.getElementById("diagnostics"));
let inspector = null;
const live = connectLive(`/ws/robots/${robotId}/`, {
  snapshot(message) {
    tasks.load(message.queue ? [message.queue] : []);
    serverTime(message.server_time);
    Object.assign(robot, message.robots[0]);
    robot.waitingFor = robot.waiting_for || null;
    if (map) { map.setRobots([robot]); map.follow(robotId, 3); }
    showHolder(robot.holder, robot.held_until);
    showStopHold(robot.stop_hold);
    showState();
    showDoing();
    if (robot.pose) onPose(robot.pose);
    inspector?.resume();
  },
  "robot.status"(message) { Object.assign(robot, { state: message.state, link_status: message.link_status, last_seen: message.last_seen }); showStopHold(message.stop_hold); showState(); if (map) map.update(robotId, { state: message.state, link_status: message.link_status }); },
  "robot.transition"(message) {
    robot.state = message.to_state;
    if (message.to_state === "ready") robot.instruction = null;
    showState();
    showDoing(message.reason);
    addTransition(message);
    if (map) map.update(robotId, { state: message.to_state });
  },
  "robot.goal"(message) { if (map) map.update(robotId, { goal: message.x == null ? null : { name: message.name, x: message.x, y: message.y } }); },
  "robot.path"(message) { robot.waitingFor = message.waiting_for; showDoing(); if (map) map.path(message); },
  "robot.scan"(message) { if (map) map.setScan(robotId, message.scan); },
  "robot.camera"(message) { onCamera(message); },
  "robot.diagnostics"(message) { diagnostics.update(message); },
  "robot.topic"(message) { inspector?.show(message); },
  "lease.update"(message) { showHolder(message.holder, message.expires_at); },
  "fleet.poses"(message) { message.poses.forEach(onPose); message.poses.forEach((pose) => tasks.pose(pose)); },
  "robot.queue"(message) { tasks.update(message); },
  "command.result"(message) {
    if (message.ok) return;
    if (message.command === "teleop") pad.refused(message.detail); else toast(message.detail, true);
  },
});
inspector = new Inspector(live, document.getElementById("inspector-form"));
setInterval(showTelemetry, 500); // "last seen" ages, a stale pose says so

// Control lease: fetch with the CSRF token; the forms still work without JS.
document.querySelectorAll(".lease-form").forEach((form) => form.addEventListener("submit", async (event) => {
  event.preventDefault();
  try {
    const reply = await request(form.getAttribute("action"), { action: form.querySelector("[name=action]").value });
    showHolder(reply.holder, reply.holder ? robot.held_until : null);
    toast(reply.detail);
  } catch (error) { toast(error.message, true); }
}));

const releaseHold = document.getElementById("release-hold-form");
if (releaseHold) releaseHold.addEventListener("submit", async (event) => {
  event.preventDefault();
  try {
    toast((await request(releaseHold.getAttribute("action"), {})).detail);
    showStopHold(null);
  } catch (error) { toast(error.message, true); }
});

// ---- teleop ---------------------------------------------------------------------------------------------------
// One command at a time from whichever source is active (buttons, keys, joystick, gamepad), repeated at 5 Hz
// while held, a zero when released. While someone else holds the lease the pad is disabled and says so once.
const pad = (() => {
  const note = document.getElementById("teleop-note");
  const group = document.getElementById("teleop");
  const stick = document.getElementById("joystick");
  let timer = null;
  let current = [0, 0];
  let lastNote = "";
  const limits = () => [Number(linear.value), Number(angular.value)];
  const blockedBy = () => (robot.holder && robot.holder !== me ? robot.holder : null);

  function say(text) {
    if (!note || text === lastNote) return; // one message, not a flood
    lastNote = text;
    note.textContent = text;
    note.hidden = !text;
  }

  function send([forward, turn]) {
    const [v, w] = limits();
    live.send({ command: "teleop", robot: robotId, linear: forward * v, angular: turn * w });
  }

  // direction: [forward, turn] in -1..1 (fractions of the sliders' speeds); [0, 0] stops.
  let sentAt = 0;
  function drive(direction) {
    if (blockedBy()) { refresh(); return; }
    const moving = Boolean(direction[0] || direction[1]);
    const same = direction[0] === current[0] && direction[1] === current[1];
    current = direction;
    // a change goes out at once (at most 10 a second); the same command is left to the 5 Hz repeat
    if (!moving || (!same && performance.now() - sentAt > 100) || !timer) { send(direction); sentAt = performance.now(); }
    if (moving && !timer) timer = setInterval(() => send(current), REPEAT_MS);
    if (!moving && timer) { clearInterval(timer); timer = null; }
    driving = moving;
    showState();
  }

  function halt() { if (timer || driving) drive([0, 0]); }

  function refresh() {
    const other = blockedBy();
    const disabled = Boolean(other);
    if (group) {
      group.setAttribute("aria-disabled", String(disabled));
      group.querySelectorAll("button").forEach((button) => { button.disabled = disabled; });
    }
    if (stick) stick.setAttribute("aria-disabled", String(disabled));
    if (disabled) {
      if (timer) { clearInterval(timer); timer = null; driving = false; showState(); }
      const until = robot.held_until ? ` until ${new Date(robot.held_until).toLocaleTimeString()}` : "";
      say(`Held by ${other}${until}: teleop is off until they release it or it expires.`);
    } else if (lastNote.startsWith("Held by")) say("");
  }

  // A refusal of the server: said once in the note (the same words again are not repeated); the repeat stops.
  function refused(detail) {
    if (timer) { clearInterval(timer); timer = null; }
    driving = false;
    showState();
    say(`Teleop refused: ${detail}`);
  }

  return { drive, halt, refresh, refused, get active() { return driving; } };
})();

if (linear && angular) {
  const outputs = () => {
    document.getElementById("linear-out").textContent = Number(linear.value).toFixed(2);
    document.getElementById("angular-out").textContent = Number(angular.value).toFixed(2);
  };
  linear.addEventListener("input", outputs);
  angular.addEventListener("input", outputs);
  outputs();

  // buttons and keys, as before
  document.querySelectorAll("[data-drive]").forEach((button) => {
    const direction = button.dataset.drive.split(",").map(Number);
    const still = !direction[0] && !direction[1];
    button.addEventListener("pointerdown", () => pad.drive(direction));
    button.addEventListener("pointerup", () => pad.halt());
    button.addEventListener("pointerleave", () => pad.halt());
    button.addEventListener("keydown", (event) => { if ((event.key === "Enter" || event.key === " ") && !event.repeat) { event.preventDefault(); pad.drive(direction); } });
    button.addEventListener("keyup", (event) => { if (event.key === "Enter" || event.key === " ") pad.halt(); });
    if (still) button.addEventListener("click", () => pad.drive([0, 0]));
  });
  const keys = { ArrowUp: [1, 0], ArrowDown: [-1, 0], ArrowLeft: [0, 1], ArrowRight: [0, -1] };
  const group = document.getElementById("teleop");
  group.addEventListener("keydown", (event) => {
    if (keys[event.key]) { event.preventDefault(); if (!event.repeat) pad.drive(keys[event.key]); }
    if (event.key === " " && event.target === group) { event.preventDefault(); pad.drive([0, 0]); }
  });
  group.addEventListener("keyup", (event) => { if (keys[event.key]) pad.halt(); });

  // the touch joystick: the knob's offset from the centre is the command (up: forward, left: turn left)
  const stick = document.getElementById("joystick");
  const knob = stick.querySelector(".knob");
  let stickPointer = null;
  const stickMove = (event) => {
    const box = stick.getBoundingClientRect();
    const radius = box.width / 2;
    let dx = (event.clientX - box.left - radius) / radius;
    let dy = (event.clientY - box.top - radius) / radius;
    const length = Math.hypot(dx, dy);
    if (length > 1) { dx /= length; dy /= length; }
    knob.style.transform = `translate(${dx * radius * 0.7}px, ${dy * radius * 0.7}px)`;
    const dead = (value) => (Math.abs(value) < 0.12 ? 0 : value);
    const direction = [dead(-dy), dead(-dx)];
    stick.setAttribute("aria-valuetext", `forward ${direction[0].toFixed(2)}, turn ${direction[1].toFixed(2)}`);
    pad.drive(direction);
  };
  const stickEnd = () => {
    if (stickPointer === null) return;
    stickPointer = null;
    knob.style.transform = "";
    stick.setAttribute("aria-valuetext", "centred");
    pad.drive([0, 0]);
  };
  stick.addEventListener("pointerdown", (event) => {
    if (stick.getAttribute("aria-disabled") === "true") { pad.refresh(); return; }
    stickPointer = event.pointerId;
    stick.setPointerCapture(event.pointerId);
    stickMove(event);
  });
  stick.addEventListener("pointermove", (event) => { if (event.pointerId === stickPointer) stickMove(event); });
  stick.addEventListener("pointerup", stickEnd);
  stick.addEventListener("pointercancel", stickEnd);

  // a gamepad (Gamepad API, standard mapping): drives only while the dead-man button (LB, 4) is held;
  // left stick up/down is forward/back, left/right turns. Releasing the dead-man button stops the robot.
  const DEADMAN = 4;
  const DEADZONE = 0.12;
  const status = document.getElementById("gamepad-status");
  let held = false;
  const pollPad = () => {
    const pads = navigator.getGamepads ? [...navigator.getGamepads()].filter(Boolean) : [];
    const gamepad = pads[0];
    if (!gamepad) {
      if (held) { held = false; pad.drive([0, 0]); }
      status.textContent = "No gamepad connected.";
      return;
    }
    const deadman = Boolean(gamepad.buttons[DEADMAN] && gamepad.buttons[DEADMAN].pressed);
    const axis = (i) => (Math.abs(gamepad.axes[i] || 0) < DEADZONE ? 0 : -(gamepad.axes[i] || 0));
    if (deadman) {
      const direction = [axis(1), axis(0)];
      pad.drive(direction);
      held = true;
      status.textContent = `Gamepad ${gamepad.id}: dead-man held, forward ${direction[0].toFixed(2)}, turn ${direction[1].toFixed(2)}.`;
    } else {
      if (held) { held = false; pad.drive([0, 0]); }
      status.textContent = `Gamepad ${gamepad.id}: hold LB (button 4) to drive.`;
    }
  };
  setInterval(pollPad, 100);
  window.addEventListener("gamepaddisconnected", () => { if (held) { held = false; pad.drive([0, 0]); } });
  window.addEventListener("blur", () => pad.halt()); // a page left behind never keeps a robot driving
}

window.fleet = { map, robot, live, pad, plots, diagnostics, inspector }; // for the browser tests and the curious
