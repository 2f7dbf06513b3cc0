// Edit the schedule in place through the JSON API (admins only; the server checks too).
import { request, toast } from "./api.js";

async function save(url, body, method) {
  try {
    await request(url, body, method);
    location.reload();
  } catch (error) {
    toast(`Not saved: ${error.message}`, true);
  }
}

document.querySelectorAll("td[data-robot] .slot-form").forEach((form) => {
  const cell = form.closest("td");
  const body = () => ({
    robot: cell.dataset.robot, start: cell.dataset.start, end: cell.dataset.end,
    goal: form.goal.value, task: form.task.value.trim(), enabled: form.enabled.checked,
  });
  form.addEventListener("submit", (event) => {
    event.preventDefault();
    if (cell.dataset.slot) save(`/api/schedules/${cell.dataset.slot}`, body(), "PUT");
    else save("/api/schedules", body(), "POST");
  });
  form.querySelector(".delete")?.addEventListener("click", () => save(`/api/schedules/${cell.dataset.slot}`, undefined, "DELETE"));
});

const add = document.getElementById("new-slot");
add?.addEventListener("submit", (event) => {
  event.preventDefault();
  save("/api/schedules", {
    robot: add.robot.value, start: add.start.value, end: add.end.value, goal: add.goal.value, task: add.task.value.trim(), enabled: true,
  }, "POST");
});
