// One WebSocket per page: the snapshot first, then deltas; reconnects by itself with backoff.

// A tick of poses comes as rows under its fields, `t` in ms after the tick's `at` (portal/fanout.py's encode):
// made back into one object per pose, as the handlers take them. A row that is not a list is left out.
export function poseRows(message) {
  const fields = Array.isArray(message.fields) ? message.fields : [];
  const at = typeof message.at === "number" ? message.at : 0;
  return message.rows.filter(Array.isArray).map((row) => {
    const pose = {};
    fields.forEach((field, i) => { if (row[i] !== null && row[i] !== undefined) pose[field] = row[i]; });
    if (typeof pose.t === "number") pose.t = at + pose.t / 1000;
    return pose;
  });
}

// Pushes that came together arrive as one {"type": "batch", "messages": [...]} frame (portal/fanout.py): the
// messages of a frame, in their order.
export function unpack(message) {
  if (message && message.type === "batch" && Array.isArray(message.messages)) return message.messages;
  return [message];
}

export function connectLive(path, handlers) {
  const conn = document.getElementById("conn");
  let socket = null;
  let delay = 500;
  const pending = [];
  const waiting = new Map(); // ref -> resolve, for request()
  let nextRef = 1;

  function status(state, text) {
    if (!conn) return;
    conn.dataset.state = state;
    conn.textContent = text;
  }

  // one message that cannot be read or handled costs itself only, never the page's later messages
  function handle(message) {
    if (!message || typeof message !== "object") return;
    if (message.type === "fleet.poses" && Array.isArray(message.rows)) message.poses = poseRows(message);
    if (message.type === "command.result" && waiting.has(message.ref)) {
      waiting.get(message.ref)(message);
      waiting.delete(message.ref);
    }
    const handler = handlers[message.type];
    try { if (handler) handler(message); } catch (error) { console.error(`live: ${message.type} not handled`, error); }
    if (message.type === "snapshot") status("live", "live");
  }

  function open() {
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    socket = new WebSocket(`${scheme}://${location.host}${path}`);
    socket.addEventListener("open", () => {
      delay = 500;
      status("syncing", "syncing"); // "live" once the snapshot is shown: before it the page shows old state
      while (pending.length) socket.send(pending.shift());
    });
    socket.addEventListener("message", (event) => {
      let message;
      try { message = JSON.parse(event.data); } catch (error) { console.error("live: unreadable message dropped", error); return; }
      unpack(message).forEach(handle);
    });
    socket.addEventListener("close", (event) => {
      if (event.code === 4401) { location.href = `/login/?next=${encodeURIComponent(location.pathname)}`; return; }
      if (event.code === 4403 || event.code === 4404) { status("down", "not allowed"); return; }
      status("down", `reconnecting in ${Math.round(delay / 100) / 10} s`);
      setTimeout(open, delay);
      delay = Math.min(delay * 2, 10000);
    });
  }

  open();
  return {
    send(message) {
      const text = JSON.stringify(message);
      if (socket && socket.readyState === WebSocket.OPEN) socket.send(text);
      else pending.push(text);
    },
    get open() { return Boolean(socket && socket.readyState === WebSocket.OPEN); },
    // A command whose answer (its command.result) is awaited: null if none came within timeoutMs.
    request(message, timeoutMs = 15000) {
      const ref = `r${nextRef++}`;
      return new Promise((resolve) => {
        waiting.set(ref, resolve);
        setTimeout(() => { if (waiting.delete(ref)) resolve(null); }, timeoutMs);
        this.send({ ...message, ref });
      });
    },
  };
}
