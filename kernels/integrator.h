#line 2 "integrator.h"
/* The path tracer. Two estimators, chosen at compile time:
 * - next-event estimation with MIS (FEATURE_NEE, nee.h): at each vertex a light sample and a
 *   BSDF sample, L = sum_b beta_b (w_b E(x_b) + f(wl) E_l w_l / p_l), beta_{b+1} = beta_b f / p_bsdf;
 * - MILO's one-sample mixture (Eq. 4): L = sum_b beta_b E(x_b), beta_{b+1} = beta_b f cos / p_mix,
 *   one ray per bounce.
 * Paths end at MAX_BOUNCES, or earlier by Russian roulette from vertex ROULETTE_DEPTH on when it
 * is compiled in (survival q = min(max(beta), 0.95), beta / q: Mitsuba's rule). The adjoint
 * (adjoint.cl) walks the recorded path back; 1 / q is part of the recorded 1 / p. */
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
#include "surface.h"
#include "nee.h"

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
    float inv_pdf;   /* 1 / p(wi), the BSDF sample's density (the mixture's without NEE); 0: the path ended */
    float mis;       /* weight of the E (or kg) found here against the light sample that could find it */
#ifdef NEE_ACTIVE
    LightSample light; /* the light sample taken here; weight 0: none */
#endif
} PathVertex;

#define PATH_CAPACITY (MAX_BOUNCES + 2)

inline void start_vertex(PathVertex* v, float3 beta, float3 d)
{
    v->texel = -1;
    v->beta = beta;
    v->d = d;
    v->inv_pdf = 0.0f;
    v->mis = 1.0f;
#ifdef NEE_ACTIVE
    v->light.weight = 0.0f;
#endif
}

/* *suspect is set when a path ends on a density or weight that is not a positive finite number
 * for a direction its strategy did draw: never on a correct scene, so the host counts it.
 * With path != 0 the vertices are recorded and *length says how many. */
inline float3 trace_path(const SceneData* s, float3 o, float3 d, ulong seed, uint ray_id, uint sample,
                         int* suspect, PathVertex* path, int* length)
{
    float3 radiance = (float3)(0.0f), beta = (float3)(1.0f);
    int skip = -1, for_derivative = 0;
#ifdef NEE_ACTIVE
    LightChoice lights = light_choice(s);
    float bsdf_pdf = 0.0f; /* of the BSDF sample that led here; 0: nothing to weigh against */
#endif
    if (path)
        *length = 0;
    for (int bounce = 0;; ++bounce) {
        Ray ray = make_ray(o, d);
        Hit hit = bvh_closest_hit(s, &ray, RAY_TMAX, skip);
        PathVertex* vertex = path ? path + (*length)++ : 0;
        if (vertex)
            start_vertex(vertex, beta, d);
        SurfacePoint sp;
        Material m;
        float3 E = (float3)(0.0f); /* what the ray finds: kg on an escape, else E of the hit */
        if (hit.slot >= 0) {
            sp = surface_point(s, &hit, d);
            m = material_at(s, sp.texel);
            if (sp.emits)
                E = emitted(s, &m, d);
        } else {
#ifdef FEATURE_ENVIRONMENT
            E = environment(s, d);
#endif
        }
        float mis = 1.0f;
#ifdef NEE_ACTIVE
        /* The weight counts only where the ray found light, or where the adjoint differentiates
         * E (ke of a dark texel too): a forward path skips the light density at a plain wall. */
        if (bsdf_pdf > 0.0f && (hit.slot < 0 || sp.emits) && (vertex || max3(E) > 0.0f))
            mis = mis_power(bsdf_pdf, light_pdf(s, &lights, d, &hit, &sp));
        if (vertex)
            vertex->mis = mis;
#endif
        radiance += beta * mis * E;
        if (hit.slot < 0)
            break;
        if (vertex) {
            vertex->texel = sp.texel;
            vertex->n = sp.n;
            vertex->emits = sp.emits;
        }
        if (bounce == MAX_BOUNCES)
            break;
        Material q = proposal_at(s, sp.texel, &m);
#ifdef NEE_ACTIVE
        MixtureWeights w = mixture_weights(0.0f, 0.0f, &q); /* the lights have their own sample */
#else
        MixtureWeights w = mixture_weights(s->w_env, s->w_emit, &q);
#endif
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
        float3 x = offset_ray_origin(sp.p, sp.n);
#ifdef NEE_ACTIVE
        if (has_lights(&lights)) {
            float4 ul = rng_uniform4(seed, ray_id, sample, (uint)bounce, RNG_BLOCK_LIGHT);
            LightSample light = sample_light(s, &lights, &w, &q, x, sp.n, wo, hit.slot, ul, suspect);
            radiance += beta * bsdf_cos(&m, sp.n, wo, light.d) * light.E * light.weight;
            if (vertex)
                vertex->light = light;
        }
#endif
        float4 u = rng_uniform4(seed, ray_id, sample, (uint)bounce, RNG_BLOCK_SCATTER);
        float3 wi = sample_mixture(s, &w, &q, sp.p, sp.n, wo, u);
        if (!(dot(wi, sp.n) > 0.0f))
            break; /* spent sample, or below the surface where f = 0 */
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
#ifdef ROULETTE_DEPTH
        if (bounce + 1 >= ROULETTE_DEPTH && !for_derivative) {
            float survive = fmin(max3(beta), 0.95f);
            if (!(rng_uniform4(seed, ray_id, sample, (uint)bounce, RNG_BLOCK_ROULETTE).x < survive))
                break;
            beta /= survive;
            if (vertex)
                vertex->inv_pdf /= survive;
        }
#endif
#ifdef NEE_ACTIVE
        bsdf_pdf = has_lights(&lights) ? pdf : 0.0f;
#endif
        o = x;
        d = wi;
        skip = hit.slot;
    }
    return radiance;
}

#endif
