// gonio view: spheres lit by a directional light and by an environment map, rendered in WebGL2
// from the data itself.
//
// Each material is an isotropic half/diff table (gonio/view/encode.py) in a 3-D texture, looked
// up by gonio's rule (gonio/brdf/lookup.py): per axis a continuous node index in the warped
// coordinate, periodic axes wrapped (REPEAT), others clamped (CLAMP_TO_EDGE); multilinear over the
// valid nodes with the weights renormalized over them. The texture holds (f * mask, mask) per
// node, so one filtered fetch gives sum(w m f) and sum(w m): their ratio is gonio's renormalized
// multilinear value. Nearest lookup with a mask reads the nearest node, and where it is invalid
// takes gonio's nearest valid one of the 8 corners.
//
// Point light: pixel = f(wi, wo) * E * max(cos theta_i, 0), E = 1, camera orthographic on +z,
// the shading frame of gonio/render/scene.py.
// Environment: pixel = integral of L(wi) f(wi, wo) cos theta_i over the upper hemisphere, L the
// lat-long map shipped in the page (gonio.render.lights.Environment, nearest texel), estimated
// progressively: each frame adds one sample per pixel, frames cycling through three strategies:
// importance-sampled from the map (its channel mean times sin theta, O(1) alias table),
// cosine-weighted, and gonio's material-independent cosine-power half-vector lobes
// (gonio/appearance/environment.py), weighted by the balance heuristic (each cycle of three
// frames an unbiased estimate). Random numbers: frame i's point of Roberts' R3 / R2 low-discrepancy
// sequences, rotated per pixel by a PCG hash of (pixel, seed): a fixed sequence. The mean of N cycles converges to the integral.
"use strict";
(function () {
  const VS = `#version 300 es
in vec2 pos;
void main() { gl_Position = vec4(pos, 0.0, 1.0); }`;

  const COMMON = `#version 300 es
precision highp float;
precision highp int;
precision highp sampler3D;
uniform sampler3D uTab;
uniform int uFold;
uniform float uScale;
uniform int uChannels;
uniform vec3 uLo, uHi, uOffset;
uniform ivec3 uSize;
uniform bvec3 uSqrt, uPeriodic;
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
vec4 node(ivec3 c) {  // (f * mask, mask) of node (theta_h, theta_d, phi_d)
  vec4 v = texelFetch(uTab, c.zyx, 0);
  return uChannels == 1 ? vec4(v.rrr, v.g) : v;
}
#ifdef NEAREST_MASKED
vec3 nearestMasked(vec3 a, vec3 b, vec3 e) {  // gonio's nearest valid corner
  float best = -1.0;
  vec4 bestv = vec4(0.0);
  for (int j = 0; j < 8; j++) {
    bool ba = (j & 4) != 0, bb = (j & 2) != 0, be = (j & 1) != 0;
    ivec3 cc = ivec3(ba ? a.y : a.x, bb ? b.y : b.x, be ? e.y : e.x);
    float w = (ba ? a.z : 1.0 - a.z) * (bb ? b.z : 1.0 - b.z) * (be ? e.z : 1.0 - e.z);
    vec4 v = node(cc);
    float score = w * v.a + v.a * 1e-6;
    if (score >= best) { best = score; bestv = v; }
  }
  return best > 0.0 ? bestv.rgb * uScale : vec3(0.0);
}
#endif

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
  vec3 t = vec3(idx(th, 0), idx(td, 1), idx(pd, 2));
#ifdef NEAREST_MASKED
  // the nearest node (per axis the corner of larger weight, i1 on a tie: the corner of largest
  // weight, which gonio's rule picks whenever it is valid), else gonio's loop over the corners
  vec3 a = corners(t.x, 0), b = corners(t.y, 1), e = corners(t.z, 2);
  vec4 nv = node(ivec3(a.z >= 0.5 ? a.y : a.x, b.z >= 0.5 ? b.y : b.x, e.z >= 0.5 ? e.y : e.x));
  if (nv.a > 0.0) return nv.rgb * uScale;
  return nearestMasked(a, b, e);
#endif
  // texel i's centre is at (i + 0.5) / n: the filtered fetch at index t is gonio's multilinear
  // (or nearest) value at t, with the texture's wrap modes doing the clamping / wrapping
  vec4 v = texture(uTab, (t.zyx + 0.5) / vec3(uSize.zyx));
  if (uChannels == 1) v = vec4(v.rrr, v.g);
  return v.a > 0.0 ? v.rgb / v.a * uScale : vec3(0.0);
}

// the pixel's normal and shading frame (rows t, b, n) as gonio/render/scene.py, false off the sphere
bool frameAt(vec2 fragXY, out vec3 n, out vec3 t, out vec3 bt) {
  vec2 p = fragXY / uRes * 2.0 - 1.0;
  float r2 = dot(p, p);
  if (r2 >= 1.0) return false;
  n = vec3(p, sqrt(1.0 - r2));
  float tn = sqrt(n.z * n.z + n.x * n.x);
  t = tn <= 1e-12 ? vec3(1.0, 0.0, 0.0) : vec3(n.z / tn, 0.0, -n.x / tn);
  bt = cross(n, t);
  return true;
}
`;

  // display: point light (exact) + environment (accumulated mean) -> exposure -> sRGB
  const FS_SHOW = COMMON + `
uniform sampler2D uAccum;
uniform float uAccumScale;  // 1 / samples accumulated per pixel (0: no environment)
uniform float uEnvScale;
uniform bool uPoint;
uniform vec3 uLight;
uniform float uExposure;
uniform bool uLinear;
float srgb(float v) { return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055; }
void main() {
  vec3 n, t, bt;
  vec3 L = vec3(0.0);
  bool on = frameAt(gl_FragCoord.xy, n, t, bt);
  if (on) {
    if (uPoint) {
      vec3 wo = vec3(t.z, bt.z, n.z);
      vec3 Lw = normalize(uLight);
      vec3 wi = vec3(dot(Lw, t), dot(Lw, bt), dot(Lw, n));
      if (wi.z > 0.0 && wo.z > 1e-6) L = lookup(wi, wo) * wi.z;
    }
    if (uAccumScale > 0.0) L += texelFetch(uAccum, ivec2(gl_FragCoord.xy), 0).rgb * uAccumScale * uEnvScale;
  }
  if (uLinear) { outColor = vec4(L, on ? 1.0 : 0.0); return; }
  vec3 v = L * exp2(uExposure);
  outColor = vec4(srgb(clamp(v.r, 0.0, 1.0)), srgb(clamp(v.g, 0.0, 1.0)),
                  srgb(clamp(v.b, 0.0, 1.0)), 1.0);
}`;

  // one frame of environment samples added to the previous accumulation
  const FS_ENV = COMMON + `
uniform sampler2D uPrev;
uniform sampler2D uEnv;    // (H, W): rgb radiance, a = cell probability * H * W / (2 pi^2)
uniform sampler2D uAlias;  // (H, W): (probability of keeping the cell, alias cell index)
uniform int uCellBits;
uniform int uFrame;     // the cycle: frame / 3
uniform int uStrategy;  // frame % 3: 0 the map, 1 cosine, 2 the lobes
uniform uint uSeed;
const float LOBES[6] = float[6](10.0, 100.0, 1e3, 1e4, 1e5, 1e6);

uint pcg(uint v) {
  uint s = v * 747796405u + 2891336453u;
  uint w = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
  return (w >> 22u) ^ w;
}
uint rngState;
// frame i's point of Roberts' R_d sequences (additive recurrences on the generalized golden
// ratios), shifted per pixel by random offsets (Cranley-Patterson rotation): a progressive
// low-discrepancy sequence per pixel, unbiased at every frame
// (in 32-bit fixed point, so that i * alpha mod 1 is exact for every frame i)
const uvec3 R3 = uvec3(3518319155u, 2882110345u, 2360945575u);
const uvec2 R2 = uvec2(3242174889u, 2447445414u);
float unit(uint x) { return float(x >> 8) * (1.0 / 16777216.0); }

vec2 latlong(vec3 w) {  // gonio.render.lights.direction_to_latlong
  float y = atan(sqrt(max(0.0, 1.0 - w.y * w.y)), clamp(w.y, -1.0, 1.0)) / PI;
  float x = atan(w.x, -w.z) / (2.0 * PI) + 0.5;
  return vec2(x, y);
}
vec4 envTexel(vec2 xy) {
  ivec2 sz = textureSize(uEnv, 0);
  ivec2 c = clamp(ivec2(floor(xy * vec2(sz))), ivec2(0), sz - 1);
  return texelFetch(uEnv, c, 0);
}
float envPdf(vec4 texel, vec3 w) {  // per unit solid angle
  float s = sqrt(max(0.0, 1.0 - w.y * w.y));
  return s > 0.0 ? texel.a / s : 0.0;
}
float lobePdf(vec3 wi, vec3 wo) {  // the lobes' mean (gonio.appearance.environment.mixture_pdf)
  vec3 h = normalize(wi + wo);
  float ch = clamp(h.z, 0.0, 1.0);
  float oh = max(dot(wo, h), 1e-12);
  float lc = log(max(ch, 1e-30));
  float p = 0.0;
  for (int k = 0; k < 6; k++) p += (LOBES[k] + 1.0) / (2.0 * PI) * exp(LOBES[k] * lc) / (4.0 * oh);
  return p / 6.0;
}
void main() {
  vec3 acc = texelFetch(uPrev, ivec2(gl_FragCoord.xy), 0).rgb;
  vec3 n, t, bt;
  if (!frameAt(gl_FragCoord.xy, n, t, bt)) { outColor = vec4(acc, 1.0); return; }
  vec3 wo = vec3(t.z, bt.z, n.z);
  uint px = uint(gl_FragCoord.x) + 65536u * uint(gl_FragCoord.y);
  rngState = pcg(px ^ pcg(uSeed));
  uint i = uint(uFrame);
  uvec3 ue = uvec3(pcg(rngState), pcg(rngState + 1u), pcg(rngState + 2u)) + i * R3;
  uvec2 uc = uvec2(pcg(rngState + 3u), pcg(rngState + 4u)) + i * R2;
  uvec2 ul = uvec2(pcg(rngState + 5u), pcg(rngState + 6u)) + i * R2;
  ivec2 esz = textureSize(uEnv, 0);
  vec3 sum = vec3(0.0);
  {
    int s = uStrategy;
    vec3 wi, world;
    vec4 texel;
    if (s == 0) {  // from the map: alias table, then uniform within the cell
      // the cell from the top bits of ue.x (the map has 2^uCellBits <= 2^16 cells), the alias
      // test from its 16 low bits
      int cell = int(ue.x >> uint(32 - uCellBits));
      vec2 al = texelFetch(uAlias, ivec2(cell % esz.x, cell / esz.x), 0).rg;
      float acc = float(ue.x & 0xFFFFu) / 65536.0;
      if (acc >= al.x) cell = int(al.y);
      vec2 xy = (vec2(cell % esz.x, cell / esz.x) + vec2(unit(ue.y), unit(ue.z))) / vec2(esz);
      float th = PI * xy.y, ph = 2.0 * PI * (xy.x - 0.5);
      world = vec3(sin(th) * sin(ph), cos(th), -sin(th) * cos(ph));
      wi = vec3(dot(world, t), dot(world, bt), dot(world, n));
      texel = texelFetch(uEnv, ivec2(cell % esz.x, cell / esz.x), 0);
    } else {
      if (s == 1) {  // cosine-weighted
        float a = unit(uc.x), phi = 2.0 * PI * unit(uc.y), r = sqrt(a);
        wi = vec3(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - a)));
      } else {  // one of the 6 lobes, then a half vector about the normal, reflected
        float u0 = unit(ul.x) * 6.0, phi = 2.0 * PI * unit(ul.y);
        int j = min(int(u0), 5);
        float ch = exp(log(max(fract(u0), 1e-30)) / (LOBES[j] + 1.0));
        float sh = sqrt(max(0.0, 1.0 - ch * ch));
        vec3 h = vec3(sh * cos(phi), sh * sin(phi), ch);
        wi = 2.0 * dot(wo, h) * h - wo;
      }
      world = wi.x * t + wi.y * bt + wi.z * n;
      texel = envTexel(latlong(world));
    }
    // the balance heuristic over the three (one sample each per cycle of three frames):
    // f L cos / (p_env + p_cos + p_lobes)
    float p = wi.z > 0.0 ? envPdf(texel, world) + wi.z / PI + lobePdf(wi, wo) : 0.0;
    if (p > 0.0) sum = lookup(wi, wo) * texel.rgb * wi.z / p;
  }
  outColor = vec4(acc + sum, 1.0);
}`;

  // frames (one sample per pixel each) until the environment's refinement stops
  const MAX_FRAMES = 768;

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
  // `defines`: lines inserted after #version (a software renderer runs skipped branches too, so
  // code a table does not need is left out of its program, not branched around)
  function program(gl, fs, defines) {
    fs = fs.replace("#version 300 es\n", "#version 300 es\n" + defines);
    const prog = gl.createProgram();
    for (const [kind, src] of [[gl.VERTEX_SHADER, VS], [gl.FRAGMENT_SHADER, fs]]) {
      const sh = gl.createShader(kind);
      gl.shaderSource(sh, src);
      gl.compileShader(sh);
      gl.attachShader(prog, sh);
    }
    gl.bindAttribLocation(prog, 0, "pos");
    gl.linkProgram(prog);
    return prog;
  }
  function check(gl, prog) {  // after linking in parallel (KHR_parallel_shader_compile)
    if (gl.getProgramParameter(prog, gl.LINK_STATUS)) return;
    for (const sh of gl.getAttachedShaders(prog)) {
      if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(sh));
    }
    throw new Error(gl.getProgramInfoLog(prog));
  }
  function floatTarget(gl, size) {
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, size, size);
    for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, p, gl.NEAREST);
    const fb = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
    gl.clearColor(0, 0, 0, 0);
    gl.clear(gl.COLOR_BUFFER_BIT);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    return { tex, fb, size };
  }

  // The environment's textures from the page's map: radiance + density, and the alias table.
  function envTextures(gl, env, img) {
    const [h, w] = env.shape;
    const n = h * w;
    if (n & (n - 1) || n > 65536) throw new Error("the environment map needs 2^k <= 2^16 cells");
    const texel = new Float32Array(n * 4), weight = new Float64Array(n);
    let total = 0;
    for (let r = 0; r < h; r++) {
      const st = Math.sin((Math.PI * (r + 0.5)) / h);
      for (let c = 0; c < w; c++) {
        const i = r * w + c;
        const v = img.subarray(i * 3, i * 3 + 3);
        texel.set(v, i * 4);
        weight[i] = ((v[0] + v[1] + v[2]) / 3) * st;
        total += weight[i];
      }
    }
    // Vose's alias method over the cells
    const prob = new Float64Array(n), alias = new Int32Array(n);
    const small = [], large = [];
    for (let i = 0; i < n; i++) {
      prob[i] = (weight[i] / total) * n;
      texel[i * 4 + 3] = ((weight[i] / total) * n) / (2 * Math.PI * Math.PI);
      (prob[i] < 1 ? small : large).push(i);
    }
    while (small.length && large.length) {
      const s = small.pop(), l = large.pop();
      alias[s] = l;
      prob[l] -= 1 - prob[s];
      (prob[l] < 1 ? small : large).push(l);
    }
    for (const i of [...small, ...large]) { prob[i] = 1; alias[i] = i; }
    const al = new Float32Array(n * 2);
    for (let i = 0; i < n; i++) { al[2 * i] = prob[i]; al[2 * i + 1] = alias[i]; }
    const mk = (fmt, f, data, comps) => {
      const tex = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_2D, tex);
      for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, p, gl.NEAREST);
      gl.texImage2D(gl.TEXTURE_2D, 0, fmt, w, h, 0, comps, f, data);
      return tex;
    };
    return { radiance: mk(gl.RGBA32F, gl.FLOAT, texel, gl.RGBA), alias: mk(gl.RG32F, gl.FLOAT, al, gl.RG) };
  }

  class Sphere {
    constructor(canvas, table, env) {
      this.canvas = canvas;
      this.table = table;
      const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: false, antialias: false });
      if (!gl) throw new Error("no WebGL2");
      this.gl = gl;
      gl.getExtension("KHR_parallel_shader_compile");
      this.envOk = !!gl.getExtension("EXT_color_buffer_float") && !!env;
      const defines = table.nearest && table.mask ? "#define NEAREST_MASKED 1\n" : "";
      this.show = program(gl, FS_SHOW, defines);
      this.envProg = this.envOk ? program(gl, FS_ENV, defines) : null;
      const buf = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, buf);
      gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 3, -1, -1, 3]), gl.STATIC_DRAW);
      gl.enableVertexAttribArray(0);
      gl.vertexAttribPointer(0, 2, gl.FLOAT, false, 0, 0);
      this.frames = 0;
      this.acc = null;
    }
    // the table's texture: (f * mask, mask) per node, RG16F (grey) or RGBA16F (RGB)
    // `bytes`: the promise of the table's inflated (values, mask)
    async load(bytes, envImage, env) {
      const gl = this.gl, t = this.table;
      const [nth, ntd, npd] = t.shape;
      const [vals, mask] = await bytes;
      mark("inflated");
      const v16 = new Uint16Array(vals.buffer);
      const c = t.channels, nodes = nth * ntd * npd, k = c === 3 ? 4 : 2;
      const tex = new Uint16Array(nodes * k);
      const ONE = 0x3c00;  // float16 1.0
      for (let i = 0; i < nodes; i++) {
        for (let j = 0; j < c; j++) tex[i * k + j] = v16[i * c + j];
        tex[i * k + k - 1] = mask && !mask[i] ? 0 : ONE;
      }
      gl.activeTexture(gl.TEXTURE0);
      const tv = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_3D, tv);
      const filt = t.nearest ? gl.NEAREST : gl.LINEAR;
      for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_3D, p, filt);
      const ax = t.axes;
      const wrap = (a) => (a.periodic ? gl.REPEAT : gl.CLAMP_TO_EDGE);
      gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_WRAP_S, wrap(ax[2]));
      gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_WRAP_T, wrap(ax[1]));
      gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_WRAP_R, wrap(ax[0]));
      gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
      gl.texImage3D(gl.TEXTURE_3D, 0, c === 3 ? gl.RGBA16F : gl.RG16F, npd, ntd, nth, 0,
                    c === 3 ? gl.RGBA : gl.RG, gl.HALF_FLOAT, tex);
      if (this.envOk) {
        const e = envTextures(gl, env, envImage);
        gl.activeTexture(gl.TEXTURE2);
        gl.bindTexture(gl.TEXTURE_2D, e.radiance);
        gl.activeTexture(gl.TEXTURE3);
        gl.bindTexture(gl.TEXTURE_2D, e.alias);
      }
      mark("uploaded");
      check(gl, this.show);  // the environment's program is checked when first used
      this.tableUniforms(this.show);
      this.su = (name) => gl.getUniformLocation(this.show, name);
      gl.uniform1i(this.su("uAccum"), 1);
      this.env = env;
      gl.activeTexture(gl.TEXTURE1);
    }
    tableUniforms(prog) {
      const gl = this.gl, t = this.table, ax = t.axes;
      gl.useProgram(prog);
      const u = (name) => gl.getUniformLocation(prog, name);
      gl.uniform1i(u("uTab"), 0);
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
    // the environment's program, linked in the background since the constructor
    envProgram() {
      const gl = this.gl;
      if (!this.eu) {
        check(gl, this.envProg);
        this.tableUniforms(this.envProg);
        const u = (name) => gl.getUniformLocation(this.envProg, name);
        gl.uniform1i(u("uPrev"), 1);
        gl.uniform1i(u("uEnv"), 2);
        gl.uniform1i(u("uAlias"), 3);
        gl.uniform1i(u("uCellBits"), Math.round(Math.log2(this.env.shape[0] * this.env.shape[1])));
        this.eu = u;
      }
      gl.useProgram(this.envProg);
    }
    // (re)start the environment's accumulation at size x size pixels
    resetEnv(size) {
      const gl = this.gl;
      if (!this.envOk) return;
      if (!this.acc || this.acc[0].size !== size) {
        for (const a of this.acc || []) { gl.deleteTexture(a.tex); gl.deleteFramebuffer(a.fb); }
        this.acc = [floatTarget(gl, size), floatTarget(gl, size)];
      } else {
        for (const a of this.acc) {
          gl.bindFramebuffer(gl.FRAMEBUFFER, a.fb);
          gl.clear(gl.COLOR_BUFFER_BIT);
        }
        gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      }
      this.frames = 0;
    }
    // add one frame of environment samples (sequence `seed`) to the accumulation
    accumulate(seed) {
      const gl = this.gl, [prev, next] = this.acc;
      this.envProgram();
      gl.bindFramebuffer(gl.FRAMEBUFFER, next.fb);
      gl.viewport(0, 0, next.size, next.size);
      gl.bindTexture(gl.TEXTURE_2D, prev.tex);
      gl.uniform2f(this.eu("uRes"), next.size, next.size);
      gl.uniform1i(this.eu("uFrame"), Math.floor(this.frames / 3));
      gl.uniform1i(this.eu("uStrategy"), this.frames % 3);
      gl.uniform1ui(this.eu("uSeed"), seed >>> 0);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      this.acc = [next, prev];
      this.frames += 1;
    }
    // draw into `fb` (null: the canvas) at size x size
    draw(view, fb, size, linear) {
      const gl = this.gl;
      const env = view.mode !== "point" && this.envOk && this.frames > 0 && this.acc[0].size === size;
      gl.useProgram(this.show);
      gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
      gl.viewport(0, 0, size, size);
      gl.bindTexture(gl.TEXTURE_2D, env ? this.acc[0].tex : null);
      // one estimate per cycle of 3 frames (a partial cycle weighs its samples as full ones)
      gl.uniform1f(this.su("uAccumScale"), env ? 3 / this.frames : 0);
      gl.uniform1f(this.su("uEnvScale"), Math.pow(2, view.envEV));
      gl.uniform1i(this.su("uPoint"), view.mode !== "environment" ? 1 : 0);
      gl.uniform3f(this.su("uLight"), view.light[0], view.light[1], view.light[2]);
      gl.uniform1f(this.su("uExposure"), view.exposure);
      gl.uniform1i(this.su("uLinear"), linear ? 1 : 0);
      gl.uniform2f(this.su("uRes"), size, size);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    }
    // Linear radiance (H, W, 4) float32, rows top first, rendered off screen at size x size.
    readLinear(view, size) {
      const gl = this.gl;
      if (!gl.getExtension("EXT_color_buffer_float")) throw new Error("no float render targets");
      const t = floatTarget(gl, size);
      this.draw(view, t.fb, size, true);
      const px = new Float32Array(size * size * 4);
      gl.bindFramebuffer(gl.FRAMEBUFFER, t.fb);
      gl.readPixels(0, 0, size, size, gl.RGBA, gl.FLOAT, px);
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      gl.deleteFramebuffer(t.fb);
      gl.deleteTexture(t.tex);
      const out = new Float32Array(size * size * 4);  // flip: readPixels starts at the bottom
      for (let y = 0; y < size; y++) out.set(px.subarray((size - 1 - y) * size * 4, (size - y) * size * 4), y * size * 4);
      return out;
    }
    wait() {  // returns once every command so far has run
      const px = new Uint8Array(4);
      this.gl.readPixels(0, 0, 1, 1, this.gl.RGBA, this.gl.UNSIGNED_BYTE, px);
    }
  }

  // The page: spheres side by side, one light, one mode and one exposure for all.
  const state = { light: [0, 0, 1], exposure: 0, envEV: 0, mode: "both", spheres: [], seed: 1, held: false,
                  touched: -1e9 };
  const mark = (name) => performance.mark("gonio:" + name);
  function fromAngles(thetaDeg, phiDeg) {
    const t = (thetaDeg * Math.PI) / 180, p = (phiDeg * Math.PI) / 180;
    return [Math.sin(t) * Math.cos(p), Math.sin(t) * Math.sin(p), Math.cos(t)];
  }
  function status() {
    const el = document.getElementById("env-label");
    const s = state.spheres[0];
    if (el && s) el.textContent = s.envOk ? `environment: ${s.frames} samples per pixel` : "environment: not available (no float render targets)";
  }
  function redraw() { for (const s of state.spheres) s.draw(state, null, s.canvas.width, false); status(); }
  function touch() { state.touched = performance.now(); redraw(); }
  let looping = false;
  function refine() {  // progressive environment: one frame per animation frame until MAX_FRAMES
    if (looping) return;
    const step = () => {
      const todo = state.mode !== "point" && !state.held &&
        state.spheres.some((s) => s.envOk && s.frames < MAX_FRAMES);
      if (!todo) { looping = false; return; }
      // while the light or the exposure moves, the frames go to the point light alone
      const busy = performance.now() - state.touched < 250;
      if (!busy) for (const s of state.spheres) if (s.envOk && s.frames < MAX_FRAMES) s.accumulate(state.seed);
      redraw();
      requestAnimationFrame(step);
    };
    looping = true;
    requestAnimationFrame(step);
  }
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
    touch();
  }
  function setMode(mode) {
    state.mode = mode;
    for (const el of document.querySelectorAll("input[name=light-mode]")) el.checked = el.value === mode;
    redraw();
    refine();
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
  function bindControls() {
    const ti = document.getElementById("light-theta"), pi = document.getElementById("light-phi");
    const fromInputs = () => setLight(fromAngles(parseFloat(ti.value), parseFloat(pi.value)));
    ti.addEventListener("input", fromInputs);
    pi.addEventListener("input", fromInputs);
    const slider = (id, key, label) => {
      const el = document.getElementById(id);
      el.addEventListener("input", () => {
        state[key] = parseFloat(el.value);
        document.getElementById(id + "-label").textContent = `${label}: ${state[key].toFixed(1)} EV`;
        touch();
      });
    };
    slider("exposure", "exposure", "exposure");
    slider("env-ev", "envEV", "environment");
    for (const el of document.querySelectorAll("input[name=light-mode]")) {
      el.addEventListener("change", () => { if (el.checked) setMode(el.value); });
    }
  }

  // Draw every sphere once (the first frame), then refine the environment in the background.
  async function start(tables, env) {
    mark("start");
    const box = document.getElementById("spheres");
    const probe = document.createElement("canvas").getContext("webgl2");
    if (!probe) {
      document.getElementById("sphere-status").textContent =
        "WebGL2 is not available in this browser: the spheres are not shown; the plots below work.";
      window.gonioView = { webgl2: false };
      return;
    }
    // every inflate started at once (the browser runs them off the main thread)
    const bytes = tables.map((t) => Promise.all([inflate(t.values), t.mask ? inflate(t.mask) : null]));
    const envImage = env ? new Float32Array((await inflate(env.radiance)).buffer) : null;
    mark("env-inflated");
    for (const [k, t] of tables.entries()) {
      const fig = document.createElement("figure");
      const c = document.createElement("canvas");
      c.width = c.height = 384;
      c.className = "sphere";
      const cap = document.createElement("figcaption");
      cap.textContent = t.label;
      fig.append(c, cap);
      box.append(fig);
      const s = new Sphere(c, t, env);
      await s.load(bytes[k], envImage, env);
      s.resetEnv(c.width);
      dragOn(c);
      state.spheres.push(s);
    }
    mark("loaded");
    const asked = location.hash.slice(1);  // view.html#point starts without the environment
    if (["point", "environment", "both"].includes(asked)) state.mode = asked;
    for (const el of document.querySelectorAll("input[name=light-mode]")) el.checked = el.value === state.mode;
    setLight(state.light);
    for (const s of state.spheres) s.wait();
    mark("first-frame");
    bindControls();
    window.gonioView = {
      ready: false,  // set once the plots are drawn too
      webgl2: true,
      env: !!env && state.spheres.every((s) => s.envOk),
      firstFrameMs: performance.now(),  // since navigation start: every sphere drawn once
      timings: () => Object.fromEntries(performance.getEntriesByType("mark")
        .filter((m) => m.name.startsWith("gonio:")).map((m) => [m.name.slice(6), m.startTime])),
      setLight,
      setMode,
      state,
      // linear radiance of sphere k under the point light (H * W * 4, rows top first)
      readLinear: (k, light, size) =>
        Array.from(state.spheres[k].readLinear({ ...state, mode: "point", light }, size)),
      // stop (true) or resume (false) the environment's background refinement
      hold: (on) => { state.held = !!on; if (!on) refine(); },
      // linear radiance of sphere k as the page shows it now (light, mode), with the
      // environment after `frames` frames of sample sequence `seed`, off screen at size x size
      readView: (k, size, frames, seed) => {
        const s = state.spheres[k];
        s.resetEnv(size);
        for (let i = 0; i < frames; i++) s.accumulate(seed);
        const out = Array.from(s.readLinear(state, size));
        s.resetEnv(s.canvas.width);
        return out;
      },
      // linear radiance of sphere k under the environment alone after `frames` frames of
      // sample sequence `seed`, rendered off screen at size x size
      readEnv: (k, size, frames, seed) => {
        const s = state.spheres[k];
        s.resetEnv(size);
        for (let i = 0; i < frames; i++) s.accumulate(seed);
        const out = Array.from(s.readLinear({ ...state, mode: "environment", envEV: 0 }, size));
        s.resetEnv(s.canvas.width);
        return out;
      },
      // median time (ms) of n frames at size x size in `mode`, each waited for (1-pixel read);
      // the light moves from frame to frame unless `light` is given
      timeFrames: (k, size, n, mode, light) => {
        state.mode = "point";  // stops the background refinement
        const s = state.spheres[k];
        s.canvas.width = s.canvas.height = size;
        s.resetEnv(size);
        const view = { ...state, mode: mode || "point" };
        const times = [];
        for (let i = -2; i < n; i++) {
          view.light = light || fromAngles(10 + (i + 2) % 60, 5 * i);
          const t0 = performance.now();
          if (view.mode !== "point") s.accumulate(state.seed);
          s.draw(view, null, size, false);
          s.wait();
          if (i >= 0) times.push(performance.now() - t0);
        }
        times.sort((a, b) => a - b);
        return times[Math.floor(times.length / 2)];
      },
    };
    refine();
  }
  window.gonioSphere = { start, inflate };
})();
