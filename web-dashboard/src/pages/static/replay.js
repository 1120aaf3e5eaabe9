// cutlab's replay page: opens rerun's viewer (the iframe) at a review note's moment, and
// moves it to a note's moment when its time is clicked. Our own code; the viewer's index
// (served by the dashboard) hands its WebHandle to `window._handle`.
(() => {
  "use strict";
  const frame = document.getElementById("replay");
  if (!frame) return;
  const timeline = frame.dataset.timeline;
  const hint = document.getElementById("moment-hint");
  // what the tests read: the moment asked for and the one the viewer was moved to, ns
  const state = { wanted_ns: frame.dataset.atNs ? Number(frame.dataset.atNs) : null, applied_ns: null };
  window.cutlabReplay = state;
  let deadline = 0;

  function viewer() {
    try { return frame.contentWindow && frame.contentWindow._handle; } catch (e) { return null; }
  }
  // moves the viewer's time cursor once the recording has loaded that far and keeps it there
  // until it stays (the viewer starts playing from the beginning as a file finishes loading);
  // true once it stayed for `STEADY` polls
  const STEADY = 8;
  let steady = 0;
  function apply() {
    const h = viewer();
    if (!h || state.wanted_ns === null) return false;
    const id = h.get_active_recording_id();
    if (!id) return false;
    const range = h.get_timeline_time_range(id, timeline);
    if (!range || !(range.max >= state.wanted_ns)) return false;
    if (h.get_time_for_timeline(id, timeline) === state.wanted_ns && h.get_playing(id) === false) {
      steady += 1;
    } else {
      steady = 0;
      h.set_playing(id, false);
      h.set_time_for_timeline(id, timeline, state.wanted_ns);
    }
    if (steady < STEADY) return false;
    state.applied_ns = state.wanted_ns;
    if (hint) hint.dataset.applied = "true";
    return true;
  }
  function poll() {
    if (apply()) return;
    if (performance.now() < deadline) setTimeout(poll, 250);
  }
  function seek(ns) {
    state.wanted_ns = ns;
    state.applied_ns = null;
    steady = 0;
    deadline = performance.now() + 120000; // the viewer and the file may take a while
    poll();
  }
  if (state.wanted_ns !== null) seek(state.wanted_ns);
  for (const a of document.querySelectorAll("a.moment[data-at-ns]")) {
    a.addEventListener("click", (event) => {
      event.preventDefault();
      history.replaceState(null, "", a.href);
      seek(Number(a.dataset.atNs));
      frame.scrollIntoView({ block: "nearest" });
    });
  }
})();
