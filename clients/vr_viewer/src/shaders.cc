#include "shaders.h"

#include <cmath>
#include <cstdio>

#include "vdyn/viewer/lighting.h"
#include "vdyn/viewer/textures.h"
#include "vdyn/viewer/world_mesh.h"

namespace vdyn::viewer {

const Lighting& SceneLighting() {
  static const Lighting l = [] {
    Lighting x;
    const double elevation = Rad(48), azimuth = Rad(225);  // from +X towards +Y: south-west
    x.sun_W = {std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth),
               std::sin(elevation)};
    x.sky_rgb = {0.24, 0.28, 0.34};
    // Balanced: sun_rgb * sun.z + sky_rgb = 1 on a face turned up.
    x.sun_rgb = Vec3{1 - x.sky_rgb.x, 1 - x.sky_rgb.y, 1 - x.sky_rgb.z} / x.sun_W.z;
    x.ground_rgb = {0.09, 0.10, 0.08};
    x.zenith_rgb = {0.13, 0.29, 0.66};
    x.horizon_rgb = {0.60, 0.68, 0.78};
    return x;
  }();
  return l;
}

namespace shaders {
namespace {

std::string Vec(const Vec3& v) {
  char b[96];
  std::snprintf(b, sizeof b, "vec3(%.6f, %.6f, %.6f)", v.x, v.y, v.z);
  return b;
}

std::string Num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.6f", v);
  return b;
}

// Shared by every fragment shader.
constexpr const char* kCommon = R"(
uniform vec3 u_eye;
uniform float u_fog_m;  // the fog's distance scale, m; 0: no fog

// sRGB <-> linear light (the sRGB curve, as the GPU decodes the textures).
vec3 Decode(vec3 c) {
  return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(vec3(0.04045), c));
}
// The sRGB curve's power part from three square roots (cheaper than pow on a software renderer;
// every 8-bit level comes back exactly).
vec3 Encode(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  vec3 s1 = sqrt(c), s2 = sqrt(s1), s3 = sqrt(s2);
  vec3 e = 0.662002687 * s1 + 0.684122060 * s2 - 0.323583601 * s3 - 0.0225411470 * c;
  return mix(12.92 * c, e, step(vec3(0.0031308), c));
}
// The sky's and the ground's light on a face with normal n.
vec3 Hemi(vec3 n) { return mix(kGroundRgb, kSkyRgb, clamp(0.5 + 0.5 * n.z, 0.0, 1.0)); }
// What a mirror turned towards d reflects.
vec3 SkyRadiance(vec3 d) {
  if (d.z < 0.0) return mix(kHorizonRgb, kGroundRgb * 2.0, clamp(-d.z * 4.0, 0.0, 1.0));
  return mix(kHorizonRgb, kZenithRgb, sqrt(d.z));
}
// The fog between the eye and a point r fog distances away (r: the point from the eye over
// u_fog_m; linear in the point, so a vertex shader's r interpolates exactly).
float FogOver(vec3 r) { return 1.0 - exp(-dot(r, r)); }
vec3 FogVector(vec3 p) { return u_fog_m > 0.0 ? (p - u_eye) / u_fog_m : vec3(0.0); }
float FogAmount(vec3 p) {
  return FogOver(FogVector(p));
}
// Filmic tone mapping: linear light as it is up to the knee (0.6: the scene's diffuse range,
// a face turned to the sun gets 1 times its albedo), then a shoulder that rolls highlights off
// towards white (extended Reinhard on the excess, white at kWhite, the slope continuous at the
// knee), per channel, so a bright highlight keeps its gradation and turns towards white as on
// film instead of clipping to a flat patch.
const float kKnee = 0.6, kWhite = 16.0;
vec3 ToneMap(vec3 c) {
  vec3 t = max(c - kKnee, 0.0) / (1.0 - kKnee);
  float w = (kWhite - kKnee) / (1.0 - kKnee);
  vec3 shoulder = kKnee + (1.0 - kKnee) * t * (1.0 + t / (w * w)) / (1.0 + t);
  return mix(c, shoulder, step(kKnee, c));
}
// Linear scene light to the screen's bytes: tone mapped, sRGB-encoded.
vec3 Output(vec3 c) { return Encode(ToneMap(c)); }
// Fogged towards the horizon's colour, tone mapped and encoded for the screen.
vec3 Finish(vec3 c, vec3 p) { return Output(mix(c, kHorizonRgb, FogAmount(p))); }
// The same with light of its own (a lamp): shown as it is beside the tone-mapped rest, so a lit
// lamp reaches full brightness in its colour (a display's emitter, not a scene highlight).
vec3 FinishOwn(vec3 c, vec3 own, vec3 p) {
  float f = FogAmount(p);
  return Encode(max(ToneMap(mix(c, kHorizonRgb, f)), mix(own, kHorizonRgb, f)));
}

