/* Rokeby appearance preview: shading under the world HDR with the prefiltered chain of
 * the chosen lobe in one lat-long atlas (levels at roughness l / (levels - 1), stacked top to
 * bottom) and order-2 SH irradiance. Needs: the block rk_appearance (RokebyAppearance), the
 * samplers rk_env_atlas and rk_brdf_lut (GGX directional albedo: r = scale, g = bias of F0, at
 * (n.v, roughness)). numpy twin: rokeby.appearance.glsl.shade_reference. */

const float RK_PI = 3.14159265358979;

vec2 rk_equirect_uv(vec3 d)
{
  return vec2(0.5 - atan(d.y, d.x) / (2.0 * RK_PI), atan(d.z, length(d.xy)) / RK_PI + 0.5);
}

vec3 rk_level_texel(int level, int i, int j, int h, int w)
{
  if (i < 0) { i = -1 - i; j += w / 2; }
  else if (i >= h) { i = 2 * h - 1 - i; j += w / 2; }
  i = clamp(i, 0, h - 1);
  j = ((j % w) + w) % w;
  return texelFetch(rk_env_atlas, ivec2(j, level * h + i), 0).rgb;
}

/* Bilinear, wrapping in u and crossing the poles at u + 1/2, exactly like rokeby_core::envmaps::envmap. */
vec3 rk_level(vec3 d, int level)
{
  ivec2 size = textureSize(rk_env_atlas, 0);
  int w = size.x;
  int h = size.y / rk_appearance.options.x;
  vec2 uv = rk_equirect_uv(normalize(d));
  float x = uv.x * float(w) - 0.5;
  float y = (1.0 - uv.y) * float(h) - 0.5;
  float x0 = floor(x), y0 = floor(y);
  float fx = x - x0, fy = y - y0;
  int j0 = int(x0), i0 = int(y0);
  return (1.0 - fx) * (1.0 - fy) * rk_level_texel(level, i0, j0, h, w)
       + fx * (1.0 - fy) * rk_level_texel(level, i0, j0 + 1, h, w)
       + (1.0 - fx) * fy * rk_level_texel(level, i0 + 1, j0, h, w)
       + fx * fy * rk_level_texel(level, i0 + 1, j0 + 1, h, w);
}

/* Prefiltered radiance for a Blender roughness: levels at roughness l / (levels - 1). */
vec3 rk_specular(vec3 r, float roughness)
{
  int levels = rk_appearance.options.x;
  float x = clamp(roughness, 0.0, 1.0) * float(levels - 1);
  int l0 = min(int(floor(x)), levels - 1);
  int l1 = min(l0 + 1, levels - 1);
  return mix(rk_level(r, l0), rk_level(r, l1), x - float(l0));
}

/* E(n)/pi from the irradiance coefficients (Ramamoorthi & Hanrahan 2001; rokeby_core::compositing::sh basis). */
vec3 rk_irradiance(vec3 n)
{
  n = normalize(n);
  return rk_appearance.sh[0].rgb * 0.28209479177387814
       + rk_appearance.sh[1].rgb * (0.4886025119029199 * n.y)
       + rk_appearance.sh[2].rgb * (0.4886025119029199 * n.z)
       + rk_appearance.sh[3].rgb * (0.4886025119029199 * n.x)
       + rk_appearance.sh[4].rgb * (1.0925484305920792 * n.x * n.y)
       + rk_appearance.sh[5].rgb * (1.0925484305920792 * n.y * n.z)
       + rk_appearance.sh[6].rgb * (0.31539156525252005 * (3.0 * n.z * n.z - 1.0))
       + rk_appearance.sh[7].rgb * (1.0925484305920792 * n.x * n.z)
       + rk_appearance.sh[8].rgb * (0.5462742152960396 * (n.x * n.x - n.y * n.y));
}

/* (scale, bias) of F0 in the GGX directional albedo, bilinear at texel centres. */
vec2 rk_brdf_albedo(float n_dot_v, float roughness)
{
  ivec2 size = textureSize(rk_brdf_lut, 0);
  vec2 p = vec2(clamp(n_dot_v, 0.0, 1.0), clamp(roughness, 0.0, 1.0)) * vec2(size - 1);
  vec2 p0 = floor(p);
  vec2 f = p - p0;
  ivec2 i0 = ivec2(p0);
  ivec2 i1 = min(i0 + 1, size - 1);
  vec2 a = mix(texelFetch(rk_brdf_lut, i0, 0).rg, texelFetch(rk_brdf_lut, ivec2(i1.x, i0.y), 0).rg, f.x);
  vec2 b = mix(texelFetch(rk_brdf_lut, ivec2(i0.x, i1.y), 0).rg, texelFetch(rk_brdf_lut, i1, 0).rg, f.x);
  return mix(a, b, f.y);
}

/* n: shading normal, v: direction to the viewer (both unit, world space); tint: the specular tint
 * (Principled's Specular Tint: the dielectric F0 times it, as Blender 4 does; metals keep F0 = base). */
