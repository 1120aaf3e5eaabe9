// The planning page: candidate incisions drawn on the skin map by a drag (mouse, pen or
// touch) fill the chosen candidate's fields; the fields, typed or drawn, are drawn as lines.
// The map is an SVG in mm with its y flipped (SVG y = -y).
"use strict";
(function () {
  const svg = document.getElementById("skin-map");
  const form = document.getElementById("planning-form");
  if (!svg || !form) {
    return;
  }
  const lines = document.getElementById("candidate-lines");
  const drag = document.getElementById("drag-line");
  const letters = ["a", "b", "c", "d"];
  const NS = "http://www.w3.org/2000/svg";

  function field(letter, key) {
    return document.getElementById(letter + "_" + key);
  }
  function number(input) {
    const v = input && input.value.trim() !== "" ? Number(input.value) : NaN;
    return Number.isFinite(v) ? v : null;
  }
  function mmAt(event) {
    const pt = svg.createSVGPoint();
    pt.x = event.clientX;
    pt.y = event.clientY;
    const p = pt.matrixTransform(svg.getScreenCTM().inverse());
    return [p.x, -p.y];
  }
  function half(v) {
    return Math.round(v * 2) / 2;
  }

  function redraw() {
    lines.replaceChildren();
    letters.forEach(function (l) {
      const e = ["from_x", "from_y", "to_x", "to_y"].map(function (k) { return number(field(l, k)); });
      if (e.some(function (v) { return v === null; })) {
        return;
      }
      const line = document.createElementNS(NS, "line");
      line.setAttribute("class", "candidate cand-" + l);
      line.setAttribute("x1", e[0]);
      line.setAttribute("y1", -e[1]);
      line.setAttribute("x2", e[2]);
      line.setAttribute("y2", -e[3]);
      const label = document.createElementNS(NS, "text");
      label.setAttribute("class", "candidate-label cand-" + l);
      label.setAttribute("x", e[2] + 1.5);
      label.setAttribute("y", -e[3] - 1.5);
      label.textContent = l.toUpperCase();
      lines.append(line, label);
    });
  }

  function chosen() {
    const r = form.querySelector("input[name=drawing]:checked");
    return r ? r.value.toLowerCase() : "a";
  }
  function choose(letter) {
    const r = form.querySelector("input[name=drawing][value=" + letter.toUpperCase() + "]");
    if (r) {
      r.checked = true;
    }
  }

  let start = null;
  svg.addEventListener("pointerdown", function (event) {
    if (event.button !== 0) {
      return;
    }
    start = mmAt(event);
    svg.setPointerCapture(event.pointerId);
    drag.setAttribute("x1", start[0]);
    drag.setAttribute("y1", -start[1]);
    drag.setAttribute("x2", start[0]);
    drag.setAttribute("y2", -start[1]);
    drag.setAttribute("visibility", "visible");
    event.preventDefault();
  });
  svg.addEventListener("pointermove", function (event) {
    if (!start) {
      return;
    }
    const p = mmAt(event);
    drag.setAttribute("x2", p[0]);
    drag.setAttribute("y2", -p[1]);
  });
  function finish(event) {
    if (!start) {
      return;
    }
    const end = mmAt(event);
    const from = start;
    start = null;
    drag.setAttribute("visibility", "hidden");
    if (Math.hypot(end[0] - from[0], end[1] - from[1]) < 2) {
      return; // a click, not a line
    }
    const l = chosen();
    field(l, "from_x").value = half(from[0]);
    field(l, "from_y").value = half(from[1]);
    field(l, "to_x").value = half(end[0]);
    field(l, "to_y").value = half(end[1]);
    if (number(field(l, "depth")) === null) {
      field(l, "depth").value = form.dataset.depth;
    }
    const next = letters[letters.indexOf(l) + 1];
    if (next) {
      choose(next);
    }
    redraw();
  }
  svg.addEventListener("pointerup", finish);
  svg.addEventListener("pointercancel", function () {
    start = null;
    drag.setAttribute("visibility", "hidden");
  });
  form.addEventListener("input", redraw);
  form.addEventListener("submit", function () {
    const button = document.getElementById("compare");
    button.disabled = true;
    button.textContent = "Cutting the incisions in the simulation…";
  });
  redraw();
})();
