/* Rokeby appearance preview, vertex stage: world position and normal, the UV for texture targets,
 * and the painted per-point parameters fetched from rk_points by the mesh vertex index (three texels
 * per vertex: base colour rgba, then specular/roughness/metallic, then the specular tint rgb), so a
 * brush stroke uploads only that texture and the geometry batch is kept. */
void main()
{
  vec4 w = rk_model * vec4(pos, 1.0);
  v_pos = w.xyz;
  v_nor = mat3(rk_appearance.normal_matrix) * nor;
  v_uv = uv;
  int width = textureSize(rk_points, 0).x;
  int t = 3 * int(vid + 0.5);
  v_base = texelFetch(rk_points, ivec2(t % width, t / width), 0);
  v_par = texelFetch(rk_points, ivec2((t + 1) % width, (t + 1) / width), 0).xyz;
  v_tint = texelFetch(rk_points, ivec2((t + 2) % width, (t + 2) / width), 0).xyz;
  gl_Position = rk_appearance.view_projection * w;
}
