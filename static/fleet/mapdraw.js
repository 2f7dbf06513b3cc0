// Drawing one frame of the live map (static/fleet/map.js holds its data, view and input, and extends this):
// the occupancy grid, locations, trails, reserved routes and goals, a selected robot's laser scan, robots as
// oriented footprints with state glyphs, their labels, a goal being dragged, and the scale bar.
//
// Labels never cover each other: a label that cannot sit above its robot is moved out along a ring of places
// and tied to it by a leader line (which places are free: static/fleet/labels.js).
//
// The subclass provides the state (canvas, map, grid, locations, robots, trails, scan, scale, ratio, ...) and
// the view (layout, toScreen).
import { BoxIndex, PointIndex, nearerOther } from "./labels.js";
import { STATE_COLOR, STATE_GLYPH } from "./api.js";
import { poseTrouble } from "./robots_table.js";

const MIN_DRAWN_M = 0.18; // small robots are drawn at least this big (metres) so they stay visible
const DEFAULT_FOOTPRINT = [[0.2, 0], [-0.15, 0.15], [-0.15, -0.15]];
// Labels are placed busy robots' first; a label finds the first free place on rings around its robot (above it
// first), so a crowd is named with leader lines; one with no free place within LABEL_RINGS rings is left out
// (the card still names it, the table lists it).
const LABEL_RANK = { motion: 3, work: 3, dialog: 3, ready: 2, registered: 1 };
const LABEL_RINGS = 6;
const DIRECTIONS = [[0, -1], [1, -1], [-1, -1], [1, 0], [-1, 0], [0, 1], [1, 1], [-1, 1]]; // above first

export class MapPainter {
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
    this.drawScan(context);
    this.robots.forEach((robot) => this.drawRobot(context, robot));
    this.drawLabels(context);
    this.drawGoalDrag(context);
    this.drawScaleBar(context);
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

  drawScan(context) {
    if (!this.scan) return;
    context.fillStyle = "#d81b60";
    const size = Math.max(2, 2.5 * this.ratio);
    this.scan.points.forEach(([x, y]) => {
      const [px, py] = this.toScreen(x, y);
      context.fillRect(px - size / 2, py - size / 2, size, size);
    });
  }

  // While a goal is dragged: where it is and the heading it will have.
  drawGoalDrag(context) {
    const gesture = this.gesture;
    if (!gesture || gesture.kind !== "goal" || !gesture.moved || gesture.yaw == null) return;
    const [x, y] = this.toScreen(...gesture.world);
    const length = 36 * this.ratio;
    const [hx, hy] = [x + Math.cos(gesture.yaw) * length, y - Math.sin(gesture.yaw) * length];
    context.strokeStyle = "#c62828";
    context.lineWidth = 3 * this.ratio;
    context.beginPath();
    context.arc(x, y, 7 * this.ratio, 0, Math.PI * 2);
    context.moveTo(x, y); context.lineTo(hx, hy);
    const back = 10 * this.ratio;
    for (const side of [-0.5, 0.5]) {
      context.moveTo(hx, hy);
      context.lineTo(hx - Math.cos(gesture.yaw + side) * back, hy + Math.sin(gesture.yaw + side) * back);
    }
    context.stroke();
  }

  // A bar of a round length (0.1 m ... 500 m) about 100 css px long, bottom left: how far is far.
  drawScaleBar(context) {
    const target = 100 * this.ratio / this.scale;
    const nice = [0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500].find((value) => value >= target * 0.6) || 500;
    const length = nice * this.scale;
    const [x, y] = [10 * this.ratio, this.canvas.height - 12 * this.ratio];
    context.fillStyle = "rgba(255,255,255,.85)";
    context.fillRect(x - 4 * this.ratio, y - 18 * this.ratio, length + 8 * this.ratio + 50 * this.ratio, 24 * this.ratio);
    context.strokeStyle = "#263238";
    context.lineWidth = 2 * this.ratio;
    context.beginPath();
    context.moveTo(x, y - 6 * this.ratio); context.lineTo(x, y); context.lineTo(x + length, y); context.lineTo(x + length, y - 6 * this.ratio);
    context.stroke();
    context.font = this.font(11, 600);
    context.fillStyle = "#263238";
    context.fillText(nice < 1 ? `${Math.round(nice * 100)} cm` : `${nice} m`, x + length + 6 * this.ratio, y - 2 * this.ratio);
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
    const trouble = poseTrouble(robot); // stale or refused: drawn faded, dashed, where it last was
    context.globalAlpha = robot.link_status === "offline" || trouble ? 0.45 : 0.9;
    context.fill();
    context.globalAlpha = 1;
    context.lineWidth = (this.following === robot.id || (this.scan && this.scan.id === robot.id) ? 3.5 : 2) * this.ratio;
    context.strokeStyle = "#111";
    if (robot.link_status === "offline" || trouble) context.setLineDash([4 * this.ratio, 3 * this.ratio]);
    if (robot.pose && robot.pose.fault) context.strokeStyle = "#c62828";
    context.stroke();
    context.setLineDash([]);
    // heading: a line from the centre to the front
    const [cx, cy] = this.toScreen(x, y);
    const [hx, hy] = this.toScreen(x + Math.cos(yaw) * size * grow * 1.3, y + Math.sin(yaw) * size * grow * 1.3);
    context.beginPath(); context.moveTo(cx, cy); context.lineTo(hx, hy); context.stroke();
    context.restore();
  }

