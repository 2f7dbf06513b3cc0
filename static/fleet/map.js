// The live map on a canvas: occupancy grid, locations, robots as oriented footprints with names, state glyphs,
// trails, goals, reserved routes, whom a robot waits for, and a selected robot's laser scan.
//
// This module holds the map's data (what the page feeds it), its view and its input: wheel zooms about the
// cursor, drag pans, two fingers pinch, the toolbar fits everything or follows a robot; hovering (or tapping) a
// robot or a crowd opens a card naming every robot there. Drawing a frame is static/fleet/mapdraw.js
// (MapPainter, which FleetMap extends); frames are coalesced to one per animation tick (redraw).
import { MapPainter } from "./mapdraw.js";
import { STATE_GLYPH } from "./api.js";
import { mergePose, placed, poseTrouble } from "./robots_table.js";

const TRAIL_POINTS = 120;
const PICK_RADIUS_M = 0.4;
const PICK_PX = 12; // css px: robots this near the pointer are "here", however small they are drawn
const DRAG_PX = 5; // css px a press must move to be a drag, not a click
const MIN_ZOOM = 0.5;
const MAX_ZOOM = 80;
const CARD_ROBOTS = 12;

export class FleetMap extends MapPainter {
  // options: onPick({id, name} | {x, y}) for a click, onGoal({x, y, yaw}) for a press-and-drag in goal mode.
  constructor(canvas, mapData, options = {}) {
    super();
    if (typeof options === "function") options = { onPick: options };
    this.canvas = canvas;
    this.map = mapData.map;
    this.locations = mapData.locations || [];
    this.onPick = options.onPick || null;
    this.onGoal = options.onGoal || null;
    this.onFollow = options.onFollow || null; // (id or null): the page may follow that robot's scan
    this.robots = new Map();
    this.trails = new Map();
    this.scan = null;
    this.labels = [];
    this.labelled = [];
    this.grid = this.renderGrid();
    this.zoom = 1;
    this.center = this.mapCenter();
    this.following = null;
    this.tool = "pan";
    this.pointers = new Map();
    this.gesture = null;
    this.queued = false;
    this.ratio = window.devicePixelRatio || 1;
    this.wrap = canvas.parentElement;
    this.card = document.createElement("div");
    this.card.className = "map-card";
    this.card.hidden = true;
    this.card.setAttribute("role", "status");
    this.wrap.append(this.card);
    this.toolbar = this.buildToolbar();
    this.listen();
    new ResizeObserver(() => this.redraw()).observe(canvas);
  }

  renderGrid() {
    const { width, height, cells } = this.map;
    const image = document.createElement("canvas");
    image.width = width;
    image.height = height;
    const context = image.getContext("2d");
    const pixels = context.createImageData(width, height);
    const shade = { "#": [55, 71, 79], "?": [176, 190, 197], ".": [250, 250, 250] };
    for (let row = 0; row < height; row += 1) {
      for (let col = 0; col < width; col += 1) {
        const [r, g, b] = shade[cells[row * width + col]] || shade["."];
        const offset = ((height - 1 - row) * width + col) * 4; // ROS row 0 is the bottom
        pixels.data.set([r, g, b, 255], offset);
      }
    }
    context.putImageData(pixels, 0, 0);
    return image;
  }

  // ---- the view: zoom about a point, pan, fit, follow ------------------------------------------------------

  mapCenter() {
    const [ox, oy] = this.map.origin;
    return [ox + (this.map.width * this.map.resolution) / 2, oy + (this.map.height * this.map.resolution) / 2];
  }

  layout() {
    const ratio = window.devicePixelRatio || 1;
    const box = this.canvas.getBoundingClientRect();
    const width = Math.max(1, Math.round(box.width * ratio));
    const height = Math.max(1, Math.round(box.height * ratio));
    if (this.canvas.width !== width) this.canvas.width = width;
    if (this.canvas.height !== height) this.canvas.height = height;
    this.ratio = ratio;
    this.fitScale = this.fitScaleFor(this.map.width * this.map.resolution, this.map.height * this.map.resolution);
    this.scale = this.fitScale * this.zoom; // device pixels per metre
  }

  fitScaleFor(worldW, worldH) {
    return 0.96 * Math.min(this.canvas.width / Math.max(worldW, 0.5), this.canvas.height / Math.max(worldH, 0.5));
  }

