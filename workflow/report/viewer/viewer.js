/* mcbench image viewer: vanilla JavaScript, no framework, no network.
 *
 * Reads the manifest window.MCBENCH_VIEWER set by data.js (a <script>, because file:// pages
 * may not fetch), written by mcbench.viewer.build_manifest:
 *   {scenes, spp, entries, labels, metrics, metric_labels: {metric: label},
 *    lower_is_better: {metric: bool}, maps: [metric with an error map, ...], exposures,
 *    scales: {<metric of maps>|weights: {legend, ticks, description, ...}},
 *    cases: {scene: {spp: {width, height, images: {entry: {ev: file}},
 *    errors: {entry: {<metric>: file}}, weights: {entry: [{input, label, file}]},
 *    numbers: {entry: {metric: value}}}}}}
 *
 * DOM contract (tests rely on it): #scene, #spp, #image-a, #image-b (option values are entry
 * names), #mode (flip | slide | side), #exposure (range, value in EV), #flip (button);
 * #view-a and #view-b show the current tone-mapped images of A and B; #numbers holds the
 * case's metric values; #maps the error and weight maps.
 *
 * Zoom and pan are one shared state (zoom factor, centre in relative image coordinates), so
 * every viewport - A, B, the maps and the crops - shows the same place, pixelated.
 */
