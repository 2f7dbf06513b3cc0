// Small helpers every page uses: the CSRF token, JSON requests, toasts, state glyphs.

export function csrfToken() {
  const field = document.querySelector("input[name=csrfmiddlewaretoken]");
  if (field) return field.value;
  const match = document.cookie.match(/(?:^|; )csrftoken=([^;]+)/);
  return match ? decodeURIComponent(match[1]) : "";
}

export async function request(url, body = undefined, method = "POST") {
  const response = await fetch(url, {
    method,
    credentials: "same-origin",
    headers: { "Content-Type": "application/json", Accept: "application/json", "X-CSRFToken": csrfToken() },
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  let data = null;
  try { data = await response.json(); } catch { data = null; }
  if (!response.ok) {
    const detail = data && data.detail ? (typeof data.detail === "string" ? data.detail : JSON.stringify(data.detail)) : response.statusText;
    const error = new Error(detail || `HTTP ${response.status}`);
    error.status = response.status;
    throw error;
  }
  return data;
}

export function toast(text, bad = false) {
  const box = document.getElementById("toasts");
  if (!box) return;
  const item = document.createElement("div");
  item.className = bad ? "toast bad" : "toast";
  item.setAttribute("role", bad ? "alert" : "status");
  item.textContent = text;
  box.append(item);
  setTimeout(() => item.remove(), 6000);
}

// State is never shown by colour alone: each state has a glyph and its name.
export const STATE_GLYPH = { registered: "○", ready: "●", dialog: "?", motion: "➤", work: "⚙", offline: "✕", teleop: "⇆" };
export const STATE_COLOR = {
  registered: "#546e7a", ready: "#2e7d32", teleop: "#00838f", dialog: "#6a1b9a", motion: "#1565c0", work: "#ef6c00", offline: "#8d8d8d",
};

export function stateBadge(state) {
  const span = document.createElement("span");
  span.className = "state";
  span.dataset.state = state;
  span.textContent = `${STATE_GLYPH[state] || "•"} ${state}`;
  return span;
}

export const canControl = () => document.body.dataset.canControl === "true";
export const canRegister = () => document.body.dataset.canRegister === "true";