  toScreen(x, y) {
    return [this.canvas.width / 2 + (x - this.center[0]) * this.scale, this.canvas.height / 2 - (y - this.center[1]) * this.scale];
  }

  toWorld(px, py) {
    return [this.center[0] + (px - this.canvas.width / 2) / this.scale, this.center[1] - (py - this.canvas.height / 2) / this.scale];
  }

  // Device pixels on the canvas of a pointer event (or of client coordinates).
  eventPoint(event) {
    const box = this.canvas.getBoundingClientRect();
    return [(event.clientX - box.left) * this.ratio, (event.clientY - box.top) * this.ratio];
  }

  // The map point under client (page viewport) coordinates: what the tests and the card read.
  worldAt(clientX, clientY) {
    this.layout();
    return this.toWorld(...this.eventPoint({ clientX, clientY }));
  }

  // Zoom by factor keeping the world point under (px, py) where it is (about the followed robot when following).
  zoomAt(px, py, factor) {
    this.layout();
    if (this.following != null) [px, py] = [this.canvas.width / 2, this.canvas.height / 2];
    const [wx, wy] = this.toWorld(px, py);
    this.zoom = Math.min(MAX_ZOOM, Math.max(MIN_ZOOM, this.zoom * factor));
    this.scale = this.fitScale * this.zoom;
    this.center = [wx - (px - this.canvas.width / 2) / this.scale, wy + (py - this.canvas.height / 2) / this.scale];
    this.redraw();
  }

  panBy(dx, dy) {
    this.center = [this.center[0] - dx / this.scale, this.center[1] + dy / this.scale];
    this.follow(null);
  }

  // Show the whole map and every robot on it.
  fit() {
    this.layout();
    const [ox, oy] = this.map.origin;
    let [x0, y0, x1, y1] = [ox, oy, ox + this.map.width * this.map.resolution, oy + this.map.height * this.map.resolution];
    this.robots.forEach((robot) => {
      const at = this.where(robot);
      if (at) { x0 = Math.min(x0, at[0]); y0 = Math.min(y0, at[1]); x1 = Math.max(x1, at[0]); y1 = Math.max(y1, at[1]); }
    });
    this.zoom = Math.min(MAX_ZOOM, Math.max(MIN_ZOOM, this.fitScaleFor(x1 - x0, y1 - y0) / this.fitScale));
    this.center = [(x0 + x1) / 2, (y0 + y1) / 2];
    this.follow(null);
  }

  // Keep a robot (id) in the middle as it moves; null stops following.
  follow(id, zoom = null) {
    const before = this.following;
    this.following = id == null || !this.robots.has(Number(id)) ? null : Number(id);
    if (this.following !== before) {
      if (this.scan && this.scan.id !== this.following) this.scan = null;
      if (this.onFollow) this.onFollow(this.following);
    }
    if (this.followSelect) this.followSelect.value = this.following == null ? "" : String(this.following);
    if (this.following != null) {
      if (zoom) this.zoom = Math.max(this.zoom, zoom);
      const at = this.where(this.robots.get(this.following));
      if (at) this.center = [at[0], at[1]];
    }
    this.redraw();
  }

  // ---- the toolbar and the pointer ---------------------------------------------------------------------------

  buildToolbar() {
    const bar = document.createElement("div");
    bar.className = "map-tools";
    bar.setAttribute("role", "toolbar");
    bar.setAttribute("aria-label", "Map view");
    const button = (text, label, action) => {
      const b = document.createElement("button");
      b.type = "button";
      b.textContent = text;
      b.setAttribute("aria-label", label);
      b.title = label;
      b.addEventListener("click", action);
      bar.append(b);
      return b;
    };
    const centre = () => { this.layout(); return [this.canvas.width / 2, this.canvas.height / 2]; };
    button("+", "Zoom in", () => this.zoomAt(...centre(), 1.5));
    button("−", "Zoom out", () => this.zoomAt(...centre(), 1 / 1.5));
    button("Fit all", "Fit the whole map and every robot", () => this.fit());
    const label = document.createElement("label");
    label.textContent = "Follow ";
    this.followSelect = document.createElement("select");
    this.followSelect.setAttribute("aria-label", "Follow a robot");
    this.followSelect.addEventListener("change", () => this.follow(this.followSelect.value || null, 3));
    label.append(this.followSelect);
    bar.append(label);
    if (this.onGoal) {
      this.goalButton = button("◎ Goal", "Goal mode: press where the robots should go and drag toward their heading", () => this.setTool(this.tool === "goal" ? "pan" : "goal"));
      this.goalButton.setAttribute("aria-pressed", "false");
    }
    this.wrap.before(bar);
    return bar;
  }

