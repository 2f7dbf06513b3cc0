// Replay of a recording: the map, each robot where it was at the chosen time (with its trail so far), the events
// up to then; a timeline to scrub, and play at real speed. Drawn on a canvas of its own (the live map is not used).
const root = document.getElementById("replay");
const canvas = document.getElementById("replay-map");
const ctx = canvas.getContext("2d");
const scrub = document.getElementById("replay-scrub");
const clock = document.getElementById("replay-time");
const play = document.getElementById("replay-play");
const robotsBody = document.querySelector("#replay-robots tbody");
const eventsList = document.getElementById("replay-events");
const COLORS = ["#1565c0", "#c62828", "#2e7d32", "#6a1b9a", "#ef6c00", "#00838f", "#4e342e", "#ad1457"];

const mapData = JSON.parse(document.getElementById("replay-mapdata").textContent);
let frames = { duration: 0, robots: {}, events: [] };
let view = null; // world -> canvas: {scale, x0, y0}

function bounds() {
  const map = mapData.map;
  if (map) {
    const [ox, oy] = map.origin;
    return { minX: ox, minY: oy, maxX: ox + map.width * map.resolution, maxY: oy + map.height * map.resolution };
  }
  const all = Object.values(frames.robots).flat();
  const xs = all.map((p) => p[1]), ys = all.map((p) => p[2]);
  return { minX: Math.min(...xs, 0) - 1, minY: Math.min(...ys, 0) - 1, maxX: Math.max(...xs, 1) + 1, maxY: Math.max(...ys, 1) + 1 };
}

function fit() {
  const b = bounds();
  // the whole map in view, the timeline under it still on screen: as wide as the card allows, at most 60 % of the
  // window's height
  const room = { width: canvas.parentElement.clientWidth || 640, height: Math.max(240, window.innerHeight * 0.6) };
  const scale = Math.min(room.width / (b.maxX - b.minX), room.height / (b.maxY - b.minY));
  canvas.width = Math.round((b.maxX - b.minX) * scale);
  canvas.height = Math.round((b.maxY - b.minY) * scale);
  view = { scale, minX: b.minX, maxY: b.maxY };
}

const fixed = (v) => (Math.abs(v) < 0.005 ? 0 : v).toFixed(2); // no "-0.00"
const px = (x, y) => [(x - view.minX) * view.scale, (view.maxY - y) * view.scale];

function drawMap() {
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  const map = mapData.map;
  if (!map) return;
  const cell = map.resolution * view.scale;
  for (let row = 0; row < map.height; row++) {
    for (let col = 0; col < map.width; col++) {
      const glyph = map.cells[row * map.width + col];
      if (glyph === ".") continue;
      ctx.fillStyle = glyph === "#" ? "#37474f" : "#eceff1";
      const [x, y] = px(map.origin[0] + col * map.resolution, map.origin[1] + (row + 1) * map.resolution);
      ctx.fillRect(x, y, cell + 0.5, cell + 0.5);
    }
  }
  ctx.font = "12px system-ui, sans-serif";
  for (const place of mapData.locations || []) {
    const [x, y] = px(place.x, place.y);
    ctx.fillStyle = "#90a4ae";
    ctx.fillRect(x - 3, y - 3, 6, 6);
    ctx.fillText(place.name, x + 5, y - 5);
  }
}

function at(poses, t) {
  // the last pose at or before t (binary search); before the first: none
  let low = 0, high = poses.length - 1, found = -1;
  while (low <= high) {
    const mid = (low + high) >> 1;
    if (poses[mid][0] <= t) { found = mid; low = mid + 1; } else high = mid - 1;
  }
  return found;
}

function render(t) {
  drawMap();
  robotsBody.replaceChildren();
  Object.entries(frames.robots).forEach(([name, poses], i) => {
    const color = COLORS[i % COLORS.length];
    const last = at(poses, t);
    const tr = document.createElement("tr");
    tr.dataset.robot = name;
    if (last < 0) {
      tr.innerHTML = "<th></th><td>–</td><td>–</td><td>–</td>";
    } else {
      ctx.strokeStyle = color;
      ctx.globalAlpha = 0.5;
      ctx.setLineDash([3, 3]);
      ctx.beginPath();
      for (let k = 0; k <= last; k++) ctx[k ? "lineTo" : "moveTo"](...px(poses[k][1], poses[k][2]));
      ctx.stroke();
      ctx.setLineDash([]);
      ctx.globalAlpha = 1;
      const [, x, y, yaw] = poses[last];
      const [cx, cy] = px(x, y);
      ctx.fillStyle = color;
      ctx.beginPath();
      ctx.arc(cx, cy, 6, 0, 2 * Math.PI);
      ctx.fill();
      ctx.beginPath();
      ctx.moveTo(cx, cy);
      ctx.lineTo(cx + 12 * Math.cos(yaw), cy - 12 * Math.sin(yaw));
      ctx.stroke();
      ctx.fillStyle = "#000";
      ctx.fillText(name, cx + 8, cy + 14);
      tr.innerHTML = `<th></th><td>${fixed(x)}</td><td>${fixed(y)}</td><td>${Math.round((yaw * 180) / Math.PI) || 0}</td>`;
    }
    tr.querySelector("th").textContent = name;
    tr.querySelector("th").style.color = color;
    robotsBody.append(tr);
  });
  let current = null;
  for (const li of eventsList.children) {
    const past = Number(li.dataset.t) <= t;
    li.classList.toggle("future", !past);
    li.classList.remove("current");
    if (past) current = li;
  }
  if (current) current.classList.add("current");
  clock.textContent = `${t.toFixed(1)} s of ${frames.duration.toFixed(1)} s`;
}

let playing = null;
function stop() {
  if (playing) cancelAnimationFrame(playing);
  playing = null;
  play.textContent = "▶ Play";
  play.setAttribute("aria-pressed", "false");
}
play.addEventListener("click", () => {
  if (playing) return stop();
  if (Number(scrub.value) >= frames.duration) scrub.value = "0";
  const begun = performance.now() - Number(scrub.value) * 1000;
  play.textContent = "❚❚ Pause";
  play.setAttribute("aria-pressed", "true");
  const step = (now) => {
    const t = Math.min(frames.duration, (now - begun) / 1000);
    scrub.value = String(t);
    render(t);
    if (t >= frames.duration) return stop();
    playing = requestAnimationFrame(step);
  };
  playing = requestAnimationFrame(step);
});
scrub.addEventListener("input", () => { stop(); render(Number(scrub.value)); });
window.addEventListener("resize", () => { fit(); render(Number(scrub.value)); });

async function load() {
  const response = await fetch(root.dataset.frames, { credentials: "same-origin" });
  if (!response.ok) { clock.textContent = `could not load the recording (HTTP ${response.status})`; return; }
  frames = await response.json();
  scrub.max = String(frames.duration);
  for (const event of frames.events) {
    const li = document.createElement("li");
    li.dataset.t = String(event.t);
    li.textContent = `${event.t.toFixed(1)} s · ${event.text}`;
    eventsList.append(li);
  }
  fit();
  render(0);
  root.dataset.loaded = "true";
}
load();
