/* Rokeby viewport preview: the per-pixel edited reflection e(q) = R_a(q) r(q) (Ritschel et al.
 * 2009, eqs. 5-7, §6.1) and the environment lookup in direction e.
 *
 * This is the GLSL twin of rokeby_native.edited_directions (rust/rokeby-core/src/field.rs,
 * polar.rs, region.rs) and follows it case by case:
 *   - K = 0, or regions of which none holds a constraint: e = r (the physical reflection).
 *   - A group (all constraints, or those inside one region) with one constraint: the smallest
 *     rotation r_n -> e_n, everywhere; a half turn (e_n = -r_n) about the axis glam's
 *     any_orthonormal_vector picks.
 *   - w_n = 1/d_n^2, accumulated normalised by the running minimum of d^2 (float32 has no room
 *     for 1/d^2 near a constraint); d = +inf (unreachable) weighs 0; all unreachable: identity.
 *   - q on constraints (d = 0): those act with equal weights, the others only choose the twist.
 *   - M numerically rank 1: the smallest rotation v1 -> u1, twisted about u1 as the remaining
 *     constraints prefer (the limit of the field, as in polar::ortho_tiebreak).
 *   - Otherwise ortho(M) by Horn's quaternion method: the eigenvector of the largest eigenvalue
 *     of a symmetric 4x4 matrix, by cyclic Jacobi. Unique for rank 2 and 3, so it is the answer
 *     of both Rust methods ("exact" SVD and "fast" Newton) up to float32 rounding.
 *   - Regions (eq. 7): ortho(sum_j a_j R_j + (1 - min(1, sum_j a_j)) r r^T); one region at full
 *     weight returns its R_j directly.
 *
 * Globals it reads (declared by the stage wrapper's create-info or header):
 *   RokebyField rk_field (uniform block), sampler2D rk_vertex_data, sampler2D rk_env.
 * Quaternions are vec4(x, y, z, w).
 */

#define RK_PI 3.14159265358979

float rk_inf()
{
  return uintBitsToFloat(0x7F800000u);
}

vec4 rk_quat_identity()
{
  return vec4(0.0, 0.0, 0.0, 1.0);
}

vec4 rk_quat_mul(vec4 a, vec4 b)
{
  return vec4(a.w * b.xyz + b.w * a.xyz + cross(a.xyz, b.xyz), a.w * b.w - dot(a.xyz, b.xyz));
}

vec3 rk_quat_rotate(vec4 q, vec3 v)
{
  vec3 t = 2.0 * cross(q.xyz, v);
  return v + q.w * t + cross(q.xyz, t);
}

