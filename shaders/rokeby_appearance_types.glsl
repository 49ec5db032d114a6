/* Rokeby appearance preview (issue 8): the uniform block, std140, shared by Blender's
 * GPUShaderCreateInfo (typedef source) and the moderngl tests (rokeby.appearance_glsl packs it).
 * Only the model matrix is a push constant (64 bytes, within Vulkan's guaranteed 128). */

#define RK_MODEL_PRINCIPLED 0        /* Blender's BSDF: GGX split sum with the albedo table */
#define RK_MODEL_PHONG 1             /* the seed's normalised Phong lobe, exponent from roughness */
#define RK_MODEL_TORRANCE_SPARROW 2  /* Fraser's simplified Torrance-Sparrow, Schlick Fresnel */

/* options.z: which parameters are painted into image textures (read at the fragment's UV, texel
 * resolution) instead of per-point attributes (read per vertex from rk_points). */
#define RK_TEX_BASE 1
#define RK_TEX_SPECULAR 2
#define RK_TEX_ROUGHNESS 4
#define RK_TEX_METALLIC 8

struct RokebyAppearance {
  mat4 view_projection;
  vec4 eye;      /* xyz: the eye (world space) */
  ivec4 options; /* x: prefiltered levels in the atlas, y: RK_MODEL_*, z: RK_TEX_* bits */
  vec4 sh[9];    /* E(n)/pi irradiance coefficients (rgb), rokeby_core::sh basis */
  vec4 tint;     /* the global diffuse slider: base colour multiplied by it */
  vec4 scale;    /* the global sliders of specular (x), roughness (y), metallic (z); clamped to [0, 1] */
  mat4 normal_matrix; /* the model matrix's inverse transpose (3x3 part), once per draw, not per vertex */
};
