// The any4d clip viewer (eval/src/view.rs): WebGL, no library. Panels share one orbit camera and one clock.
"use strict";
(function () {
  const body = document.body;
  const setStatus = (s) => { body.dataset.status = s; };
  window.addEventListener("error", (e) => setStatus("error: " + e.message));

  const data = JSON.parse(document.getElementById("data").textContent);
  const decode = (b64, Type) => {
    const bin = atob(b64);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return new Type(bytes.buffer);
  };
  document.getElementById("title").textContent = data.title;
  document.getElementById("caption").textContent = data.caption ? "“" + data.caption + "”" : "(no caption)";

  // Camera: orbit around the first panel's frame-0 bounding box.
  const first = decode(data.panels[0].positions, Float32Array);
  const n0 = data.panels[0].vertices;
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let v = 0; v < n0; v++) for (let k = 0; k < 3; k++) {
    lo[k] = Math.min(lo[k], first[3 * v + k]); hi[k] = Math.max(hi[k], first[3 * v + k]);
  }
  const center = [0, 1, 2].map((k) => (lo[k] + hi[k]) / 2);
  const radius = Math.max(1e-6, Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2);
  const cam = { yaw: 0.6, pitch: 0.35, dist: 2.6 * radius };

  const perspective = (fovy, aspect, near, far) => {
    const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
  };
  const lookAt = (eye, at, up) => {
    const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    const norm = (a) => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
    return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
  };
  const mul = (a, b) => {
    const o = new Array(16).fill(0);
    for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) for (let k = 0; k < 4; k++) o[c * 4 + r] += a[k * 4 + r] * b[c * 4 + k];
    return o;
  };

  const VS = "attribute vec3 p; attribute vec3 nrm; attribute float err; uniform mat4 mvp; uniform float scale;" +
    "varying vec3 vn; varying float ve; void main(){ gl_Position = mvp * vec4(p, 1.0); vn = nrm; ve = err / scale; }";
  // `base`: the uncoloured mesh's colour (the scene's darker grey, docs/method.md §6.5).
  const FS = "precision mediump float; varying vec3 vn; varying float ve; uniform float colored; uniform vec3 light;" +
    "uniform vec3 base; void main(){ float l = length(vn) > 0.0 ? 0.35 + 0.65 * abs(dot(normalize(vn), light)) : 0.7;" +
    " float t = clamp(ve, 0.0, 1.0); vec3 heat = mix(mix(vec3(0.2,0.4,0.9), vec3(0.95,0.85,0.2), min(t*2.0,1.0))," +
    " vec3(0.85,0.1,0.1), max(t*2.0-1.0,0.0)); vec3 c = mix(base, heat, colored);" +
    " gl_FragColor = vec4(c * l, 1.0); }";
  const CLIP_GREY = [0.72, 0.74, 0.78], SCENE_GREY = [0.5, 0.5, 0.5];
  const scene = data.scene ? {
    positions: decode(data.scene.positions, Float32Array), faces: decode(data.scene.faces, Uint32Array),
  } : null;

  const main = document.getElementById("panels");
  const width = Math.max(240, Math.min(420, Math.floor((window.innerWidth - 48) / Math.min(data.panels.length, 4)) - 12));
  const panels = [];
  let webgl = true;
  for (const pd of data.panels) {
    const div = document.createElement("div");
    div.className = "panel";
    const h = document.createElement("h2");
    h.textContent = pd.label;
    const canvas = document.createElement("canvas");
    canvas.width = width; canvas.height = width;
    div.append(h, canvas);
    if (pd.metrics.length) {
      const table = document.createElement("table");
      for (const [k, v] of pd.metrics) {
        const tr = table.insertRow();
        tr.insertCell().textContent = k; tr.insertCell().textContent = v;
      }
      div.append(table);
    }
    main.append(div);
    const gl = canvas.getContext("webgl", { antialias: true });
    if (!gl) { webgl = false; continue; }
    const uint = gl.getExtension("OES_element_index_uint");
    const compile = (type, src) => {
      const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      return s;
    };
    const prog = gl.createProgram();
    gl.attachShader(prog, compile(gl.VERTEX_SHADER, VS)); gl.attachShader(prog, compile(gl.FRAGMENT_SHADER, FS));
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
    const faces = decode(pd.faces, Uint32Array);
    if (!uint && pd.vertices > 65535) throw new Error("this browser cannot index more than 65535 vertices");
    const index = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, index);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, uint ? faces : new Uint16Array(faces), gl.STATIC_DRAW);
    let sceneIndex = null;
    if (scene) {
      if (!uint && scene.positions.length / 3 > 65535) throw new Error("this browser cannot index the scene's vertices");
      sceneIndex = gl.createBuffer();
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, sceneIndex);
      gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, uint ? scene.faces : new Uint16Array(scene.faces), gl.STATIC_DRAW);
    }
    panels.push({
      pd, gl, prog, canvas, faces, index, uintIndex: !!uint, sceneIndex,
      positions: decode(pd.positions, Float32Array),
      errors: pd.errors ? decode(pd.errors, Float32Array) : null,
      buffers: { p: gl.createBuffer(), n: gl.createBuffer(), e: gl.createBuffer() },
    });
  }
  if (!webgl) {
    main.insertAdjacentHTML("afterbegin", "<p><b>This browser has no WebGL: the clips cannot be drawn.</b></p>");
    setStatus("no-webgl");
    return;
  }

  // Smooth vertex normals of one frame (area-weighted face normals).
  const normals = (pos, faces, n, f) => {
    const out = new Float32Array(3 * n), o = 3 * n * f;
    for (let t = 0; t < faces.length; t += 3) {
      const a = o + 3 * faces[t], b = o + 3 * faces[t + 1], c = o + 3 * faces[t + 2];
      const ux = pos[b] - pos[a], uy = pos[b + 1] - pos[a + 1], uz = pos[b + 2] - pos[a + 2];
      const vx = pos[c] - pos[a], vy = pos[c + 1] - pos[a + 1], vz = pos[c + 2] - pos[a + 2];
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      for (const i of [faces[t], faces[t + 1], faces[t + 2]]) { out[3 * i] += nx; out[3 * i + 1] += ny; out[3 * i + 2] += nz; }
    }
    return out;
  };

  const draw = (frame) => {
    const eye = [
      center[0] + cam.dist * Math.cos(cam.pitch) * Math.sin(cam.yaw),
      center[1] + cam.dist * Math.sin(cam.pitch),
      center[2] + cam.dist * Math.cos(cam.pitch) * Math.cos(cam.yaw),
    ];
    const mvp = mul(perspective(0.8, 1, cam.dist * 0.02, cam.dist * 10), lookAt(eye, center, [0, 1, 0]));
    for (const p of panels) {
      const { gl, prog, pd } = p, n = pd.vertices;
      gl.viewport(0, 0, p.canvas.width, p.canvas.height);
      gl.clearColor(1, 1, 1, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT); gl.enable(gl.DEPTH_TEST);
      gl.useProgram(prog);
      const attr = (name, buf, values, size) => {
        const loc = gl.getAttribLocation(prog, name);
        gl.bindBuffer(gl.ARRAY_BUFFER, buf); gl.bufferData(gl.ARRAY_BUFFER, values, gl.DYNAMIC_DRAW);
        gl.enableVertexAttribArray(loc); gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0);
      };
      gl.uniformMatrix4fv(gl.getUniformLocation(prog, "mvp"), false, new Float32Array(mvp));
      gl.uniform1f(gl.getUniformLocation(prog, "scale"), Math.max(data.error_scale, 1e-12));
      gl.uniform3f(gl.getUniformLocation(prog, "light"), 0.3, 0.8, 0.52);
      if (scene) {
        const m = scene.positions.length / 3;
        attr("p", p.buffers.p, scene.positions, 3);
        attr("nrm", p.buffers.n, normals(scene.positions, scene.faces, m, 0), 3);
        attr("err", p.buffers.e, new Float32Array(m), 1);
        gl.uniform1f(gl.getUniformLocation(prog, "colored"), 0);
        gl.uniform3fv(gl.getUniformLocation(prog, "base"), SCENE_GREY);
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, p.sceneIndex);
        gl.drawElements(gl.TRIANGLES, scene.faces.length, p.uintIndex ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT, 0);
      }
      attr("p", p.buffers.p, p.positions.subarray(3 * n * frame, 3 * n * (frame + 1)), 3);
      attr("nrm", p.buffers.n, normals(p.positions, p.faces, n, frame), 3);
      attr("err", p.buffers.e, p.errors ? p.errors.subarray(n * frame, n * (frame + 1)) : new Float32Array(n), 1);
      gl.uniform1f(gl.getUniformLocation(prog, "colored"), p.errors ? 1 : 0);
      gl.uniform3fv(gl.getUniformLocation(prog, "base"), CLIP_GREY);
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, p.index);
      gl.drawElements(gl.TRIANGLES, p.faces.length, p.uintIndex ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT, 0);
    }
  };

  // Timeline: slider, keyframe marks, frame label, play/pause.
  const slider = document.getElementById("slider"), label = document.getElementById("frame");
  const play = document.getElementById("play");
  slider.max = String(data.frames - 1);
  const marks = document.getElementById("marks");
  for (const k of data.keyframes) {
    const m = document.createElement("div");
    m.className = "mark"; m.title = "keyframe " + k;
    m.style.left = (data.frames > 1 ? (100 * k) / (data.frames - 1) : 0) + "%";
    marks.append(m);
  }
  if (data.ground_truth && data.panels.some((p) => p.errors)) {
    document.getElementById("legend").textContent =
      "colour: distance to " + data.panels[0].label + ", blue 0 → red ≥ " + data.error_scale.toPrecision(3);
  }
  let frame = 0, playing = true, last = performance.now(), acc = 0;
  const show = (f) => {
    frame = f; slider.value = String(f);
    label.textContent = "frame " + f + " / " + (data.frames - 1) + (data.keyframes.includes(f) ? " (keyframe)" : "");
    draw(f);
  };
  slider.addEventListener("input", () => { playing = false; play.textContent = "Play"; show(Number(slider.value)); });
  play.addEventListener("click", () => { playing = !playing; play.textContent = playing ? "Pause" : "Play"; });
  const tick = (now) => {
    acc += now - last; last = now;
    if (playing && acc >= 1000 / data.fps) { acc = 0; show((frame + 1) % data.frames); }
    requestAnimationFrame(tick);
  };

  // Orbit: drag on any panel rotates every panel; the wheel zooms.
  let drag = null;
  for (const p of panels) {
    p.canvas.addEventListener("mousedown", (e) => { e.preventDefault(); drag = [e.clientX, e.clientY]; });
    p.canvas.addEventListener("wheel", (e) => {
      e.preventDefault(); cam.dist *= Math.exp(e.deltaY * 0.001); draw(frame);
    }, { passive: false });
  }
  window.addEventListener("mouseup", () => { drag = null; });
  window.addEventListener("mousemove", (e) => {
    if (!drag) return;
    cam.yaw -= (e.clientX - drag[0]) * 0.01;
    cam.pitch = Math.max(-1.5, Math.min(1.5, cam.pitch + (e.clientY - drag[1]) * 0.01));
    drag = [e.clientX, e.clientY];
    draw(frame);
  });

  show(0);
  setStatus("ready");
  requestAnimationFrame(tick);

  // `#selftest` (the browser test): with playback paused, moving the slider must change the frame and the pixels.
  if (location.hash === "#selftest") {
    playing = false;
    const canvas = panels[panels.length - 1].canvas;
    show(0);
    const before = canvas.toDataURL();
    const target = Math.floor((data.frames - 1) / 2) || 1;
    slider.value = String(target);
    slider.dispatchEvent(new Event("input"));
    const after = canvas.toDataURL();
    const problems = [];
    if (frame !== target) problems.push("the slider left the frame at " + frame);
    if (!label.textContent.startsWith("frame " + target + " ")) problems.push("label says " + label.textContent);
    if (before === after) problems.push("frames 0 and " + target + " render the same pixels");
    body.dataset.selftest = problems.length ? "fail: " + problems.join("; ") : "pass";
  }
})();