// --- physically based shading (metal/roughness), the sky as the environment light -------------
const float kPi = 3.14159265;
// The sky's light reflected by a surface of roughness r (0 mirror .. 1 rough) towards the eye
// along the mirror direction d of a face with normal n: a mirror sees the gradient, a rough face
// the average of its hemisphere (the ambient light of Hemi, as radiance), between the two as the
// lobe widens (the dominant direction bends towards the normal).
vec3 SkySpecular(vec3 d, vec3 n, float r) {
  vec3 mirror = SkyRadiance(normalize(mix(d, n, r * r)));
  return mix(mirror, Hemi(n), r * r);
}
// The split-sum environment BRDF's scale and bias on F0 for roughness r at n.v (the analytic fit
// of Karis, "Physically based shading on mobile", 2014).
vec2 EnvBrdf(float r, float nv) {
  vec4 q = r * vec4(-1.0, -0.0275, -0.572, 0.022) + vec4(1.0, 0.0425, 1.04, -0.04);
  float a004 = min(q.x * q.x, exp2(-9.28 * nv)) * q.x + q.y;
  return vec2(-1.04, 1.04) * a004 + q.zw;
}
// The sun's specular reflection: GGX distribution, height-correlated Smith visibility
// (Hammon's approximation), Schlick's Fresnel; times the sun's light where it reaches.
vec3 SunSpecular(vec3 n, vec3 v, vec3 f0, float r, float sun) {
  vec3 h = normalize(kSunDir + v);
  float nl = max(dot(n, kSunDir), 0.0), nv = max(dot(n, v), 1e-4);
  float nh = max(dot(n, h), 0.0), vh = max(dot(v, h), 0.0);
  float a = max(r * r, 0.004), a2 = a * a;
  float d = nh * nh * (a2 - 1.0) + 1.0;
  float D = a2 / (kPi * d * d);
  float vis = 0.5 / (nl * (nv * (1.0 - a) + a) + nv * (nl * (1.0 - a) + a) + 1e-5);
  float x = 1.0 - vh, x2 = x * x;
  vec3 F = f0 + (1.0 - f0) * (x2 * x2 * x);
  return kSunRgb * (sun * nl * D * vis) * F;
}
// A rough dielectric's reflection of the sky and the sun beyond what its albedo holds: the
// world's surfaces. Their textures' colours are as seen from above, their reflection there
// included; what grows with the angle is the split-sum's rise from normal incidence to n.v (for a
// rough surface a few per cent: Schlick's full rise holds only for a mirror), and the sun's GGX
// highlight (the road's glare against a low sun).
vec3 WorldSpecular(vec3 n, vec3 v, float r, float sun) {
  vec2 at_v = EnvBrdf(r, max(dot(n, v), 1e-4)), at_normal = EnvBrdf(r, 1.0);
  float rise = max(0.04 * (at_v.x - at_normal.x) + at_v.y - at_normal.y, 0.0);
  return rise * SkySpecular(reflect(-v, n), n, r) + SunSpecular(n, v, vec3(0.04), r, sun);
}

