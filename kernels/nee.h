#line 2 "nee.h"
/* Next-event estimation with multiple importance sampling (Veach 1997, ch. 9; what Mitsuba 3's
 * `path` does): at every vertex a light sample, traced to its first hit, besides the BSDF sample
 * that continues the path; each of the two weights what it finds by the power heuristic against
 * the other's density.
 *
 * The light sample picks strategy 3 (kg by luminance) or 4 (emitting triangles by area x
 * radiance, lights.h) with probabilities proportional to w_env, w_emit, and brings the radiance
 * E = ke + kw kg of the first surface it meets (so an environment sample that leaves through a
 * window brings kw kg, one that meets a wall brings nothing), or kg if it escapes. Its density
 * is that of the *segment* from x to that first hit: p_env(d) for strategy 3, and for strategy 4
 * P(t) / area(t) dist^2 / |cos| of the first hit's triangle t, counted only when strategy 4 aimed
 * at t itself (a point behind an occluder is a miss, not a sample of the occluder). Thus neither
 * estimator needs MILO's all-hits traversal of the emitter BVH: a hit's light density is a lookup
 * (tri_light_pdf). Compiled in with FEATURE_NEE when there is a light strategy to sample. */
#ifndef INVRENDER_NEE_H
#define INVRENDER_NEE_H

#include "common.h"
#include "scene_data.h"
#include "rng.h"
#include "intersect.h"
#include "bvh.h"
#include "textures.h"
#include "bsdf.h"
#include "lights.h"
#include "sampling.h"
#include "surface.h"

#if defined(FEATURE_NEE) && (defined(FEATURE_ENV_SAMPLING) || defined(FEATURE_EMITTER_SAMPLING))
#define NEE_ACTIVE 1

/* Probabilities of picking strategy 3 or 4 for a light sample; both 0: nothing to sample. */
typedef struct {
    float env, emit;
} LightChoice;

inline LightChoice light_choice(const SceneData* s)
{
    LightChoice c = {0.0f, 0.0f};
#ifdef FEATURE_ENV_SAMPLING
    c.env = s->w_env;
#endif
#ifdef FEATURE_EMITTER_SAMPLING
    c.emit = s->w_emit;
#endif
    float sum = c.env + c.emit;
    if (sum > 0.0f) {
        c.env /= sum;
        c.emit /= sum;
    }
    return c;
}

inline int has_lights(const LightChoice* c) { return c->env + c->emit > 0.0f; }

/* Density (solid angle at the origin) with which a light sample makes the segment along unit d
 * that ends at hit h, at distance h->t on point sp (h->slot < 0: it escapes). */
inline float light_pdf(const SceneData* s, const LightChoice* c, float3 d, const Hit* h, const SurfacePoint* sp)
{
    float pdf = 0.0f;
#ifdef FEATURE_ENV_SAMPLING
    if (c->env > 0.0f)
        pdf += c->env * pdf_environment(s, d);
#endif
#ifdef FEATURE_EMITTER_SAMPLING
    if (c->emit > 0.0f && h->slot >= 0 && sp->emits) {
        float per_area = s->tri_light_pdf[h->slot];
        if (per_area > 0.0f)
            pdf += c->emit * per_area * h->t * h->t / fabs(dot(sp->n, d));
    }
#endif
    return pdf;
}

/* Power heuristic weight of a strategy with density a against one with density b, written so
 * that an infinite or zero density gives 1 or 0, never inf / inf. */
inline float mis_power(float a, float b)
{
    if (!(a > 0.0f))
        return 0.0f;
    float r = b / a;
    return 1.0f / (1.0f + r * r);
}

/* What a light sample found: the radiance E arriving along d and where it came from. */
typedef struct {
    float3 d;      /* unit direction from the shading point */
    float3 E;      /* ke + kw kg(d) of the first hit, or kg(d) if it escaped */
    float weight;  /* MIS weight / light density: the sample adds beta f(d) E weight; 0: nothing */
    int texel;     /* the first hit's texel, -1: the sky */
} LightSample;

/* One light sample from x (offset off a surface with normal n, on triangle `skip`); wb and q
 * give the BSDF sampling density the sample is weighted against. *suspect as in trace_path. */
inline LightSample sample_light(const SceneData* s, const LightChoice* c, const MixtureWeights* wb,
                                const Material* q, float3 x, float3 n, float3 wo, int skip, float4 u, int* suspect)
{
    LightSample ls = {(float3)(0.0f), (float3)(0.0f), 0.0f, -1};
    int target = -1; /* the slot strategy 4 aimed at; -1: strategy 3, whatever the ray meets */
    float3 d = (float3)(0.0f);
    float tmax = RAY_TMAX; /* strategy 4: just past the point aimed at, a shorter traversal */
    if (u.x < c->env) {
#ifdef FEATURE_ENV_SAMPLING
        d = sample_environment(s, u.y, u.z, u.w);
#endif
    } else {
#ifdef FEATURE_EMITTER_SAMPLING
        int t;
        float3 y = sample_emitter_point(s, u.y, u.z, u.w, &t);
        if (!emitter_faces(s, t, y, x))
            return ls; /* the back of a one-sided emitter: a spent sample */
        float dist = length(y - x);
        d = (y - x) / dist;
        tmax = dist * 1.001f;
        target = s->em_slot[t];
#endif
    }
    if (!(dot(d, n) > 0.0f))
        return ls; /* below the surface: f = 0 */
    Ray ray = make_ray(x, d);
    Hit hit = bvh_closest_hit(s, &ray, tmax, skip);
    if (target >= 0 && hit.slot != target)
        return ls; /* occluded */
    SurfacePoint sp;
    if (hit.slot >= 0) {
        sp = surface_point(s, &hit, d);
        if (!sp.emits)
            return ls; /* the back of a one-sided face: nothing, and no derivative */
        Material m = material_at(s, sp.texel);
        ls.E = emitted(s, &m, d);
        ls.texel = sp.texel;
    } else {
#ifdef FEATURE_ENVIRONMENT
        ls.E = environment(s, d);
#endif
    }
    float p_light = light_pdf(s, c, d, &hit, &sp);
    float p_bsdf = pdf_mixture(s, wb, q, x, n, wo, d);
    if (!(p_light > 0.0f) || !isfinite(p_light)) {
        *suspect = 1;
        return ls;
    }
    ls.d = d;
    ls.weight = mis_power(p_light, p_bsdf) / p_light;
    return ls;
}

#endif
#endif