vec3 rk_shade_tinted(vec3 n, vec3 v, vec3 base, float specular, float roughness, float metallic, vec3 tint)
{
  vec3 r = reflect(-v, n);
  float nv = clamp(dot(n, v), 0.0, 1.0);
  vec3 f0 = mix(0.08 * specular * tint, base, metallic);
  vec3 diffuse = base * (1.0 - metallic) * rk_irradiance(n);
  vec3 spec = rk_specular(r, roughness);
  int model = rk_appearance.options.y;
  if (model == RK_MODEL_PRINCIPLED) {
    vec2 ab = rk_brdf_albedo(nv, roughness);
    vec3 e_dielectric = 0.08 * specular * tint * ab.x + ab.y; /* the specular layer's albedo */
    return diffuse * (1.0 - e_dielectric) + spec * (f0 * ab.x + ab.y);
  }
  if (model == RK_MODEL_TORRANCE_SPARROW) {
    vec3 fresnel = f0 + (1.0 - f0) * pow(1.0 - nv, 5.0);
    return diffuse + spec * fresnel;
  }
  return diffuse + spec * f0; /* Phong: k_s = F0, the lobe is normalised */
}

vec3 rk_shade(vec3 n, vec3 v, vec3 base, float specular, float roughness, float metallic)
{
  return rk_shade_tinted(n, v, base, specular, roughness, metallic, vec3(1.0));
}

/* Fraser's second view: the same painted parameters under one point light (light.xyz, intensity
 * light.w, falling off as 1/d^2), each model's BRDF evaluated directly (numpy twin:
 * rokeby.appearance.glsl.shade_point_reference). p: the shaded point (world space).
 * Principled: GGX D, Smith height-correlated visibility, Schlick F (alpha = roughness^2), the
 * diffuse weighted by what the specular layer leaves, as in rk_shade. Phong: the paper's
 * (1 + s)/(2 pi) k_s max(0, r.l)^s / (l.n), s = (2/alpha^2 - 2)/4 as the atlas levels use.
 * Torrance-Sparrow: the paper's k_s S / (4 cos_i cos_o), S = exp(-(theta_h/s)^2)/(pi s^2), s = alpha. */
vec3 rk_shade_point(vec3 n, vec3 v, vec3 p, vec3 base, float specular, float roughness, float metallic, vec3 tint)
{
  vec3 to_light = rk_appearance.light.xyz - p;
  float d2 = max(dot(to_light, to_light), 1e-8);
  vec3 l = to_light * inversesqrt(d2);
  float nl = dot(n, l);
  if (nl <= 0.0) {
    return vec3(0.0);
  }
  float nv = clamp(dot(n, v), 1e-3, 1.0);
  vec3 h = normalize(l + v);
  float nh = clamp(dot(n, h), 0.0, 1.0);
  float vh = clamp(dot(v, h), 0.0, 1.0);
  float alpha = max(roughness * roughness, 1e-3);
  vec3 f0 = mix(0.08 * specular * tint, base, metallic);
  vec3 diffuse = base * (1.0 - metallic) / RK_PI;
  vec3 brdf_nl; /* the BRDF times n.l */
  int model = rk_appearance.options.y;
  if (model == RK_MODEL_PRINCIPLED) {
    float a2 = alpha * alpha;
    float q = nh * nh * (a2 - 1.0) + 1.0;
    float d = a2 / (RK_PI * q * q);
    float vis = 0.5 / (nl * sqrt(nv * nv * (1.0 - a2) + a2) + nv * sqrt(nl * nl * (1.0 - a2) + a2));
    vec3 f = f0 + (1.0 - f0) * pow(1.0 - vh, 5.0);
    vec2 ab = rk_brdf_albedo(nv, roughness);
    vec3 e_dielectric = 0.08 * specular * tint * ab.x + ab.y;
    brdf_nl = (diffuse * (1.0 - e_dielectric) + d * vis * f) * nl;
  }
  else if (model == RK_MODEL_TORRANCE_SPARROW) {
    float th = acos(nh);
    float s = exp(-(th / alpha) * (th / alpha)) / (RK_PI * alpha * alpha);
    vec3 f = f0 + (1.0 - f0) * pow(1.0 - nv, 5.0);
    brdf_nl = diffuse * nl + f * s / (4.0 * nv);
  }
  else {
    float sigma = min((2.0 / (alpha * alpha) - 2.0) / 4.0, 1e6);
    float rl = max(dot(reflect(-v, n), l), 1e-8); /* pow(0, 0) is undefined */
    brdf_nl = diffuse * nl + f0 * (1.0 + sigma) / (2.0 * RK_PI) * pow(rl, sigma);
  }
  return brdf_nl * rk_appearance.light.w / d2;
}

/* A painted image at uv as the material's Image Texture node reads it (Linear, Extend): bilinear
 * between texel centres (i + 1/2) / size, clamped at the borders; row 0 is v = 0. */
vec4 rk_painted(sampler2D image, vec2 uv)
{
  ivec2 size = textureSize(image, 0);
  vec2 p = clamp(uv * vec2(size) - 0.5, vec2(0.0), vec2(size - 1));
  vec2 p0 = floor(p);
  vec2 f = p - p0;
  ivec2 i0 = ivec2(p0);
  ivec2 i1 = min(i0 + 1, size - 1);
  vec4 a = mix(texelFetch(image, i0, 0), texelFetch(image, ivec2(i1.x, i0.y), 0), f.x);
  vec4 b = mix(texelFetch(image, ivec2(i0.x, i1.y), 0), texelFetch(image, i1, 0), f.x);
  return mix(a, b, f.y);
}
