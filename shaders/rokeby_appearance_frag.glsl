/* Rokeby appearance preview, fragment stage (v_par: specular, roughness, metallic; v_tint: the
 * specular tint). Parameters on a texture target come from their image at the fragment's UV; then
 * the global sliders, as the material's rokeby_global_* nodes apply them; then the light
 * (options.w): the prefiltered world, or the point light of Fraser's second view. */
void main()
{
  vec3 n = normalize(v_nor);
  vec3 v = normalize(rk_appearance.eye.xyz - v_pos);
  if (dot(n, v) < 0.0) {
    n = -n; /* back faces seen through an open mesh */
  }
  vec4 base = v_base;
  vec3 par = v_par;
  int tex = rk_appearance.options.z;
  if ((tex & RK_TEX_BASE) != 0) {
    base = rk_painted(rk_tex_base, v_uv);
  }
  if ((tex & RK_TEX_SPECULAR) != 0) {
    par.x = rk_painted(rk_tex_specular, v_uv).r;
  }
  if ((tex & RK_TEX_ROUGHNESS) != 0) {
    par.y = rk_painted(rk_tex_roughness, v_uv).r;
  }
  if ((tex & RK_TEX_METALLIC) != 0) {
    par.z = rk_painted(rk_tex_metallic, v_uv).r;
  }
  vec3 tint = v_tint;
  if ((tex & RK_TEX_SPECULAR_TINT) != 0) {
    tint = rk_painted(rk_tex_specular_tint, v_uv).rgb;
  }
  base *= rk_appearance.tint;
  tint = max(tint * rk_appearance.spec_tint.rgb, vec3(0.0));
  par = clamp(par * rk_appearance.scale.xyz, 0.0, 1.0);
  if (rk_appearance.options.w == RK_LIGHT_POINT) {
    frag = vec4(rk_shade_point(n, v, v_pos, base.rgb, par.x, par.y, par.z, tint), 1.0);
  }
  else {
    frag = vec4(rk_shade_tinted(n, v, base.rgb, par.x, par.y, par.z, tint), 1.0);
  }
  /* The 3D view has drawn this same surface already (Solid shading's grey), its depth sampled
   * with a sub-pixel jitter for its anti-aliasing: pulled toward the eye by the depth change
   * across one pixel (a slope-scaled polygon offset) and RK_DEPTH_EPSILON, the preview wins that
   * tie everywhere instead of in speckles; a surface in front by more still hides it. */
  float z = gl_FragCoord.z;
  gl_FragDepth = max(z - fwidth(z) - RK_DEPTH_EPSILON, 0.0);
}
