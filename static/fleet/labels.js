// Where the map's labels may go: boxes already taken, and robots' centres, in coarse grids of cells so that
// placing hundreds of labels stays local (static/fleet/map.js places them).

// Whether another robot's centre is nearer this label box than its own robot's.
export function nearerOther(points, box, own) {
  const d = boxDistance(box, own.cx, own.cy);
  for (const point of points.near(box, d)) if (point !== own && boxDistance(box, point.cx, point.cy) < d) return true;
  return false;
}

// Boxes [x, y, w, h] in a coarse grid of cells, so overlap checks stay local with hundreds of labels.
export class BoxIndex {
  constructor(cell) { this.cell = cell; this.cells = new Map(); }
  *keys([x, y, w, h]) {
    for (let i = Math.floor(x / this.cell); i <= Math.floor((x + w) / this.cell); i += 1) {
      for (let j = Math.floor(y / this.cell); j <= Math.floor((y + h) / this.cell); j += 1) yield `${i},${j}`;
    }
  }
  add(box) { for (const key of this.keys(box)) (this.cells.get(key) || this.cells.set(key, []).get(key)).push(box); }
  hits(box) {
    for (const key of this.keys(box)) {
      for (const [x, y, w, h] of this.cells.get(key) || []) {
        if (box[0] < x + w && x < box[0] + box[2] && box[1] < y + h && y < box[1] + box[3]) return true;
      }
    }
    return false;
  }
}

// Robots' centres in the same coarse cells: which robots are near a label's place.
export class PointIndex {
  constructor(cell) { this.cell = cell; this.cells = new Map(); }
  add(point) {
    const key = `${Math.floor(point.cx / this.cell)},${Math.floor(point.cy / this.cell)}`;
    (this.cells.get(key) || this.cells.set(key, []).get(key)).push(point);
  }
  *near([x, y, w, h], d) {
    for (let i = Math.floor((x - d) / this.cell); i <= Math.floor((x + w + d) / this.cell); i += 1) {
      for (let j = Math.floor((y - d) / this.cell); j <= Math.floor((y + h + d) / this.cell); j += 1) yield* this.cells.get(`${i},${j}`) || [];
    }
  }
}

// How far a point is from a box (0 inside it).
function boxDistance([x, y, w, h], px, py) {
  return Math.hypot(Math.max(x - px, 0, px - x - w), Math.max(y - py, 0, py - y - h));
}

