// cutlab supervision: redraws the running attempts from the server-sent events of
// /supervision/events. Text goes in with textContent only (never as HTML).
"use strict";
(function () {
  const tbody = document.querySelector("#running tbody");
  const status = document.getElementById("live-status");
  const none = document.getElementById("none-running");
  if (!tbody || !window.EventSource) return;
  function cell(tr, text, href) {
    const td = document.createElement("td");
    if (href) {
      const a = document.createElement("a");
      a.href = href;
      a.textContent = text;
      td.appendChild(a);
    } else {
      td.textContent = text;
    }
    tr.appendChild(td);
    return td;
  }
  function when(ns) {
    return new Date(ns / 1e6).toISOString().slice(0, 19).replace("T", " ");
  }
  const source = new EventSource("/supervision/events");
  source.addEventListener("running", function (e) {
    const list = JSON.parse(e.data);
    tbody.replaceChildren();
    for (const r of list) {
      const tr = document.createElement("tr");
      cell(tr, "attempt " + r.id, "/attempts/" + Number(r.id));
      cell(tr, r.trainee.name, "/trainees/" + Number(r.trainee.id));
      cell(tr, r.exercise.name);
      cell(tr, when(r.started_ns));
      cell(tr, Math.round(r.elapsed_s) + " s").className = "num";
      cell(tr, r.recording_bytes == null ? "–" : (r.recording_bytes / 1e6).toFixed(1) + " MB").className = "num";
      if (r.live) cell(tr, "live view", "/station/" + Number(r.id)); else cell(tr, "–");
      tbody.appendChild(tr);
    }
    if (none) none.hidden = list.length > 0;
    if (status) status.textContent = "Last update " + new Date().toLocaleTimeString() + ".";
  });
  source.addEventListener("error", function () {
    if (status) status.textContent = "Connection lost; retrying.";
  });
})();
