// The live map on a canvas: occupancy grid, locations, robots as oriented footprints with names, state glyphs,
// trails, goals, reserved routes and whom a robot waits for. Drawing is coalesced to one frame per animation tick, however many poses arrive.
import { STATE_COLOR, STATE_GLYPH } from "./api.js";

const TRAIL_POINTS = 120;
const PICK_RADIUS_M = 0.4;
const MIN_DRAWN_M = 0.18; // small robots are drawn at least this big (metres) so they stay visible
const DEFAULT_FOOTPRINT = [[0.2, 0], [-0.15, 0.15], [-0.15, -0.15]];
// Labels are placed busy robots' first; one that would cover a label already placed is left out, so a map of
// hundreds of robots stays readable (every robot is still drawn, over the labels, and listed in the table).
const LABEL_RANK = { motion: 3, work: 3, dialog: 3, ready: 2, registered: 1 };

export class FleetMap {
  constructor(canvas, mapData, onPick) {
    this.canvas = canvas;
    this.map = mapData.map;
    this.locations = mapData.locations || [];
    this.onPick = onPick;
    this.robots = new Map();
    this.trails = new Map();
    this.grid = this.renderGrid();
    this.queued = false;
    canvas.addEventListener("click", (event) => this.click(event));
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

  layout() {
    const ratio = window.devicePixelRatio || 1;
    const box = this.canvas.getBoundingClientRect();
    this.canvas.width = Math.round(box.width * ratio);
    this.canvas.height = Math.round(box.height * ratio);
    const worldW = this.map.width * this.map.resolution;
    const worldH = this.map.height * this.map.resolution;
    this.scale = Math.min(this.canvas.width / worldW, this.canvas.height / worldH);
    this.offsetX = (this.canvas.width - worldW * this.scale) / 2;
    this.offsetY = (this.canvas.height - worldH * this.scale) / 2;
    this.ratio = ratio;
  }

  toScreen(x, y) {
    const [ox, oy] = this.map.origin;
    const worldH = this.map.height * this.map.resolution;
    return [this.offsetX + (x - ox) * this.scale, this.offsetY + (worldH - (y - oy)) * this.scale];
  }

  toWorld(px, py) {
    const [ox, oy] = this.map.origin;
    const worldH = this.map.height * this.map.resolution;
    return [(px - this.offsetX) / this.scale + ox, worldH - (py - this.offsetY) / this.scale + oy];
  }

  click(event) {
    const box = this.canvas.getBoundingClientRect();
    const [x, y] = this.toWorld((event.clientX - box.left) * this.ratio, (event.clientY - box.top) * this.ratio);
    const near = this.locations.find((spot) => Math.hypot(spot.x - x, spot.y - y) < PICK_RADIUS_M);
    this.onPick(near ? { id: near.id, name: near.name } : { x: Math.round(x * 10) / 10, y: Math.round(y * 10) / 10 });
  }

  setRobots(rows) {
    this.robots = new Map(rows.map((robot) => [robot.id, { ...robot }]));
    this.redraw();
  }

  update(id, changes) {
    const robot = this.robots.get(id);
    if (robot) Object.assign(robot, changes);
    this.redraw();
  }

  pose(pose) {
    const robot = this.robots.get(pose.id);
    if (!robot) return;
    robot.pose = pose;
    const trail = this.trails.get(pose.id) || [];
    const last = trail[trail.length - 1];
    if (!last || Math.hypot(last[0] - pose.x, last[1] - pose.y) > 0.03) trail.push([pose.x, pose.y]);
    if (trail.length > TRAIL_POINTS) trail.shift();
    this.trails.set(pose.id, trail);
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

  where(robot) {
    if (robot.pose) return [robot.pose.x, robot.pose.y, robot.pose.yaw];
    if (robot.start_pose && robot.start_pose.length >= 2) return [robot.start_pose[0], robot.start_pose[1], robot.start_pose[2] || 0];
    return null;
  }

  redraw() {
    if (this.queued) return;
    this.queued = true;
    requestAnimationFrame(() => { this.queued = false; this.draw(); });
  }

  draw() {
    this.layout();
    const context = this.canvas.getContext("2d");
    context.imageSmoothingEnabled = false;
    context.fillStyle = "#cfd8dc";
    context.fillRect(0, 0, this.canvas.width, this.canvas.height);
    const [gx, gy] = this.toScreen(this.map.origin[0], this.map.origin[1] + this.map.height * this.map.resolution);
    context.drawImage(this.grid, gx, gy, this.map.width * this.map.resolution * this.scale, this.map.height * this.map.resolution * this.scale);
    this.locations.forEach((spot) => this.drawLocation(context, spot));
    this.robots.forEach((robot) => this.drawTrail(context, robot));
    this.robots.forEach((robot) => this.drawRoute(context, robot));
    this.robots.forEach((robot) => this.drawGoal(context, robot));
    const placed = [];
    const byRank = [...this.robots.values()].sort((a, b) => (LABEL_RANK[b.state] || 0) - (LABEL_RANK[a.state] || 0));
    this.labelled = byRank.filter((robot) => this.drawLabel(context, robot, placed)).map((robot) => robot.name);
    this.robots.forEach((robot) => this.drawRobot(context, robot));
  }

  footprint(robot) {
    return robot.footprint && robot.footprint.length >= 3 ? robot.footprint : DEFAULT_FOOTPRINT;
  }

  // The robot's drawn radius in metres.
  reach(robot) {
    return Math.max(MIN_DRAWN_M, ...this.footprint(robot).map(([fx, fy]) => Math.hypot(fx, fy)));
  }

  font(size, weight = 600) { return `${weight} ${Math.round(size * this.ratio)}px system-ui, sans-serif`; }

  drawLocation(context, spot) {
    const [x, y] = this.toScreen(spot.x, spot.y);
    const r = 5 * this.ratio;
    context.fillStyle = spot.kind === "room" ? "#00897b" : "#f9a825";
    context.strokeStyle = "#263238";
    context.lineWidth = 1.5 * this.ratio;
    context.beginPath();
    context.moveTo(x, y - r); context.lineTo(x + r, y); context.lineTo(x, y + r); context.lineTo(x - r, y); context.closePath();
    context.fill(); context.stroke();
    context.font = this.font(12, 700);
    context.fillStyle = "#263238";
    context.fillText(spot.name, x + r + 2 * this.ratio, y - r);
  }

  drawTrail(context, robot) {
    const trail = this.trails.get(robot.id);
    if (!trail || trail.length < 2) return;
    context.strokeStyle = STATE_COLOR[robot.state] || "#546e7a";
    context.globalAlpha = 0.55;
    context.lineWidth = 2 * this.ratio;
    context.setLineDash([3 * this.ratio, 3 * this.ratio]);
    context.beginPath();
    trail.forEach(([x, y], index) => {
      const [px, py] = this.toScreen(x, y);
      if (index) context.lineTo(px, py); else context.moveTo(px, py);
    });
    context.stroke();
    context.setLineDash([]);
    context.globalAlpha = 1;
  }

  drawRoute(context, robot) {
    const at = this.where(robot);
    if (!robot.route || !robot.route.length || !at) return;
    context.strokeStyle = STATE_COLOR[robot.state] || "#546e7a";
    context.lineWidth = Math.max(2 * this.ratio, 2 * this.reach(robot) * this.scale * 0.35); // the lane it holds
    context.globalAlpha = 0.3;
    context.lineJoin = context.lineCap = "round";
    context.beginPath();
    [at, ...robot.route].forEach(([x, y], index) => {
      const [px, py] = this.toScreen(x, y);
      if (index) context.lineTo(px, py); else context.moveTo(px, py);
    });
    context.stroke();
    context.globalAlpha = 1;
  }

  drawGoal(context, robot) {
    if (!robot.goal || robot.goal.x == null) return;
    const [x, y] = this.toScreen(robot.goal.x, robot.goal.y);
    const r = 9 * this.ratio;
    context.strokeStyle = "#c62828";
    context.lineWidth = 2 * this.ratio;
    context.beginPath();
    context.arc(x, y, r, 0, Math.PI * 2);
    context.moveTo(x - r * 1.4, y); context.lineTo(x + r * 1.4, y);
    context.moveTo(x, y - r * 1.4); context.lineTo(x, y + r * 1.4);
    context.stroke();
    const at = this.where(robot);
    if (at) {
      const [rx, ry] = this.toScreen(at[0], at[1]);
      context.setLineDash([6 * this.ratio, 4 * this.ratio]);
      context.beginPath(); context.moveTo(rx, ry); context.lineTo(x, y); context.stroke();
      context.setLineDash([]);
    }
  }

  drawRobot(context, robot) {
    const at = this.where(robot);
    if (!at) return;
    const [x, y, yaw] = at;
    const color = STATE_COLOR[robot.state] || "#546e7a";
    const footprint = this.footprint(robot);
    const size = Math.max(...footprint.map(([fx, fy]) => Math.hypot(fx, fy)));
    const grow = this.reach(robot) / size;
    context.save();
    context.beginPath();
    footprint.forEach(([fx, fy], index) => {
      const wx = x + grow * (fx * Math.cos(yaw) - fy * Math.sin(yaw));
      const wy = y + grow * (fx * Math.sin(yaw) + fy * Math.cos(yaw));
      const [px, py] = this.toScreen(wx, wy);
      if (index) context.lineTo(px, py); else context.moveTo(px, py);
    });
    context.closePath();
    context.fillStyle = color;
    context.globalAlpha = robot.link_status === "offline" ? 0.45 : 0.9;
    context.fill();
    context.globalAlpha = 1;
    context.lineWidth = 2 * this.ratio;
    context.strokeStyle = "#111";
    if (robot.link_status === "offline") context.setLineDash([4 * this.ratio, 3 * this.ratio]);
    context.stroke();
    context.setLineDash([]);
    // heading: a line from the centre to the front
    const [cx, cy] = this.toScreen(x, y);
    const [hx, hy] = this.toScreen(x + Math.cos(yaw) * size * grow * 1.3, y + Math.sin(yaw) * size * grow * 1.3);
    context.beginPath(); context.moveTo(cx, cy); context.lineTo(hx, hy); context.stroke();
    context.restore();
  }

  // The robot's name and state glyph above it, unless that would cover a label in placed; true if drawn.
  drawLabel(context, robot, placed) {
    const at = this.where(robot);
    if (!at) return false;
    const [cx, cy] = this.toScreen(at[0], at[1]);
    const top = cy - this.reach(robot) * this.scale - 20 * this.ratio;
    const waiting = robot.waitingFor ? ` ⏸ waiting for ${robot.waitingFor}` : "";
    const label = `${STATE_GLYPH[robot.state] || "•"} ${robot.name}${waiting}`;
    context.font = this.font(12, 700);
    const width = context.measureText(label).width;
    const box = [cx - width / 2 - 3 * this.ratio, top, width + 6 * this.ratio, 16 * this.ratio];
    const covers = ([x, y, w, h]) => box[0] < x + w && x < box[0] + box[2] && box[1] < y + h && y < box[1] + box[3];
    if (placed.some(covers)) return false;
    placed.push(box);
    context.fillStyle = "rgba(255,255,255,.88)";
    context.fillRect(...box);
    context.fillStyle = "#111";
    context.fillText(label, cx - width / 2, top + 12 * this.ratio);
    return true;
  }
}
