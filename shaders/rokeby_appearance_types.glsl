/* Rokeby appearance preview: the uniform block, std140, shared by Blender's
 * GPUShaderCreateInfo (typedef source) and the moderngl tests (rokeby.appearance.glsl packs it).
 * Only the model matrix is a push constant (64 bytes, within Vulkan's guaranteed 128). */

#define RK_MODEL_PRINCIPLED 0        /* Blender's BSDF: GGX split sum with the albedo table */
#define RK_MODEL_PHONG 1             /* the seed's normalised Phong lobe, exponent from roughness */
#define RK_MODEL_TORRANCE_SPARROW 2  /* Fraser's simplified Torrance-Sparrow, Schlick Fresnel */

/* options.z: which parameters are painted into image textures (read at the fragment's UV, texel
 * resolution) instead of per-point attributes (read per vertex from rk_points). */
/* The preview's depth pulled toward the eye beyond the slope offset (window depth, 0..1): ~17
 * steps of a 24-bit depth buffer (see the fragment stage). */
#define RK_DEPTH_EPSILON 1.0e-6
#define RK_TEX_BASE 1
#define RK_TEX_SPECULAR 2
#define RK_TEX_ROUGHNESS 4
#define RK_TEX_METALLIC 8
#define RK_TEX_SPECULAR_TINT 16

/* options.w: what lights the preview (Fraser's interface shows both views side by side). */
#define RK_LIGHT_ENVIRONMENT 0 /* the world, prefiltered (the atlas and the SH irradiance) */
#define RK_LIGHT_POINT 1       /* one point light at light.xyz, intensity light.w, 1/d^2 falloff */

struct RokebyAppearance {
  mat4 view_projection;
  vec4 eye;      /* xyz: the eye (world space) */
  ivec4 options; /* x: prefiltered levels in the atlas, y: RK_MODEL_*, z: RK_TEX_* bits, w: RK_LIGHT_* */
  vec4 sh[9];    /* E(n)/pi irradiance coefficients (rgb), rokeby_core::compositing::sh basis */
  vec4 tint;     /* the global diffuse slider: base colour multiplied by it */
  vec4 scale;    /* the global sliders of specular (x), roughness (y), metallic (z); clamped to [0, 1] */
  mat4 normal_matrix; /* the model matrix's inverse transpose (3x3 part), once per draw, not per vertex */
  vec4 spec_tint; /* the global specular colour slider: the painted specular tint multiplied by it */
  vec4 light;     /* RK_LIGHT_POINT: xyz the light's world position, w its intensity (W/sr) */
};