#ifdef SHADOWS
uniform sampler2DShadow u_shadow_map;
uniform mat4 u_shadow_mat;        // world -> shadow map [0, 1]^3
uniform vec4 u_shadow_box;        // centre x, y; radius; metres per texel
uniform float u_shadow_texel_uv;  // one texel in texture coordinates
// How much of the sun reaches p (1: all): two bilinear comparisons half a texel apart (a soft
// edge two texels wide), fading out towards the edge of the map.
float SunVisibility(vec3 p, vec3 n) {
  float texel = u_shadow_box.w;
  vec3 q = p + n * (1.5 * texel) + kSunDir * (0.5 * texel);
  vec3 s = (u_shadow_mat * vec4(q, 1.0)).xyz;
  if (any(lessThan(s, vec3(0.0))) || any(greaterThan(s, vec3(1.0)))) return 1.0;
  float t = u_shadow_texel_uv;
  float v = 0.5 * (texture(u_shadow_map, s + vec3(-0.5 * t, -0.25 * t, 0.0)) +
                   texture(u_shadow_map, s + vec3(0.5 * t, 0.25 * t, 0.0)));
  float fade = smoothstep(0.8 * u_shadow_box.z, u_shadow_box.z, length(p.xy - u_shadow_box.xy));
  return mix(v, 1.0, fade);
}
#else
float SunVisibility(vec3 p, vec3 n) { return 1.0; }
#endif

// Diffuse light on a face: the sun (where it reaches) and the sky.
vec3 Diffuse(vec3 n, float sun) {
  return kSunRgb * (max(dot(n, kSunDir), 0.0) * sun) + Hemi(n);
}
)";

}  // namespace

std::string Vertex(const char* body) {
  return std::string("#version 330 core\n") + body;
}

std::string Fragment(const Options& o, const char* body) {
  const Lighting& l = SceneLighting();
  std::string s = "#version 330 core\n";
  if (o.high) s += "#define HIGH 1\n";
  if (o.shadows) s += "#define SHADOWS 1\n";
  if (o.clouds) s += "#define CLOUDS 1\n";
  if (o.grid) s += "#define GRID 1\n";
  s += "#define STYLE " + std::to_string(o.style) + "\n";
  s += "const vec3 kSunDir = " + Vec(l.sun_W) + ";\n";
  s += "const vec3 kSunRgb = " + Vec(l.sun_rgb) + ";\n";
  s += "const vec3 kSkyRgb = " + Vec(l.sky_rgb) + ";\n";
  s += "const vec3 kGroundRgb = " + Vec(l.ground_rgb) + ";\n";
  s += "const vec3 kZenithRgb = " + Vec(l.zenith_rgb) + ";\n";
  s += "const vec3 kHorizonRgb = " + Vec(l.horizon_rgb) + ";\n";
  s += "const float kKerbWidth = " + Num(RoadMarkings::kKerbWidth) + ";\n";
  s += "const float kKerbBlock = " + Num(RoadMarkings::kKerbBlock) + ";\n";
  s += "const float kEdgeLineInset = " + Num(RoadMarkings::kEdgeLineInset) + ";\n";
  s += "const float kLineWidth = " + Num(RoadMarkings::kLineWidth) + ";\n";
  s += "const float kDash = " + Num(RoadMarkings::kDash) + ";\n";
  s += "const float kDashPeriod = " + Num(RoadMarkings::kDashPeriod) + ";\n";
  {
    const Rgb8 g = MeanColour(TextureLayer::kGrass);  // the grass texture's mean, linear
    s += "const float kGrassLuma = " +
         Num(0.2126 * ToLinear(g.r) + 0.7152 * ToLinear(g.g) + 0.0722 * ToLinear(g.b)) + ";\n";
  }
  s += kCommon;
  s += body;
  return s;
}

std::string VertexLit(const Options& o, const char* body) {
  return Fragment(o, body);
}

// --- terrain -----------------------------------------------------------------------------------

// Per vertex what is linear or constant over a face: the fog's vector and, without the shadow
// map, the diffuse light (the same at every point of a flat face: a software renderer shades
// each pixel, so what a vertex can do is taken off every pixel).
const char* const kTerrainVs = R"(
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_normal;
uniform mat4 u_view_proj;
uniform float u_relief;  // the slopes' shading made this much steeper (Relief in the fragment shader)
out vec3 v_pos;
out vec3 v_normal;
out vec3 v_fog;
#ifndef SHADOWS
out vec3 v_light;
#endif
void main() {
  v_pos = a_pos;
  v_normal = a_normal;
  v_fog = FogVector(a_pos);
#ifndef SHADOWS
  vec3 n = normalize(a_normal);
#if STYLE == 3 || STYLE == 4
  n = normalize(vec3(n.xy * u_relief, n.z));
#endif
  v_light = Diffuse(n * sign(dot(n, u_eye - a_pos) + 1e-9), 1.0);
#endif
  gl_Position = u_view_proj * vec4(a_pos, 1.0);
}
)";

