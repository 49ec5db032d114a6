/* The scene's distance from a capture point, fragment stage: |x - c| of the nearest surface (the
 * depth test keeps it); the colour comes from Blender's own drawing of the same view. */

void main()
{
  rk_out = vec4(length(rk_v_world - rk_capture_origin), 0.0, 0.0, 1.0);
}
