// The diff page: frames worst first; the selected frame's reference and test with a swipe
// divider, a toggle view cycling reference -> test -> heat map (button or `t`), and the
// heat map. Passing frames have no images (mipray diff writes them for failing frames).
"use strict";
(() => {
  const frames = pageData("diff-data").frames;
  const swipe = makeSwipe(document.getElementById("swipe"), "test", "reference");
  const flip = document.getElementById("flip");
  const heat = document.getElementById("heat");
  const views = [["ref", "reference"], ["test", "test"], ["diff", "heat map"]];
  let current = frames.find((f) => f.ref && f.test) || frames[0];
  let view = 0;

  function showToggle() {
    const [key, name] = views[view];
    if (current && current[key]) flip.src = current[key]; else flip.removeAttribute("src");
    document.getElementById("flip-caption").textContent = "toggle view: " + name;
    document.getElementById("toggle-state").textContent = "showing " + name;
    document.documentElement.dataset.toggleView = name;
  }

  function select(frame) {
    current = frame;
    if (!frame) return;
    document.getElementById("frame-title").textContent =
      "frame " + frame.frame + (frame.passed ? " (pass)" : frame.problem ? " (not compared)" : " (FAIL)");
    const hasImages = frame.ref && frame.test;
    document.getElementById("frame-images").style.display = hasImages ? "" : "none";
    document.getElementById("no-images").textContent = hasImages ? "" : frame.problem ?
      "Frame " + frame.frame + " was not compared: " + frame.problem :
      "Frame " + frame.frame + " is within the threshold; mipray diff writes images only for failing frames.";
    if (hasImages) {
      swipe.set(frame.test, frame.ref, "test", "reference");
      if (frame.diff) heat.src = frame.diff; else heat.removeAttribute("src");
    }
    showToggle();
    for (const row of document.querySelectorAll("#frames tr[data-key]")) {
      row.classList.toggle("selected", row.dataset.key === String(frame.frame));
    }
  }

  function toggle() { view = (view + 1) % views.length; showToggle(); }
  document.getElementById("toggle").addEventListener("click", toggle);
  document.addEventListener("keydown", (event) => { if (event.key === "t") toggle(); });
  for (const row of document.querySelectorAll("#frames tr[data-key]")) {
    const frame = frames.find((f) => String(f.frame) === row.dataset.key);
    if (!frame.passed) row.classList.add("fail");
    row.classList.add("clickable");
    row.addEventListener("click", () => select(frame));
  }
  select(current);
  auditImages();
})();