// Surfaces by style (SurfaceStyle in world_mesh.h; one program per style: a software renderer
// runs every branch of a shader for every pixel): textures from the array (grass, asphalt,
// concrete, dirt; the large-scale variation in layer 4), road markings and kerbs from the strip
// frame, the glass barrier with its posts and rail.
const char* const kTerrainFs = R"(
in vec3 v_pos;
in vec3 v_normal;
in vec3 v_fog;
#ifndef SHADOWS
in vec3 v_light;
#endif
uniform sampler2DArray u_surfaces;
uniform vec4 u_frame;        // the mesh's strip frame: centre x, y; its long axis x, y
uniform vec2 u_half_size;    // from the centre along and across, m
uniform float u_strip;       // 1: a strip (markings and kerbs)
uniform float u_grid;        // grid spacing, m
uniform float u_relief;      // slopes shaded this much steeper (rough ground 3, washboard 4)
uniform vec2 u_z_range;      // the mesh's lowest and highest point, m
uniform vec4 u_poster_a;     // a prop's poster face: lower left corner x, y, z; width
uniform vec4 u_poster_b;     // its right (unit) x, y; height; 1 when it has one
out vec4 o_colour;

vec3 Tex(float layer, vec2 uv_m, float tile_m) {
  return texture(u_surfaces, vec3(uv_m / tile_m, layer)).rgb;
}
float Variation(vec2 xy) {
#ifdef HIGH
  return 0.7 + 0.6 * texture(u_surfaces, vec3(xy / 61.0, 4.0)).r;
#else
  return 1.0;
#endif
}
// Coverage of a band |d| < half_width, antialiased over a pixel.
float Band(float d, float half_width) {
  return clamp((half_width - abs(d)) / max(fwidth(d), 1e-4) + 0.5, 0.0, 1.0);
}
float Luma(vec3 c) { return dot(c, vec3(0.2126, 0.7152, 0.0722)); }
// Grass; quality high: near the eye its own grain again, 4.4 times finer, fading out by 30 m (the
// nearest metres show blades, not one magnified tile).
vec3 Grass(vec2 xy, float dist) {
  vec3 g = Tex(0.0, xy, 4.0) * Variation(xy);
#ifdef HIGH
  float near = 1.0 - smoothstep(4.0, 30.0, dist);
  g *= mix(1.0, clamp(Luma(Tex(0.0, xy, 0.91)) / kGrassLuma, 0.45, 1.7), near);
#endif
  return g;
}