mat3 rk_quat_to_mat3(vec4 q)
{
  float x = q.x, y = q.y, z = q.z, w = q.w;
  /* columns */
  return mat3(vec3(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
              vec3(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
              vec3(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)));
}

vec4 rk_axis_angle(vec3 axis, float angle)
{
  return vec4(axis * sin(0.5 * angle), cos(0.5 * angle));
}

/* glam's DVec3::any_orthonormal_vector (Duff et al. 2017); signum(0) = +1 as in Rust. */
vec3 rk_any_orthonormal(vec3 v)
{
  float s = v.z >= 0.0 ? 1.0 : -1.0;
  float a = -1.0 / (s + v.z);
  float b = v.x * v.y * a;
  return vec3(b, s + v.y * v.y * a, -v.y);
}

/* The smallest rotation taking unit `from` to unit `to` (polar::min_rotation). */
vec4 rk_min_rotation(vec3 from, vec3 to)
{
  float c = dot(from, to);
  vec3 v = cross(from, to);
  float s = length(v);
  if (s < 1e-7) {
    if (c > 0.0) {
      return rk_quat_identity();
    }
    return vec4(rk_any_orthonormal(from), 0.0);
  }
  return rk_axis_angle(v / s, atan(s, c));
}

/* a b^T */
mat3 rk_outer(vec3 a, vec3 b)
{
  return mat3(a * b.x, a * b.y, a * b.z);
}

float rk_frobenius2(mat3 m)
{
  return dot(m[0], m[0]) + dot(m[1], m[1]) + dot(m[2], m[2]);
}

/* sigma2 / sigma1 below about 1e-5: the cofactor matrix (pairwise cross products of the
 * columns) has norm ~ sigma1 sigma2, M has norm ~ sigma1. Float32 cannot resolve the twist of
 * such an M; its remaining constraints decide it, as in Rust. */
bool rk_rank_one(mat3 m)
{
  vec3 c0 = cross(m[0], m[1]), c1 = cross(m[1], m[2]), c2 = cross(m[2], m[0]);
  float cof2 = dot(c0, c0) + dot(c1, c1) + dot(c2, c2);
  float f2 = rk_frobenius2(m);
  return cof2 <= 1e-10 * f2 * f2;
}

/* Rotation about unit `u` maximising tr(T^T C) (polar::best_twist). */
vec4 rk_best_twist(vec3 u, mat3 c)
{
  float utcu = dot(u, c * u);
  float tr = c[0][0] + c[1][1] + c[2][2];
  /* C_ij = c[j][i] */
  float s = u.x * (c[1][2] - c[2][1]) + u.y * (c[2][0] - c[0][2]) + u.z * (c[0][1] - c[1][0]);
  float a = tr - utcu;
  if (abs(a) + abs(s) <= 1e-6 * sqrt(rk_frobenius2(c))) {
    return rk_quat_identity();
  }
  return rk_axis_angle(u, atan(s, a));
}

/* Rank-1 `m` (nonzero): the smallest rotation v1 -> u1, twisted about u1 to fit `b`
 * (polar::ortho_tiebreak's rank-1 branch). */
vec4 rk_rank_one_rotation(mat3 m, mat3 b, bool use_b)
{
  /* m ~ sigma u v^T: its longest column is +-u; m^T u1 then points along the matching v. */
  float l0 = dot(m[0], m[0]), l1 = dot(m[1], m[1]), l2 = dot(m[2], m[2]);
  vec3 col = l0 >= l1 && l0 >= l2 ? m[0] : (l1 >= l2 ? m[1] : m[2]);
  vec3 u1 = normalize(col);
  vec3 v1 = normalize(transpose(m) * u1);
  vec4 r0 = rk_min_rotation(v1, u1);
  if (!use_b) {
    return r0;
  }
  mat3 c = b * transpose(rk_quat_to_mat3(r0));
  return normalize(rk_quat_mul(rk_best_twist(u1, c), r0));
}

/* One Jacobi rotation of the symmetric 4x4 `a`, zeroing a_pq; `v` accumulates eigenvectors.
 * A' = J^T A J touches only rows and columns p and q (called with constant p, q). */
void rk_jacobi(inout mat4 a, inout mat4 v, int p, int q)
{
  float apq = a[q][p];
  if (apq == 0.0) {
    return;
  }
  float theta = (a[q][q] - a[p][p]) / (2.0 * apq);
  float t = (theta >= 0.0 ? 1.0 : -1.0) / (abs(theta) + sqrt(theta * theta + 1.0));
  float c = inversesqrt(t * t + 1.0);
  float s = t * c;
  vec4 ap = a[p], aq = a[q];
  a[p] = c * ap - s * aq;
  a[q] = s * ap + c * aq;
  /* rows p and q, column by column (no loop: keeps every index constant) */
  float b0p = a[0][p], b0q = a[0][q], b1p = a[1][p], b1q = a[1][q];
  float b2p = a[2][p], b2q = a[2][q], b3p = a[3][p], b3q = a[3][q];
  a[0][p] = c * b0p - s * b0q;
  a[0][q] = s * b0p + c * b0q;
  a[1][p] = c * b1p - s * b1q;
  a[1][q] = s * b1p + c * b1q;
  a[2][p] = c * b2p - s * b2q;
  a[2][q] = s * b2p + c * b2q;
  a[3][p] = c * b3p - s * b3q;
  a[3][q] = s * b3p + c * b3q;
  vec4 vp = v[p], vq = v[q];
  v[p] = c * vp - s * vq;
  v[q] = s * vp + c * vq;
}

/* ortho(M) for rank >= 2 by Horn's method: max tr(R^T M) = max over unit quaternions of
 * q^T N q, with N built from S = M^T (quaternion order w, x, y, z in N). */
vec4 rk_ortho_horn(mat3 m)
{
  /* S_ab = M_ba = m[a][b] */
  float sxx = m[0][0], sxy = m[0][1], sxz = m[0][2];
  float syx = m[1][0], syy = m[1][1], syz = m[1][2];
  float szx = m[2][0], szy = m[2][1], szz = m[2][2];
  mat4 n = mat4(vec4(sxx + syy + szz, syz - szy, szx - sxz, sxy - syx),
                vec4(syz - szy, sxx - syy - szz, sxy + syx, szx + sxz),
                vec4(szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy),
                vec4(sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz));
  mat4 v = mat4(1.0);
  float scale2 = dot(n[0], n[0]) + dot(n[1], n[1]) + dot(n[2], n[2]) + dot(n[3], n[3]);
  for (int sweep = 0; sweep < 8; sweep++) {
    float off = n[1][0] * n[1][0] + n[2][0] * n[2][0] + n[3][0] * n[3][0] + n[2][1] * n[2][1] +
                n[3][1] * n[3][1] + n[3][2] * n[3][2];
    if (off <= 1e-14 * scale2) {
      break;
    }
    rk_jacobi(n, v, 0, 1);
    rk_jacobi(n, v, 0, 2);
    rk_jacobi(n, v, 0, 3);
    rk_jacobi(n, v, 1, 2);
    rk_jacobi(n, v, 1, 3);
    rk_jacobi(n, v, 2, 3);
  }
  vec4 e = v[0];
  float top = n[0][0];
  if (n[1][1] > top) {
    top = n[1][1];
    e = v[1];
  }
  if (n[2][2] > top) {
    top = n[2][2];
    e = v[2];
  }
  if (n[3][3] > top) {
    e = v[3];
  }
  e = normalize(e);
  vec4 q = vec4(e.y, e.z, e.w, e.x);
  return q.w < 0.0 ? -q : q;
}

/* ortho(M), completed by the tie-break B where M is rank 1 (polar::ortho_tiebreak):
 * M = 0 -> ortho(B) without tie-break; rank 1 -> smallest rotation v1 -> u1 twisted to fit B;
 * rank >= 2 -> Horn. One function for every use, so the shader holds one copy of each path
 * (a CPU rasteriser such as llvmpipe runs both sides of a branch). */
vec4 rk_ortho_tiebreak(mat3 m, mat3 b)
{
  bool use_b = rk_frobenius2(b) > 0.0;
  if (!(rk_frobenius2(m) > 0.0)) {
    m = b;
    use_b = false;
  }
  if (!(rk_frobenius2(m) > 0.0)) {
    return rk_quat_identity();
  }
  if (rk_rank_one(m)) {
    return rk_rank_one_rotation(m, b, use_b);
  }
  return rk_ortho_horn(m);
}

/* ---- per-vertex data: distances, region weights, rotation vectors, in one RGBA32F texture ---- */

float rk_vertex_value(int vid, int slot)
{
  int texel = vid * rk_field.counts.w + (slot >> 2);
  int width = rk_field.vlayout.w;
  vec4 t = texelFetch(rk_vertex_data, ivec2(texel % width, texel / width), 0);
  return dot(t, vec4(equal(ivec4(slot & 3), ivec4(0, 1, 2, 3))));
}

/* Linear interpolation over the triangle (the paper's "smooth shading" of per-vertex values);
 * +inf at a corner (unreachable: another connected component) stays +inf. */
float rk_interpolate(ivec3 vids, vec3 bary, int slot)
{
  float a = rk_vertex_value(vids.x, slot);
  float b = rk_vertex_value(vids.y, slot);
  float c = rk_vertex_value(vids.z, slot);
  if (isinf(a) || isinf(b) || isinf(c)) {
    return rk_inf();
  }
  return bary.x * a + bary.y * b + bary.z * c;
}

/* d(p_n, q)^2 */
float rk_distance2(int n, vec3 q, ivec3 vids, vec3 bary)
{
  if (rk_field.counts.z == RK_DIST_PER_VERTEX) {
    float d = rk_interpolate(vids, bary, rk_field.vlayout.x + n);
    return d * d;
  }
  vec3 dq = q - rk_field.cp[n].xyz;
  return dot(dq, dq);
}

bool rk_member(int g, int n)
{
  if (rk_field.counts.y == 0) {
    return true;
  }
  uvec4 m = rk_field.region_members[g];
  uint word = n < 32 ? m.x : (n < 64 ? m.y : (n < 96 ? m.z : m.w));
  return ((word >> uint(n & 31)) & 1u) != 0u;
}

int rk_group_size(int g)
{
  return rk_field.counts.y == 0 ? rk_field.counts.x : int(rk_field.region_b[g].w);
}

mat3 rk_er(int n)
{
  return rk_outer(rk_field.ce[n].xyz, rk_field.cr[n].xyz);
}

/* Eq. 5 for group g (all constraints, or those of region g) at q (Field::solve_group), in one
 * pass over the constraints. With dmin^2 the running minimum of d^2, it keeps
 *   near = e r^T of the (first) nearest constraint, weight 1,
 *   rest = sum of the others' e r^T dmin^2 / d^2 (summed apart: M minus the nearest term cancels),
 *   m0   = sum of e r^T of constraints at distance 0 (q on them: interpolation),
 * so M = near + rest, and the tie-breaks need no second pass. */
vec4 rk_solve_group(int g, vec3 q, ivec3 vids, vec3 bary)
{
  int k = rk_field.counts.x;
  mat3 near = mat3(0.0), rest = mat3(0.0), m0 = mat3(0.0);
  float dmin2 = rk_inf();
  int members = 0;
  vec3 r1 = vec3(0.0), e1 = vec3(0.0);
  for (int n = 0; n < k; n++) {
    if (!rk_member(g, n)) {
      continue;
    }
    members += 1;
    r1 = rk_field.cr[n].xyz;
    e1 = rk_field.ce[n].xyz;
    mat3 er = rk_outer(e1, r1);
    float x = rk_distance2(n, q, vids, bary);
    if (x == 0.0) {
      m0 += er;
    }
    else if (x < dmin2) {
      /* dmin2 = inf: near and rest are still zero */
      rest = (rest + near) * (x / dmin2);
      near = er;
      dmin2 = x;
    }
    else if (!isinf(x)) {
      rest += er * (dmin2 / x);
    }
  }
  if (members == 1) {
    /* One constraint: the smallest rotation r_n -> e_n everywhere (incl. the half turn). */
    return rk_min_rotation(r1, e1);
  }
  bool on_constraint = rk_frobenius2(m0) > 0.0;
  if (!on_constraint && isinf(dmin2)) {
    return rk_quat_identity(); /* no constraint of this group reaches q */
  }
  /* On constraints: those act with equal weights, the others only break a rank-1 tie.
   * Elsewhere: M = near + rest; where it is rank 1 the rest decides the twist. */
  return on_constraint ? rk_ortho_tiebreak(m0, near + rest) : rk_ortho_tiebreak(near + rest, rest);
}

float rk_falloff(float d, float radius, float border)
{
  border = min(border, radius);
  if (d >= radius) {
    return 0.0;
  }
  float inner = radius - border;
  if (d <= inner) {
    return 1.0;
  }
  float t = clamp((d - inner) / border, 0.0, 1.0);
  return 1.0 - t * t * (3.0 - 2.0 * t);
}

/* a_g(q) (Region::at_point) */
float rk_region_weight(int g, vec3 q, ivec3 vids, vec3 bary)
{
  vec4 a = rk_field.region_a[g];
  vec4 b = rk_field.region_b[g];
  if (a.w == 0.0) {
    return rk_falloff(distance(q, a.xyz), b.x, b.y);
  }
  return rk_interpolate(vids, bary, rk_field.vlayout.y + int(b.z));
}

/* R_a(q) (Field::rotation_at) for the physical reflection r at q. Without regions the one
 * group of all constraints acts with weight 1. */
vec4 rk_rotation(vec3 q, vec3 r, ivec3 vids, vec3 bary)
{
  if (rk_field.counts.x == 0) {
    return rk_quat_identity();
  }
  int regions = rk_field.counts.y;
  mat3 acc = mat3(0.0);
  float asum = 0.0;
  int count = 0;
  vec4 last = rk_quat_identity();
  for (int g = 0; g < max(regions, 1); g++) {
    float a = regions == 0 ? 1.0 : rk_region_weight(g, q, vids, bary);
    if (a <= 0.0) {
      continue;
    }
    vec4 rg = rk_solve_group(g, q, vids, bary);
    acc += rk_quat_to_mat3(rg) * a;
    asum += a;
    count += 1;
    last = rg;
  }
  if (count == 0) {
    return rk_quat_identity();
  }
  if (count == 1 && asum >= 1.0) {
    return last;
  }
  float rest = 1.0 - min(1.0, asum);
  if (rest > 0.0) {
    acc += rk_outer(r, r) * rest;
  }
  return rk_ortho_tiebreak(acc, mat3(0.0));
}

/* The fallback: the stored field (rotation vectors, axis x angle), interpolated per pixel. */
vec4 rk_rotation_per_vertex(ivec3 vids, vec3 bary)
{
  int o = rk_field.vlayout.z;
  vec3 rv = vec3(rk_interpolate(vids, bary, o), rk_interpolate(vids, bary, o + 1),
                 rk_interpolate(vids, bary, o + 2));
  float angle = length(rv);
  return angle > 0.0 ? rk_axis_angle(rv / angle, angle) : rk_quat_identity();
}

/* r(q) = reflect(i, n), i from the eye (w = 1) or along a fixed view direction (w = 0). */
vec3 rk_physical_reflection(vec3 q, vec3 n)
{
  vec3 i = rk_field.eye.w != 0.0 ? normalize(q - rk_field.eye.xyz) : -normalize(rk_field.eye.xyz);
  n = normalize(n);
  return normalize(i - 2.0 * dot(i, n) * n);
}

/* e(q) */
vec3 rokeby_edited_direction(vec3 q, vec3 n, ivec3 vids, vec3 bary)
{
  vec3 r = rk_physical_reflection(q, n);
  vec4 rot = rk_field.counts.z == RK_PER_VERTEX_FIELD ? rk_rotation_per_vertex(vids, bary) :
                                                          rk_rotation(q, r, vids, bary);
  return normalize(rk_quat_rotate(rot, r));
}

/* Blender's equirectangular convention, as its Environment Texture node computes it
 * (node_tex_environment_equirectangular, and Cycles' direction_to_equirectangular):
 * u = 0.5 - atan2(d.y, d.x) / 2pi, v = 0.5 + atan2(d.z, hypot(d.x, d.y)) / pi; +X at the image
 * centre, +Y at u = 0.25, -X on the seam; image row 0 (v = 0) at the bottom. */
vec2 rokeby_equirect_uv(vec3 d)
{
  d = normalize(d);
  return vec2(0.5 - atan(d.y, d.x) / (2.0 * RK_PI), atan(d.z, length(d.xy)) / RK_PI + 0.5);
}

/* Without an image: a sky and ground with a 15-degree grid, so that edits are visible. */
vec3 rk_builtin_sky(vec3 d)
{
  d = normalize(d);
  vec3 sky = mix(vec3(0.65, 0.75, 0.9), vec3(0.15, 0.3, 0.7), clamp(d.z, 0.0, 1.0));
  vec3 ground = mix(vec3(0.35, 0.3, 0.25), vec3(0.1, 0.09, 0.08), clamp(-d.z, 0.0, 1.0));
  vec3 c = d.z >= 0.0 ? sky : ground;
  vec2 uv = rokeby_equirect_uv(d) * vec2(24.0, 12.0);
  vec2 f = abs(fract(uv) - 0.5);
  float line = step(0.47, max(f.x, f.y));
  return mix(c, vec3(0.95), 0.5 * line);
}

/* ---- the scene captured from the mirror (RK_ENV_SCENE) ----
 * rk_env holds a lat-long panorama taken from rk_field.env_origin: linear RGB, and 1/distance of
 * what each texel sees (0: the world, at infinity). Fetched texel by texel and filtered here
 * (bilinear, wrapping around the seam, clamped at the poles) so that every GPU and sampler
 * state gives the same result. */

/* Bilinear texel of direction d. Where the world is seen (1/distance = 0) and the world's own
 * lat-long image is bound (rk_world, scaled to the capture by world_scale), that image stands in
 * for the world's texels: it is sharper than the capture and free of its noise. */
vec4 rk_scene_texel(vec3 d)
{
  ivec2 size = textureSize(rk_env, 0);
  vec2 uv = rokeby_equirect_uv(d);
  vec2 st = uv * vec2(size) - 0.5;
  vec2 f = fract(st);
  ivec2 i0 = ivec2(floor(st));
  int x0 = (i0.x % size.x + size.x) % size.x;
  int x1 = (x0 + 1) % size.x;
  int y0 = clamp(i0.y, 0, size.y - 1);
  int y1 = clamp(i0.y + 1, 0, size.y - 1);
  vec4 t00 = texelFetch(rk_env, ivec2(x0, y0), 0);
  vec4 t10 = texelFetch(rk_env, ivec2(x1, y0), 0);
  vec4 t01 = texelFetch(rk_env, ivec2(x0, y1), 0);
  vec4 t11 = texelFetch(rk_env, ivec2(x1, y1), 0);
  vec4 w = vec4((1.0 - f.x) * (1.0 - f.y), f.x * (1.0 - f.y), (1.0 - f.x) * f.y, f.x * f.y);
  vec4 c = t00 * w.x + t10 * w.y + t01 * w.z + t11 * w.w;
  if (rk_field.world_scale.w != 0.0) {
    vec4 is_world = vec4(equal(vec4(t00.a, t10.a, t01.a, t11.a), vec4(0.0)));
    float ww = dot(w, is_world);
    if (ww > 0.0) {
      vec3 objects = t00.rgb * (w.x * (1.0 - is_world.x)) + t10.rgb * (w.y * (1.0 - is_world.y)) +
                     t01.rgb * (w.z * (1.0 - is_world.z)) + t11.rgb * (w.w * (1.0 - is_world.w));
      vec3 world = rk_field.world_scale.rgb * textureLod(rk_world, uv, 0.0).rgb;
      c.rgb = objects + ww * world;
    }
  }
  return c;
}

/* 1/distance of the texel holding direction d (not filtered: a blend of a near object's and
 * the background's values would stand for a surface that is not there, one texel around every
 * outline). */
float rk_scene_inverse_distance(vec3 d)
{
  ivec2 size = textureSize(rk_env, 0);
  ivec2 i = ivec2(floor(rokeby_equirect_uv(d) * vec2(size)));
  return texelFetch(rk_env, ivec2((i.x % size.x + size.x) % size.x, clamp(i.y, 0, size.y - 1)), 0).a;
}

/* The direction, seen from the capture point c, of what the ray q + t e meets (a distance
 * impostor, after Szirmay-Kalos et al. 2005). With a = q - c and t = s |a| / (1 - s), the ray's
 * point is c + p(s) / (1 - s), p(s) = (1 - s) a + s |a| e: s = 0 is q, s -> 1 the point at
 * infinity in direction e, and dir p(s) turns evenly from a towards e. The ray is behind the
 * captured surface where |x - c| >= D(dir), i.e. h(s) = |p| / D(dir p) - (1 - s) >= 0.
 *
 * A linear search finds where h turns from negative to positive; secant steps refine it. A
 * crossing where the ray is still well behind the nearest surface around it is not a hit but
 * the ray passing behind an object's outline (what lies there was hidden from c): the search goes
 * on. No hit: the ray leaves for the world, seen in direction e (as the centre-only lookup);
 * where that direction is hidden from c behind an object the ray passed, the nearest direction
 * in front of it along the search stands in (what c saw just beside that outline). */
#define RK_MARCH_STEPS 32
#define RK_SECANT_STEPS 6
#define RK_HIT_TOLERANCE 0.15 /* relative depth mismatch still taken as a hit */

vec3 rk_scene_direction(vec3 q, vec3 e)
{
  vec3 a = q - rk_field.env_origin.xyz;
  float la = length(a);
  if (rk_field.env_origin.w == 0.0 || !(la > 1e-7)) {
    return e;
  }
  vec3 b = la * e;
  float s0 = 0.0;
  float h0 = la * rk_scene_inverse_distance(a) - 1.0;
  if (h0 >= 0.0) {
    return a; /* q lies behind the captured surface (an object inside the mirror): what c sees there */
  }
  vec3 front = a; /* the last point of the search in front of the captured surface */
  for (int i = 1; i <= RK_MARCH_STEPS; i++) {
    float s1 = float(i) / float(RK_MARCH_STEPS + 1);
    vec3 p1 = mix(a, b, s1);
    float h1 = length(p1) * rk_scene_inverse_distance(p1) - (1.0 - s1);
    if (h1 < 0.0) {
      front = p1;
    }
    if (h0 < 0.0 && h1 >= 0.0) {
      /* between s0 (in front) and s1 (behind): secant steps, keeping the bracket */
      float lo = s0, hlo = h0, hi = s1, hhi = h1;
      for (int k = 0; k < RK_SECANT_STEPS; k++) {
        float s = lo + (hi - lo) * (-hlo) / (hhi - hlo);
        vec3 p = mix(a, b, s);
        float h = length(p) * rk_scene_inverse_distance(p) - (1.0 - s);
        if (h >= 0.0) {
          hi = s;
          hhi = h;
        }
        else {
          lo = s;
          hlo = h;
        }
      }
      vec3 p = mix(a, b, hi);
      /* the nearest surface among the texels around (a steep surface spans depths in one texel) */
      float inv_near = max(rk_scene_inverse_distance(p), rk_scene_texel(p).a);
      if (length(p) * inv_near <= (1.0 - hi) * (1.0 + RK_HIT_TOLERANCE)) {
        return p;
      }
      front = mix(a, b, lo);
    }
    s0 = s1;
    h0 = h1;
  }
  /* the point at infinity: hidden from c (1/D > 0 there and the ray went behind) or not */
  return (h0 >= 0.0 && rk_scene_inverse_distance(e) > 0.0) ? front : e;
}

/* The colour seen along e from the surface point q. */
vec3 rokeby_environment_at(vec3 q, vec3 d)
{
  if (rk_field.options.y == RK_ENV_SCENE) {
    return rk_scene_texel(rk_scene_direction(q, normalize(d))).rgb;
  }
  if (rk_field.options.y == RK_ENV_IMAGE) {
    /* level 0: no mip jump at the seam u = 0 / 1 */
    return textureLod(rk_env, rokeby_equirect_uv(d), 0.0).rgb;
  }
  return rk_builtin_sky(d);
}

/* The colour seen in direction d from far away (no surface point: no parallax). */
vec3 rokeby_environment(vec3 d)
{
  if (rk_field.options.y == RK_ENV_SCENE) {
    return rk_scene_texel(normalize(d)).rgb;
  }
  if (rk_field.options.y == RK_ENV_IMAGE) {
    return textureLod(rk_env, rokeby_equirect_uv(d), 0.0).rgb;
  }
  return rk_builtin_sky(d);
}

vec3 rk_linear_to_srgb(vec3 c)
{
  c = max(c, vec3(0.0));
  return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}

/* What a fragment of the mirror writes, by rk_field.options.x. */
vec4 rokeby_fragment(vec3 q, vec3 n, vec3 bary, vec3 vertex_ids)
{
  ivec3 vids = ivec3(vertex_ids + 0.5);
  int mode = rk_field.options.x;
  if (mode == RK_OUT_POSITION) {
    return vec4(q, 1.0);
  }
  if (mode == RK_OUT_NORMAL) {
    return vec4(normalize(n), 1.0);
  }
  if (mode == RK_OUT_BARY) {
    return vec4(bary, 1.0);
  }
  if (mode == RK_OUT_VERTEX_IDS) {
    return vec4(vec3(vids), 1.0);
  }
  vec3 e = rokeby_edited_direction(q, n, vids, bary);
  if (mode == RK_OUT_DIRECTION) {
    return vec4(e, 1.0);
  }
  vec3 c = rokeby_environment_at(q, e);
  return vec4(rk_field.options.z == 1 ? rk_linear_to_srgb(c) : c, 1.0);
}
