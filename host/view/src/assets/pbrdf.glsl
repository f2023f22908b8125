// pbrdf.glsl — a port of ellipso_model::optics to GLSL ES 3.00 (single precision).
//
// Same equations, same order of operations, same clamps as the Rust model:
//   fresnel.rs     FresnelTerms::dielectric (conjugate-denominator forms, R− without cancellation)
//   microfacet.rs  ggx_d, smith_g1, smith_g1_over_cos, microfacet_weight (cosine forms)
//   frame.rs       Frame::from_z_up (light: z = −ω_i, camera: z = ω_o), rotator_to_axis
//   stokes.rs      Rotator::from_direction / apply / apply_row (C(θ) as cos2θ, sin2θ)
//   pbrdf.rs       Geometry, reflection_axis, diffuse_unit, reflection_unit, lobe_weight
// Checked against the Rust model (f64) on a seeded grid by the page /check and the test
// `view_browser::shader_port_matches_the_rust_model`: max |ΔM|/max|M| ≤ 1e-3 (docs/view.md).
// Matrices are GLSL mat4 (column-major): element (row i, column j) is M[j][i]; M * s applies.

const float PI = 3.14159265358979;
const float ALPHA_MIN = 1e-6;
const float DIRECTION_EPS_SQ = 1e-24;

struct Fresnel { float r_s; float r_p; float t_s; float t_p; float r_minus; };

Fresnel fresnel(float cos_theta, float eta_in) {
    float c = clamp(cos_theta, 0.0, 1.0);
    float eta = max(eta_in, 1.0);
    float eta_sq = eta * eta;
    float eta_sq_m1 = (eta - 1.0) * (eta + 1.0);
    float q_sq = eta_sq_m1 + c * c;
    float q = q_sq > 0.0 ? sqrt(q_sq) : c;
    float den_s = c + q;
    float den_p = eta_sq * c + q;
    if (den_s <= 0.0 || den_p <= 0.0) {
        return Fresnel(0.0, 0.0, 1.0, 1.0, 0.0);
    }
    float sin_sq = (1.0 - c) * (1.0 + c);
    float u = eta_sq_m1 / den_s / den_p;
    Fresnel f;
    f.r_s = -(eta_sq_m1 / den_s) / den_s;
    f.r_p = (eta_sq_m1 / den_p) * (((eta_sq + 1.0) * c * c - 1.0) / den_p);
    f.t_s = (4.0 * c / den_s) * (q / den_s);
    f.t_p = (4.0 * eta_sq * c / den_p) * (q / den_p);
    f.r_minus = 2.0 * c * q * sin_sq * u * u;
    return f;
}
float r_plus(Fresnel f) { return (f.r_s * f.r_s + f.r_p * f.r_p) * 0.5; }
float r_cross(Fresnel f) { return f.r_s * f.r_p; }
float t_plus(Fresnel f) { return (f.t_s + f.t_p) * 0.5; }
float t_minus(Fresnel f) { return -f.r_minus; }

float ggx_d(float cos_theta_h, float alpha) {
    if (cos_theta_h < 0.0) return 0.0;
    float c = min(cos_theta_h, 1.0);
    float a = max(alpha, ALPHA_MIN);
    float a2 = a * a;
    float sin2 = (1.0 - c) * (1.0 + c);
    float den = a2 * c * c + sin2;
    return a2 / (PI * den * den);
}
float smith_g1_over_cos(float cos_theta, float alpha) {
    if (cos_theta < 0.0) return 0.0;
    float c = min(cos_theta, 1.0);
    float a = max(alpha, ALPHA_MIN);
    float a2 = a * a;
    float root = sqrt(max(a2 + (1.0 - a2) * c * c, 0.0));
    return 2.0 / (c + root);
}
float smith_g1(float cos_theta, float alpha) {
    if (cos_theta < 0.0) return 0.0;
    float c = min(cos_theta, 1.0);
    return c * smith_g1_over_cos(c, alpha);
}
float microfacet_weight(float ci, float co, float ch, float alpha) {
    return ggx_d(ch, alpha) * smith_g1(ci, alpha) * smith_g1_over_cos(co, alpha) * 0.25;
}

struct Frame { vec3 x; vec3 y; vec3 z; };

// Frame::from_z_up: y = up orthogonalised against z, x = y × z; fallback up = the world axis
// least aligned with z.
Frame frame_from_z_up(vec3 z_in, vec3 up) {
    vec3 z = normalize(z_in);
    float scale = dot(up, up);
    vec3 u = up - z * dot(up, z);
    vec3 y;
    if (dot(u, u) > 1e-12 * scale && scale > 0.0) {
        y = normalize(u);
    } else {
        vec3 a = abs(z);
        vec3 axis = (a.x <= a.y && a.x <= a.z) ? vec3(1, 0, 0) : (a.y <= a.z ? vec3(0, 1, 0) : vec3(0, 0, 1));
        y = normalize(axis - z * dot(axis, z));
    }
    return Frame(cross(y, z), y, z);
}