void main() {
  vec3 n = normalize(v_normal);
  vec3 to_eye = u_eye - v_pos;
  n *= sign(dot(n, to_eye) + 1e-9);
  vec3 n_mesh = n;
#if STYLE == 3 || STYLE == 4
  // Low relief (rough ground's bumps, the washboard's ripples: slopes of a few degrees) shaded as
  // if steeper, so it reads from the driver's seat: the normal's tilt scaled by u_relief.
  n = normalize(vec3(n.xy * u_relief, n.z));
#endif
  vec2 xy = v_pos.xy;
  // The frame's coordinates: along, across from the centre line.
  vec2 rel = xy - u_frame.xy;
  vec2 v_uv = vec2(dot(rel, u_frame.zw), dot(rel, vec2(-u_frame.w, u_frame.z)));
  vec3 add = vec3(0.0);
  float alpha = 1.0;
#if STYLE == 0 || STYLE == 4
  vec2 tc = xy;
#else
  // On a steep face: along the face and up.
  vec2 t = normalize(vec2(-n.y, n.x) + vec2(1e-6, 0.0));
  vec2 tc = mix(vec2(dot(xy, t), v_pos.z), xy, step(0.6, abs(n.z)));
#endif
#if STYLE == 1
  // Asphalt; on a strip its markings and kerbs.
  vec3 albedo = Tex(1.0, tc, 3.0);
  float along = v_uv.x, across = v_uv.y, d = abs(across), hw = u_half_size.y;
  float grain = 0.75 + 0.6 * Luma(albedo) / 0.077;
  vec3 paint = vec3(0.80, 0.80, 0.76) * clamp(grain, 0.7, 1.15);
  float edge = Band(d - (hw - kEdgeLineInset), 0.5 * kLineWidth);
  float dash = step(fract(along / kDashPeriod), kDash / kDashPeriod);
  float centre = Band(across, 0.5 * kLineWidth) * dash;
  albedo = mix(albedo, paint, 0.92 * u_strip * max(edge, centre));
  float kerb = clamp((d - (hw - kKerbWidth)) / max(fwidth(d), 1e-4) + 0.5, 0.0, 1.0);
  float block = mod(floor(along / kKerbBlock), 2.0);
  vec3 kerb_rgb = mix(vec3(0.58, 0.012, 0.011), vec3(0.80, 0.80, 0.76), block);
  albedo = mix(albedo, kerb_rgb * clamp(grain, 0.8, 1.1), u_strip * kerb);
#elif STYLE == 2
  // Hazard paint: yellow and black blocks along the bump.
  float block = mod(floor(v_uv.x / 0.5), 2.0);
  vec3 albedo = mix(vec3(0.80, 0.50, 0.008), vec3(0.018), block) *
                clamp(0.7 + 0.5 * Luma(Tex(1.0, tc, 3.0)) / 0.077, 0.7, 1.2);
#elif STYLE == 3
  // Concrete; its edges (where a face meets the mesh's bounds: a ramp's foot, sides and top edge,
  // the washboard's outline) a worn, lighter arris, and grime in a band just inside.
  vec3 albedo = Tex(2.0, tc, 3.0);
  vec2 to_bound = u_half_size - abs(v_uv);
  vec2 dir = u_frame.zw;
  float e = 1e3;  // to the nearest bound that lies within the face, m
  if (abs(dot(n_mesh.xy, dir)) < 0.7) e = min(e, to_bound.x);
  if (abs(dot(n_mesh.xy, vec2(-dir.y, dir.x))) < 0.7) e = min(e, to_bound.y);
  if (abs(n_mesh.z) < 0.7) e = min(e, min(v_pos.z - u_z_range.x, u_z_range.y - v_pos.z));
  float arris = 1.0 - clamp((e - 0.05) / max(fwidth(e), 1e-4) + 0.5, 0.0, 1.0);
  float grime = 1.0 - smoothstep(0.05, 0.5, e);
  albedo *= 1.0 + 0.45 * arris - 0.3 * grime * (1.0 - arris);
#elif STYLE == 4
  // Dirt and gravel, into the grass at the edge.
  vec3 dirt = Tex(3.0, tc, 3.0) * Variation(xy + vec2(17.0, 5.0));
  vec2 inside = u_half_size - abs(v_uv);
  float edge = min(inside.x, inside.y);
  vec3 albedo = mix(Grass(tc, length(to_eye)), dirt, smoothstep(0.5, 5.0, edge));
#elif STYLE == 5
  // Glass: posts every 3 m, a rail on top, a concrete foot.
  float along = abs(n.x) > abs(n.y) ? v_pos.y : v_pos.x;
  float post = Band(fract(along / 3.0 + 0.5) - 0.5, 0.06 / 3.0);
  float solid = clamp(post + step(0.7, n.z) + step(v_pos.z, 0.12), 0.0, 1.0);
  vec3 view = normalize(to_eye);
  float fres = pow(1.0 - abs(dot(n, view)), 5.0);
  vec3 albedo = mix(vec3(0.05, 0.08, 0.08), vec3(0.30, 0.31, 0.32), solid);
  add = (1.0 - solid) * SkyRadiance(reflect(-view, n)) * (0.08 + 0.8 * fres);
  alpha = mix(0.22 + 0.6 * fres, 1.0, solid);
#elif STYLE == 6
  vec3 albedo = vec3(0.55, 0.57, 0.59) * (0.85 + 0.3 * Luma(Tex(2.0, tc, 3.0)) / 0.38);
  // The poster (texture layer 5) on its face, front side only.
  if (u_poster_b.w > 0.5) {
    vec2 right = u_poster_b.xy;
    vec3 pn = vec3(right.y, -right.x, 0.0);
    vec3 d = v_pos - u_poster_a.xyz;
    vec2 puv = vec2(dot(d.xy, right) / u_poster_a.w, d.z / u_poster_b.z);
    float on = step(0.95, dot(normalize(v_normal), pn)) * step(abs(dot(d, pn)), 0.02) *
               step(0.0, puv.x) * step(puv.x, 1.0) * step(0.0, puv.y) * step(puv.y, 1.0);
    albedo = mix(albedo, texture(u_surfaces, vec3(puv.x, 1.0 - puv.y, 5.0)).rgb, on);
  }
#else
  vec3 albedo = Grass(tc, length(to_eye));
#endif
#ifdef SHADOWS
  float sun = SunVisibility(v_pos, n);
  vec3 c = albedo * Diffuse(n, sun) + add;
#else
  float sun = 1.0;
  vec3 c = albedo * v_light + add;
#endif
#if defined(HIGH) && (STYLE == 1 || STYLE == 2 || STYLE == 3 || STYLE == 6)
  // Asphalt, paint and concrete: rough dielectrics, a sheen towards the sun and the sky.
  c += WorldSpecular(n, normalize(to_eye), STYLE == 2 ? 0.55 : 0.75, sun);
#endif
#ifdef GRID
  vec2 g = xy / u_grid;
  vec2 w = fwidth(g);
  vec2 gd = abs(fract(g - 0.5) - 0.5) / max(w, vec2(1e-6));
  c *= 1.0 - 0.35 * (1.0 - clamp(min(gd.x, gd.y), 0.0, 1.0));
#endif
  o_colour = vec4(Output(mix(c, kHorizonRgb, FogOver(v_fog))), alpha);
}
)";

