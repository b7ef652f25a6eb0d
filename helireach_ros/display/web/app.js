// helireach cockpit display: receives JSON frames (SI units) over a WebSocket from helireach_ros.display.node
// and draws them. Read-only: the page never sends anything. The banner follows /helireach/safety_status only;
// the server decides staleness, and the page also shows NO DATA when its own link goes quiet or drops.
"use strict";

(() => {
  const LEVEL_WORDS = { safe: "SAFE", caution: "CAUTION", avoid: "AVOID", nodata: "NO DATA" };
  const DEFAULT_STALE_S = 2.0; // until the server's config arrives
  const TRAIL_SECONDS = 20.0;
  const TRAIL_SPACING_MS = 200;
  const TRAIL_GAP_MS = 1000;
  const DEFAULT_AXES = { speedKt: 160, heightFt: 1000 }; // when no envelope is loaded
  const RECONNECT_MIN_MS = 500;
  const RECONNECT_MAX_MS = 5000;
  const COLORS = {
    grid: "#26313c",
    axis: "#9aa7b4",
    text: "#e8ecf0",
    avoid: "rgba(224, 0, 0, 0.55)",
    avoidEdge: "#ff5050",
    boundary: "#ffffff",
    plan: "#ff40ff",
    aircraft: "#ffffff",
    trail: "#35d0ff",
    stale: "#8a939e",
    collective: "#35d0ff",
    pitch: "#ffd54f",
    rotorBand: "#00c853",
    rotorBad: "#e00000",
    rotorCaution: "#ffb300",
    ground: "#8d6e3f",
    footprint: "#00c853",
    footprintBand: "rgba(0, 200, 83, 0.55)",
    siteReachable: "#00c853",
    siteNotReachable: "#ff5050",
    siteUnknown: "#ffb300",
  };
  const SITE_COLORS = { reachable: COLORS.siteReachable, not_reachable: COLORS.siteNotReachable, unknown: COLORS.siteUnknown };

  const model = {
    config: null,
    envelope: null,
    plan: null,
    live: null,
    link: "connecting",
    lastMessageAt: 0,
    trail: [], // {t, speedKt, heightFt, broken (no line from the previous point)}
    trailBroken: false,
    lastPhase: null, // the phase before the data went stale
    frozenTimer: null, // s after the failure at touchdown
  };
  // What the page currently shows, for people debugging and for the acceptance test.
  const view = { banner: "nodata", bannerDetail: "", marker: null, plan: { shown: false, pathPoints: 0 }, frames: 0, link: "connecting" };
  window.helireach = view;

  const $ = (id) => document.getElementById(id);
  const ft = (meters) => meters / unit("m_per_ft", 0.3048);
  const kt = (metersPerSecond) => metersPerSecond / unit("ms_per_kt", 1852 / 3600);
  const isNum = (x) => typeof x === "number" && Number.isFinite(x);

  function unit(name, fallback) {
    const units = model.config && model.config.units;
    return units && isNum(units[name]) ? units[name] : fallback;
  }

  function staleMs() {
    const seconds = model.config && isNum(model.config.stale_after_s) ? model.config.stale_after_s : DEFAULT_STALE_S;
    return seconds * 1000;
  }

  function fmt(x, digits = 0, signed = false) {
    if (!isNum(x)) return "---";
    const text = Math.abs(x).toFixed(digits);
    if (Number(text) === 0) return (0).toFixed(digits);
    return (x < 0 ? "\u2212" : signed ? "+" : "") + text;
  }

  // ---- WebSocket --------------------------------------------------------------------------------------
  let reconnectMs = RECONNECT_MIN_MS;

  function connect() {
    const scheme = location.protocol === "https:" ? "wss:" : "ws:";
    let socket;
    try {
      socket = new WebSocket(`${scheme}//${location.host}/ws`);
    } catch (error) {
      scheduleReconnect();
      return;
    }
    socket.onopen = () => {
      model.link = "up";
      model.lastMessageAt = performance.now();
      reconnectMs = RECONNECT_MIN_MS;
    };
    socket.onmessage = (event) => {
      let frame;
      try {
        frame = JSON.parse(event.data);
      } catch (error) {
        return; // a broken frame is ignored; silence then turns the banner to NO DATA
      }
      applyFrame(frame);
    };
    socket.onclose = () => {
      model.link = "down";
      updateDom();
      scheduleReconnect();
    };
    socket.onerror = () => socket.close();
  }

  function scheduleReconnect() {
    setTimeout(connect, reconnectMs);
    reconnectMs = Math.min(reconnectMs * 2, RECONNECT_MAX_MS);
  }

  function applyFrame(frame) {
    model.lastMessageAt = performance.now();
    model.link = "up";
    if ("config" in frame) model.config = frame.config;
    if ("envelope" in frame) model.envelope = frame.envelope;
    if ("plan" in frame) model.plan = frame.plan;
    if ("live" in frame) model.live = frame.live;
    view.frames += 1;
    extendTrail();
    updateDom();
    requestDraw();
  }

  function extendTrail() {
    const state = model.live && model.live.state;
    const now = performance.now();
    if (!state || state.stale || !isNum(state.height_m) || !isNum(state.speed_ms)) {
      model.trailBroken = true; // do not join the track across a gap in the data
    } else {
      const last = model.trail[model.trail.length - 1];
      if (!last || now - last.t >= TRAIL_SPACING_MS) {
        const broken = model.trailBroken || (last && now - last.t > TRAIL_GAP_MS);
        model.trail.push({ t: now, speedKt: kt(state.speed_ms), heightFt: ft(state.height_m), broken });
        model.trailBroken = false;
      }
    }
    while (model.trail.length && now - model.trail[0].t > TRAIL_SECONDS * 1000) model.trail.shift();
  }

  // ---- banner and readouts (DOM) -----------------------------------------------------------------------
  // The server decides the phase and its banner (helireach_ros/core/policies/flight_phase.py); the page only adds its own
  // link check: a lost or quiet link is STALE whatever the last frame said.
  function bannerState() {
    const now = performance.now();
    if (model.link !== "up") {
      const detail = model.link === "down" ? "DISPLAY LINK LOST \u2014 RECONNECTING" : "CONNECTING";
      return { phase: "stale", level: "nodata", word: "STALE", detail, link: model.link };
    }
    const quietMs = now - model.lastMessageAt;
    if (quietMs > staleMs()) {
      const detail = `NO DATA FROM DISPLAY SERVER FOR ${(quietMs / 1000).toFixed(1)} s`;
      return { phase: "stale", level: "nodata", word: "STALE", detail, link: "quiet" };
    }
    const phase = model.live && model.live.phase;
    if (!phase) return { phase: "stale", level: "nodata", word: "STALE", detail: "NO PHASE FROM THE SERVER", link: "up" };
    const level = Object.prototype.hasOwnProperty.call(LEVEL_WORDS, phase.level) ? phase.level : "nodata";
    let detail = phase.detail || "";
    const status = model.live.status;
    if (phase.phase === "normal" && level === "nodata" && status && status.last_level && isNum(status.age_s)) {
      detail += ` \u00b7 LAST ${LEVEL_WORDS[status.last_level] || "?"} ${status.age_s.toFixed(1)} s AGO`;
    }
    return { phase: phase.phase, level, word: phase.word || LEVEL_WORDS[level], detail, link: "up" };
  }

  function setData(element, key, value) {
    if (element.dataset[key] !== value) element.dataset[key] = value;
  }

  function updateDom() {
    const banner = bannerState();
    setData(document.body, "phase", banner.phase);
    setData(document.body, "level", banner.level);
    setData($("banner"), "level", banner.level);
    $("banner-word").textContent = banner.word;
    $("banner-word").classList.toggle("long", banner.word.length > 12);
    $("banner-detail").textContent = banner.detail;
    view.phase = banner.phase;
    view.banner = banner.level;
    view.word = banner.word;
    view.bannerDetail = banner.detail;
    view.link = banner.link;
    if (banner.phase !== "stale") model.lastPhase = banner.phase;

    const link = $("link-state");
    link.dataset.link = banner.link;
    link.textContent = `LINK: ${banner.link.toUpperCase()}`;

    updateBannerSide(banner);
    updateEngineStrip(banner);
    updateReadouts(banner);
    updatePlanPanel();
    updateFooter();
  }

  // Margins along the axes (feet above/below the H-V boundary at this speed, knots faster/slower at this height),
  // only while the status rests on the envelope (it then carries a margin) and the page shows the H-V status.
  function updateBannerSide(banner) {
    const phase = banner.phase === "stale" ? model.lastPhase : banner.phase;
    const flying = phase === "autorotation";
    // the H-V margins mean something only while the H-V status is the banner (normal, ended)
    $("banner-margin").hidden = phase === "autorotation" || phase === "landed";
    $("banner-touchdown").hidden = !flying;
    const clock = model.live && model.live.plan_clock;
    $("banner-ttd").textContent = flying && clock ? fmt(clock.time_to_touchdown_s, 1) : "---";
    const status = model.live && model.live.status;
    const margins = model.live && model.live.margins;
    const usable = !flying && banner.level !== "nodata" && status && isNum(status.margin) && margins;
    const axes = [
      ["margin-ft", "vertical", ft, "ABOVE", "BELOW"],
      ["margin-kt", "horizontal", kt, "FASTER", "SLOWER"],
    ];
    view.margins = {};
    for (const [id, axis, convert, positive, negative] of axes) {
      const line = usable ? margins[axis] : null;
      let value = "---";
      let direction = "";
      if (line && isNum(line.offset)) {
        value = fmt(Math.abs(convert(line.offset)));
        direction = line.offset >= 0 ? positive : negative;
      } else if (line) {
        direction = line.safe ? "CLEAR" : "NO SAFE";
      }
      $(id).textContent = value;
      $(`${id}-dir`).textContent = direction;
      view.margins[axis] = `${value} ${direction}`.trim();
    }
  }

  // The engine failure is its own strip while the episode lasts: red in the air, grey once landed or recovered;
  // the timer runs only in the air (it freezes at the touchdown).
  function updateEngineStrip(banner) {
    const live = model.live;
    const phase = banner.phase === "stale" ? model.lastPhase : banner.phase;
    const failure = live && live.failure;
    const touchdown = live && live.touchdown;
    const episode = live && live.episode;
    const strip = $("engine-strip");
    let word = null;
    let timer = "";
    if (phase === "autorotation") {
      word = "ENGINE FAILURE";
      timer = failure && isNum(failure.age_s) ? `T+${fmt(failure.age_s, 1)} s` : "";
      model.frozenTimer = null;
    } else if (phase === "landed") {
      word = "ENGINE FAILURE \u00b7 LANDED";
      if (touchdown && isNum(touchdown.time_after_failure_s)) {
        model.frozenTimer = touchdown.time_after_failure_s;
      } else if (episode && isNum(episode.started_ns) && isNum(episode.ended_ns)) {
        model.frozenTimer = (episode.ended_ns - episode.started_ns) / 1e9;
      } else if (model.frozenTimer === null && failure && isNum(failure.age_s)) {
        model.frozenTimer = failure.age_s; // first frame seen landed
      }
      timer = isNum(model.frozenTimer) ? `TOUCHDOWN AT T+${fmt(model.frozenTimer, 1)} s` : "";
    } else if (phase === "ended") {
      word = "ENGINE RECOVERED \u00b7 EPISODE ENDED";
    }
    strip.hidden = !word;
    setData(strip, "phase", banner.phase === "stale" ? "stale" : phase || "");
    if (word) $("engine-word").textContent = word;
    $("engine-timer").textContent = timer;
    const cue = phase === "autorotation" && banner.phase !== "stale" && live ? live.cue : null;
    $("cue").textContent = cue ? `CUE: ${cue}` : "";
    $("cue").hidden = !cue;
    view.engine = word;
    view.cue = cue;
    view.episode = episode ? episode.phase : null;
  }

  // The plan's controls now and one second ahead, piecewise constant as the vehicle flies them.
  function planValueAt(values, t) {
    const times = model.plan && model.plan.trajectory && model.plan.trajectory.t_s;
    if (!times || !values || !isNum(t)) return null;
    let value = null;
    for (let i = 0; i < times.length; i += 1) {
      if (isNum(times[i]) && times[i] <= t + 1e-9 && isNum(values[i])) value = values[i];
      else if (isNum(times[i]) && times[i] > t) break;
    }
    return value;
  }

  // Thrust in % of weight: scale (100 ρA(Ω₀R)²/W, the plan's weight and density when it says, else the airframe
  // file's) × C_T × (Ω/Ω₀)² with the measured rotor speed; Ω₀ when none is fresh (marked "@100 %").
  function thrustPct(collective) {
    const status = model.plan && model.plan.status;
    const config = model.config && model.config.thrust;
    const scale = status && isNum(status.thrust_scale_pct) ? status.thrust_scale_pct : config && config.scale_pct;
    if (!isNum(scale) || !isNum(collective)) return { pct: null, assumed: false };
    const rotor = model.live && model.live.rotor;
    const limits = model.config && model.config.rotor_limits;
    const measured = rotor && !rotor.stale && isNum(rotor.speed_rad_s) && limits;
    const ratio = measured ? rotor.speed_rad_s / limits.nominal_rad_s : 1;
    return { pct: scale * collective * ratio * ratio, assumed: !measured };
  }

  function updateReadouts(banner) {
    const state = model.live && model.live.state;
    const stale = !state || state.stale || model.link !== "up";
    const phase = banner.phase === "stale" ? model.lastPhase : banner.phase; // stale: as the last phase, struck out
    const descending = phase === "autorotation" || phase === "landed";
    $("height-value").textContent = state ? fmt(ft(state.height_m)) : "---";
    $("speed-value").textContent = state ? fmt(kt(state.speed_ms)) : "---";
    $("climb-label").textContent = descending ? "DESCENT" : "V/S";
    const climbFpm = state && isNum(state.climb_ms) ? ft(state.climb_ms) * 60 : null;
    $("climb-value").textContent = climbFpm === null ? "---" : descending ? fmt(-climbFpm) : fmt(climbFpm, 0, true);
    $("state-age").textContent = !state ? "NO STATE" : state.stale ? "STALE" : "LIVE";
    document.querySelector(".readouts").classList.toggle("stale", stale);

    const clock = model.live && model.live.plan_clock;
    const flying = banner.phase === "autorotation" && planState() === "shown" && clock && isNum(clock.elapsed_s);
    const trajectory = flying ? model.plan.trajectory : null;
    const pitch = trajectory ? planValueAt(trajectory.pitch_rad, clock.elapsed_s) : null;
    $("pitch-value").textContent = isNum(pitch) ? fmt((-pitch * 180) / Math.PI, 0, true) : "---"; // −θ: nose up +
    const now = trajectory ? thrustPct(planValueAt(trajectory.collective, clock.elapsed_s)) : { pct: null };
    const ahead = trajectory ? thrustPct(planValueAt(trajectory.collective, clock.elapsed_s + 1)) : { pct: null };
    $("thrust-value").textContent = isNum(now.pct) ? fmt(now.pct) : "---";
    let trend = "";
    if (isNum(now.pct) && isNum(ahead.pct)) {
      // the plan over the next second: up / down by more than 5 % of the weight, else steady
      trend = ahead.pct - now.pct > 5 ? "\u25b2" : ahead.pct - now.pct < -5 ? "\u25bc" : "\u25b6";
    }
    $("thrust-trend").textContent = trend + (now.assumed && isNum(now.pct) ? " @100 %" : "");
    view.readouts = {
      climbLabel: $("climb-label").textContent,
      climb: $("climb-value").textContent,
      pitch: $("pitch-value").textContent,
      thrust: $("thrust-value").textContent,
      trend,
    };

    const rotor = model.live && model.live.rotor;
    const limits = model.config && model.config.rotor_limits;
    const rotorPanel = document.querySelector(".rotor");
    if (!rotor || !isNum(rotor.speed_rad_s)) {
      $("rotor-value").textContent = "---";
      $("rotor-rpm").textContent = rotor ? "NO MAIN ROTOR SPEED" : "NO ROTOR DATA";
      rotorPanel.dataset.state = "none";
    } else {
      const rpm = (rotor.speed_rad_s * 60) / (2 * Math.PI);
      const pct = limits ? (100 * rotor.speed_rad_s) / limits.nominal_rad_s : null;
      $("rotor-value").textContent = limits ? fmt(pct) : "---";
      $("rotor-rpm").textContent = `${fmt(rpm)} rpm` + (rotor.stale ? " \u00b7 STALE" : "") + (limits ? "" : " \u00b7 NO LIMITS");
      rotorPanel.dataset.state = rotorState(rotor, limits, pct, phase);
    }
    view.rotor = rotorPanel.dataset.state;
  }

  // ok (green), caution (amber: within caution_pct of a limit), low/high (red: beyond a limit); on the ground after
  // the failure the rotor runs down by design: no colour ("ground").
  function rotorState(rotor, limits, pct, phase) {
    if (rotor.stale || model.link !== "up") return "stale";
    if (!limits) return "none";
    if (phase === "landed") return "ground";
    const minPct = (100 * limits.min_rad_s) / limits.nominal_rad_s;
    const maxPct = (100 * limits.max_rad_s) / limits.nominal_rad_s;
    const band = isNum(limits.caution_pct) ? limits.caution_pct : 0;
    if (pct < minPct) return "low";
    if (pct > maxPct) return "high";
    if (pct < minPct + band || pct > maxPct - band) return "caution";
    return "ok";
  }

  function planState() {
    const plan = model.plan;
    if (!plan) return "none";
    const phase = view.phase === "stale" ? model.lastPhase : view.phase;
    if (phase === "landed") return "landed"; // on the ground: the plan (and its countdown) no longer applies
    if (plan.status && plan.status.status === "ended") return "ended"; // engine recovered: the plan is void
    if (!plan.trajectory) return "planning";
    if (plan.trajectory.error) return "error";
    return "shown";
  }

  function updatePlanPanel() {
    const state = planState();
    const panel = $("plan-panel");
    panel.dataset.state = state;
    const badge = $("plan-badge");
    $("plan-idle").hidden = state === "shown";
    $("plan-body").hidden = state !== "shown";
    $("side-panel").hidden = state !== "shown" && !groundLine().show;
    if (state === "none") $("plan-idle").textContent = "ENGINE NORMAL \u00b7 NO PLAN";
    if (state === "planning") $("plan-idle").textContent = "ENGINE FAILURE \u00b7 PLANNING\u2026";
    if (state === "error") $("plan-idle").textContent = `PLAN UNREADABLE: ${model.plan.trajectory.error}`.toUpperCase();
    if (state === "ended") $("plan-idle").textContent = "ENDED (ENGINE RECOVERED) \u00b7 NO PLAN";
    if (state === "landed") $("plan-idle").textContent = "LANDED \u00b7 THE PLAN NO LONGER APPLIES";
    view.plan.shown = state === "shown";
    view.plan.state = state;
    if (state !== "shown") {
      badge.hidden = state !== "ended";
      badge.dataset.kind = "ended";
      badge.textContent = "ENDED";
      view.plan.badge = state === "ended" ? "ENDED" : null;
      view.plan.robust = null;
      return;
    }
    const status = model.plan.status;
    let kind = "unverified";
    let text = "UNVERIFIED";
    if (status && status.fallback === true) {
      kind = "fallback";
      text = "FALLBACK";
    } else if (status && (status.safe === false || status.level === "avoid")) {
      kind = "unsafe";
      text = "UNSAFE";
    } else if (status && status.verified === true) {
      kind = "verified";
      text = status.robust === true ? "ROBUST" : "VERIFIED";
      if (status.standby === true) text = `STANDBY \u00b7 ${text}`;
    }
    if (status && status.late === true && kind === "verified") {
      kind = "late"; // verified from a state long after the failure: caution, never plain green
      text += " \u00b7 LATE";
    }
    // a plan is never shown green on a page whose data is stale or held
    if (kind === "verified" && view.phase === "stale") kind = "stale";
    badge.hidden = false;
    badge.dataset.kind = kind;
    badge.textContent = text;
    view.plan.badge = text;
    view.plan.badgeKind = kind;

    const clock = model.live && model.live.plan_clock;
    $("touchdown-value").textContent = clock ? fmt(clock.time_to_touchdown_s, 1) : "---";
    view.plan.timeToTouchdown = clock ? clock.time_to_touchdown_s : null;
    const details = [];
    if (status) {
      if (isNum(status.replan_index) && status.replan_index > 0) details.push(`re-plan ${fmt(status.replan_index)}`);
      if (isNum(status.solve_time_ms)) details.push(`solve ${fmt(status.solve_time_ms)} ms`);
      if (status.message) {
        details.push(status.message);
      } else if (isNum(status.touchdown_descent_rate_ms) && isNum(status.touchdown_forward_speed_ms)) {
        const rate = fmt(ft(status.touchdown_descent_rate_ms), 1);
        details.push(`touchdown ${rate} ft/s, ${fmt(kt(status.touchdown_forward_speed_ms))} kt`);
      }
    } else {
      details.push("no plan status");
    }
    $("plan-detail").textContent = details.join(" \u00b7 ");
    updateRobustVerdict(status, model.plan.robust_verdict);
  }

  // The failure plan's robust verdict (/helireach/robust_verdict), shown only beside a plan of the same failure:
  // a verdict of an earlier failure says nothing of this one. Green only for robust = true.
  function updateRobustVerdict(status, verdict) {
    const line = $("plan-robust");
    const values = (status && status.values) || {};
    const same =
      verdict && verdict.robust !== null && verdict.failure_id !== undefined && verdict.failure_id !== null &&
      String(verdict.failure_id) === String(values.failure_id) &&
      String(verdict.failure_stamp_ns) === String(values.failure_stamp_ns);
    line.hidden = !same;
    view.plan.robust = null;
    if (!same) return;
    // the verdict is the failure plan's (re-plans are not verified robustly): the text says so
    let kind = "pending";
    let text = "FIRST PLAN: ROBUST CHECK PENDING";
    if (verdict.robust === "true") {
      kind = "robust";
      text = isNum(verdict.models_flown) ? `FIRST PLAN ROBUST IN ${fmt(verdict.models_flown)} MODELS` : "FIRST PLAN ROBUST";
    } else if (verdict.robust === "false") {
      kind = "not_robust";
      const reason = verdict.message.replace(/^NOT ROBUST:\s*/, "");
      text = verdict.error ? `FIRST PLAN: ROBUST CHECK FAILED: ${reason}` : `FIRST PLAN NOT ROBUST: ${reason}`;
    }
    if (kind === "robust" && view.phase === "stale") kind = "stale"; // never green on a stale page
    line.dataset.kind = kind;
    line.textContent = text;
    line.title = verdict.message;
    view.plan.robust = { kind, text };
  }

  function updateFooter() {
    const config = model.config;
    const envelope = model.envelope;
    $("airframe-label").textContent = config && config.airframe ? `AIRFRAME ${config.airframe.toUpperCase()}` : "";
    $("status-source").textContent = config && config.state_topic ? `STATE ${config.state_topic}` : "";
    let label = "no envelope";
    if (envelope && envelope.available) {
      label = `envelope ${envelope.envelope_id}` + (envelope.method ? ` \u00b7 ${envelope.method}` : "");
      if (envelope.conditions) label += ` \u00b7 ${envelope.conditions}`; // a family member's weight and altitude
      if (isNum(envelope.power_fraction)) label += ` \u00b7 power ${fmt(100 * envelope.power_fraction)} %`;
    } else if (envelope) {
      label = "envelope unavailable";
    }
    $("envelope-label").textContent = label;
    $("hv-nodata").hidden = !envelope || envelope.available;
    if (envelope && !envelope.available) $("hv-nodata-reason").textContent = envelope.reason;
  }

  // ---- canvases ----------------------------------------------------------------------------------------
  let drawPending = false;

  function requestDraw() {
    if (drawPending) return;
    drawPending = true;
    requestAnimationFrame(() => {
      drawPending = false;
      drawHv();
      drawRotor();
      drawPlanCharts();
      drawSideView();
    });
  }

  function prepareCanvas(canvas) {
    const ratio = window.devicePixelRatio || 1;
    const width = Math.max(canvas.clientWidth, 1);
    const height = Math.max(canvas.clientHeight, 1);
    if (canvas.width !== Math.round(width * ratio) || canvas.height !== Math.round(height * ratio)) {
      canvas.width = Math.round(width * ratio);
      canvas.height = Math.round(height * ratio);
    }
    const context = canvas.getContext("2d");
    context.setTransform(ratio, 0, 0, ratio, 0, 0);
    context.clearRect(0, 0, width, height);
    return { context, width, height };
  }

  function niceStep(range, targetTicks) {
    const raw = range / Math.max(targetTicks, 1);
    const power = Math.pow(10, Math.floor(Math.log10(raw)));
    for (const multiple of [1, 2, 2.5, 5, 10]) if (multiple * power >= raw) return multiple * power;
    return 10 * power;
  }

  let hatchTile = null;

  function hatchPattern(context) {
    if (hatchTile) return context.createPattern(hatchTile, "repeat");
    const tile = document.createElement("canvas");
    tile.width = 10;
    tile.height = 10;
    const tileContext = tile.getContext("2d");
    tileContext.strokeStyle = "rgba(150, 160, 172, 0.7)";
    tileContext.lineWidth = 2;
    tileContext.beginPath();
    tileContext.moveTo(0, 10);
    tileContext.lineTo(10, 0);
    tileContext.stroke();
    hatchTile = tile;
    return context.createPattern(tile, "repeat");
  }

  function drawAxes(context, frame, xMax, yMax, xTitle, yTitle, xStep, yStep, fontPx) {
    context.strokeStyle = COLORS.grid;
    context.lineWidth = 1;
    context.fillStyle = COLORS.axis;
    context.font = `bold ${fontPx}px "DejaVu Sans", "Liberation Sans", Arial, sans-serif`;
    context.textAlign = "center";
    context.textBaseline = "top";
    for (let x = 0; x <= xMax + 1e-9; x += xStep) {
      const px = frame.x(x);
      context.beginPath();
      context.moveTo(px, frame.top);
      context.lineTo(px, frame.bottom);
      context.stroke();
      context.fillText(String(Number(x.toFixed(3))), px, frame.bottom + 6);
    }
    context.textAlign = "right";
    context.textBaseline = "middle";
    for (let y = 0; y <= yMax + 1e-9; y += yStep) {
      const py = frame.y(y);
      context.beginPath();
      context.moveTo(frame.left, py);
      context.lineTo(frame.right, py);
      context.stroke();
      context.fillText(String(Number(y.toFixed(3))), frame.left - 8, py);
    }
    context.strokeStyle = COLORS.axis;
    context.lineWidth = 2;
    context.strokeRect(frame.left, frame.top, frame.right - frame.left, frame.bottom - frame.top);
    context.fillStyle = COLORS.text;
    context.textAlign = "center";
    context.textBaseline = "bottom";
    if (xTitle) context.fillText(xTitle, (frame.left + frame.right) / 2, frame.bottom + 2.6 * fontPx + 8);
    if (yTitle) {
      context.save();
      context.translate(frame.left - 3.2 * fontPx, (frame.top + frame.bottom) / 2);
      context.rotate(-Math.PI / 2);
      context.textBaseline = "middle";
      context.fillText(yTitle, 0, 0);
      context.restore();
    }
  }

  function makeFrame(left, top, right, bottom, xMin, xMax, yMin, yMax) {
    const sx = (right - left) / (xMax - xMin || 1);
    const sy = (bottom - top) / (yMax - yMin || 1);
    return {
      left, top, right, bottom,
      x: (value) => left + (value - xMin) * sx,
      y: (value) => bottom - (value - yMin) * sy,
    };
  }

  function drawHv() {
    const { context, width, height } = prepareCanvas($("hv-canvas"));
    const envelope = model.envelope && model.envelope.available ? model.envelope : null;
    const speedsKt = envelope ? envelope.speeds_ms.map(kt) : null;
    const heightsFt = envelope ? envelope.heights_m.map(ft) : null;
    const xMax = envelope ? speedsKt[speedsKt.length - 1] : DEFAULT_AXES.speedKt;
    const yMax = envelope ? heightsFt[heightsFt.length - 1] : DEFAULT_AXES.heightFt;
    const fontPx = Math.max(14, Math.min(20, Math.round(width / 50)));
    const frame = makeFrame(4.4 * fontPx + 8, 12, width - 16, height - 3 * fontPx - 12, 0, xMax, 0, yMax);
    drawAxes(context, frame, xMax, yMax, "FORWARD SPEED (kt)", "HEIGHT (ft)", niceStep(xMax, 8), niceStep(yMax, 8), fontPx);

    context.save();
    context.beginPath();
    context.rect(frame.left, frame.top, frame.right - frame.left, frame.bottom - frame.top);
    context.clip();
    if (envelope) drawEnvelope(context, frame, envelope, speedsKt, heightsFt);
    drawPlanPath(context, frame);
    context.restore();
    drawAircraft(context, frame, xMax, yMax); // unclipped: clamped to the axes, but never cut off
  }

  function drawEnvelope(context, frame, envelope, speedsKt, heightsFt) {
    const hatch = hatchPattern(context);
    const codes = envelope.status;
    // Outside the grid is unknown, never safe.
    context.fillStyle = hatch;
    if (heightsFt[0] > 0) context.fillRect(frame.left, frame.y(heightsFt[0]), frame.right - frame.left, frame.y(0) - frame.y(heightsFt[0]));
    if (speedsKt[0] > 0) context.fillRect(frame.x(0), frame.top, frame.x(speedsKt[0]) - frame.x(0), frame.bottom - frame.top);
    // A cell is shaded by its worst corner: the status between grid nodes is never more optimistic than that.
    for (let i = 0; i + 1 < heightsFt.length; i += 1) {
      for (let j = 0; j + 1 < speedsKt.length; j += 1) {
        const corners = [codes[i][j], codes[i][j + 1], codes[i + 1][j], codes[i + 1][j + 1]];
        const worst = corners.includes(1) ? 1 : corners.includes(2) ? 2 : 0;
        if (worst === 0) continue;
        const x0 = frame.x(speedsKt[j]);
        const x1 = frame.x(speedsKt[j + 1]);
        const y0 = frame.y(heightsFt[i]);
        const y1 = frame.y(heightsFt[i + 1]);
        context.fillStyle = worst === 1 ? COLORS.avoid : hatch;
        // +0.5 px overlap so neighbouring cells leave no hairline gaps
        context.fillRect(x0 - 0.25, y1 - 0.25, x1 - x0 + 0.5, y0 - y1 + 0.5);
      }
    }
    drawBoundary(context, frame, envelope);
  }

  function drawBoundary(context, frame, envelope) {
    // The server joins the refined boundary points into segments (marching squares over the grid cells).
    const segments = (envelope.boundary_segments || []).filter((s) => s.every(isNum));
    const points = (envelope.boundary || []).filter((p) => isNum(p[0]) && isNum(p[1]));
    for (const [stroke, widthPx] of [["#000000", 7], [COLORS.boundary, 3.5]]) {
      context.strokeStyle = stroke;
      context.lineWidth = widthPx;
      context.lineCap = "round";
      context.beginPath();
      for (const [h1, v1, h2, v2] of segments) {
        context.moveTo(frame.x(kt(v1)), frame.y(ft(h1)));
        context.lineTo(frame.x(kt(v2)), frame.y(ft(h2)));
      }
      context.stroke();
    }
    context.fillStyle = COLORS.boundary;
    for (const [heightM, speedMs] of points) {
      context.beginPath();
      context.arc(frame.x(kt(speedMs)), frame.y(ft(heightM)), 3, 0, 2 * Math.PI);
      context.fill();
    }
  }

  function drawPlanPath(context, frame) {
    view.plan.pathPoints = 0;
    const path = planState() === "shown" && model.plan.path;
    if (!path || path.error || !path.speed_ms) return;
    const points = [];
    path.speed_ms.forEach((speed, index) => {
      const heightM = path.z_m[index];
      if (isNum(speed) && isNum(heightM)) points.push([frame.x(kt(speed)), frame.y(ft(Math.max(heightM, 0)))]);
    });
    if (points.length < 2) return;
    for (const [stroke, widthPx] of [["#000000", 7], [COLORS.plan, 4]]) {
      context.strokeStyle = stroke;
      context.lineWidth = widthPx;
      context.beginPath();
      points.forEach(([x, y], index) => (index ? context.lineTo(x, y) : context.moveTo(x, y)));
      context.stroke();
    }
    const [endX, endY] = points[points.length - 1];
    context.fillStyle = COLORS.plan;
    context.strokeStyle = "#000";
    context.lineWidth = 2;
    context.beginPath();
    context.rect(endX - 7, endY - 7, 14, 14);
    context.fill();
    context.stroke();
    context.fillStyle = COLORS.plan;
    context.font = 'bold 16px "DejaVu Sans", Arial, sans-serif';
    context.textAlign = "left";
    context.textBaseline = "bottom";
    context.fillText("TD", endX + 10, endY - 4);
    view.plan.pathPoints = points.length;
  }

  function drawAircraft(context, frame, xMax, yMax) {
    const clamp = (value, high) => Math.min(Math.max(value, 0), high);
    const onAxes = (point) => [frame.x(clamp(point.speedKt, xMax)), frame.y(clamp(point.heightFt, yMax))];
    // trail: older points fainter
    const trail = model.trail;
    for (let index = 1; index < trail.length; index += 1) {
      if (trail[index].broken) continue;
      const alpha = 0.15 + 0.85 * (index / trail.length);
      context.strokeStyle = `rgba(53, 208, 255, ${alpha.toFixed(3)})`;
      context.lineWidth = 4;
      context.beginPath();
      context.moveTo(...onAxes(trail[index - 1]));
      context.lineTo(...onAxes(trail[index]));
      context.stroke();
    }
    const state = model.live && model.live.state;
    if (!state || !isNum(state.height_m) || !isNum(state.speed_ms)) {
      view.marker = null;
      return;
    }
    const speedKt = kt(state.speed_ms);
    const heightFt = ft(state.height_m);
    const offScale = speedKt < 0 || speedKt > xMax || heightFt < 0 || heightFt > yMax;
    const [x, y] = onAxes({ speedKt, heightFt });
    const stale = state.stale || model.link !== "up";
    context.lineWidth = 3;
    context.strokeStyle = "#000";
    context.fillStyle = stale ? COLORS.stale : COLORS.aircraft;
    context.beginPath();
    context.arc(x, y, 11, 0, 2 * Math.PI);
    if (stale || offScale) {
      context.strokeStyle = stale ? COLORS.stale : COLORS.aircraft;
      context.stroke();
    } else {
      context.fill();
      context.stroke();
      context.strokeStyle = COLORS.trail;
      context.lineWidth = 3;
      context.beginPath();
      context.arc(x, y, 16, 0, 2 * Math.PI);
      context.stroke();
    }
    // crosshair ticks
    context.strokeStyle = stale ? COLORS.stale : COLORS.aircraft;
    context.lineWidth = 3;
    context.beginPath();
    for (const [dx, dy] of [[1, 0], [-1, 0], [0, 1], [0, -1]]) {
      context.moveTo(x + dx * 18, y + dy * 18);
      context.lineTo(x + dx * 28, y + dy * 28);
    }
    context.stroke();
    if (stale || offScale) {
      context.fillStyle = stale ? COLORS.stale : COLORS.aircraft;
      context.font = 'bold 16px "DejaVu Sans", Arial, sans-serif';
      context.textAlign = "left";
      context.textBaseline = "bottom";
      context.fillText(stale ? "STALE" : "OFF SCALE", x + 20, y - 18);
    }
    view.marker = { speedKt, heightFt, x, y, stale, offScale };
  }

  function drawRotor() {
    const { context, width, height } = prepareCanvas($("rotor-canvas"));
    const limits = model.config && model.config.rotor_limits;
    const rotor = model.live && model.live.rotor;
    const lowPct = 70;
    const highPct = 125;
    const left = 8;
    const right = width - 8;
    const x = (pct) => left + ((Math.min(Math.max(pct, lowPct), highPct) - lowPct) / (highPct - lowPct)) * (right - left);
    const barTop = 4;
    const barHeight = height - 24;
    context.fillStyle = limits ? COLORS.rotorBad : "#333a42";
    context.fillRect(left, barTop, right - left, barHeight);
    if (limits) {
      const minPct = (100 * limits.min_rad_s) / limits.nominal_rad_s;
      const maxPct = (100 * limits.max_rad_s) / limits.nominal_rad_s;
      const band = isNum(limits.caution_pct) ? limits.caution_pct : 0;
      context.fillStyle = COLORS.rotorCaution; // amber inside each red limit, green between
      context.fillRect(x(minPct), barTop, x(maxPct) - x(minPct), barHeight);
      context.fillStyle = COLORS.rotorBand;
      context.fillRect(x(minPct + band), barTop, x(maxPct - band) - x(minPct + band), barHeight);
    }
    context.fillStyle = COLORS.axis;
    context.font = 'bold 13px "DejaVu Sans", Arial, sans-serif';
    context.textAlign = "center";
    context.textBaseline = "top";
    for (let pct = 70; pct <= 125; pct += 10) context.fillText(String(pct), x(pct), barTop + barHeight + 3);
    if (rotor && isNum(rotor.speed_rad_s) && limits) {
      const pct = (100 * rotor.speed_rad_s) / limits.nominal_rad_s;
      const px = x(pct);
      context.fillStyle = rotor.stale ? COLORS.stale : "#ffffff";
      context.strokeStyle = "#000";
      context.lineWidth = 2;
      context.beginPath();
      context.moveTo(px - 9, barTop - 2);
      context.lineTo(px + 9, barTop - 2);
      context.lineTo(px, barTop + barHeight * 0.75);
      context.closePath();
      context.fill();
      context.stroke();
    }
  }

  function drawPlanCharts() {
    const canvas = $("plan-canvas");
    if (planState() !== "shown" || canvas.clientHeight < 20) return;
    const { context, width, height } = prepareCanvas(canvas);
    const trajectory = model.plan.trajectory;
    const times = trajectory.t_s;
    const lastTime = times.filter(isNum).reduce((a, b) => Math.max(a, b), 0) || 1;
    const clock = model.live && model.live.plan_clock;
    const elapsed = clock && isNum(clock.elapsed_s) ? clock.elapsed_s : null;
    const compact = height < 170; // small screens: tighter rows, no axis title
    const gap = compact ? 24 : 34;
    const top0 = compact ? 17 : 20;
    const bottomReserve = compact ? 20 : 40; // time tick labels (and the axis title)
    const rowHeight = Math.max((height - top0 - gap - bottomReserve) / 2, 10);
    const rows = [
      {
        values: trajectory.collective.map((c) => thrustPct(c).pct),
        label: "THRUST, % OF WEIGHT (estimate)",
        color: COLORS.collective,
      },
      {
        values: trajectory.pitch_rad.map((p) => (isNum(p) ? (-p * 180) / Math.PI : null)), // −θ: nose up positive
        label: "PITCH ATTITUDE, \u00b0 NOSE UP",
        color: COLORS.pitch,
      },
    ];
    rows.forEach((row, index) => {
      const top = top0 + index * (rowHeight + gap);
      const values = row.values.map((v) => (isNum(v) ? v : null));
      const finite = values.filter(isNum);
      let low = Math.min(0, ...finite);
      let high = Math.max(...finite, low + 1e-6);
      const pad = 0.08 * (high - low);
      low -= low < 0 ? pad : 0;
      high += pad;
      const frame = makeFrame(54, top, width - 10, top + rowHeight, 0, lastTime, low, high);
      context.fillStyle = row.color;
      context.font = 'bold 14px "DejaVu Sans", Arial, sans-serif';
      context.textAlign = "left";
      context.textBaseline = "bottom";
      context.fillText(row.label, frame.left, top - 3);
      const yStep = niceStep(high - low, compact ? 1.5 : 3);
      context.strokeStyle = COLORS.grid;
      context.fillStyle = COLORS.axis;
      context.font = '13px "DejaVu Sans", Arial, sans-serif';
      context.textAlign = "right";
      context.textBaseline = "middle";
      for (let y = Math.ceil(low / yStep) * yStep; y <= high; y += yStep) {
        context.beginPath();
        context.moveTo(frame.left, frame.y(y));
        context.lineTo(frame.right, frame.y(y));
        context.stroke();
        context.fillText(Math.abs(y) < 1e-12 ? "0" : Number(y.toPrecision(3)).toString(), frame.left - 6, frame.y(y));
      }
      context.strokeStyle = COLORS.axis;
      context.lineWidth = 1.5;
      context.strokeRect(frame.left, frame.top, frame.right - frame.left, frame.bottom - frame.top);
      context.strokeStyle = row.color;
      context.lineWidth = 3;
      context.beginPath();
      let started = false;
      values.forEach((value, i) => {
        if (!isNum(value) || !isNum(times[i])) {
          started = false;
          return;
        }
        if (started) context.lineTo(frame.x(times[i]), frame.y(value));
        else context.moveTo(frame.x(times[i]), frame.y(value));
        started = true;
      });
      context.stroke();
      if (elapsed !== null && elapsed >= 0 && elapsed <= lastTime) {
        context.strokeStyle = COLORS.plan;
        context.lineWidth = 2;
        context.beginPath();
        context.moveTo(frame.x(elapsed), frame.top);
        context.lineTo(frame.x(elapsed), frame.bottom);
        context.stroke();
      }
      if (index === rows.length - 1) {
        context.fillStyle = COLORS.axis;
        context.textAlign = "center";
        context.textBaseline = "top";
        const tStep = niceStep(lastTime, 6);
        for (let t = 0; t <= lastTime + 1e-9; t += tStep) context.fillText(String(Number(t.toFixed(3))), frame.x(t), frame.bottom + 4);
        context.font = 'bold 13px "DejaVu Sans", Arial, sans-serif';
        if (!compact) context.fillText("TIME SINCE PLAN START (s)", (frame.left + frame.right) / 2, frame.bottom + 21);
      }
    });
  }

  // What the side view's ground line shows (the server's live.footprint and live.site, SI along-track metres):
  // the reachable footprint between its verified ends ("if the engine failed now": not once it has failed), and the
  // selected landing site (after the failure: the plan's). Never optimistic: an unverified end is no end; an old footprint (server: not current) or
  // a stale page draws no band; a site is green only for a current verdict that lands on it, on a page that is live.
  function groundLine() {
    const live = model.live;
    const phase = view.phase === "stale" ? model.lastPhase : view.phase;
    const failed = phase === "autorotation" || phase === "landed";
    const pageStale = view.phase === "stale" || model.link !== "up";
    const raw = live && live.footprint && !live.footprint.off && !failed ? live.footprint : null;
    let footprint = null;
    if (raw) {
      const verified = (end) => raw[`${end}_verified`] === true && isNum(raw[`${end}_distance_m`]);
      const near = verified("nearest") ? raw.nearest_distance_m : null;
      const far = verified("farthest") ? raw.farthest_distance_m : null;
      const ahead = (end, along) => (isNum(raw[`${end}_m`]) ? raw[`${end}_m`] : along - (isNum(raw.distance_m) ? raw.distance_m : NaN));
      let drawn = null;
      let text;
      if (pageStale) {
        text = "FOOTPRINT NOT SHOWN: DATA STALE";
      } else if (!raw.current) {
        text = `FOOTPRINT STALE (${isNum(raw.age_s) ? `${fmt(raw.age_s, 1)} s OLD` : "NO STAMP"})`;
      } else if (isNum(near) && isNum(far)) {
        drawn = "band";
        text = `FOOTPRINT ${fmt(ft(ahead("nearest", near)))}\u2013${fmt(ft(ahead("farthest", far)))} ft AHEAD`;
      } else if (isNum(near)) {
        drawn = "nearest";
        text = `FOOTPRINT NEAREST ${fmt(ft(ahead("nearest", near)))} ft AHEAD \u00b7 FARTHEST UNKNOWN`;
      } else if (isNum(far)) {
        drawn = "farthest";
        text = `FOOTPRINT FARTHEST ${fmt(ft(ahead("farthest", far)))} ft AHEAD \u00b7 NEAREST UNKNOWN`;
      } else {
        text = "FOOTPRINT UNKNOWN (NO END VERIFIED)";
      }
      if (drawn && isNum(raw.sites_in_footprint)) {
        text += ` \u00b7 ${fmt(raw.sites_in_footprint)} SITE${raw.sites_in_footprint === 1 ? "" : "S"} IN FOOTPRINT`;
      }
      footprint = {
        drawn,
        kind: drawn ? "reachable" : raw.current && !pageStale ? "unknown" : "stale",
        text,
        nearFt: drawn && drawn !== "farthest" ? ft(near) : null,
        farFt: drawn && drawn !== "nearest" ? ft(far) : null,
      };
    }
    let site = null;
    const rawSite = live && live.site;
    // after the failure only the plan's site (landed: nothing; the plan no longer applies)
    const siteApplies = rawSite && (!failed || (phase === "autorotation" && rawSite.source === "plan"));
    if (siteApplies && isNum(rawSite.start_m) && isNum(rawSite.end_m)) {
      // never green on a stale page (as the plan badge)
      const kind = pageStale && rawSite.kind === "reachable" ? "stale" : rawSite.kind || "unknown";
      let words = rawSite.words || "REACHABILITY UNKNOWN";
      if (rawSite.source === "plan" && rawSite.on_site === true && isNum(rawSite.margin_m)) {
        words += ` \u00b7 TD ${fmt(Math.abs(ft(rawSite.margin_m)))} ft ${rawSite.margin_m >= 0 ? "INSIDE" : "OUTSIDE"}`;
      }
      const name = String(rawSite.name || "").toUpperCase();
      site = {
        name,
        kind,
        source: rawSite.source,
        label: `${name ? `SITE ${name}` : "SITE"} \u00b7 ${words}`,
        startFt: ft(rawSite.start_m),
        endFt: ft(rawSite.end_m),
        inFootprint: rawSite.in_footprint || null,
      };
    }
    return { show: Boolean(footprint || site), drawable: Boolean((footprint && footprint.drawn) || site), footprint, site };
  }

  // The ground line's marks: the footprint band (one verified end: a mark at that end only) and the site interval;
  // returns what was drawn (for window.helireach.ground) and draws the labels later (above the path: drawGroundLabels).
  function drawGround(context, frame, ground) {
    const groundY = frame.y(0);
    const shown = { footprint: null, site: null };
    const labels = [];
    const footprint = ground.footprint;
    if (footprint && footprint.drawn) {
      context.fillStyle = COLORS.footprintBand;
      context.strokeStyle = COLORS.footprint;
      context.lineWidth = 3;
      const ends = [footprint.nearFt, footprint.farFt].filter(isNum).map((x) => frame.x(x));
      if (footprint.drawn === "band") context.fillRect(Math.min(...ends), groundY - 10, Math.max(Math.abs(ends[1] - ends[0]), 2), 10);
      context.beginPath();
      for (const x of ends) {
        context.moveTo(x, groundY + 2);
        context.lineTo(x, groundY - 16);
      }
      context.stroke();
      if (footprint.drawn !== "band") {
        const words = footprint.drawn === "nearest" ? "NEAREST TD \u00b7 FARTHEST ?" : "FARTHEST TD \u00b7 NEAREST ?";
        labels.push({ text: words, x: ends[0], y: groundY - 18, color: COLORS.footprint, font: 'bold 12px "DejaVu Sans", Arial, sans-serif' });
      }
      shown.footprint = { drawn: footprint.drawn, nearFt: footprint.nearFt, farFt: footprint.farFt };
    }
    const site = ground.site;
    if (site) {
      const color = SITE_COLORS[site.kind] || COLORS.stale;
      const x0 = frame.x(site.startFt);
      const x1 = frame.x(site.endFt);
      const top = groundY - 28;
      for (const [stroke, widthPx] of [["#000000", 6], [color, 3]]) {
        context.strokeStyle = stroke;
        context.lineWidth = widthPx;
        context.beginPath();
        context.moveTo(x0, groundY + 2);
        context.lineTo(x0, top);
        context.lineTo(x1, top);
        context.lineTo(x1, groundY + 2);
        context.stroke();
      }
      labels.push({ text: site.label, x: (x0 + x1) / 2, y: top - 3, color, font: 'bold 13px "DejaVu Sans", Arial, sans-serif' });
      shown.site = { name: site.name, kind: site.kind, label: site.label, startFt: site.startFt, endFt: site.endFt, source: site.source, inFootprint: site.inFootprint };
    }
    return { shown, labels };
  }

  // Labels centred over their mark, kept inside the frame, on a dark backing so that the path cannot hide them.
  function drawGroundLabels(context, frame, labels) {
    for (const label of labels) {
      context.font = label.font;
      const half = context.measureText(label.text).width / 2;
      const x = Math.min(Math.max(label.x, frame.left + half + 2), frame.right - half - 2);
      context.fillStyle = "rgba(12, 17, 23, 0.8)";
      context.fillRect(x - half - 3, label.y - 15, 2 * half + 6, 16);
      context.fillStyle = label.color;
      context.textAlign = "center";
      context.textBaseline = "bottom";
      context.fillText(label.text, x, label.y);
    }
  }

  // Side view: height against distance along the track, the planned path (magenta), the touchdown point (TD)
  // and the aircraft; the distance to the touchdown point is the path's last x minus the aircraft's x. On its ground
  // line the reachable footprint and the landing site (groundLine); without a plan, only those and the aircraft.
  function drawSideView() {
    const canvas = $("side-canvas");
    const planShown = planState() === "shown";
    const path = planShown && model.plan.path && !model.plan.path.error ? model.plan.path : null;
    const ground = groundLine();
    view.side = null;
    const footprintText = ground.footprint ? ground.footprint.text : "";
    const received = model.live && model.live.footprint ? model.live.footprint.status : null;
    view.ground = { footprint: null, site: null, text: footprintText, received };
    const footprintLine = $("side-footprint");
    footprintLine.textContent = footprintText;
    footprintLine.hidden = !ground.footprint;
    setData(footprintLine, "kind", ground.footprint ? ground.footprint.kind : "none");
    $("side-title").textContent = planShown ? "SIDE VIEW \u00b7 PLANNED PATH" : "SIDE VIEW \u00b7 LANDING AREA";
    $("side-distance").hidden = !planShown;
    $("side-distance").textContent = "TO TOUCHDOWN ---";
    if (canvas.clientHeight < 20) return;
    const { context, width, height } = prepareCanvas(canvas); // cleared: nothing old stays drawn
    if (!path && !ground.drawable) return;
    const points = [];
    if (path) {
      path.x_m.forEach((x, i) => {
        if (isNum(x) && isNum(path.z_m[i])) points.push([ft(x), ft(Math.max(path.z_m[i], 0))]);
      });
      if (points.length < 2) return;
    }
    const state = model.live && model.live.state;
    const aircraft = state && isNum(state.distance_m) && isNum(state.height_m) ? [ft(state.distance_m), ft(Math.max(state.height_m, 0))] : null;
    const groundXs = [];
    if (ground.footprint && ground.footprint.drawn) groundXs.push(...[ground.footprint.nearFt, ground.footprint.farFt].filter(isNum));
    if (ground.site) groundXs.push(ground.site.startFt, ground.site.endFt);
    const xs = points.map((p) => p[0]).concat(aircraft ? [aircraft[0]] : [], groundXs);
    const ys = points.map((p) => p[1]).concat(aircraft ? [aircraft[1]] : []);
    let xMin = Math.min(...xs);
    let xMax = Math.max(...xs, xMin + 1);
    if (groundXs.length) {
      // room for the marks at the ends and the labels
      const pad = Math.max(0.04 * (xMax - xMin), 50);
      xMin -= pad;
      xMax += pad;
    }
    const yMax = Math.max(...ys, 10) * 1.1;
    const fontPx = 13;
    const frame = makeFrame(62, 8, width - 14, height - 36, xMin, xMax, 0, yMax);
    context.fillStyle = COLORS.ground;
    context.fillRect(frame.left, frame.y(0), frame.right - frame.left, 4);
    context.strokeStyle = COLORS.grid;
    context.fillStyle = COLORS.axis;
    context.font = `${fontPx}px "DejaVu Sans", Arial, sans-serif`;
    context.textAlign = "right";
    context.textBaseline = "middle";
    const yStep = niceStep(yMax, 3);
    for (let y = 0; y <= yMax; y += yStep) {
      context.beginPath();
      context.moveTo(frame.left, frame.y(y));
      context.lineTo(frame.right, frame.y(y));
      context.stroke();
      context.fillText(String(Number(y.toFixed(0))), frame.left - 6, frame.y(y));
    }
    context.textAlign = "center";
    context.textBaseline = "top";
    const xStep = niceStep(xMax - xMin, 6);
    for (let x = Math.ceil(xMin / xStep) * xStep; x <= xMax; x += xStep) context.fillText(String(Number(x.toFixed(0))), frame.x(x), frame.bottom + 6);
    context.fillText("DISTANCE (ft) \u00b7 HEIGHT (ft)", (frame.left + frame.right) / 2, frame.bottom + 20);
    const { shown: shownGround, labels } = drawGround(context, frame, ground);
    view.ground = { ...view.ground, ...shownGround };
    if (!path) {
      drawSideAircraft(context, frame, state, aircraft);
      drawGroundLabels(context, frame, labels);
      return;
    }
    context.strokeStyle = COLORS.plan;
    context.lineWidth = 3;
    context.beginPath();
    points.forEach(([x, y], i) => (i ? context.lineTo(frame.x(x), frame.y(y)) : context.moveTo(frame.x(x), frame.y(y))));
    context.stroke();
    const [tdX, tdY] = points[points.length - 1];
    context.fillStyle = COLORS.plan;
    context.fillRect(frame.x(tdX) - 6, frame.y(tdY) - 6, 12, 12);
    context.font = 'bold 15px "DejaVu Sans", Arial, sans-serif';
    context.textAlign = "right";
    context.textBaseline = "bottom";
    context.fillText("TD", frame.x(tdX) - 8, frame.y(tdY) - 6);
    let distanceText = "TO TOUCHDOWN ---";
    if (aircraft) {
      drawSideAircraft(context, frame, state, aircraft);
      const toGo = tdX - aircraft[0];
      distanceText = `TO TOUCHDOWN ${fmt(Math.abs(toGo))} ft ${toGo >= 0 ? "AHEAD" : "BEHIND"}`;
    }
    drawGroundLabels(context, frame, labels);
    $("side-distance").textContent = distanceText;
    view.side = { points: points.length, distance: distanceText };
  }

  function drawSideAircraft(context, frame, state, aircraft) {
    if (!aircraft) return;
    const stale = state.stale || model.link !== "up";
    context.fillStyle = stale ? COLORS.stale : COLORS.aircraft;
    context.strokeStyle = "#000";
    context.lineWidth = 2;
    context.beginPath();
    context.arc(frame.x(aircraft[0]), frame.y(aircraft[1]), 8, 0, 2 * Math.PI);
    context.fill();
    context.stroke();
  }

  // The banner also depends on time (a quiet link), so re-evaluate it even without frames.
  setInterval(() => {
    updateDom();
    requestDraw();
  }, 250);
  window.addEventListener("resize", requestDraw);
  connect();
  updateDom();
})();
