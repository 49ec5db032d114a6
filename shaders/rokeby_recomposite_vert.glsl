/* Rokeby recompositing, vertex stage: one triangle covering the viewport, no inputs.
 * Declarations come from rokeby.compositing.gl.RECOMPOSITE_INTERFACE (a #version header for
 * moderngl, GPUShaderCreateInfo in Blender). */

void main()
{
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
