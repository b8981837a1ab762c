// csboundary review page: pan/zoom over an image pyramid, boundaries (chains of edges between
// junctions and ends) coloured by confidence; accept / delete / cut a boundary, move a vertex,
// draw, delete every doubtful boundary inside a drawn area, mark areas complete (labels for
// fine-tuning); edits exported as GeoJSON in the prediction's CRS, edge by edge. Boundaries held
// back from the review draft (not worth a look, docs/metrics.md) are hidden until asked for.
(function () {
  "use strict";
  const D = window.REVIEW_DATA;
  const canvas = document.getElementById("view");
  const ctx = canvas.getContext("2d");
  const listEl = document.getElementById("edge-list");
  const statusEl = document.getElementById("status");
  const gtBox = document.getElementById("show-gt");
  const heldBox = document.getElementById("show-held");
  const belowInput = document.getElementById("below");
  const tiles = new Map();
  const state = { scale: 1, ox: 0, oy: 0, selected: null, deleted: new Set(), accepted: new Set(), moved: new Map(),
                  added: [], areas: [], drawing: null, drawingArea: false, sweeping: false, cutting: false, drag: null, frames: 0 };
  // a page of an older build has no boundaries: each edge is one
  const B = D.boundaries || D.edges.map((e) => ({ edges: [e.id], score: e.score, draft: true, length_m: null }));
  const boundaryOf = new Array(D.edges.length);
  B.forEach((b, i) => { b.id = i; b.edges.forEach((k) => { boundaryOf[k] = i; }); });
  const shown = (b) => b.draft || heldBox.checked || b.edges.some((k) => state.accepted.has(k));
  const gone = (b) => b.edges.every((k) => state.deleted.has(k));
  const rows = {};

  const pos = (i) => state.moved.get(i) || D.vertices[i];
  function edgeLine(e) {
    const line = e.line.map((p) => p.slice());
    line[0] = pos(e.u).slice();
    line[line.length - 1] = pos(e.v).slice();
    return line;
  }
  const colour = (s) => (s === null ? "#bbb" : `hsl(${Math.round(120 * Math.max(0, Math.min(1, s)))}, 90%, 50%)`);
  const toScreen = (p) => [(p[0] - state.ox) * state.scale, (p[1] - state.oy) * state.scale];
  const toImage = (x, y) => [x / state.scale + state.ox, y / state.scale + state.oy];

  function resize() {
    canvas.width = canvas.clientWidth;
    canvas.height = canvas.clientHeight;
    render();
  }
  function fit() {
    state.scale = Math.min(canvas.clientWidth / D.width, canvas.clientHeight / D.height);
    state.ox = (D.width - canvas.clientWidth / state.scale) / 2;
    state.oy = (D.height - canvas.clientHeight / state.scale) / 2;
  }
  function centreOn(p, minScale) {
    state.scale = Math.max(state.scale, minScale || 0);
    state.ox = p[0] - canvas.width / 2 / state.scale;
    state.oy = p[1] - canvas.height / 2 / state.scale;
  }

  let pending = false;
  function render() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(draw);
  }
  function tile(level, r, c) {
    const key = `${level}/${r}_${c}`;
    let img = tiles.get(key);
    if (!img) {
      img = new Image();
      img.onload = render;
      img.src = `tiles/${key}.jpg`;
      tiles.set(key, img);
    }
    return img;
  }
  function drawTiles() {
    const level = Math.max(0, Math.min(D.levels - 1, Math.floor(Math.log2(1 / state.scale))));
    const f = 2 ** level, span = D.tile * f;
    const [x0, y0] = toImage(0, 0), [x1, y1] = toImage(canvas.width, canvas.height);
    const rMax = Math.ceil(D.height / span) - 1, cMax = Math.ceil(D.width / span) - 1;
    for (let r = Math.max(0, Math.floor(y0 / span)); r <= Math.min(rMax, Math.floor(y1 / span)); r++) {
      for (let c = Math.max(0, Math.floor(x0 / span)); c <= Math.min(cMax, Math.floor(x1 / span)); c++) {
        const img = tile(level, r, c);
        if (img.complete && img.naturalWidth) {
          const [sx, sy] = toScreen([c * span, r * span]);
          ctx.drawImage(img, sx, sy, img.naturalWidth * f * state.scale, img.naturalHeight * f * state.scale);
        }
      }
    }
  }
  function stroke(line, style, width, dash) {
    ctx.beginPath();
    line.forEach((p, k) => { const [x, y] = toScreen(p); if (k) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
    ctx.strokeStyle = style;
    ctx.lineWidth = width;
    ctx.setLineDash(dash || []);
    ctx.stroke();
    ctx.setLineDash([]);
  }
  function draw() {
    pending = false;
    state.frames += 1;
    ctx.fillStyle = "#333";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    drawTiles();
    if (gtBox.checked) D.ground_truth.forEach((line) => stroke(line, "#0ff", 1.5));
    // one path per colour bucket (a few strokes instead of one per edge), edges off screen skipped
    const [vx0, vy0] = toImage(0, 0), [vx1, vy1] = toImage(canvas.width, canvas.height);
    const buckets = new Map();
    for (const e of D.edges) {
      const owner = B[boundaryOf[e.id]];
      if (state.deleted.has(e.id) || owner.id === state.selected || !shown(owner)) continue;
      const b = e.box;
      if (!state.moved.has(e.u) && !state.moved.has(e.v) && (b[2] < vx0 || b[0] > vx1 || b[3] < vy0 || b[1] > vy1)) continue;
      const line = edgeLine(e);
      if (state.accepted.has(e.id)) stroke(line, "#fff", 5);
      const key = owner.score === null ? -1 : Math.round(owner.score * 20) + (owner.draft ? 0 : 100);
      if (!buckets.has(key)) buckets.set(key, []);
      buckets.get(key).push(line);
    }
    for (const [key, lines] of buckets) {  // held-back boundaries (key >= 100) dashed
      ctx.beginPath();
      for (const line of lines) line.forEach((p, k) => { const [x, y] = toScreen(p); if (k) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
      ctx.strokeStyle = colour(key < 0 ? null : (key % 100) / 20);
      ctx.lineWidth = 2;
      ctx.setLineDash(key >= 100 ? [5, 4] : []);
      ctx.stroke();
      ctx.setLineDash([]);
    }
    if (state.selected !== null) {
      const b = B[state.selected];
      for (const k of b.edges) {
        if (state.deleted.has(k)) continue;
        if (state.accepted.has(k)) stroke(edgeLine(D.edges[k]), "#fff", 6);
        stroke(edgeLine(D.edges[k]), colour(b.score), 4);
      }
    }
    for (const ring of state.areas) {
      ctx.beginPath();
      ring.forEach((p, k) => { const [x, y] = toScreen(p); if (k) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
      ctx.closePath();
      ctx.fillStyle = "rgba(255, 220, 0, 0.12)";
      ctx.fill();
      ctx.strokeStyle = "#fd0";
      ctx.lineWidth = 2;
      ctx.stroke();
    }
    state.added.forEach((line) => stroke(line, "#f0f", 3));
    const area = state.drawingArea || state.sweeping;
    if (state.drawing) stroke(area ? [...state.drawing, state.drawing[0] || []].filter((p) => p.length) : state.drawing,
                              state.sweeping ? "#f44" : (area ? "#fd0" : "#f0f"), 2, [6, 4]);
    if (state.selected !== null) {
      for (const i of boundaryVertices(B[state.selected])) {
        const [x, y] = toScreen(pos(i));
        ctx.fillStyle = "#fff";
        ctx.fillRect(x - 4, y - 4, 8, 8);
      }
    }
    const [left, minutes] = remaining();
    const held = B.filter((b) => !b.draft).length;
    statusEl.textContent = `${B.length} boundaries (${D.edges.length} edges${held ? `, ${held} held back from the draft` : ""}), ` +
      `${state.deleted.size} edges deleted, ${state.accepted.size} accepted, ` +
      `${state.moved.size} vertices moved, ${state.added.length} added, ${state.areas.length} areas complete. ` +
      `${left} boundaries left to look at: about ${minutes.toFixed(1)} min, then drawing what is missing`;
  }

  // Boundaries shown and neither accepted nor deleted, and the minutes to look at them: each
  // costs a look (longer for a longer line) and a deletion as often as its confidence says it is
  // false (costs: docs/metrics.md, "Review effort").
  function remaining() {
    const costs = D.review_costs || { look_s: 1.5, look_s_per_20m: 0.5, delete_s: 1.0 };
    let left = 0, seconds = 0;
    for (const b of B) {
      if (!shown(b) || b.edges.every((k) => state.deleted.has(k) || state.accepted.has(k))) continue;
      left += 1;
      seconds += costs.look_s + (costs.look_s_per_20m || 0) * (b.length_m || 0) / 20 + costs.delete_s * (b.score === null ? 0.5 : 1 - b.score);
    }
    return [left, seconds / 60];
  }

  // the vertices of a boundary in walk order (its edges are listed in walk order)
  function boundaryVertices(b) {
    const first = D.edges[b.edges[0]];
    if (b.edges.length === 1) return [first.u, first.v];
    const second = D.edges[b.edges[1]];
    let at = (first.v === second.u || first.v === second.v) ? first.u : first.v;
    const out = [at];
    for (const k of b.edges) { const e = D.edges[k]; at = e.u === at ? e.v : e.u; out.push(at); }
    return out;
  }

  function distanceToLine(p, line) {
    let best = Infinity;
    for (let k = 1; k < line.length; k++) {
      const [ax, ay] = line[k - 1], [bx, by] = line[k];
      const dx = bx - ax, dy = by - ay, len = dx * dx + dy * dy;
      const t = len ? Math.max(0, Math.min(1, ((p[0] - ax) * dx + (p[1] - ay) * dy) / len)) : 0;
      best = Math.min(best, Math.hypot(p[0] - ax - t * dx, p[1] - ay - t * dy));
    }
    return best;
  }
  function pick(p) {  // the boundary under the point
    let best = null, bestD = 6 / state.scale;
    for (const e of D.edges) {
      const b = B[boundaryOf[e.id]];
      if (state.deleted.has(e.id) || !shown(b)) continue;
      const d = distanceToLine(p, edgeLine(e));
      if (d < bestD) { best = b.id; bestD = d; }
    }
    return best;
  }
  function select(id, centre) {
    if (state.selected !== null && rows[state.selected]) rows[state.selected].classList.remove("selected");
    state.selected = id;
    if (id !== null) {
      rows[id].classList.add("selected");
      rows[id].scrollIntoView({ block: "nearest" });
      if (centre) {
        const b = B[id], line = edgeLine(D.edges[b.edges[Math.floor(b.edges.length / 2)]]);
        centreOn(line[Math.floor(line.length / 2)], 1);
      }
    }
    render();
  }
  function mark() {
    for (const b of B) {
      if (!rows[b.id]) continue;
      rows[b.id].classList.toggle("deleted", gone(b));
      rows[b.id].classList.toggle("accepted", b.edges.some((k) => state.accepted.has(k)));
      rows[b.id].hidden = !shown(b);
    }
  }
  function setBoundary(id, keep) {
    for (const k of B[id].edges) {
      (keep ? state.accepted : state.deleted).add(k);
      (keep ? state.deleted : state.accepted).delete(k);
    }
  }
  function accept() {
    if (state.selected === null) return;
    setBoundary(state.selected, true);
    mark();
    render();
  }
  function remove() {
    if (state.selected === null) return;
    setBoundary(state.selected, false);
    mark();
    select(null);
  }
  // Cut the selected boundary at its vertex nearest to p: two boundaries, each to accept or delete.
  function cutAt(p) {
    state.cutting = false;
    document.getElementById("cut").classList.remove("on");
    if (state.selected === null) return null;
    const b = B[state.selected], verts = boundaryVertices(b);
    let best = -1, bestD = Infinity;
    for (let j = 1; j < verts.length - 1; j++) {
      const q = pos(verts[j]), d = Math.hypot(q[0] - p[0], q[1] - p[1]);
      if (d < bestD) { best = j; bestD = d; }
    }
    if (best < 0) { render(); return null; }
    const tail = { edges: b.edges.slice(best), score: b.score, draft: b.draft, length_m: null, id: B.length };
    b.edges = b.edges.slice(0, best);
    for (const part of [b, tail]) {  // each part's confidence and length from its own edges
      let sum = 0, weight = 0, length = 0;
      for (const k of part.edges) {
        const line = edgeLine(D.edges[k]);
        let l = 0;
        for (let i = 1; i < line.length; i++) l += Math.hypot(line[i][0] - line[i - 1][0], line[i][1] - line[i - 1][1]);
        length += l;
        if (D.edges[k].score !== null) { sum += D.edges[k].score * l; weight += l; }
      }
      part.score = weight > 0 ? sum / weight : part.score;
      part.length_m = length * (D.metres_per_px || 0);
    }
    B.push(tail);
    tail.edges.forEach((k) => { boundaryOf[k] = tail.id; });
    listBoundaries();
    select(b.id);
    return tail.id;
  }
  function startCut() {
    if (state.selected === null) return;
    state.cutting = true;
    document.getElementById("cut").classList.add("on");
  }
  function startDrawing(area) {
    state.drawing = [];
    state.drawingArea = Boolean(area);
    document.getElementById(area ? "area" : "draw").classList.add("on");
  }
  function startSweep() {  // an area inside which every boundary below the confidence goes
    state.drawing = [];
    state.sweeping = true;
    document.getElementById("sweep").classList.add("on");
  }
  function inside(p, ring) {
    let odd = false;
    for (let i = 0, j = ring.length - 1; i < ring.length; j = i++) {
      const [xi, yi] = ring[i], [xj, yj] = ring[j];
      if ((yi > p[1]) !== (yj > p[1]) && p[0] < ((xj - xi) * (p[1] - yi)) / (yj - yi) + xi) odd = !odd;
    }
    return odd;
  }
  // delete every shown boundary less sure than the threshold whose middle lies inside the ring
  function sweep(ring, below) {
    let count = 0;
    for (const b of B) {
      if (!shown(b) || gone(b) || b.score === null || !(b.score < below)) continue;
      const e = D.edges[b.edges[Math.floor(b.edges.length / 2)]], line = edgeLine(e);
      if (!inside(line[Math.floor(line.length / 2)], ring)) continue;
      setBoundary(b.id, false);
      count += 1;
    }
    mark();
    return count;
  }
  function finishDrawing(keep) {
    if (state.drawing && keep && state.sweeping && state.drawing.length >= 3) sweep(state.drawing, parseFloat(belowInput.value));
    else if (state.drawing && keep && state.drawingArea && state.drawing.length >= 3) state.areas.push(state.drawing);
    else if (state.drawing && keep && !state.drawingArea && !state.sweeping && state.drawing.length >= 2) state.added.push(state.drawing);
    state.drawing = null;
    state.drawingArea = state.sweeping = false;
    for (const id of ["draw", "area", "sweep"]) document.getElementById(id).classList.remove("on");
    render();
  }
  function markViewComplete() {  // the part of the imagery on screen
    const [x0, y0] = toImage(0, 0), [x1, y1] = toImage(canvas.width, canvas.height);
    const cx0 = Math.max(0, x0), cy0 = Math.max(0, y0), cx1 = Math.min(D.width, x1), cy1 = Math.min(D.height, y1);
    if (cx1 - cx0 < 1 || cy1 - cy0 < 1) return;
    state.areas.push([[cx0, cy0], [cx1, cy0], [cx1, cy1], [cx0, cy1]]);
    render();
  }

  // a district's page names the city's edges and vertices (their numbers in the city's graph.json)
  const cityEdge = (id) => (D.edge_ids ? D.edge_ids[id] : id);
  const cityVertex = (i) => (D.vertex_ids ? D.vertex_ids[i] : i);
  const world = (p) => { const t = D.transform; return [t[0] * p[0] + t[1] * p[1] + t[2], t[3] * p[0] + t[4] * p[1] + t[5]]; };
  function exportEdits() {
    const features = [];
    const edgeGeometry = (id) => ({ type: "LineString", coordinates: edgeLine(D.edges[id]).map(world) });
    [...state.deleted].sort((a, b) => a - b).forEach((id) => features.push({ type: "Feature", properties: { action: "delete", edge: cityEdge(id) }, geometry: edgeGeometry(id) }));
    [...state.accepted].sort((a, b) => a - b).forEach((id) => features.push({ type: "Feature", properties: { action: "accept", edge: cityEdge(id) }, geometry: edgeGeometry(id) }));
    [...state.moved.keys()].sort((a, b) => a - b).forEach((i) => features.push({ type: "Feature", properties: { action: "move", vertex: cityVertex(i) }, geometry: { type: "Point", coordinates: world(pos(i)) } }));
    state.added.forEach((line) => features.push({ type: "Feature", properties: { action: "add" }, geometry: { type: "LineString", coordinates: line.map(world) } }));
    state.areas.forEach((ring) => features.push({ type: "Feature", properties: { action: "complete" }, geometry: { type: "Polygon", coordinates: [[...ring, ring[0]].map(world)] } }));
    const text = JSON.stringify({ type: "FeatureCollection", properties: { crs: D.crs, graph_sha256: D.graph_sha256, tool: "csboundary review" }, features }, null, 1);
    document.getElementById("export-text").value = text;
    const link = document.getElementById("download");
    link.href = URL.createObjectURL(new Blob([text], { type: "application/geo+json" }));
    link.hidden = false;
    return text;
  }

  for (const e of D.edges) {  // bounding boxes, to skip edges off screen
    const xs = e.line.map((p) => p[0]), ys = e.line.map((p) => p[1]);
    e.box = [Math.min(...xs), Math.min(...ys), Math.max(...xs), Math.max(...ys)];
  }

  // the boundary list, least sure first
  function listBoundaries() {
    const order = B.map((b) => b.id).sort((a, b) => {
      const sa = B[a].score, sb = B[b].score;
      return (sa === null) - (sb === null) || (sa - sb) || a - b;
    });
    const fragment = document.createDocumentFragment();
    for (const id of order) {
      const b = B[id];
      const li = document.createElement("li");
      li.id = `boundary-${id}`;
      li.dataset.boundary = id;
      li.dataset.edges = b.edges.join(",");
      li.textContent = `boundary ${id} · ${b.score === null ? "?" : b.score.toFixed(3)} · ${b.edges.length} edge${b.edges.length > 1 ? "s" : ""}` +
        (b.length_m ? ` · ${b.length_m.toFixed(0)} m` : "") + (b.draft ? "" : " · held back");
      li.onclick = () => select(id, true);
      rows[id] = li;
      fragment.appendChild(li);
    }
    listEl.replaceChildren(fragment);
    mark();
  }
  listBoundaries();

  canvas.addEventListener("mousedown", (ev) => {
    const p = toImage(ev.offsetX, ev.offsetY);
    if (state.drawing) { state.drawing.push(p); render(); return; }
    if (state.cutting) { cutAt(p); return; }
    if (state.selected !== null) {
      for (const i of boundaryVertices(B[state.selected])) {
        const [x, y] = toScreen(pos(i));
        if (Math.abs(x - ev.offsetX) <= 6 && Math.abs(y - ev.offsetY) <= 6) { state.drag = { vertex: i }; return; }
      }
    }
    state.drag = { x: ev.offsetX, y: ev.offsetY, ox: state.ox, oy: state.oy, moved: false };
  });
  canvas.addEventListener("mousemove", (ev) => {
    const d = state.drag;
    if (!d) return;
    if (d.vertex !== undefined) { state.moved.set(d.vertex, toImage(ev.offsetX, ev.offsetY)); render(); return; }
    if (Math.abs(ev.offsetX - d.x) + Math.abs(ev.offsetY - d.y) > 3) d.moved = true;
    state.ox = d.ox - (ev.offsetX - d.x) / state.scale;
    state.oy = d.oy - (ev.offsetY - d.y) / state.scale;
    render();
  });
  canvas.addEventListener("mouseup", (ev) => {
    const d = state.drag;
    state.drag = null;
    if (d && d.vertex === undefined && !d.moved) select(pick(toImage(ev.offsetX, ev.offsetY)));
  });
  canvas.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    const before = toImage(ev.offsetX, ev.offsetY);
    state.scale = Math.max(1 / 2 ** (D.levels + 1), Math.min(8, state.scale * Math.exp(-ev.deltaY * 0.0015)));
    state.ox = before[0] - ev.offsetX / state.scale;
    state.oy = before[1] - ev.offsetY / state.scale;
    render();
  }, { passive: false });
  document.addEventListener("keydown", (ev) => {
    if (ev.target.tagName === "TEXTAREA") return;
    if (ev.key === "a") accept();
    else if (ev.key === "Delete" || ev.key === "Backspace") remove();
    else if (ev.key === "x") startCut();
    else if (ev.key === "s") startSweep();
    else if (ev.key === "d") startDrawing(false);
    else if (ev.key === "c") startDrawing(true);
    else if (ev.key === "v") markViewComplete();
    else if (ev.key === "Enter") finishDrawing(true);
    else if (ev.key === "Escape") finishDrawing(false);
  });
  document.getElementById("accept").onclick = accept;
  document.getElementById("delete").onclick = remove;
  document.getElementById("draw").onclick = () => startDrawing(false);
  document.getElementById("area").onclick = () => startDrawing(true);
  document.getElementById("view-complete").onclick = markViewComplete;
  document.getElementById("cut").onclick = startCut;
  document.getElementById("sweep").onclick = startSweep;
  heldBox.onchange = () => { mark(); render(); };
  document.getElementById("finish").onclick = () => finishDrawing(true);
  document.getElementById("export").onclick = exportEdits;
  gtBox.onchange = render;
  gtBox.disabled = D.ground_truth.length === 0;
  window.addEventListener("resize", resize);

  canvas.width = canvas.clientWidth;
  canvas.height = canvas.clientHeight;
  fit();
  render();
  const loadedTiles = () => [...tiles.values()].filter((img) => img.complete && img.naturalWidth).length;
  const drawNow = () => { const t = performance.now(); draw(); return performance.now() - t; };  // for benchmarks
  const zoomAt = (x, y, factor) => {
    const before = toImage(x, y);
    state.scale *= factor;
    state.ox = before[0] - x / state.scale;
    state.oy = before[1] - y / state.scale;
  };
  const pendingTiles = () => [...tiles.values()].filter((img) => !img.complete).length;
  window.review = { state, select, fit: () => { fit(); render(); }, accept, remove, exportEdits, markViewComplete, loadedTiles, pendingTiles, render, drawNow, zoomAt,
                    boundaries: B, boundaryCount: () => [...listEl.children].filter((li) => !li.hidden).length,
                    edgeCount: () => D.edges.length, remaining, cutAt, sweep, boundaryVertices };
})();
