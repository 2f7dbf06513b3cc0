// The experiments page: the paper's tables plotted beside ours (uPlot, vendored), and each unfinished run's status
// and progress followed live (polled: the page opens no socket); a run that ends brings its results in place.
const PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf"];
const POLL_MS = 2000;

function shortColumn(text) {
  // "U_x^s = 0.5 m/s" -> "0.5 m/s"; "Goal 01 success rate 08.00-10.00" -> "08.00-10.00"
  const speed = text.match(/=\s*(.+)$/);
  if (speed) return speed[1];
  const slot = text.match(/(\d\d\.\d\d-\d\d\.\d\d)$/);
  return slot ? slot[1] : text.length > 18 ? `${text.slice(0, 16)}…` : text;
}

function sectionPlot(table, section, width) {
  const columns = table.columns.map(shortColumn);
  const xs = columns.map((_, i) => i + 1);
  const series = [{ label: table.column_quantity || "column", value: (u, v) => (v == null ? "–" : columns[v - 1]) }];
  const data = [xs];
  section.rows.forEach((row, i) => {
    const stroke = PALETTE[i % PALETTE.length];
    const show = (u, v) => (v == null ? "–" : v.toFixed(3));
    series.push({ label: `${row.label} paper`, stroke, dash: [6, 4], width: 1.5, value: show, points: { show: true } });
    data.push(row.cells.map((cell) => cell.paper));
    series.push({ label: `${row.label} ours`, stroke, width: 2, value: show, points: { show: true } });
    data.push(row.cells.map((cell) => cell.ours));
  });
  return {
    opts: {
      title: section.name,
      width,
      height: 220,
      series,
      scales: { x: { time: false, range: [0.7, columns.length + 0.3] } },
      axes: [
        { label: table.column_quantity, splits: () => xs, values: (u, splits) => splits.map((v) => columns[v - 1] ?? "") },
        { label: table.unit, size: 56 },
      ],
      legend: { live: true },
    },
    data,
  };
}

function drawPlots() {
  const source = document.getElementById("comparisons");
  if (!source || !window.uPlot) return;
  for (const table of JSON.parse(source.textContent)) {
    const holder = document.querySelector(`.plots[data-table="${table.number}"]`);
    if (!holder) continue;
    const width = Math.max(320, Math.min(560, holder.clientWidth || 480));
    for (const section of table.sections) {
      const { opts, data } = sectionPlot(table, section, width);
      const figure = document.createElement("figure");
      figure.className = "plot";
      figure.setAttribute("aria-label", `Table ${table.number}, ${section.name}: the paper against ours`);
      holder.append(figure);
      new window.uPlot(opts, data, figure);
    }
  }
}

function unfinished() {
  return [...document.querySelectorAll("#runs tr[data-run]")].filter((row) => !["succeeded", "failed"].includes(row.dataset.status));
}

function show(row, run) {
  row.dataset.status = run.status;
  const status = row.querySelector(".status");
  status.textContent = run.status;
  status.dataset.status = run.status;
  const bar = row.querySelector("progress");
  bar.max = Math.max(1, run.total);
  bar.value = run.done;
  row.querySelector(".run-count").textContent = `${run.done} / ${run.total}`;
}

async function refreshRuns() {
  // a run ended: its results table, from a fresh copy of the page
  const response = await fetch(location.pathname + location.search, { credentials: "same-origin" });
  if (!response.ok) return;
  const fresh = new DOMParser().parseFromString(await response.text(), "text/html").getElementById("runs");
  if (fresh) document.getElementById("runs").replaceWith(document.adoptNode(fresh));
}

async function poll() {
  const rows = unfinished();
  if (rows.length) {
    try {
      const ids = rows.map((row) => row.dataset.run).join(",");
      const response = await fetch(`/experiments/status/?ids=${ids}`, { credentials: "same-origin" });
      if (response.ok) {
        let ended = false;
        for (const run of (await response.json()).runs) {
          const row = document.querySelector(`#runs tr[data-run="${run.id}"]`);
          if (!row) continue;
          show(row, run);
          ended ||= run.status === "succeeded" || run.status === "failed";
        }
        if (ended) await refreshRuns();
      }
    } catch (error) {
      // the server restarting: the next poll tries again
    }
  }
  setTimeout(poll, POLL_MS);
}

drawPlots();
poll();