  // Robots' labels (busy ones first), then locations' names: each on the first free place of the rings around
  // its anchor, tied to it by a leader line when it is not in its usual place. Robots' bodies are kept clear.
  drawLabels(context) {
    const index = new BoxIndex(64 * this.ratio);
    const ratio = this.ratio;
    const anchors = [];
    this.robots.forEach((robot) => {
      const at = this.where(robot);
      if (!at) return;
      const [cx, cy] = this.toScreen(at[0], at[1]);
      const r = Math.max(this.reach(robot) * this.scale, 4 * ratio);
      const keep = Math.min(r, 10 * ratio); // the middle of each robot stays in sight, however big it is drawn
      index.add([cx - keep, cy - keep, 2 * keep, 2 * keep]);
      anchors.push({ robot, cx, cy, r });
    });
    const points = new PointIndex(64 * ratio);
    anchors.forEach((anchor) => points.add(anchor));
    const rank = ({ robot }) => LABEL_RANK[robot.state] || 0;
    anchors.sort((a, b) => rank(b) - rank(a) || a.robot.name.localeCompare(b.robot.name));
    const shown = [];
    context.font = this.font(12, 700);
    anchors.forEach((anchor) => {
      const { robot, cx, cy, r } = anchor;
      const waiting = robot.waitingFor ? ` ‖ waiting for ${robot.waitingFor}` : "";
      const trouble = poseTrouble(robot);
      const text = `${STATE_GLYPH[robot.state] || "•"} ${robot.name}${waiting}${trouble ? ` · ${trouble}` : ""}`;
      const [w, h] = [context.measureText(text).width + 6 * ratio, 16 * ratio];
      // a label reads as the name of the robot nearest it: first a place nearer its own robot than any other;
      // in a crowd too tight for that, the first free place, tied to its robot by a leader line
      const own = (candidate) => !nearerOther(points, candidate, anchor);
      const box = this.placeLabel(index, cx, cy, r, w, h, DIRECTIONS, own) || this.placeLabel(index, cx, cy, r, w, h, DIRECTIONS, null, true);
      if (box) shown.push({ id: robot.id, name: robot.name, text, box: box.box, leader: box.leader, anchor: [cx, cy], kind: "robot" });
    });
    context.font = this.font(12, 700);
    this.locations.forEach((spot) => {
      const [cx, cy] = this.toScreen(spot.x, spot.y);
      const box = this.placeLabel(index, cx, cy, 6 * ratio, context.measureText(spot.name).width + 4 * ratio, 15 * ratio, [[1, 0], [-1, 0], [0, -1], [0, 1], [1, -1], [-1, -1], [1, 1], [-1, 1]]);
      if (box) shown.push({ id: null, name: spot.name, text: spot.name, box: box.box, leader: box.leader, anchor: [cx, cy], kind: "location" });
    });
    shown.forEach((label) => this.drawLabel(context, label));
    this.labels = shown.filter((label) => label.kind === "robot");
    this.labelled = this.labels.map((label) => label.name);
    this.labelTexts = this.labels.map((label) => label.text); // what a person reads by each robot (tests read it)
    this.locationLabels = shown.filter((label) => label.kind === "location").map((label) => label.name);
  }

  // The first box (w x h) on rings around (cx, cy) beyond radius r that is on the canvas and free; null if none.
  // accept(box): a further test the place must pass; leader: always tie the label to its anchor.
  placeLabel(index, cx, cy, r, w, h, directions = DIRECTIONS, accept = null, leader = false) {
    const gap = 4 * this.ratio;
    for (let ring = 0; ring < LABEL_RINGS; ring += 1) {
      const distance = r + gap + ring * (h + gap);
      for (const [dx, dy] of directions) {
        const length = Math.hypot(dx, dy);
        const [ux, uy] = [dx / length, dy / length];
        // the box's side nearest the anchor sits at the distance along the direction
        const bx = cx + ux * distance + (ux > 0.1 ? 0 : ux < -0.1 ? -w : -w / 2);
        const by = cy + uy * distance + (uy > 0.1 ? 0 : uy < -0.1 ? -h : -h / 2);
        const box = [bx, by, w, h];
        if (bx < 0 || by < 0 || bx + w > this.canvas.width || by + h > this.canvas.height) continue;
        if (index.hits(box) || (accept && !accept(box))) continue;
        index.add(box);
        return { box, leader: leader || ring > 0 || dx !== directions[0][0] || dy !== directions[0][1] };
      }
    }
    return null;
  }

  drawLabel(context, label) {
    const [x, y, w, h] = label.box;
    const [ax, ay] = label.anchor;
    if (label.leader) {
      const [ex, ey] = [Math.min(Math.max(ax, x), x + w), Math.min(Math.max(ay, y), y + h)]; // nearest point of the box
      context.strokeStyle = "#263238";
      context.lineWidth = 1 * this.ratio;
      context.beginPath(); context.moveTo(ax, ay); context.lineTo(ex, ey); context.stroke();
    }
    if (label.kind === "robot") {
      context.fillStyle = "rgba(255,255,255,.9)";
      context.fillRect(x, y, w, h);
      context.font = this.font(12, 700);
      context.fillStyle = "#111";
      context.fillText(label.text, x + 3 * this.ratio, y + 12 * this.ratio);
    } else {
      context.font = this.font(12, 700);
      context.lineWidth = 3 * this.ratio;
      context.strokeStyle = "rgba(255,255,255,.9)";
      context.strokeText(label.text, x + 2 * this.ratio, y + 11 * this.ratio);
      context.fillStyle = "#263238";
      context.fillText(label.text, x + 2 * this.ratio, y + 11 * this.ratio);
    }
  }
}