// --- models: car bodies, wheels ----------------------------------------------------------------

const char* const kModelVs = R"(
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec4 a_rgba;
layout(location = 3) in uint a_material;
uniform mat4 u_model;
uniform mat4 u_view_proj;
uniform vec3 u_paint;  // linear
uniform vec2 u_lights;  // the body's brake and reversing lights: 1 lit, 0 not
out vec3 v_pos;
out vec3 v_normal;
out vec3 v_albedo;
// The material (car_model.h: matte, paint, glass, chrome, rubber, headlight, tail light,
// reversing light) as numbers rather than branches: metallic, roughness, clear coat (a smooth
// lacquer over the paint), light of its own (the lamps: times kLit while lit).
flat out vec4 v_material;
const vec4 kMaterial[8] = vec4[8](vec4(0.0, 0.7, 0.0, 0.0),    // matte plastic
                                  vec4(0.0, 0.45, 1.0, 0.0),   // paint under a clear coat
                                  vec4(0.0, 0.03, 0.0, 0.0),   // tinted glass
                                  vec4(1.0, 0.12, 0.0, 0.0),   // chrome
                                  vec4(0.0, 0.85, 0.0, 0.0),   // rubber
                                  vec4(0.0, 0.3, 0.0, 0.9),    // headlight
                                  vec4(0.0, 0.3, 0.0, 0.3),    // tail light
                                  vec4(0.0, 0.3, 0.0, 0.15));  // reversing light
const float kLit = 14.0;  // a lit lamp's own light over an unlit one's
vec3 Decode(vec3 c) {
  return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(vec3(0.04045), c));
}
void main() {
  vec4 p = u_model * vec4(a_pos, 1.0);
  v_pos = p.xyz;
  v_normal = mat3(u_model) * a_normal;
  int m = int(min(a_material, 7u));
  v_albedo = Decode(a_rgba.rgb) * (m == 1 ? u_paint : vec3(1.0));
  v_material = kMaterial[m];
  float lit = m == 6 ? u_lights.x : (m == 7 ? u_lights.y : 0.0);
  v_material.w *= mix(1.0, kLit, lit);
  gl_Position = u_view_proj * p;
}
)";

