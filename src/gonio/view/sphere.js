// gonio view: spheres lit by a directional light, rendered in WebGL2 from the data itself.
// Each material is an isotropic half/diff table (gonio/view/encode.py) in a 3-D texture, looked
// up by gonio's rule (gonio/brdf/lookup.py): per axis a continuous node index in the warped
// coordinate, periodic axes wrapped, others clamped; multilinear (or nearest) over the valid
// nodes with the weights renormalized over them. Pixel = f(wi, wo) * E * max(cos theta_i, 0)
// with E = 1, the camera orthographic on +z, and the shading frame of gonio/render/scene.py.
"use strict";
(function () {
  const VS = `#version 300 es
in vec2 pos;
void main() { gl_Position = vec4(pos, 0.0, 1.0); }`;

  const FS = `#version 300 es
precision highp float;
precision highp int;
precision highp sampler3D;
precision highp usampler3D;
uniform sampler3D uVals;
uniform usampler3D uMask;
uniform bool uHasMask;
uniform bool uNearest;
uniform int uFold;
uniform float uScale;
uniform int uChannels;
uniform vec3 uLo, uHi, uOffset;
uniform ivec3 uSize;
uniform bvec3 uSqrt, uPeriodic;
uniform vec3 uLight;
uniform float uExposure;
uniform bool uLinear;
uniform vec2 uRes;
out vec4 outColor;
const float PI = 3.14159265358979;

float idx(float a, int k) {  // gonio Axis.continuous_index + wrap of periodic axes
  float x = (a - uLo[k]) / (uHi[k] - uLo[k]);
  if (uSqrt[k]) x = sqrt(max(x, 0.0));
  float n = float(uSize[k]);
  float t = x * n - uOffset[k];
  if (uPeriodic[k] && uSize[k] > 1) t = t - n * floor(t / n);
  return t;
}
// (i0, i1) and the weight of i1 along one axis (lookup._index_corners)
vec3 corners(float t, int k) {
  int n = uSize[k];
  if (n == 1) return vec3(0.0, 0.0, 0.0);
  if (uPeriodic[k]) {
    float f0 = floor(t);
    int i0 = int(f0);
    if (i0 >= n) i0 -= n;
    int i1 = i0 + 1 >= n ? 0 : i0 + 1;
    return vec3(float(i0), float(i1), t - f0);
  }
  t = clamp(t, 0.0, float(n - 1));
  int i0 = min(int(floor(t)), n - 2);
  return vec3(float(i0), float(i0 + 1), t - float(i0));
}
vec3 fetchv(ivec3 c) { vec4 v = texelFetch(uVals, c.zyx, 0); return uChannels == 1 ? v.rrr : v.rgb; }
float fetchm(ivec3 c) { return uHasMask ? float(texelFetch(uMask, c.zyx, 0).r) : 1.0; }

vec3 lookup(vec3 wi, vec3 wo) {
  // Rusinkiewicz angles as lookup._half_diff_fast computes them
  vec3 h = normalize(wi + wo);
  float r2 = h.x * h.x + h.y * h.y;
  bool pole = r2 <= 0.0;
  float r = sqrt(r2);
  float c = pole ? 1.0 : h.x / r, s = pole ? 0.0 : h.y / r;
  float x1 = c * wi.x + s * wi.y, y1 = -s * wi.x + c * wi.y;
  float dx = h.z * x1 - r * wi.z, dz = r * x1 + h.z * wi.z;
  float th = atan(r, h.z);
  float td = atan(sqrt(dx * dx + y1 * y1), dz);
  float pd = atan(y1, dx);
  if (pd < 0.0) pd += 2.0 * PI;
  if (uFold >= 1 && pd >= PI) pd -= PI;
  if (uFold >= 2) pd = min(pd, PI - pd);
  vec3 a = corners(idx(th, 0), 0), b = corners(idx(td, 1), 1), e = corners(idx(pd, 2), 2);
  vec3 num = vec3(0.0);
  float den = 0.0, best = -1.0;
  ivec3 bestc = ivec3(0);
  if (uNearest && !uHasMask) {
    ivec3 cn = ivec3(a.z >= 0.5 ? a.y : a.x, b.z >= 0.5 ? b.y : b.x, e.z >= 0.5 ? e.y : e.x);
    return fetchv(cn) * uScale;
  }
  for (int j = 0; j < 8; j++) {
    bool ba = (j & 4) != 0, bb = (j & 2) != 0, be = (j & 1) != 0;
    ivec3 cc = ivec3(ba ? a.y : a.x, bb ? b.y : b.x, be ? e.y : e.x);
    float w = (ba ? a.z : 1.0 - a.z) * (bb ? b.z : 1.0 - b.z) * (be ? e.z : 1.0 - e.z);
    float m = fetchm(cc);
    if (uNearest) {
      float score = w * m + m * 1e-6;
      if (score >= best) { best = score; bestc = cc; }
    } else {
      num += w * fetchv(cc);
      den += w * m;
    }
  }
  if (uNearest) return best > 0.0 ? fetchv(bestc) * uScale : vec3(0.0);
  if (!uHasMask) return num * uScale;
  return den > 0.0 ? num / den * uScale : vec3(0.0);
}

float srgb(float v) { return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055; }

void main() {
  vec2 p = gl_FragCoord.xy / uRes * 2.0 - 1.0;
  float r2 = dot(p, p);
  vec3 L = vec3(0.0);
  if (r2 < 1.0) {
    vec3 n = vec3(p, sqrt(1.0 - r2));
    float tn = sqrt(n.z * n.z + n.x * n.x);
    vec3 t = tn <= 1e-12 ? vec3(1.0, 0.0, 0.0) : vec3(n.z / tn, 0.0, -n.x / tn);
    vec3 bt = cross(n, t);
    vec3 wo = vec3(t.z, bt.z, n.z);
    vec3 Lw = normalize(uLight);
    vec3 wi = vec3(dot(Lw, t), dot(Lw, bt), dot(Lw, n));
    if (wi.z > 0.0 && wo.z > 1e-6) L = lookup(wi, wo) * wi.z;
  }
  if (uLinear) { outColor = vec4(L, r2 < 1.0 ? 1.0 : 0.0); return; }
  vec3 v = L * exp2(uExposure);
  outColor = vec4(srgb(clamp(v.r, 0.0, 1.0)), srgb(clamp(v.g, 0.0, 1.0)),
                  srgb(clamp(v.b, 0.0, 1.0)), 1.0);
}`;

  function b64bytes(s) {
    const bin = atob(s);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }
  async function inflate(s) {
    const stream = new Blob([b64bytes(s)]).stream().pipeThrough(new DecompressionStream("gzip"));
    return new Uint8Array(await new Response(stream).arrayBuffer());
  }

  class Sphere {
    constructor(canvas, table) {
      this.canvas = canvas;
      this.table = table;
      const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false });
      if (!gl) throw new Error("no WebGL2");
      this.gl = gl;
      const prog = gl.createProgram();
      for (const [kind, src] of [[gl.VERTEX_SHADER, VS], [gl.FRAGMENT_SHADER, FS]]) {
        const sh = gl.createShader(kind);
        gl.shaderSource(sh, src);
        gl.compileShader(sh);
        if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(sh));
        gl.attachShader(prog, sh);
      }
      gl.linkProgram(prog);
      if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
      this.prog = prog;
      gl.useProgram(prog);
      const buf = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, buf);
      gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 3, -1, -1, 3]), gl.STATIC_DRAW);
      const loc = gl.getAttribLocation(prog, "pos");
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, 2, gl.FLOAT, false, 0, 0);
      this.u = (name) => gl.getUniformLocation(prog, name);
    }
    async load() {
      const gl = this.gl, t = this.table;
      const [nth, ntd, npd] = t.shape;
      const vals = new Uint16Array((await inflate(t.values)).buffer);
      gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
      gl.activeTexture(gl.TEXTURE0);
      const tv = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_3D, tv);
      for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_3D, p, gl.NEAREST);
      const rgb = t.channels === 3;
      gl.texImage3D(gl.TEXTURE_3D, 0, rgb ? gl.RGB16F : gl.R16F, npd, ntd, nth, 0,
                    rgb ? gl.RGB : gl.RED, gl.HALF_FLOAT, vals);
      gl.activeTexture(gl.TEXTURE1);
      const tm = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_3D, tm);
      for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_3D, p, gl.NEAREST);
      if (t.mask) {
        const m = await inflate(t.mask);
        gl.texImage3D(gl.TEXTURE_3D, 0, gl.R8UI, npd, ntd, nth, 0, gl.RED_INTEGER, gl.UNSIGNED_BYTE, m);
      } else {
        gl.texImage3D(gl.TEXTURE_3D, 0, gl.R8UI, 1, 1, 1, 0, gl.RED_INTEGER, gl.UNSIGNED_BYTE, new Uint8Array([1]));
      }
      const u = this.u, ax = t.axes;
      gl.uniform1i(u("uVals"), 0);
      gl.uniform1i(u("uMask"), 1);
      gl.uniform1i(u("uHasMask"), t.mask ? 1 : 0);
      gl.uniform1i(u("uNearest"), t.nearest ? 1 : 0);
      gl.uniform1i(u("uFold"), t.fold);
      gl.uniform1f(u("uScale"), t.scale);
      gl.uniform1i(u("uChannels"), t.channels);
      gl.uniform3f(u("uLo"), ax[0].lo, ax[1].lo, ax[2].lo);
      gl.uniform3f(u("uHi"), ax[0].hi, ax[1].hi, ax[2].hi);
      gl.uniform3f(u("uOffset"), ax[0].node_offset, ax[1].node_offset, ax[2].node_offset);
      gl.uniform3i(u("uSize"), ax[0].size, ax[1].size, ax[2].size);
      gl.uniform3i(u("uSqrt"), ...ax.map((a) => (a.warp === "sqrt" ? 1 : 0)));
      gl.uniform3i(u("uPeriodic"), ...ax.map((a) => (a.periodic ? 1 : 0)));
    }
    draw(light, exposure, linear) {
      const gl = this.gl;
      gl.useProgram(this.prog);
      gl.uniform3f(this.u("uLight"), light[0], light[1], light[2]);
      gl.uniform1f(this.u("uExposure"), exposure);
      gl.uniform1i(this.u("uLinear"), linear ? 1 : 0);
      gl.uniform2f(this.u("uRes"), this.w || this.canvas.width, this.h || this.canvas.height);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    }
    // Linear radiance (H, W, 4) float32, rows top first, rendered off screen at size x size.
    readLinear(light, size) {
      const gl = this.gl;
      if (!gl.getExtension("EXT_color_buffer_float")) throw new Error("no float render targets");
      const fb = gl.createFramebuffer(), rb = gl.createRenderbuffer();
      gl.bindRenderbuffer(gl.RENDERBUFFER, rb);
      gl.renderbufferStorage(gl.RENDERBUFFER, gl.RGBA32F, size, size);
      gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
      gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.RENDERBUFFER, rb);
      gl.viewport(0, 0, size, size);
      this.w = size; this.h = size;
      this.draw(light, 0, true);
      const px = new Float32Array(size * size * 4);
      gl.readPixels(0, 0, size, size, gl.RGBA, gl.FLOAT, px);
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      gl.deleteFramebuffer(fb);
      gl.deleteRenderbuffer(rb);
      this.w = 0; this.h = 0;
      gl.viewport(0, 0, this.canvas.width, this.canvas.height);
      const out = new Float32Array(size * size * 4);  // flip: readPixels starts at the bottom
      for (let y = 0; y < size; y++) out.set(px.subarray((size - 1 - y) * size * 4, (size - y) * size * 4), y * size * 4);
      return out;
    }
  }

  // The page: spheres side by side, one light direction and one exposure for all.
  const state = { light: [0, 0, 1], exposure: 0, spheres: [] };
  function fromAngles(thetaDeg, phiDeg) {
    const t = (thetaDeg * Math.PI) / 180, p = (phiDeg * Math.PI) / 180;
    return [Math.sin(t) * Math.cos(p), Math.sin(t) * Math.sin(p), Math.cos(t)];
  }
  function redraw() { for (const s of state.spheres) s.draw(state.light, state.exposure, false); }
  function setLight(v) {
    const n = Math.hypot(v[0], v[1], v[2]);
    state.light = [v[0] / n, v[1] / n, v[2] / n];
    const th = (Math.acos(Math.min(1, state.light[2])) * 180) / Math.PI;
    const ph = (Math.atan2(state.light[1], state.light[0]) * 180) / Math.PI;
    const ti = document.getElementById("light-theta"), pi = document.getElementById("light-phi");
    if (ti) ti.value = th.toFixed(1);
    if (pi) pi.value = ph.toFixed(1);
    const lab = document.getElementById("light-label");
    if (lab) lab.textContent = `light: θ = ${th.toFixed(1)}°, φ = ${ph.toFixed(1)}°`;
    redraw();
  }
  function dragOn(canvas) {
    let down = false;
    const move = (ev) => {
      if (!down) return;
      const r = canvas.getBoundingClientRect();
      let x = ((ev.clientX - r.left) / r.width) * 2 - 1, y = 1 - ((ev.clientY - r.top) / r.height) * 2;
      const d = Math.hypot(x, y);
      if (d > 0.999) { x *= 0.999 / d; y *= 0.999 / d; }
      setLight([x, y, Math.sqrt(Math.max(0, 1 - x * x - y * y))]);
    };
    canvas.addEventListener("pointerdown", (ev) => { down = true; canvas.setPointerCapture(ev.pointerId); move(ev); });
    canvas.addEventListener("pointermove", move);
    canvas.addEventListener("pointerup", () => { down = false; });
  }

  async function start(tables) {
    const box = document.getElementById("spheres");
    const probe = document.createElement("canvas").getContext("webgl2");
    if (!probe) {
      document.getElementById("sphere-status").textContent =
        "WebGL2 is not available in this browser: the spheres are not shown; the plots below work.";
      window.gonioView = { webgl2: false };
      return;
    }
    for (const t of tables) {
      const fig = document.createElement("figure");
      const c = document.createElement("canvas");
      c.width = c.height = 384;
      c.className = "sphere";
      const cap = document.createElement("figcaption");
      cap.textContent = t.label;
      fig.append(c, cap);
      box.append(fig);
      const s = new Sphere(c, t);
      await s.load();
      dragOn(c);
      state.spheres.push(s);
    }
    const ti = document.getElementById("light-theta"), pi = document.getElementById("light-phi");
    const ex = document.getElementById("exposure");
    const fromInputs = () => setLight(fromAngles(parseFloat(ti.value), parseFloat(pi.value)));
    ti.addEventListener("input", fromInputs);
    pi.addEventListener("input", fromInputs);
    ex.addEventListener("input", () => {
      state.exposure = parseFloat(ex.value);
      document.getElementById("exposure-label").textContent = `exposure: ${state.exposure.toFixed(1)} EV`;
      redraw();
    });
    setLight(state.light);
    const px = new Uint8Array(4);
    for (const s of state.spheres) s.gl.readPixels(0, 0, 1, 1, s.gl.RGBA, s.gl.UNSIGNED_BYTE, px);
    window.gonioView = {
      ready: false,  // set once the plots are drawn too
      webgl2: true,
      firstFrameMs: performance.now(),  // since navigation start: every sphere drawn once
      setLight,
      state,
      // linear radiance of sphere k as a plain array (H * W * 4, rows top first)
      readLinear: (k, light, size) => Array.from(state.spheres[k].readLinear(light, size)),
      timeFrames: (k, size, n) => {
        const s = state.spheres[k];
        s.canvas.width = s.canvas.height = size;
        s.gl.viewport(0, 0, size, size);
        const px = new Uint8Array(4);
        s.draw(state.light, state.exposure, false);
        s.gl.readPixels(0, 0, 1, 1, s.gl.RGBA, s.gl.UNSIGNED_BYTE, px);
        const t0 = performance.now();
        for (let i = 0; i < n; i++) {
          s.draw(fromAngles(10 + i % 60, 5 * i), state.exposure, false);
          s.gl.readPixels(0, 0, 1, 1, s.gl.RGBA, s.gl.UNSIGNED_BYTE, px);  // waits for the frame
        }
        return (performance.now() - t0) / n;
      },
    };
  }
  window.gonioSphere = { start };
})();
