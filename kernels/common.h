#line 2 "common.h"
/* Constants, small vector helpers and the scene's device data, shared by every header.
 *
 * Feature flags (set by the host from features.json, see workflow/invrender/render/features.py):
 *   FEATURE_SPECULAR          Cook-Torrance lobe (else the material is Lambertian)
 *   FEATURE_EMISSION          ke term of E = ke + kw kg
 *   FEATURE_EMITTER_SAMPLING  strategy 4: emitting triangles by area x radiance
 *   FEATURE_ENVIRONMENT       kg seen by rays that leave the scene
 *   FEATURE_WINDOW            kw kg term on surfaces (needs FEATURE_ENVIRONMENT)
 *   FEATURE_ENV_SAMPLING      strategy 3: kg cube map by luminance (needs FEATURE_ENVIRONMENT)
 *   MAX_BOUNCES               scattering events per path (Mitsuba's max_depth - 1)
 */
#ifndef INVRENDER_COMMON_H
#define INVRENDER_COMMON_H

#ifndef MAX_BOUNCES
#define MAX_BOUNCES 10
#endif
#if defined(FEATURE_WINDOW) && !defined(FEATURE_ENVIRONMENT)
#error "FEATURE_WINDOW needs FEATURE_ENVIRONMENT"
#endif
#if defined(FEATURE_ENV_SAMPLING) && !defined(FEATURE_ENVIRONMENT)
#error "FEATURE_ENV_SAMPLING needs FEATURE_ENVIRONMENT"
#endif

#define INV_PI 0.31830988618379067f
#define PI_F 3.14159265358979323f
#define RAY_TMAX 3.0e38f

inline float luminance(float3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }
inline float max3(float3 c) { return fmax(c.x, fmax(c.y, c.z)); }
inline float safe_sqrt(float x) { return sqrt(fmax(x, 0.0f)); }
inline int all_finite3(float3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }

/* Orthonormal basis around n (Duff et al. 2017, "Building an Orthonormal Basis, Revisited"):
 * continuous everywhere but the sign flip, no division by a small number. */
inline void make_frame(float3 n, float3* s, float3* t)
{
    float sign = copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float b = n.x * n.y * a;
    *s = (float3)(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    *t = (float3)(b, sign + n.y * n.y * a, -n.y);
}

inline float3 to_world(float3 v, float3 n)
{
    float3 s, t;
    make_frame(n, &s, &t);
    return v.x * s + v.y * t + v.z * n;
}

/* Material at one texel, unpacked from the three float4 the host stores per texel:
 * [kd.rgb, ka], [ks.rgb, kw], [ke.rgb, -]. */
typedef struct {
    float3 kd, ks, ke;
    float ka, kw;
} Material;

/* Everything the kernels read about a scene. Entry kernels take SCENE_PARAMS and build one of
 * these with SCENE_INIT, so the list of buffers is written once (the host passes them in the
 * same order: SceneBuffers.args() in workflow/invrender/render/scene_buffers.py). */
typedef struct {
    global const float4* tri_v;        /* 3 vertices per triangle, in BVH leaf order */
    global const float2* tri_uv;       /* 3 UVs per triangle */
    global const int* tri_id;          /* leaf slot -> original triangle index */
    global const int* tri_instance;    /* leaf slot -> instance id */
    global const float8* bvh_bounds;   /* 6 rows per node: min xyz, max xyz over 8 lanes */
    global const int8* bvh_children;   /* 2 rows per node: child/first slot, count */
    global const float4* material;     /* 3 float4 per texel */
    int atlas_w, atlas_h;
    global const float4* kg;           /* 6 N N texels, faces +X -X +Y -Y +Z -Z */
    int cube_n;
    global const float* env_cdf;       /* 6 N N, inclusive prefix sums, last = 1 */
    global const float* env_pmf;       /* P(texel) */
    global const float4* em_v;         /* 3 vertices per emitting triangle, emitter-BVH order */
    global const float* em_cdf;        /* per emitting triangle */
    global const float* em_pdf_area;   /* P(t) / area(t) */
    int num_emitters;
    global const float8* em_bounds;
    global const int8* em_children;
    float w_env, w_emit;               /* mixture weights of strategies 3 and 4 */
    global const float4* proposal;     /* the material paths are sampled from: `material`, */
} SceneData;                           /* or another under FIXED_PROPOSAL (below) */

/* FIXED_PROPOSAL, a test hook: paths are sampled with the densities of a second material
 * buffer and evaluated with `material`. Importance sampling with a proposal that stays put as
 * the material moves gives an estimator whose finite differences in a BSDF parameter are as
 * smooth as the adjoint's, path for path (tests/render/test_gradients_fd.py). */
#ifdef FIXED_PROPOSAL
#define PROPOSAL_PARAM , global const float4 *proposal_material
#define PROPOSAL_BUFFER proposal_material
#else
#define PROPOSAL_PARAM
#define PROPOSAL_BUFFER material
#endif

#define SCENE_PARAMS                                                                         \
    global const float4 *tri_v, global const float2 *tri_uv, global const int *tri_id,      \
        global const int *tri_instance, global const float8 *bvh_bounds,                    \
        global const int8 *bvh_children, global const float4 *material, int atlas_w,        \
        int atlas_h, global const float4 *kg, int cube_n, global const float *env_cdf,      \
        global const float *env_pmf, global const float4 *em_v, global const float *em_cdf, \
        global const float *em_pdf_area, int num_emitters, global const float8 *em_bounds,  \
        global const int8 *em_children, float w_env, float w_emit PROPOSAL_PARAM

#define SCENE_INIT(s)                                                                        \
    SceneData s = {tri_v,   tri_uv,  tri_id,   tri_instance, bvh_bounds, bvh_children,      \
                   material, atlas_w, atlas_h, kg,           cube_n,     env_cdf,           \
                   env_pmf, em_v,    em_cdf,   em_pdf_area,  num_emitters, em_bounds,       \
                   em_children, w_env, w_emit, PROPOSAL_BUFFER}

#endif
