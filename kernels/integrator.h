#line 2 "integrator.h"
/* The path tracer of MILO Eq. 4: L = sum_b beta_b E(x_b), beta_{b+1} = beta_b f cos / p_mix.
 * No next-event estimation and no Russian roulette: one ray per bounce and a fixed path length,
 * which keeps the adjoint (gradients) a replay of the same loop. */
#ifndef INVRENDER_INTEGRATOR_H
#define INVRENDER_INTEGRATOR_H

#include "common.h"
#include "scene_data.h"
#include "rng.h"
#include "intersect.h"
#include "bvh.h"
#include "camera.h"
#include "textures.h"
#include "bsdf.h"
#include "lights.h"
#include "sampling.h"

typedef struct {
    float3 p;   /* on the triangle, from barycentrics (more precise than o + t d) */
    float3 n;   /* unit geometric normal, turned to face the incoming ray: two-sided surfaces */
    float2 uv;
    int texel;
    int emits;  /* 0 on the back of a one-sided face, which emits nothing (lights.h) */
} SurfacePoint;

inline SurfacePoint surface_point(const SceneData* s, const Hit* h, float3 d)
{
    float3 v0 = tri_vertex(s->tri_v, h->slot, 0), v1 = tri_vertex(s->tri_v, h->slot, 1),
           v2 = tri_vertex(s->tri_v, h->slot, 2);
    float b0 = 1.0f - h->b1 - h->b2;
    SurfacePoint sp;
    sp.p = b0 * v0 + h->b1 * v1 + h->b2 * v2;
    float3 n = normalize(cross(v1 - v0, v2 - v0));
    sp.n = dot(n, d) > 0.0f ? -n : n;
    sp.emits = emits_towards(s->tri_one_sided, h->slot, n, d);
    global const float2* uv = s->tri_uv + 3 * h->slot;
    sp.uv = b0 * uv[0] + h->b1 * uv[1] + h->b2 * uv[2];
    sp.texel = atlas_texel(s, sp.uv);
    return sp;
}

/* The camera ray of sample k of request q = (camera, x, y, ray id): jittered in its pixel with
 * block 1 of bounce 0, so every kernel that traces this sample traces the same ray. */
inline float3 camera_sample_direction(global const CameraData* cam, int4 q, ulong seed, uint k)
{
    float4 jitter = rng_uniform4(seed, (uint)q.w, k, 0u, RNG_BLOCK_CAMERA);
    return camera_direction(cam, (float)q.y + jitter.x, (float)q.z + jitter.y);
}

/* What the adjoint (adjoint.cl) needs of each vertex of a path, recorded by trace_path when it
 * is given somewhere to put it: the path is at most MAX_BOUNCES + 2 vertices long (the last may
 * be an escape), so it is stored whole instead of replayed. */
typedef struct {
    int texel;       /* atlas texel hit; -1: the ray escaped and saw kg along d */
    float3 beta;     /* path throughput arriving at the vertex */
    float3 d;        /* direction the ray travelled to reach it */
    float3 n, wi;    /* shading normal (facing -d) and the direction sampled from here */
    int emits;       /* E counts here: not the back of a one-sided face */
    float inv_pdf;   /* 1 / p_mix(wi); 0 when the path ended here */
} PathVertex;

#define PATH_CAPACITY (MAX_BOUNCES + 2)

/* *suspect is set when a path ends on a density or weight that is not a positive finite number
 * for a direction its strategy did draw: never on a correct scene, so the host counts it.
 * With path != 0 the vertices are recorded and *length says how many. */
inline float3 trace_path(const SceneData* s, float3 o, float3 d, ulong seed, uint ray_id, uint sample,
                         int* suspect, PathVertex* path, int* length)
{
    float3 radiance = (float3)(0.0f), beta = (float3)(1.0f);
    int skip = -1, for_derivative = 0;
    if (path)
        *length = 0;
    for (int bounce = 0;; ++bounce) {
        Ray ray = make_ray(o, d);
        Hit hit = bvh_closest_hit(s, &ray, RAY_TMAX, skip);
        PathVertex* vertex = path ? path + (*length)++ : 0;
        if (vertex) {
            vertex->texel = -1;
            vertex->beta = beta;
            vertex->d = d;
            vertex->inv_pdf = 0.0f;
        }
        if (hit.slot < 0) {
#ifdef FEATURE_ENVIRONMENT
            radiance += beta * environment(s, d);
#endif
            break;
        }
        SurfacePoint sp = surface_point(s, &hit, d);
        Material m = material_at(s, sp.texel);
        if (vertex) {
            vertex->texel = sp.texel;
            vertex->n = sp.n;
            vertex->emits = sp.emits;
        }
        if (sp.emits)
            radiance += beta * emitted(s, &m, d);
        if (bounce == MAX_BOUNCES)
            break;
        Material q = proposal_at(s, sp.texel, &m);
        MixtureWeights w = mixture_weights(s, &q);
        if (!reflects(&w)) {
            /* A black texel (kd = ks = 0) ends the path, but d(f cos)/d kd there is cos / pi,
             * not 0: a recorded path (the adjoint) goes on from the first one with kd's lobe in
             * the mixture and beta 0, to estimate the light arriving there. */
            if (!path || !(max3(beta) > 0.0f))
                break;
            w.diffuse = 1.0f - w.env - w.emit;
            for_derivative = 1;
        }
        float3 wo = -d;
        float4 u = rng_uniform4(seed, ray_id, sample, (uint)bounce, RNG_BLOCK_SCATTER);
        float3 wi = sample_mixture(s, &w, &q, sp.p, sp.n, wo, u);
        if (!(dot(wi, sp.n) > 0.0f))
            break; /* spent sample, or below the surface where f = 0 */
        float3 x = offset_ray_origin(sp.p, sp.n);
        float pdf = pdf_mixture(s, &w, &q, x, sp.n, wo, wi);
        float3 f = bsdf_cos(&m, sp.n, wo, wi);
        if (!(pdf > 0.0f) || !isfinite(pdf)) {
            *suspect = 1;
            break;
        }
        beta *= f / pdf;
        if (!all_finite3(beta)) {
            *suspect = 1;
            break;
        }
        if (vertex) {
            vertex->wi = wi;
            vertex->inv_pdf = 1.0f / pdf;
        }
        if (!(max3(beta) > 0.0f) && !for_derivative)
            break;
        o = x;
        d = wi;
        skip = hit.slot;
    }
    return radiance;
}

#endif