(function () {
  "use strict";

  var data = window.MCBENCH_VIEWER;
  var ZOOMS = [1, 2, 4, 8, 16];

  function byId(id) { return document.getElementById(id); }

  function showMessage(text) {
    var box = byId("message");
    box.textContent = text;
    box.hidden = !text;
  }

  if (!data || !data.cases || !data.entries || !data.entries.length) {
    showMessage("No viewer data: data.js is missing or empty (rebuild the viewer with Snakemake).");
    return;
  }

  var controls = {
    scene: byId("scene"), spp: byId("spp"), a: byId("image-a"), b: byId("image-b"),
    mode: byId("mode"), flip: byId("flip"), exposure: byId("exposure"),
    exposureValue: byId("exposure-value"), zoom: byId("zoom"), reset: byId("reset-view")
  };
  var stage = byId("stage");
  var paneA = byId("pane-a"), paneB = byId("pane-b");
  var viewportA = byId("viewport-a"), viewportB = byId("viewport-b");
  var viewA = byId("view-a"), viewB = byId("view-b");
  var divider = byId("divider");

  var exposures = data.exposures && data.exposures.length ? data.exposures : [0];
  var state = {
    scene: data.scenes[0], spp: String(data.spp[0]),
    a: data.entries.indexOf("noisy") >= 0 ? "noisy" : data.entries[0],
    b: data.entries.length > 2 ? data.entries[2] : data.entries[data.entries.length - 1],
    mode: "flip", shown: "a", ev: exposures.indexOf(0) >= 0 ? 0 : exposures[0],
    zoom: 1, cx: 0.5, cy: 0.5, slide: 0.5
  };

  // ---------------------------------------------------------------------------------------
  // Helpers

  function label(entry) { return (data.labels && data.labels[entry]) || entry; }
  function metricLabel(metric) { return (data.metric_labels && data.metric_labels[metric]) || metric; }
  function lowerIsBetter(metric) { return !data.lower_is_better || data.lower_is_better[metric] !== false; }
  function better(value, other, metric) { return lowerIsBetter(metric) ? value < other : value > other; }

  function currentCase() {
    var perSpp = data.cases[state.scene];
    return perSpp ? perSpp[state.spp] : undefined;
  }

  function cssPixels(name, fallback) {
    var value = parseFloat(getComputedStyle(document.documentElement).getPropertyValue(name));
    return isFinite(value) && value > 0 ? value : fallback;
  }

  function fillSelect(select, values, text) {
    var previous = select.value;
    while (select.firstChild) { select.removeChild(select.firstChild); }
    values.forEach(function (value) {
      var option = document.createElement("option");
      option.value = String(value);
      option.textContent = text ? text(value) : String(value);
      select.appendChild(option);
    });
    return previous;
  }

  function formatValue(value) {
    if (typeof value !== "number" || !isFinite(value)) { return "\u2014"; }
    if (value === 0) { return "0"; }
    var magnitude = Math.abs(value);
    return magnitude >= 1e-3 && magnitude < 1e4 ? value.toPrecision(4) : value.toExponential(3);
  }

  function formatTick(value, log) {
    if (log) { return "1e" + Math.round(Math.log10(value)); }
    return String(Math.round(value * 100) / 100);
  }

  function imageFile(entry) {
    var record = currentCase();
    var files = record && record.images[entry];
    return files ? files[String(state.ev)] : undefined;
  }

  // ---------------------------------------------------------------------------------------
  // Zoomable viewports: one shared zoom and centre

  var zoomables = [];   // {viewport, img, side} of every zoomable image on the page

  function fitScale(side, width, height) {
    var scale = side / Math.max(width, height);
    return scale >= 1 ? Math.floor(scale) : scale;
  }

  function sizeViewport(item) {
    var record = currentCase();
    var scale = fitScale(item.side, record.width, record.height);
    item.width = Math.round(record.width * scale);
    item.height = Math.round(record.height * scale);
    item.viewport.style.width = item.width + "px";
    item.viewport.style.height = item.height + "px";
  }

  function place(item) {
    var shownWidth = item.width * state.zoom, shownHeight = item.height * state.zoom;
    var x = Math.min(0, Math.max(item.width - shownWidth, item.width / 2 - state.cx * shownWidth));
    var y = Math.min(0, Math.max(item.height - shownHeight, item.height / 2 - state.cy * shownHeight));
    item.img.style.width = shownWidth + "px";
    item.img.style.height = shownHeight + "px";
    item.img.style.transform = "translate(" + x + "px, " + y + "px)";
  }

  function placeAll() {
    zoomables.forEach(place);
    placeDivider();
  }

  function clampCentre() {
    var half = 0.5 / state.zoom;
    state.cx = Math.min(1 - half, Math.max(half, state.cx));
    state.cy = Math.min(1 - half, Math.max(half, state.cy));
  }

  function setZoom(zoom, focusX, focusY) {
    zoom = Math.min(ZOOMS[ZOOMS.length - 1], Math.max(ZOOMS[0], zoom));
    if (typeof focusX === "number") {
      // keep the image point under the pointer where it is
      state.cx = focusX + (state.cx - focusX) * state.zoom / zoom;
      state.cy = focusY + (state.cy - focusY) * state.zoom / zoom;
    }
    state.zoom = zoom;
    clampCentre();
    controls.zoom.value = String(zoom);
    placeAll();
  }

  function stepZoom(direction, focusX, focusY) {
    var index = ZOOMS.indexOf(state.zoom);
    var next = ZOOMS[Math.min(ZOOMS.length - 1, Math.max(0, (index < 0 ? 0 : index) + direction))];
    setZoom(next, focusX, focusY);
  }

  function pointInImage(item, event) {
    // relative image coordinates (0..1) of a pointer event over item's viewport
    var rect = item.viewport.getBoundingClientRect();
    var shownWidth = item.width * state.zoom, shownHeight = item.height * state.zoom;
    var x = Math.min(0, Math.max(item.width - shownWidth, item.width / 2 - state.cx * shownWidth));
    var y = Math.min(0, Math.max(item.height - shownHeight, item.height / 2 - state.cy * shownHeight));
    return {x: (event.clientX - rect.left - x) / shownWidth, y: (event.clientY - rect.top - y) / shownHeight};
  }

  function attachPanning(item) {
    var drag = null;
    item.viewport.addEventListener("pointerdown", function (event) {
      if (event.button !== 0) { return; }
      drag = {x: event.clientX, y: event.clientY, cx: state.cx, cy: state.cy, moved: false};
      item.viewport.setPointerCapture(event.pointerId);
      item.viewport.classList.add("dragging");
    });
    item.viewport.addEventListener("pointermove", function (event) {
      if (!drag) { return; }
      var dx = event.clientX - drag.x, dy = event.clientY - drag.y;
      if (Math.abs(dx) + Math.abs(dy) > 3) { drag.moved = true; }
      state.cx = drag.cx - dx / (item.width * state.zoom);
      state.cy = drag.cy - dy / (item.height * state.zoom);
      clampCentre();
      placeAll();
    });
    function end(event) {
      if (!drag) { return; }
      item.moved = drag.moved;
      drag = null;
      item.viewport.classList.remove("dragging");
      if (item.viewport.hasPointerCapture(event.pointerId)) {
        item.viewport.releasePointerCapture(event.pointerId);
      }
    }
    item.viewport.addEventListener("pointerup", end);
    item.viewport.addEventListener("pointercancel", end);
    item.viewport.addEventListener("dblclick", function (event) {
      var point = pointInImage(item, event);
      state.cx = point.x;
      state.cy = point.y;
      stepZoom(+1);
    });
    item.viewport.addEventListener("wheel", function (event) {
      event.preventDefault();
      var point = pointInImage(item, event);
      stepZoom(event.deltaY < 0 ? +1 : -1, point.x, point.y);
    }, {passive: false});
  }

  function registerZoomable(viewport, img, side) {
    var item = {viewport: viewport, img: img, side: side, width: 0, height: 0, moved: false};
    img.draggable = false;
    img.addEventListener("error", function () {
      showMessage("Cannot load " + img.getAttribute("src") + " (is the viewer folder complete?)");
    });
    attachPanning(item);
    zoomables.push(item);
    sizeViewport(item);
    place(item);
    return item;
  }

  function makeZoomable(side, src, alt) {
    var viewport = document.createElement("div");
    viewport.className = "viewport";
    var img = document.createElement("img");
    img.className = "zoomable";
    img.alt = alt;
    img.src = src;
    viewport.appendChild(img);
    return registerZoomable(viewport, img, side);
  }

  // ---------------------------------------------------------------------------------------
  // A and B

  var mainItems = [];

  function caption(element, which, entry) {
    while (element.firstChild) { element.removeChild(element.firstChild); }
    element.appendChild(document.createTextNode(which + ": "));
    var name = document.createElement("b");
    name.textContent = label(entry);
    element.appendChild(name);
    element.appendChild(document.createTextNode(" \u00b7 " + state.scene + ", " + state.spp + " spp, " +
      (state.ev > 0 ? "+" : "") + state.ev + " EV"));
  }

  function updateMain() {
    viewA.src = imageFile(state.a);
    viewB.src = imageFile(state.b);
    viewA.alt = "A: " + label(state.a);
    viewB.alt = "B: " + label(state.b);
    caption(byId("caption-a"), "A", state.a);
    caption(byId("caption-b"), "B", state.b);
    stage.className = "mode-" + state.mode;
    var flipping = state.mode === "flip";
    paneA.classList.toggle("hidden", flipping && state.shown !== "a");
    paneB.classList.toggle("hidden", flipping && state.shown !== "b");
    controls.flip.textContent = "Showing " + state.shown.toUpperCase() + " (F)";
    controls.flip.setAttribute("aria-pressed", state.shown === "b" ? "true" : "false");
    mainItems.forEach(sizeViewport);
    placeAll();
  }

  function placeDivider() {
    var item = mainItems[1];
    if (!item) { return; }
    if (state.mode === "slide") {
      var x = Math.round(state.slide * item.width);
      viewportB.style.clipPath = "inset(0 0 0 " + x + "px)";
      divider.style.left = x + "px";
      divider.style.height = item.height + "px";
    } else {
      viewportB.style.clipPath = "";
    }
  }

  function attachDivider() {
    var dragging = false;
    function move(event) {
      var rect = viewportA.getBoundingClientRect();
      state.slide = Math.min(1, Math.max(0, (event.clientX - rect.left) / rect.width));
      placeDivider();
    }
    divider.addEventListener("pointerdown", function (event) {
      dragging = true;
      divider.setPointerCapture(event.pointerId);
      event.stopPropagation();
      move(event);
    });
    divider.addEventListener("pointermove", function (event) { if (dragging) { move(event); } });
    function end(event) {
      dragging = false;
      if (divider.hasPointerCapture(event.pointerId)) { divider.releasePointerCapture(event.pointerId); }
    }
    divider.addEventListener("pointerup", end);
    divider.addEventListener("pointercancel", end);
  }

  function toggleFlip() {
    state.shown = state.shown === "a" ? "b" : "a";
    if (state.mode !== "flip") {
      state.mode = "flip";
      controls.mode.value = "flip";
    }
    updateMain();
  }

  // ---------------------------------------------------------------------------------------
  // Numbers beside the images

  function rankOf(numbers, entry, metric) {
    var value = numbers[entry] && numbers[entry][metric];
    if (typeof value !== "number") { return null; }
    var rank = 1, count = 0;
    Object.keys(numbers).forEach(function (other) {
      var v = numbers[other][metric];
      if (typeof v !== "number") { return; }
      count += 1;
      if (better(v, value, metric)) { rank += 1; }
    });
    return {rank: rank, count: count};
  }

  function updateNumbers() {
    var box = byId("numbers");
    while (box.firstChild) { box.removeChild(box.firstChild); }
    var numbers = currentCase().numbers || {};
    var table = document.createElement("table");
    var head = table.insertRow();
    ["metric", "A: " + label(state.a), "B: " + label(state.b)].forEach(function (text) {
      var th = document.createElement("th");
      th.textContent = text;
      head.appendChild(th);
    });
    data.metrics.forEach(function (metric) {
      var row = table.insertRow();
      row.insertCell().textContent = metric;
      var values = [state.a, state.b].map(function (entry) {
        return numbers[entry] ? numbers[entry][metric] : undefined;
      });
      [state.a, state.b].forEach(function (entry, i) {
        var cell = row.insertCell();
        cell.className = "value-" + (i === 0 ? "a" : "b");
        cell.dataset.metric = metric;
        if (entry === "reference") {
          cell.textContent = "reference";
          return;
        }
        cell.textContent = formatValue(values[i]);
        var rank = rankOf(numbers, entry, metric);
        if (rank) {
          var span = document.createElement("span");
          span.className = "rank";
          span.textContent = " #" + rank.rank + "/" + rank.count;
          cell.appendChild(span);
        }
        var other = values[1 - i];
        if (typeof values[i] === "number" && typeof other === "number" && better(values[i], other, metric)) {
          cell.classList.add("better");
        }
      });
    });
    box.appendChild(table);
    var note = document.createElement("p");
    note.className = "note";
    note.textContent = "Errors against the reference (results/metrics.csv); the better value is marked. " +
      "#k/n: rank among the n images of this case, the noisy input included.";
    box.appendChild(note);
  }

  // ---------------------------------------------------------------------------------------
  // Error and weight maps, crops

  function removeZoomables(container) {
    zoomables = zoomables.filter(function (item) { return !container.contains(item.viewport); });
    while (container.firstChild) { container.removeChild(container.firstChild); }
  }

  function legend(scaleName) {
    var scale = data.scales[scaleName];
    var box = document.createElement("div");
    box.className = "legend";
    var bar = document.createElement("img");
    bar.src = scale.legend;
    bar.alt = scale.description;
    bar.title = scale.description;
    box.appendChild(bar);
    scale.ticks.forEach(function (tick, i) {
      var span = document.createElement("span");
      span.textContent = formatTick(tick.value, scale.log);
      span.style.left = (100 * tick.position) + "%";
      if (i === 0) { span.className = "first"; }
      if (i === scale.ticks.length - 1) { span.className = "last"; }
      box.appendChild(span);
    });
    return box;
  }

  function mapFigure(src, title, scaleName, side) {
    var figure = document.createElement("figure");
    figure.className = "map map-" + scaleName;
    var item = makeZoomable(side, src, title);
    figure.style.width = item.width + "px";
    figure.appendChild(item.viewport);
    var text = document.createElement("figcaption");
    text.textContent = title;
    figure.appendChild(text);
    figure.appendChild(legend(scaleName));
    return figure;
  }

  function updateMaps() {
    var box = byId("maps");
    removeZoomables(box);
    var record = currentCase();
    var side = cssPixels("--map", 256);
    [["A", state.a], ["B", state.b]].forEach(function (pair) {
      var entry = pair[1];
      var row = document.createElement("div");
      row.className = "map-row";
      row.dataset.entry = entry;
      var title = document.createElement("h3");
      title.textContent = pair[0] + ": " + label(entry);
      row.appendChild(title);
      var errors = record.errors[entry];
      if (!errors) {
        var none = document.createElement("p");
        none.textContent = "The reference: no error maps.";
        row.appendChild(none);
      } else {
        (data.maps || Object.keys(errors)).forEach(function (metric) {
          if (errors[metric]) { row.appendChild(mapFigure(errors[metric], metricLabel(metric) + " per pixel", metric, side)); }
        });
      }
      (record.weights[entry] || []).forEach(function (weight) {
        row.appendChild(mapFigure(weight.file, "weight of " + weight.label, "weights", side));
      });
      box.appendChild(row);
    });
  }

  function updateCrops() {
    var box = byId("crops");
    removeZoomables(box);
    var record = currentCase();
    var side = cssPixels("--crop", 128);
    var metric = data.metrics[0];
    data.entries.forEach(function (entry) {
      var figure = document.createElement("figure");
      figure.className = "crop";
      figure.dataset.entry = entry;
      if (entry === state.a) { figure.classList.add("is-a"); }
      if (entry === state.b) { figure.classList.add("is-b"); }
      var item = makeZoomable(side, imageFile(entry), label(entry));
      figure.style.width = item.width + "px";
      figure.appendChild(item.viewport);
      var text = document.createElement("figcaption");
      var value = record.numbers[entry] ? record.numbers[entry][metric] : undefined;
      text.textContent = label(entry) + (entry === "reference" ? "" : " \u00b7 " + metric + " " + formatValue(value));
      figure.appendChild(text);
      figure.addEventListener("click", function (event) {
        if (item.moved) { item.moved = false; return; }
        if (event.shiftKey) { setEntry("a", entry); } else { setEntry("b", entry); }
      });
      box.appendChild(figure);
    });
  }

  // ---------------------------------------------------------------------------------------
  // Controls

  function setEntry(which, entry) {
    state[which] = entry;
    controls[which].value = entry;
    refreshImages();
  }

  function refreshImages() {
    updateMain();
    updateNumbers();
    updateMaps();
    updateCrops();
  }

  function fillSpp() {
    var available = data.spp.filter(function (spp) { return data.cases[state.scene] && data.cases[state.scene][String(spp)]; });
    fillSelect(controls.spp, available);
    if (available.map(String).indexOf(state.spp) < 0) { state.spp = String(available[0]); }
    controls.spp.value = state.spp;
  }

  function setExposure(ev) {
    var nearest = exposures[0];
    exposures.forEach(function (value) { if (Math.abs(value - ev) < Math.abs(nearest - ev)) { nearest = value; } });
    state.ev = nearest;
    controls.exposure.value = String(nearest);
    controls.exposureValue.textContent = (nearest > 0 ? "+" : "") + nearest + " EV";
    updateMain();
    updateCrops();
  }

  function stepExposure(direction) {
    var index = exposures.indexOf(state.ev) + direction;
    if (index >= 0 && index < exposures.length) { setExposure(exposures[index]); }
  }

  function init() {
    fillSelect(controls.scene, data.scenes);
    controls.scene.value = state.scene;
    fillSpp();
    fillSelect(controls.a, data.entries, label);
    fillSelect(controls.b, data.entries, label);
    controls.a.value = state.a;
    controls.b.value = state.b;
    controls.mode.value = state.mode;
    controls.exposure.min = String(exposures[0]);
    controls.exposure.max = String(exposures[exposures.length - 1]);
    controls.exposure.step = String(exposures.length > 1 ? exposures[1] - exposures[0] : 1);
    controls.zoom.value = String(state.zoom);

    var stageSide = cssPixels("--stage", 512);
    mainItems = [registerZoomable(viewportA, viewA, stageSide), registerZoomable(viewportB, viewB, stageSide)];
    attachDivider();

    controls.scene.addEventListener("change", function () {
      state.scene = controls.scene.value;
      fillSpp();
      refreshImages();
    });
    controls.spp.addEventListener("change", function () {
      state.spp = controls.spp.value;
      refreshImages();
    });
    controls.a.addEventListener("change", function () { setEntry("a", controls.a.value); });
    controls.b.addEventListener("change", function () { setEntry("b", controls.b.value); });
    controls.mode.addEventListener("change", function () {
      state.mode = controls.mode.value;
      updateMain();
    });
    controls.flip.addEventListener("click", toggleFlip);
    controls.exposure.addEventListener("input", function () { setExposure(Number(controls.exposure.value)); });
    controls.exposure.addEventListener("change", function () { setExposure(Number(controls.exposure.value)); });
    controls.zoom.addEventListener("change", function () { setZoom(Number(controls.zoom.value)); });
    controls.reset.addEventListener("click", function () {
      state.cx = 0.5;
      state.cy = 0.5;
      setZoom(1);
    });
    document.addEventListener("keydown", function (event) {
      if (event.ctrlKey || event.metaKey || event.altKey) { return; }
      var tag = event.target && event.target.tagName;
      var inControl = tag === "SELECT" || tag === "INPUT" || tag === "BUTTON" || tag === "TEXTAREA";
      if (event.key === "f" || event.key === "F" || (event.key === " " && !inControl)) {
        event.preventDefault();
        toggleFlip();
      } else if (!inControl && event.key === "ArrowLeft") {
        event.preventDefault();
        stepExposure(-1);
      } else if (!inControl && event.key === "ArrowRight") {
        event.preventDefault();
        stepExposure(+1);
      } else if (event.key === "+" || event.key === "=") {
        stepZoom(+1);
      } else if (event.key === "-") {
        stepZoom(-1);
      }
    });
    setExposure(state.ev);
    refreshImages();
  }

  init();
}());