// Metal/roughness shading lit by the sun and the sky: the base layer (a metal reflects in its
// own colour and has no diffuse part; a dielectric reflects 4 % at normal incidence, more at
// grazing angles), then the clear coat over the paint (F0 0.04, smooth: the sky's gradient and a
// sharp sun highlight). The inside of a body (a face seen from behind) is dark. Quality low: the
// sky's reflection along the mirror direction without the sun's highlight or the rough lobe.
const char* const kModelFs = R"(
in vec3 v_pos;
in vec3 v_normal;
in vec3 v_albedo;
flat in vec4 v_material;
out vec4 o_colour;
void main() {
  vec3 n = normalize(v_normal);
  vec3 v = normalize(u_eye - v_pos);
  float metal = v_material.x, rough = v_material.y, coat = v_material.z;
  float sun = SunVisibility(v_pos, n);
  float nv = max(dot(n, v), 1e-4);
  vec3 f0 = mix(vec3(0.04), v_albedo, metal);
  vec3 r = reflect(-v, n);
#ifdef HIGH
  vec2 ab = EnvBrdf(rough, nv);
  vec3 spec = f0 * ab.x + ab.y;
  vec3 c = v_albedo * (1.0 - metal) * (1.0 - spec) * Diffuse(n, sun) +
           SkySpecular(r, n, rough) * spec + SunSpecular(n, v, f0, rough, sun);
  // The clear coat takes its Fresnel share of the light off the layer beneath.
  float x = 1.0 - nv, x2 = x * x;
  float fc = coat * (0.04 + 0.96 * x2 * x2 * x);
  c = c * (1.0 - fc) + fc * SkySpecular(r, n, 0.03) + coat * SunSpecular(n, v, vec3(0.04), 0.2, sun);
#else
  float x = 1.0 - nv, x2 = x * x;
  vec3 spec = f0 + (max(vec3(1.0 - rough), f0) - f0) * (x2 * x2 * x);
  spec = max(spec, vec3(0.04 * coat));
  vec3 c = v_albedo * (1.0 - metal) * (1.0 - spec) * Diffuse(n, sun) + SkyRadiance(r) * spec;
#endif
  vec3 own = gl_FrontFacing ? v_albedo * v_material.w : vec3(0.0);
  c = gl_FrontFacing ? c : vec3(0.012);
  o_colour = vec4(FinishOwn(c, own, v_pos), 1.0);
}
)";

// --- the frame's lists: landmarks (lit), arrows (unlit, exact colours) -------------------------

const char* const kListVs = R"(
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec4 a_colour;
uniform mat4 u_view_proj;
out vec3 v_pos;
out vec3 v_normal;
out vec4 v_colour;
void main() {
  v_pos = a_pos;
  v_normal = a_normal;
  v_colour = a_colour;
  gl_Position = u_view_proj * vec4(a_pos, 1.0);
}
)";

// A zero normal means unlit: the arrows keep the legend's exact colours.
const char* const kListFs = R"(
in vec3 v_pos;
in vec3 v_normal;
in vec4 v_colour;
uniform float u_alpha;
out vec4 o_colour;
void main() {
  vec4 c = v_colour;
  float len = length(v_normal);
  if (len > 0.5) {
    vec3 n = v_normal / len;
    if (dot(n, u_eye - v_pos) < 0.0) n = -n;
    c.rgb = Finish(Decode(c.rgb) * Diffuse(n, SunVisibility(v_pos, n)), v_pos);
  }
  c.a *= u_alpha;
  o_colour = c;
}
)";

// --- sky ---------------------------------------------------------------------------------------

// The view ray through a point of the screen, from the near plane to the far one: linear over
// the screen (perspective or orthographic), so the vertices' rays interpolate exactly.
const char* const kSkyVs = R"(
uniform mat4 u_inv_view_proj;
out vec3 v_ray;
void main() {
  vec2 p = vec2((gl_VertexID == 1) ? 3.0 : -1.0, (gl_VertexID == 2) ? 3.0 : -1.0);
  vec4 a = u_inv_view_proj * vec4(p, -1.0, 1.0);
  vec4 b = u_inv_view_proj * vec4(p, 1.0, 1.0);
  v_ray = b.xyz / b.w - a.xyz / a.w;
  gl_Position = vec4(p, 1.0, 1.0);
}
)";