  setTool(tool) {
    this.tool = tool;
    this.canvas.dataset.tool = tool;
    if (this.goalButton) this.goalButton.setAttribute("aria-pressed", String(tool === "goal"));
  }

  fillFollow() {
    if (!this.followSelect) return;
    const options = [["", "nobody"], ...[...this.robots.values()].sort((a, b) => a.name.localeCompare(b.name)).map((r) => [String(r.id), r.name])];
    this.followSelect.replaceChildren(...options.map(([value, text]) => new Option(text, value)));
    this.followSelect.value = this.following == null ? "" : String(this.following);
  }

  listen() {
    const canvas = this.canvas;
    canvas.tabIndex = 0;
    canvas.style.touchAction = "none"; // the map handles pinch and drag itself
    canvas.addEventListener("wheel", (event) => {
      event.preventDefault();
      const step = event.deltaMode === 1 ? 0.05 : 0.0015; // lines or pixels
      this.zoomAt(...this.eventPoint(event), Math.exp(-event.deltaY * step));
    }, { passive: false });
    canvas.addEventListener("pointerdown", (event) => this.down(event));
    canvas.addEventListener("pointermove", (event) => this.move(event));
    canvas.addEventListener("pointerup", (event) => this.up(event));
    canvas.addEventListener("pointercancel", (event) => { this.pointers.delete(event.pointerId); this.gesture = null; this.redraw(); });
    canvas.addEventListener("pointerleave", (event) => { if (event.pointerType === "mouse" && !this.card.dataset.pinned) this.hideCard(); });
    canvas.addEventListener("contextmenu", (event) => event.preventDefault());
    canvas.addEventListener("keydown", (event) => this.key(event));
  }

  key(event) {
    const step = 40 * this.ratio;
    const centre = [this.canvas.width / 2, this.canvas.height / 2];
    const actions = {
      "+": () => this.zoomAt(...centre, 1.5), "=": () => this.zoomAt(...centre, 1.5), "-": () => this.zoomAt(...centre, 1 / 1.5),
      0: () => this.fit(), ArrowLeft: () => this.panBy(step, 0), ArrowRight: () => this.panBy(-step, 0),
      ArrowUp: () => this.panBy(0, step), ArrowDown: () => this.panBy(0, -step), Escape: () => this.hideCard(),
    };
    if (actions[event.key]) { event.preventDefault(); actions[event.key](); }
  }

  down(event) {
    this.canvas.setPointerCapture(event.pointerId);
    const point = this.eventPoint(event);
    this.pointers.set(event.pointerId, point);
    if (this.pointers.size === 2) {
      const [a, b] = [...this.pointers.values()];
      this.gesture = { kind: "pinch", distance: Math.hypot(a[0] - b[0], a[1] - b[1]), mid: [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2] };
      return;
    }
    if (this.pointers.size > 2) return;
    const goal = this.tool === "goal" && this.onGoal && event.button === 0;
    this.gesture = { kind: goal ? "goal" : "pan", start: point, last: point, moved: false, world: this.toWorld(...point), touch: event.pointerType !== "mouse" };
  }

