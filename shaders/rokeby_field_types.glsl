/* Rokeby viewport preview: the constants of the per-pixel field (Ritschel et al. 2009, §6.1).
 *
 * One std140 uniform block holds everything that is the same for every pixel of a mirror. It is
 * packed by rokeby.reflection.viewport.glsl.pack_field (Python), which states the byte offsets it writes; a test
 * checks them against the block size the driver reports. Blender passes this file to
 * GPUShaderCreateInfo.typedef_source, the moderngl tests paste it before the block declaration.
 */

#define RK_MAX_CONSTRAINTS 64
#define RK_MAX_REGIONS 8

/* counts.z: where the rotation comes from */
#define RK_DIST_EUCLIDEAN 0  /* per-pixel field, d = |q - p_n| computed here */
#define RK_DIST_PER_VERTEX 1 /* per-pixel field, d from per-vertex distances, interpolated */
#define RK_PER_VERTEX_FIELD 2 /* fallback: the stored per-vertex rotation vectors, interpolated */

/* options.y: what e(q) is looked up in */
#define RK_ENV_SKY 0    /* the built-in sky with a 15-degree grid */
#define RK_ENV_IMAGE 1  /* a lat-long image (the world's, or the mirror's reflection map) */
#define RK_ENV_SCENE 2  /* the scene captured from the mirror: lat-long RGB + 1/distance in alpha */

/* options.x: what the fragment writes (0 is the preview; the others are for tests) */
#define RK_OUT_COLOR 0
#define RK_OUT_DIRECTION 1
#define RK_OUT_POSITION 2
#define RK_OUT_NORMAL 3
#define RK_OUT_BARY 4
#define RK_OUT_VERTEX_IDS 5

struct RokebyField {
  vec4 cp[RK_MAX_CONSTRAINTS];      /* xyz: p_n, the constraint's surface point */
  vec4 cr[RK_MAX_CONSTRAINTS];      /* xyz: r_n, physical reflected direction (unit) */
  vec4 ce[RK_MAX_CONSTRAINTS];      /* xyz: e_n, edited direction (unit) */
  vec4 region_a[RK_MAX_REGIONS];    /* xyz: centre of a Euclidean region; w: 0 Euclidean, 1 per-vertex */
  vec4 region_b[RK_MAX_REGIONS];    /* x: radius, y: border, z: per-vertex slot, w: member count */
  uvec4 region_members[RK_MAX_REGIONS]; /* bit n (of x, y, z, w: 32 each) = constraint n acts here */
  vec4 eye;                         /* xyz: eye point (w = 1), or direction towards the eye (w = 0) */
  ivec4 counts;                     /* x: K, y: regions (0 = all constraints everywhere), z: RK_DIST_*, w: texels per vertex */
  ivec4 vlayout;                    /* per-vertex texture: x distances, y region weights, z rotation vector (float offsets), w width */
  ivec4 options;                    /* x: RK_OUT_*, y: RK_ENV_*, z: 1 = encode sRGB */
  vec4 env_origin;                  /* RK_ENV_SCENE: xyz the capture point; w: 1 = correct for q (distance), 0 = centre only */
  vec4 world_scale;                 /* RK_ENV_SCENE: rgb scale of rk_world (the world's own lat-long image) to the capture; w: 1 = use it */
};
