/* Rokeby viewport preview, fragment stage: everything is in rokeby_field_lib.glsl. */

void main()
{
  rk_out = rokeby_fragment(rk_v_position, rk_v_normal, rk_v_bary, rk_v_vertex_ids);
}
