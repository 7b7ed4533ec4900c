// The compare page: selecting a method (table row, or a point or label of the inlined
// pareto.svg, matched by the label text and the point's colour) and a frame shows the
// reference against the method's frame (swipe), the FLIP heat map and the LOD view.
// Sets data-selected-method on <html> for tests.
"use strict";
(() => {
  const data = pageData("compare-data");
  const methods = data.methods;
  let method = methods.find((m) => m !== "none") || methods[0];
  let frame = data.frames[0];
  const select = document.getElementById("frame-select");
  const swipeBox = document.getElementById("swipe");
  const swipe = swipeBox ? makeSwipe(swipeBox, "method", "reference") : null;

  function selectMethod(name) {
    if (!methods.includes(name)) return;
    method = name;
    document.documentElement.dataset.selectedMethod = name;
    for (const row of document.querySelectorAll("#methods tr[data-key]")) {
      row.classList.toggle("selected", row.dataset.key === name);
    }
    showFrame();
  }

  function showFrame() {
    if (!swipe) return;
    const images = (data.images[method] || {})[frame] || {};
    const reference = data.images.reference[frame];
    document.getElementById("selected-method").textContent = method;
    if (images.image && reference) swipe.set(images.image, reference, method, "reference");
    const heat = document.getElementById("heat");
    if (images.heat) heat.src = images.heat; else heat.removeAttribute("src");
    const lod = document.getElementById("lod");
    const lodFigure = document.getElementById("lod-figure");
    if (images.lod) { lod.src = images.lod; lodFigure.style.display = ""; }
    else { lod.removeAttribute("src"); lodFigure.style.display = "none"; }
    document.getElementById("lod-note").innerHTML = images.lod ? "" :
      "No MIP level image: run <code>mipray compare ... --view lod</code> to see it here.";
    const row = data.perFrame.find((r) => r.method === method && Number(r.frame) === Number(frame));
    document.getElementById("frame-metrics").textContent = row ?
      "PSNR " + row.psnr + " dB, SSIM " + row.ssim + ", FLIP " + row.flip + ", LOD bias " + row.lod_bias + ", LOD RMS " + row.lod_rms : "";
  }

  if (select) {
    for (const f of data.frames) {
      const option = document.createElement("option");
      option.value = option.textContent = String(f);
      select.appendChild(option);
    }
    select.addEventListener("change", () => { frame = Number(select.value); showFrame(); });
  }
  for (const row of document.querySelectorAll("#methods tr[data-key]")) {
    row.classList.add("clickable");
    row.addEventListener("click", () => selectMethod(row.dataset.key));
  }
  // pareto.svg: labels are <text> holding a method name in the method's colour, points are
  // <circle>s of the same colour.
  const colorToMethod = {};
  let clickablePoints = 0;
  for (const text of document.querySelectorAll("#pareto text")) {
    const name = text.textContent.trim();
    if (!methods.includes(name)) continue;
    text.classList.add("method");
    text.addEventListener("click", () => selectMethod(name));
    colorToMethod[(text.getAttribute("fill") || "").toLowerCase()] = name;
  }
  for (const circle of document.querySelectorAll("#pareto circle")) {
    const name = colorToMethod[(circle.getAttribute("fill") || "").toLowerCase()];
    if (!name) continue;
    circle.addEventListener("click", () => selectMethod(name));
    clickablePoints += 1;
  }
  document.documentElement.dataset.clickablePoints = String(clickablePoints);
  selectMethod(method);
  auditImages();
})();
