/* Rokeby viewport preview, vertex stage. Declarations come from rokeby.reflection.viewport.glsl.INTERFACE (Blender's
 * GPUShaderCreateInfo, or the #version header the moderngl tests generate from it).
 * The mesh arrives as a triangle soup (three vertices per triangle) so that each fragment knows
 * its barycentric coordinates and the three mesh vertices it lies between. */

void main()
{
  int corner = gl_VertexID % 3;
  rk_v_position = rk_position;
  rk_v_normal = rk_normal;
  rk_v_bary = vec3(corner == 0 ? 1.0 : 0.0, corner == 1 ? 1.0 : 0.0, corner == 2 ? 1.0 : 0.0);
  rk_v_vertex_ids = rk_vertex_ids;
  gl_Position = rk_view_projection * vec4(rk_position, 1.0);
  /* drawn over Blender's own drawing of the same surface: win the depth test */
  gl_Position.z -= rk_depth_bias * gl_Position.w;
}
