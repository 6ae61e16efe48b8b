#line 2 "scene_data.h"
/* Everything the kernels read about a scene, listed once (Blender Cycles' state_template.h
 * habit). SCENE_DATA(BUFFER, VALUE, NEXT) calls BUFFER(type, name) for each read-only global
 * buffer of `type` and VALUE(type, name) for each scalar passed by value, in kernel argument
 * order, with NEXT between two entries. SceneData, SCENE_PARAMS (the entry kernels' scene
 * parameters) and SCENE_INIT (SceneData from those parameters) are made from it below, and the
 * host reads the same list: workflow/invrender/render/scene_buffers.py parses this macro (one
 * entry per line, in exactly this form) for the order of the arguments it passes. */
#ifndef INVRENDER_SCENE_DATA_H
#define INVRENDER_SCENE_DATA_H

#define SCENE_DATA(BUFFER, VALUE, NEXT)                                                          \
    BUFFER(float4, tri_v) NEXT        /* 3 vertices per triangle, in BVH leaf order */          \
    BUFFER(float2, tri_uv) NEXT       /* 3 UVs per triangle */                                  \
    BUFFER(int, tri_id) NEXT          /* leaf slot -> original triangle index */                \
    BUFFER(int, tri_instance) NEXT    /* leaf slot -> instance id */                            \
    BUFFER(uchar, tri_one_sided) NEXT /* leaf slot -> 1: emits on its front side only */        \
    BUFFER(float8, bvh_bounds) NEXT   /* 6 rows per node: min xyz, max xyz over 8 lanes */      \
    BUFFER(int8, bvh_children) NEXT   /* 2 rows per node: child node/leaf block, count */       \
    BUFFER(float8, bvh_leaves) NEXT   /* 10 rows per leaf: v0 xyz, v1 xyz, v2 xyz, slot */      \
    BUFFER(float4, material) NEXT     /* 3 float4 per texel (Material in common.h) */           \
    VALUE(int, atlas_w) NEXT                                                                     \
    VALUE(int, atlas_h) NEXT                                                                     \
    BUFFER(float4, kg) NEXT           /* 6 N N texels, faces +X -X +Y -Y +Z -Z */               \
    VALUE(int, cube_n) NEXT                                                                      \
    BUFFER(float, env_cdf) NEXT       /* 6 N N, inclusive prefix sums, last = 1 */              \
    BUFFER(float, env_pmf) NEXT       /* P(texel) */                                            \
    BUFFER(float4, em_v) NEXT         /* 3 vertices per emitting triangle, emitter-BVH order */ \
    BUFFER(float, em_cdf) NEXT        /* per emitting triangle */                               \
    BUFFER(float, em_pdf_area) NEXT   /* P(t) / area(t) */                                      \
    VALUE(int, num_emitters) NEXT                                                                \
    BUFFER(float8, em_bounds) NEXT    /* the emitter BVH, laid out as bvh_bounds */             \
    BUFFER(int8, em_children) NEXT    /* and as bvh_children, but child/first slot, count */    \
    BUFFER(uchar, em_one_sided) NEXT  /* per emitting triangle, as tri_one_sided */             \
    BUFFER(int, em_slot) NEXT         /* per emitting triangle: its slot in tri_v */            \
    BUFFER(float, tri_light_pdf) NEXT /* per slot of tri_v: P(t) / area(t), or 0 */             \
    VALUE(float, w_env) NEXT          /* mixture weight of strategy 3 */                        \
    VALUE(float, w_emit)              /* mixture weight of strategy 4 */

/* FIXED_PROPOSAL, a test hook: paths are sampled with the densities of a second material
 * buffer and evaluated with `material`. Importance sampling with a proposal that stays put as
 * the material moves gives an estimator whose finite differences in a BSDF parameter are as
 * smooth as the adjoint's, path for path (tests/render/test_gradients_fd.py). The host passes
 * it after the list (Renderer._scene_args in workflow/invrender/render/renderer.py). */
#ifdef FIXED_PROPOSAL
#define PROPOSAL_PARAM , global const float4 *proposal_material
#define PROPOSAL_BUFFER proposal_material
#else
#define PROPOSAL_PARAM
#define PROPOSAL_BUFFER material
#endif

#define SCENE_NOTHING
#define SCENE_COMMA ,
#define SCENE_MEMBER_BUFFER(type, name) global const type* name;
#define SCENE_MEMBER_VALUE(type, name) type name;
#define SCENE_PARAM_BUFFER(type, name) global const type* name
#define SCENE_PARAM_VALUE(type, name) type name
#define SCENE_NAME(type, name) name

typedef struct {
    SCENE_DATA(SCENE_MEMBER_BUFFER, SCENE_MEMBER_VALUE, SCENE_NOTHING)
    global const float4* proposal; /* the material paths are sampled from: `material`, or */
} SceneData;                       /* another under FIXED_PROPOSAL */

#define SCENE_PARAMS SCENE_DATA(SCENE_PARAM_BUFFER, SCENE_PARAM_VALUE, SCENE_COMMA) PROPOSAL_PARAM
#define SCENE_INIT(s) SceneData s = {SCENE_DATA(SCENE_NAME, SCENE_NAME, SCENE_COMMA), PROPOSAL_BUFFER}

#endif
