// The dashboard and the robot list: live table, live map, console; map clicks send the selected robots,
// the robot list's buttons stop them or take or release control of them.
import { canControl, request, toast } from "./api.js";
import { Console } from "./console.js";
import { connectLive } from "./live.js";
import { FleetMap } from "./map.js";
import { poseAge, poseTrouble, RobotTable, serverTime, STALE_S } from "./robots_table.js";
import { TaskList } from "./tasklist.js";

const table = new RobotTable(document.querySelector("#robot-table tbody"));
const tasks = new TaskList(document.getElementById("tasklist"));
const mapData = document.getElementById("map-data") ? JSON.parse(document.getElementById("map-data").textContent) : null;
const canvas = document.getElementById("fleet-map");
const console_ = new Console(document.getElementById("console-form"), document.getElementById("parse"), document.getElementById("progress") || document.createElement("ol"));

// Click-to-move sends robot ids and a location id or a point: a robot's name is data, never instruction text.
async function sendSelected(target) {
  const robots = table.selected();
  if (!robots.length) { toast("Select one or more robots in the table first.", true); return; }
  const destination = target.id != null ? { location: Number(target.id) } : { x: target.x, y: target.y };
  if (target.yaw != null) destination.yaw = target.yaw; // a goal dragged on the map: the heading to end with
  await console_.send({ robot_ids: robots.map((robot) => robot.id), destination });
}

async function forSelected(action) {
  const robots = table.selected();
  if (!robots.length) { toast("Select one or more robots in the table first.", true); return; }
  if (action === "stop") {
    try { toast((await request("/control/stop/", { robots: robots.map((robot) => robot.id) })).detail); }
    catch (error) { toast(`Stop refused: ${error.message}`, true); }
    return;
  }
  // one lease per robot: each answer is said (a robot held by someone else is refused in words)
  const replies = await Promise.allSettled(robots.map((robot) => request(`/robots/${robot.id}/lease/`, { action })));
  replies.forEach((reply, i) => {
    if (reply.status === "fulfilled") table.update(robots[i].id, { holder: reply.value.holder });
    toast(reply.status === "fulfilled" ? reply.value.detail : `${robots[i].name}: ${reply.reason.message}`, reply.status !== "fulfilled");
  });
}
const filter = document.getElementById("robot-filter");
if (filter) filter.addEventListener("input", () => table.filter(filter.value));
if (table.pickAll) table.pickAll.addEventListener("change", () => table.selectAll(table.pickAll.checked));
document.querySelectorAll("button[data-selected]").forEach((button) => button.addEventListener("click", () => forSelected(button.dataset.selected)));

// the robot the map follows shows its laser scan (the socket follows that one robot's scan)
const onFollow = (id) => { if (console_.live) console_.live.send({ command: "watch", robot: id }); };
const mapOptions = canControl() ? { onPick: sendSelected, onGoal: sendSelected, onFollow } : { onFollow };
const map = canvas && mapData && mapData.map ? new FleetMap(canvas, mapData, mapOptions) : null;
document.querySelectorAll("button.goto").forEach((button) => button.addEventListener("click", () => sendSelected({ id: button.dataset.locationId, name: button.dataset.location })));

console_.live = connectLive("/ws/fleet/", {
  snapshot(message) {
    serverTime(message.server_time);
    table.load(message.robots);
    if (map) map.setRobots(message.robots);
    tasks.load(message.queues);
  },
  "robot.queue"(message) { tasks.update(message); },
  "robot.status"(message) {
    const changes = { state: message.state, link_status: message.link_status, last_seen: message.last_seen, stop_hold: message.stop_hold };
    if (!table.update(message.id, changes)) table.load([...table.robots.values(), { id: message.id, name: message.robot, ...changes }]);
    if (map) map.update(message.id, changes);
  },
  "robot.transition"(message) {
    table.update(message.id, { state: message.to_state });
    if (map) map.update(message.id, { state: message.to_state });
    console_.transition(message);
  },
  "robot.goal"(message) {
    const goal = message.x == null ? null : { name: message.name, x: message.x, y: message.y };
    if (map) map.update(message.id, { goal });
  },
  "robot.scan"(message) { if (map && map.following === message.id) map.setScan(message.id, message.scan); },
  "robot.path"(message) {
    if (map) map.path(message);
    table.update(message.id, { waitingFor: message.waiting_for });
  },
  "lease.update"(message) {
    table.update(message.id, { holder: message.holder, held_until: message.expires_at });
    if (map) map.update(message.id, { holder: message.holder });
  },
  "instruction.update"(message) {
    console_.instructionUpdate(message);
    const done = ["succeeded", "failed", "cancelled", "refused"].includes(message.status);
    table.robots.forEach((robot) => {
      if (robot.instruction && robot.instruction.id === message.id && done) table.update(robot.id, { instruction: null });
    });
  },
  "fleet.poses"(message) {
    message.poses.forEach((pose) => {
      table.speed(pose.id, pose);
      if (map) map.pose(pose);
      tasks.pose(pose);
    });
  },
  "command.result"(message) { toast(message.detail, !message.ok); },
});

// The whole fleet stale: no robot's pose is fresher than STALE_S (the links process frozen or gone, say). Only a
// clock in the browser can tell: nothing comes from a process that is stuck.
const staleBanner = document.createElement("p");
staleBanner.id = "fleet-stale";
staleBanner.className = "banner warning";
staleBanner.setAttribute("role", "status");
staleBanner.hidden = true;
(canvas || document.getElementById("robot-table")).before(staleBanner);

function fleetStale() {
  const ages = [...table.robots.values()].filter((robot) => robot.link_status !== "offline").map(poseAge).filter((age) => age != null);
  const freshest = ages.length ? Math.min(...ages) : null;
  const stale = freshest != null && freshest > STALE_S;
  staleBanner.hidden = !stale;
  if (stale) staleBanner.textContent = `Fleet stale: no robot's pose has come for ${freshest.toFixed(1)} s; the map and the table show where they last were.`;
  document.body.dataset.fleetStale = stale ? "1" : "";
}

let troubles = "";
setInterval(() => {
  table.tick(); // "last seen" ages, a stale pose says so
  fleetStale();
  const now = [...table.robots.values()].map((robot) => poseTrouble(robot).replace(/\(.*\)/, "")).join("|");
  if (map && (now !== troubles || now.includes("stale"))) map.redraw(); // stale labels show their age
  troubles = now;
}, 500);

window.fleet = { map, table, console: console_, tasks }; // for the browser tests and the curious