// The gradient from the horizon's haze to the zenith, the sun and its glow, a band of far hills
// in the haze, and (quality high) clouds.
const char* const kSkyFs = R"(
in vec3 v_ray;
uniform sampler2D u_clouds;
out vec4 o_colour;
void main() {
  vec3 dir = normalize(v_ray);
  vec3 c = SkyRadiance(dir);
  // The glow's powers by squaring (s^8, and s^200 = (s^64)^3 s^8): cheaper than pow.
  float s = max(dot(dir, kSunDir), 0.0);
  float s2 = s * s, s4 = s2 * s2, s8 = s4 * s4, s16 = s8 * s8, s32 = s16 * s16, s64 = s32 * s32;
  float s200 = s64 * s64 * s64 * s8;
  c += kSunRgb * (0.18 * s8 + 0.5 * s200) + vec3(6.0) * smoothstep(0.99955, 0.9997, s);
#ifdef CLOUDS
  if (dir.z > 0.0) {
    vec2 uv = dir.xy / (dir.z + 0.08) * 0.35 + vec2(0.13, 0.41);
    vec4 cl = texture(u_clouds, uv);
    float cover = cl.a * smoothstep(0.0, 0.15, dir.z);
    vec3 lit = cl.rgb * (0.55 * kSunRgb + 1.3 * kSkyRgb);
    c = mix(c, lit, 0.9 * cover);
  }
#endif
  o_colour = vec4(Output(c), 1.0);
}
)";

// --- far hills: a ring of low hills in the haze, around the eye near the far plane -------------

const char* const kHillsVs = R"(
layout(location = 0) in vec3 a_dir;  // cos, sin of the azimuth; elevation angle, rad
uniform mat4 u_view_proj;
uniform vec3 u_eye;
uniform float u_radius;
out float v_height;
void main() {
  v_height = a_dir.z;
  vec3 p = u_eye + vec3(a_dir.xy * u_radius, tan(a_dir.z) * u_radius);
  gl_Position = u_view_proj * vec4(p, 1.0);
}
)";

const char* const kHillsFs = R"(
in float v_height;
out vec4 o_colour;
void main() {
  vec3 hills = mix(vec3(0.10, 0.15, 0.12), kHorizonRgb, 0.6 + 8.0 * max(v_height, 0.0));
  o_colour = vec4(Output(hills), 1.0);
}
)";

// --- contact shadows under the vehicles, and the mirrors: a textured quad in the world -----------

const char* const kWorldQuadVs = R"(
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec2 a_uv;
uniform mat4 u_view_proj;
out vec2 v_uv;
void main() {
  v_uv = a_uv;
  gl_Position = u_view_proj * vec4(a_pos, 1.0);
}
)";

// Multiplies what is behind (blend: zero, source colour): darkest under the middle of the body.
const char* const kContactFs = R"(
in vec2 v_uv;
uniform float u_strength;
out vec4 o_colour;
void main() {
  vec2 q = abs(v_uv);
  float k = (1.0 - smoothstep(0.55, 1.0, q.x)) * (1.0 - smoothstep(0.35, 1.0, q.y));
  o_colour = vec4(vec3(1.0 - u_strength * k), 1.0);
}
)";

// --- the cockpit's mirrors (vertex shader: kWorldQuadVs) -------------------------------------

// The mirror's image, already encoded for the screen; the glass reflects 85 % of the light.
const char* const kMirrorFs = R"(
in vec2 v_uv;
uniform sampler2D u_image;
out vec4 o_colour;
void main() {
  vec3 c = texture(u_image, v_uv).rgb;
  o_colour = vec4(Encode(0.85 * Decode(c)), 1.0);
}
)";

// --- the sun's shadow map ----------------------------------------------------------------------

const char* const kDepthVs = R"(
layout(location = 0) in vec3 a_pos;
uniform mat4 u_model;
uniform mat4 u_view_proj;
void main() { gl_Position = u_view_proj * (u_model * vec4(a_pos, 1.0)); }
)";

const char* const kDepthFs = R"(
void main() {}
)";

}  // namespace shaders
}  // namespace vdyn::viewer
