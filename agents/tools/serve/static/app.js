// The page: draws the scene the server sends and sends the player's controls, one step each 0.1 s.
"use strict";
const $ = (id) => document.getElementById(id);
const STEP_MS = 100;  // the env's control step (0.1 s): the page paces the trial in real time
const XI_NAMES = {"-1": "uncooperative", "0": "unresponsive", "1": "cooperative"};
let role = null, trial = null, running = false;
const held = {push: 0, verbal: 0, lift: 0, lean: null};

async function post(path, body) {
  const response = await fetch(path, {method: "POST", headers: {"Content-Type": "application/json"},
                                      body: JSON.stringify(body || {})});
  const data = await response.json();
  if (!response.ok) { throw new Error(data.error || response.statusText); }
  return data;
}

function showError(err) { $("error").textContent = err ? String(err.message || err) : ""; }

function draw(scene) {
  const c = $("scene"), g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  // The chair and the seated person; the torso leans by the shoulder's forward displacement x.
  const hipX = 260, hipY = 230, torso = 130;
  const angle = Math.asin(Math.max(-0.9, Math.min(0.9, scene.x_m / 0.5)));
  g.fillStyle = "#b58a5a"; g.fillRect(170, hipY, 110, 12); g.fillRect(170, 120, 12, 122); g.fillRect(270, hipY, 10, 70);
  const sx = hipX + torso * Math.sin(angle), sy = hipY - torso * Math.cos(angle);
  g.strokeStyle = "#335"; g.lineWidth = 10; g.lineCap = "round";
  g.beginPath(); g.moveTo(hipX, hipY); g.lineTo(sx, sy); g.stroke();
  g.beginPath(); g.moveTo(hipX, hipY); g.lineTo(hipX + 70, hipY); g.lineTo(hipX + 70, hipY + 70); g.stroke();
  g.beginPath(); g.arc(sx + 10 * Math.sin(angle), sy - 28, 22, 0, 2 * Math.PI); g.fillStyle = "#335"; g.fill();
  // The robot's push on the upper back, and its words.
  if (scene.push_force_n > 0) {
    const len = 2.5 * scene.push_force_n;
    g.strokeStyle = "#c33"; g.lineWidth = 6; g.beginPath(); g.moveTo(sx - 20 - len, sy + 20); g.lineTo(sx - 20, sy + 20); g.stroke();
    g.fillStyle = "#c33"; g.font = "16px sans-serif"; g.fillText(scene.push_force_n.toFixed(0) + " N", sx - 20 - len, sy + 45);
  }
  if (scene.verbal_cue !== 0) {
    g.fillStyle = "#06c"; g.font = "bold 22px sans-serif";
    g.fillText(scene.verbal_cue > 0 ? "\u201cLean forward\u201d" : "\u201cLean back\u201d", 60, 50);
  }
  // The filter's reading: xi estimate on [-1.5, 1.5] with the paper's +/-0.3 band.
  const gx = 560, gw = 300, gy = 250, toX = (v) => gx + (Math.max(-1.5, Math.min(1.5, v)) + 1.5) / 3 * gw;
  g.fillStyle = "#ddd"; g.fillRect(toX(-0.3), gy - 20, toX(0.3) - toX(-0.3), 40);
  g.strokeStyle = "#333"; g.lineWidth = 2; g.beginPath(); g.moveTo(gx, gy); g.lineTo(gx + gw, gy); g.stroke();
  g.fillStyle = "#070"; g.beginPath(); g.arc(toX(scene.xi_estimate), gy, 9, 0, 2 * Math.PI); g.fill();
  g.fillStyle = "#000"; g.font = "15px sans-serif";
  g.fillText("filter's xi estimate " + scene.xi_estimate.toFixed(2), gx, gy - 30);
  const judged = scene.judgment === null || scene.judgment === undefined ? "none yet" : XI_NAMES[String(scene.judgment)];
  g.fillText("judgment: " + judged, gx, gy + 40);
  g.fillText("t = " + scene.elapsed_s.toFixed(1) + " s", gx, 40);
  if (scene.true_xi) { drawTruth(g, scene); }
  if (scene.p_xi_imm) { drawProbabilities(g, scene.p_xi_imm); }
}

function drawProbabilities(g, p) {
  // The IMM's P(xi = -1, 0, +1), read from the same samples as the paper's filter.
  const x0 = 560, y0 = 170, labels = ["uncoop.", "unresp.", "coop."];
  g.fillStyle = "#000"; g.font = "14px sans-serif"; g.fillText("IMM P(xi)", x0, y0 - 95);
  p.forEach((v, k) => {
    g.fillStyle = "#69c"; g.fillRect(x0 + 20 + 90 * k, y0 - 80 * v, 40, 80 * v);
    g.fillStyle = "#000"; g.fillText(labels[k] + " " + v.toFixed(2), x0 + 90 * k, y0 + 18);
  });
}

