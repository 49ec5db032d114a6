/* The scene's distance from a capture point, vertex stage: world-space triangles, one view of a
 * cube around the point. Declarations come from rokeby.reflection.viewport.gpu_capture.DISTANCE_INTERFACE. */

void main()
{
  rk_v_world = rk_position;
  gl_Position = rk_view_projection * vec4(rk_position, 1.0);
}