// Rotator::from_direction → (cos2θ, sin2θ); (1, 0) where the direction vanishes.
vec2 rotator_from_direction(float c, float s, float min_norm_sq) {
    float n2 = c * c + s * s;
    if (!(n2 > min_norm_sq && n2 > 0.0)) return vec2(1.0, 0.0);
    float m = max(abs(c), abs(s));
    c /= m;
    s /= m;
    float inv = 1.0 / (c * c + s * s);
    return vec2((c * c - s * s) * inv, (c * s + c * s) * inv);
}
vec2 rotator_to_axis(Frame f, vec3 axis) {
    float scale = dot(axis, axis);
    return rotator_from_direction(dot(f.x, axis), dot(f.y, axis), DIRECTION_EPS_SQ * scale);
}

struct Geometry {
    vec3 n; vec3 wi; vec3 wo; Frame light; Frame camera; vec3 h;
    float ci; float co; float ch; float cd; bool front;
};

Geometry make_geometry(vec3 normal, vec3 to_light, vec3 to_camera, vec3 light_up, vec3 camera_up) {
    Geometry g;
    g.n = normalize(normal);
    g.wi = normalize(to_light);
    g.wo = normalize(to_camera);
    g.light = frame_from_z_up(-g.wi, light_up);
    g.camera = frame_from_z_up(g.wo, camera_up);
    vec3 hs = g.wi + g.wo;
    g.h = dot(hs, hs) > DIRECTION_EPS_SQ ? normalize(hs) : g.n;
    float raw_i = dot(g.n, g.wi);
    float raw_o = dot(g.n, g.wo);
    g.ci = clamp(raw_i, 0.0, 1.0);
    g.co = clamp(raw_o, 0.0, 1.0);
    g.ch = clamp(dot(g.n, g.h), 0.0, 1.0);
    g.cd = clamp(dot(g.h, g.wi), 0.0, 1.0);
    g.front = raw_i >= 0.0 && raw_o >= 0.0;
    return g;
}

vec3 reflection_axis(Geometry g) {
    vec3 s = cross(g.wi, g.wo);
    return dot(s, s) > DIRECTION_EPS_SQ ? s : g.camera.x;
}

// rows given as in the Rust code (row-major); returns the GLSL matrix
mat4 from_rows(vec4 r0, vec4 r1, vec4 r2, vec4 r3) { return transpose(mat4(r0, r1, r2, r3)); }

// C_out · [[a b 0 0][b a 0 0][0 0 c 0][0 0 0 c]] · C_in (pbrdf.rs rotated_symmetric)
mat4 rotated_symmetric(float a, float b, float c, vec2 rin, vec2 rout) {
    float ci = rin.x, si = rin.y, co = rout.x, so = rout.y;
    vec4 row0 = vec4(a, b * ci, b * si, 0.0);
    vec4 row1 = vec4(b, a * ci, a * si, 0.0);
    vec4 row2 = vec4(0.0, -c * si, c * ci, 0.0);
    return from_rows(row0, co * row1 + so * row2, -so * row1 + co * row2, vec4(0, 0, 0, c));
}

// C_{h→o} F^R(θ_d) C_{i→h} (unit weight)
mat4 reflection_unit(Geometry g, float eta) {
    if (!g.front) return mat4(0.0);
    Fresnel f = fresnel(g.cd, eta);
    vec3 s = reflection_axis(g);
    vec2 rin = rotator_to_axis(g.light, s);
    vec2 rout = rotator_to_axis(g.camera, s) * vec2(1.0, -1.0);
    return rotated_symmetric(r_plus(f), f.r_minus, r_cross(f), rin, rout);
}

float lobe_weight(Geometry g, float sigma) {
    if (!g.front) return 0.0;
    return microfacet_weight(g.ci, g.co, g.ch, sigma);
}

// P^d with ρ_d = 1: C_{n→o}[T_o+, T_o−, 0, 0]ᵀ [T_i+, T_i−, 0, 0] C_{i→n} · cosθ_i
mat4 diffuse_unit(Geometry g, float eta) {
    if (!g.front) return mat4(0.0);
    Fresnel fi = fresnel(g.ci, eta);
    Fresnel fo = fresnel(g.co, eta);
    vec2 rin = rotator_to_axis(g.light, cross(g.wi, g.n));
    vec2 rout = rotator_to_axis(g.camera, cross(g.wo, g.n)) * vec2(1.0, -1.0);
    // Rotator::apply_row on [T+, T−, 0, 0]
    vec4 row = vec4(t_plus(fi), t_minus(fi) * rin.x, t_minus(fi) * rin.y, 0.0);
    // Rotator::apply on [T+, T−, 0, 0]
    vec4 col = vec4(t_plus(fo), rout.x * t_minus(fo), -rout.y * t_minus(fo), 0.0);
    return outerProduct(col, row) * g.ci;
}

// The total P per colour channel: P_c = ρ_d,c·D + (ρ_s·w_s + ρ_ss,c·w_ss)·R
struct Lobes { mat4 diffuse; mat4 reflection; float w_s; float w_ss; };

Lobes evaluate_lobes(Geometry g, float eta, float sigma_s, float sigma_ss) {
    Lobes l;
    l.diffuse = diffuse_unit(g, eta);
    l.reflection = reflection_unit(g, eta);
    l.w_s = lobe_weight(g, sigma_s);
    l.w_ss = lobe_weight(g, sigma_ss);
    return l;
}

mat4 total_channel(Lobes l, float rho_d, float rho_s, float rho_ss) {
    return l.diffuse * rho_d + l.reflection * (rho_s * l.w_s + rho_ss * l.w_ss);
}
