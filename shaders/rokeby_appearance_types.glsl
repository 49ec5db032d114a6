/* Rokeby appearance preview (issue 8): the uniform block, std140, shared by Blender's
 * GPUShaderCreateInfo (typedef source) and the moderngl tests (rokeby.appearance_glsl packs it).
 * Only the model matrix is a push constant (64 bytes, within Vulkan's guaranteed 128). */

#define RK_MODEL_PRINCIPLED 0        /* Blender's BSDF: GGX split sum with the albedo table */
#define RK_MODEL_PHONG 1             /* the seed's normalised Phong lobe, exponent from roughness */
#define RK_MODEL_TORRANCE_SPARROW 2  /* Fraser's simplified Torrance-Sparrow, Schlick Fresnel */

struct RokebyAppearance {
  mat4 view_projection;
  vec4 eye;      /* xyz: the eye (world space) */
  ivec4 options; /* x: prefiltered levels in the atlas, y: RK_MODEL_* */
  vec4 sh[9];    /* E(n)/pi irradiance coefficients (rgb), rokeby_core::sh basis */
};
