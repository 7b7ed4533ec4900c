// Shared by every mipray page: records script errors and failed image loads on <html>
// (data-errors, data-images) so a headless browser's DOM dump shows them, and the swipe
// widget (two stacked images, the top one clipped at a divider that follows the pointer).
"use strict";
const pageErrors = [];
function recordError(message) {
  pageErrors.push(String(message));
  document.documentElement.dataset.errors = JSON.stringify(pageErrors);
}
window.addEventListener("error", (event) => {
  const target = event.target;
  if (target && target !== window && (target.src || target.data)) {
    recordError("cannot load " + (target.src || target.data));
  } else {
    recordError(event.message + " at " + event.filename + ":" + event.lineno);
  }
}, true);
window.addEventListener("unhandledrejection", (event) => recordError("unhandled rejection: " + event.reason));

// The page's data, embedded as JSON in <script type="application/json" id="...">.
function pageData(id) {
  return JSON.parse(document.getElementById(id).textContent);
}

// Counts the page's images that loaded (naturalWidth > 0) once all have settled, into
// data-images="loaded/total" and data-broken-images.
function auditImages() {
  const images = Array.from(document.images).filter((img) => img.getAttribute("src"));
  const settled = images.map((img) => img.complete ? Promise.resolve() :
    new Promise((done) => { img.addEventListener("load", done); img.addEventListener("error", done); }));
  return Promise.all(settled).then(() => {
    const broken = images.filter((img) => !(img.naturalWidth > 0)).map((img) => img.getAttribute("src"));
    const root = document.documentElement.dataset;
    root.images = (images.length - broken.length) + "/" + images.length;
    root.brokenImages = JSON.stringify(broken);
  });
}

// Turns <div class="swipe"> with two <img> (bottom first, then top) into a swipe view:
// the top image shows left of the divider. Returns a function that sets both sources.
function makeSwipe(container, bottomLabel, topLabel) {
  const [bottom, top] = container.querySelectorAll("img");
  const clip = document.createElement("div");
  clip.className = "top";
  container.insertBefore(clip, top);
  clip.appendChild(top);
  const divider = document.createElement("div");
  divider.className = "divider";
  container.appendChild(divider);
  const left = document.createElement("span");
  left.className = "label";
  left.style.left = "2px";
  const right = left.cloneNode();
  right.style.left = "";
  right.style.right = "2px";
  container.append(left, right);
  let share = 0.5;
  const place = () => {
    const width = bottom.clientWidth;
    clip.style.width = (share * width) + "px";
    divider.style.left = (share * width - 1) + "px";
  };
  container.addEventListener("pointermove", (event) => {
    const box = container.getBoundingClientRect();
    share = Math.min(1, Math.max(0, (event.clientX - box.left) / box.width));
    place();
  });
  bottom.addEventListener("load", place);
  window.addEventListener("resize", place);
  const labels = (l, r) => { left.textContent = l; right.textContent = r; };
  labels(topLabel, bottomLabel);
  place();
  return { set(bottomSrc, topSrc, bottomName, topName) {
    bottom.src = bottomSrc;
    top.src = topSrc;
    labels(topName || topLabel, bottomName || bottomLabel);
    place();
  } };
}

function formatNumber(value) {
  if (typeof value !== "number") return String(value);
  if (Number.isInteger(value)) return value.toLocaleString("en-US");
  return Math.abs(value) >= 100 ? value.toFixed(1) : value.toPrecision(4);
}
