/* Rokeby recompositing: Zubiaga et al. 2016 eqs. 3–5 per pixel, written as
 * rust/rokeby-core/src/compositing/recomposite/ does (so that unmodified normals give I back bit for bit):
 *
 *   D~ = D0 + a_D ([D0 + Σ_k c_k (Y_k(ñ) − Y_k(n))] − D0),  [x] = max(x, min(0, D0))     (eq. 3)
 *   R~ = R0 + v a_R (R(r~) − R0),  v = min(1, θ/ε), θ = 2 asin(|r − r~| / 2)            (eq. 4)
 *   I~ = I + a [(k_D c_D D~ + k_R c_R R~)^(1/γ) − (c_D D0 + c_R R0)^(1/γ)]               (eq. 5)
 *
 * Inputs (declared by the generated header; all float textures read with texelFetch, so no
 * filtering by the driver):
 *   rk_ids       R    patch index per pixel (< 0 or ≥ rk_npatches: none)
 *   rk_normals, rk_edited, rk_view (RGB; rk_view_const when rk_flags.x == 0)
 *   rk_diffuse, rk_reflection, rk_image (RGB)
 *   rk_alphas    RGB  (α_D, α_R, α)
 *   rk_dcolor, rk_rcolor  RGB reflectance c_D, c_R (rk_flags.y, rk_flags.z: given, else 1)
 *   rk_sh        RGB  width 10 × height rk_npatches: texel (k, p) = patch p's coefficient k of the
 *                     three channels (k < 9); texel (9, p) = (has SH, has map, unused)
 *   rk_env       RGB  2D array, layer 2p + face, the dual-paraboloid map of patch p, size S×S with
 *                     texel (j, i) = map[face, i, j] (the convention of ParaboloidMap)
 * Output rk_out: (I~, status) with status 0 = I returned unchanged, 1 = recomposited,
 * 2 = masked (a non-finite or zero input, or a patch without reconstruction). */

bool rk_unit(vec3 c, out vec3 u)
{
  float l = length(c);
  u = c / l;
  return !(isnan(l) || isinf(l)) && l > 1e-12;
}

bool rk_finite3(vec3 x)
{
  return !(any(isnan(x)) || any(isinf(x)));
}

void rk_basis(vec3 n, out float b[9])
{
  float x = n.x, y = n.y, z = n.z;
  b[0] = 0.28209479177387814;
  b[1] = 0.4886025119029199 * y;
  b[2] = 0.4886025119029199 * z;
  b[3] = 0.4886025119029199 * x;
  b[4] = 1.0925484305920792 * x * y;
  b[5] = 1.0925484305920792 * y * z;
  b[6] = 0.31539156525252005 * (3.0 * z * z - 1.0);
  b[7] = 1.0925484305920792 * x * z;
  b[8] = 0.5462742152960396 * (x * x - y * y);
}

/* ParaboloidMap::lookup: face by the sign of z, (u, v) = (x, y) / (1 ± z), bilinear on texel
 * centres with the coordinates clamped to the map (no wrap). */
vec3 rk_env_lookup(int pid, vec3 d)
{
  float l = length(d);
  d = (l > 0.0 && !(isnan(l) || isinf(l))) ? d / l : vec3(0.0, 0.0, 1.0);
  int face = d.z >= 0.0 ? 0 : 1;
  float k = 1.0 / (1.0 + abs(d.z));
  vec2 uv = d.xy * k;
  int size = textureSize(rk_env, 0).x;
  float s = float(size);
  vec2 xy = clamp((uv + 1.0) * 0.5 * s - 0.5, 0.0, s - 1.0);
  ivec2 p0 = ivec2(xy);
  ivec2 p1 = min(p0 + 1, ivec2(size - 1));
  vec2 f = xy - vec2(p0);
  int layer = 2 * pid + face;
  vec3 t00 = texelFetch(rk_env, ivec3(p0.x, p0.y, layer), 0).rgb;
  vec3 t01 = texelFetch(rk_env, ivec3(p1.x, p0.y, layer), 0).rgb;
  vec3 t10 = texelFetch(rk_env, ivec3(p0.x, p1.y, layer), 0).rgb;
  vec3 t11 = texelFetch(rk_env, ivec3(p1.x, p1.y, layer), 0).rgb;
  vec3 top = t00 + f.x * (t01 - t00);
  vec3 bot = t10 + f.x * (t11 - t10);
  return top + f.y * (bot - top);
}

