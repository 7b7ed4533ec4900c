// The render page: a frame player, the current frame's stats, and per-frame charts (SVG
// drawn here from the embedded records) with the current frame marked.
// The player sets data-frames-shown on <html> (distinct frames whose image loaded), so a
// headless browser test can see that it advances. `#play` in the URL starts playing.
"use strict";
(() => {
  const data = pageData("render-data");
  const frames = data.frames;
  const image = document.getElementById("frame-image");
  const slider = document.getElementById("slider");
  const label = document.getElementById("frame-label");
  const caption = document.getElementById("frame-caption");
  const playButton = document.getElementById("play");
  const fpsInput = document.getElementById("fps");
  const lodToggle = document.getElementById("lod-toggle");
  const statsList = document.getElementById("frame-stats");
  const shown = new Set();
  let index = 0;
  let playing = false;
  let timer = null;
  const markers = [];

  slider.max = String(frames.length - 1);
  fpsInput.value = String(data.fps);
  if (!frames.some((f) => f.lod)) document.getElementById("lod-toggle-label").style.display = "none";

  image.addEventListener("load", () => {
    shown.add(image.dataset.frame);
    document.documentElement.dataset.framesShown = String(shown.size);
    if (playing) schedule();
  });
  image.addEventListener("error", () => { if (playing) schedule(); });

  function show(i) {
    index = (i + frames.length) % frames.length;
    const f = frames[index];
    const src = lodToggle.checked && f.lod ? f.lod : f.image;
    slider.value = String(index);
    label.textContent = "frame " + f.frame + " (" + (index + 1) + "/" + frames.length + ")";
    if (src) {
      image.dataset.frame = String(f.frame);
      image.src = src;
      caption.textContent = src;
    } else {
      image.removeAttribute("src");
      caption.textContent = "no image file for frame " + f.frame;
      if (playing) schedule();
    }
    showStats(f.stats);
    markers.forEach((m) => m(index));
  }

  function showStats(stats) {
    statsList.textContent = "";
    for (const [key, value] of Object.entries(stats)) {
      const dt = document.createElement("dt");
      const dd = document.createElement("dd");
      dt.textContent = key;
      dd.textContent = Array.isArray(value) ? value.join(" ") : formatNumber(value);
      statsList.append(dt, dd);
    }
  }

  // The next frame after 1/fps, once the current one has loaded (a slow disk slows the
  // playback instead of skipping frames).
  function schedule() {
    clearTimeout(timer);
    const fps = Math.max(1, Number(fpsInput.value) || data.fps);
    timer = setTimeout(() => { if (playing) show(index + 1); }, 1000 / fps);
  }

  function setPlaying(on) {
    playing = on && frames.length > 1;
    playButton.textContent = playing ? "pause" : "play";
    if (playing) schedule(); else clearTimeout(timer);
  }

  playButton.addEventListener("click", () => setPlaying(!playing));
  slider.addEventListener("input", () => show(Number(slider.value)));
  lodToggle.addEventListener("change", () => show(index));
  document.addEventListener("keydown", (event) => {
    if (event.target.tagName === "INPUT" && event.target.type === "number") return;
    if (event.key === "ArrowRight") { setPlaying(false); show(index + 1); event.preventDefault(); }
    else if (event.key === "ArrowLeft") { setPlaying(false); show(index - 1); event.preventDefault(); }
    else if (event.key === " ") { setPlaying(!playing); event.preventDefault(); }
  });

  // One chart: a line per series over the frames, log scale for times, a vertical marker
  // at the current frame; clicking jumps to the nearest frame.
  const SVG = "http://www.w3.org/2000/svg";
  const COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"];
  function chart(title, keys, logScale) {
    const present = keys.filter((k) => frames.some((f) => typeof f.stats[k] === "number"));
    if (present.length === 0) return;
    const [W, H, left, right, top, bottom] = [760, 220, 60, 130, 22, 28];
    const svg = document.createElementNS(SVG, "svg");
    svg.setAttribute("class", "chart");
    svg.setAttribute("width", W);
    svg.setAttribute("height", H);
    const add = (tag, attrs, text) => {
      const el = document.createElementNS(SVG, tag);
      for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, v);
      if (text !== undefined) el.textContent = text;
      svg.appendChild(el);
      return el;
    };
    const values = present.flatMap((k) => frames.map((f) => f.stats[k])).filter((v) => typeof v === "number" && (!logScale || v > 0));
    let lo = logScale ? Math.log10(Math.min(...values, 1)) : 0;
    let hi = logScale ? Math.log10(Math.max(...values, 1)) : Math.max(...values, 1);
    if (logScale) { lo = Math.floor(lo); hi = Math.ceil(hi); if (hi === lo) hi = lo + 1; }
    const x = (i) => left + (frames.length > 1 ? i / (frames.length - 1) : 0.5) * (W - left - right);
    const y = (v) => {
      const t = logScale ? (Math.log10(v) - lo) / (hi - lo) : v / hi;
      return H - bottom - t * (H - top - bottom);
    };
    add("text", { x: left, y: 14 }, title);
    add("line", { x1: left, y1: H - bottom, x2: W - right, y2: H - bottom, stroke: "#999" });
    add("line", { x1: left, y1: top, x2: left, y2: H - bottom, stroke: "#999" });
    const ticks = logScale ? Array.from({ length: hi - lo + 1 }, (_, k) => Math.pow(10, lo + k)) : [0, hi / 2, hi];
    for (const t of ticks) {
      const tick = logScale && t < 1 ? t.toExponential(0) : formatNumber(t);
      add("text", { x: left - 4, y: y(t) + 4, "text-anchor": "end" }, tick);
    }
    add("text", { x: left, y: H - 8 }, "frame " + frames[0].frame);
    add("text", { x: W - right, y: H - 8, "text-anchor": "end" }, "frame " + frames[frames.length - 1].frame);
    present.forEach((key, k) => {
      const points = frames.map((f, i) => [i, f.stats[key]]).filter(([, v]) => typeof v === "number" && (!logScale || v > 0));
      if (points.length === 0) return;
      const color = COLORS[k % COLORS.length];
      add("polyline", { fill: "none", stroke: color, "stroke-width": 1.5, points: points.map(([i, v]) => x(i) + "," + y(v)).join(" ") });
      add("text", { x: W - right + 8, y: top + 14 * k + 8, fill: color }, key);
    });
    const marker = add("line", { y1: top, y2: H - bottom, stroke: "#000", "stroke-dasharray": "3,2" });
    markers.push((i) => { marker.setAttribute("x1", x(i)); marker.setAttribute("x2", x(i)); });
    svg.addEventListener("click", (event) => {
      const box = svg.getBoundingClientRect();
      const t = (event.clientX - box.left - left) / (W - left - right);
      setPlaying(false);
      show(Math.round(Math.min(1, Math.max(0, t)) * (frames.length - 1)));
    });
    const holder = document.createElement("div");
    holder.appendChild(svg);
    document.getElementById("charts").appendChild(holder);
  }
  chart("phase times (ms)", ["animate_ms", "dirty_ms", "refit_ms", "build_ms", "lod_update_ms", "render_ms", "total_ms"], true);
  chart("triangles per frame", ["moved_triangles", "deformed_triangles", "lod_recomputed", "lod_shifted"], false);

  show(0);
  if (location.hash === "#play") setPlaying(true);
  auditImages();
})();