function drawTruth(g, scene) {
  // After the episode: the true mental state over time, uncovered.
  const x0 = 560, w = 300, y0 = 80, h = 90, end = Math.max(1, scene.times_s[scene.times_s.length - 1]);
  g.strokeStyle = "#a0a"; g.lineWidth = 2; g.beginPath();
  scene.times_s.forEach((t, k) => { const x = x0 + t / end * w, y = y0 + (1 - scene.true_xi[k]) / 2 * h;
                                    k ? g.lineTo(x, y) : g.moveTo(x, y); });
  g.stroke(); g.fillStyle = "#a0a"; g.fillText("true xi (+1 top, -1 bottom), revealed", x0, y0 - 8);
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function loop(path, controls, onDone) {
  running = true;
  while (running && trial) {
    const began = performance.now();
    let data;
    try {
      data = await post(path, {trial_id: trial.trial_id, token: trial.token, seq: ++trial.seq, ...controls()});
    } catch (err) { showError(err); running = false; break; }
    draw(data.scene);
    if (data.scene.done) { running = false; await onDone(data); break; }
    await sleep(Math.max(0, STEP_MS - (performance.now() - began)));
  }
}

function caregiverControls() {
  const out = {push: held.push, verbal: held.verbal, lift: held.lift};
  held.verbal = 0;  // words are said once; the env plays them for 1 s
  return out;
}

async function caregiverDone(data) {
  const s = data.scene, rows = data.compared.map((c) =>
    `<tr><td>${c.agent}</td><td>${c.outcome}</td><td>${c.lift_time_s === null ? "-" : c.lift_time_s.toFixed(1) + " s"}</td></tr>`);
  $("outcome").innerHTML = `<p id="cg-outcome">Outcome: <b>${s.outcome}</b> (persona ${s.persona}, seed ${s.seed},
    return ${s.episode_return.toFixed(2)}). Stored. Enter: next person.</p>
    <table><tr><th>caregiver</th><th>outcome</th><th>lift</th></tr>
    <tr><td>you</td><td>${s.outcome}</td><td>${s.lift_time_s === null ? "-" : s.lift_time_s.toFixed(1) + " s"}</td></tr>
    ${rows.join("")}</table>`;
  trial = null;
}

async function caregiverStart() {
  if (running) { return; }
  showError(""); $("outcome").innerHTML = "";
  Object.assign(held, {push: 0, verbal: 0, lift: 0});
  try { trial = await post("/api/caregiver/start"); } catch (err) { showError(err); return; }
  trial.seq = 0;
  $("status").textContent = `caregiver episode: ${trial.env_id}, seed ${trial.scene.seed}`;
  draw(trial.scene);
  loop("/api/caregiver/step", caregiverControls, caregiverDone);
}

function intention() {
  if (held.lean === "forward") { return 0.25; }
  if (held.lean === "back") { return -0.03; }
  return parseFloat($("intention").value);
}

async function personDone(data) {
  $("status").textContent = `trial ${trial.trial_index + 1} of ${trial.n_trials} stored. Enter: next trial.`;
  if (data.results) {
    $("results").hidden = false;
    $("results").textContent = data.results.text;
    $("status").textContent = `session ${trial.session_id} complete: balanced accuracy ` +
      (100 * data.results.balanced_accuracy).toFixed(1) + " %";
    localStorage.removeItem("coop_gym_session");
  }
  trial = null;
}

async function personStart() {
  if (running) { return; }
  showError(""); $("results").hidden = true;
  const saved = localStorage.getItem("coop_gym_session");
  try {
    trial = await post("/api/person/start", saved ? {session_id: parseInt(saved, 10)} : {});
  } catch (err) { showError(err); return; }
  trial.seq = 0;
  localStorage.setItem("coop_gym_session", String(trial.session_id));
  $("request").textContent = `Trial ${trial.trial_index + 1} of ${trial.n_trials}: please be ${trial.requested.toUpperCase()}`;
  $("status").textContent = `session ${trial.session_id}`;
  draw(trial.scene);
  loop("/api/person/step", () => ({intention_m: intention()}), personDone);
}

function choose(which) {
  role = which;
  $("caregiver").hidden = which !== "caregiver";
  $("person").hidden = which !== "person";
}

$("role-caregiver").onclick = () => choose("caregiver");
$("role-person").onclick = () => choose("person");
$("cg-start").onclick = caregiverStart;
$("ps-start").onclick = personStart;
$("cg-lift").onclick = () => { held.lift = 1; };
document.querySelectorAll("[data-push]").forEach((b) => { b.onclick = () => { held.push = +b.dataset.push; }; });
document.querySelectorAll("[data-verbal]").forEach((b) => { b.onclick = () => { held.verbal = +b.dataset.verbal; }; });
$("intention").oninput = () => { $("intention-value").textContent = (+$("intention").value).toFixed(3) + " m"; };

document.addEventListener("keydown", (e) => {
  const k = e.key.toLowerCase();
  if (k === "enter") { role === "caregiver" ? caregiverStart() : role === "person" ? personStart() : null; return; }
  if (role === "caregiver") {
    if (k in {"1": 0, "2": 0, "3": 0}) { held.push = +k - 1; }
    if (k === "b") { held.verbal = 1; }
    if (k === "f") { held.verbal = 2; }
    if (k === "l") { held.lift = 1; }
  } else if (role === "person") {
    if (k === "f" || k === "arrowup") { held.lean = "forward"; e.preventDefault(); }
    if (k === "b" || k === "arrowdown") { held.lean = "back"; e.preventDefault(); }
  }
});
document.addEventListener("keyup", (e) => {
  const k = e.key.toLowerCase();
  if (role === "person" && ["f", "b", "arrowup", "arrowdown"].includes(k)) { held.lean = null; }
});
draw({x_m: 0, push_force_n: 0, verbal_cue: 0, xi_estimate: 0, judgment: null, elapsed_s: 0});