vec3 rk_gamma(vec3 x)
{
  return rk_params.z == 1.0 ? x : pow(max(x, vec3(0.0)), vec3(1.0 / rk_params.z));
}

void main()
{
  ivec2 q = ivec2(gl_FragCoord.xy);
  vec3 img = texelFetch(rk_image, q, 0).rgb;
  rk_out = vec4(img, 0.0);
  float idf = texelFetch(rk_ids, q, 0).r;
  if (!(idf >= 0.0) || idf >= float(rk_npatches)) {
    return;
  }
  int pid = int(idf);
  vec3 nb = texelFetch(rk_normals, q, 0).rgb;
  vec3 eb = texelFetch(rk_edited, q, 0).rgb;
  if (nb == eb && rk_params.x == 1.0 && rk_params.y == 1.0) {
    return; /* unmodified normal and material: eqs. 3–5 give I exactly */
  }
  vec3 vb = rk_flags.x != 0 ? texelFetch(rk_view, q, 0).rgb : rk_view_const;
  vec3 d0 = texelFetch(rk_diffuse, q, 0).rgb;
  vec3 r0 = texelFetch(rk_reflection, q, 0).rgb;
  vec3 al = texelFetch(rk_alphas, q, 0).rgb;
  vec3 cd = rk_flags.y != 0 ? texelFetch(rk_dcolor, q, 0).rgb : vec3(1.0);
  vec3 cr = rk_flags.z != 0 ? texelFetch(rk_rcolor, q, 0).rgb : vec3(1.0);
  vec3 flags = texelFetch(rk_sh, ivec2(9, pid), 0).rgb;
  bool has_sh = flags.x != 0.0, has_env = flags.y != 0.0;
  vec3 nn, ne, vv;
  bool ok = rk_unit(nb, nn) && rk_unit(eb, ne) && rk_unit(vb, vv);
  bool finite = rk_finite3(d0) && rk_finite3(r0) && rk_finite3(al) && rk_finite3(cd) && rk_finite3(cr);
  if (!ok || !finite || !(has_sh || has_env)) {
    rk_out.a = 2.0;
    return;
  }
  rk_out.a = 1.0;
  /* eq. 3 */
  vec3 delta = vec3(0.0);
  if (has_sh) {
    float be[9], bn[9];
    rk_basis(ne, be);
    rk_basis(nn, bn);
    for (int k = 0; k < 9; k++) {
      delta += texelFetch(rk_sh, ivec2(k, pid), 0).rgb * (be[k] - bn[k]);
    }
  }
  vec3 res = max(d0 + delta, min(d0, vec3(0.0)));
  vec3 dt = d0 + al.x * (res - d0);
  /* eq. 4 */
  vec3 r = 2.0 * dot(nn, vv) * nn - vv;
  vec3 re = 2.0 * dot(ne, vv) * ne - vv;
  float chord = length(r - re);
  float vis = chord >= rk_params.w ? 1.0 : 2.0 * asin(min(0.5 * chord, 1.0)) * rk_inv_eps;
  vec3 look = (has_env && vis * al.y != 0.0) ? rk_env_lookup(pid, re) : r0;
  vec3 rt = r0 + vis * al.y * (look - r0);
  /* eq. 5 */
  vec3 shade = rk_params.x * (cd * dt) + rk_params.y * (cr * rt);
  vec3 shade0 = cd * d0 + cr * r0;
  rk_out.rgb = img + al.z * (rk_gamma(shade) - rk_gamma(shade0));
}