  move(event) {
    const point = this.eventPoint(event);
    if (!this.pointers.has(event.pointerId)) { if (event.pointerType === "mouse") this.hover(point); return; }
    this.pointers.set(event.pointerId, point);
    const gesture = this.gesture;
    if (!gesture) return;
    if (gesture.kind === "pinch") {
      const [a, b] = [...this.pointers.values()];
      const distance = Math.hypot(a[0] - b[0], a[1] - b[1]);
      const mid = [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2];
      this.panBy(mid[0] - gesture.mid[0], mid[1] - gesture.mid[1]);
      if (gesture.distance > 0) this.zoomAt(...mid, distance / gesture.distance);
      Object.assign(gesture, { distance, mid });
      return;
    }
    if (Math.hypot(point[0] - gesture.start[0], point[1] - gesture.start[1]) > DRAG_PX * this.ratio) gesture.moved = true;
    if (gesture.kind === "pan" && gesture.moved) this.panBy(point[0] - gesture.last[0], point[1] - gesture.last[1]);
    if (gesture.kind === "goal" && gesture.moved) {
      const [wx, wy] = this.toWorld(...point);
      gesture.yaw = Math.atan2(wy - gesture.world[1], wx - gesture.world[0]);
      this.redraw();
    }
    gesture.last = point;
  }

  up(event) {
    if (!this.pointers.delete(event.pointerId)) return;
    const gesture = this.gesture;
    if (!gesture || gesture.kind === "pinch") { if (!this.pointers.size) this.gesture = null; return; }
    this.gesture = null;
    if (gesture.kind === "goal" && gesture.moved) {
      const [x, y] = gesture.world;
      const round = (value, digits) => Math.round(value * 10 ** digits) / 10 ** digits;
      this.redraw();
      this.onGoal({ x: round(x, 2), y: round(y, 2), yaw: round(gesture.yaw, 3) });
      return;
    }
    if (!gesture.moved) this.tap(gesture.start);
  }

  // A click or a tap: on robots, the card naming them (pinned); elsewhere, the place for onPick.
  tap(point) {
    const here = this.robotsAt(point);
    if (here.length) { this.showCard(here, point, true); return; }
    this.hideCard();
    if (!this.onPick) return;
    const [x, y] = this.toWorld(...point);
    const near = this.locations.find((spot) => Math.hypot(spot.x - x, spot.y - y) < Math.max(PICK_RADIUS_M, (PICK_PX * this.ratio) / this.scale));
    this.onPick(near ? { id: near.id, name: near.name } : { x: Math.round(x * 100) / 100, y: Math.round(y * 100) / 100 });
  }

  hover(point) {
    if (this.card.dataset.pinned) return;
    const here = this.robotsAt(point);
    if (here.length) this.showCard(here, point, false); else this.hideCard();
  }

  // The robots at a canvas point: within PICK_PX of it or of their drawn body, or whose label is there.
  robotsAt([px, py]) {
    const found = [];
    this.robots.forEach((robot) => {
      const at = this.where(robot);
      if (!at) return;
      const [sx, sy] = this.toScreen(at[0], at[1]);
      const distance = Math.hypot(sx - px, sy - py);
      const label = this.labels.find((entry) => entry.id === robot.id);
      const onLabel = label && px >= label.box[0] && px <= label.box[0] + label.box[2] && py >= label.box[1] && py <= label.box[1] + label.box[3];
      if (onLabel || distance <= Math.max(PICK_PX * this.ratio, this.reach(robot) * this.scale)) found.push([onLabel ? -1 : distance, robot]);
    });
    return found.sort((a, b) => a[0] - b[0]).map(([, robot]) => robot);
  }

  showCard(robots, [px, py], pinned) {
    const card = this.card;
    card.replaceChildren();
    if (pinned) card.dataset.pinned = "1"; else delete card.dataset.pinned;
    const title = document.createElement("div");
    title.className = "map-card-title";
    title.textContent = robots.length === 1 ? "1 robot here" : `${robots.length} robots here`;
    card.append(title);
    const list = document.createElement("ul");
    robots.slice(0, CARD_ROBOTS).forEach((robot) => {
      const li = document.createElement("li");
      li.dataset.robotId = robot.id;
      const name = document.createElement("a");
      name.href = `/robots/${robot.id}/`;
      name.textContent = `${STATE_GLYPH[robot.state] || "•"} ${robot.name}`;
      const facts = [robot.state, robot.model, robot.pose ? `${Math.abs(robot.pose.v || 0).toFixed(2)} m/s` : null,
        robot.pose && robot.pose.battery != null ? `battery ${Math.round(robot.pose.battery)}%` : null,
        robot.waitingFor ? `waiting for ${robot.waitingFor}` : null, robot.holder ? `held by ${robot.holder}` : null,
        poseTrouble(robot) || null].filter(Boolean);
      const detail = document.createElement("span");
      detail.className = "muted";
      detail.textContent = ` ${facts.join(" · ")}`;
      li.append(name, detail);
      if (pinned) {
        const follow = document.createElement("button");
        follow.type = "button";
        follow.textContent = "Follow";
        follow.addEventListener("click", () => { this.follow(robot.id, 3); this.hideCard(); });
        li.append(" ", follow);
      }
      list.append(li);
    });
    card.append(list);
    if (robots.length > CARD_ROBOTS) card.append(`… and ${robots.length - CARD_ROBOTS} more (zoom in)`);
    if (pinned) {
      const close = document.createElement("button");
      close.type = "button";
      close.className = "map-card-close";
      close.textContent = "×";
      close.setAttribute("aria-label", "Close");
      close.addEventListener("click", () => this.hideCard());
      card.prepend(close);
    }
    card.hidden = false;
    const width = this.canvas.clientWidth;
    const x = px / this.ratio + 14;
    card.style.left = `${Math.max(0, Math.min(x, width - card.offsetWidth - 4))}px`;
    card.style.top = `${Math.max(0, py / this.ratio + 14)}px`;
  }

