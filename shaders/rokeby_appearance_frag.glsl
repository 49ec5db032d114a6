/* Rokeby appearance preview, fragment stage (v_par: specular, roughness, metallic). */
void main()
{
  vec3 n = normalize(v_nor);
  vec3 v = normalize(rk_appearance.eye.xyz - v_pos);
  if (dot(n, v) < 0.0) {
    n = -n; /* back faces seen through an open mesh */
  }
  frag = vec4(rk_shade(n, v, v_base.rgb, v_par.x, v_par.y, v_par.z), 1.0);
}
