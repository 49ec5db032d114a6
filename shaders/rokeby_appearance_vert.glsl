/* Rokeby appearance preview, vertex stage: world position and normal, painted parameters. */
void main()
{
  vec4 w = rk_model * vec4(pos, 1.0);
  v_pos = w.xyz;
  v_nor = transpose(inverse(mat3(rk_model))) * nor;
  v_base = base;
  v_par = par;
  gl_Position = rk_appearance.view_projection * w;
}