  hideCard() {
    this.card.hidden = true;
    delete this.card.dataset.pinned;
  }

  // ---- what the page feeds it ----------------------------------------------------------------------------

  setRobots(rows) {
    // a snapshot's waiting_for (whom a robot waits for) is what robot.path messages say later
    this.robots = new Map(rows.map((robot) => [robot.id, { waitingFor: robot.waiting_for || null, ...robot }]));
    this.fillFollow();
    this.redraw();
  }

  update(id, changes) {
    const robot = this.robots.get(id);
    if (robot) Object.assign(robot, changes);
    if (robot && "name" in changes) this.fillFollow();
    this.redraw();
  }

  // A pose from a tick. One refused at the gate keeps the robot where it last was, marked with the reason; one
  // with no place (never a good pose) draws nothing new.
  pose(pose) {
    const robot = this.robots.get(pose.id);
    if (!robot) return;
    robot.pose = placed(pose) ? pose : mergePose(robot, pose);
    if (!placed(robot.pose)) { this.redraw(); return; }
    pose = robot.pose;
    const trail = this.trails.get(pose.id) || [];
    const last = trail[trail.length - 1];
    if (!last || Math.hypot(last[0] - pose.x, last[1] - pose.y) > 0.03) trail.push([pose.x, pose.y]);
    if (trail.length > TRAIL_POINTS) trail.shift();
    this.trails.set(pose.id, trail);
    if (this.following === pose.id) this.center = [pose.x, pose.y];
    this.redraw();
  }

  // A robot's reserved route ([[x, y], ...]; null leaves it; [] clears it) and whom it waits for (execution.traffic).
  path(message) {
    const robot = this.robots.get(message.id);
    if (!robot) return;
    if (message.path !== null) robot.route = message.path;
    robot.waitingFor = message.waiting_for;
    this.redraw();
  }

  // A sensor_msgs/LaserScan of one robot, placed at the robot's pose when it came (the laser at its centre).
  setScan(id, message) {
    const robot = this.robots.get(id);
    const at = robot && this.where(robot);
    if (!at || !message || !Array.isArray(message.ranges)) { this.scan = null; this.redraw(); return; }
    const [x, y, yaw] = at;
    const points = [];
    message.ranges.forEach((range, i) => {
      if (range == null || !Number.isFinite(range) || range < message.range_min || range > message.range_max) return;
      const angle = yaw + message.angle_min + i * message.angle_increment;
      points.push([x + range * Math.cos(angle), y + range * Math.sin(angle)]);
    });
    this.scan = { id, points };
    this.redraw();
  }

  where(robot) {
    if (placed(robot.pose)) return [robot.pose.x, robot.pose.y, Number.isFinite(robot.pose.yaw) ? robot.pose.yaw : 0];
    if (robot.start_pose && robot.start_pose.length >= 2) return [robot.start_pose[0], robot.start_pose[1], robot.start_pose[2] || 0];
    return null;
  }

  // ---- drawing -------------------------------------------------------------------------------------------

  redraw() {
    if (this.queued) return;
    this.queued = true;
    requestAnimationFrame(() => { this.queued = false; this.draw(); });
  }
}
